//! The controller's logic as firmware would implement it, without I/O: command handling with
//! id-based retry safety, the trigger timeline of a run, and the counters. The emulator
//! ([`crate::emulator`]) drives it from a pseudo-terminal; tests drive it directly.

use crate::message::{
    Command, DeviceInfo, DeviceMessage, DeviceState, DeviceStatus, NakCode, PROTOCOL_VERSION, Request, TriggerEvent,
};
use crate::schedule::Schedule;
use std::collections::VecDeque;

/// The fixed properties of a controller.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerSpec {
    pub firmware: String,
    pub counts_per_rev: u32,
    pub facets: u32,
    pub lasers: u32,
    /// Highest trigger rate (Hz): the camera's frame rate limit.
    pub max_rate_hz: f64,
}

impl Default for ControllerSpec {
    /// 12 facets, 36000 counts per revolution (0.01° per count), 2 lasers, 50 Hz.
    fn default() -> Self {
        ControllerSpec {
            firmware: format!("omni-emu-{}", env!("CARGO_PKG_VERSION")),
            counts_per_rev: 36000,
            facets: 12,
            lasers: 2,
            max_rate_hz: 50.0,
        }
    }
}

/// Delay from START to the index pulse at which triggering begins (µs).
const START_DELAY_US: u64 = 20_000;
/// Slowest motor speed accepted (rev/min), 0 aside: slower, a run's trigger times overflow the
/// clock (found by omni-fuzz: `SPEED 9 3e-319`).
pub const MIN_RPM: f64 = 1e-3;
/// Ids remembered for retry detection.
const REMEMBERED_IDS: usize = 64;
/// Stall watch (firmware/src/config.h): a running run faults when the encoder count has not
/// changed for this many count periods at its speed, checked every [`STALL_CHECK_US`], for at
/// least [`STALL_MIN_CHECKS`] checks.
pub const STALL_COUNTS: f64 = 16.0;
/// Period of the firmware's stall check (its Timer1 overflow: 65 536 ticks of 0.5 µs).
pub const STALL_CHECK_US: u64 = 32_768;
pub const STALL_MIN_CHECKS: u64 = 2;

/// How long after the last encoder count the stall watch faults a run at `us_per_count` µs per
/// count: the firmware's earliest (it detects within one check period after this).
pub fn stall_timeout_us(us_per_count: f64) -> u64 {
    let checks = (STALL_COUNTS * us_per_count / STALL_CHECK_US as f64).ceil() as u64;
    checks.max(STALL_MIN_CHECKS) * STALL_CHECK_US
}

#[derive(Debug, Clone)]
struct Run {
    schedule: Schedule,
    start_us: u64,
    us_per_count: f64,
    /// Revolutions to run (0 = until STOP).
    revolutions: u64,
    next_seq: u64,
    stop_requested: bool,
    /// The polygon stops after this many of the run's triggers (a stalled motor).
    stall_after: Option<u64>,
}

impl Run {
    fn total(&self) -> Option<u64> {
        // Saturating: `START ID 18446744073709551615` is "until STOP" in all but name.
        (self.revolutions > 0).then(|| self.revolutions.saturating_mul(self.schedule.per_revolution()))
    }

    fn time_of(&self, seq: u64) -> u64 {
        self.start_us + (self.schedule.position(seq) as f64 * self.us_per_count).round() as u64
    }
}

/// A controller: feed it command lines and the clock, collect its output lines.
#[derive(Debug)]
pub struct Controller {
    spec: ControllerSpec,
    state: DeviceState,
    counts: Vec<u32>,
    facets: Option<Vec<u32>>,
    lasers: Vec<u32>,
    ambient: bool,
    rpm_requested: f64,
    armed: Option<(Schedule, f64)>,
    run: Option<Run>,
    fired: u64,
    overruns: u64,
    crc_errors: u64,
    fault: Option<String>,
    answered: VecDeque<(u32, DeviceMessage)>,
}

impl Controller {
    pub fn new(spec: ControllerSpec) -> Self {
        let lasers = (0..spec.lasers).collect();
        Controller {
            spec,
            state: DeviceState::Idle,
            counts: vec![],
            facets: None,
            lasers,
            ambient: false,
            rpm_requested: 0.0,
            armed: None,
            run: None,
            fired: 0,
            overruns: 0,
            crc_errors: 0,
            fault: None,
            answered: VecDeque::new(),
        }
    }

