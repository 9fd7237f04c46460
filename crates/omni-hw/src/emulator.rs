//! A virtual trigger controller and camera: the [`Controller`] logic served over a byte stream
//! (a pseudo-terminal in `omni-trigger emulate`), a [`VirtualCamera`] that renders each
//! triggered frame into a directory, and fault injection.
//!
//! Timing model: the controller's clock is µs since the emulator started plus a pretend uptime.
//! Each trigger is stamped with the time the encoder reached its count; the camera "exposes" at
//! that instant and writes the frame (atomically: temporary hidden file, then rename) with its
//! modification time set to the exposure time — as camera software that keeps capture
//! timestamps does. A camera still busy with the previous frame misses the trigger, like a real
//! camera ignoring triggers during readout.

use crate::controller::{Controller, ControllerSpec};
use crate::framing::{LineReader, encode_line};
use crate::message::{DeviceMessage, DeviceState, TriggerEvent};
use omni_geom::rng::SplitMix64;
use std::io::{ErrorKind, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime};

/// Pretend controller uptime at emulator start (µs), so timestamps do not start at zero.
const BOOT_US: u64 = 5_000_000;

/// One camera exposure.
#[derive(Debug, Clone, PartialEq)]
pub struct Shot {
    pub trigger_seq: u64,
    /// Mirror angle within the facet (radians).
    pub alpha_rad: f64,
    pub facet: u32,
    /// Lasers on (empty = laser-off frame).
    pub lasers: Vec<u32>,
    /// Host-clock exposure time.
    pub exposure: SystemTime,
}

/// Produces the encoded image (PNG bytes) the camera sees for a shot. The bin wires the
/// simulator's renderer in; [`BlankRenderer`] serves tests that only exercise timing.
pub trait FrameRenderer: Send {
    fn render(&mut self, shot: &Shot) -> Result<Vec<u8>, String>;
}

/// A uniform grey 8-bit image (no scene): for protocol and pairing tests.
pub struct BlankRenderer {
    pub width: u32,
    pub height: u32,
}

impl FrameRenderer for BlankRenderer {
    fn render(&mut self, _shot: &Shot) -> Result<Vec<u8>, String> {
        let pixels = vec![40u8; (self.width * self.height) as usize];
        let mut bytes = Vec::new();
        omni_formats::png::write_png(&mut bytes, &pixels, self.width, self.height, image::ExtendedColorType::L8)
            .map_err(|e| e.to_string())?;
        Ok(bytes)
    }
}

/// The camera: renders on its own thread; triggers arriving while it is busy are missed.
pub struct VirtualCamera {
    busy: Arc<AtomicBool>,
    tx: Option<mpsc::Sender<Shot>>,
    thread: Option<std::thread::JoinHandle<()>>,
    written: Arc<AtomicU64>,
    /// Triggers missed because the camera was busy.
    pub missed: u64,
    /// A camera with a frame buffer: triggers queue up instead of being missed.
    buffered: bool,
}

/// One line of the emulator's ground-truth file (JSON Lines): which trigger each frame shows.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TruthRecord {
    /// Frame file name inside the frames directory.
    pub path: String,
    pub trigger_seq: u64,
    /// True mirror angle within the facet (degrees).
    pub alpha_deg: f64,
    pub facet: u32,
    pub lasers: Vec<u32>,
}

