//! Pairing trigger events with camera frames.
//!
//! Frames are matched to triggers **by order and checked by timestamps**: the controller stamps
//! each trigger with its own clock, the host maps that clock onto its own (the smallest observed
//! "received − stamped" difference, i.e. clock offset plus the fastest transport), and each frame
//! carries a host-clock timestamp from its [`FrameSource`] (for [`DirFrameSource`], the file's
//! modification time). A frame is paired with the pending trigger whose expected frame time
//! (trigger time + estimated latency) is nearest, and only if it lies within a tolerance of
//! `tolerance_fraction` × the gap to the neighbouring scheduled trigger — lost events included,
//! because the [`Schedule`] places every sequence number. So a frame can never be shifted onto a
//! neighbouring angle: it pairs with its own trigger or is reported as unmatched. Triggers whose
//! frame never comes are reported missing after `frame_timeout_us`, or as soon as a later frame
//! arrives (cameras deliver in order).
//!
//! Lost events (sequence gaps, or fewer events than `DONE fired=`) are placed from the schedule:
//! the sequence number fixes facet, encoder count and lasers, and the time is interpolated in
//! encoder position between the received neighbours. Their frames pair like any other (the
//! record carries `"trigger_inferred": true`), through the same timestamp window.

use crate::message::TriggerEvent;
use crate::schedule::Schedule;
use omni_formats::stream::Frame;
use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// A complete image file from the camera.
#[derive(Debug, Clone, PartialEq)]
pub struct CapturedFrame {
    pub path: PathBuf,
    /// The path as written into the manifest (relative to the frames directory).
    pub name: String,
    /// Host-clock timestamp (µs since the Unix epoch) of the exposure or of the file.
    pub time_us: i64,
    /// The trigger (sequence number) this frame answers, when the source knows it (a camera the
    /// host fired by software for that trigger). The frame then pairs with that trigger or with
    /// none: its timestamp must still fall in the trigger's window.
    pub trigger_seq: Option<u64>,
    /// Fields copied into the frame's manifest record (e.g. the camera's frame id).
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl CapturedFrame {
    /// A frame file with its timestamp and nothing else known.
    pub fn new(path: PathBuf, name: String, time_us: i64) -> Self {
        CapturedFrame { path, name, time_us, trigger_seq: None, extra: serde_json::Map::new() }
    }
}

/// Where frames come from: a directory the camera software writes into ([`DirFrameSource`]) or
/// a camera the host drives itself (`genicam::AravisFrameSource`, feature `aravis`); pairing
/// only sees [`CapturedFrame`]s.
pub trait FrameSource {
    /// Frames that became complete since the previous call, oldest first.
    fn poll(&mut self) -> std::io::Result<Vec<CapturedFrame>>;
    /// A short description for messages, e.g. the directory.
    fn describe(&self) -> String;
    /// The controller fired trigger `ev` (its event arrived at host time `received_us`): a
    /// source that triggers the camera by software does so now. An error stops the scan.
    fn on_trigger(&mut self, _ev: &TriggerEvent, _received_us: i64) -> std::io::Result<()> {
        Ok(())
    }
    /// Frames the source received broken or not at all since the previous call (e.g. a camera
    /// frame with lost packets), one line each, for the status record.
    fn take_losses(&mut self) -> Vec<String> {
        Vec::new()
    }
    /// The scan ended: frames still in progress (e.g. being written), waiting briefly for them.
    fn finish(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        Ok(Vec::new())
    }
    /// Counters for the status record (e.g. camera packets lost), added to its fields.
    fn stats(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

/// Image files appearing in a directory, written by the camera's software.
///
/// Files present when the source is created are ignored (stale frames of an earlier run must
/// never pair) unless they are rewritten (camera software that restarts its numbering). Hidden files (`.name`, the usual temporary names) and non-image extensions are
/// ignored; a file is reported once its size is non-zero and unchanged between two polls, so a
/// frame still being written is not read half-done. Its timestamp is the modification time.
///
/// A poll lists the directory only when its modification time changed (a file added, removed
/// or renamed) or a file seen is still to settle, and at least every
/// [`DirFrameSource::FULL_LISTING_EVERY`]; only those full listings look at the stale files
/// again, which a camera may rewrite in place without changing the directory. So thousands of
/// stale frames cost a listing twice a second, not a stat of each every poll.
pub struct DirFrameSource {
    dir: PathBuf,
    /// Files present at the start, with (size, modification time): ignored while unchanged.
    stale: HashMap<OsString, (u64, Option<std::time::SystemTime>)>,
    /// Files already reported.
    reported: HashSet<OsString>,
    /// Files seen but not yet reported, with the size they had.
    sizes: HashMap<OsString, u64>,
    /// The directory's modification time when it was last listed.
    listed_mtime: Option<std::time::SystemTime>,
    /// When the stale files were last looked at (a full listing).
    full_listing_at: Option<std::time::Instant>,
    full_listing_every: std::time::Duration,
}

const IMAGE_EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "tif", "tiff", "pgm", "bmp"];

impl DirFrameSource {
    /// Watches `dir` (created if missing).
    pub fn new(dir: &Path) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let mut src = DirFrameSource {
            dir: dir.to_path_buf(),
            stale: HashMap::new(),
            reported: HashSet::new(),
            sizes: HashMap::new(),
            listed_mtime: None,
            full_listing_at: None,
            full_listing_every: Self::FULL_LISTING_EVERY,
        };
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            let stamp = entry.metadata().map(|m| (m.len(), m.modified().ok())).unwrap_or((0, None));
            src.stale.insert(entry.file_name(), stamp);
        }
        Ok(src)
    }

