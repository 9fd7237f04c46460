//! omni-live: measured frames in (the stream of `omni-ridge | omni-triangulate`), one point
//! cloud per sweep out, published as it happens.

use clap::Parser;
use omni_cli::{CliError, CliResult};
use omni_cloud::motion::Trajectory;
use omni_formats::stream::StreamReader;
use omni_publish::dds::{DdsOptions, DdsPublisher, MAX_DOMAIN_ID};
use omni_publish::foxglove::{FoxgloveOptions, FoxgloveSink};
use omni_publish::{DdsSink, FrameRetention, LiveOptions, Published, Sink};
use std::io::Write;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

const TOOL: &str = "omni-live";

#[derive(Parser, Debug)]
#[command(
    term_width = 0,
    version,
    about = "Publish every sweep as it is measured: ROS 2 PointCloud2 over DDS (no ROS install) and Foxglove, one line per sweep on stdout.",
    long_about = "Reads the measured stream (`omni-ridge | omni-triangulate`, JSON Lines; `-` = stdin) as it \
arrives, groups its frames into sweeps (one facet's pass of the lasers: every frame of one revolution and \
facet, a full 360° x 60° scan) and publishes each sweep as soon as its last frame has arrived. The number \
of frames per sweep comes from the header's `angles` (omni-trigger writes it) or --frames-per-sweep; \
without it a sweep ends when the next one begins. A sweep whose frames stop arriving is published after \
--sweep-timeout-ms, marked incomplete, never held.\n\n\
With --ros2: `PREFIX/points` (sensor_msgs/msg/PointCloud2 per sweep, sensor-data QoS: best effort, \
volatile, keep last 5) with fields x y z (m) intensity (float32) t (uint32, ns after the sweep's first \
frame, for deskewing) frame (uint32, trigger sequence number) alpha (float32, mirror angle, degrees) ring \
(uint16, the frame's index in the sweep) laser (uint8), stamped with the sweep's first frame; \
`PREFIX/calibration` (std_msgs/msg/String: {\"camera\": camera.json, \"scanner\": scanner.json}, reliable, \
transient-local, so a late subscriber gets it); `/tf_static` (tf2_msgs/msg/TFMessage: --base-frame → \
--frame-id from --extrinsics, transient-local). The DDS stack is RustDDS: no ROS library is needed at build \
or run time; subscribers need a receive buffer of a few MB for large clouds.\n\n\
With --foxglove [HOST:]PORT: a Foxglove WebSocket server (subprotocol foxglove.sdk.v1; bound to 127.0.0.1 \
unless a host is given) with `PREFIX/points` (foxglove.PointCloud, the same fields and bytes), `PREFIX/image` \
(foxglove.RawImage, the sweep's last laser frame, mono8/mono16), `PREFIX/calibration` (JSON) and `/tf` \
(foxglove.FrameTransforms, from --extrinsics), the last two with every sweep. Open Foxglove, connect to \
ws://HOST:PORT.\n\n\
A slow or stalled consumer never holds back the input: each output keeps at most --queue sweeps waiting \
and drops the oldest, counted in the status record; the Foxglove server also keeps at most --queue sweeps \
for each client and drops a slow client's oldest (its own count). The frames of a live capture (a stream whose header \
says \"live\": true, as `omni-trigger scan --until-stopped` writes) are deleted once their points have \
arrived (laser-off frames two revolutions later, when no frame can still need them), so that disk use stays \
flat over hours; --keep-frames keeps them. A recorded scan's frames are kept unless --delete-frames. With --poses, each point is moved to where the sensor was at the sweep's \
last frame (deskewed by its own time); without, points are published as measured, with `t` for the \
robot's own deskewing.\n\n\
stdout: one JSON line per sweep and output ({\"type\":\"sweep\",\"sink\",\"revolution\",\"facet\",\"frames\",\
\"points\",\"complete\",\"latency_ms\",\"published_unix_us\"}, latency from the arrival of the sweep's last frame to the end of its \
publication), and a last status line (frames, sweeps, sweeps_incomplete, sweeps_dropped per output, \
frames_deleted). SIGINT or SIGTERM ends the run cleanly: the open sweep is published, the status written.",
    after_help = "Examples:\n  \
omni-trigger scan --port /dev/ttyACM0 --frames /dev/shm/frames --angles 0:30:0.5 --until-stopped | omni-ridge --camera camera.json | omni-triangulate --camera camera.json --scanner scanner.json | omni-live --ros2 --camera camera.json --scanner scanner.json --extrinsics base_link.json\n  \
omni-live --ros2 --domain-id 7 --prefix /robot1/omniscan --dds-interface 127.0.0.1 points.jsonl\n  \
omni-live --ros2 --poses odometry.jsonl points.jsonl\n  \
omni-live --foxglove 8765 --camera camera.json --scanner scanner.json points.jsonl\n\n\
Exit codes: 0 ok (also after SIGINT/SIGTERM), 1 bad input, a file or an output that cannot be set up, 2 usage error."
)]
struct Args {
    /// The measured stream (JSON Lines from omni-triangulate); `-` = stdin.
    #[arg(default_value = "-")]
    input: PathBuf,
    /// Publish to ROS 2 over DDS.
    #[arg(long)]
    ros2: bool,
    /// Serve Foxglove on [HOST:]PORT (host default 127.0.0.1; port 0 = any free one, printed on stderr).
    #[arg(long, value_name = "[HOST:]PORT")]
    foxglove: Option<String>,
    /// ROS 2 domain id (0-232); default: $ROS_DOMAIN_ID, else 0.
    #[arg(long)]
    domain_id: Option<u32>,
    /// Namespace of the topics.
    #[arg(long, default_value = "/omniscan")]
    prefix: String,
    /// Local address DDS may use (repeatable), e.g. 127.0.0.1 to stay on this machine; default: every interface.
    #[arg(long, value_name = "ADDR")]
    dds_interface: Vec<IpAddr>,
    /// The sensor's frame id (the clouds' header.frame_id, the static transform's child).
    #[arg(long, default_value = "omniscan")]
    frame_id: String,
    /// The robot's frame, parent of the static transform.
    #[arg(long, default_value = "base_link")]
    base_frame: String,
    /// Where the sensor sits on the robot: transform.json (omniscan.transform: rotation row by row, translation_mm) mapping sensor coordinates into --base-frame.
    #[arg(long, value_name = "TRANSFORM_JSON")]
    extrinsics: Option<PathBuf>,
    /// Receiver model, published on PREFIX/calibration.
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Transmitter model, published on PREFIX/calibration.
    #[arg(long)]
    scanner: Option<PathBuf>,
    /// Odometry (omniscan.odometry JSON Lines): deskew every point to the sweep's last frame.
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Longest odometry gap (ms) that may be interpolated across.
    #[arg(long, default_value_t = 100.0)]
    max_pose_gap_ms: f64,
    /// Frames per sweep (trigger angles per facet); default: from the header's `angles`.
    #[arg(long)]
    frames_per_sweep: Option<u32>,
    /// Publish a sweep incomplete when no frame has arrived for this long (ms).
    #[arg(long, default_value_t = 500)]
    sweep_timeout_ms: u64,
    /// Sweeps waiting per output before the oldest is dropped.
    #[arg(long, default_value_t = 2)]
    queue: usize,
    /// Keep every frame's image file, also from a live capture.
    #[arg(long, conflicts_with = "delete_frames")]
    keep_frames: bool,
    /// Delete each frame's image file once its points have arrived, also from a recorded scan.
    #[arg(long)]
    delete_frames: bool,
}

