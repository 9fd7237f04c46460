//! A whole scan: configure the controller, arm, run, pair triggers with frames, and account for
//! everything that was lost. The caller receives each [`PairEvent`] as it happens (to write the
//! manifest record at once) and gets the final stream [`Status`] — also when the scan fails.

use crate::client::{Client, HwError, host_time_us};
use crate::framing::MAX_BODY;
use crate::message::{Command, DeviceInfo, DeviceMessage, DeviceState, DeviceStatus, describe_fault, format_list};
use crate::pairing::{FrameSource, PairEvent, PairOptions, PairStats, Pairer};
use crate::schedule::{AngleSpec, Schedule};
use omni_formats::stream::Status;
use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// When the run ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StopWhen {
    /// After this many revolutions with the lasers on (ambient revolutions come on top).
    Revolutions(u64),
    /// After this long (host clock); the controller is sent STOP.
    Duration(Duration),
    /// Until the cancel flag is raised (SIGINT/SIGTERM): a live scan, whose planned end that is.
    UntilStopped,
}

/// What to scan.
#[derive(Debug, Clone)]
pub struct ScanConfig {
    pub angles: AngleSpec,
    /// Triggering facets; `None` = all.
    pub facets: Option<Vec<u32>>,
    /// Lasers on in laser frames; `None` = all.
    pub lasers: Option<Vec<u32>>,
    /// Interleave laser-off revolutions (ambient frames).
    pub ambient: bool,
    /// Motor speed (rev/min); 0 = the fastest the controller's trigger rate allows.
    pub rpm: f64,
    pub stop: StopWhen,
    pub pairing: PairOptions,
    /// Silence from the controller this long makes the host ask for its status.
    pub silence_timeout: Duration,
    /// Set (e.g. by a Ctrl-C handler) to stop the run early: the controller gets STOP, the frames
    /// still due are collected, and the status record says the scan was interrupted.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl ScanConfig {
    /// A scan of `revolutions` revolutions over all facets and lasers at the fastest speed.
    pub fn new(angles: AngleSpec, revolutions: u64) -> Self {
        ScanConfig {
            angles,
            facets: None,
            lasers: None,
            ambient: false,
            rpm: 0.0,
            stop: StopWhen::Revolutions(revolutions),
            pairing: PairOptions::default(),
            silence_timeout: Duration::from_millis(1500),
            cancel: None,
        }
    }
}

/// Configures and arms the controller; returns the schedule it will fire and its speed (rpm).
pub fn configure<P: Read + Write>(
    client: &mut Client<P>,
    info: &DeviceInfo,
    cfg: &ScanConfig,
) -> Result<(Schedule, f64), HwError> {
    let schedule = Schedule {
        counts_per_rev: info.counts_per_rev,
        facets_total: info.facets,
        facets: cfg.facets.clone().unwrap_or_else(|| (0..info.facets).collect()),
        counts: cfg.angles.to_counts(info).map_err(HwError::Protocol)?,
        lasers: cfg.lasers.clone().unwrap_or_else(|| (0..info.lasers).collect()),
        ambient: cfg.ambient,
    };
    schedule.validate().map_err(HwError::Protocol)?;
    if let Some(&j) = schedule.lasers.iter().find(|&&j| j >= info.lasers) {
        return Err(HwError::Protocol(format!("laser {j} does not exist (the controller has {})", info.lasers)));
    }
    // A run left over from an interrupted scan would refuse the configuration: stop it first
    // (in `idle` or `armed` this only disarms).
    client.request(Command::Stop)?;
    client.request(Command::Speed(cfg.rpm))?;
    client.request(Command::Lasers(schedule.lasers.clone()))?;
    client.request(Command::Ambient(cfg.ambient))?;
    client.request(Command::Facets(cfg.facets.as_ref().map(|_| schedule.facets.clone())))?;
    for (i, chunk) in angle_chunks(&schedule.counts).into_iter().enumerate() {
        client.request(if i == 0 { Command::AnglesSet(chunk) } else { Command::AnglesAdd(chunk) })?;
    }
    client.request(Command::Arm)?;
    let status = client.status()?;
    if status.state != DeviceState::Armed || !(status.rpm > 0.0) {
        return Err(HwError::Protocol(format!(
            "after ARM the controller is {} at {} rpm",
            status.state.as_str(),
            status.rpm
        )));
    }
    Ok((schedule, status.rpm))
}

