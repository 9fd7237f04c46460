//! The live loop: measured frames in, sweeps out to every sink, as they happen.
//!
//! A reader thread drains the input as fast as it comes, so that the upstream tools (and the
//! capture behind them) never wait on a pipe. Sweeps go to each sink through its own
//! [`DropOldest`] queue: a sink that falls behind loses its oldest sweeps, counted, and holds
//! back nothing else.

use crate::queue::DropOldest;
use crate::sweep::{Sweep, SweepAssembler};
use nalgebra::Point3;
use omni_cloud::motion::Trajectory;
use omni_formats::stream::{Frame, Record, Status, StreamReader, resolve_frame_path};
use serde_json::json;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{RecvTimeoutError, sync_channel};
use std::time::{Duration, Instant};

/// Something that takes finished sweeps: a ROS 2 publisher, a Foxglove server, a file.
pub trait Sink: Send {
    /// A short name for the status records (`dds`, `foxglove`).
    fn name(&self) -> &str;
    /// Whether it shows the sweep's last frame (its file is then read before it is deleted).
    fn wants_frame(&self) -> bool {
        false
    }
    /// Sends one sweep, with its last laser frame's file if [`Sink::wants_frame`]; an error is
    /// reported and the loop goes on.
    fn publish(&mut self, sweep: &Sweep, frame: Option<&FrameFile>) -> Result<(), String>;
}

/// An image file's bytes as read (decoding is the sink's, off the loop's thread).
#[derive(Debug, Clone)]
pub struct FrameFile {
    /// The path, for messages.
    pub name: String,
    pub bytes: Vec<u8>,
}

/// How the loop runs.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// A sweep with no new frame for this long is published incomplete.
    pub sweep_timeout: Duration,
    /// Sweeps waiting per sink before the oldest is dropped.
    pub queue: usize,
    /// Frames per sweep, if known (else the header's `angles` tells).
    pub frames_per_sweep: Option<u32>,
    /// Whether each frame's image file is deleted once its points have arrived.
    pub frames: FrameRetention,
}

/// What happens to the frames' image files once measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrameRetention {
    /// Deleted when the stream's header says it is a live capture (`"live": true`, written by
    /// `omni-trigger scan --until-stopped`), kept otherwise: a recorded scan replayed into the
    /// live stage must not lose its frames.
    #[default]
    AsStreamSays,
    Keep,
    Delete,
}

impl FrameRetention {
    fn deletes(self, header_says_live: bool) -> bool {
        match self {
            FrameRetention::AsStreamSays => header_says_live,
            FrameRetention::Keep => false,
            FrameRetention::Delete => true,
        }
    }
}

/// The header field that marks a live capture's frames as transient.
pub const LIVE_HEADER_FIELD: &str = "live";

/// A sweep on its way to the sinks, with the arrival time of its last frame.
pub struct Queued {
    pub sweep: Sweep,
    pub last_frame_at: Instant,
    /// Its last laser frame's file, if a sink wants it and it could be read.
    pub frame: Option<FrameFile>,
}

/// One line of the report: a sweep published (or failed) by a sink.
#[derive(Debug, Clone)]
pub struct Published {
    pub sink: String,
    pub revolution: u64,
    pub facet: u32,
    pub frames: u32,
    pub points: usize,
    pub complete: bool,
    /// From the arrival of the sweep's last frame to the end of its publication (ms).
    pub latency_ms: f64,
    /// When its publication ended (µs since the Unix epoch), to measure latency end to end.
    pub published_unix_us: u64,
    pub error: Option<String>,
}

impl Published {
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = json!({"type": "sweep", "sink": self.sink, "revolution": self.revolution, "facet": self.facet,
            "frames": self.frames, "points": self.points, "complete": self.complete,
            "latency_ms": (self.latency_ms * 1000.0).round() / 1000.0, "published_unix_us": self.published_unix_us});
        if let Some(e) = &self.error {
            v["error"] = e.clone().into();
        }
        v
    }
}

