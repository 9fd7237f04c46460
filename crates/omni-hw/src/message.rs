//! The messages inside protocol lines (see `docs/PROTOCOL.md`): host commands with ids, and
//! the controller's replies and events. Pure parsing and formatting, no I/O.
//!
//! Bodies are words separated by single spaces. Commands are `VERB ID ARGS…`; controller
//! messages are `ACK ID`, `NAK ID CODE REASON…`, or a type word followed by `key=value` fields
//! (unknown keys are ignored so later firmware can add fields).

use std::collections::HashMap;

/// The protocol version this crate speaks (`proto=` in `HELLO`).
pub const PROTOCOL_VERSION: u32 = 1;

/// A host command (the part after the id).
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Ask for the controller description.
    Hello,
    /// Replace the trigger angles: encoder counts within a facet, strictly increasing.
    AnglesSet(Vec<u32>),
    /// Append trigger angles (counts within a facet) after the current last one.
    AnglesAdd(Vec<u32>),
    /// Replace the trigger angles by `start, start+step, …` below `stop` (counts, half-open).
    AnglesRange { start: u32, stop: u32, step: u32 },
    /// Facets that trigger, strictly increasing; `None` = all.
    Facets(Option<Vec<u32>>),
    /// Lasers switched on during laser frames (empty = none).
    Lasers(Vec<u32>),
    /// Interleave laser-off revolutions for ambient subtraction.
    Ambient(bool),
    /// Motor speed in revolutions per minute; 0 = the fastest the trigger rate limit allows.
    Speed(f64),
    /// Validate the configuration and arm the trigger output.
    Arm,
    /// Start triggering at the next index pulse for this many revolutions (0 = until STOP).
    Start { revolutions: u64 },
    /// Stop triggering (ends the run with `DONE`).
    Stop,
    /// Ask for a `STS` line.
    Status,
}

/// A command with its id, as sent on the wire.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    pub id: u32,
    pub command: Command,
}

/// Reasons for a `NAK`, as numeric codes on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NakCode {
    /// The line parsed but the command's words do not.
    Syntax = 1,
    /// Unknown verb.
    UnknownCommand = 2,
    /// A value is out of range (angle beyond the facet, unknown laser, …).
    BadArgument = 3,
    /// Not allowed now (configure while running, START before ARM, ARM without angles, …).
    WrongState = 4,
    /// The requested speed would exceed the trigger rate limit.
    RateLimit = 5,
}

impl NakCode {
    pub fn from_u32(v: u32) -> Option<NakCode> {
        Some(match v {
            1 => NakCode::Syntax,
            2 => NakCode::UnknownCommand,
            3 => NakCode::BadArgument,
            4 => NakCode::WrongState,
            5 => NakCode::RateLimit,
            _ => return None,
        })
    }
}

/// The controller's description (`HELLO` reply).
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceInfo {
    /// Protocol version.
    pub protocol: u32,
    /// Firmware version string (one word).
    pub firmware: String,
    /// Encoder counts per polygon revolution (a multiple of `facets`).
    pub counts_per_rev: u32,
    /// Number of polygon facets.
    pub facets: u32,
    /// Number of lasers.
    pub lasers: u32,
    /// Highest trigger rate the controller (and camera) sustains (Hz).
    pub max_rate_hz: f64,
}

impl DeviceInfo {
    /// Encoder counts per facet.
    pub fn counts_per_facet(&self) -> u32 {
        self.counts_per_rev / self.facets.max(1)
    }

    /// Mirror angle of one encoder count (degrees).
    pub fn degrees_per_count(&self) -> f64 {
        360.0 / self.counts_per_rev as f64
    }
}

/// One fired trigger.
#[derive(Debug, Clone, PartialEq)]
pub struct TriggerEvent {
    /// Sequence number since ARM, from 0; a gap means lost events.
    pub seq: u64,
    /// Encoder count within the revolution when the trigger fired.
    pub encoder: u32,
    /// Facet facing laser 0.
    pub facet: u32,
    /// Revolution since START, from 0.
    pub revolution: u64,
    /// Controller clock (µs since power-up).
    pub t_us: u64,
    /// Lasers that were on (empty = laser-off frame).
    pub lasers: Vec<u32>,
}

