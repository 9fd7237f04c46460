//! ROS 2 bags without a ROS install: a rosbag2 directory holding one MCAP file (the `ros2`
//! profile, through the `mcap` crate) and `metadata.yaml`, with `sensor_msgs/msg/PointCloud2`
//! messages in CDR (little-endian) on one topic and, optionally, the camera frames as
//! `sensor_msgs/msg/Image` (mono8/mono16) with a `sensor_msgs/msg/CameraInfo` beside each.
//!
//! Each point message is a slice of a [`PointCloud`]: `x y z` in metres (REP 103; float32, or
//! float64 with `--double`) followed by the scalar fields in their types, packed, `height` 1.
//! Every schema is the `ros2msg` text of its type with every type it uses (Header, Time,
//! PointField, RegionOfInterest), so readers that have no ROS message definitions (Foxglove,
//! mcap-ros2-support) decode it. Messages go in time order (at one stamp: image, camera info,
//! points). The MCAP has message and chunk indexes and statistics (Jazzy's reader needs the
//! indexes), and the channels and `metadata.yaml` carry the offered QoS profile (reliable,
//! volatile). [`camera_info`] says how each receiver model maps onto CameraInfo.

use crate::export::{CloudOptions, Units};
use crate::ply::{PointCloud, ScalarType};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

/// The Header and Time dependencies of a schema, as rosbag2 writes them.
macro_rules! header_schema {
    () => {
        "================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"
    };
}

/// The message type and its `ros2msg` schema: PointCloud2, then each dependency after a line of
/// 80 `=` and `MSG: package/Type`, as rosbag2 and Foxglove write them.
pub const POINTCLOUD2_TYPE: &str = "sensor_msgs/msg/PointCloud2";
const POINTCLOUD2_SCHEMA: &str = concat!(
    "std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
",
    header_schema!(),
    "================================================================================
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
"
);

pub const IMAGE_TYPE: &str = "sensor_msgs/msg/Image";
const IMAGE_SCHEMA: &str = concat!(
    "std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data
",
    header_schema!()
);

pub const CAMERA_INFO_TYPE: &str = "sensor_msgs/msg/CameraInfo";
const CAMERA_INFO_SCHEMA: &str = concat!(
    "std_msgs/Header header
uint32 height
uint32 width
string distortion_model
float64[] d
float64[9] k
float64[9] r
float64[12] p
uint32 binning_x
uint32 binning_y
RegionOfInterest roi
",
    header_schema!(),
    "================================================================================
MSG: sensor_msgs/RegionOfInterest
uint32 x_offset
uint32 y_offset
uint32 height
uint32 width
bool do_rectify
"
);

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

/// One camera frame for a `sensor_msgs/msg/Image`: grey samples row by row from the top-left
/// pixel, 8-bit (`mono8`) or 16-bit (`mono16`, written little-endian).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagImage {
    pub width: u32,
    pub height: u32,
    /// 8 or 16.
    pub bit_depth: u8,
    pub samples: Vec<u16>,
}

/// A `sensor_msgs/msg/CameraInfo`: image size, distortion model name and coefficients `d`,
/// intrinsic matrix `k` (px, row-major), rectification `r` and projection `p` (row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    pub width: u32,
    pub height: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
}

