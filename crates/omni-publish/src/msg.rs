//! The ROS 2 messages the live output sends, as serde structs whose field order is the CDR
//! layout of their `.msg` definitions (`sensor_msgs/PointCloud2`, `std_msgs/String`,
//! `tf2_msgs/TFMessage`), and the sweep's cloud layout.

use crate::sweep::Sweep;
use nalgebra::Isometry3;
use serde::{Serialize, Serializer};

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From a timestamp in µs (the stream's clock).
    pub fn from_us(us: u64) -> Self {
        Time { sec: (us / 1_000_000).min(i32::MAX as u64) as i32, nanosec: (us % 1_000_000) as u32 * 1000 }
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

/// `sensor_msgs/PointField` datatypes.
pub mod datatype {
    pub const UINT8: u8 = 2;
    pub const UINT16: u8 = 4;
    pub const UINT32: u8 = 6;
    pub const FLOAT32: u8 = 7;
}

/// A `uint8[]` written as one block (length, then the bytes), not element by element.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Bytes(pub Vec<u8>);

impl Serialize for Bytes {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(&self.0)
    }
}

/// `sensor_msgs/PointCloud2`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Bytes,
    pub is_dense: bool,
}

/// `std_msgs/String`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StringMsg {
    pub data: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

/// `geometry_msgs/Transform`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

/// The static transform `parent → child` (ROS: a point in `child` is `iso · p` in `parent`),
/// from an isometry in mm; ROS wants metres.
pub fn static_transform(parent: &str, child: &str, child_to_parent_mm: &Isometry3<f64>) -> TransformStamped {
    let t = child_to_parent_mm.translation.vector / 1000.0;
    let q = child_to_parent_mm.rotation;
    TransformStamped {
        header: Header { stamp: Time { sec: 0, nanosec: 0 }, frame_id: parent.into() },
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 { x: t.x, y: t.y, z: t.z },
            rotation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w },
        },
    }
}

/// The sweep cloud's fields: name, offset, datatype. x y z in metres (REP 103) and intensity
/// as float32; `t` (ns after the sweep's first frame) as Ouster's driver names it; `frame` the
/// trigger sequence number; `alpha` the mirror angle (°); `ring` the frame's index in the sweep
/// (each frame is one 360° ring, like a lidar's beam); `laser`. 32 bytes per point, aligned.
pub const CLOUD_FIELDS: [(&str, u32, u8); 9] = [
    ("x", 0, datatype::FLOAT32),
    ("y", 4, datatype::FLOAT32),
    ("z", 8, datatype::FLOAT32),
    ("intensity", 12, datatype::FLOAT32),
    ("t", 16, datatype::UINT32),
    ("frame", 20, datatype::UINT32),
    ("alpha", 24, datatype::FLOAT32),
    ("ring", 28, datatype::UINT16),
    ("laser", 30, datatype::UINT8),
];

/// Bytes per point of [`CLOUD_FIELDS`].
pub const POINT_STEP: u32 = 32;

/// The packed little-endian point data of a sweep (see [`CLOUD_FIELDS`]).
pub fn cloud_data(sweep: &Sweep) -> Vec<u8> {
    let mut data = Vec::with_capacity(sweep.points.len() * POINT_STEP as usize);
    for p in &sweep.points {
        for c in p.xyz_mm {
            data.extend_from_slice(&((c / 1000.0) as f32).to_le_bytes());
        }
        data.extend_from_slice(&p.intensity.to_le_bytes());
        data.extend_from_slice(&p.t_ns.to_le_bytes());
        data.extend_from_slice(&p.frame.to_le_bytes());
        data.extend_from_slice(&p.alpha_deg.to_le_bytes());
        data.extend_from_slice(&p.ring.to_le_bytes());
        data.push(p.laser);
        data.push(0);
    }
    data
}

/// The sweep as a PointCloud2 in `frame_id`, stamped with its first frame's time.
pub fn point_cloud2(sweep: &Sweep, frame_id: &str) -> PointCloud2 {
    let width = sweep.points.len() as u32;
    PointCloud2 {
        header: Header { stamp: Time::from_us(sweep.start_us), frame_id: frame_id.into() },
        height: 1,
        width,
        fields: CLOUD_FIELDS
            .iter()
            .map(|&(name, offset, datatype)| PointField { name: name.into(), offset, datatype, count: 1 })
            .collect(),
        is_bigendian: false,
        point_step: POINT_STEP,
        row_step: POINT_STEP * width,
        data: Bytes(cloud_data(sweep)),
        is_dense: true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::SweepPoint;

    #[test]
    fn a_point_is_packed_at_the_offsets_its_fields_name() {
        let p = SweepPoint {
            xyz_mm: [1000.0, -250.0, 12.5],
            intensity: 200.0,
            t_ns: 4_000_000,
            frame: 77,
            ring: 3,
            alpha_deg: 12.5,
            laser: 1,
        };
        let sweep = Sweep {
            revolution: 0,
            facet: 0,
            start_us: 1_500_000,
            end_us: 0,
            frames: 1,
            frames_missing: 0,
            complete: true,
            last_frame_path: None,
            points: vec![p],
        };
        let msg = point_cloud2(&sweep, "omniscan");
        assert_eq!((msg.header.stamp.sec, msg.header.stamp.nanosec), (1, 500_000_000));
        let d = &msg.data.0;
        assert_eq!(d.len(), POINT_STEP as usize);
        let f32_at = |o: usize| f32::from_le_bytes(d[o..o + 4].try_into().unwrap());
        let u32_at = |o: usize| u32::from_le_bytes(d[o..o + 4].try_into().unwrap());
        assert_eq!((f32_at(0), f32_at(4), f32_at(8), f32_at(12)), (1.0, -0.25, 0.0125, 200.0));
        assert_eq!((u32_at(16), u32_at(20), f32_at(24)), (4_000_000, 77, 12.5));
        assert_eq!((u16::from_le_bytes([d[28], d[29]]), d[30]), (3, 1));
    }
}