/// The controller's run state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceState {
    Idle,
    Armed,
    Running,
}

impl DeviceState {
    pub fn as_str(self) -> &'static str {
        match self {
            DeviceState::Idle => "idle",
            DeviceState::Armed => "armed",
            DeviceState::Running => "running",
        }
    }
}

/// Periodic and requested status counters.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceStatus {
    pub state: DeviceState,
    /// Triggers fired since ARM.
    pub fired: u64,
    /// Triggers that could not be fired in time (trigger output or event queue still busy).
    pub overruns: u64,
    /// Received lines dropped for a bad checksum.
    pub crc_errors: u64,
    /// Motor speed in use (rev/min).
    pub rpm: f64,
    /// Controller clock (µs).
    pub t_us: u64,
    /// The run's fault (`fault=` word, absent when there is none): `stall` = the encoder stopped
    /// during the run, the controller switched the trigger and lasers off and fires no more.
    pub fault: Option<String>,
}

/// What a controller fault word means, for people (docs/PROTOCOL.md §4).
pub fn describe_fault(fault: &str) -> String {
    match fault {
        "stall" => "the encoder stopped during the run (a stalled polygon motor or a dead encoder); the controller \
                    switched the trigger and lasers off"
            .into(),
        other => format!("a fault this host does not know ({other:?})"),
    }
}

/// A line from the controller.
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceMessage {
    Ack {
        id: u32,
    },
    Nak {
        id: u32,
        code: u32,
        reason: String,
    },
    Hello(DeviceInfo),
    Trigger(TriggerEvent),
    Status(DeviceStatus),
    /// The run ended (revolutions done or STOP); `fired` = total triggers of the run.
    Done {
        fired: u64,
        t_us: u64,
    },
}

/// Why a body could not be understood.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// The command id, when it could be read (so a controller can NAK it).
    pub id: Option<u32>,
    pub code: NakCode,
    pub message: String,
}

impl std::fmt::Display for ParseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

fn err(id: Option<u32>, code: NakCode, message: impl Into<String>) -> ParseError {
    ParseError { id, code, message: message.into() }
}

/// `0,1,2` or `NONE`.
pub fn format_list(values: &[u32]) -> String {
    if values.is_empty() {
        return "NONE".into();
    }
    values.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(",")
}

/// Parses `0,1,2` or `NONE`.
pub fn parse_list(word: &str) -> Result<Vec<u32>, String> {
    if word == "NONE" {
        return Ok(vec![]);
    }
    word.split(',').map(|w| w.parse::<u32>().map_err(|_| format!("bad number {w:?} in list {word:?}"))).collect()
}

fn parse_num<T: std::str::FromStr>(word: Option<&&str>, what: &str) -> Result<T, String> {
    let w = word.ok_or_else(|| format!("missing {what}"))?;
    w.parse().map_err(|_| format!("bad {what} {w:?}"))
}

impl Request {
    pub fn new(id: u32, command: Command) -> Self {
        Request { id, command }
    }

    /// The line body, e.g. `ANGLES 7 SET 0,50,100`.
    pub fn to_body(&self) -> String {
        let id = self.id;
        match &self.command {
            Command::Hello => format!("HELLO {id}"),
            Command::AnglesSet(c) => format!("ANGLES {id} SET {}", format_list(c)),
            Command::AnglesAdd(c) => format!("ANGLES {id} ADD {}", format_list(c)),
            Command::AnglesRange { start, stop, step } => format!("ANGLES {id} RANGE {start} {stop} {step}"),
            Command::Facets(None) => format!("FACETS {id} ALL"),
            Command::Facets(Some(f)) => format!("FACETS {id} {}", format_list(f)),
            Command::Lasers(l) => format!("LASERS {id} {}", format_list(l)),
            Command::Ambient(on) => format!("AMBIENT {id} {}", u8::from(*on)),
            Command::Speed(rpm) => format!("SPEED {id} {rpm}"),
            Command::Arm => format!("ARM {id}"),
            Command::Start { revolutions } => format!("START {id} {revolutions}"),
            Command::Stop => format!("STOP {id}"),
            Command::Status => format!("STATUS {id}"),
        }
    }

