//! `omni-trigger`: talk to the polygon-mirror trigger controller, capture a scan, or emulate one.

mod camera;
mod render;

use clap::{Args, Parser, Subcommand};
use omni_cli::{CliError, CliResult};
use omni_formats::stream::{Header, Record, StreamWriter};
use omni_hw::emulator::{BlankRenderer, EmulatorOptions, Faults, FrameRenderer, ServeEnd, VirtualCamera, serve};
use omni_hw::pairing::{DirFrameSource, FrameSource, PairEvent, PairOptions};
use omni_hw::scan::{ScanConfig, StopWhen, configure, expected_triggers, failed_status, run_scan};
use omni_hw::schedule::AngleSpec;
use omni_hw::{Client, ClientOptions, DeviceInfo};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

const TOOL: &str = "omni-trigger";

#[derive(Parser)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    name = "omni-trigger",
    version,
    about = "Talk to the polygon-mirror trigger controller: describe it, capture a scan manifest, or emulate one.",
    long_about = "Talk to the polygon-mirror trigger controller over a serial port (protocol: docs/PROTOCOL.md).\n\
        `scan` configures and runs the controller and pairs every trigger with the camera frame that \
        appears for it in the frames directory, writing the scan manifest (JSON Lines) as it goes. \
        `emulate` is a virtual controller + camera on a pseudo-terminal, for testing without hardware.",
    after_help = "Examples:\n  \
        omni-trigger info --port /dev/ttyACM0\n  \
        omni-trigger scan --port /dev/ttyACM0 --frames frames/ --angles 0:30:0.5 --revolutions 1 > scan.jsonl\n  \
        omni-trigger scan --port /dev/ttyACM0 --frames frames/ --angles 5,10,15 --facets 0,6 --laser-off | omni-ridge\n  \
        omni-trigger emulate --frames frames/ --width 256 > port.txt &  sleep 2\n  \
        omni-trigger scan --port \"$(head -1 port.txt)\" --frames frames/ --angles 0:30:2 --facets 0 > scan.jsonl"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    Info(InfoArgs),
    Scan(ScanArgs),
    Emulate(EmulateArgs),
    Cameras(camera::CamerasArgs),
}

#[derive(Args)]
struct PortArgs {
    /// Serial device of the controller, e.g. /dev/ttyACM0 (or the path `emulate` printed).
    #[arg(long)]
    port: String,
    /// Baud rate (ignored by USB CDC devices and pseudo-terminals).
    #[arg(long, default_value_t = 115_200, allow_negative_numbers = true)]
    baud: u32,
}

