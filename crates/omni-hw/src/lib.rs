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
//! * [`frame_id`], [`frame_writer`]: camera frame ids (the 16-bit GigE block id wraps), the
//!   record of software triggers, and writing captured frames (PNG, PGM) in capture order.
//! * [`genicam`]: GenICam cameras through Aravis as a frame source — listing, setup, software
//!   or hardware-line trigger. The settings' checks and the frames' bookkeeping are always
//!   built; the camera itself needs feature `aravis` (the system libaravis-0.8).
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
//!
//! A scan from a program (what `omni-trigger scan` does):
//!
//! ```no_run
//! use omni_hw::scan::{ScanConfig, configure, run_scan};
//! use omni_hw::schedule::AngleSpec;
//! use omni_hw::{Client, ClientOptions, DirFrameSource, PairEvent};
//! use std::time::Duration;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let port = serialport::new("/dev/ttyACM0", 115_200).timeout(Duration::from_millis(20)).open_native()?;
//! let mut client = Client::new(port, ClientOptions::default());
//! let info = client.hello()?;
//! let cfg = ScanConfig::new(AngleSpec::parse("0:30:0.5")?, 2);
//! let (schedule, rpm) = configure(&mut client, &info, &cfg)?;
//! let mut frames = DirFrameSource::new(std::path::Path::new("frames"))?;
//! let mut on_event = |e: &PairEvent| {
//!     if let PairEvent::Paired(frame) = e {
//!         println!("{} at {}° on facet {}", frame.path, frame.alpha_deg, frame.facet);
//!     }
//!     Ok(())
//! };
//! let outcome = run_scan(&mut client, &mut frames, schedule, rpm, &cfg, &mut on_event);
//! println!("{} frames, {} missing", outcome.status.frames, outcome.status.frames_missing);
//! # Ok(())
//! # }
//! ```

pub mod client;
pub mod controller;
pub mod crc;
pub mod emulator;
pub mod frame_id;
pub mod frame_writer;
pub mod framing;
pub mod genicam;
pub mod message;
pub mod pairing;
pub mod scan;
pub mod schedule;

pub use client::{Client, ClientOptions, HwError, host_time_us};
pub use message::{DeviceInfo, TriggerEvent};
pub use pairing::{CapturedFrame, DirFrameSource, FrameSource, PairEvent};