    /// Parses a command body (the controller side).
    pub fn parse(body: &str) -> Result<Request, ParseError> {
        let words: Vec<&str> = body.split(' ').collect();
        let verb = words[0];
        let id: u32 = match words.get(1).map(|w| w.parse()) {
            Some(Ok(id)) => id,
            _ => return Err(err(None, NakCode::Syntax, format!("{verb}: missing or bad command id"))),
        };
        let args = &words[2..];
        let syntax = |m: String| err(Some(id), NakCode::Syntax, format!("{verb}: {m}"));
        let no_args = |c: Command| if args.is_empty() { Ok(c) } else { Err(syntax("unexpected arguments".into())) };
        let one_arg = || if args.len() == 1 { Ok(args[0]) } else { Err(syntax("expected one argument".into())) };
        let command = match verb {
            "HELLO" => no_args(Command::Hello)?,
            "ARM" => no_args(Command::Arm)?,
            "STOP" => no_args(Command::Stop)?,
            "STATUS" => no_args(Command::Status)?,
            "START" => Command::Start { revolutions: parse_num(args.first(), "revolutions").map_err(syntax)? },
            "SPEED" => Command::Speed(parse_num(args.first(), "rpm").map_err(syntax)?),
            "AMBIENT" => match one_arg()? {
                "0" => Command::Ambient(false),
                "1" => Command::Ambient(true),
                other => return Err(syntax(format!("expected 0 or 1, got {other:?}"))),
            },
            "LASERS" => Command::Lasers(parse_list(one_arg()?).map_err(syntax)?),
            "FACETS" => match one_arg()? {
                "ALL" => Command::Facets(None),
                list => Command::Facets(Some(parse_list(list).map_err(syntax)?)),
            },
            "ANGLES" => match (args.first().copied(), args.len()) {
                (Some("SET"), 2) => Command::AnglesSet(parse_list(args[1]).map_err(syntax)?),
                (Some("ADD"), 2) => Command::AnglesAdd(parse_list(args[1]).map_err(syntax)?),
                (Some("RANGE"), 4) => Command::AnglesRange {
                    start: parse_num(args.get(1), "start").map_err(syntax)?,
                    stop: parse_num(args.get(2), "stop").map_err(syntax)?,
                    step: parse_num(args.get(3), "step").map_err(syntax)?,
                },
                _ => return Err(syntax("expected SET list, ADD list or RANGE start stop step".into())),
            },
            _ => return Err(err(Some(id), NakCode::UnknownCommand, format!("unknown command {verb:?}"))),
        };
        Ok(Request { id, command })
    }
}

/// `key=value` fields of a controller message.
struct Fields<'a> {
    kind: &'a str,
    map: HashMap<&'a str, &'a str>,
}

impl<'a> Fields<'a> {
    fn parse(kind: &'a str, words: &[&'a str]) -> Result<Self, String> {
        let mut map = HashMap::new();
        for w in words {
            let (k, v) = w.split_once('=').ok_or_else(|| format!("{kind}: expected key=value, got {w:?}"))?;
            map.insert(k, v);
        }
        Ok(Fields { kind, map })
    }

    fn get<T: std::str::FromStr>(&self, key: &str) -> Result<T, String> {
        let v = self.map.get(key).ok_or_else(|| format!("{}: missing field {key}", self.kind))?;
        v.parse().map_err(|_| format!("{}: bad value {v:?} for field {key}", self.kind))
    }

    fn finite(&self, key: &str) -> Result<f64, String> {
        let v: f64 = self.get(key)?;
        if v.is_finite() { Ok(v) } else { Err(format!("{}: field {key} is not finite", self.kind)) }
    }

    fn list(&self, key: &str) -> Result<Vec<u32>, String> {
        let v = self.map.get(key).ok_or_else(|| format!("{}: missing field {key}", self.kind))?;
        parse_list(v).map_err(|e| format!("{}: field {key}: {e}", self.kind))
    }
}

