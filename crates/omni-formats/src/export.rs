//! Point-cloud files for other programs: PLY ([`crate::ply`]), PCD ([`crate::pcd`], PCL) and
//! LAS 1.4 ([`crate::las`]), chosen by the output's extension or by name; never a PLY under
//! another extension. ROS 2 bags are in [`crate::rosbag`].

use crate::ply::{PointCloud, ScalarType};
use crate::{Error, Result};
use std::path::Path;

/// A point-cloud file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CloudFormat {
    Ply,
    Pcd,
    Las,
}

impl CloudFormat {
    /// Every format, with its name (= the extension it is chosen by).
    pub const ALL: [(CloudFormat, &'static str); 3] =
        [(CloudFormat::Ply, "ply"), (CloudFormat::Pcd, "pcd"), (CloudFormat::Las, "las")];

    /// The format named `name` (`ply`, `pcd`, `las`; any case).
    pub fn parse(name: &str) -> std::result::Result<CloudFormat, String> {
        Self::ALL
            .iter()
            .find(|(_, n)| n.eq_ignore_ascii_case(name))
            .map(|(f, _)| *f)
            .ok_or_else(|| format!("unknown point-cloud format {name:?} (ply, pcd or las)"))
    }

    /// The format of an output file: `explicit` if given (a `--format` option), else the
    /// extension; a stream without a name of its own (`-` for stdout, an existing device or
    /// FIFO such as `/dev/null`) is PLY. An unknown or missing extension is an error naming the
    /// file.
    pub fn for_output(path: &Path, explicit: Option<CloudFormat>) -> std::result::Result<CloudFormat, String> {
        if let Some(f) = explicit {
            return Ok(f);
        }
        let is_stream = path == Path::new("-") || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir());
        if is_stream {
            return Ok(CloudFormat::Ply);
        }
        let ext = path.extension().map(|e| e.to_string_lossy().into_owned());
        match ext {
            Some(e) => Self::parse(&e).map_err(|_| {
                format!(
                    "{}: unknown point-cloud extension `.{e}` (.ply, .pcd or .las; or name the format with --format)",
                    path.display()
                )
            }),
            None => Err(format!(
                "{}: no extension to choose the point-cloud format by (.ply, .pcd or .las; or --format)",
                path.display()
            )),
        }
    }

    /// Whether `path`'s extension names a point-cloud format.
    pub fn has_cloud_extension(path: &Path) -> bool {
        path.extension().is_some_and(|e| Self::parse(&e.to_string_lossy()).is_ok())
    }

    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(f, _)| *f == self).map_or("ply", |(_, n)| n)
    }
}

/// The unit coordinates are written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Units {
    #[default]
    Millimetres,
    Metres,
}

impl Units {
    /// Parses `mm` or `m`.
    pub fn parse(s: &str) -> std::result::Result<Units, String> {
        match s {
            "mm" => Ok(Units::Millimetres),
            "m" => Ok(Units::Metres),
            _ => Err(format!("unknown unit {s:?} (m or mm)")),
        }
    }

    /// The unit's symbol, as written into the files.
    pub fn name(self) -> &'static str {
        match self {
            Units::Millimetres => "mm",
            Units::Metres => "m",
        }
    }

    /// Output units per millimetre.
    pub fn per_mm(self) -> f64 {
        match self {
            Units::Millimetres => 1.0,
            Units::Metres => 1e-3,
        }
    }
}

/// How coordinates are written. Scalar fields keep their own types and values whatever the
/// options (a `scalar_range` stays in millimetres).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CloudOptions {
    /// ASCII instead of binary (PLY, PCD; LAS is always binary).
    pub ascii: bool,
    /// Coordinates as float64 instead of float32 (PLY, PCD; LAS stores scaled integers).
    pub double: bool,
    pub units: Units,
}

impl CloudOptions {
    /// The type coordinates are written as.
    pub fn coordinate_type(&self) -> ScalarType {
        if self.double { ScalarType::F64 } else { ScalarType::F32 }
    }
}

/// Writes `cloud` to `path` in `format` (`-` = stdout), staged to be put in place with the
/// tool's other outputs ([`crate::io::write_staged`]); errors name the file.
pub fn write_cloud_staged(
    path: &Path,
    cloud: &PointCloud,
    format: CloudFormat,
    opts: &CloudOptions,
) -> Result<crate::io::Staged> {
    let name = crate::io::display_name(path, "stdout");
    match format {
        CloudFormat::Ply => crate::io::write_staged(path, |w| crate::ply::write_ply_with(w, cloud, opts)),
        CloudFormat::Pcd => crate::io::write_staged(path, |w| crate::pcd::write_pcd_to(w, cloud, opts)),
        CloudFormat::Las => {
            let bytes = crate::las::las_bytes(cloud, opts).map_err(|m| Error::new(&name, "", m))?;
            crate::io::write_staged(path, |w| w.write_all(&bytes))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_format_comes_from_the_extension_or_the_option() {
        let f = |p: &str, e| CloudFormat::for_output(Path::new(p), e);
        assert_eq!(f("a.ply", None), Ok(CloudFormat::Ply));
        assert_eq!(f("a.PCD", None), Ok(CloudFormat::Pcd));
        assert_eq!(f("dir/a.las", None), Ok(CloudFormat::Las));
        assert_eq!(f("-", None), Ok(CloudFormat::Ply));
        assert_eq!(f("/dev/null", None), Ok(CloudFormat::Ply));
        assert_eq!(f("a.txt", Some(CloudFormat::Pcd)), Ok(CloudFormat::Pcd));
        let e = f("a.xyz", None).unwrap_err();
        assert!(e.starts_with("a.xyz: unknown point-cloud extension `.xyz`"), "{e}");
        assert!(f("cloud", None).unwrap_err().contains("no extension"));
        assert!(CloudFormat::parse("laz").is_err());
    }
}