/// The CameraInfo of a receiver model. ROS has no omnidirectional model of its own, so each is
/// named after ours (documented in docs/FORMATS.md); `r` is the identity and `p` is `k` with a
/// zero fourth column.
/// * Mei: `distortion_model` `mei`, `d = [xi, k1, k2, p1, p2]` (ξ first, then OpenCV's
///   radial-tangential order, as cv2.omnidir takes `xi` and `D`), `k` from fx, fy, cx, cy.
/// * Hyperbolic: `omniscan_hyperbolic`, `d = [a, b, rim radius, inner radius (mm), camera
///   offset x, y, z (mm), camera tilt x, y (degrees)]`, `k` the pinhole behind the mirror.
/// * OCamCalib: `ocam`, `d = [c, d, e, a0, a1, …]` (the affine part, then the forward polynomial),
///   `k` holds only the centre (cx, cy; no focal length, the entries are 0).
/// * Pinhole: ROS's own `plumb_bob`, `d = [k1, k2, p1, p2, k3]`.
/// * Fisheye (Kannala–Brandt): ROS's own `equidistant`, `d = [k1, k2, k3, k4]`.
pub fn camera_info(spec: &crate::CameraSpec) -> CameraInfo {
    use crate::CameraSpec;
    let k = |fx: f64, fy: f64, cx: f64, cy: f64| [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0];
    let (width, height, distortion_model, d, k) = match spec {
        CameraSpec::Mei(m) => {
            (m.width, m.height, "mei", vec![m.xi, m.k1, m.k2, m.p1, m.p2], k(m.fx_px, m.fy_px, m.cx_px, m.cy_px))
        }
        CameraSpec::Hyperbolic(h) => {
            let mut d = vec![h.a_mm, h.b_mm, h.rim_radius_mm, h.inner_radius_mm];
            d.extend(h.camera_offset_mm);
            d.extend(h.camera_tilt_deg);
            (h.width, h.height, "omniscan_hyperbolic", d, k(h.fx_px, h.fy_px, h.cx_px, h.cy_px))
        }
        CameraSpec::Ocam(o) => {
            let mut d = vec![o.c, o.d, o.e];
            d.extend(&o.poly);
            (o.width, o.height, "ocam", d, k(0.0, 0.0, o.cx_px, o.cy_px))
        }
        CameraSpec::Pinhole(c) => {
            let d = vec![c.k1, c.k2, c.p1, c.p2, c.k3];
            (c.width, c.height, "plumb_bob", d, k(c.fx_px, c.fy_px, c.cx_px, c.cy_px))
        }
        CameraSpec::Fisheye(c) => {
            let d = vec![c.k1, c.k2, c.k3, c.k4];
            (c.width, c.height, "equidistant", d, k(c.fx_px, c.fy_px, c.cx_px, c.cy_px))
        }
    };
    let mut p = [0.0; 12];
    for row in 0..3 {
        p[row * 4..row * 4 + 3].copy_from_slice(&k[row * 3..row * 3 + 3]);
    }
    let r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    CameraInfo { width, height, distortion_model: distortion_model.into(), d, k, r, p }
}

/// The camera frames of a bag: one Image per entry of `stamps_ns` (time order), loaded only when
/// written by `load(index)` (whose error names the file), each with `camera_info` if given.
pub struct BagImages<'a> {
    pub topic: String,
    /// Default: the image topic's namespace + `/camera_info` ([`camera_info_topic`]).
    pub info_topic: String,
    pub stamps_ns: Vec<u64>,
    pub load: &'a mut dyn FnMut(usize) -> Result<BagImage>,
    pub camera_info: Option<CameraInfo>,
}

/// The CameraInfo topic beside an image topic, as image_transport pairs them:
/// `/ns/image_raw` → `/ns/camera_info`.
pub fn camera_info_topic(image_topic: &str) -> String {
    match image_topic.rfind('/') {
        Some(k) => format!("{}/camera_info", &image_topic[..k]),
        None => "/camera_info".into(),
    }
}