    /// How often the directory is listed whole, stale files included, whether or not it changed.
    pub const FULL_LISTING_EVERY: std::time::Duration = std::time::Duration::from_millis(500);

    /// [`Self::FULL_LISTING_EVERY`] set otherwise (zero: every poll lists and looks at every file).
    pub fn with_full_listing_every(mut self, every: std::time::Duration) -> Self {
        self.full_listing_every = every;
        self
    }

    fn is_image(name: &OsString) -> bool {
        let name = name.to_string_lossy();
        !name.starts_with('.')
            && Path::new(name.as_ref())
                .extension()
                .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_string_lossy().to_ascii_lowercase().as_str()))
    }
}

impl FrameSource for DirFrameSource {
    fn poll(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        let mut out = Vec::new();
        // Read before the listing: a file added during it changes the time again.
        let mtime = std::fs::metadata(&self.dir)?.modified().ok();
        let full = self.full_listing_at.is_none_or(|t| t.elapsed() >= self.full_listing_every);
        if !full && mtime.is_some() && mtime == self.listed_mtime && self.sizes.is_empty() {
            return Ok(out);
        }
        self.listed_mtime = mtime;
        if full {
            self.full_listing_at = Some(std::time::Instant::now());
        }
        for entry in std::fs::read_dir(&self.dir)? {
            let entry = entry?;
            let name = entry.file_name();
            let settling = self.sizes.contains_key(&name);
            if self.reported.contains(&name)
                || !Self::is_image(&name)
                || (!full && !settling && self.stale.contains_key(&name))
            {
                continue;
            }
            // The file may vanish or change between listing and stat: just look again next time.
            let Ok(meta) = entry.metadata() else { continue };
            let len = meta.len();
            if self.stale.get(&name) == Some(&(len, meta.modified().ok())) {
                continue;
            }
            if len == 0 || self.sizes.get(&name) != Some(&len) {
                self.sizes.insert(name, len);
                continue;
            }
            let time_us = meta
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map(|d| d.as_micros() as i64)
                .unwrap_or_else(crate::client::host_time_us);
            self.sizes.remove(&name);
            self.stale.remove(&name);
            out.push(CapturedFrame::new(entry.path(), name.to_string_lossy().into_owned(), time_us));
            self.reported.insert(name);
        }
        out.sort_by(|a, b| (a.time_us, &a.name).cmp(&(b.time_us, &b.name)));
        Ok(out)
    }

    fn describe(&self) -> String {
        self.dir.display().to_string()
    }
}

/// Tolerances of the pairing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairOptions {
    /// A trigger without a frame this long after its expected frame time is missing (µs).
    pub frame_timeout_us: i64,
    /// Initial estimate of frame timestamp − trigger time (µs); refined as frames pair. 0 when
    /// the camera stamps frames with their exposure time.
    pub latency_us: i64,
    /// How long a new frame waits for its trigger event (µs). A frame is matched as soon as an
    /// event at or after its time has arrived; the wait matters for a frame whose event was lost,
    /// which is only known (and placed) when the next event or `DONE` arrives.
    pub event_grace_us: i64,
    /// A frame must lie within this fraction of the gap to the neighbouring trigger (< 0.5).
    pub tolerance_fraction: f64,
}

impl Default for PairOptions {
    fn default() -> Self {
        PairOptions { frame_timeout_us: 2_000_000, latency_us: 0, event_grace_us: 2_000_000, tolerance_fraction: 0.4 }
    }
}

/// What the pairing concluded, in the order it concluded it.
#[derive(Debug, Clone, PartialEq)]
pub enum PairEvent {
    /// A frame with its trigger: a manifest record.
    Paired(Box<Frame>),
    /// A trigger that fired but whose frame never came.
    FrameMissing { seq: u64, facet: u32, alpha_deg: f64, reason: String },
    /// Trigger events that were sent but never arrived (a sequence gap). Their triggers are
    /// placed from the schedule (`placed` = how many could be) and still pair with their frames.
    EventsLost { first_seq: u64, count: u64, placed: u64 },
    /// A frame that no received trigger accounts for (not written to the manifest).
    FrameUnmatched { path: String, reason: String },
    /// An event contradicting the schedule (dropped, never paired).
    BadEvent(String),
    /// A frame the source received broken (e.g. packets lost on the network) or not at all; it
    /// is never paired, and its trigger ends up missing.
    FrameBroken(String),
}

