//! Questions to a calibrated camera, one per line (`omni-calib-receiver query`): a pixel gives
//! its world ray, a 3-D point (mm, world frame) gives its pixel.
//!
//! Input lines: `u v` (pixel) or `x y z` (point), or JSON: `[u, v]`, `[x, y, z]`,
//! `{"px": [u, v]}`, `{"point_mm": [x, y, z]}`. Blank lines and `#` comments are skipped.
//! Text answers repeat the question, then `ox oy oz dx dy dz` (ray origin in mm and unit
//! direction, world frame) or `u v`, or `none` where the pixel or point is not seen through the
//! mirror. JSON answers are objects: `{"px": [u, v], "origin_mm": [..], "dir": [..]}` and
//! `{"point_mm": [..], "px": [u, v]}`, with `null` for what is not seen.

use nalgebra::{Point3, Vector2};
use omni_model::CameraModel;
use serde_json::{Value, json};

/// One question.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Query {
    /// Image position (px).
    Pixel([f64; 2]),
    /// World point (mm).
    Point([f64; 3]),
}

fn from_numbers(v: &[f64]) -> Result<Query, String> {
    if !v.iter().all(|x| x.is_finite()) {
        return Err("values must be finite".into());
    }
    match *v {
        [u, v] => Ok(Query::Pixel([u, v])),
        [x, y, z] => Ok(Query::Point([x, y, z])),
        _ => Err(format!("expected 2 numbers (pixel u v) or 3 (point x y z, mm), got {}", v.len())),
    }
}

fn json_numbers(v: &Value) -> Option<Vec<f64>> {
    v.as_array()?.iter().map(Value::as_f64).collect()
}

/// Parses one input line; `None` for blank lines and comments.
pub fn parse_query(line: &str) -> Result<Option<Query>, String> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    if line.starts_with('[') || line.starts_with('{') {
        let v: Value = serde_json::from_str(line).map_err(|e| format!("not JSON: {e}"))?;
        let numbers = match &v {
            Value::Array(_) => json_numbers(&v),
            Value::Object(o) => match (o.get("px"), o.get("point_mm")) {
                (Some(p), None) => json_numbers(p).filter(|n| n.len() == 2),
                (None, Some(p)) => json_numbers(p).filter(|n| n.len() == 3),
                _ => None,
            },
            _ => None,
        };
        let numbers = numbers.ok_or("expected [u, v], [x, y, z], {\"px\": [u, v]} or {\"point_mm\": [x, y, z]}")?;
        return from_numbers(&numbers).map(Some);
    }
    let numbers: Vec<f64> = line
        .split_whitespace()
        .map(|t| t.parse::<f64>().map_err(|_| format!("{t:?} is not a number")))
        .collect::<Result<_, _>>()?;
    from_numbers(&numbers).map(Some)
}

/// A point beyond 2^332 mm (about 1e100) scaled by a power of two to within it: the models
/// square its coordinates, which overflow beyond 1e154. The scaling is exact, so a central
/// model's pixel is unchanged; a non-central one's moves by its rays' offsets (mm) over the
/// distance, under 1e-96 px.
fn within_range_of_squares(p: [f64; 3]) -> Point3<f64> {
    let largest = p.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    let scale = match largest > 2f64.powi(332) && largest.is_finite() {
        true => 2f64.powi(332 - largest.log2().ceil() as i32),
        false => 1.0,
    };
    Point3::new(p[0] * scale, p[1] * scale, p[2] * scale)
}

