//! Capture to stripe points, sustained (`make bench`): camera frames go through the
//! [`FrameWriter`] that `omni-trigger scan --camera` writes with, each written frame's record
//! goes down a pipe to the real `omni-ridge` binary as the scan's manifest does, and the frames
//! per second are counted from the first frame handed to the writer to the last frame's stripe
//! points coming out of omni-ridge. Writer and omni-ridge share the machine's cores.
//!
//! The frames are an omni-sim scan's (realistic stripe images), loaded into memory first and
//! replayed round-robin, each copied once per frame as a camera buffer is (`--pixel mono16`: the
//! 8-bit frames scaled to 16 bits). The camera delivers
//! as fast as the pipeline takes frames (the figure is the pipeline's sustained rate), or with
//! `--rate` at a fixed rate like a triggered camera: the run then also says how long a frame
//! waited to be taken at most, against what the camera's stream buffers hold, and how long from
//! delivery to stripe points.
//!
//! ```text
//! capture_pipeline --scan SCAN.jsonl --frames 600 --format pgm [--pixel mono16] [--sync]
//!                  [--ridge omni-ridge --camera camera.json] [--rate 200] [--target 200]
//! ```
//! Without `--ridge`, the capture alone is timed.

use omni_formats::stream::{Frame, Header, Record, Status, StreamReader, StreamWriter};
use omni_hw::frame_writer::{FrameFormat, FrameWriter, RawFrame};
use omni_hw::host_time_us;
use omni_hw::pairing::CapturedFrame;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

struct Options {
    scan: PathBuf,
    frames: u64,
    format: FrameFormat,
    bit_depth: u8,
    sync: bool,
    ridge: Option<PathBuf>,
    camera: Option<PathBuf>,
    target_fps: f64,
    /// Deliver frames at this rate, as a triggered camera does; `None`: as fast as taken.
    rate_hz: Option<f64>,
}

fn options() -> Result<Options, String> {
    let mut o = Options {
        scan: PathBuf::new(),
        frames: 600,
        format: FrameFormat::Pgm,
        bit_depth: 8,
        sync: false,
        ridge: None,
        camera: None,
        target_fps: 200.0,
        rate_hz: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        if flag == "--sync" {
            o.sync = true;
            continue;
        }
        let value = args.next().ok_or_else(|| format!("{flag} needs a value"))?;
        let number = |v: &str| v.parse::<f64>().map_err(|_| format!("{flag}: bad number {v:?}"));
        match flag.as_str() {
            "--scan" => o.scan = value.into(),
            "--frames" => o.frames = number(&value)? as u64,
            "--format" => o.format = FrameFormat::parse(&value)?,
            "--pixel" => {
                o.bit_depth = match value.to_ascii_lowercase().as_str() {
                    "mono8" => 8,
                    "mono16" => 16,
                    _ => return Err(format!("--pixel: Mono8 or Mono16, not {value:?}")),
                }
            }
            "--ridge" => o.ridge = Some(value.into()),
            "--camera" => o.camera = Some(value.into()),
            "--target" => o.target_fps = number(&value)?,
            "--rate" => o.rate_hz = Some(number(&value)?).filter(|hz| *hz > 0.0),
            _ => return Err(format!("unknown flag {flag}")),
        }
    }
    if o.scan.as_os_str().is_empty() || o.frames == 0 {
        return Err(
            "usage: capture_pipeline --scan SCAN.jsonl [--frames N] [--format pgm|png] [--pixel mono8|mono16] \
                    [--sync] [--ridge OMNI_RIDGE [--camera camera.json]] [--rate HZ] [--target FPS]"
                .into(),
        );
    }
    Ok(o)
}