impl DeviceMessage {
    /// The line body, e.g. `TRG seq=3 enc=1250 facet=0 rev=0 t=52100 las=0,1`.
    pub fn to_body(&self) -> String {
        match self {
            DeviceMessage::Ack { id } => format!("ACK {id}"),
            DeviceMessage::Nak { id, code, reason } => format!("NAK {id} {code} {reason}"),
            DeviceMessage::Hello(i) => format!(
                "HELLO proto={} fw={} cpr={} facets={} lasers={} max_hz={}",
                i.protocol, i.firmware, i.counts_per_rev, i.facets, i.lasers, i.max_rate_hz
            ),
            DeviceMessage::Trigger(e) => format!(
                "TRG seq={} enc={} facet={} rev={} t={} las={}",
                e.seq,
                e.encoder,
                e.facet,
                e.revolution,
                e.t_us,
                format_list(&e.lasers)
            ),
            DeviceMessage::Status(s) => format!(
                "STS state={} fired={} overruns={} crc={} rpm={} t={}{}",
                s.state.as_str(),
                s.fired,
                s.overruns,
                s.crc_errors,
                s.rpm,
                s.t_us,
                s.fault.as_ref().map(|f| format!(" fault={f}")).unwrap_or_default()
            ),
            DeviceMessage::Done { fired, t_us } => format!("DONE fired={fired} t={t_us}"),
        }
    }

