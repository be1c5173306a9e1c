//! QoS profiles, ROS names and topics and servers created by their wire
//! type, shared by every module that creates DDS entities (one definition
//! each, so topics and services stay compatible).

use crate::error::err;
use ros2_client::dds::rustdds::Topic;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Name, Node, Publisher, QosProfile, Server, ServiceMapping, Subscription};

use super::params::NodeParams;
use super::resource_names::Names;
use super::wire::{RosAction, RosService, RosType};

/// Topic QoS from the parameters: volatile, keep-last `qos_depth`.
pub fn topic_qos(p: &NodeParams) -> QosProfile {
    let q = QosProfile::publisher_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast {
            depth: p.qos_depth as usize,
        });
    if p.qos_reliable {
        q.reliability_reliable(WhenFull::DEFAULT)
    } else {
        q.reliability_best_effort()
    }
}

/// QoS of the input subscriptions (`input_qos`): as the topics
/// ([`topic_qos`]), reliable or best effort keep-last `input_qos_depth`, or
/// `sensor_data` (rclpy's SensorDataQoS: best effort, keep-last 5). A
/// best-effort subscriber matches reliable and best-effort publishers; a
/// reliable one only reliable publishers.
pub fn input_qos(p: &NodeParams) -> QosProfile {
    let keep = |depth: u32| {
        QosProfile::publisher_default()
            .durability(Durability::Volatile)
            .history(History::KeepLast {
                depth: depth as usize,
            })
    };
    match p.input_qos.as_str() {
        "reliable" => keep(p.input_qos_depth).reliability_reliable(WhenFull::DEFAULT),
        "best_effort" => keep(p.input_qos_depth).reliability_best_effort(),
        "sensor_data" => keep(5).reliability_best_effort(),
        // "topics" (the parameter's kind admits no other word).
        _ => topic_qos(p),
    }
}

/// `/clock` QoS: best-effort keep-last 1 (as rclpy's time source), which
/// matches reliable and best-effort publishers.
pub fn clock_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 1 })
}

/// Reliable, volatile, keep-last 10: what rclpy's default services, action
/// endpoints and subscribers match.
pub fn reliable_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// The ROS name `s` resolved for the node's `names` (namespace, node name,
/// remaps), or an error naming it.
pub fn ros_name(names: &Names, s: &str) -> crate::error::Result<Name> {
    let full = names.resolve(s)?;
    Name::parse(&full).map_err(|e| err!("invalid ROS name {full:?}: {e:?}"))
}

/// The topic `name` (resolved for `names`) of message type `T`.
fn topic<T: RosType>(
    node: &Node,
    names: &Names,
    name: &str,
    qos: &QosProfile,
) -> crate::error::Result<Topic> {
    node.create_topic(&ros_name(names, name)?, T::message_type_name(), qos)
        .map_err(|e| err!("creating topic {name}: {e:?}"))
}

/// A publisher of message type `T` on the topic `name` (resolved for
/// `names`).
pub fn publisher<T: RosType>(
    node: &mut Node,
    names: &Names,
    name: &str,
    qos: &QosProfile,
) -> crate::error::Result<Publisher<T>> {
    let topic = topic::<T>(node, names, name, qos)?;
    node.create_publisher(&topic, Some(qos.clone()))
        .map_err(|e| err!("creating the publisher of {name}: {e:?}"))
}

/// A subscription to the topic `name` (resolved for `names`) of message type
/// `T`.
pub fn subscription<T: RosType>(
    node: &mut Node,
    names: &Names,
    name: &str,
    qos: &QosProfile,
) -> crate::error::Result<Subscription<T>> {
    let topic = topic::<T>(node, names, name, qos)?;
    node.create_subscription(&topic, Some(qos.clone()))
        .map_err(|e| err!("creating the subscription to {name}: {e:?}"))
}

/// A server of service type `S` named `name` (resolved for `names`), with
/// rclpy's QoS.
pub fn server<S: RosService>(
    node: &mut Node,
    names: &Names,
    name: &str,
) -> crate::error::Result<Server<S::Request, S::Response>> {
    node.create_server(
        ServiceMapping::Enhanced,
        &ros_name(names, name)?,
        &S::service_type_name(),
        reliable_qos(),
        reliable_qos(),
    )
    .map_err(|e| err!("creating the {} service {name}: {e:?}", S::NAME))
}