/// Handshake with the controller and print its description.
#[derive(Args)]
#[command(after_help = "Example:\n  omni-trigger info --port /dev/ttyACM0 --json")]
struct InfoArgs {
    #[command(flatten)]
    port: PortArgs,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Configure, arm and run the controller; pair triggers with frames; write the manifest.
#[derive(Args)]
#[command(after_help = "The manifest (omniscan.stream JSON Lines) starts with a header, has one frame record per \
    paired frame (seq = trigger sequence number, alpha_deg from the encoder count that fired, facet, revolution, \
    encoder, timestamp_us, lasers) written and flushed as it arrives, and ends with a status record (frames, \
    frames_missing, complete, errors) — also when the scan fails. A frame is paired only if its timestamp \
    (file modification time; see --latency-ms) falls in its trigger's window; otherwise it is reported, never shifted to a \
    neighbouring angle. A trigger event lost on the wire is placed from the trigger schedule (the sequence \
    number fixes its facet and angle, its time is interpolated) and its frame still pairs, marked \
    \"trigger_inferred\": true. With --laser-off, even revolutions fire with all lasers off and each laser frame's \
    ambient_path names the laser-off frame taken one revolution earlier at the same encoder count.\n\n\
    Examples:\n  \
    omni-trigger scan --port /dev/ttyACM0 --frames frames/ --angles 0:30:0.5 --revolutions 2 -o scan.jsonl\n  \
    omni-trigger scan --port /dev/ttyACM0 --frames frames/ --angles 2.5,15,27.5 --facets 0 --duration 10\n  \
    omni-trigger scan --port /dev/ttyACM0 --camera aravis:Basler-21234567 --trigger Line0 --pixel-format Mono8 --exposure-us 500 --frames frames/ -o scan.jsonl")]
struct ScanArgs {
    #[command(flatten)]
    port: PortArgs,
    /// Directory the camera software writes frames into (files already there are ignored);
    /// with --camera, the directory omni-trigger writes the camera's frames into.
    #[arg(long)]
    frames: PathBuf,
    #[command(flatten)]
    camera: camera::CameraArgs,
    /// Trigger angles within a facet in degrees: start:stop:step (stop excluded) or a list a,b,c.
    #[arg(long, default_value = "0:30:0.5", allow_hyphen_values = true)]
    angles: String,
    /// Facets that trigger: `all` or a list, e.g. 0,6.
    #[arg(long, default_value = "all", allow_hyphen_values = true)]
    facets: String,
    /// Lasers on in laser frames, e.g. 0 or 0,1 (default: all).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    lasers: Option<Vec<u32>>,
    /// Interleave laser-off (ambient) revolutions.
    #[arg(long)]
    laser_off: bool,
    /// Laser revolutions to scan.
    #[arg(long, conflicts_with = "duration", allow_negative_numbers = true)]
    revolutions: Option<u64>,
    /// Scan for this many seconds instead (then STOP).
    #[arg(long, allow_negative_numbers = true)]
    duration: Option<f64>,
    /// Scan until SIGINT or SIGTERM (then STOP), the planned end of a live scan: the status
    /// record is then complete, and the header says `"live": true`, so that omni-live deletes
    /// the frames once measured.
    #[arg(long, conflicts_with_all = ["duration", "revolutions"])]
    until_stopped: bool,
    /// Motor speed in rev/min (0 = the fastest the controller's trigger rate allows).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    rpm: f64,
    /// A trigger without a frame after this long is reported missing (ms).
    #[arg(long, default_value_t = 2000, allow_negative_numbers = true)]
    frame_timeout_ms: u64,
    /// Expected frame timestamp minus trigger time (ms): 0 if the camera stamps exposure time.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    latency_ms: f64,
    /// Missing frames (triggers without a frame) tolerated: more make the scan fail, with
    /// `complete: false` in the status record.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    max_missing: u64,
    /// Manifest output (`-` = stdout). Written as it goes, so a failed scan keeps what it got.
    #[arg(short, long, default_value = "-")]
    output: PathBuf,
}

/// A virtual controller + camera on a pseudo-terminal (prints the device path first).
#[derive(Args)]
#[command(after_help = "The first line on stdout is the pseudo-terminal to pass as --port. The emulator serves \
    until killed or until the host closes the port (--persist: keep serving). Each trigger the host configures \
    fires the virtual camera, which renders the frame through omni-simulator (or a blank image with \
    --camera-mode blank) into --frames; the trigger rate is limited to what the camera can render. \
    --truth writes which trigger and true angle each frame shows (JSON Lines).\n\n\
    Examples:\n  \
    omni-trigger emulate --frames frames/ --width 256 --scene scene.json\n  \
    omni-trigger emulate --frames frames/ --camera-mode blank --bad-crc 0.05 --drop-events 0.02 --disconnect-after 40")]
struct EmulateArgs {
    /// Directory the virtual camera writes frames into.
    #[arg(long)]
    frames: PathBuf,
    /// Receiver model (camera.json); default: the paper's camera scaled to --width.
    #[arg(long, requires = "scanner")]
    camera: Option<PathBuf>,
    /// Transmitter model (scanner.json); default: the paper's transmitter.
    #[arg(long, requires = "camera")]
    scanner: Option<PathBuf>,
    /// Scene to render (scene.json); default: the paper bench plane.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Image width = height of the default (paper) camera, px.
    #[arg(long, default_value_t = 1024, conflicts_with = "camera", allow_negative_numbers = true)]
    width: u32,
    /// `render` through omni-simulator, or `blank` (grey frames, for timing tests).
    #[arg(long, default_value = "render", value_parser = ["render", "blank"])]
    camera_mode: String,
    /// Trigger rate limit (Hz) announced to the host; default: measured render speed / 2.5
    /// (with --buffered-camera: 50 Hz).
    #[arg(long, allow_negative_numbers = true)]
    max_rate_hz: Option<f64>,
    /// Give the virtual camera a frame buffer: triggers queue up and every frame is rendered
    /// (stamped with its exposure time), so scans run at full trigger rate however slow the
    /// renderer is. Pair with `scan --frame-timeout-ms` long enough for the queue to drain.
    #[arg(long)]
    buffered_camera: bool,
    /// Render noise seed.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    seed: u64,
    /// Render with the idealised sensor (Gaussian blur σ 0.7 px, no speckle, a dim room) instead
    /// of the realistic one (the lens in camera.json's `optics`, laser speckle).
    #[arg(long)]
    ideal: bool,
    /// Write the ground truth of every frame (JSON Lines) here.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Keep serving after the host disconnects.
    #[arg(long)]
    persist: bool,
    /// Fault: probability of random garbage bytes before a line.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    garbage: f64,
    /// Fault: probability of a wrong checksum on a line.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    bad_crc: f64,
    /// Fault: probability that a trigger event is not sent.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    drop_events: f64,
    /// Fault: probability that a trigger event is sent twice.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    dup_events: f64,
    /// Fault: extra camera time per frame (ms), so it misses triggers.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    slow_camera_ms: u64,
    /// Fault: close the port after this many triggers (an unplugged cable).
    #[arg(long, allow_negative_numbers = true)]
    disconnect_after: Option<u64>,
    /// Fault: the motor stalls after this many triggers (the controller reports fault=stall; 0:
    /// before the first index, where nothing watches, and the run never ends).
    #[arg(long, allow_negative_numbers = true)]
    stall_after: Option<u64>,
    /// Seed of the fault generator.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    fault_seed: u64,
}

fn main() -> ExitCode {
    omni_cli::main(TOOL, || match omni_cli::parse_args::<Cli>()?.command {
        Cmd::Info(a) => info(a),
        Cmd::Scan(a) => scan(a),
        Cmd::Emulate(a) => emulate(a),
        Cmd::Cameras(a) => camera::cameras(a),
    })
}

fn open_client(p: &PortArgs) -> CliResult<Client<serialport::TTYPort>> {
    let port = serialport::new(&p.port, p.baud)
        .timeout(Duration::from_millis(20))
        .open_native()
        .map_err(|e| CliError::new(format!("{}: cannot open: {e}", p.port)))?;
    let _ = serialport::SerialPort::clear(&port, serialport::ClearBuffer::All);
    Ok(Client::new(port, ClientOptions::default()))
}

fn hello(client: &mut Client<serialport::TTYPort>, port: &str) -> CliResult<DeviceInfo> {
    client.hello().map_err(|e| CliError::new(format!("{port}: {e}")))
}

fn info(a: InfoArgs) -> CliResult {
    let mut client = open_client(&a.port)?;
    let i = hello(&mut client, &a.port.port)?;
    let status = client.status().map_err(|e| CliError::new(format!("{}: {e}", a.port.port)))?;
    let mut out = std::io::stdout().lock();
    if a.json {
        let v = serde_json::json!({
            "port": a.port.port, "protocol": i.protocol, "firmware": i.firmware,
            "counts_per_rev": i.counts_per_rev, "facets": i.facets, "lasers": i.lasers,
            "max_rate_hz": i.max_rate_hz, "state": status.state.as_str(),
            "fired": status.fired, "overruns": status.overruns, "crc_errors": status.crc_errors,
        });
        writeln!(out, "{v}")?;
    } else {
        writeln!(out, "port:             {}", a.port.port)?;
        writeln!(out, "protocol:         {}", i.protocol)?;
        writeln!(out, "firmware:         {}", i.firmware)?;
        writeln!(out, "encoder:          {} counts/rev ({}°/count)", i.counts_per_rev, i.degrees_per_count())?;
        writeln!(out, "facets:           {} ({}° of mirror angle each)", i.facets, 360.0 / i.facets as f64)?;
        writeln!(out, "lasers:           {}", i.lasers)?;
        writeln!(out, "max trigger rate: {} Hz", i.max_rate_hz)?;
        writeln!(
            out,
            "state:            {} (fired {}, overruns {}, crc errors {})",
            status.state.as_str(),
            status.fired,
            status.overruns,
            status.crc_errors
        )?;
    }
    Ok(())
}

fn scan_config(a: &ScanArgs) -> CliResult<ScanConfig> {
    let angles = AngleSpec::parse(&a.angles).map_err(CliError::usage)?;
    let facets = match a.facets.as_str() {
        "all" => None,
        list => Some(
            list.split(',')
                .map(|w| w.trim().parse::<u32>().map_err(|_| CliError::usage(format!("--facets: bad facet {w:?}"))))
                .collect::<CliResult<Vec<u32>>>()?,
        ),
    };
    let stop = match (a.revolutions, a.duration) {
        _ if a.until_stopped => StopWhen::UntilStopped,
        (_, Some(d)) if !(d > 0.0 && d.is_finite()) => return Err(CliError::usage("--duration must be positive")),
        (_, Some(d)) => StopWhen::Duration(Duration::from_secs_f64(d)),
        (Some(0), None) => return Err(CliError::usage("--revolutions must be at least 1")),
        (n, None) => StopWhen::Revolutions(n.unwrap_or(1)),
    };
    if !(a.rpm >= 0.0 && a.rpm.is_finite() && a.latency_ms.is_finite()) {
        return Err(CliError::usage("--rpm must be >= 0 and --latency-ms finite"));
    }
    let mut facets_sorted = facets.clone();
    if let Some(f) = facets_sorted.as_mut() {
        f.sort_unstable();
        f.dedup();
    }
    let mut lasers = a.lasers.clone();
    if let Some(l) = lasers.as_mut() {
        l.sort_unstable();
        l.dedup();
    }
    Ok(ScanConfig {
        angles,
        facets: facets_sorted,
        lasers,
        ambient: a.laser_off,
        rpm: a.rpm,
        stop,
        pairing: PairOptions {
            frame_timeout_us: a.frame_timeout_ms as i64 * 1000,
            latency_us: (a.latency_ms * 1000.0).round() as i64,
            ..PairOptions::default()
        },
        silence_timeout: Duration::from_millis(1500),
        // Ctrl-C (SIGINT) or SIGTERM: the scan stops the controller and still ends its manifest
        // with a status record.
        cancel: Some(omni_cli::stop_on_interrupt().map_err(|e| CliError::new(format!("signal handler: {e}")))?),
    })
}

fn open_output(path: &Path) -> CliResult<Box<dyn Write>> {
    if path == Path::new("-") {
        return Ok(Box::new(std::io::stdout()));
    }
    let f = std::fs::File::create(path).map_err(|e| CliError::new(format!("{}: {e}", path.display())))?;
    Ok(Box::new(std::io::BufWriter::new(f)))
}

fn scan(a: ScanArgs) -> CliResult {
    let cfg = scan_config(&a)?;
    // A camera is opened and set up first: any refusal is reported before the controller is
    // touched. A directory a camera writes into is made (if missing) only once the port is open.
    let camera = a.camera.open(&a.frames)?;
    let mut client = open_client(&a.port)?;
    let mut source: Box<dyn FrameSource> = match camera {
        Some(camera) => camera,
        None => {
            Box::new(DirFrameSource::new(&a.frames).map_err(|e| CliError::new(format!("{}: {e}", a.frames.display())))?)
        }
    };
    let info = hello(&mut client, &a.port.port)?;
    let out_name = omni_formats::io::display_name(&a.output, "stdout");
    let mut writer = StreamWriter::new(open_output(&a.output)?, out_name);
    let mut header = Header::new(&format!("{TOOL} {}", env!("CARGO_PKG_VERSION")));
    header.frames_dir = Some(omni_formats::stream::frames_dir_for_manifest(&a.output, &a.frames));
    header.extra.insert(
        "controller".into(),
        serde_json::json!({"port": a.port.port, "firmware": info.firmware, "protocol": info.protocol,
            "counts_per_rev": info.counts_per_rev, "facets": info.facets, "lasers": info.lasers}),
    );
    header.extra.insert("angles".into(), a.angles.clone().into());
    if a.until_stopped {
        // A live capture's frames are transient: the live stage deletes them once measured.
        header.extra.insert("live".into(), true.into());
    }
    if let Some(c) = a.camera.header() {
        header.extra.insert("genicam".into(), c);
    }
    writer.write(&Record::Header(header))?;

    let (schedule, rpm) = match configure(&mut client, &info, &cfg) {
        Ok(s) => s,
        Err(e) => {
            let msg = format!("{}: configuration failed: {e}", a.port.port);
            writer.write(&Record::Status(failed_status(&msg)))?;
            return Err(CliError::new(msg));
        }
    };
    let hint = match a.camera.camera {
        Some(_) => "can the camera keep up with the trigger rate? Its counters are in the status record".to_string(),
        None => format!(
            "is --frames {} the directory the camera writes to, and can the camera keep up?",
            a.frames.display()
        ),
    };
    let bar = omni_cli::progress(expected_triggers(&schedule, &cfg), "scan");
    let mut write_error = None;
    // Losses are warned about one by one up to this many; the status record counts them all.
    const MAX_WARNINGS: usize = 20;
    let mut warnings = 0;
    let mut missing = 0u64;
    let mut sink = |e: &PairEvent| -> Result<(), String> {
        // Each trigger ends paired or missing exactly once.
        if matches!(e, PairEvent::Paired(_) | PairEvent::FrameMissing { .. }) {
            bar.inc(1);
        }
        if matches!(e, PairEvent::FrameMissing { .. }) {
            missing += 1;
            // A scan until stopped has no end at which to find it failed: it stops at once,
            // instead of running on with the lasers firing for frames it never gets.
            if a.until_stopped && missing > a.max_missing {
                let frames =
                    if missing == 1 { "1 triggered frame".to_string() } else { format!("{missing} triggered frames") };
                return Err(format!("{frames} missing, more than --max-missing {} ({hint})", a.max_missing));
            }
        }
        match e {
            PairEvent::Paired(f) => writer.write(&Record::Frame(f.clone())).map_err(|e| {
                let m = e.to_string();
                write_error = Some(m.clone());
                m
            }),
            other => {
                warnings += 1;
                if let Some(m) = omni_hw::scan::describe(other).filter(|_| warnings <= MAX_WARNINGS) {
                    let m = if warnings == MAX_WARNINGS {
                        format!("{m} (further losses: see the status record)")
                    } else {
                        m
                    };
                    bar.suspend(|| omni_cli::warn(TOOL, &m));
                }
                Ok(())
            }
        }
    };
    let outcome = run_scan(&mut client, source.as_mut(), schedule, rpm, &cfg, &mut sink);
    bar.finish_and_clear();
    if let Some(e) = write_error {
        return Err(CliError::new(e));
    }
    let mut status = outcome.status.clone();
    let too_many_missing = status.frames_missing > a.max_missing;
    let missing_msg = format!(
        "{} of {} triggered frames missing, more than --max-missing {} ({hint})",
        status.frames_missing,
        status.frames + status.frames_missing,
        a.max_missing,
    );
    if too_many_missing {
        status.complete = false;
        status.errors.push(missing_msg.clone());
    }
    writer.write(&Record::Status(status.clone()))?;
    writer.flush()?;
    let s = &status;
    match outcome.error {
        Some(e) => Err(CliError::new(format!("{}: scan stopped after {} frames: {e}", a.port.port, s.frames))),
        None if too_many_missing => Err(CliError::new(format!("{}: {missing_msg}", a.port.port))),
        None => {
            if s.frames_missing > 0 || outcome.stats.frames_unmatched > 0 {
                omni_cli::warn(
                    TOOL,
                    &format!(
                        "{} frames paired, {} missing, {} unmatched frames (see the status record)",
                        s.frames, s.frames_missing, outcome.stats.frames_unmatched
                    ),
                );
            }
            Ok(())
        }
    }
}

/// The virtual camera's renderer, and the polygon's facets and lasers it implies.
fn renderer(a: &EmulateArgs) -> CliResult<(Box<dyn FrameRenderer>, u32, u32)> {
    if a.camera_mode == "blank" {
        let w = a.width.min(64);
        let spec = omni_hw::controller::ControllerSpec::default();
        return Ok((Box::new(BlankRenderer { width: w, height: w }), spec.facets, spec.lasers));
    }
    let (sensor, optics) = match (&a.camera, &a.scanner) {
        (Some(c), Some(s)) => omni_simulator::Sensor::load_with_optics(c, s)?,
        _ => {
            if !(16..=8192).contains(&a.width) {
                return Err(CliError::usage(format!("--width must be in 16..=8192, got {}", a.width)));
            }
            (omni_simulator::Sensor::paper_scaled(a.width), None)
        }
    };
    let scene = match &a.scene {
        Some(p) => omni_simulator::Scene::load(p)?,
        None => omni_simulator::Scene::from_file(omni_simulator::paper_bench(omni_simulator::BenchObject::Plane))
            .map_err(CliError::new)?,
    };
    let options = if a.ideal {
        omni_simulator::RenderOptions::ideal()
    } else {
        let realistic = omni_simulator::RenderOptions::default();
        match optics {
            Some(o) => realistic.with_optics(o),
            None => realistic,
        }
    };
    let options = omni_simulator::RenderOptions { seed: a.seed, ..options };
    options.check_sensor(&sensor).map_err(|e| {
        CliError::new(format!("{}: {e}", a.camera.as_ref().map_or("camera".into(), |c| c.display().to_string())))
    })?;
    let (facets, lasers) = (sensor.transmitter.num_facets(), sensor.transmitter.num_lasers() as u32);
    Ok((Box::new(render::SimRenderer { sensor, scene, options }), facets, lasers))
}

fn check_probability(name: &str, p: f64) -> CliResult {
    if (0.0..=1.0).contains(&p) { Ok(()) } else { Err(CliError::usage(format!("--{name} must be within 0..1"))) }
}

fn emulate(a: EmulateArgs) -> CliResult {
    for (name, p) in
        [("garbage", a.garbage), ("bad-crc", a.bad_crc), ("drop-events", a.drop_events), ("dup-events", a.dup_events)]
    {
        check_probability(name, p)?;
    }
    let (mut renderer, facets, lasers) = renderer(&a)?;
    let all_lasers: Vec<u32> = (0..lasers).collect();
    let max_rate_hz = match a.max_rate_hz {
        Some(r) if r > 0.0 && r.is_finite() => r,
        Some(_) => return Err(CliError::usage("--max-rate-hz must be positive")),
        None if a.buffered_camera => 50.0,
        None => {
            let secs = render::measure_frame_time(renderer.as_mut(), &all_lasers, facets)?;
            let rate = (1.0 / (2.5 * secs)).min(50.0);
            eprintln!(
                "{TOOL} emulate: a frame takes {:.1} ms to render; trigger rate limited to {rate:.2} Hz",
                secs * 1e3
            );
            rate
        }
    };
    let mut camera =
        VirtualCamera::start(&a.frames, renderer, Duration::from_millis(a.slow_camera_ms), a.truth.clone())
            .map_err(CliError::new)?;
    camera.set_buffered(a.buffered_camera);
    let (mut master, slave) =
        serialport::TTYPort::pair().map_err(|e| CliError::new(format!("cannot create a pseudo-terminal: {e}")))?;
    let path = serialport::SerialPort::name(&slave).ok_or_else(|| CliError::new("the pseudo-terminal has no name"))?;
    // The host opens the slave side itself; holding it here would hide the host's hang-up.
    drop(slave);
    serialport::SerialPort::set_timeout(&mut master, Duration::from_millis(2))?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "{path}")?;
        out.flush()?;
    }
    let mut options = EmulatorOptions::default();
    options.spec.max_rate_hz = max_rate_hz;
    options.spec.facets = facets;
    options.spec.lasers = lasers;
    // 0.01° per count for the usual 12 facets; any facet count divides the fallback.
    if !options.spec.counts_per_rev.is_multiple_of(facets) {
        options.spec.counts_per_rev = facets * 3000;
    }
    options.persist = a.persist;
    options.faults = Faults {
        garbage: a.garbage,
        bad_crc: a.bad_crc,
        drop_events: a.drop_events,
        duplicate_events: a.dup_events,
        disconnect_after: a.disconnect_after,
        stall_after: a.stall_after,
        seed: a.fault_seed,
    };
    let end = serve(&mut master, &options, &mut camera).map_err(|e| CliError::new(format!("{path}: {e}")))?;
    match end {
        ServeEnd::HostDisconnected => camera.finish(),
        ServeEnd::SimulatedDisconnect => {
            eprintln!("{TOOL} emulate: simulated disconnect after {} triggers", a.disconnect_after.unwrap_or(0));
            // The port goes first, as an unplugged cable would; the frame being written is then
            // finished, not left behind as a temporary file.
            drop(master);
            camera.finish();
        }
    }
    Ok(())
}