    pub fn info(&self) -> DeviceInfo {
        DeviceInfo {
            protocol: PROTOCOL_VERSION,
            firmware: self.spec.firmware.clone(),
            counts_per_rev: self.spec.counts_per_rev,
            facets: self.spec.facets,
            lasers: self.spec.lasers,
            max_rate_hz: self.spec.max_rate_hz,
        }
    }

    pub fn state(&self) -> DeviceState {
        self.state
    }

    /// Counts a received line dropped for a bad checksum.
    pub fn count_crc_error(&mut self) {
        self.crc_errors += 1;
    }

    /// Counts a trigger that could not be delivered in time.
    pub fn count_overrun(&mut self) {
        self.overruns += 1;
    }

    pub fn status(&self, now_us: u64) -> DeviceStatus {
        DeviceStatus {
            state: self.state,
            fired: self.fired,
            overruns: self.overruns,
            crc_errors: self.crc_errors,
            rpm: self.armed.as_ref().map(|a| a.1).unwrap_or(0.0),
            t_us: now_us,
            fault: self.fault.clone(),
        }
    }

    /// The polygon stops turning right after the run's `triggers`-th trigger (0: before the
    /// first index): nothing fires after it. As in the firmware, the run then faults
    /// [`stall_timeout_us`] after that trigger (`fault=stall`, a `STS` at once) and stays running,
    /// firing nothing, until `STOP`; a run stalled before its first index is not watched and
    /// just waits. No effect without a run.
    pub fn stall_motor_after(&mut self, triggers: u64) {
        if let Some(run) = &mut self.run {
            run.stall_after = Some(triggers);
        }
    }

    /// Handles one verified command line; returns the lines to send back.
    pub fn handle_line(&mut self, body: &str, now_us: u64) -> Vec<DeviceMessage> {
        let req = match Request::parse(body) {
            Ok(r) => r,
            Err(e) => {
                // A command whose id cannot be read cannot be answered: the host will retry.
                return e
                    .id
                    .map(|id| vec![DeviceMessage::Nak { id, code: e.code as u32, reason: e.message }])
                    .unwrap_or_default();
            }
        };
        let is_query = matches!(req.command, Command::Hello | Command::Status);
        if let Some((_, reply)) = self.answered.iter().find(|(id, _)| *id == req.id) {
            // A retry: answer again, never execute again. Queries are harmless to re-answer fresh.
            let reply = reply.clone();
            let mut out = if is_query { self.query_lines(&req.command, now_us) } else { vec![] };
            out.push(reply);
            return out;
        }
        let result = self.execute(&req.command, now_us);
        let reply = match result {
            Ok(()) => DeviceMessage::Ack { id: req.id },
            Err((code, reason)) => DeviceMessage::Nak { id: req.id, code: code as u32, reason },
        };
        self.answered.push_back((req.id, reply.clone()));
        if self.answered.len() > REMEMBERED_IDS {
            self.answered.pop_front();
        }
        let mut out = if is_query { self.query_lines(&req.command, now_us) } else { vec![] };
        out.push(reply);
        out
    }

    fn query_lines(&self, command: &Command, now_us: u64) -> Vec<DeviceMessage> {
        match command {
            Command::Hello => vec![DeviceMessage::Hello(self.info())],
            Command::Status => vec![DeviceMessage::Status(self.status(now_us))],
            _ => vec![],
        }
    }

