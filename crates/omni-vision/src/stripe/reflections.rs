//! One stripe per scan line: a laser-triangulation sensor's laser lights one point of each image
//! column (or row), so a dimmer stripe sharing columns with a brighter one is laser light that
//! came off the lit surface, a reflection, not the sheet itself.
//!
//! In such a sensor each ray of the laser's fan lights the first surface it meets and nothing
//! behind it, and the fan's rays run, in the image, along the lines across which the stripe
//! moves with depth: the columns for a stripe along the rows. Light elsewhere on such a line
//! reached the surface after the stripe (glossy paper, a shiny edge). The stripe itself is the
//! brighter one: stripes are compared by their connected pieces' median intensity, not point
//! by point, so that the stripe where it crosses dark print still outshines a reflection on
//! white paper beside it.
//!
//! Not for the catadioptric sensor: there the laser sits off the mirror's axis, and one radial
//! line of the image can cross the stripe on two walls at different distances.

use super::StripePoint;
use std::collections::HashMap;

/// The image lines along which the laser lights one point each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanLines {
    /// Image columns: a stripe running along the rows.
    Columns,
    /// Image rows: a stripe running along the columns.
    Rows,
}

impl ScanLines {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ScanLines::Columns => "column",
            ScanLines::Rows => "row",
        }
    }

    /// The line (whole px) a point lies on.
    fn line_of(self, p: &StripePoint) -> i64 {
        let across = match self {
            ScanLines::Columns => p.u,
            ScanLines::Rows => p.v,
        };
        (across + 0.5).floor() as i64
    }
}

impl std::str::FromStr for ScanLines {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        [ScanLines::Columns, ScanLines::Rows]
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown scan line \"{s}\" (known: column, row)"))
    }
}

/// A piece is a reflection on a line where a piece at least this many times brighter (median
/// intensity) crosses the same line or one beside it. Between pieces alike in brightness the
/// stripe cannot be told from its reflection, and both are kept.
pub const REFLECTION_RATIO: f64 = 2.0;

/// Drops the points of `points` that [`ScanLines`] shows to be reflections: those on a line
/// (or a line beside it) crossed by a piece of stripe [`REFLECTION_RATIO`] times brighter, and
/// the whole of a piece at least half of whose points are. A piece is a connected stretch of
/// stripe: points linked by gaps of at most 2.5 px, as the along-stripe fit links them. Returns
/// the kept points, in their order, and how many were dropped.
pub fn drop_reflections(points: Vec<StripePoint>, lines: ScanLines) -> (Vec<StripePoint>, usize) {
    let piece = super::along::stripe_labels(&points);
    let brightness = median_intensity_per_piece(&points, &piece);
    // The brightest piece crossing each line.
    let mut brightest: HashMap<i64, f64> = HashMap::new();
    for (p, &k) in points.iter().zip(&piece) {
        let b = brightest.entry(lines.line_of(p)).or_insert(f64::NEG_INFINITY);
        *b = b.max(brightness[k]);
    }
    // (A piece never outshines itself, whatever its brightness: 0 or NaN included.)
    let outshone = |p: &StripePoint, k: usize| {
        let line = lines.line_of(p);
        let own = brightness[k];
        (line.saturating_sub(1)..=line.saturating_add(1))
            .any(|l| brightest.get(&l).is_some_and(|&b| b > own && b >= REFLECTION_RATIO * own))
    };
    let reflected: Vec<bool> = points.iter().zip(&piece).map(|(p, &k)| outshone(p, k)).collect();
    let mut share = vec![(0usize, 0usize); brightness.len()];
    for (&k, &r) in piece.iter().zip(&reflected) {
        share[k].0 += usize::from(r);
        share[k].1 += 1;
    }
    let dropped_whole = |k: usize| 2 * share[k].0 >= share[k].1;
    let before = points.len();
    let kept: Vec<StripePoint> = points
        .into_iter()
        .zip(piece.iter().zip(&reflected))
        .filter(|(_, (k, r))| !**r && !dropped_whole(**k))
        .map(|(p, _)| p)
        .collect();
    let dropped = before - kept.len();
    (kept, dropped)
}