/// One Image message in CDR.
fn encode_image(img: &BagImage, stamp_ns: u64, frame_id: &str) -> std::result::Result<Vec<u8>, String> {
    let n = img.width as usize * img.height as usize;
    if img.samples.len() != n {
        return Err(format!("{} samples for {}×{} pixels", img.samples.len(), img.width, img.height));
    }
    let (encoding, bytes) = match img.bit_depth {
        8 => ("mono8", 1),
        16 => ("mono16", 2),
        b => return Err(format!("bit depth {b} (mono8 or mono16 only)")),
    };
    let mut c = Cdr::new(n * bytes + 64 + frame_id.len());
    c.header(stamp_ns, frame_id);
    c.u32(img.height);
    c.u32(img.width);
    c.string(encoding);
    c.u8(0);
    c.u32(img.width * bytes as u32);
    c.u32((n * bytes) as u32);
    if bytes == 1 {
        c.buf.extend(img.samples.iter().map(|&v| v.min(255) as u8));
    } else {
        c.buf.extend(img.samples.iter().flat_map(|v| v.to_le_bytes()));
    }
    Ok(c.buf)
}

/// One CameraInfo message in CDR.
fn encode_camera_info(info: &CameraInfo, stamp_ns: u64, frame_id: &str) -> Vec<u8> {
    let mut c = Cdr::new(512 + frame_id.len());
    c.header(stamp_ns, frame_id);
    c.u32(info.height);
    c.u32(info.width);
    c.string(&info.distortion_model);
    c.u32(info.d.len() as u32);
    for v in info.d.iter().chain(&info.k).chain(&info.r).chain(&info.p) {
        c.f64(*v);
    }
    c.u32(1);
    c.u32(1);
    // roi: all zero = the whole image; do_rectify false.
    for _ in 0..4 {
        c.u32(0);
    }
    c.u8(0);
    c.buf
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
    fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    /// std_msgs/Header: stamp (ns since the epoch) and frame id.
    fn header(&mut self, stamp_ns: u64, frame_id: &str) {
        self.i32((stamp_ns / 1_000_000_000) as i32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame_id);
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
    c.header(stamp_ns, &opts.frame_id);
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
    write_rosbag_with_images(dir, cloud, messages, None, opts)
}

/// [`write_rosbag`] with the camera frames (and their CameraInfo) on topics of their own.
pub fn write_rosbag_with_images(
    dir: &Path,
    cloud: &PointCloud,
    messages: &[BagMessage],
    images: Option<&mut BagImages>,
    opts: &BagOptions,
) -> Result<()> {
    write_rosbag_staged(dir, cloud, messages, images, opts)?.commit()
}

/// [`write_rosbag_with_images`] up to the rename ([`crate::io::write_staged`]).
pub fn write_rosbag_staged(
    dir: &Path,
    cloud: &PointCloud,
    messages: &[BagMessage],
    images: Option<&mut BagImages>,
    opts: &BagOptions,
) -> Result<crate::io::Staged> {
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
    let in_order = |t: &mut dyn Iterator<Item = u64>| {
        let v: Vec<u64> = t.collect();
        v.windows(2).all(|w| w[0] <= w[1])
    };
    if !in_order(&mut messages.iter().map(|m| m.stamp_ns))
        || images.as_ref().is_some_and(|im| !in_order(&mut im.stamps_ns.iter().copied()))
    {
        return Err(Error::new(&name, "", "messages are not in time order"));
    }
    if let Some(im) = &images {
        let topics = [&opts.topic, &im.topic, &im.info_topic];
        if topics.iter().any(|t| !t.starts_with('/'))
            || topics[0] == topics[1]
            || topics[1] == topics[2]
            || topics[0] == topics[2]
        {
            return Err(Error::new(&name, "", format!("topics {topics:?} must be distinct and start with `/`")));
        }
    }
    if dir.exists() || dir.symlink_metadata().is_ok() {
        return Err(Error::new(&name, "", crate::io::DIRECTORY_EXISTS));
    }
    let base = dir.file_name().map(|s| s.to_string_lossy().into_owned()).filter(|s| !s.is_empty() && s != "..");
    let base = base.ok_or_else(|| Error::new(&name, "", "is not a directory name"))?;
    // Dropped on an error (removed with what it holds); removed by the CLI's signal handler.
    let tmp = crate::io::TempDir::create(dir).map_err(|e| Error::io(&name, &e))?;
    write_bag_files(tmp.path(), &base, cloud, messages, images, opts).map_err(|e| match e {
        BagFailure::Io(e) => Error::io(&name, &e),
        BagFailure::Input(e) => e,
    })?;
    Ok(crate::io::Staged::dir(name, tmp))
}

/// Why writing the bag's files stopped: the bag's own I/O, or an input (an image) at fault.
enum BagFailure {
    Io(std::io::Error),
    Input(Error),
}

impl From<std::io::Error> for BagFailure {
    fn from(e: std::io::Error) -> Self {
        BagFailure::Io(e)
    }
}

impl From<mcap::McapError> for BagFailure {
    fn from(e: mcap::McapError) -> Self {
        BagFailure::Io(std::io::Error::other(e.to_string()))
    }
}

/// A topic of the bag: name, type and message count (for metadata.yaml).
struct Topic {
    name: String,
    ty: &'static str,
    count: usize,
}

fn write_bag_files(
    tmp: &Path,
    base: &str,
    cloud: &PointCloud,
    messages: &[BagMessage],
    mut images: Option<&mut BagImages>,
    opts: &BagOptions,
) -> std::result::Result<(), BagFailure> {
    let mcap_name = format!("{base}_0.mcap");
    let file = std::fs::File::create(tmp.join(&mcap_name))?;
    let mut out = std::io::BufWriter::with_capacity(1 << 16, file);
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("omniscan ", env!("CARGO_PKG_VERSION")))
        .compression(None)
        .chunk_size(Some(opts.chunk_size))
        .emit_message_indexes(true)
        .emit_chunk_indexes(true)
        .emit_statistics(true)
        .create(&mut out)?;
    let metadata = BTreeMap::from([("offered_qos_profiles".to_string(), OFFERED_QOS.to_string())]);
    let mut add_topic = |name: &str, ty: &'static str, schema: &str| -> std::result::Result<u16, BagFailure> {
        let schema = writer.add_schema(ty, "ros2msg", schema.as_bytes())?;
        Ok(writer.add_channel(schema, name, "cdr", &metadata)?)
    };
    let points_channel = add_topic(&opts.topic, POINTCLOUD2_TYPE, POINTCLOUD2_SCHEMA)?;
    let mut topics = vec![Topic { name: opts.topic.clone(), ty: POINTCLOUD2_TYPE, count: messages.len() }];
    let image_channels = match images.as_deref() {
        Some(im) => {
            let image = add_topic(&im.topic, IMAGE_TYPE, IMAGE_SCHEMA)?;
            topics.push(Topic { name: im.topic.clone(), ty: IMAGE_TYPE, count: im.stamps_ns.len() });
            let info = match &im.camera_info {
                Some(_) => {
                    topics.push(Topic { name: im.info_topic.clone(), ty: CAMERA_INFO_TYPE, count: im.stamps_ns.len() });
                    Some(add_topic(&im.info_topic, CAMERA_INFO_TYPE, CAMERA_INFO_SCHEMA)?)
                }
                None => None,
            };
            Some((image, info))
        }
        None => None,
    };
    let mut sequences = BTreeMap::<u16, u32>::new();
    let mut put = |writer: &mut mcap::Writer<_>, channel: u16, stamp_ns: u64, data: &[u8]| {
        let seq = sequences.entry(channel).or_insert(0);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: *seq,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        *seq += 1;
        writer.write_to_known_channel(&header, data)
    };
    // Merge the two time-ordered lists; at one stamp the frame (image, info) comes first.
    let image_stamps: Vec<u64> = images.as_deref().map_or(Vec::new(), |im| im.stamps_ns.clone());
    let (mut i, mut j) = (0, 0);
    while i < messages.len() || j < image_stamps.len() {
        if j < image_stamps.len() && (i == messages.len() || image_stamps[j] <= messages[i].stamp_ns) {
            let (Some(im), Some((image_ch, info_ch))) = (images.as_deref_mut(), image_channels) else { break };
            let stamp = image_stamps[j];
            let img = (im.load)(j).map_err(BagFailure::Input)?;
            let data = encode_image(&img, stamp, &opts.frame_id)
                .map_err(|m| BagFailure::Input(Error::new(&im.topic, format!("image {j}"), m)))?;
            put(&mut writer, image_ch, stamp, &data)?;
            if let (Some(ch), Some(info)) = (info_ch, &im.camera_info) {
                put(&mut writer, ch, stamp, &encode_camera_info(info, stamp, &opts.frame_id))?;
            }
            j += 1;
        } else {
            let m = &messages[i];
            let data = encode_pointcloud2(cloud, m.points.clone(), m.stamp_ns, opts);
            put(&mut writer, points_channel, m.stamp_ns, &data)?;
            i += 1;
        }
    }
    writer.finish()?;
    drop(writer);
    use std::io::Write as _;
    out.flush()?;
    out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    let stamps: Vec<u64> = messages.iter().map(|m| m.stamp_ns).chain(image_stamps.iter().copied()).collect();
    let yaml = metadata_yaml(&mcap_name, &stamps, &topics);
    std::fs::write(tmp.join("metadata.yaml"), yaml)?;
    Ok(())
}

