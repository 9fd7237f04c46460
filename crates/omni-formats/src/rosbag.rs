//! ROS 2 bags without a ROS install: a rosbag2 directory holding one MCAP file (the `ros2`
//! profile, through the `mcap` crate) and `metadata.yaml`, with `sensor_msgs/msg/PointCloud2`
//! messages in CDR (little-endian) on one topic.
//!
//! Each message is a slice of a [`PointCloud`]: `x y z` in metres (REP 103; float32, or float64
//! with `--double`) followed by the scalar fields in their types, packed, `height` 1. The schema
//! is the `ros2msg` text of PointCloud2 with every type it uses (Header, Time, PointField), so
//! readers that have no ROS message definitions (Foxglove, mcap-ros2-support) decode it. The
//! MCAP has message and chunk indexes and statistics (Jazzy's reader needs the indexes), and the
//! channel and `metadata.yaml` carry the offered QoS profile (reliable, volatile).

use crate::export::{CloudOptions, Units};
use crate::ply::{PointCloud, ScalarType};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

/// The message type and its `ros2msg` schema: PointCloud2, then each dependency after a line of
/// 80 `=` and `MSG: package/Type`, as rosbag2 and Foxglove write them.
pub const POINTCLOUD2_TYPE: &str = "sensor_msgs/msg/PointCloud2";
const POINTCLOUD2_SCHEMA: &str = "\
std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: sensor_msgs/PointField
uint8 INT8=1
uint8 UINT8=2
uint8 INT16=3
uint8 UINT16=4
uint8 INT32=5
uint8 UINT32=6
uint8 FLOAT32=7
uint8 FLOAT64=8
string name
uint32 offset
uint8 datatype
uint32 count
";

/// The QoS profile the topic is offered with (rosbag2's YAML: history keep-last-unknown, reliable,
/// volatile, no deadline, lifespan or lease limits), as `ros2 bag record` writes it.
const OFFERED_QOS: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false";

/// Where and how the bag is written.
#[derive(Debug, Clone, PartialEq)]
pub struct BagOptions {
    pub topic: String,
    /// The `header.frame_id` of every message.
    pub frame_id: String,
    /// MCAP chunk size target (bytes); a larger message gets a chunk of its own.
    pub chunk_size: u64,
    /// Coordinates as float64 instead of float32 (they are metres whatever the cloud's unit).
    pub double: bool,
}

impl Default for BagOptions {
    fn default() -> Self {
        BagOptions { topic: "/omniscan/points".into(), frame_id: "omniscan".into(), chunk_size: 1 << 20, double: false }
    }
}

/// One message: the points `points` of the cloud, stamped `stamp_ns` (ns).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagMessage {
    pub stamp_ns: u64,
    pub points: Range<usize>,
}

/// PointField datatype codes (sensor_msgs/PointField).
fn point_field_type(ty: ScalarType) -> u8 {
    match ty {
        ScalarType::I8 => 1,
        ScalarType::U8 => 2,
        ScalarType::I16 => 3,
        ScalarType::U16 => 4,
        ScalarType::I32 => 5,
        ScalarType::U32 => 6,
        ScalarType::F32 => 7,
        ScalarType::F64 => 8,
    }
}

/// ROS's field name for one of ours (normals as PCL names them).
fn ros_field_name(name: &str) -> &str {
    match name {
        "nx" => "normal_x",
        "ny" => "normal_y",
        "nz" => "normal_z",
        other => other,
    }
}

/// CDR (XCDR1, little-endian) serialisation: each primitive aligned to its size, counted from
/// the end of the 4-byte encapsulation header.
struct Cdr {
    buf: Vec<u8>,
}

impl Cdr {
    fn new(capacity: usize) -> Self {
        let mut buf = Vec::with_capacity(capacity + 64);
        buf.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
        Cdr { buf }
    }
    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }
    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
}

/// The fields of every message: name, offset, type; and the point step (bytes).
fn message_fields(cloud: &PointCloud, coord: ScalarType) -> (Vec<(String, u32, ScalarType)>, usize) {
    let mut fields = Vec::new();
    let mut offset = 0;
    let names = ["x", "y", "z"].map(|a| (a, coord));
    for (name, ty) in names.into_iter().chain(cloud.scalars.iter().map(|s| (ros_field_name(&s.name), s.ty))) {
        fields.push((name.to_string(), offset as u32, ty));
        offset += ty.size();
    }
    (fields, offset)
}