/// The answer to `q` as one line (without the newline), text or JSON.
pub fn answer(cam: &dyn CameraModel, q: Query, as_json: bool) -> String {
    match q {
        Query::Pixel(px) => {
            let ray = cam.pixel_to_ray(&Vector2::new(px[0], px[1]));
            if as_json {
                let (origin, dir) = match &ray {
                    Some(r) => (json!([r.origin.x, r.origin.y, r.origin.z]), json!([r.dir.x, r.dir.y, r.dir.z])),
                    None => (Value::Null, Value::Null),
                };
                return json!({"px": px, "origin_mm": origin, "dir": dir}).to_string();
            }
            match ray {
                Some(r) => format!(
                    "{} {} {} {} {} {} {} {}",
                    px[0], px[1], r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z
                ),
                None => format!("{} {} none", px[0], px[1]),
            }
        }
        Query::Point(p) => {
            let px = cam.point_to_pixel(&within_range_of_squares(p));
            if as_json {
                let px = px.map_or(Value::Null, |q| json!([q.x, q.y]));
                return json!({"point_mm": p, "px": px}).to_string();
            }
            match px {
                Some(q) => format!("{} {} {} {} {}", p[0], p[1], p[2], q.x, q.y),
                None => format!("{} {} {} none", p[0], p[1], p[2]),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_model::{HyperbolicCamera, HyperbolicParams};

    #[test]
    fn points_far_beyond_the_squares_range_give_the_pixel_of_their_direction() {
        let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        let pixel = |p: [f64; 3]| {
            let answer: Value = serde_json::from_str(&answer(&cam, Query::Point(p), true)).unwrap();
            json_numbers(&answer["px"]).unwrap_or_else(|| panic!("{p:?}: {answer}"))
        };
        let far = pixel([1e90, 0.0, -0.3e90]);
        for farther in [1e155, 1e300, f64::MAX / 2.0] {
            let got = pixel([farther, 0.0, -0.3 * farther]);
            assert!((got[0] - far[0]).abs() < 1e-9 && (got[1] - far[1]).abs() < 1e-9, "{farther}: {got:?} vs {far:?}");
        }
        assert_eq!(within_range_of_squares([3.0, -4.0, 5.0]), Point3::new(3.0, -4.0, 5.0));
        let scaled = within_range_of_squares([2f64.powi(400), 0.0, -2f64.powi(399)]);
        assert_eq!(scaled, Point3::new(2f64.powi(332), 0.0, -2f64.powi(331)));
    }

    #[test]
    fn parses_text_and_json_questions_and_names_the_problem() {
        assert_eq!(parse_query(" 10 20.5 ").unwrap(), Some(Query::Pixel([10.0, 20.5])));
        assert_eq!(parse_query("1 2 -3").unwrap(), Some(Query::Point([1.0, 2.0, -3.0])));
        assert_eq!(parse_query("[1, 2]").unwrap(), Some(Query::Pixel([1.0, 2.0])));
        assert_eq!(parse_query("{\"point_mm\": [1, 2, 3]}").unwrap(), Some(Query::Point([1.0, 2.0, 3.0])));
        assert_eq!(parse_query("{\"px\": [4, 5]}").unwrap(), Some(Query::Pixel([4.0, 5.0])));
        assert_eq!(parse_query("# note").unwrap(), None);
        assert_eq!(parse_query("").unwrap(), None);
        assert!(parse_query("1 x").unwrap_err().contains("\"x\" is not a number"));
        assert!(parse_query("1 2 3 4").unwrap_err().contains("got 4"));
        assert!(parse_query("{\"px\": [1, 2, 3]}").unwrap_err().contains("expected [u, v]"));
        assert!(parse_query("1 NaN").unwrap_err().contains("finite"));
    }

    #[test]
    fn answers_agree_with_the_camera_model_both_ways() {
        let p = HyperbolicParams::paper();
        let cam = HyperbolicCamera::new(p.clone()).unwrap();
        let u = p.cx_px + 200.0;
        let text = answer(&cam, Query::Pixel([u, p.cy_px]), false);
        let v: Vec<f64> = text.split(' ').map(|t| t.parse().unwrap()).collect();
        let ray = cam.pixel_to_ray(&Vector2::new(u, p.cy_px)).unwrap();
        assert_eq!(v[..2], [u, p.cy_px]);
        assert_eq!(v[2..], [ray.origin.x, ray.origin.y, ray.origin.z, ray.dir.x, ray.dir.y, ray.dir.z]);
        // The point 1 m along that ray comes back to the pixel.
        let point = ray.at(1000.0);
        let back: Value = serde_json::from_str(&answer(&cam, Query::Point([point.x, point.y, point.z]), true)).unwrap();
        let px = json_numbers(&back["px"]).unwrap();
        assert!((px[0] - u).abs() < 1e-6 && (px[1] - p.cy_px).abs() < 1e-6, "{back}");
        assert_eq!(answer(&cam, Query::Pixel([p.cx_px, p.cy_px]), false), format!("{} {} none", p.cx_px, p.cy_px));
        let blind: Value = serde_json::from_str(&answer(&cam, Query::Pixel([p.cx_px, p.cy_px]), true)).unwrap();
        assert!(blind["dir"].is_null());
    }
}