/// The median intensity of each piece's points.
fn median_intensity_per_piece(points: &[StripePoint], piece: &[usize]) -> Vec<f64> {
    let n = piece.iter().max().map_or(0, |&k| k + 1);
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); n];
    for (p, &k) in points.iter().zip(piece) {
        values[k].push(p.intensity);
    }
    values.iter().map(|v| omni_geom::stats::median(v).unwrap_or(0.0)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(u: f64, v: f64, intensity: f64) -> StripePoint {
        StripePoint { u, v, intensity, width: 4.0, quality: 0 }
    }

    /// A stripe along the rows from u0 to u1 at row `v`, one point per px.
    fn run(u0: i32, u1: i32, v: f64, intensity: f64) -> Vec<StripePoint> {
        (u0..=u1).map(|u| point(u as f64, v, intensity)).collect()
    }

    #[test]
    fn a_dim_copy_sharing_the_columns_is_dropped_whole_a_step_beside_them_is_kept() {
        // The stripe (200, crossing dark print at 40 over u 30-50: less than twice the
        // reflection's there, but its piece is 200), a reflection 80 px below (25, running on
        // 10 px beyond the stripe's columns: those go with the rest), and the stripe stepping to
        // another depth beyond u 102 (its own columns: kept however dim).
        let mut points = run(0, 29, 100.0, 200.0);
        points.extend(run(30, 50, 100.0, 40.0));
        points.extend(run(51, 100, 100.0, 200.0));
        let reflection = run(20, 110, 180.0, 25.0);
        points.extend(reflection.iter().copied());
        points.extend(run(103, 160, 130.0, 15.0));
        let (kept, dropped) = drop_reflections(points.clone(), ScanLines::Columns);
        assert_eq!(dropped, reflection.len());
        assert!(kept.iter().all(|p| p.v != 180.0));
        assert_eq!(kept.len(), points.len() - reflection.len());
        // Read along rows, nothing shares a line.
        assert_eq!(drop_reflections(points, ScanLines::Rows).1, 0);
    }

    #[test]
    fn pieces_go_from_twice_as_bright_and_alike_ones_are_both_kept() {
        let pair = |dim: f64| {
            let mut points = run(0, 60, 100.0, 100.0);
            points.extend(run(0, 60, 140.0, dim));
            drop_reflections(points, ScanLines::Columns).1
        };
        assert_eq!(pair(60.0), 0);
        assert_eq!(pair(51.0), 0);
        assert_eq!(pair(50.0), 61);
        assert_eq!(pair(40.0), 61);
    }

    #[test]
    fn a_lone_piece_is_kept_whatever_its_intensity() {
        for intensity in [0.0, -1.0, f64::NAN] {
            assert_eq!(drop_reflections(run(0, 10, 5.0, intensity), ScanLines::Columns).1, 0, "{intensity}");
        }
    }

    #[test]
    fn a_piece_mostly_beside_the_stripe_loses_only_its_shared_columns() {
        // A dim piece overlapping the stripe's last 10 columns over 40 of its own.
        let mut points = run(0, 50, 100.0, 200.0);
        points.extend(run(40, 90, 150.0, 30.0));
        let (kept, dropped) = drop_reflections(points, ScanLines::Columns);
        // Columns 40-50 and 51 beside them: 12 points.
        assert_eq!(dropped, 12);
        assert!(kept.iter().filter(|p| p.v == 150.0).all(|p| p.u >= 52.0));
    }

    #[test]
    fn scan_lines_parse_by_their_names() {
        assert_eq!("column".parse::<ScanLines>(), Ok(ScanLines::Columns));
        assert_eq!("row".parse::<ScanLines>(), Ok(ScanLines::Rows));
        assert!("radial".parse::<ScanLines>().unwrap_err().contains("known: column, row"));
        assert!(drop_reflections(Vec::new(), ScanLines::Rows).0.is_empty());
    }
}
