//! The managed-node lifecycle's services (`lifecycle_msgs` `change_state`,
//! `get_state`, ...) and its `~/transition_event` publisher, over the state
//! machine of [`super::lifecycle`].

use super::lifecycle::{
    available_states, get_state, transition_graph, ChangeStateRequest, ChangeStateResponse,
    EmptyRequest, GetAvailableStatesResponse, GetAvailableTransitionsResponse, GetStateResponse,
    Lifecycle, TransitionEvent, LIFECYCLE_PACKAGE,
};

/// The lifecycle services and the transition-event publisher.
pub struct LifecycleServers {
    change: ros2_client::Server<ChangeStateRequest, ChangeStateResponse>,
    get: ros2_client::Server<EmptyRequest, GetStateResponse>,
    states: ros2_client::Server<EmptyRequest, GetAvailableStatesResponse>,
    transitions: ros2_client::Server<EmptyRequest, GetAvailableTransitionsResponse>,
    graph: ros2_client::Server<EmptyRequest, GetAvailableTransitionsResponse>,
    events: ros2_client::Publisher<TransitionEvent>,
}

/// Creates the lifecycle services under the node (`~/change_state`, ...), as
/// rclcpp names them.
pub fn create(
    node: &mut ros2_client::Node,
    names: &super::names::Names,
) -> crate::error::Result<LifecycleServers> {
    use super::qos::{reliable_qos, ros_name};
    use crate::error::err;
    use ros2_client::{MessageTypeName, ServiceMapping, ServiceTypeName};
    macro_rules! server {
        ($srv:literal, $ty:literal) => {
            node.create_server(
                ServiceMapping::Enhanced,
                &ros_name(names, &format!("~/{}", $srv))?,
                &ServiceTypeName::new(LIFECYCLE_PACKAGE, $ty),
                reliable_qos(),
                reliable_qos(),
            )
            .map_err(|e| err!("creating the lifecycle service {}: {e:?}", $srv))?
        };
    }
    let topic = node
        .create_topic(
            &ros_name(names, "~/transition_event")?,
            MessageTypeName::new(LIFECYCLE_PACKAGE, "TransitionEvent"),
            &reliable_qos(),
        )
        .map_err(|e| err!("creating the transition_event topic: {e:?}"))?;
    Ok(LifecycleServers {
        change: server!("change_state", "ChangeState"),
        get: server!("get_state", "GetState"),
        states: server!("get_available_states", "GetAvailableStates"),
        transitions: server!("get_available_transitions", "GetAvailableTransitions"),
        // rclcpp serves the graph with the GetAvailableTransitions type too.
        graph: server!("get_transition_graph", "GetAvailableTransitions"),
        events: node
            .create_publisher(&topic, Some(reliable_qos()))
            .map_err(|e| err!("creating the transition_event publisher: {e:?}"))?,
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
        "ChangeState",
        Quiet,
        change_state,
    ));
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.get,
        "GetState",
        Quiet,
        |c: &Ctx, _| get_state(&c.lifecycle),
    ));
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.states,
        "GetAvailableStates",
        Quiet,
        |_: &Ctx, _| available_states(),
    ));
    tokio::spawn(serve(
        ctx.clone(),
        d(),
        s.transitions,
        "GetAvailableTransitions",
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