impl VirtualCamera {
    /// Starts the camera writing `frame_NNNNNN.png` into `dir`, sleeping `extra_delay` after each
    /// render (a slow camera) and appending a [`TruthRecord`] per frame to `truth` if given.
    pub fn start(
        dir: &Path,
        mut renderer: Box<dyn FrameRenderer>,
        extra_delay: Duration,
        truth: Option<PathBuf>,
    ) -> Result<VirtualCamera, String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let mut truth_file = match truth {
            Some(p) => Some(
                std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(&p)
                    .map_err(|e| format!("{}: {e}", p.display()))?,
            ),
            None => None,
        };
        let (tx, rx) = mpsc::channel::<Shot>();
        let busy = Arc::new(AtomicBool::new(false));
        let written = Arc::new(AtomicU64::new(0));
        let (busy_t, written_t, dir) = (busy.clone(), written.clone(), dir.to_path_buf());
        let thread = std::thread::spawn(move || {
            for shot in rx {
                let result = renderer.render(&shot).and_then(|bytes| {
                    std::thread::sleep(extra_delay);
                    let n = written_t.load(Ordering::SeqCst);
                    let name = format!("frame_{n:06}.png");
                    write_frame(&dir, &name, &bytes, shot.exposure).map_err(|e| format!("{name}: {e}"))?;
                    written_t.fetch_add(1, Ordering::SeqCst);
                    Ok(name)
                });
                match result {
                    Ok(name) => {
                        if let Some(f) = truth_file.as_mut() {
                            let rec = TruthRecord {
                                path: name,
                                trigger_seq: shot.trigger_seq,
                                alpha_deg: shot.alpha_rad.to_degrees(),
                                facet: shot.facet,
                                lasers: shot.lasers.clone(),
                            };
                            let line = serde_json::to_string(&rec).unwrap_or_default();
                            let _ = writeln!(f, "{line}").and_then(|_| f.flush());
                        }
                    }
                    Err(e) => eprintln!("omni-trigger emulate: camera: {e}"),
                }
                busy_t.store(false, Ordering::SeqCst);
            }
        });
        Ok(VirtualCamera { busy, tx: Some(tx), thread: Some(thread), written, missed: 0, buffered: false })
    }

    /// Gives the camera an unbounded frame buffer: every trigger is exposed (its frame keeps the
    /// exposure time as its timestamp) and written in trigger order, however long rendering takes.
    /// This lets a slow renderer serve fast trigger rates, like a camera that buffers frames.
    pub fn set_buffered(&mut self, buffered: bool) {
        self.buffered = buffered;
    }

    /// Fires the camera; `false` if it was busy and missed the trigger.
    pub fn trigger(&mut self, shot: Shot) -> bool {
        if self.buffered {
            return self.tx.as_ref().is_some_and(|tx| tx.send(shot).is_ok());
        }
        if self.busy.swap(true, Ordering::SeqCst) {
            self.missed += 1;
            return false;
        }
        match self.tx.as_ref().map(|tx| tx.send(shot)) {
            Some(Ok(())) => true,
            _ => {
                self.busy.store(false, Ordering::SeqCst);
                false
            }
        }
    }

    /// Frames written so far.
    pub fn frames_written(&self) -> u64 {
        self.written.load(Ordering::SeqCst)
    }

    /// Waits for the frame in progress and stops the camera thread.
    pub fn finish(mut self) {
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Writes a frame atomically with its modification time set to the exposure time.
fn write_frame(dir: &Path, name: &str, bytes: &[u8], exposure: SystemTime) -> std::io::Result<()> {
    let mut tmp = omni_formats::io::TempFile::create(&dir.join(name))?;
    tmp.file().write_all(bytes)?;
    tmp.file().set_modified(exposure)?;
    tmp.commit()
}

/// Faults to inject; probabilities are per line (per event for drop/duplicate).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// Random bytes before a line (half of the time without a newline, so they corrupt it).
    pub garbage: f64,
    /// A wrong checksum on a line (events, ACKs, everything).
    pub bad_crc: f64,
    /// Trigger events not sent (the camera still fires).
    pub drop_events: f64,
    /// Trigger events sent twice.
    pub duplicate_events: f64,
    /// Close the port after this many triggers (an unplugged cable).
    pub disconnect_after: Option<u64>,
    /// The motor stalls after this many triggers: no more triggers; the controller faults the
    /// run as the firmware does (`STS … fault=stall`, see [`Controller::stall_motor_after`]) and
    /// keeps it running until `STOP`. Stalled before a run's first index (0, or reached in an
    /// earlier run) it is not watched: that run never ends.
    pub stall_after: Option<u64>,
    /// Seed of the fault generator (same seed, same faults).
    pub seed: u64,
}

/// Emulator settings.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    pub spec: ControllerSpec,
    pub faults: Faults,
    /// Period of `STS` lines while running.
    pub status_period: Duration,
    /// Keep serving after the host disconnects (for several tool runs against one emulator).
    pub persist: bool,
}

impl Default for EmulatorOptions {
    fn default() -> Self {
        EmulatorOptions {
            spec: ControllerSpec::default(),
            faults: Faults::default(),
            status_period: Duration::from_secs(1),
            persist: false,
        }
    }
}

/// Why [`serve`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServeEnd {
    /// The host closed the port.
    HostDisconnected,
    /// The `disconnect_after` fault fired: the caller must close the port now.
    SimulatedDisconnect,
}

struct Link<'a, P> {
    port: &'a mut P,
    rng: SplitMix64,
    faults: &'a Faults,
}

impl<P: Write> Link<'_, P> {
    /// Sends one line with the configured faults. A write that cannot complete (host not
    /// reading) is dropped: the host sees a corrupt or missing line, like on a real wire.
    fn send(&mut self, msg: &DeviceMessage) -> std::io::Result<()> {
        if self.rng.chance(self.faults.garbage) {
            let n = 1 + (self.rng.next_u64() % 24) as usize;
            let mut junk: Vec<u8> = (0..n).map(|_| (self.rng.next_u64() % 256) as u8).filter(|&b| b != b'\n').collect();
            if self.rng.chance(0.5) {
                junk.push(b'\n');
            }
            self.write(&junk)?;
        }
        let mut line = encode_line(&msg.to_body()).into_bytes();
        if self.rng.chance(self.faults.bad_crc) {
            let i = line.len() - 2;
            line[i] = if line[i] == b'0' { b'1' } else { b'0' };
        }
        self.write(&line)
    }

    /// Sends the lines; `false` if the port failed (no host: the lines are lost, as on a wire
    /// without a listener).
    fn send_all(&mut self, msgs: &[DeviceMessage]) -> bool {
        msgs.iter().all(|m| self.send(m).is_ok())
    }

    fn write(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        match self.port.write_all(bytes) {
            Err(e) if e.kind() == ErrorKind::TimedOut => Ok(()),
            other => other,
        }
    }
}