/// ros2-client's action server for our action type `A`.
pub type ActionServerOf<A> = ros2_client::action::AsyncActionServer<
    <A as RosAction>::Goal,
    <A as RosAction>::Result,
    <A as RosAction>::Feedback,
>;

/// An action server of type `A` named `name` (resolved for `names`), with
/// rclpy's action QoS (reliable, volatile services and feedback;
/// transient-local status), and its resolved name.
pub fn action_server<A: RosAction>(
    node: &mut Node,
    names: &Names,
    name: &str,
) -> crate::error::Result<(ActionServerOf<A>, String)> {
    let status = QosProfile::publisher_default()
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 });
    let qos = ros2_client::action::ActionServerQosPolicies {
        goal_service: reliable_qos(),
        result_service: reliable_qos(),
        cancel_service: reliable_qos(),
        feedback_publisher: reliable_qos(),
        status_publisher: status,
    };
    let server = node
        .create_action_server(
            ServiceMapping::Enhanced,
            &ros_name(names, name)?,
            &A::action_type_name(),
            qos,
        )
        .map_err(|e| err!("creating the {} action {name}: {e:?}", A::NAME))?;
    Ok((
        ros2_client::action::AsyncActionServer::new(server),
        names.resolve(name)?,
    ))
}

/// Publishes what `rx` receives as the goal's feedback until `job` ends, then
/// what the job sent just before it ended (a feedback per report); returns
/// the job's output.
pub async fn forward_feedback<A: RosAction, T>(
    server: &ActionServerOf<A>,
    handle: &ros2_client::action::ExecutingGoalHandle<A::Goal>,
    rx: &mut tokio::sync::mpsc::UnboundedReceiver<A::Feedback>,
    job: tokio::task::JoinHandle<T>,
) -> Result<T, tokio::task::JoinError>
where
    A::Goal: Clone,
    A::Feedback: Clone,
{
    tokio::pin!(job);
    let done = loop {
        tokio::select! {
            Some(fb) = rx.recv() => {
                // Fails once the goal is canceling: expected, not worth a warning.
                let _ = server.publish_feedback(handle.clone(), fb).await;
            }
            done = &mut job => break done,
        }
    };
    while let Ok(fb) = rx.try_recv() {
        let _ = server.publish_feedback(handle.clone(), fb).await;
    }
    done
}

#[cfg(test)]
mod tests {
    use super::*;
    use ros2_client::qos::{History as H, Reliability};

    fn of(words: &[(&str, &str)]) -> (Reliability, H) {
        let mut p = NodeParams::default();
        for (k, v) in words {
            let v = crate::ros::yaml::Scalar::parse_plain(v);
            p.set(k, &v, true).unwrap();
        }
        let q = input_qos(&p);
        (q.reliability, q.history)
    }

    #[test]
    fn input_qos_is_its_own_and_outputs_keep_theirs() {
        let best_effort = Reliability::BestEffort;
        let (r, h) = of(&[("input_qos", "sensor_data")]);
        assert_eq!((r, h), (best_effort, H::KeepLast { depth: 5 }));
        let (r, h) = of(&[("input_qos", "best_effort"), ("input_qos_depth", "7")]);
        assert_eq!((r, h), (best_effort, H::KeepLast { depth: 7 }));
        let (r, _) = of(&[("input_qos", "reliable"), ("qos_reliable", "false")]);
        assert!(matches!(r, Reliability::Reliable { .. }), "{r:?}");
        // `topics` follows qos_reliable and qos_depth, as before.
        let (r, h) = of(&[("qos_reliable", "false"), ("qos_depth", "3")]);
        assert_eq!((r, h), (best_effort, H::KeepLast { depth: 3 }));
        // The outputs keep theirs.
        let p = NodeParams {
            input_qos: "sensor_data".into(),
            ..NodeParams::default()
        };
        assert!(matches!(
            topic_qos(&p).reliability,
            Reliability::Reliable { .. }
        ));
    }
}