/// The scan's header and its frames, each with its image as the camera would deliver it.
fn load_scan(path: &Path, bit_depth: u8) -> Result<(Header, Vec<(Frame, RawFrame)>), String> {
    let mut header = None;
    let mut frames = Vec::new();
    for record in StreamReader::open(path).map_err(|e| e.to_string())? {
        match record.map_err(|e| e.to_string())? {
            Record::Header(h) => header = Some(h),
            Record::Frame(f) => {
                let h: &Header = header.as_ref().ok_or("no header")?;
                let file = f.resolve_path(h.frames_dir.as_deref(), &f.path);
                let img = image::open(&file).map_err(|e| format!("{}: {e}", file.display()))?;
                let (width, height) = (img.width(), img.height());
                let data = if bit_depth == 16 {
                    img.to_luma16().into_raw().iter().flat_map(|s| s.to_le_bytes()).collect()
                } else {
                    img.to_luma8().into_raw()
                };
                frames.push((*f, RawFrame { width, height, bit_depth, data }));
            }
            _ => {}
        }
    }
    let header = header.ok_or("no header")?;
    if frames.is_empty() {
        return Err(format!("{}: no frames", path.display()));
    }
    Ok((header, frames))
}

/// What came out of omni-ridge: when each frame's record did, the stripe points in all, and
/// the CPU time spent reading it (the next tool's work, not the capture's).
struct RidgeOutput {
    out_at: Vec<Instant>,
    points: u64,
    read_cpu: f64,
}

fn read_ridge(out: impl std::io::Read) -> Result<RidgeOutput, String> {
    let mut r = RidgeOutput { out_at: Vec::new(), points: 0, read_cpu: 0.0 };
    let cpu0 = thread_cpu_seconds();
    for record in StreamReader::new(BufReader::new(out), "omni-ridge output") {
        match record.map_err(|e| e.to_string())? {
            Record::Frame(f) => {
                r.out_at.push(Instant::now());
                r.points += f.stripe.map_or(0, |s| s.len() as u64);
            }
            Record::Error(e) => return Err(format!("omni-ridge failed on frame {}: {}", e.seq, e.message)),
            _ => {}
        }
    }
    r.read_cpu = thread_cpu_seconds().zip(cpu0).map_or(0.0, |(b, a)| b - a);
    Ok(r)
}

/// omni-ridge as a child process, fed the capture's manifest records as frames are written.
struct Ridge {
    child: std::process::Child,
    reader: std::thread::JoinHandle<Result<RidgeOutput, String>>,
    stream: StreamWriter<std::process::ChildStdin>,
}

impl Ridge {
    fn start(bin: &Path, camera: Option<&Path>, header: Header) -> Result<Ridge, String> {
        let mut c = Command::new(bin);
        if let Some(cam) = camera {
            c.arg("--camera").arg(cam);
        }
        let mut child =
            c.stdin(Stdio::piped()).stdout(Stdio::piped()).spawn().map_err(|e| format!("{}: {e}", bin.display()))?;
        let out = child.stdout.take().expect("piped");
        let reader = std::thread::spawn(move || read_ridge(out));
        let mut stream = StreamWriter::new(child.stdin.take().expect("piped"), "omni-ridge input");
        stream.flush_each = true;
        stream.write(&Record::Header(header)).map_err(|e| e.to_string())?;
        Ok(Ridge { child, reader, stream })
    }