    /// Parses a controller line body (the host side). The error names the field at fault.
    pub fn parse(body: &str) -> Result<DeviceMessage, String> {
        let words: Vec<&str> = body.split(' ').collect();
        let kind = words[0];
        let id =
            || -> Result<u32, String> { parse_num(words.get(1), "command id").map_err(|e| format!("{kind}: {e}")) };
        match kind {
            "ACK" => Ok(DeviceMessage::Ack { id: id()? }),
            "NAK" => Ok(DeviceMessage::Nak {
                id: id()?,
                code: parse_num(words.get(2), "NAK code").map_err(|e| format!("NAK: {e}"))?,
                reason: words.get(3..).map(|w| w.join(" ")).unwrap_or_default(),
            }),
            "HELLO" => {
                let f = Fields::parse(kind, &words[1..])?;
                let info = DeviceInfo {
                    protocol: f.get("proto")?,
                    firmware: f.get("fw")?,
                    counts_per_rev: f.get("cpr")?,
                    facets: f.get("facets")?,
                    lasers: f.get("lasers")?,
                    max_rate_hz: f.finite("max_hz")?,
                };
                Ok(DeviceMessage::Hello(info))
            }
            "TRG" => {
                let f = Fields::parse(kind, &words[1..])?;
                Ok(DeviceMessage::Trigger(TriggerEvent {
                    seq: f.get("seq")?,
                    encoder: f.get("enc")?,
                    facet: f.get("facet")?,
                    revolution: f.get("rev")?,
                    t_us: f.get("t")?,
                    lasers: f.list("las")?,
                }))
            }
            "STS" => {
                let f = Fields::parse(kind, &words[1..])?;
                let state = match f.map.get("state").copied() {
                    Some("idle") => DeviceState::Idle,
                    Some("armed") => DeviceState::Armed,
                    Some("running") => DeviceState::Running,
                    other => return Err(format!("STS: bad value {other:?} for field state")),
                };
                Ok(DeviceMessage::Status(DeviceStatus {
                    state,
                    fired: f.get("fired")?,
                    overruns: f.get("overruns")?,
                    crc_errors: f.get("crc")?,
                    rpm: f.finite("rpm")?,
                    t_us: f.get("t")?,
                    fault: f.map.get("fault").map(|v| v.to_string()),
                }))
            }
            "DONE" => {
                let f = Fields::parse(kind, &words[1..])?;
                Ok(DeviceMessage::Done { fired: f.get("fired")?, t_us: f.get("t")? })
            }
            other => Err(format!("unknown message type {other:?}")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_commands() -> Vec<Command> {
        vec![
            Command::Hello,
            Command::AnglesSet(vec![0, 50, 2950]),
            Command::AnglesAdd(vec![3000]),
            Command::AnglesRange { start: 0, stop: 3000, step: 50 },
            Command::Facets(None),
            Command::Facets(Some(vec![0, 3, 11])),
            Command::Lasers(vec![]),
            Command::Lasers(vec![0, 1]),
            Command::Ambient(true),
            Command::Speed(12.5),
            Command::Arm,
            Command::Start { revolutions: 2 },
            Command::Stop,
            Command::Status,
        ]
    }

    #[test]
    fn commands_round_trip() {
        for (i, c) in all_commands().into_iter().enumerate() {
            let req = Request::new(i as u32 + 1, c);
            let body = req.to_body();
            assert_eq!(Request::parse(&body), Ok(req), "{body}");
        }
    }

    #[test]
    fn device_messages_round_trip() {
        let msgs = vec![
            DeviceMessage::Ack { id: 4 },
            DeviceMessage::Nak { id: 5, code: 4, reason: "not armed".into() },
            DeviceMessage::Hello(DeviceInfo {
                protocol: 1,
                firmware: "emu-0.1.0".into(),
                counts_per_rev: 36000,
                facets: 12,
                lasers: 2,
                max_rate_hz: 40.5,
            }),
            DeviceMessage::Trigger(TriggerEvent {
                seq: 7,
                encoder: 4250,
                facet: 1,
                revolution: 3,
                t_us: 123_456_789,
                lasers: vec![0, 1],
            }),
            DeviceMessage::Trigger(TriggerEvent {
                seq: 8,
                encoder: 0,
                facet: 0,
                revolution: 0,
                t_us: 0,
                lasers: vec![],
            }),
            DeviceMessage::Status(DeviceStatus {
                state: DeviceState::Running,
                fired: 10,
                overruns: 1,
                crc_errors: 2,
                rpm: 3.75,
                t_us: 99,
                fault: None,
            }),
            DeviceMessage::Status(DeviceStatus {
                state: DeviceState::Running,
                fired: 5,
                overruns: 0,
                crc_errors: 0,
                rpm: 60.0,
                t_us: 7,
                fault: Some("stall".into()),
            }),
            DeviceMessage::Done { fired: 10, t_us: 1000 },
        ];
        for m in msgs {
            let body = m.to_body();
            assert!(body.len() <= crate::framing::MAX_BODY, "{body}");
            assert_eq!(DeviceMessage::parse(&body), Ok(m), "{body}");
        }
    }

    #[test]
    fn bad_bodies_name_what_is_wrong() {
        let e = Request::parse("FLY 3").unwrap_err();
        assert_eq!((e.id, e.code), (Some(3), NakCode::UnknownCommand));
        let e = Request::parse("ARM x").unwrap_err();
        assert_eq!((e.id, e.code), (None, NakCode::Syntax));
        let e = Request::parse("ANGLES 4 SET 1,x").unwrap_err();
        assert_eq!((e.id, e.code), (Some(4), NakCode::Syntax));
        assert!(e.message.contains("\"x\""), "{}", e.message);
        let e = DeviceMessage::parse("TRG seq=1 enc=2 facet=0 rev=0 las=0").unwrap_err();
        assert!(e.contains("missing field t"), "{e}");
        let e = DeviceMessage::parse("STS state=idle fired=0 overruns=0 crc=0 rpm=NaN t=0").unwrap_err();
        assert!(e.contains("rpm"), "{e}");
        assert!(DeviceMessage::parse("").is_err());
    }
}