    fn execute(&mut self, command: &Command, now_us: u64) -> Result<(), (NakCode, String)> {
        let configuring = !matches!(command, Command::Hello | Command::Status | Command::Stop | Command::Start { .. });
        if configuring && self.state == DeviceState::Running {
            return Err((NakCode::WrongState, "running: STOP first".into()));
        }
        let per_facet = self.spec.counts_per_rev / self.spec.facets;
        let bad = |m: String| Err((NakCode::BadArgument, m));
        match command {
            Command::Hello | Command::Status => {}
            Command::AnglesSet(c) | Command::AnglesAdd(c) => {
                let mut all = if matches!(command, Command::AnglesAdd(_)) { self.counts.clone() } else { vec![] };
                all.extend_from_slice(c);
                if !all.windows(2).all(|w| w[0] < w[1]) || all.iter().any(|&x| x >= per_facet) {
                    return bad(format!("angles must increase and stay below {per_facet}"));
                }
                self.counts = all;
                self.disarm();
            }
            Command::AnglesRange { start, stop, step } => {
                if *step == 0 || start >= stop || *stop > per_facet {
                    return bad(format!("range needs step>0, start<stop<={per_facet}"));
                }
                self.counts = (*start..*stop).step_by(*step as usize).collect();
                self.disarm();
            }
            Command::Facets(f) => {
                if let Some(f) = f
                    && (f.is_empty() || !f.windows(2).all(|w| w[0] < w[1]) || f.iter().any(|&k| k >= self.spec.facets))
                {
                    return bad(format!("facets must increase and stay below {}", self.spec.facets));
                }
                self.facets = f.clone();
                self.disarm();
            }
            Command::Lasers(l) => {
                if !l.windows(2).all(|w| w[0] < w[1]) || l.iter().any(|&j| j >= self.spec.lasers) {
                    return bad(format!("lasers must increase and stay below {}", self.spec.lasers));
                }
                self.lasers = l.clone();
                self.disarm();
            }
            Command::Ambient(on) => {
                self.ambient = *on;
                self.disarm();
            }
            Command::Speed(rpm) => {
                if !(rpm.is_finite() && (*rpm == 0.0 || *rpm >= MIN_RPM)) {
                    return bad(format!("speed must be 0 or at least {MIN_RPM} rpm"));
                }
                self.rpm_requested = *rpm;
                self.disarm();
            }
            Command::Arm => self.arm()?,
            Command::Start { revolutions } => {
                let Some((schedule, rpm)) = self.armed.clone() else {
                    return Err((NakCode::WrongState, "not armed".into()));
                };
                if self.state == DeviceState::Running {
                    return Err((NakCode::WrongState, "already running".into()));
                }
                let us_per_count = 60e6 / (rpm * self.spec.counts_per_rev as f64);
                self.run = Some(Run {
                    schedule,
                    start_us: now_us + START_DELAY_US,
                    us_per_count,
                    revolutions: *revolutions,
                    next_seq: 0,
                    stop_requested: false,
                    stall_after: None,
                });
                self.state = DeviceState::Running;
            }
            Command::Stop => {
                // The DONE line follows from `poll`.
                match &mut self.run {
                    Some(run) => run.stop_requested = true,
                    None => self.disarm(),
                }
            }
        }
        Ok(())
    }

    fn disarm(&mut self) {
        self.armed = None;
        self.state = DeviceState::Idle;
    }

    fn arm(&mut self) -> Result<(), (NakCode, String)> {
        if self.counts.is_empty() {
            return Err((NakCode::WrongState, "no trigger angles".into()));
        }
        let schedule = Schedule {
            counts_per_rev: self.spec.counts_per_rev,
            facets_total: self.spec.facets,
            facets: self.facets.clone().unwrap_or_else(|| (0..self.spec.facets).collect()),
            counts: self.counts.clone(),
            lasers: self.lasers.clone(),
            ambient: self.ambient,
        };
        schedule.validate().map_err(|e| (NakCode::BadArgument, e))?;
        let max_rpm = max_rpm(&schedule, self.spec.max_rate_hz);
        let rpm = if self.rpm_requested == 0.0 { max_rpm } else { self.rpm_requested };
        if rpm > max_rpm * (1.0 + 1e-9) {
            return Err((
                NakCode::RateLimit,
                format!("{rpm} rpm exceeds {max_rpm:.3} rpm at {} Hz", self.spec.max_rate_hz),
            ));
        }
        self.armed = Some((schedule, rpm));
        self.fault = None;
        self.fired = 0;
        self.overruns = 0;
        self.state = DeviceState::Armed;
        Ok(())
    }

    /// Controller time (µs) of the next trigger, if a run is going.
    pub fn next_trigger_us(&self) -> Option<u64> {
        let run = self.run.as_ref()?;
        Some(run.time_of(run.next_seq))
    }