fn main() -> std::process::ExitCode {
    omni_cli::main(TOOL, || run(omni_cli::parse_args()?))
}

fn run(a: Args) -> CliResult {
    let stop = omni_cli::stop_on_interrupt().map_err(|e| CliError::new(format!("signal handler: {e}")))?;
    let deskew = match &a.poses {
        Some(p) => {
            let samples = omni_formats::odometry::read_odometry(p)?;
            Some(
                Trajectory::new(&samples, (a.max_pose_gap_ms * 1000.0).max(0.0) as u64)
                    .map_err(|m| CliError::new(format!("{}: {m}", p.display())))?,
            )
        }
        None => None,
    };
    // Files first, read once for every output: a bad file is reported before the network is
    // touched.
    let calibration = calibration_json(a.camera.as_deref(), a.scanner.as_deref())?;
    let placement = a.extrinsics.as_deref().map(extrinsics).transpose()?;
    let mut sinks: Vec<Box<dyn Sink>> = Vec::new();
    if a.ros2 {
        sinks.push(Box::new(ros2_sink(&a, calibration.clone(), placement)?));
    }
    if let Some(addr) = &a.foxglove {
        sinks.push(Box::new(foxglove_sink(&a, addr, calibration, placement)?));
    }
    if sinks.is_empty() {
        omni_cli::warn(TOOL, "neither --ros2 nor --foxglove: nothing is published, the sweeps are only counted");
    }
    let input = StreamReader::open(&a.input)?;
    let out = Arc::new(Mutex::new(std::io::stdout()));
    let (out2, stop2) = (out.clone(), stop.clone());
    let report = Arc::new(move |p: Published| {
        let mut o = out2.lock().unwrap_or_else(|e| e.into_inner());
        // A closed stdout (`| head`) ends the run, cleanly.
        if writeln!(o, "{}", p.to_json()).and_then(|_| o.flush()).is_err() {
            stop2.store(true, Ordering::Relaxed);
        }
    });
    let opts = LiveOptions {
        sweep_timeout: Duration::from_millis(a.sweep_timeout_ms.max(1)),
        queue: a.queue.max(1),
        frames_per_sweep: a.frames_per_sweep,
        frames: match (a.keep_frames, a.delete_frames) {
            (true, _) => FrameRetention::Keep,
            (_, true) => FrameRetention::Delete,
            _ => FrameRetention::AsStreamSays,
        },
    };
    let summary = omni_publish::live::run(input, sinks, report, &opts, deskew, stop).map_err(CliError::new)?;
    if summary.cut_short {
        omni_cli::warn(TOOL, "the input ended without its status record (cut short upstream)");
    }
    let mut o = out.lock().unwrap_or_else(|e| e.into_inner());
    let _ = writeln!(o, "{}", summary.to_json()).and_then(|_| o.flush());
    Ok(())
}