/// rosbag2's `metadata.yaml` (version 5, read by Humble and later and by the `rosbags` package)
/// for messages stamped `stamps` (ns) on `topics`.
fn metadata_yaml(mcap_name: &str, stamps: &[u64], topics: &[Topic]) -> String {
    let start = stamps.iter().copied().min().unwrap_or(0);
    let duration = stamps.iter().copied().max().unwrap_or(0) - start;
    let n: usize = topics.iter().map(|t| t.count).sum();
    let qos = OFFERED_QOS.replace('\n', "\\n");
    let mut topic_list = String::new();
    for t in topics {
        topic_list += &format!(
            "    - topic_metadata:
        name: {}
        type: {}
        serialization_format: cdr
        offered_qos_profiles: \"{qos}\"
      message_count: {}
",
            t.name, t.ty, t.count
        );
    }
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
{topic_list}  compression_format: \"\"
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

    #[test]
    fn image_and_camera_info_cdr_layouts() {
        let img = BagImage { width: 3, height: 2, bit_depth: 16, samples: vec![1, 2, 3, 256, 65535, 0] };
        let data = encode_image(&img, 7, "c").unwrap();
        let u32_at = |d: &[u8], o: usize| u32::from_le_bytes(d[o..o + 4].try_into().unwrap());
        // header (stamp 8, "c\0" 4+2, pad 2) → height at 20, width 24, "mono16\0" at 28.
        assert_eq!((u32_at(&data, 20), u32_at(&data, 24), u32_at(&data, 28)), (2, 3, 7));
        assert_eq!(&data[32..39], b"mono16\0");
        // is_bigendian at 39, then step 6 and 12 data bytes.
        assert_eq!((data[39], u32_at(&data, 40), u32_at(&data, 44)), (0, 6, 12));
        assert_eq!(&data[48..], &[1, 0, 2, 0, 3, 0, 0, 1, 255, 255, 0, 0]);
        let bad = BagImage { samples: vec![0; 5], ..img.clone() };
        assert!(encode_image(&bad, 0, "c").unwrap_err().contains("5 samples"));
        assert!(encode_image(&BagImage { bit_depth: 12, ..img }, 0, "c").unwrap_err().contains("bit depth"));

        let spec = crate::CameraSpec::Mei(omni_model::mei::MeiParams {
            xi: 0.9,
            fx_px: 200.0,
            fy_px: 201.0,
            cx_px: 100.0,
            cy_px: 99.0,
            k1: 0.1,
            k2: 0.2,
            p1: 0.3,
            p2: 0.4,
            width: 320,
            height: 240,
            inner_radius_px: 0.0,
            outer_radius_px: 0.0,
            viewpoint_mm: [0.0; 3],
        });
        let info = camera_info(&spec);
        assert_eq!((info.distortion_model.as_str(), info.d.as_slice()), ("mei", &[0.9, 0.1, 0.2, 0.3, 0.4][..]));
        assert_eq!(info.k, [200.0, 0.0, 100.0, 0.0, 201.0, 99.0, 0.0, 0.0, 1.0]);
        assert_eq!(info.p, [200.0, 0.0, 100.0, 0.0, 0.0, 201.0, 99.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let data = encode_camera_info(&info, 0, "c");
        // header as above → height 240 at 20, width at 24, "mei\0" at 28..36, 5 coefficients
        // at 36, then d[0] at 44 (body offset 36 → 40: 8-aligned from the body's start).
        assert_eq!((u32_at(&data, 20), u32_at(&data, 24), u32_at(&data, 36)), (240, 320, 5));
        assert_eq!(&data[32..36], b"mei\0");
        assert_eq!(f64::from_le_bytes(data[44..52].try_into().unwrap()), 0.9);
        // d 5 + k 9 + r 9 + p 12 doubles, binning 1 1, roi 4 × 0, do_rectify.
        assert_eq!(data.len(), 44 + 35 * 8 + 8 + 16 + 1);
        assert_eq!(camera_info_topic("/omniscan/image_raw"), "/omniscan/camera_info");
        assert_eq!(camera_info_topic("/image"), "/camera_info");
    }

    #[test]
    fn images_interleave_with_points_in_time_order_and_a_bad_image_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let msgs = vec![BagMessage { stamp_ns: 5, points: 0..1 }, BagMessage { stamp_ns: 9, points: 1..3 }];
        let frame = |v: u16| BagImage { width: 2, height: 1, bit_depth: 8, samples: vec![v, 200] };
        let mut load = |i: usize| Ok(frame(i as u16));
        let mut images = BagImages {
            topic: "/o/image_raw".into(),
            info_topic: "/o/camera_info".into(),
            stamps_ns: vec![5, 7, 9],
            load: &mut load,
            camera_info: Some(CameraInfo {
                width: 2,
                height: 1,
                distortion_model: "mei".into(),
                d: vec![1.0],
                k: [0.0; 9],
                r: [0.0; 9],
                p: [0.0; 12],
            }),
        };
        let bag = dir.path().join("bag");
        write_rosbag_with_images(&bag, &cloud(), &msgs, Some(&mut images), &BagOptions::default()).unwrap();
        let bytes = std::fs::read(bag.join("bag_0.mcap")).unwrap();
        let order: Vec<(u64, String, u32)> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .map(|m| (m.log_time, m.channel.topic.clone(), m.sequence))
            .collect();
        let t = |s: u64, topic: &str, q: u32| (s, topic.to_string(), q);
        assert_eq!(
            order,
            [
                t(5, "/o/image_raw", 0),
                t(5, "/o/camera_info", 0),
                t(5, "/omniscan/points", 0),
                t(7, "/o/image_raw", 1),
                t(7, "/o/camera_info", 1),
                t(9, "/o/image_raw", 2),
                t(9, "/o/camera_info", 2),
                t(9, "/omniscan/points", 1),
            ]
        );
        let yaml = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
        assert!(yaml.contains("message_count: 8") && yaml.contains("name: /o/camera_info"), "{yaml}");

        let mut failing = |i: usize| if i == 1 { Err(Error::new("f1.png", "", "truncated")) } else { Ok(frame(0)) };
        images.load = &mut failing;
        let bag2 = dir.path().join("bag2");
        let e = write_rosbag_with_images(&bag2, &cloud(), &msgs, Some(&mut images), &BagOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("f1.png") && e.contains("truncated"), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "only the first bag is left");
    }
}
