//! The host side of the protocol over any byte stream (`Read + Write`): a serial port, a
//! pseudo-terminal, or an in-memory pipe in tests.
//!
//! The port's own read timeout bounds each read (a serial port opened with
//! `serialport::new(path, baud).timeout(..)`); a read that times out simply returns no data.
//! End of file, a hang-up or any other read/write error means the controller is gone
//! ([`HwError::Disconnected`]).

use crate::framing::{LineReader, LineStats, encode_line};
use crate::message::{Command, DeviceInfo, DeviceMessage, DeviceStatus, PROTOCOL_VERSION, Request};
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// Host clock: microseconds since the Unix epoch (the clock file modification times use too).
pub fn host_time_us() -> i64 {
    match std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
        Ok(d) => d.as_micros() as i64,
        Err(e) => -(e.duration().as_micros() as i64),
    }
}

/// A failure talking to the controller.
#[derive(Debug, Clone, PartialEq)]
pub enum HwError {
    /// The port closed, hung up or failed (unplugged cable, controller reset).
    Disconnected(String),
    /// No valid reply within the timeout, after all retries.
    Timeout(String),
    /// The controller refused a command.
    Nak { command: String, code: u32, reason: String },
    /// The controller said something that contradicts the protocol.
    Protocol(String),
}

impl std::fmt::Display for HwError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            HwError::Disconnected(m) => write!(f, "controller disconnected: {m}"),
            HwError::Timeout(m) => write!(f, "controller timeout: {m}"),
            HwError::Nak { command, code, reason } => write!(f, "controller refused `{command}`: NAK {code} {reason}"),
            HwError::Protocol(m) => write!(f, "protocol error: {m}"),
        }
    }
}

impl std::error::Error for HwError {}

/// A message with the host time at which its line was read (µs, [`host_time_us`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    pub message: DeviceMessage,
    pub at_us: i64,
}

/// Reply timeout and retries for commands.
#[derive(Debug, Clone, Copy)]
pub struct ClientOptions {
    /// How long to wait for the ACK of one attempt.
    pub reply_timeout: Duration,
    /// Attempts per command (the same id each time, so a retry is never executed twice).
    pub attempts: u32,
}

impl Default for ClientOptions {
    fn default() -> Self {
        ClientOptions { reply_timeout: Duration::from_millis(250), attempts: 4 }
    }
}

/// A protocol client over a byte stream.
pub struct Client<P> {
    port: P,
    reader: LineReader,
    next_id: u32,
    inbox: VecDeque<Received>,
    options: ClientOptions,
    /// Verified lines whose content did not parse (firmware bug or a CRC collision).
    pub unparsable: Vec<String>,
    /// Commands that had to be sent more than once.
    pub retries: u64,
}

/// The first command id of a session: new to the controller. A controller that stays powered
/// between sessions remembers the previous session's last ids and answers them again without
/// running them (PROTOCOL.md §3), so a session numbering from 1 again would have its `ARM`
/// taken for an old one. The clock's nanoseconds and the process id make a start that lands
/// within one session's few hundred ids of an earlier one's about once in ten million.
fn session_first_id() -> u32 {
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let mixed = (nanos as u64) ^ ((std::process::id() as u64) << 32);
    // SplitMix64's finaliser spreads neighbouring clock values over the whole range.
    let mut z = mixed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) as u32).max(1)
}

impl<P: Read + Write> Client<P> {
    pub fn new(port: P, options: ClientOptions) -> Self {
        Client {
            port,
            reader: LineReader::new(),
            next_id: session_first_id(),
            inbox: VecDeque::new(),
            options,
            unparsable: Vec::new(),
            retries: 0,
        }
    }

    /// Lines accepted and dropped so far.
    pub fn line_stats(&self) -> LineStats {
        self.reader.stats
    }