    /// Advances the clock to `now_us`: the triggers that fired by then (each stamped with its
    /// own firing time and encoder position, as the hardware timer latched them) and, when the
    /// run is over, `DONE`.
    pub fn poll(&mut self, now_us: u64) -> Vec<DeviceMessage> {
        let mut out = Vec::new();
        let Some(run) = &mut self.run else { return out };
        while !run.stop_requested
            && run.total().is_none_or(|n| run.next_seq < n)
            && run.stall_after.is_none_or(|k| run.next_seq < k)
            && run.time_of(run.next_seq) <= now_us
        {
            let seq = run.next_seq;
            let e = run.schedule.expected(seq);
            out.push(DeviceMessage::Trigger(TriggerEvent {
                seq,
                encoder: e.encoder,
                facet: e.facet,
                revolution: e.revolution,
                t_us: run.time_of(seq),
                lasers: e.lasers,
            }));
            run.next_seq += 1;
            self.fired += 1;
        }
        if run.stop_requested || run.total().is_some_and(|n| run.next_seq >= n) {
            out.push(DeviceMessage::Done { fired: self.fired, t_us: now_us });
            self.run = None;
            self.disarm();
        } else if self.fault.is_none()
            && let Some(k) = run.stall_after.filter(|&k| k > 0 && run.next_seq >= k)
            && now_us >= run.time_of(k - 1) + stall_timeout_us(run.us_per_count)
        {
            self.fault = Some("stall".into());
            out.push(DeviceMessage::Status(self.status(now_us)));
        }
        out
    }
}