fn ros2_sink(a: &Args, calibration: Option<String>, tf: Option<nalgebra::Isometry3<f64>>) -> CliResult<DdsSink> {
    let domain = match a.domain_id {
        Some(d) => d,
        None => match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => {
                v.trim().parse().map_err(|_| CliError::new(format!("ROS_DOMAIN_ID={v:?} is not a number")))?
            }
            _ => 0,
        },
    };
    if domain > u32::from(MAX_DOMAIN_ID) {
        return Err(match a.domain_id {
            Some(_) => CliError::usage(format!("--domain-id {domain} is out of range 0..={MAX_DOMAIN_ID}")),
            None => CliError::new(format!("ROS_DOMAIN_ID={domain} is out of range 0..={MAX_DOMAIN_ID}")),
        });
    }
    let publisher = DdsPublisher::new(&DdsOptions {
        domain_id: domain as u16,
        prefix: a.prefix.clone(),
        interfaces: a.dds_interface.clone(),
    })
    .map_err(CliError::new)?;
    if let Some(json) = calibration {
        publisher.publish_calibration(json).map_err(CliError::new)?;
    }
    if let Some(iso) = tf {
        let t = omni_publish::msg::static_transform(&a.base_frame, &a.frame_id, &iso);
        publisher.publish_tf_static(vec![t]).map_err(CliError::new)?;
    }
    Ok(DdsSink { publisher, frame_id: a.frame_id.clone() })
}

fn foxglove_sink(
    a: &Args,
    addr: &str,
    calibration: Option<String>,
    extrinsics: Option<nalgebra::Isometry3<f64>>,
) -> CliResult<FoxgloveSink> {
    let (host, port) = match addr.rsplit_once(':') {
        Some((h, p)) => (h.trim_start_matches('[').trim_end_matches(']').to_string(), p),
        None => ("127.0.0.1".to_string(), addr),
    };
    let port: u16 =
        port.parse().map_err(|_| CliError::usage(format!("--foxglove {addr}: expected [HOST:]PORT, PORT 0-65535")))?;
    let sink = FoxgloveSink::start(FoxgloveOptions {
        host,
        port,
        prefix: a.prefix.clone(),
        frame_id: a.frame_id.clone(),
        base_frame: a.base_frame.clone(),
        extrinsics,
        calibration,
        backlog_sweeps: a.queue,
    })
    .map_err(CliError::new)?;
    eprintln!("{TOOL}: Foxglove server on port {} (subprotocol foxglove.sdk.v1)", sink.port());
    Ok(sink)
}

/// camera.json and scanner.json as one object, each checked by its own reader first.
fn calibration_json(camera: Option<&Path>, scanner: Option<&Path>) -> CliResult<Option<String>> {
    if camera.is_none() && scanner.is_none() {
        return Ok(None);
    }
    let mut obj = serde_json::Map::new();
    if let Some(p) = camera {
        omni_formats::CameraFile::load(p)?;
        obj.insert("camera".into(), read_json(p)?);
    }
    if let Some(p) = scanner {
        omni_formats::ScannerFile::load(p)?;
        obj.insert("scanner".into(), read_json(p)?);
    }
    Ok(Some(serde_json::Value::Object(obj).to_string()))
}

fn read_json(p: &Path) -> CliResult<serde_json::Value> {
    let text = std::fs::read_to_string(p).map_err(|e| CliError::new(format!("{}: {e}", p.display())))?;
    serde_json::from_str(&text).map_err(|e| CliError::new(format!("{}: {e}", p.display())))
}

/// The sensor's pose on the robot; a non-rotation or a non-finite number is named.
fn extrinsics(p: &Path) -> CliResult<nalgebra::Isometry3<f64>> {
    let file: omni_formats::transform::TransformFile = omni_formats::read_doc(p)?;
    file.isometry().map_err(|m| CliError::new(format!("{}: {m}", p.display())))
}
