//! The type names of ParticleState and its parts: their structs live in
//! [`crate::data::msg`], which reads and writes bags without ROS.

use crate::data::msg::{Header, ParticleState, Point, Time, Vector3};

ros_types!("mcgnode_msgs" / "msg": ParticleState = "ParticleState");
ros_types!("std_msgs" / "msg": Header = "Header");
ros_types!("builtin_interfaces" / "msg": Time = "Time");
ros_types!("geometry_msgs" / "msg": Vector3 = "Vector3", Point = "Point");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::msg::{DEP_HEADER, DEP_POINT, DEP_TIME, DEP_VECTOR3, PARTICLE_STATE_TYPE};
    use crate::ros::wire::RosType;

    /// The bag reader's names (src/data, which knows no ROS) and these agree.
    #[test]
    fn the_bag_reader_spells_the_same_names() {
        assert_eq!(ParticleState::TYPE_NAME, PARTICLE_STATE_TYPE);
        assert_eq!(Header::SCHEMA_NAME, DEP_HEADER.0);
        assert_eq!(Time::SCHEMA_NAME, DEP_TIME.0);
        assert_eq!(Vector3::SCHEMA_NAME, DEP_VECTOR3.0);
        assert_eq!(Point::SCHEMA_NAME, DEP_POINT.0);
    }
}