/// Splits counts into lists that fit in one line (`ANGLES <id> ADD <list>`).
fn angle_chunks(counts: &[u32]) -> Vec<Vec<u32>> {
    let room = MAX_BODY - "ANGLES 4294967295 ADD ".len();
    let mut chunks: Vec<Vec<u32>> = vec![vec![]];
    for &c in counts {
        let mut candidate = chunks.last().cloned().unwrap_or_default();
        candidate.push(c);
        if format_list(&candidate).len() > room {
            chunks.push(vec![c]);
        } else if let Some(last) = chunks.last_mut() {
            *last = candidate;
        }
    }
    chunks
}

/// The outcome of a scan: the final status record and, if it failed, why.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanOutcome {
    pub status: Status,
    pub error: Option<String>,
    pub stats: PairStats,
}

/// Number of triggers a run fires, if known in advance.
pub fn expected_triggers(schedule: &Schedule, cfg: &ScanConfig) -> Option<u64> {
    match cfg.stop {
        StopWhen::Revolutions(n) => Some(n * schedule.per_revolution() * if cfg.ambient { 2 } else { 1 }),
        StopWhen::Duration(_) | StopWhen::UntilStopped => None,
    }
}

/// A one-line description of a loss, for the status record and warnings.
pub fn describe(event: &PairEvent) -> Option<String> {
    match event {
        PairEvent::Paired(_) => None,
        PairEvent::FrameMissing { seq, facet, alpha_deg, reason } => {
            Some(format!("trigger seq {seq} (facet {facet}, {alpha_deg}°): frame missing: {reason}"))
        }
        PairEvent::EventsLost { first_seq, count, placed } => Some(format!(
            "trigger events seq {first_seq}..{} lost ({count}); {placed} placed from the schedule",
            first_seq + count - 1
        )),
        PairEvent::FrameUnmatched { path, reason } => Some(format!("frame {path}: not paired: {reason}")),
        PairEvent::BadEvent(m) => Some(format!("dropped event: {m}")),
        PairEvent::FrameBroken(m) => Some(m.clone()),
    }
}

/// `STATUS` round trips used to map the controller clock before a run.
const CLOCK_SAMPLES: usize = 5;

/// Errors kept in the status record; the rest are counted.
const MAX_LISTED_ERRORS: usize = 50;

struct Run<'a, P, S: ?Sized> {
    client: &'a mut Client<P>,
    source: &'a mut S,
    sink: &'a mut dyn FnMut(&PairEvent) -> Result<(), String>,
    pairer: Pairer,
    errors: Vec<String>,
    errors_total: usize,
    controller: Option<DeviceStatus>,
    done: Option<Instant>,
    interrupted: bool,
}