    /// The manifest records of frames just written (frame k shows source frame k mod n).
    fn hand_on(&mut self, done: Vec<CapturedFrame>, source: &[(Frame, RawFrame)]) -> Result<(), String> {
        for f in done {
            let k = f.trigger_seq.expect("set when submitted");
            let mut record = source[(k % source.len() as u64) as usize].0.clone();
            record.seq = k;
            record.path = f.name;
            // A camera capture has no laser-off frames (and these files are not there).
            record.ambient_path = None;
            self.stream.write(&Record::Frame(Box::new(record))).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Ends the stream and waits for every frame's points.
    fn finish(mut self, frames: u64) -> Result<RidgeOutput, String> {
        self.stream.write(&Record::Status(Status::complete(frames))).map_err(|e| e.to_string())?;
        drop(self.stream);
        let out = self.reader.join().map_err(|_| "omni-ridge reader panicked")??;
        let status = self.child.wait().map_err(|e| e.to_string())?;
        if !status.success() || out.out_at.len() as u64 != frames {
            return Err(format!("omni-ridge: {status}, {} of {frames} frames out", out.out_at.len()));
        }
        Ok(out)
    }
}

/// CPU seconds (user + system) of this process and of its waited-for children, from
/// `/proc/self/stat` (Linux; `None` elsewhere).
fn cpu_seconds() -> Option<(f64, f64)> {
    let f = proc_stat("/proc/self/stat")?;
    Some((f(14)? + f(15)?, f(16)? + f(17)?))
}

/// CPU seconds (user + system) of the calling thread.
fn thread_cpu_seconds() -> Option<f64> {
    let f = proc_stat("/proc/thread-self/stat")?;
    Some(f(14)? + f(15)?)
}

/// Field k (1-based, as `proc_pid_stat(5)` numbers them) of a stat file, in seconds for the
/// clock-tick fields (1/100 s: Linux's USER_HZ).
fn proc_stat(path: &str) -> Option<impl Fn(usize) -> Option<f64>> {
    let stat = std::fs::read_to_string(path).ok()?;
    // The fields after the command name in parentheses; the first of them, state, is field 3.
    let f: Vec<f64> = stat.rsplit_once(')')?.1.split_whitespace().map(|w| w.parse().unwrap_or(0.0)).collect();
    Some(move |k: usize| f.get(k - 3).map(|t| t / 100.0))
}

/// The 1-minute load average (other work sharing the cores shows here).
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg").ok()?.split_whitespace().next()?.parse().ok()
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// Stream buffers `omni-trigger scan --camera` gives the camera by default: how far capture may
/// fall behind a paced camera before frames are lost.
const CAMERA_BUFFERS: u32 = 16;

fn run(o: &Options) -> Result<(), String> {
    let (mut header, source) = load_scan(&o.scan, o.bit_depth)?;
    let (w, h) = (source[0].1.width, source[0].1.height);
    let dir = tempfile::Builder::new()
        .prefix("capture-bench-")
        .tempdir_in(std::env::temp_dir())
        .map_err(|e| e.to_string())?;
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get().clamp(1, 4));
    let mut writer = FrameWriter::new(dir.path(), o.format, threads, 16).map_err(|e| e.to_string())?;
    writer.sync_each_frame(o.sync);

    let mut ridge = match &o.ridge {
        Some(bin) => {
            header.frames_dir = Some(dir.path().display().to_string());
            Some(Ridge::start(bin, o.camera.as_deref(), header)?)
        }
        None => None,
    };
    // When each frame came off the camera (paced: its due time; else when it was taken), and how
    // long the capture kept a paced camera waiting at most.
    let mut delivered = Vec::with_capacity(o.frames as usize);
    let mut max_lag = Duration::ZERO;
    let load = load_average();
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    for k in 0..o.frames {
        let now = Instant::now();
        let due = o.rate_hz.map_or(now, |hz| t0 + Duration::from_secs_f64(k as f64 / hz));
        if due > now {
            std::thread::sleep(due - now);
        }
        max_lag = max_lag.max(Instant::now().saturating_duration_since(due));
        delivered.push(due);
        let image = source[(k % source.len() as u64) as usize].1.clone();
        let mut frame = CapturedFrame::new(PathBuf::new(), writer.file_name(&format!("{k:06}")), host_time_us());
        // Frame k answers trigger k.
        frame.trigger_seq = Some(k);
        writer.submit(frame, image).map_err(|e| e.to_string())?;
        let done = writer.written().map_err(|e| e.to_string())?;
        if let Some(r) = ridge.as_mut() {
            r.hand_on(done, &source)?;
        }
    }
    let done = writer.flush(Duration::from_secs(600)).map_err(|e| e.to_string())?;
    if let Some(r) = ridge.as_mut() {
        r.hand_on(done, &source)?;
    }
    let captured = t0.elapsed();

    let sync = if o.sync { ", each file synced" } else { "" };
    let bits = if o.bit_depth == 16 { "Mono16" } else { "Mono8" };
    let camera = match o.rate_hz {
        Some(hz) => format!("camera at {hz:.0} fps"),
        None => "camera as fast as taken".into(),
    };
    let what = format!("{w}x{h} {bits}, {camera} -> {} ({threads} writer threads{sync})", o.format.extension());
    let mut read_cpu = 0.0;
    let (fps, mut line) = match ridge {
        None => {
            let fps = o.frames as f64 / captured.as_secs_f64();
            (fps, format!("capture {what}: {} frames in {:.2} s = {fps:.0} frames/s", o.frames, captured.as_secs_f64()))
        }
        Some(r) => {
            let out = r.finish(o.frames)?;
            read_cpu = out.read_cpu;
            let (first, last) = (out.out_at[0], *out.out_at.last().expect("frames"));
            let total = last.duration_since(t0).as_secs_f64();
            // Paced, the rate the points came out at (a steady delay does not lower it, a
            // pipeline falling behind does); else all frames over all the time.
            let fps = match o.rate_hz {
                Some(_) => (o.frames - 1) as f64 / last.duration_since(first).as_secs_f64(),
                None => o.frames as f64 / total,
            };
            let mut line = format!(
                "capture {what} + omni-ridge: {} frames in {total:.2} s, {fps:.0} frames/s to stripe points ({:.0} \
                 points per frame)",
                o.frames,
                out.points as f64 / o.frames as f64,
            );
            if o.rate_hz.is_some() {
                let mut latency: Vec<f64> = out
                    .out_at
                    .iter()
                    .zip(&delivered)
                    .map(|(out, due)| out.duration_since(*due).as_secs_f64() * 1e3)
                    .collect();
                latency.sort_by(f64::total_cmp);
                line += &format!(
                    "; frame to points median {:.0} ms, 99 % {:.0} ms",
                    percentile(&latency, 0.5),
                    percentile(&latency, 0.99)
                );
            }
            (fps, line)
        }
    };
    // CPU time per frame: what 2 cores free of other work would sustain, however loaded this
    // machine was (the wall clock is what it did here). The capture's part is this process's
    // (frame writer, records to omni-ridge) without the thread reading omni-ridge's output.
    let mut cpu_fps = None;
    if let (Some((s0, c0)), Some((s1, c1))) = (cpu0, cpu_seconds()) {
        let per = |sec: f64| sec / o.frames as f64 * 1e3;
        let (mine, ridge) = (per(s1 - s0 - read_cpu), per(c1 - c0));
        let ridge_part = if o.ridge.is_some() { format!(", omni-ridge {ridge:.1}") } else { String::new() };
        cpu_fps = Some(2e3 / (mine + ridge));
        line += &format!(
            "; CPU {:.1} ms per frame (capture {mine:.1}{ridge_part}) = {:.0} frames/s on 2 free cores",
            mine + ridge,
            2e3 / (mine + ridge)
        );
    }
    let met_here = match o.rate_hz {
        // A paced camera is kept up with when no frame waited longer than its buffers hold.
        Some(hz) => {
            let holds = Duration::from_secs_f64(CAMERA_BUFFERS as f64 / hz);
            line += &format!(
                "; capture kept the camera waiting {:.1} ms at most (its {CAMERA_BUFFERS} buffers hold {:.0} ms)",
                max_lag.as_secs_f64() * 1e3,
                holds.as_secs_f64() * 1e3
            );
            max_lag < holds && fps >= 0.98 * hz
        }
        None => fps >= o.target_fps,
    };
    let verdict = match (met_here, cpu_fps) {
        (true, _) if o.rate_hz.is_some() => "kept up, no frame lost".to_string(),
        (true, _) => "target met".to_string(),
        (false, Some(c)) if c >= o.target_fps => {
            "target NOT met on this machine's wall clock (shared with other work), met on CPU time".to_string()
        }
        (false, _) => "target NOT met".to_string(),
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let load = load.map_or(String::new(), |l| format!(", load {l:.1} at the start"));
    println!("{line}; target >= {:.0} fps on 2 cores ({cores} here{load}): {verdict}", o.target_fps);
    Ok(())
}

fn main() -> std::process::ExitCode {
    match options().and_then(|o| run(&o)) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("capture_pipeline: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