/// One PointCloud2 message in CDR: the points `range` of `cloud`, in metres.
fn encode_pointcloud2(cloud: &PointCloud, range: Range<usize>, stamp_ns: u64, opts: &BagOptions) -> Vec<u8> {
    let coord = if opts.double { ScalarType::F64 } else { ScalarType::F32 };
    let (fields, step) = message_fields(cloud, coord);
    let n = range.len();
    let mut c = Cdr::new(n * step + 64 * fields.len() + opts.frame_id.len());
    c.i32((stamp_ns / 1_000_000_000) as i32);
    c.u32((stamp_ns % 1_000_000_000) as u32);
    c.string(&opts.frame_id);
    c.u32(1);
    c.u32(n as u32);
    c.u32(fields.len() as u32);
    for (name, offset, ty) in &fields {
        c.string(name);
        c.u32(*offset);
        c.u8(point_field_type(*ty));
        c.u32(1);
    }
    c.u8(0);
    c.u32(step as u32);
    c.u32((step * n) as u32);
    c.u32((step * n) as u32);
    let per_mm = Units::Metres.per_mm();
    for i in range {
        for v in cloud.positions[i] {
            coord.encode_le(v * per_mm, &mut c.buf);
        }
        for s in &cloud.scalars {
            s.ty.encode_le(s.values[i] as f64, &mut c.buf);
        }
    }
    c.u8(1);
    c.buf
}

/// Writes the rosbag2 directory `dir` (which must not exist yet): `<name>_0.mcap` and
/// `metadata.yaml`, built in a temporary sibling ([`crate::io::TempDir`]) and renamed into
/// place, so a failure or a signal leaves nothing (and a later run sweeps what a killed one
/// left). Messages must be in time order.
pub fn write_rosbag(dir: &Path, cloud: &PointCloud, messages: &[BagMessage], opts: &BagOptions) -> Result<()> {
    let name = dir.display().to_string();
    cloud
        .validate_for(&CloudOptions { double: opts.double, ..Default::default() })
        .map_err(|m| Error::new(&name, "", m))?;
    if let Some((i, m)) = messages.iter().enumerate().find(|(_, m)| m.points.end > cloud.len()) {
        return Err(Error::new(
            &name,
            format!("message {i}"),
            format!("points {:?} beyond the cloud's {}", m.points, cloud.len()),
        ));
    }
    if messages.windows(2).any(|w| w[1].stamp_ns < w[0].stamp_ns) {
        return Err(Error::new(&name, "", "messages are not in time order"));
    }
    if dir.exists() || dir.symlink_metadata().is_ok() {
        return Err(Error::new(
            &name,
            "",
            "already exists (a bag directory is never overwritten; remove it or choose another)",
        ));
    }
    let base = dir.file_name().map(|s| s.to_string_lossy().into_owned()).filter(|s| !s.is_empty() && s != "..");
    let base = base.ok_or_else(|| Error::new(&name, "", "is not a directory name"))?;
    // Dropped on an error (removed with what it holds); removed by the CLI's signal handler.
    let result = crate::io::TempDir::create(dir)
        .and_then(|tmp| write_bag_files(tmp.path(), &base, cloud, messages, opts).map(|_| tmp))
        .and_then(|tmp| tmp.commit());
    match result {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(Error::new(
            &name,
            "",
            "already exists (a bag directory is never overwritten; remove it or choose another)",
        )),
        Err(e) => Err(Error::io(name, &e)),
    }
}

fn write_bag_files(
    tmp: &Path,
    base: &str,
    cloud: &PointCloud,
    messages: &[BagMessage],
    opts: &BagOptions,
) -> std::io::Result<()> {
    let mcap_name = format!("{base}_0.mcap");
    let file = std::fs::File::create(tmp.join(&mcap_name))?;
    let mut out = std::io::BufWriter::with_capacity(1 << 16, file);
    let mcap_err = |e: mcap::McapError| std::io::Error::other(e.to_string());
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("omniscan ", env!("CARGO_PKG_VERSION")))
        .compression(None)
        .chunk_size(Some(opts.chunk_size))
        .emit_message_indexes(true)
        .emit_chunk_indexes(true)
        .emit_statistics(true)
        .create(&mut out)
        .map_err(mcap_err)?;
    let schema = writer.add_schema(POINTCLOUD2_TYPE, "ros2msg", POINTCLOUD2_SCHEMA.as_bytes()).map_err(mcap_err)?;
    let metadata = BTreeMap::from([("offered_qos_profiles".to_string(), OFFERED_QOS.to_string())]);
    let channel = writer.add_channel(schema, &opts.topic, "cdr", &metadata).map_err(mcap_err)?;
    for (seq, m) in messages.iter().enumerate() {
        let data = encode_pointcloud2(cloud, m.points.clone(), m.stamp_ns, opts);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: seq as u32,
            log_time: m.stamp_ns,
            publish_time: m.stamp_ns,
        };
        writer.write_to_known_channel(&header, &data).map_err(mcap_err)?;
    }
    writer.finish().map_err(mcap_err)?;
    drop(writer);
    use std::io::Write as _;
    out.flush()?;
    out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    let yaml = metadata_yaml(&mcap_name, messages, &opts.topic);
    std::fs::write(tmp.join("metadata.yaml"), yaml)?;
    Ok(())
}

