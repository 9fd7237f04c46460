//! Odometry: the sensor's pose over time, as JSON Lines (`odometry.jsonl`).
//!
//! ```text
//! {"type":"header","format":"omniscan.odometry","version":1}
//! {"t_us":0,"translation_mm":[0,0,0],"quaternion_wxyz":[1,0,0,0]}
//! {"t_us":50000,"translation_mm":[12.5,0,0],"quaternion_wxyz":[0.9999,0,0,0.0141]}
//! ```
//! Each sample is the pose of the sensor (world = receiver frame of SENSOR.md) in a fixed
//! world frame at time `t_us` (µs, the same clock as the stream's `timestamp_us`):
//! p_world = R·p_sensor + translation. Samples must be strictly increasing in time; the
//! quaternion must be unit length (within 1e-6). Gaps are checked where poses are
//! interpolated (omni-cloud's `Trajectory`), against a maximum gap given there.

use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::io::BufRead;
use std::path::Path;

pub const ODOMETRY_FORMAT: &str = "omniscan.odometry";
pub const ODOMETRY_VERSION: u32 = 1;

/// One timed pose (sensor → world).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSample {
    /// Time (µs).
    pub t_us: u64,
    /// Position of the sensor's origin in the world (mm).
    pub translation_mm: [f64; 3],
    /// Orientation as a unit quaternion (w, x, y, z).
    pub quaternion_wxyz: [f64; 4],
}

impl PoseSample {
    /// The identity pose at time `t_us`.
    pub fn identity(t_us: u64) -> Self {
        PoseSample { t_us, translation_mm: [0.0; 3], quaternion_wxyz: [1.0, 0.0, 0.0, 0.0] }
    }

    fn validate(&self) -> std::result::Result<(), String> {
        if !self.translation_mm.iter().all(|x| x.is_finite()) {
            return Err("field translation_mm: not a finite number".into());
        }
        if !self.quaternion_wxyz.iter().all(|x| x.is_finite()) {
            return Err("field quaternion_wxyz: not a finite number".into());
        }
        let n = self.quaternion_wxyz.iter().map(|x| x * x).sum::<f64>().sqrt();
        if (n - 1.0).abs() > 1e-6 {
            return Err(format!("field quaternion_wxyz: not unit length (norm {n})"));
        }
        Ok(())
    }
}

#[derive(Debug, Deserialize)]
struct HeaderLine {
    #[serde(rename = "type")]
    kind: String,
}

/// Reads an odometry file: header first, then samples strictly increasing in time.
/// Errors name the file and the line.
pub fn read_odometry_from(reader: impl BufRead, name: &str) -> Result<Vec<PoseSample>> {
    let mut samples: Vec<PoseSample> = Vec::new();
    let mut seen_header = false;
    for (i, line) in reader.lines().enumerate() {
        let loc = format!("line {}", i + 1);
        let line = line.map_err(|e| Error::io(name, &e))?;
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let value: serde_json::Value =
            serde_json::from_str(line).map_err(|e| Error::new(name, &loc, format!("invalid JSON: {e}")))?;
        if !seen_header {
            let h: HeaderLine = serde_json::from_value(value.clone())
                .map_err(|_| Error::new(name, &loc, "expected the header record first"))?;
            if h.kind != "header" {
                return Err(Error::new(name, &loc, "expected the header record first"));
            }
            crate::docs::check_header(&value, ODOMETRY_FORMAT, ODOMETRY_VERSION, name)
                .map_err(|e| Error::new(name, format!("{loc}, {}", e.location), e.message))?;
            seen_header = true;
            continue;
        }
        let s: PoseSample = serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            let loc = if path == "." { loc.clone() } else { format!("{loc}, field {path}") };
            Error::new(name, loc, e.into_inner().to_string())
        })?;
        s.validate().map_err(|m| Error::new(name, &loc, m))?;
        if let Some(prev) = samples.last()
            && s.t_us <= prev.t_us
        {
            return Err(Error::new(
                name,
                &loc,
                format!("timestamps not strictly increasing ({} µs after {} µs)", s.t_us, prev.t_us),
            ));
        }
        samples.push(s);
    }
    if !seen_header {
        return Err(Error::new(name, "", "empty file (no header record)"));
    }
    if samples.is_empty() {
        return Err(Error::new(name, "", "no pose samples"));
    }
    Ok(samples)
}

/// Reads an odometry file (`-` = stdin).
pub fn read_odometry(path: &Path) -> Result<Vec<PoseSample>> {
    let name = crate::io::display_name(path, "stdin");
    read_odometry_from(crate::io::open_input(path)?, &name)
}

/// Writes an odometry file atomically (`-` = stdout).
pub fn write_odometry(path: &Path, samples: &[PoseSample]) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        let header = serde_json::json!({"type": "header", "format": ODOMETRY_FORMAT, "version": ODOMETRY_VERSION});
        writeln!(w, "{header}")?;
        for s in samples {
            serde_json::to_writer(&mut *w, s)?;
            w.write_all(b"\n")?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "{\"type\":\"header\",\"format\":\"omniscan.odometry\",\"version\":1}\n";

    #[test]
    fn round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("odo.jsonl");
        let s = vec![
            PoseSample::identity(0),
            PoseSample { t_us: 10, translation_mm: [1.0, 2.0, 3.0], quaternion_wxyz: [0.0, 1.0, 0.0, 0.0] },
        ];
        write_odometry(&path, &s).unwrap();
        assert_eq!(read_odometry(&path).unwrap(), s);
    }

    #[test]
    fn bad_files_name_the_line() {
        let read =
            |body: &str| read_odometry_from(format!("{HEADER}{body}").as_bytes(), "odo.jsonl").unwrap_err().to_string();
        let unsorted = "{\"t_us\":5,\"translation_mm\":[0,0,0],\"quaternion_wxyz\":[1,0,0,0]}\n\
                        {\"t_us\":5,\"translation_mm\":[0,0,0],\"quaternion_wxyz\":[1,0,0,0]}\n";
        let e = read(unsorted);
        assert!(e.contains("line 3") && e.contains("strictly increasing"), "{e}");
        let e = read("{\"t_us\":5,\"translation_mm\":[0,0,0],\"quaternion_wxyz\":[2,0,0,0]}\n");
        assert!(e.contains("line 2") && e.contains("unit length"), "{e}");
        let e = read("{\"t_us\":5,\"translation_mm\":[0,0],\"quaternion_wxyz\":[1,0,0,0]}\n");
        assert!(e.contains("translation_mm"), "{e}");
        let e = read_odometry_from("{\"t_us\":5}\n".as_bytes(), "odo.jsonl").unwrap_err().to_string();
        assert!(e.contains("header"), "{e}");
        let e = read_odometry_from(
            "{\"type\":\"header\",\"format\":\"omniscan.odometry\",\"version\":9}\n".as_bytes(),
            "odo.jsonl",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("version"), "{e}");
    }
}
