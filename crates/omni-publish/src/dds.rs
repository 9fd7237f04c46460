//! ROS 2 output through a pure-Rust DDS stack (`ros2-client` over RustDDS): no ROS library at
//! build or run time.
//!
//! Topics (under the prefix, default `/omniscan`):
//! - `points`: `sensor_msgs/msg/PointCloud2`, one per sweep, ROS 2's sensor-data QoS (best
//!   effort, volatile, keep last 5), so that a slow subscriber never holds the publisher back;
//! - `calibration`: `std_msgs/msg/String` holding camera.json and scanner.json as one JSON
//!   object, reliable and transient-local (latched), so that a late subscriber gets it;
//! - `/tf_static`: `tf2_msgs/msg/TFMessage` with the static transform to the sensor frame,
//!   transient-local as `tf2_ros::StaticTransformBroadcaster` sends it.

use crate::msg::{PointCloud2, StringMsg, TfMessage, TransformStamped};
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::dds::{Context, Node, Publisher};
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use std::net::IpAddr;

/// Where and how to publish.
#[derive(Debug, Clone)]
pub struct DdsOptions {
    /// ROS 2 domain id (ROS_DOMAIN_ID), 0–232.
    pub domain_id: u16,
    /// Namespace of the sensor's topics, e.g. `/omniscan`.
    pub prefix: String,
    /// Local addresses DDS may use (discovery and data); empty = every interface.
    pub interfaces: Vec<IpAddr>,
}

/// The largest domain id whose RTPS ports (7400 + 250 · id + …) fit in 16 bits.
pub const MAX_DOMAIN_ID: u16 = 232;

/// ROS 2's `rmw_qos_profile_sensor_data`.
pub const SENSOR_DATA_QOS: QosProfile =
    QosProfile::subscription_default().reliability(Reliability::BestEffort).history(History::KeepLast { depth: 5 });

/// Reliable, transient-local, keep last 1: a latched topic.
pub const LATCHED_QOS: QosProfile = QosProfile::subscription_default()
    .reliability(Reliability::Reliable { when_full: WhenFull::Wait(std::time::Duration::from_millis(100)) })
    .durability(Durability::TransientLocal)
    .history(History::KeepLast { depth: 1 });

/// The live ROS 2 publisher of one sensor.
pub struct DdsPublisher {
    points: Publisher<PointCloud2>,
    calibration: Publisher<StringMsg>,
    tf_static: Publisher<TfMessage>,
    // Kept alive: dropping the node or the context ends the participant.
    _node: Node,
    _context: Context,
}

impl DdsPublisher {
    /// Joins the domain and creates the topics; errors are one line naming what failed.
    pub fn new(opts: &DdsOptions) -> Result<Self, String> {
        if opts.domain_id > MAX_DOMAIN_ID {
            return Err(format!("domain id {} is out of range 0..={MAX_DOMAIN_ID}", opts.domain_id));
        }
        let namespace = namespace_of(&opts.prefix)?;
        let mut builder = DomainParticipantBuilder::new(opts.domain_id);
        if !opts.interfaces.is_empty() {
            builder = builder.with_only_networks(opts.interfaces.iter().copied());
        }
        let participant = builder.build().map_err(|e| format!("DDS domain {}: {e}", opts.domain_id))?;
        let context = Context::from_domain_participant(participant).map_err(|e| format!("ROS 2 context: {e}"))?;
        let node_name = NodeName::new("/", "omniscan_live").map_err(|e| format!("node name: {e:?}"))?;
        let mut node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .map_err(|e| format!("ROS 2 node: {e:?}"))?;
        let topic_name = |base_name: &str| {
            Name::new(&namespace, base_name).map_err(|e| format!("topic {}/{base_name}: {e:?}", opts.prefix))
        };
        let points_topic = node
            .create_topic(&topic_name("points")?, MessageTypeName::new("sensor_msgs", "PointCloud2"), &SENSOR_DATA_QOS)
            .map_err(|e| format!("topic points: {e:?}"))?;
        let calibration_topic = node
            .create_topic(&topic_name("calibration")?, MessageTypeName::new("std_msgs", "String"), &LATCHED_QOS)
            .map_err(|e| format!("topic calibration: {e:?}"))?;
        let tf_topic = node
            .create_topic(
                &Name::new("/", "tf_static").map_err(|e| format!("{e:?}"))?,
                MessageTypeName::new("tf2_msgs", "TFMessage"),
                &LATCHED_QOS,
            )
            .map_err(|e| format!("topic /tf_static: {e:?}"))?;
        let points = node.create_publisher(&points_topic, None).map_err(|e| format!("publisher points: {e:?}"))?;
        let calibration =
            node.create_publisher(&calibration_topic, None).map_err(|e| format!("publisher calibration: {e:?}"))?;
        let tf_static = node.create_publisher(&tf_topic, None).map_err(|e| format!("publisher /tf_static: {e:?}"))?;
        Ok(DdsPublisher { points, calibration, tf_static, _node: node, _context: context })
    }

    /// Sends one sweep's cloud (best effort: never waits for a subscriber).
    pub fn publish_points(&self, cloud: PointCloud2) -> Result<(), String> {
        self.points.publish(cloud).map_err(|e| format!("publishing points: {e:?}"))
    }

    /// Sends the calibration (latched).
    pub fn publish_calibration(&self, json: String) -> Result<(), String> {
        self.calibration.publish(StringMsg { data: json }).map_err(|e| format!("publishing calibration: {e:?}"))
    }

    /// Sends the static transforms (latched).
    pub fn publish_tf_static(&self, transforms: Vec<TransformStamped>) -> Result<(), String> {
        self.tf_static.publish(TfMessage { transforms }).map_err(|e| format!("publishing /tf_static: {e:?}"))
    }
}

/// The ROS namespace of a topic prefix (`/robot1/omniscan/` → `/robot1/omniscan`), checked
/// against ROS's naming rules so that a bad prefix is refused before joining the domain.
fn namespace_of(prefix: &str) -> Result<String, String> {
    if prefix == "/" {
        return Ok("/".into());
    }
    let trimmed = prefix.trim_end_matches('/');
    if !trimmed.starts_with('/') {
        return Err(format!("topic prefix {prefix:?} must start with /"));
    }
    let ok = trimmed.split('/').skip(1).all(|tok| {
        !tok.is_empty()
            && tok.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
            && tok.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            && !tok.contains("__")
    });
    if !ok {
        return Err(format!(
            "topic prefix {prefix:?}: each part must start with a letter and hold only letters, digits and single underscores"
        ));
    }
    Ok(trimmed.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_are_checked_as_ros_names() {
        assert_eq!(namespace_of("/omniscan").unwrap(), "/omniscan");
        assert_eq!(namespace_of("/robot1/omniscan/").unwrap(), "/robot1/omniscan");
        assert_eq!(namespace_of("/").unwrap(), "/");
        assert!(namespace_of("omniscan").unwrap_err().contains("must start with /"));
        assert!(namespace_of("/omni-scan").unwrap_err().contains("letters, digits"));
    }
}