/// Serves the controller on `port` until the host disconnects (or, with `persist`, forever: a run
/// then goes on without a listener, as real firmware would) or the disconnect fault fires. The
/// port's read timeout should be short (1–2 ms): it sets the loop's tick. Before a host
/// connects, a pseudo-terminal master reports a hang-up; that is waited out.
pub fn serve<P: Read + Write>(
    port: &mut P,
    options: &EmulatorOptions,
    camera: &mut VirtualCamera,
) -> std::io::Result<ServeEnd> {
    let t0 = Instant::now();
    let sys0 = SystemTime::now();
    let clock = || t0.elapsed().as_micros() as u64 + BOOT_US;
    let mut controller = Controller::new(options.spec.clone());
    let mut reader = LineReader::new();
    let mut link = Link { port, rng: SplitMix64::new(options.faults.seed), faults: &options.faults };
    let mut connected = false;
    let mut fired = 0u64;
    let mut stall_set = false;
    let mut last_status = Instant::now();
    let mut buf = [0u8; 256];
    loop {
        let mut outgoing = Vec::new();
        let mut disconnect = false;
        let running = controller.state() == DeviceState::Running;
        if let Some(n) = options.faults.stall_after
            && running
            && !stall_set
        {
            controller.stall_motor_after(n.saturating_sub(fired));
        }
        stall_set = running;
        let fired_now = controller.poll(clock());
        for msg in fired_now {
            if let DeviceMessage::Trigger(ev) = &msg {
                camera.trigger(shot_for(ev, &options.spec, sys0));
                fired += 1;
                // The event leaves a whole trigger period after its edge: the queue fell behind.
                if clock().saturating_sub(ev.t_us) as f64 > 1e6 / options.spec.max_rate_hz {
                    controller.count_overrun();
                }
                disconnect |= options.faults.disconnect_after.is_some_and(|n| fired >= n);
                if link.rng.chance(options.faults.drop_events) {
                    continue;
                }
                if link.rng.chance(options.faults.duplicate_events) {
                    outgoing.push(msg.clone());
                }
            }
            outgoing.push(msg);
        }
        if controller.state() == DeviceState::Running && last_status.elapsed() >= options.status_period {
            last_status = Instant::now();
            outgoing.push(DeviceMessage::Status(controller.status(clock())));
        }
        if !link.send_all(&outgoing) && connected && !options.persist {
            return Ok(ServeEnd::HostDisconnected);
        }
        if disconnect {
            return Ok(ServeEnd::SimulatedDisconnect);
        }
        let n = match link.port.read(&mut buf) {
            Ok(n) if n > 0 => n,
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                continue;
            }
            _ => {
                // End of file or hang-up: no host has the port open.
                if connected && !options.persist {
                    return Ok(ServeEnd::HostDisconnected);
                }
                connected = false;
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
        };
        connected = true;
        let crc_before = reader.stats.crc_errors;
        let mut bodies = Vec::new();
        reader.push(&buf[..n], &mut bodies);
        for _ in crc_before..reader.stats.crc_errors {
            controller.count_crc_error();
        }
        let replies: Vec<DeviceMessage> =
            bodies.iter().flat_map(|body| controller.handle_line(body, clock())).collect();
        if !link.send_all(&replies) && !options.persist {
            return Ok(ServeEnd::HostDisconnected);
        }
    }
}

fn shot_for(ev: &TriggerEvent, spec: &ControllerSpec, sys0: SystemTime) -> Shot {
    let per_facet = spec.counts_per_rev / spec.facets;
    let alpha_deg = (ev.encoder % per_facet) as f64 * 360.0 / spec.counts_per_rev as f64;
    Shot {
        trigger_seq: ev.seq,
        alpha_rad: alpha_deg.to_radians(),
        facet: ev.facet,
        lasers: ev.lasers.clone(),
        exposure: sys0 + Duration::from_micros(ev.t_us.saturating_sub(BOOT_US)),
    }
}

/// Reads an emulator truth file.
pub fn read_truth(path: &Path) -> Result<Vec<TruthRecord>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| serde_json::from_str(l).map_err(|e| format!("{}: line {}: {e}", path.display(), i + 1)))
        .collect()
}