/// Fastest motor speed (rev/min) at which no two consecutive triggers of `schedule` come closer
/// than `1 / max_rate_hz`.
pub fn max_rpm(schedule: &Schedule, max_rate_hz: f64) -> f64 {
    let per_rev = schedule.per_revolution();
    let min_gap_counts = (0..per_rev)
        .map(|s| schedule.position(s + 1) - schedule.position(s))
        .min()
        .unwrap_or(schedule.counts_per_rev as u64)
        .max(1);
    let min_gap_us = 1e6 / max_rate_hz;
    let us_per_count = min_gap_us / min_gap_counts as f64;
    60e6 / (us_per_count * schedule.counts_per_rev as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(c: &mut Controller, body: &str, now: u64) -> Vec<String> {
        c.handle_line(body, now).iter().map(|m| m.to_body()).collect()
    }

    fn configured() -> Controller {
        let mut c = Controller::new(ControllerSpec::default());
        assert_eq!(lines(&mut c, "ANGLES 1 RANGE 0 3000 1000", 0), vec!["ACK 1"]);
        assert_eq!(lines(&mut c, "FACETS 2 0,6", 0), vec!["ACK 2"]);
        c
    }

    #[test]
    fn a_repeated_id_is_acknowledged_but_not_executed_again() {
        let mut c = configured();
        assert_eq!(lines(&mut c, "ANGLES 3 ADD 2500", 0), vec!["ACK 3"]);
        // The retry of id 3 must not append 2500 a second time (that would NAK: not increasing).
        assert_eq!(lines(&mut c, "ANGLES 3 ADD 2500", 0), vec!["ACK 3"]);
        assert_eq!(c.counts, vec![0, 1000, 2000, 2500]);
        assert_eq!(lines(&mut c, "ANGLES 4 ADD 2500", 0), vec!["NAK 4 3 angles must increase and stay below 3000"]);
    }

    #[test]
    fn start_before_arm_and_configure_while_running_are_refused() {
        let mut c = configured();
        assert!(lines(&mut c, "START 5 1", 0)[0].starts_with("NAK 5 4"));
        assert_eq!(lines(&mut c, "ARM 6", 0), vec!["ACK 6"]);
        assert_eq!(lines(&mut c, "START 7 1", 0), vec!["ACK 7"]);
        assert!(lines(&mut c, "FACETS 8 ALL", 0)[0].starts_with("NAK 8 4"));
        let hello = lines(&mut c, "HELLO 9", 0);
        assert_eq!(hello.len(), 2);
        assert!(hello[0].starts_with("HELLO proto=1 ") && hello[1] == "ACK 9");
        assert!(lines(&mut c, "JUMP 10", 0)[0].starts_with("NAK 10 2"));
    }

    #[test]
    fn a_run_fires_the_schedule_at_the_right_times_then_done() {
        let mut c = configured();
        lines(&mut c, "ARM 3", 0);
        // 50 Hz and a smallest gap of 1000 counts (10°) give 20 ms per 1000 counts.
        let st = c.status(0);
        let us_per_count = 60e6 / (st.rpm * 36000.0);
        assert!((us_per_count - 20.0).abs() < 1e-9, "{us_per_count}");
        lines(&mut c, "START 4 2", 1000);
        let mut events = Vec::new();
        let mut now = 0;
        while c.state() == DeviceState::Running {
            now += 5000;
            events.extend(c.poll(now));
        }
        let trg: Vec<&TriggerEvent> =
            events.iter().filter_map(|m| if let DeviceMessage::Trigger(t) = m { Some(t) } else { None }).collect();
        assert_eq!(trg.len(), 12, "2 revolutions x 2 facets x 3 angles");
        assert_eq!(events.last(), Some(&DeviceMessage::Done { fired: 12, t_us: now }));
        // Trigger 4 = revolution 0, facet 6, count 1000: position 19000 counts after the index.
        assert_eq!((trg[4].facet, trg[4].encoder, trg[4].revolution), (6, 19000, 0));
        assert_eq!(trg[4].t_us, 1000 + START_DELAY_US + 19000 * 20);
        // Trigger 7 = revolution 1, facet 0, count 1000.
        assert_eq!(trg[7].t_us, 1000 + START_DELAY_US + (36000 + 1000) * 20);
        assert!(trg.windows(2).all(|w| w[1].t_us - w[0].t_us >= 20_000), "never faster than 50 Hz");
    }

    #[test]
    fn a_stalled_motor_faults_the_run_once_after_the_stall_timeout_and_stop_ends_it() {
        let mut c = configured();
        lines(&mut c, "ARM 3", 0);
        lines(&mut c, "START 4 2", 1000);
        c.stall_motor_after(2);
        // 20 µs per count: trigger 1 (count 1000) at 1000 + START_DELAY_US + 20 000 µs.
        let last = 1000 + START_DELAY_US + 1000 * 20;
        let trg = |m: &[DeviceMessage]| m.iter().filter(|m| matches!(m, DeviceMessage::Trigger(_))).count();
        assert_eq!(trg(&c.poll(last)), 2);
        // 16 count periods are 320 µs: the floor of two 32.768 ms checks applies.
        assert_eq!(stall_timeout_us(20.0), 65_536);
        assert!(c.poll(last + 65_535).is_empty(), "no trigger, no fault before the timeout");
        let out = c.poll(last + 65_536);
        let [DeviceMessage::Status(s)] = out.as_slice() else { panic!("{out:?}") };
        assert_eq!((s.state, s.fired, s.fault.as_deref()), (DeviceState::Running, 2, Some("stall")));
        assert!(c.poll(last + 10_000_000).is_empty(), "reported once, nothing fires, the run goes on");
        lines(&mut c, "STOP 5", last + 10_000_000);
        assert_eq!(c.poll(last + 10_000_001), vec![DeviceMessage::Done { fired: 2, t_us: last + 10_000_001 }]);
        assert_eq!(c.status(0).fault.as_deref(), Some("stall"), "kept until the next ARM");
        lines(&mut c, "ARM 6", 0);
        assert_eq!(c.status(0).fault, None);
    }

    #[test]
    fn the_stall_timeout_is_sixteen_count_periods_in_whole_checks_as_the_firmware_computes_it() {
        // 0.01 rpm at 36 000 counts: 166 667 µs per count; 16 of them are 81.4 checks of 32.768 ms.
        assert_eq!(stall_timeout_us(60e6 / (0.01 * 36000.0)), 82 * 32_768);
        assert_eq!(stall_timeout_us(60e6 / (60.0 * 36000.0)), 2 * 32_768);
    }

    #[test]
    fn requested_speed_above_the_rate_limit_is_refused() {
        let mut c = configured();
        lines(&mut c, "SPEED 3 1000", 0);
        let r = lines(&mut c, "ARM 4", 0);
        assert!(r[0].starts_with("NAK 4 5"), "{r:?}");
        lines(&mut c, "SPEED 5 80", 0);
        assert_eq!(lines(&mut c, "ARM 6", 0), vec!["ACK 6"]);
    }

    #[test]
    fn a_speed_too_slow_for_the_clock_and_endless_revolutions_are_handled() {
        let mut c = configured();
        let r = lines(&mut c, "SPEED 3 3.051e-319", 0);
        assert!(r[0].starts_with("NAK 3 3 speed must be 0 or at least"), "{r:?}");
        assert_eq!(lines(&mut c, "SPEED 4 0.001", 0), vec!["ACK 4"]);
        assert_eq!(lines(&mut c, "ARM 5", 0), vec!["ACK 5"]);
        assert_eq!(lines(&mut c, "START 6 18446744073709551615", 0), vec!["ACK 6"]);
        // Count 0 fires at the index pulse; count 1000 comes 1000 × 1.67 s later at 0.001 rpm.
        assert_eq!(c.poll(1_000_000).len(), 1);
        assert_eq!(lines(&mut c, "STOP 7", 2_000_000), vec!["ACK 7"]);
        assert!(matches!(c.poll(2_000_000).last(), Some(DeviceMessage::Done { .. })));
    }
}