/// Counters of the pairing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PairStats {
    pub triggers: u64,
    pub paired: u64,
    pub frames_missing: u64,
    pub events_lost: u64,
    /// Lost events that could not be placed in time (no event received at all).
    pub events_unplaced: u64,
    /// Frames paired with a trigger placed from the schedule (its event was lost).
    pub paired_inferred: u64,
    pub events_duplicated: u64,
    pub frames_unmatched: u64,
    pub bad_events: u64,
}

impl PairStats {
    /// Triggers without a frame in the manifest.
    pub fn missing_total(&self) -> u64 {
        self.frames_missing + self.events_unplaced
    }
}

struct PendingFrame {
    frame: CapturedFrame,
    detected_us: i64,
}

/// The pairing state machine. All times are host-clock µs ([`crate::host_time_us`]) passed in
/// by the caller, so it is deterministic under test.
pub struct Pairer {
    schedule: Schedule,
    options: PairOptions,
    us_per_count: f64,
    clock_offset_us: Option<i64>,
    latency_us: f64,
    next_seq: u64,
    pending: BTreeMap<u64, TriggerEvent>,
    frames: VecDeque<PendingFrame>,
    ambient: HashMap<(u32, u64), String>,
    /// Sequence number and expected frame time of the newest received event.
    newest_trigger_time: Option<(u64, i64)>,
    /// The last received event: (seq, controller time µs), anchor for placing lost ones.
    last_received: Option<(u64, u64)>,
    inferred: HashSet<u64>,
    /// `DONE` arrived: no event will come any more, so no frame needs to wait for one.
    run_ended: bool,
    /// The longest time between two scheduled triggers at the nominal speed (µs): a frame whose
    /// event was lost learns so only from the next event, which may come this much later.
    longest_gap_us: i64,
    pub stats: PairStats,
}

impl Pairer {
    /// `rpm`: the motor speed the controller runs at (its `STS` line).
    pub fn new(schedule: Schedule, rpm: f64, options: PairOptions) -> Self {
        let us_per_count = 60e6 / (rpm.max(1e-9) * schedule.counts_per_rev as f64);
        let gaps = (0..schedule.per_revolution()).map(|s| schedule.position(s + 1) - schedule.position(s));
        let longest_gap_us = (gaps.max().unwrap_or(0) as f64 * us_per_count).round() as i64;
        Pairer {
            schedule,
            latency_us: options.latency_us as f64,
            options,
            us_per_count,
            clock_offset_us: None,
            next_seq: 0,
            pending: BTreeMap::new(),
            frames: VecDeque::new(),
            ambient: HashMap::new(),
            newest_trigger_time: None,
            last_received: None,
            inferred: HashSet::new(),
            run_ended: false,
            longest_gap_us,
            stats: PairStats::default(),
        }
    }

    /// Nothing is waiting: every received trigger and frame has been accounted for.
    pub fn is_idle(&self) -> bool {
        self.pending.is_empty() && self.frames.is_empty()
    }

    /// Sequence number of the next expected event (= events accounted for).
    pub fn next_seq(&self) -> u64 {
        self.next_seq
    }

    /// A trigger event received at host time `received_us`.
    pub fn on_trigger(&mut self, ev: TriggerEvent, received_us: i64) -> Vec<PairEvent> {
        let mut out = Vec::new();
        if let Err(e) = self.schedule.check(&ev) {
            self.stats.bad_events += 1;
            out.push(PairEvent::BadEvent(e));
            return out;
        }
        if ev.seq < self.next_seq {
            self.stats.events_duplicated += 1;
            return out;
        }
        out.extend(self.lose_events_before(ev.seq, Some((ev.seq, ev.t_us))));
        self.last_received = Some((ev.seq, ev.t_us));
        self.observe_clock(ev.t_us, received_us);
        self.stats.triggers += 1;
        self.next_seq = ev.seq + 1;
        self.pending.insert(ev.seq, ev);
        self.newest_trigger_time = self.pending.values().last().map(|e| (e.seq, self.frame_time(e)));
        out
    }

