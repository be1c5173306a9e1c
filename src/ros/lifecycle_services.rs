//! The managed-node lifecycle's services (`lifecycle_msgs` `change_state`,
//! `get_state`, ...) and its `~/transition_event` publisher, over the state
//! machine of [`super::lifecycle`].

use super::lifecycle::{available_states, get_state, transition_graph, Lifecycle};
use super::wire::{
    ChangeState, ChangeStateRequest, ChangeStateResponse, GetAvailableStates,
    GetAvailableStatesRequest, GetAvailableStatesResponse, GetAvailableTransitions,
    GetAvailableTransitionsRequest, GetAvailableTransitionsResponse, GetState, GetStateRequest,
    GetStateResponse, RosService, TransitionEvent,
};

/// The lifecycle services and the transition-event publisher.
pub struct LifecycleServers {
    change: ros2_client::Server<ChangeStateRequest, ChangeStateResponse>,
    get: ros2_client::Server<GetStateRequest, GetStateResponse>,
    states: ros2_client::Server<GetAvailableStatesRequest, GetAvailableStatesResponse>,
    transitions:
        ros2_client::Server<GetAvailableTransitionsRequest, GetAvailableTransitionsResponse>,
    graph: ros2_client::Server<GetAvailableTransitionsRequest, GetAvailableTransitionsResponse>,
    events: ros2_client::Publisher<TransitionEvent>,
}

/// Creates the lifecycle services under the node (`~/change_state`, ...), as
/// rclcpp names them.
pub fn create(
    node: &mut ros2_client::Node,
    names: &super::resource_names::Names,
) -> crate::error::Result<LifecycleServers> {
    use super::qos::{publisher, reliable_qos, server};
    use super::topics::lifecycle::{
        CHANGE_STATE, GET_AVAILABLE_STATES, GET_AVAILABLE_TRANSITIONS, GET_STATE,
        GET_TRANSITION_GRAPH, TRANSITION_EVENT,
    };
    Ok(LifecycleServers {
        change: server::<ChangeState>(node, names, CHANGE_STATE)?,
        get: server::<GetState>(node, names, GET_STATE)?,
        states: server::<GetAvailableStates>(node, names, GET_AVAILABLE_STATES)?,
        transitions: server::<GetAvailableTransitions>(node, names, GET_AVAILABLE_TRANSITIONS)?,
        // rclcpp serves the graph with the GetAvailableTransitions type too.
        graph: server::<GetAvailableTransitions>(node, names, GET_TRANSITION_GRAPH)?,
        events: publisher(node, names, TRANSITION_EVENT, &reliable_qos())?,
    })
}

impl super::service::Reply for ChangeStateResponse {
    fn failure(_message: String) -> Self {
        ChangeStateResponse { success: false }
    }
    fn failure_reason(&self) -> Option<&str> {
        None
    }
}

macro_rules! no_failure_reply {
    ($($t:ty),*) => {$(
        impl super::service::Reply for $t {
            fn failure(_message: String) -> Self {
                Self::default()
            }
            fn failure_reason(&self) -> Option<&str> {
                None
            }
        }
    )*};
}
no_failure_reply!(
    GetStateResponse,
    GetAvailableStatesResponse,
    GetAvailableTransitionsResponse
);

/// What a transition works with: the state, where to announce it, the log
/// and the clock.
#[derive(Clone)]
struct Ctx {
    lifecycle: std::sync::Arc<Lifecycle>,
    events: std::sync::Arc<ros2_client::Publisher<TransitionEvent>>,
    diag: std::sync::Arc<super::handles::Diagnostics>,
    clock: std::sync::Arc<super::clock::Clock>,
}

/// Serves the lifecycle services (inside the runtime).
pub fn spawn(
    lifecycle: std::sync::Arc<Lifecycle>,
    diag: std::sync::Arc<super::handles::Diagnostics>,
    clock: std::sync::Arc<super::clock::Clock>,
    s: LifecycleServers,
) {
    use super::service::{serve, OnFailure::Quiet};
    let ctx = Ctx {
        lifecycle,
        events: std::sync::Arc::new(s.events),
        diag: diag.clone(),
        clock,
    };
    let d = || diag.clone();
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.change,
        ChangeState::NAME,
        Quiet,
        change_state,
    ));
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.get,
        GetState::NAME,
        Quiet,
        |c: &Ctx, _| get_state(&c.lifecycle),
    ));
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.states,
        GetAvailableStates::NAME,
        Quiet,
        |_: &Ctx, _| available_states(),
    ));
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.transitions,
        GetAvailableTransitions::NAME,
        Quiet,
        |c: &Ctx, _| GetAvailableTransitionsResponse {
            available_transitions: c.lifecycle.available(),
        },
    ));
    tokio::spawn(serve(
        ctx,
        d(),
        s.graph,
        "get_transition_graph",
        Quiet,
        |_: &Ctx, _| transition_graph(),
    ));
}

/// Takes a requested transition, logs it and announces it on
/// `transition_event`; a refused one is logged with the reason.
fn change_state(c: &Ctx, req: ChangeStateRequest) -> ChangeStateResponse {
    use ros2_client::log::LogLevel;
    match c.lifecycle.transition(&req.transition) {
        Ok(d) => {
            c.diag.log(
                LogLevel::Info,
                &format!(
                    "lifecycle: {} -> {} ({})",
                    d.start_state.label, d.goal_state.label, d.transition.label
                ),
            );
            let event = TransitionEvent {
                timestamp: c.clock.now_log_ns(),
                transition: d.transition,
                start_state: d.start_state,
                goal_state: d.goal_state,
            };
            if let Err(e) = c.events.publish(event) {
                c.diag.log(
                    LogLevel::Warn,
                    &format!("announcing a lifecycle transition failed: {e:?}"),
                );
            }
            ChangeStateResponse { success: true }
        }
        Err(e) => {
            c.diag.log(LogLevel::Warn, &e.to_string());
            ChangeStateResponse { success: false }
        }
    }
}