    /// Reads once (blocking at most the port's timeout) and queues the messages received.
    fn fill(&mut self) -> Result<(), HwError> {
        let mut buf = [0u8; 512];
        let n = match self.port.read(&mut buf) {
            Ok(0) => return Err(HwError::Disconnected("end of stream".into())),
            Ok(n) => n,
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                return Ok(());
            }
            Err(e) => return Err(HwError::Disconnected(describe_io(&e))),
        };
        let at_us = host_time_us();
        let mut bodies = Vec::new();
        self.reader.push(&buf[..n], &mut bodies);
        for body in bodies {
            match DeviceMessage::parse(&body) {
                Ok(message) => self.inbox.push_back(Received { message, at_us }),
                Err(e) => self.unparsable.push(format!("{body:?}: {e}")),
            }
        }
        Ok(())
    }

    /// The next message, waiting until `deadline`; `Ok(None)` if none came in time.
    pub fn recv(&mut self, deadline: Instant) -> Result<Option<Received>, HwError> {
        loop {
            if let Some(m) = self.inbox.pop_front() {
                return Ok(Some(m));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            self.fill()?;
        }
    }

    fn send_line(&mut self, body: &str) -> Result<(), HwError> {
        let line = encode_line(body);
        self.port
            .write_all(line.as_bytes())
            .and_then(|_| self.port.flush())
            .map_err(|e| HwError::Disconnected(describe_io(&e)))
    }

    /// Sends a command and waits for its ACK, retrying with the same id on timeout.
    pub fn request(&mut self, command: Command) -> Result<(), HwError> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let body = Request::new(id, command).to_body();
        for attempt in 0..self.options.attempts {
            if attempt > 0 {
                self.retries += 1;
            }
            self.send_line(&body)?;
            let deadline = Instant::now() + self.options.reply_timeout;
            while Instant::now() < deadline {
                if let Some(reply) = self.take_reply(id) {
                    return match reply {
                        DeviceMessage::Nak { code, reason, .. } => Err(HwError::Nak { command: body, code, reason }),
                        _ => Ok(()),
                    };
                }
                self.fill()?;
            }
            if let Some(reply) = self.take_reply(id) {
                return match reply {
                    DeviceMessage::Nak { code, reason, .. } => Err(HwError::Nak { command: body, code, reason }),
                    _ => Ok(()),
                };
            }
        }
        Err(HwError::Timeout(format!("no ACK for `{body}` after {} attempts", self.options.attempts)))
    }

    fn take_reply(&mut self, id: u32) -> Option<DeviceMessage> {
        let pos = self.inbox.iter().position(
            |r| matches!(r.message, DeviceMessage::Ack { id: a } | DeviceMessage::Nak { id: a, .. } if a == id),
        )?;
        self.inbox.remove(pos).map(|r| r.message)
    }

    fn take_first<T>(&mut self, pick: impl Fn(&DeviceMessage) -> Option<T>) -> Option<T> {
        let pos = self.inbox.iter().position(|r| pick(&r.message).is_some())?;
        self.inbox.remove(pos).and_then(|r| pick(&r.message))
    }

    /// Handshake: asks for the controller description and checks the protocol version.
    pub fn hello(&mut self) -> Result<DeviceInfo, HwError> {
        for _ in 0..self.options.attempts {
            self.request(Command::Hello)?;
            // The description precedes the ACK; a lost description line is asked for again.
            let deadline = Instant::now() + self.options.reply_timeout / 4;
            loop {
                if let Some(info) =
                    self.take_first(|m| if let DeviceMessage::Hello(i) = m { Some(i.clone()) } else { None })
                {
                    return check_info(info);
                }
                if Instant::now() >= deadline {
                    break;
                }
                self.fill()?;
            }
        }
        Err(HwError::Timeout("no HELLO description from the controller".into()))
    }

    /// Asks for a status line.
    pub fn status(&mut self) -> Result<DeviceStatus, HwError> {
        for _ in 0..self.options.attempts {
            self.request(Command::Status)?;
            let deadline = Instant::now() + self.options.reply_timeout / 4;
            loop {
                let newest = self.inbox.iter().rposition(|r| matches!(r.message, DeviceMessage::Status(_)));
                if let Some(DeviceMessage::Status(s)) = newest.and_then(|p| self.inbox.remove(p)).map(|r| r.message) {
                    return Ok(s);
                }
                if Instant::now() >= deadline {
                    break;
                }
                self.fill()?;
            }
        }
        Err(HwError::Timeout("no STS line from the controller".into()))
    }

    /// Forgets every message received so far (stale events of an interrupted earlier run).
    pub fn discard_received(&mut self) {
        self.inbox.clear();
    }

    /// Gives the port back (e.g. to close it).
    pub fn into_inner(self) -> P {
        self.port
    }
}

/// A port failure in words; a hang-up is named as such (not "broken pipe", which command-line
/// tools reserve for a closed output pipe).
fn describe_io(e: &std::io::Error) -> String {
    match e.kind() {
        ErrorKind::BrokenPipe => "the port hung up (cable unplugged or device closed)".into(),
        _ => format!("port error: {e}"),
    }
}

fn check_info(info: DeviceInfo) -> Result<DeviceInfo, HwError> {
    if info.protocol != PROTOCOL_VERSION {
        return Err(HwError::Protocol(format!(
            "controller speaks protocol version {}, this tool speaks version {PROTOCOL_VERSION}",
            info.protocol
        )));
    }
    if info.facets == 0 || info.counts_per_rev == 0 || !info.counts_per_rev.is_multiple_of(info.facets) {
        return Err(HwError::Protocol(format!(
            "HELLO: cpr={} is not a multiple of facets={}",
            info.counts_per_rev, info.facets
        )));
    }
    if !(info.max_rate_hz > 0.0) {
        return Err(HwError::Protocol(format!("HELLO: max_hz={} must be positive", info.max_rate_hz)));
    }
    Ok(info)
}