    /// Events `next_seq..seq` were lost. The schedule says exactly which trigger each was (its
    /// facet, encoder count, lasers); its time is interpolated in encoder position between the
    /// received neighbours `prev` and `next` (constant speed), or extrapolated at the nominal
    /// speed from one of them. Placed triggers wait for their frames like received ones.
    fn lose_events_before(&mut self, seq: u64, next: Option<(u64, u64)>) -> Option<PairEvent> {
        if seq <= self.next_seq {
            return None;
        }
        let (first_seq, count) = (self.next_seq, seq - self.next_seq);
        self.stats.events_lost += count;
        let mut placed = 0;
        for lost in first_seq..seq {
            match self.place(lost, self.last_received, next) {
                Some(t_us) => {
                    let e = self.schedule.expected(lost);
                    let ev = TriggerEvent {
                        seq: lost,
                        encoder: e.encoder,
                        facet: e.facet,
                        revolution: e.revolution,
                        t_us,
                        lasers: e.lasers,
                    };
                    self.pending.insert(lost, ev);
                    self.inferred.insert(lost);
                    placed += 1;
                }
                None => self.stats.events_unplaced += 1,
            }
        }
        self.next_seq = seq;
        Some(PairEvent::EventsLost { first_seq, count, placed })
    }

    /// Controller time (µs) of trigger `seq` from its received neighbours.
    fn place(&self, seq: u64, prev: Option<(u64, u64)>, next: Option<(u64, u64)>) -> Option<u64> {
        let pos = |s: u64| self.schedule.position(s) as f64;
        let t = match (prev, next) {
            (Some((sp, tp)), Some((sn, tn))) => {
                tp as f64 + (pos(seq) - pos(sp)) * (tn as f64 - tp as f64) / (pos(sn) - pos(sp))
            }
            (Some((sp, tp)), None) => tp as f64 + (pos(seq) - pos(sp)) * self.us_per_count,
            (None, Some((sn, tn))) => tn as f64 - (pos(sn) - pos(seq)) * self.us_per_count,
            (None, None) => return None,
        };
        (t >= 0.0).then_some(t.round() as u64)
    }

    /// The controller reported the run's total trigger count: events beyond the last received
    /// one are lost (and placed after it at the nominal speed).
    pub fn on_run_end(&mut self, fired: u64) -> Vec<PairEvent> {
        self.run_ended = true;
        self.lose_events_before(fired, None).into_iter().collect()
    }

    /// A controller timestamp `controller_us` read at host time `received_us` (a `STS` line):
    /// refines the clock mapping before and between trigger events.
    pub fn observe_clock(&mut self, controller_us: u64, received_us: i64) {
        let offset = received_us - controller_us as i64;
        self.clock_offset_us = Some(self.clock_offset_us.map_or(offset, |o| o.min(offset)));
    }

    /// A new frame, first seen at host time `now_us`.
    pub fn on_frame(&mut self, frame: CapturedFrame, now_us: i64) {
        self.frames.push_back(PendingFrame { frame, detected_us: now_us });
    }

    /// Expected host-clock time of trigger `ev`'s frame.
    fn frame_time(&self, ev: &TriggerEvent) -> i64 {
        ev.t_us as i64 + self.clock_offset_us.unwrap_or(0) + self.latency_us.round() as i64
    }

    /// Half-width of the window around trigger `seq`'s expected frame time (µs).
    fn tolerance_us(&self, seq: u64) -> f64 {
        let here = self.schedule.position(seq);
        let next_gap = self.schedule.position(seq + 1) - here;
        let gap = if seq > 0 { next_gap.min(here - self.schedule.position(seq - 1)) } else { next_gap };
        self.options.tolerance_fraction * gap as f64 * self.us_per_count
    }

    /// Pairs the frames that are ready and expires overdue triggers. Call it often.
    pub fn tick(&mut self, now_us: i64) -> Vec<PairEvent> {
        let mut out = Vec::new();
        while let Some(f) = self.frames.front() {
            // Events arrive in order: once one at (or, within its window, just before) the frame's
            // time has arrived, the frame's own event has arrived or been found lost.
            let trigger_seen = self
                .newest_trigger_time
                .is_some_and(|(seq, t)| t as f64 + self.tolerance_us(seq) >= f.frame.time_us as f64);
            // A frame whose event is lost waits for the next event, which tells: up to the
            // schedule's longest gap after it, then the grace for the line's way here.
            let waited = now_us - f.detected_us;
            if !trigger_seen && !self.run_ended && waited < self.options.event_grace_us + self.longest_gap_us {
                break;
            }
            let f = self.frames.pop_front().map(|f| f.frame);
            if let Some(f) = f {
                out.extend(self.match_frame(f));
            }
        }
        let overdue: Vec<u64> = self
            .pending
            .values()
            .filter(|e| now_us - self.frame_time(e) > self.options.frame_timeout_us)
            .map(|e| e.seq)
            .collect();
        for seq in overdue {
            let reason = format!("no frame within {} ms of the trigger", self.options.frame_timeout_us / 1000);
            out.extend(self.declare_missing(seq, reason));
        }
        out
    }

    /// Ends the pairing: every waiting frame is matched now, every unpaired trigger is missing.
    pub fn drain(&mut self) -> Vec<PairEvent> {
        let mut out = Vec::new();
        while let Some(f) = self.frames.pop_front() {
            out.extend(self.match_frame(f.frame));
        }
        let left: Vec<u64> = self.pending.keys().copied().collect();
        for seq in left {
            out.extend(self.declare_missing(seq, "no frame before the scan ended".into()));
        }
        out
    }