/// What the run did, for the final status record.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub frames: u64,
    pub sweeps: u64,
    pub sweeps_incomplete: u64,
    /// Per sink: sweeps dropped because it fell behind.
    pub dropped: BTreeMap<String, u64>,
    pub frames_deleted: u64,
    /// The input's own status record, if it ended with one.
    pub input_status: Option<Status>,
    /// The input stopped without its status record.
    pub cut_short: bool,
}

impl Summary {
    pub fn to_json(&self) -> serde_json::Value {
        json!({"type": "status", "frames": self.frames, "sweeps": self.sweeps,
            "sweeps_incomplete": self.sweeps_incomplete, "sweeps_dropped": self.dropped,
            "frames_deleted": self.frames_deleted, "input_complete": self.input_status.as_ref().map(|s| s.complete),
            "cut_short": self.cut_short})
    }
}

/// Runs until the input ends or `stop` is set: sweeps to `sinks`, a [`Published`] per sweep and
/// sink to `report` (called from the sinks' threads, in order per sink).
pub fn run<R: BufRead + Send + 'static>(
    input: StreamReader<R>,
    sinks: Vec<Box<dyn Sink>>,
    report: Arc<dyn Fn(Published) + Send + Sync>,
    opts: &LiveOptions,
    deskew: Option<Trajectory>,
    stop: Arc<AtomicBool>,
) -> Result<Summary, String> {
    let (tx, rx) = sync_channel::<Result<Record, String>>(1024);
    let reader = std::thread::spawn(move || read_records(input, tx));
    let queues: Vec<Arc<DropOldest<Arc<Queued>>>> =
        sinks.iter().map(|_| Arc::new(DropOldest::new(opts.queue))).collect();
    let names: Vec<String> = sinks.iter().map(|s| s.name().to_string()).collect();
    let read_frames = sinks.iter().any(|s| s.wants_frame());
    let workers: Vec<_> = sinks
        .into_iter()
        .zip(&queues)
        .map(|(sink, q)| {
            let (q, report) = (q.clone(), report.clone());
            std::thread::spawn(move || drain(sink, &q, &*report))
        })
        .collect();
    let mut summary = Summary::default();
    let mut assembler = SweepAssembler::new(opts.frames_per_sweep);
    let mut frames_dir: Option<String> = None;
    let mut deleter = FrameDeleter::default();
    let mut failure = None;
    let mut last_frame_at = Instant::now();
    let mut delete_frames = opts.frames.deletes(false);
    let emit = |sweep: Sweep, at: Instant, frames_dir: Option<&str>, summary: &mut Summary| {
        let mut sweep = sweep;
        if let Some(traj) = &deskew {
            deskew_to_end(&mut sweep, traj);
        }
        summary.sweeps += 1;
        summary.sweeps_incomplete += u64::from(!sweep.complete);
        let frame = match (&sweep.last_frame_path, read_frames) {
            (Some(path), true) => read_frame(frames_dir, path),
            _ => None,
        };
        let q = Arc::new(Queued { sweep, last_frame_at: at, frame });
        queues.iter().for_each(|queue| queue.push(q.clone()));
    };
    while !stop.load(Ordering::Relaxed) {
        match rx.recv_timeout(opts.sweep_timeout.min(Duration::from_millis(100))) {
            Ok(Ok(Record::Header(h))) => {
                frames_dir = h.frames_dir.clone();
                let live = h.extra.get(LIVE_HEADER_FIELD).and_then(|v| v.as_bool()).unwrap_or(false);
                delete_frames = opts.frames.deletes(live);
                if opts.frames_per_sweep.is_none() {
                    assembler = SweepAssembler::new(frames_per_sweep_of(&h));
                }
            }
            Ok(Ok(Record::Frame(frame))) => {
                last_frame_at = Instant::now();
                summary.frames += 1;
                for sweep in assembler.push(&frame) {
                    emit(sweep, last_frame_at, frames_dir.as_deref(), &mut summary);
                }
                if delete_frames {
                    summary.frames_deleted += deleter.frame_passed(&frame, frames_dir.as_deref());
                }
            }
            Ok(Ok(Record::Status(s))) => summary.input_status = Some(s),
            Ok(Ok(Record::Error(_))) => {}
            Ok(Err(e)) => {
                failure = Some(e);
                break;
            }
            Err(RecvTimeoutError::Timeout) => {
                if assembler.is_open() && last_frame_at.elapsed() >= opts.sweep_timeout {
                    emit(assembler.flush().expect("open"), last_frame_at, frames_dir.as_deref(), &mut summary);
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    if let Some(sweep) = assembler.flush() {
        emit(sweep, last_frame_at, frames_dir.as_deref(), &mut summary);
    }
    if delete_frames {
        summary.frames_deleted += deleter.finish();
    }
    queues.iter().for_each(|q| q.close());
    for w in workers {
        let _ = w.join();
    }
    for (name, q) in names.iter().zip(&queues) {
        summary.dropped.insert(name.clone(), q.dropped());
    }
    let stopped = stop.load(Ordering::Relaxed);
    summary.cut_short = summary.input_status.is_none() && failure.is_none() && !stopped;
    // The reader may still block on a read that never ends (SIGINT with a silent input).
    if reader.is_finished() {
        let _ = reader.join();
    }
    // The reader's errors name the input already.
    match failure {
        Some(e) => Err(e),
        None => Ok(summary),
    }
}

/// Trigger angles per facet from the header omni-trigger writes (`angles`: `0:30:0.5` or a
/// list), if present and readable.
pub fn frames_per_sweep_of(h: &omni_formats::stream::Header) -> Option<u32> {
    let spec = h.extra.get("angles")?.as_str()?;
    let n = omni_hw::schedule::AngleSpec::parse(spec).ok()?.degrees().len();
    u32::try_from(n).ok()
}

fn read_records<R: BufRead>(mut input: StreamReader<R>, tx: std::sync::mpsc::SyncSender<Result<Record, String>>) {
    loop {
        let item = match input.next_record() {
            // Points are what is published: a stream not yet triangulated has none to give.
            Ok(Some(Record::Frame(f))) if f.points.is_none() => Err(format!(
                "{}: line {} (frame {}): no `points` field (run omni-triangulate first)",
                input.name(),
                input.line(),
                f.seq
            )),
            Ok(Some(r)) => Ok(r),
            Ok(None) => return,
            Err(e) => Err(e.to_string()),
        };
        let fatal = item.is_err();
        if tx.send(item).is_err() || fatal {
            return;
        }
    }
}

/// The bytes of a frame file, or `None` if it is gone (a slow consumer upstream, or no file).
fn read_frame(frames_dir: Option<&str>, path: &str) -> Option<FrameFile> {
    let full = resolve_frame_path(frames_dir, path);
    let bytes = std::fs::read(&full).ok()?;
    Some(FrameFile { name: full.display().to_string(), bytes })
}

fn drain(mut sink: Box<dyn Sink>, queue: &DropOldest<Arc<Queued>>, report: &(dyn Fn(Published) + Send + Sync)) {
    while let Some(q) = queue.pop() {
        let result = sink.publish(&q.sweep, q.frame.as_ref());
        let s = &q.sweep;
        report(Published {
            sink: sink.name().to_string(),
            revolution: s.revolution,
            facet: s.facet,
            frames: s.frames,
            points: s.points.len(),
            complete: s.complete,
            latency_ms: q.last_frame_at.elapsed().as_secs_f64() * 1000.0,
            published_unix_us: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_micros() as u64),
            error: result.err(),
        });
    }
}

/// Moves every point to where the sensor was at the sweep's last frame: the point was measured
/// at its frame's time, when the sensor stood at `pose(t)`; in the end pose's frame it lies at
/// `pose(end)⁻¹ · pose(t) · p`. Points whose time the odometry does not cover stay as they are.
pub fn deskew_to_end(sweep: &mut Sweep, trajectory: &Trajectory) {
    let Ok(end) = trajectory.pose_at(sweep.end_us) else { return };
    let end_inv = end.inverse();
    let mut cache: Option<(u32, nalgebra::Isometry3<f64>)> = None;
    for p in &mut sweep.points {
        let to_end = match cache {
            Some((t, iso)) if t == p.t_ns => iso,
            _ => match trajectory.pose_at(sweep.start_us + u64::from(p.t_ns) / 1000) {
                Ok(pose) => {
                    let iso = end_inv * pose;
                    cache = Some((p.t_ns, iso));
                    iso
                }
                Err(_) => continue,
            },
        };
        let q = to_end * Point3::from(p.xyz_mm);
        p.xyz_mm = [q.x, q.y, q.z];
    }
}

/// Deletes frame files once measured. A laser frame goes when the next frame's points arrive
/// (the sweep it closes may show it as its last image); a laser-off frame is shared by the
/// laser frames of the next revolution (their `ambient_path`), so it goes once a frame two
/// revolutions later arrives.
#[derive(Default)]
struct FrameDeleter {
    /// Laser-off frames waiting: (revolution, path).
    ambient: Vec<(u64, PathBuf)>,
    /// The latest laser frame.
    latest: Option<PathBuf>,
}

impl FrameDeleter {
    fn frame_passed(&mut self, frame: &Frame, frames_dir: Option<&str>) -> u64 {
        let mut deleted = 0;
        if let Some(previous) = self.latest.take() {
            deleted += u64::from(std::fs::remove_file(&previous).is_ok());
        }
        let path = resolve_frame_path(frames_dir, &frame.path);
        if frame.lasers.is_empty() {
            self.ambient.push((frame.revolution, path));
        } else {
            self.latest = Some(path);
        }
        let (done, keep): (Vec<_>, Vec<_>) =
            self.ambient.drain(..).partition(|(rev, _)| frame.revolution >= rev.saturating_add(2));
        self.ambient = keep;
        deleted + done.iter().filter(|(_, p)| std::fs::remove_file(p).is_ok()).count() as u64
    }

    fn finish(&mut self) -> u64 {
        self.ambient
            .drain(..)
            .map(|(_, p)| p)
            .chain(self.latest.take())
            .filter(|p| std::fs::remove_file(p).is_ok())
            .count() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::SweepPoint;
    use omni_formats::odometry::PoseSample;

    fn point(x: f64, t_ns: u32) -> SweepPoint {
        SweepPoint { xyz_mm: [x, 0.0, 0.0], intensity: 0.0, t_ns, frame: 0, ring: 0, alpha_deg: 0.0, laser: 0 }
    }

    #[test]
    fn deskewing_moves_each_point_to_the_sensor_pose_at_the_sweeps_end() {
        // The sensor drives along +x at 1 mm/ms and turns 90° about z over the 10 ms.
        let pose = |t_ms: u64| PoseSample {
            t_us: 1_000_000 + t_ms * 1000,
            translation_mm: [t_ms as f64, 0.0, 0.0],
            quaternion_wxyz: {
                let a = (t_ms as f64 / 10.0) * std::f64::consts::FRAC_PI_4;
                [a.cos(), 0.0, 0.0, a.sin()]
            },
        };
        let traj = Trajectory::new(&(0..=10).map(pose).collect::<Vec<_>>(), 5_000).unwrap();
        let mut sweep = Sweep {
            revolution: 0,
            facet: 0,
            start_us: 1_000_000,
            end_us: 1_010_000,
            frames: 2,
            frames_missing: 0,
            complete: true,
            last_frame_path: None,
            points: vec![point(100.0, 0), point(100.0, 10_000_000)],
        };
        deskew_to_end(&mut sweep, &traj);
        // The point taken at the start is world (100, 0, 0); seen from the end pose (at x = 10 mm,
        // turned 90° about z) it is end⁻¹ · world.
        let world_first = nalgebra::Vector3::new(100.0, 0.0, 0.0);
        let end_rot =
            nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let expected = end_rot.inverse() * (world_first - nalgebra::Vector3::new(10.0, 0.0, 0.0));
        for (got, want) in sweep.points[0].xyz_mm.iter().zip(expected.iter()) {
            assert!((got - want).abs() < 1e-9, "{:?} vs {expected:?}", sweep.points[0].xyz_mm);
        }
        // The point taken at the end pose is unchanged.
        assert_eq!(sweep.points[1].xyz_mm, [100.0, 0.0, 0.0]);
    }
}