impl<P: Read + Write, S: FrameSource + ?Sized> Run<'_, P, S> {
    fn emit(&mut self, events: Vec<PairEvent>) -> Result<(), String> {
        for e in &events {
            if let Some(m) = describe(e) {
                self.errors_total += 1;
                if self.errors.len() < MAX_LISTED_ERRORS {
                    self.errors.push(m);
                }
            }
            (self.sink)(e)?;
        }
        Ok(())
    }

    fn handle(&mut self, message: DeviceMessage, at_us: i64) -> Result<(), String> {
        match message {
            DeviceMessage::Trigger(ev) => {
                self.source.on_trigger(&ev, at_us).map_err(|e| format!("{}: {e}", self.source.describe()))?;
                let out = self.pairer.on_trigger(ev, at_us);
                self.emit(out)
            }
            DeviceMessage::Done { fired, .. } => {
                self.done.get_or_insert_with(Instant::now);
                let out = self.pairer.on_run_end(fired);
                self.emit(out)
            }
            DeviceMessage::Status(s) => {
                self.pairer.observe_clock(s.t_us, at_us);
                let fault = self.fault(&s);
                self.controller = Some(s);
                fault
            }
            // Late duplicate replies of retried commands, or a HELLO after a controller reset.
            DeviceMessage::Ack { .. } | DeviceMessage::Nak { .. } | DeviceMessage::Hello(_) => Ok(()),
        }
    }

    fn poll_frames(&mut self) -> Result<(), String> {
        let frames = self.source.poll().map_err(|e| format!("{}: {e}", self.source.describe()))?;
        let now = host_time_us();
        for f in frames {
            self.pairer.on_frame(f, now);
        }
        let broken: Vec<PairEvent> = self.source.take_losses().into_iter().map(PairEvent::FrameBroken).collect();
        self.emit(broken)?;
        let out = self.pairer.tick(now);
        self.emit(out)
    }

    /// Frames the source still had in progress when the run ended; an error is recorded.
    fn finish_frames(&mut self) {
        let now = host_time_us();
        match self.source.finish() {
            Ok(frames) => frames.into_iter().for_each(|f| self.pairer.on_frame(f, now)),
            Err(e) => {
                let m = format!("{}: {e}", self.source.describe());
                self.errors_total += 1;
                self.errors.push(m);
            }
        }
    }

    /// A fault the controller reports during the run (e.g. a stalled motor) ends the scan with
    /// an error: the run will fire nothing more.
    fn fault(&self, s: &DeviceStatus) -> Result<(), String> {
        match &s.fault {
            Some(f) if self.done.is_none() => Err(format!("the controller reports fault={f}: {}", describe_fault(f))),
            _ => Ok(()),
        }
    }

    /// Silence: ask the controller what it is doing; an idle controller means the run ended
    /// and its `DONE` line was lost.
    fn check_alive(&mut self) -> Result<(), String> {
        let s = self.client.status().map_err(|e| e.to_string())?;
        if let Err(e) = self.fault(&s) {
            self.controller = Some(s);
            return Err(e);
        }
        if s.state != DeviceState::Running && self.done.is_none() {
            self.done = Some(Instant::now());
            let out = self.pairer.on_run_end(s.fired);
            self.emit(out)?;
        }
        self.controller = Some(s);
        Ok(())
    }

    /// `expected`: how long the run should take (Revolutions mode); a run still going at twice
    /// that plus 5 s (a stalled motor the controller does not report, a controller that forgot
    /// to stop) is an error, as is a fault the controller reports.
    fn main_loop(&mut self, cfg: &ScanConfig, revolutions: u64, expected: Option<Duration>) -> Result<(), String> {
        // Map the controller clock onto ours before the first frame: each round trip bounds the
        // offset from above; the smallest of a few is within one fast round trip.
        for _ in 0..CLOCK_SAMPLES {
            let s = self.client.status().map_err(|e| e.to_string())?;
            self.pairer.observe_clock(s.t_us, host_time_us());
        }
        // Armed controllers send no triggers: anything queued now belongs to an earlier run.
        self.client.discard_received();
        self.client.request(Command::Start { revolutions }).map_err(|e| e.to_string())?;
        let started = Instant::now();
        let mut stop_sent = false;
        let mut last_heard = Instant::now();
        let linger = Duration::from_micros((cfg.pairing.frame_timeout_us + cfg.pairing.event_grace_us).max(0) as u64);
        loop {
            let deadline = Instant::now() + Duration::from_millis(10);
            while let Some(r) = self.client.recv(deadline).map_err(|e| e.to_string())? {
                last_heard = Instant::now();
                self.handle(r.message, r.at_us)?;
            }
            self.poll_frames()?;
            if let Some(done) = self.done {
                if self.pairer.is_idle() || done.elapsed() > linger {
                    return Ok(());
                }
                continue;
            }
            let timed_out = matches!(cfg.stop, StopWhen::Duration(d) if started.elapsed() >= d);
            let cancelled = cfg.cancel.as_ref().is_some_and(|c| c.load(Ordering::SeqCst));
            if (timed_out || cancelled) && !stop_sent {
                self.client.request(Command::Stop).map_err(|e| e.to_string())?;
                stop_sent = true;
                // Stopping a scan that runs until stopped is its planned end, not an interruption.
                self.interrupted = cancelled && cfg.stop != StopWhen::UntilStopped;
            }
            if last_heard.elapsed() > cfg.silence_timeout {
                self.check_alive()?;
                last_heard = Instant::now();
            }
            if let Some(e) = expected
                && started.elapsed() > 2 * e + Duration::from_secs(5)
            {
                return Err(format!(
                    "the run should have ended after {:.1} s but the controller is still running",
                    e.as_secs_f64()
                ));
            }
        }
    }
}

