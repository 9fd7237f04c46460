//! Every omniscan file and stream record type, in one place.
//!
//! * Description files (pretty JSON, each with `format` and `version`): [`CameraFile`]
//!   (`camera.json`), [`ScannerFile`] (`scanner.json`), [`BoardFile`] (`board.json`) and the
//!   simulator's scene (see [`scene`]).
//! * The per-frame stream (JSON Lines, [`stream`]): a header record, one record per frame that
//!   grows along the pipe (frame → stripe points → 3D points), and a final status record.
//! * Point clouds as PLY ([`ply`]): binary little-endian or ASCII, `x y z` float or double plus
//!   typed scalars; for other programs also PCD ([`pcd`]) and LAS 1.4 ([`las`]), chosen by
//!   [`export::CloudFormat`], and ROS 2 bags of `PointCloud2` messages ([`rosbag`]).
//! * Frames as PNG ([`png`]: written to be read fast).
//! * [`io`]: `-` for stdin/stdout and atomic writes (temporary file, then rename; devices and
//!   FIFOs written straight into).
//!
//! Readers refuse unknown formats and versions, and every error names the file and the
//! field, record or line at fault ([`Error`]).

mod docs;
mod error;
pub mod export;
pub mod io;
pub mod las;
pub mod odometry;
pub mod pcd;
pub mod ply;
pub mod png;
pub mod rig;
pub mod rosbag;
pub mod scene;
pub mod stream;
pub mod transform;

pub use docs::{
    BoardFile, CameraFile, CameraSpec, ScannerFile, TransmitterSpec, not_polygon, parse_doc, read_doc, stage_doc,
    unobserved_in, write_doc,
};
pub use error::{Error, Result};

/// A versioned document type: its `format` name and the versions this build reads.
pub trait Versioned {
    /// The `format` field's value, e.g. `omniscan.camera`.
    const FORMAT: &'static str;
    /// The newest version this build reads (and writes).
    const VERSION: u32;
    /// The oldest version this build still reads.
    const MIN_VERSION: u32 = Self::VERSION;

    /// Checks values a reader must never accept (sizes beyond the limits, negative lengths), run
    /// by [`read_doc`]/[`docs::parse_doc`] after parsing; the message names the field.
    fn check(&self) -> std::result::Result<(), String> {
        Ok(())
    }
}