    fn declare_missing(&mut self, seq: u64, reason: String) -> Option<PairEvent> {
        let ev = self.pending.remove(&seq)?;
        self.inferred.remove(&seq);
        self.stats.frames_missing += 1;
        Some(PairEvent::FrameMissing { seq, facet: ev.facet, alpha_deg: self.schedule.alpha_deg(ev.encoder), reason })
    }

    /// The pending trigger a frame could be, with its timestamp error (µs): the one the source
    /// named, or else the nearest in time.
    fn candidate(&self, frame: &CapturedFrame) -> Result<(u64, f64), String> {
        let error = |e: &TriggerEvent| (frame.time_us - self.frame_time(e)) as f64;
        match frame.trigger_seq {
            Some(seq) => self.pending.get(&seq).map(|e| (seq, error(e))).ok_or_else(|| {
                format!("the camera answered trigger seq {seq}, which is not waiting for a frame (already paired or expired)")
            }),
            None => self
                .pending
                .values()
                .map(|e| (e.seq, error(e)))
                .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                .ok_or_else(|| "no pending trigger (its event was lost or it came too late)".into()),
        }
    }

    fn match_frame(&mut self, frame: CapturedFrame) -> Vec<PairEvent> {
        let mut out = Vec::new();
        let best = self.candidate(&frame);
        let Some((seq, error_us)) = best.clone().ok().filter(|(seq, err)| err.abs() <= self.tolerance_us(*seq)) else {
            self.stats.frames_unmatched += 1;
            let reason = match best {
                Ok((seq, err)) => format!(
                    "its timestamp is {:.1} ms from the {} trigger (seq {seq}), beyond the ±{:.1} ms window",
                    err / 1000.0,
                    if frame.trigger_seq.is_some() { "answered" } else { "nearest pending" },
                    self.tolerance_us(seq) / 1000.0
                ),
                Err(reason) => reason,
            };
            out.push(PairEvent::FrameUnmatched { path: frame.name, reason });
            return out;
        };
        let earlier: Vec<u64> = self.pending.range(..seq).map(|(s, _)| *s).collect();
        for s in earlier {
            out.extend(self.declare_missing(s, "a later frame arrived first".into()));
        }
        // Track slow drifts of the latency; a single frame moves the estimate by a third at most.
        self.latency_us += 0.3 * error_us;
        if let Some(ev) = self.pending.remove(&seq) {
            self.stats.paired += 1;
            if self.inferred.contains(&seq) {
                self.stats.paired_inferred += 1;
            }
            let mut record = self.record(&ev, frame.name);
            record.extra.extend(frame.extra);
            out.push(PairEvent::Paired(Box::new(record)));
        }
        out
    }