/// Runs a configured scan (see [`configure`]) to its end. `sink` sees every pairing event as
/// it happens; an error from it (e.g. a closed output pipe) stops the scan.
pub fn run_scan<P: Read + Write, S: FrameSource + ?Sized>(
    client: &mut Client<P>,
    source: &mut S,
    schedule: Schedule,
    rpm: f64,
    cfg: &ScanConfig,
    sink: &mut dyn FnMut(&PairEvent) -> Result<(), String>,
) -> ScanOutcome {
    let revolutions = match cfg.stop {
        StopWhen::Revolutions(n) if cfg.ambient => 2 * n,
        StopWhen::Revolutions(n) => n,
        StopWhen::Duration(_) | StopWhen::UntilStopped => 0,
    };
    let expected = match cfg.stop {
        StopWhen::Revolutions(_) => {
            let last = schedule.position((revolutions * schedule.per_revolution()).max(1) - 1);
            Some(Duration::from_secs_f64(last as f64 * 60.0 / (rpm.max(1e-9) * schedule.counts_per_rev as f64)))
        }
        StopWhen::Duration(_) | StopWhen::UntilStopped => None,
    };
    let mut run = Run {
        client,
        source,
        sink,
        pairer: Pairer::new(schedule, rpm, cfg.pairing),
        errors: Vec::new(),
        errors_total: 0,
        controller: None,
        done: None,
        interrupted: false,
    };
    let result = run.main_loop(cfg, revolutions, expected);
    let disconnected = result.as_ref().err().is_some_and(|e| e.contains("disconnected"));
    if result.is_err() && !disconnected {
        // Best effort: leave the controller stopped.
        let _ = run.client.request(Command::Stop);
    }
    // Account for everything still waiting, without waiting any longer.
    let _ = run.poll_frames();
    run.finish_frames();
    let out = run.pairer.drain();
    let sink_result = run.emit(out);
    if result.is_ok() && sink_result.is_ok() {
        let _ = run.client.status().map(|s| run.controller = Some(s));
    }
    let interrupted = run.interrupted.then(|| "interrupted: the run was stopped early".to_string());
    let error = result.err().or(sink_result.err()).or(interrupted);
    finish(run, error)
}

fn finish<P: Read + Write, S: FrameSource + ?Sized>(run: Run<'_, P, S>, error: Option<String>) -> ScanOutcome {
    let stats = run.pairer.stats;
    let mut errors = run.errors;
    if run.errors_total > MAX_LISTED_ERRORS {
        errors.push(format!("… and {} more", run.errors_total - MAX_LISTED_ERRORS));
    }
    if let Some(e) = &error {
        errors.push(e.clone());
    }
    let lines = run.client.line_stats();
    let mut extra = serde_json::Map::new();
    let mut put = |k: &str, v: u64| {
        extra.insert(k.into(), v.into());
    };
    put("triggers", stats.triggers);
    put("events_lost", stats.events_lost);
    put("frames_with_inferred_trigger", stats.paired_inferred);
    put("events_duplicated", stats.events_duplicated);
    put("frames_unmatched", stats.frames_unmatched);
    put("bad_events", stats.bad_events);
    put("line_crc_errors", lines.crc_errors);
    put("lines_malformed", lines.malformed);
    put("command_retries", run.client.retries);
    if let Some(c) = &run.controller {
        put("controller_fired", c.fired);
        put("controller_overruns", c.overruns);
        put("controller_crc_errors", c.crc_errors);
    }
    extra.extend(run.source.stats());
    let status = Status {
        frames: stats.paired,
        frames_missing: stats.missing_total(),
        frames_failed: 0,
        complete: error.is_none() && run.done.is_some(),
        errors,
        extra,
    };
    ScanOutcome { status, error, stats }
}

/// A status record for a scan that failed before it started (handshake or configuration).
pub fn failed_status(error: &str) -> Status {
    Status {
        frames: 0,
        frames_missing: 0,
        frames_failed: 0,
        complete: false,
        errors: vec![error.to_string()],
        extra: Default::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_lists_are_split_into_lines_that_fit() {
        let counts: Vec<u32> = (0..600).map(|i| i * 5).collect();
        let chunks = angle_chunks(&counts);
        assert!(chunks.len() > 1);
        assert_eq!(chunks.concat(), counts);
        for c in &chunks {
            let body = crate::message::Request::new(u32::MAX, Command::AnglesAdd(c.clone())).to_body();
            assert!(body.len() <= MAX_BODY, "{} bytes", body.len());
        }
    }
}
