//! The hardware path: the protocol between the host and the polygon-mirror trigger controller,
//! a host client, the pairing of trigger events with camera frames, and a device emulator.
//!
//! * [`crc`], [`framing`], [`message`]: the wire protocol of `docs/PROTOCOL.md` — pure
//!   functions, no I/O. Lines are `BODY*XXXX\n` with a CRC-16/CCITT-FALSE checksum.
//! * [`schedule`]: which trigger each sequence number is (so events can be checked and gaps
//!   placed).
//! * [`client`]: the host side over any `Read + Write` (a serial port from the `serialport` crate).
//! * [`pairing`]: trigger events ↔ camera frames, by order and checked by timestamps; the frame
//!   source sits behind the small [`pairing::FrameSource`] trait.
//! * [`scan`]: a whole scan session (configure, arm, run, pair) producing stream records.
//! * [`controller`] and [`emulator`]: the firmware logic and a virtual controller + camera that
//!   serve it on a pseudo-terminal, with fault injection.
//!
//! ```
//! use omni_hw::framing::{LineReader, encode_line};
//! use omni_hw::message::DeviceMessage;
//!
//! let mut reader = LineReader::new();
//! let mut bodies = Vec::new();
//! reader.push(b"\x00noise\n", &mut bodies);
//! reader.push(encode_line("DONE fired=12 t=5000").as_bytes(), &mut bodies);
//! assert_eq!(DeviceMessage::parse(&bodies[0]), Ok(DeviceMessage::Done { fired: 12, t_us: 5000 }));
//! ```

pub mod client;
pub mod controller;
pub mod crc;
pub mod emulator;
pub mod framing;
pub mod message;
pub mod pairing;
pub mod scan;
pub mod schedule;

pub use client::{Client, ClientOptions, HwError, host_time_us};
pub use message::{DeviceInfo, TriggerEvent};