/// rosbag2's `metadata.yaml` (version 5, read by Humble and later and by the `rosbags` package).
fn metadata_yaml(mcap_name: &str, messages: &[BagMessage], topic: &str) -> String {
    let start = messages.first().map_or(0, |m| m.stamp_ns);
    let duration = messages.last().map_or(0, |m| m.stamp_ns - start);
    let n = messages.len();
    let qos = OFFERED_QOS.replace('\n', "\\n");
    format!(
        "rosbag2_bagfile_information:
  version: 5
  storage_identifier: mcap
  duration:
    nanoseconds: {duration}
  starting_time:
    nanoseconds_since_epoch: {start}
  message_count: {n}
  topics_with_message_count:
    - topic_metadata:
        name: {topic}
        type: {POINTCLOUD2_TYPE}
        serialization_format: cdr
        offered_qos_profiles: \"{qos}\"
      message_count: {n}
  compression_format: \"\"
  compression_mode: \"\"
  relative_file_paths:
    - {mcap_name}
  files:
    - path: {mcap_name}
      starting_time:
        nanoseconds_since_epoch: {start}
      duration:
        nanoseconds: {duration}
      message_count: {n}
"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ply::ScalarField;

    fn cloud() -> PointCloud {
        PointCloud {
            positions: vec![[1000.0, -2000.0, 500.0], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
            scalars: vec![
                ScalarField::new("intensity", vec![10.0, 20.0, 30.0]),
                ScalarField { name: "red".into(), values: vec![1.0, 2.0, 3.0], ty: ScalarType::U8 },
            ],
        }
    }

    #[test]
    fn pointcloud2_cdr_layout_follows_the_alignment_rules() {
        let opts = BagOptions { frame_id: "ab".into(), ..Default::default() };
        let data = encode_pointcloud2(&cloud(), 0..2, 3_000_000_007, &opts);
        let u32_at = |o: usize| u32::from_le_bytes(data[o..o + 4].try_into().unwrap());
        assert_eq!(&data[..4], &[0, 1, 0, 0]);
        assert_eq!((u32_at(4), u32_at(8)), (3, 7));
        assert_eq!(u32_at(12), 3); // "ab\0"
        assert_eq!(&data[16..19], b"ab\0");
        // height at body offset 16 (after one byte of padding), width, 5 fields.
        assert_eq!((u32_at(20), u32_at(24), u32_at(28)), (1, 2, 5));
        // The last 2 × 17 data bytes then is_dense; the first point's x is 1 m.
        let step = 3 * 4 + 4 + 1;
        let points = &data[data.len() - 1 - 2 * step..data.len() - 1];
        assert_eq!(f32::from_le_bytes(points[0..4].try_into().unwrap()), 1.0);
        assert_eq!(f32::from_le_bytes(points[4..8].try_into().unwrap()), -2.0);
        assert_eq!(points[step - 1], 1);
        assert_eq!(points[2 * step - 1], 2);
        assert_eq!(*data.last().unwrap(), 1);
    }

    #[test]
    fn writes_the_bag_directory_and_refuses_an_existing_one() {
        let dir = tempfile::tempdir().unwrap();
        let bag = dir.path().join("bag");
        let msgs = vec![BagMessage { stamp_ns: 5, points: 0..1 }, BagMessage { stamp_ns: 9, points: 1..3 }];
        write_rosbag(&bag, &cloud(), &msgs, &BagOptions::default()).unwrap();
        let yaml = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
        assert!(yaml.contains("message_count: 2") && yaml.contains("- bag_0.mcap"), "{yaml}");
        let bytes = std::fs::read(bag.join("bag_0.mcap")).unwrap();
        let messages: Vec<_> =
            mcap::MessageStream::new(&bytes).unwrap().collect::<std::result::Result<_, _>>().unwrap();
        assert_eq!(messages.len(), 2);
        assert_eq!(messages[1].log_time, 9);
        assert_eq!(messages[0].channel.message_encoding, "cdr");
        assert_eq!(messages[0].data.as_ref(), encode_pointcloud2(&cloud(), 0..1, 5, &BagOptions::default()).as_slice());
        let e = write_rosbag(&bag, &cloud(), &msgs, &BagOptions::default()).unwrap_err().to_string();
        assert!(e.contains("already exists"), "{e}");
        let e = write_rosbag(
            &dir.path().join("b2"),
            &cloud(),
            &[BagMessage { stamp_ns: 0, points: 0..4 }],
            &BagOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("message 0"), "{e}");
        assert!(!dir.path().join("b2").exists());
    }
}