    fn record(&mut self, ev: &TriggerEvent, path: String) -> Frame {
        let mut f = Frame::new(ev.seq, path.clone(), self.schedule.alpha_deg(ev.encoder), ev.facet);
        f.revolution = ev.revolution;
        f.encoder = Some(ev.encoder as u64);
        f.timestamp_us = Some(ev.t_us);
        f.lasers = ev.lasers.clone();
        if self.inferred.remove(&ev.seq) {
            // Its event was lost: angle, facet and encoder come from the schedule, the timestamp
            // is interpolated.
            f.extra.insert("trigger_inferred".into(), true.into());
        }
        if self.schedule.ambient {
            let key = |rev: u64| (ev.encoder, rev);
            if ev.lasers.is_empty() {
                self.ambient.insert(key(ev.revolution), path);
            } else if ev.revolution > 0 {
                f.ambient_path = self.ambient.remove(&key(ev.revolution - 1));
            }
        }
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 36000 counts/rev, facets 0 and 6, angles 0°, 10°, 20°; at 83.33 rpm one count is 20 µs,
    /// so neighbouring triggers are ≥ 20 ms apart and the window is ±8 ms.
    fn schedule(ambient: bool) -> Schedule {
        Schedule {
            counts_per_rev: 36000,
            facets_total: 12,
            facets: vec![0, 6],
            counts: vec![0, 1000, 2000],
            lasers: vec![0, 1],
            ambient,
        }
    }
    const RPM: f64 = 60e6 / (20.0 * 36000.0);
    const OFFSET: i64 = 1_700_000_000_000_000;

    fn event(s: &Schedule, seq: u64) -> TriggerEvent {
        let e = s.expected(seq);
        TriggerEvent {
            seq,
            encoder: e.encoder,
            facet: e.facet,
            revolution: e.revolution,
            t_us: 1000 + s.position(seq) * 20,
            lasers: e.lasers,
        }
    }

    fn frame(name: &str, time_us: i64) -> CapturedFrame {
        CapturedFrame::new(PathBuf::from(name), name.into(), time_us)
    }

    /// Feeds events (received 300 µs after firing) and frames (stamped `latency` after firing,
    /// seen 5 ms later), in time order; returns everything the pairer said.
    fn run(s: &Schedule, events: &[u64], frames: &[(u64, i64)], fired: u64) -> (Vec<PairEvent>, PairStats) {
        let mut p = Pairer::new(s.clone(), RPM, PairOptions::default());
        let mut timeline: Vec<(i64, Result<TriggerEvent, CapturedFrame>)> = Vec::new();
        for &seq in events {
            let ev = event(s, seq);
            timeline.push((ev.t_us as i64 + OFFSET + 300, Ok(ev)));
        }
        for &(seq, latency) in frames {
            let t = event(s, seq).t_us as i64 + OFFSET + latency;
            timeline.push((t + 5000, Err(frame(&format!("f{seq}.png"), t))));
        }
        timeline.sort_by_key(|(t, _)| *t);
        let mut out = Vec::new();
        let mut now = 0;
        for (t, item) in timeline {
            now = t;
            match item {
                Ok(ev) => out.extend(p.on_trigger(ev, t)),
                Err(f) => p.on_frame(f, t),
            }
            out.extend(p.tick(now));
        }
        out.extend(p.on_run_end(fired));
        out.extend(p.tick(now + 10_000_000));
        out.extend(p.drain());
        (out, p.stats)
    }

    fn paired(out: &[PairEvent]) -> Vec<(u64, String, f64, u32)> {
        out.iter()
            .filter_map(|e| match e {
                PairEvent::Paired(f) => Some((f.seq, f.path.clone(), f.alpha_deg, f.facet)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn directory_source_reports_only_new_complete_image_files_with_their_mtime() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("stale.png"), b"old run").unwrap();
        let mut src = DirFrameSource::new(dir.path()).unwrap().with_full_listing_every(std::time::Duration::ZERO);
        std::fs::write(dir.path().join(".tmp.png"), b"being written").unwrap();
        std::fs::write(dir.path().join("notes.txt"), b"not an image").unwrap();
        std::fs::write(dir.path().join("empty.png"), b"").unwrap();
        let f = std::fs::File::create(dir.path().join("b.PNG")).unwrap();
        let stamp = std::time::UNIX_EPOCH + std::time::Duration::from_micros(1_700_000_000_123_456);
        std::io::Write::write_all(&mut &f, b"png bytes").unwrap();
        f.set_modified(stamp).unwrap();
        drop(f);
        // First sight: the size is recorded; it is reported once it has not changed.
        assert!(src.poll().unwrap().is_empty());
        let got = src.poll().unwrap();
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!((got[0].name.as_str(), got[0].time_us), ("b.PNG", 1_700_000_000_123_456));
        assert!(src.poll().unwrap().is_empty(), "reported once");
        // A stale file rewritten by the camera (numbering restarted) is a new frame.
        let f = std::fs::File::create(dir.path().join("stale.png")).unwrap();
        std::io::Write::write_all(&mut &f, b"new frame").unwrap();
        f.set_modified(stamp + std::time::Duration::from_millis(5)).unwrap();
        drop(f);
        assert!(src.poll().unwrap().is_empty());
        let got = src.poll().unwrap();
        assert_eq!(got.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), vec!["stale.png"]);
    }

    #[test]
    fn stale_files_are_looked_at_only_on_full_listings_new_ones_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let stale = dir.path().join("stale.png");
        std::fs::write(&stale, b"old run").unwrap();
        let every = std::time::Duration::from_millis(1000);
        let mut src = DirFrameSource::new(dir.path()).unwrap().with_full_listing_every(every);
        assert!(src.poll().unwrap().is_empty(), "the first poll lists whole");
        // Rewritten in place: the directory does not change, so only a full listing sees it.
        let started = std::time::Instant::now();
        std::fs::write(&stale, b"a new frame").unwrap();
        std::fs::write(dir.path().join("new.png"), b"new").unwrap();
        let mut seen: Vec<(String, std::time::Duration)> = Vec::new();
        while seen.len() < 2 && started.elapsed() < 10 * every {
            let got = src.poll().unwrap();
            seen.extend(got.into_iter().map(|f| (f.name, started.elapsed())));
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let names: Vec<&str> = seen.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["new.png", "stale.png"], "{seen:?}");
        assert!(seen[0].1 < every / 2, "the new file waited for a full listing: {seen:?}");
        assert!(seen[1].1 >= every / 2, "the stale file was looked at every poll: {seen:?}");
    }

    #[test]
    fn clean_run_pairs_every_frame_with_its_own_angle() {
        let s = schedule(false);
        let all: Vec<u64> = (0..12).collect();
        let frames: Vec<(u64, i64)> = all.iter().map(|&q| (q, 1500)).collect();
        let (out, stats) = run(&s, &all, &frames, 12);
        let p = paired(&out);
        assert_eq!(p.len(), 12);
        for (seq, path, alpha, facet) in p {
            let e = s.expected(seq);
            assert_eq!(path, format!("f{seq}.png"));
            assert_eq!(facet, e.facet);
            assert!((alpha - e.count_in_facet as f64 * 0.01).abs() < 1e-12);
        }
        assert_eq!(stats.missing_total(), 0);
        assert_eq!(stats.frames_unmatched, 0);
    }

    #[test]
    fn a_missed_frame_is_reported_and_the_next_frame_is_not_shifted() {
        let s = schedule(false);
        let all: Vec<u64> = (0..12).collect();
        let frames: Vec<(u64, i64)> = all.iter().filter(|&&q| q != 4).map(|&q| (q, 0)).collect();
        let (out, stats) = run(&s, &all, &frames, 12);
        assert!(paired(&out).iter().all(|(seq, path, _, _)| *path == format!("f{seq}.png")));
        assert_eq!(paired(&out).len(), 11);
        assert!(out.iter().any(|e| matches!(e, PairEvent::FrameMissing { seq: 4, .. })));
        assert_eq!(stats.frames_missing, 1);
    }

    /// The event before the schedule's longest gap (320 ms here) is lost and its frame comes:
    /// the frame waits for the next event, which shows the loss and places the trigger, even
    /// when the gap is longer than the grace (a slow motor, few angles: seconds).
    #[test]
    fn a_frame_whose_event_is_lost_before_a_long_gap_waits_for_the_next_event() {
        let s = schedule(false);
        let mut p = Pairer::new(s.clone(), RPM, PairOptions { event_grace_us: 50_000, ..PairOptions::default() });
        let at = |seq| event(&s, seq).t_us as i64 + OFFSET;
        let mut out = Vec::new();
        for seq in 0..2 {
            out.extend(p.on_trigger(event(&s, seq), at(seq) + 300));
            p.on_frame(frame(&format!("f{seq}.png"), at(seq)), at(seq) + 5000);
            out.extend(p.tick(at(seq) + 5000));
        }
        p.on_frame(frame("f2.png", at(2)), at(2) + 5000);
        let mut now = at(2) + 5000;
        while now + 10_000 < at(3) {
            now += 10_000;
            out.extend(p.tick(now));
        }
        out.extend(p.on_trigger(event(&s, 3), at(3) + 300));
        p.on_frame(frame("f3.png", at(3)), at(3) + 5000);
        out.extend(p.tick(at(3) + 5000));
        let pairs: Vec<(u64, String)> = paired(&out).into_iter().map(|(seq, path, ..)| (seq, path)).collect();
        assert_eq!(pairs, [0, 1, 2, 3].map(|q| (q, format!("f{q}.png"))), "{out:?}");
        assert_eq!((p.stats.frames_unmatched, p.stats.paired_inferred), (0, 1));
    }

    #[test]
    fn lost_events_are_placed_from_the_schedule_and_still_pair_with_their_own_frames() {
        let s = schedule(false);
        let events: Vec<u64> = (0..12).filter(|&q| ![0, 5, 6, 11].contains(&q)).collect();
        let frames: Vec<(u64, i64)> = (0..12).map(|q| (q, 0)).collect();
        let (out, stats) = run(&s, &events, &frames, 12);
        let p = paired(&out);
        assert_eq!(p.len(), 12, "{out:?}");
        for (seq, path, alpha, facet) in &p {
            let e = s.expected(*seq);
            assert_eq!(*path, format!("f{seq}.png"));
            assert_eq!((*facet, *alpha), (e.facet, e.count_in_facet as f64 * 0.01));
        }
        let inferred: Vec<u64> = out
            .iter()
            .filter_map(|e| match e {
                PairEvent::Paired(f) if f.extra.contains_key("trigger_inferred") => Some(f.seq),
                _ => None,
            })
            .collect();
        assert_eq!(inferred, vec![0, 5, 6, 11], "first (extrapolated), a gap of two (interpolated), last (from DONE)");
        for f in out.iter().filter_map(|e| if let PairEvent::Paired(f) = e { Some(f) } else { None }) {
            assert_eq!(f.timestamp_us, Some(event(&s, f.seq).t_us), "placed times are exact at constant speed");
        }
        assert_eq!((stats.events_lost, stats.paired_inferred, stats.missing_total()), (4, 4, 0));
        assert_eq!(stats.frames_unmatched, 0);
    }

    #[test]
    fn a_frame_off_its_placed_trigger_time_is_not_paired() {
        let s = schedule(false);
        let events: Vec<u64> = (0..6).filter(|&q| q != 2).collect();
        // Frame 2 comes 10 ms late: beyond the ±8 ms window of its placed trigger.
        let frames: Vec<(u64, i64)> = (0..6).map(|q| (q, if q == 2 { 10_000 } else { 0 })).collect();
        let (out, stats) = run(&s, &events, &frames, 6);
        assert_eq!(paired(&out).len(), 5);
        assert_eq!((stats.frames_unmatched, stats.frames_missing), (1, 1));
    }

    #[test]
    fn duplicated_and_contradictory_events_are_dropped() {
        let s = schedule(false);
        let mut p = Pairer::new(s.clone(), RPM, PairOptions::default());
        assert!(p.on_trigger(event(&s, 0), OFFSET).is_empty());
        assert!(p.on_trigger(event(&s, 0), OFFSET).is_empty());
        let mut wrong = event(&s, 1);
        wrong.encoder += 1;
        assert!(matches!(p.on_trigger(wrong, OFFSET)[0], PairEvent::BadEvent(_)));
        assert_eq!((p.stats.events_duplicated, p.stats.bad_events, p.stats.triggers), (1, 1, 1));
    }

    #[test]
    fn latency_jitter_within_the_window_pairs_and_beyond_it_is_refused() {
        let s = schedule(false);
        let all: Vec<u64> = (0..6).collect();
        // ±6 ms jitter around 3 ms latency: inside the ±8 ms window once the estimate settles.
        let frames: Vec<(u64, i64)> =
            all.iter().map(|&q| (q, if q % 2 == 0 { 3000 + 5000 } else { 3000 - 5000 })).collect();
        let (out, _) = run(&s, &all, &frames, 6);
        assert_eq!(paired(&out).len(), 6);
        // A frame 12 ms late sits between triggers (window ±8 ms): unmatched, not guessed.
        let (out, stats) = run(&s, &all, &[(0, 0), (1, 0), (2, 12_000)], 6);
        assert_eq!(paired(&out).len(), 2);
        assert_eq!(stats.frames_unmatched, 1);
    }

    #[test]
    fn laser_frames_point_at_the_ambient_frame_of_the_previous_revolution() {
        let s = schedule(true);
        let all: Vec<u64> = (0..12).collect();
        let frames: Vec<(u64, i64)> = all.iter().map(|&q| (q, 0)).collect();
        let (out, _) = run(&s, &all, &frames, 12);
        let recs: Vec<&Frame> =
            out.iter().filter_map(|e| if let PairEvent::Paired(f) = e { Some(f.as_ref()) } else { None }).collect();
        assert_eq!(recs.len(), 12);
        for f in &recs[..6] {
            assert!(f.lasers.is_empty() && f.ambient_path.is_none());
        }
        for f in &recs[6..] {
            assert_eq!(f.lasers, vec![0, 1]);
            assert_eq!(f.ambient_path.as_deref(), Some(format!("f{}.png", f.seq - 6).as_str()));
        }
    }

    #[test]
    fn a_frame_naming_its_trigger_pairs_with_it_or_with_none() {
        let s = schedule(false);
        let mut p = Pairer::new(s.clone(), RPM, PairOptions::default());
        for seq in 0..4 {
            let ev = event(&s, seq);
            assert!(p.on_trigger(ev.clone(), ev.t_us as i64 + OFFSET).is_empty());
        }
        let at = |seq: u64, late_us: i64| event(&s, seq).t_us as i64 + OFFSET + late_us;
        let named =
            |seq: u64, time_us: i64| CapturedFrame { trigger_seq: Some(seq), ..frame(&format!("c{seq}.pgm"), time_us) };
        let mut extra = named(0, at(0, 1000));
        extra.extra.insert("camera_frame".into(), 7.into());
        // Named trigger 1, but exposed at trigger 2's time: beyond trigger 1's window, so not
        // paired, although trigger 2 would fit in time.
        let frames = [extra, named(1, at(2, 0)), named(0, at(0, 2000)), named(3, at(3, 500))];
        let mut out = Vec::new();
        for f in frames {
            p.on_frame(f, at(3, 6000));
        }
        out.extend(p.tick(at(3, 6000)));
        out.extend(p.drain());
        let got = paired(&out);
        assert_eq!(got.iter().map(|g| (g.0, g.1.as_str())).collect::<Vec<_>>(), vec![(0, "c0.pgm"), (3, "c3.pgm")]);
        let first = out.iter().find_map(|e| if let PairEvent::Paired(f) = e { Some(f) } else { None }).unwrap();
        assert_eq!(first.extra.get("camera_frame"), Some(&7.into()), "the source's fields reach the record");
        let unmatched: Vec<&String> = out
            .iter()
            .filter_map(|e| if let PairEvent::FrameUnmatched { reason, .. } = e { Some(reason) } else { None })
            .collect();
        assert_eq!(unmatched.len(), 2, "{out:?}");
        assert!(unmatched[0].contains("answered trigger (seq 1)"), "{}", unmatched[0]);
        assert!(unmatched[1].contains("seq 0, which is not waiting"), "{}", unmatched[1]);
        assert_eq!((p.stats.paired, p.stats.frames_missing), (2, 2));
    }
}
