//! The managed-node lifecycle (ROS 2 design "Managed nodes"): its states,
//! transitions over the `lifecycle_msgs` wire types ([`super::wire::lifecycle`]),
//! with no DDS here (the services are in [`super::lifecycle_services`]). Served with
//! ros2-client's plain services since it has no lifecycle node: the node
//! answers `lifecycle_msgs` `change_state`, `get_state`,
//! `get_available_states`, `get_available_transitions` and
//! `get_transition_graph` under its name, as rclcpp's lifecycle nodes do, and
//! announces each transition on `~/transition_event`. Only an active node
//! predicts; inactive and unconfigured ones refuse states and Rollout calls
//! with the reason. Transitions are immediate (the node holds no resource
//! that configuring would allocate: the model is loaded, and checked, at
//! start), so the intermediate states are never observed.

use std::sync::atomic::{AtomicU8, Ordering};

use super::wire::{
    GetAvailableStatesResponse, GetAvailableTransitionsResponse, GetStateResponse, StateMsg,
    TransitionDescription, TransitionMsg,
};

/// A primary state of a managed node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Primary {
    /// Created, not configured: refuses work.
    Unconfigured = 1,
    /// Configured, not active: refuses work.
    Inactive = 2,
    /// Predicting and serving.
    Active = 3,
    /// Shut down: refuses work until the process ends.
    Finalized = 4,
}

impl Primary {
    const ALL: [Primary; 4] = [
        Primary::Unconfigured,
        Primary::Inactive,
        Primary::Active,
        Primary::Finalized,
    ];

    /// The label rclcpp gives it.
    pub fn label(self) -> &'static str {
        match self {
            Primary::Unconfigured => "unconfigured",
            Primary::Inactive => "inactive",
            Primary::Active => "active",
            Primary::Finalized => "finalized",
        }
    }

    fn msg(self) -> StateMsg {
        StateMsg {
            id: self as u8,
            label: self.label().into(),
        }
    }

    fn from_id(id: u8) -> Primary {
        Primary::ALL
            .into_iter()
            .find(|p| *p as u8 == id)
            .unwrap_or(Primary::Finalized)
    }
}

/// The transitions between primary states: (id, label, from, to), with
/// `lifecycle_msgs/msg/Transition`'s ids.
const TRANSITIONS: [(u8, &str, Primary, Primary); 7] = [
    (1, "configure", Primary::Unconfigured, Primary::Inactive),
    (2, "cleanup", Primary::Inactive, Primary::Unconfigured),
    (3, "activate", Primary::Inactive, Primary::Active),
    (4, "deactivate", Primary::Active, Primary::Inactive),
    (5, "shutdown", Primary::Unconfigured, Primary::Finalized),
    (6, "shutdown", Primary::Inactive, Primary::Finalized),
    (7, "shutdown", Primary::Active, Primary::Finalized),
];

fn describe(t: &(u8, &str, Primary, Primary)) -> TransitionDescription {
    TransitionDescription {
        transition: TransitionMsg {
            id: t.0,
            label: t.1.into(),
        },
        start_state: t.2.msg(),
        goal_state: t.3.msg(),
    }
}

/// Why a transition was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("lifecycle transition {asked} is not available from {from} (available: {available})")]
pub struct Refused {
    /// The transition asked for (id and label).
    pub asked: String,
    /// The state the node is in.
    pub from: &'static str,
    /// The labels available from there.
    pub available: String,
}

/// The node's lifecycle state, shared by the input loop, the services and
/// the lifecycle services.
#[derive(Debug)]
pub struct Lifecycle(AtomicU8);

impl Lifecycle {
    /// A node in `start`.
    pub fn new(start: Primary) -> Self {
        Lifecycle(AtomicU8::new(start as u8))
    }

    /// The state now.
    pub fn state(&self) -> Primary {
        Primary::from_id(self.0.load(Ordering::Acquire))
    }

    /// Why work is refused now (`None` when active).
    pub fn refusal(&self) -> Option<String> {
        match self.state() {
            Primary::Active => None,
            s => Some(format!(
                "the node is {} (managed lifecycle); activate it with /mcgnode/change_state \
                 (configure, then activate)",
                s.label()
            )),
        }
    }

    /// Takes the transition `t` (by id, or by label when the id is 0) and
    /// returns its description, or why not.
    pub fn transition(&self, t: &TransitionMsg) -> Result<TransitionDescription, Refused> {
        let from = self.state();
        let found = TRANSITIONS
            .iter()
            .find(|x| x.2 == from && (x.0 == t.id || (t.id == 0 && x.1 == t.label.trim())));
        match found {
            Some(x) => {
                self.0.store(x.3 as u8, Ordering::Release);
                Ok(describe(x))
            }
            None => Err(Refused {
                asked: format!("{} {:?}", t.id, t.label),
                from: from.label(),
                available: self
                    .available()
                    .iter()
                    .map(|d| d.transition.label.clone())
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        }
    }

    /// The transitions from the state now.
    pub fn available(&self) -> Vec<TransitionDescription> {
        let from = self.state();
        TRANSITIONS
            .iter()
            .filter(|x| x.2 == from)
            .map(describe)
            .collect()
    }
}

/// Every transition of the graph.
pub fn transition_graph() -> GetAvailableTransitionsResponse {
    GetAvailableTransitionsResponse {
        available_transitions: TRANSITIONS.iter().map(describe).collect(),
    }
}

/// Every primary state.
pub fn available_states() -> GetAvailableStatesResponse {
    GetAvailableStatesResponse {
        available_states: Primary::ALL.iter().map(|p| p.msg()).collect(),
    }
}

/// The current state as `get_state` answers it.
pub fn get_state(l: &Lifecycle) -> GetStateResponse {
    GetStateResponse {
        current_state: l.state().msg(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn by_label(l: &str) -> TransitionMsg {
        TransitionMsg {
            id: 0,
            label: l.into(),
        }
    }

    #[test]
    fn transitions_follow_the_managed_node_graph() {
        let l = Lifecycle::new(Primary::Unconfigured);
        assert!(l.refusal().unwrap().contains("unconfigured"));
        let e = l.transition(&by_label("activate")).unwrap_err();
        assert_eq!(e.available, "configure, shutdown");
        assert_eq!(l.state(), Primary::Unconfigured);
        let d = l.transition(&by_label("configure")).unwrap();
        assert_eq!((d.start_state.id, d.goal_state.id), (1, 2));
        let ids: Vec<u8> = l.available().iter().map(|d| d.transition.id).collect();
        assert_eq!(ids, vec![2, 3, 6]);
        l.transition(&TransitionMsg {
            id: 3,
            label: String::new(),
        })
        .unwrap();
        assert_eq!(l.state(), Primary::Active);
        assert!(l.refusal().is_none());
        l.transition(&by_label("deactivate")).unwrap();
        assert!(l.refusal().unwrap().contains("inactive"));
        l.transition(&by_label("shutdown")).unwrap();
        assert_eq!(l.state(), Primary::Finalized);
        assert!(l.available().is_empty());
        assert!(l.transition(&by_label("configure")).is_err());
        assert_eq!(transition_graph().available_transitions.len(), 7);
        assert_eq!(available_states().available_states.len(), 4);
    }
}
