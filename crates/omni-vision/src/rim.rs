//! The mirror annulus of a catadioptric image: the outer rim circle of the mirror and, if visible,
//! the inner circle of the blind centre (the camera's own reflection).
//!
//! Method: the image is smoothed (Gaussian, [`RimOptions::blur_sigma_px`]) and sampled along
//! radial rays from a centre guess (the image centre); every ray keeps its strongest radial edges
//! (local maxima of |dI/dr|, sub-pixel by a parabola through the peak) with their sign (brighter
//! or darker outwards). A circle is a set of same-signed edges on many rays: RANSAC over triples of
//! edges on well separated rays finds the best supported circles, then each is refined by
//! re-sampling the rays from its own centre (so they cross the rim at right angles), keeping per
//! ray the edge nearest the circle and fitting [`omni_geom::fit::fit_circle_2d`] to them, three
//! times with a shrinking tolerance. The outer rim is the largest well-supported circle, the blind
//! centre the best-supported circle well inside it about the same centre.
//!
//! One board image shows only part of the mirror; the per-pixel range of all of them
//! ([`range_image`]) shows it wherever a board moved, which is usually enough on a dark
//! background. Boards held in a static lit room change only where the board was, so the range
//! shows no rim, while each single image shows it all round but where its board covers it:
//! [`rim_image`] takes the range, else the single image whose rim is best supported.

use crate::corners::{GrayF32, gaussian_blur};
use omni_geom::rng::SplitMix64;

/// Tuning of [`detect_rim`]; the defaults suit images of 256 px to a few MP.
#[derive(Debug, Clone)]
pub struct RimOptions {
    /// Number of radial rays over 360°.
    pub rays: usize,
    /// Gaussian smoothing before the edge search (px).
    pub blur_sigma_px: f64,
    /// Edges kept per ray (the strongest).
    pub edges_per_ray: usize,
    /// Largest distance of an edge from a circle to count as support (px), in the RANSAC stage.
    pub inlier_px: f64,
    /// Least fraction of the rays that cross a circle inside the image and support it.
    pub min_support: f64,
    /// RANSAC hypotheses per search.
    pub trials: usize,
}

impl Default for RimOptions {
    fn default() -> Self {
        RimOptions { rays: 720, blur_sigma_px: 1.0, edges_per_ray: 6, inlier_px: 2.0, min_support: 0.5, trials: 3000 }
    }
}

/// One fitted circle (image pixels, centres at integer coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RimCircle {
    /// Centre (px).
    pub centre: [f64; 2],
    /// Radius (px).
    pub radius: f64,
    /// RMS distance of the supporting edge points from the circle (px).
    pub rms_px: f64,
    /// Fraction of the rays crossing the circle inside the image whose edge lies on it.
    pub support: f64,
    /// +1 if the image gets brighter outwards across the circle, −1 if darker.
    pub sign: i8,
}

/// The mirror annulus found in an image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rim {
    /// The mirror's outer rim.
    pub outer: RimCircle,
    /// The blind centre (camera's reflection), if a circle was found there.
    pub inner: Option<RimCircle>,
}

impl Rim {
    /// `[cx, cy, r_in, r_out]` (px) as `--annulus` and `DetectorOptions::annulus` take it: the
    /// outer rim's centre, the inner radius measured about it (0 without a blind-centre circle).
    pub fn annulus(&self) -> [f64; 4] {
        let [cx, cy] = self.outer.centre;
        [cx, cy, self.inner.map_or(0.0, |c| c.radius), self.outer.radius]
    }
}

/// The per-pixel range (maximum − minimum) of images of one size, e.g. all board images of a
/// calibration set; one image is returned as it is. Inside the mirror the content changes from
/// image to image (the board moves), outside it (housing, glass, black background) it does not,
/// so the range shows the mirror disc wherever something moved in front of it: on the real
/// MiniOmni set, whose rim is a blurred glass ring, only the range gives a circle supported all
/// round; on simulated boards over a black background it equals the maximum.
pub fn range_image(images: &[GrayF32]) -> Result<GrayF32, String> {
    let first = images.first().ok_or("no images")?;
    let (mut lo, mut hi) = (first.clone(), first.clone());
    for (k, img) in images.iter().enumerate().skip(1) {
        if (img.width, img.height) != (first.width, first.height) {
            return Err(format!(
                "image {k} is {} × {} px but image 0 is {} × {} px",
                img.width, img.height, first.width, first.height
            ));
        }
        for ((l, h), &v) in lo.data.iter_mut().zip(hi.data.iter_mut()).zip(&img.data) {
            *l = l.min(v);
            *h = h.max(v);
        }
    }
    if images.len() > 1 {
        for (h, l) in hi.data.iter_mut().zip(&lo.data) {
            *h -= l;
        }
    }
    Ok(hi)
}

/// Which image [`rim_image`] found the rim in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RimSource {
    /// The per-pixel range of all the images ([`range_image`]).
    Range,
    /// This one image (its index).
    Single(usize),
}

/// The image to find the mirror annulus in, with the rim found there.
#[derive(Debug, Clone)]
pub struct RimImage {
    pub image: GrayF32,
    pub source: RimSource,
    pub rim: Rim,
    /// Why the range of several images showed no rim, when a single image was taken instead.
    pub range_error: Option<String>,
}

/// The image of a set (one camera, one size) that shows the mirror rim: one image as it is;
/// several by their per-pixel range if its rim is supported by at least [`RANGE_SUPPORT`] of
/// the rays, else whichever of the range and the single images shows the rim supported by the
/// most rays (a static lit room: see the module docs; there the range may even show a small
/// false circle, where the boards' coverage ends). Of many images, [`SINGLE_IMAGES`] spread over
/// the set are tried (any lit image shows the rim; each costs a full search). Errors give the
/// range's reason and the first image's.
pub fn rim_image(images: &[GrayF32], opts: &RimOptions) -> Result<RimImage, String> {
    use rayon::prelude::*;
    if let [one] = images {
        let rim = detect_rim(one, opts)?;
        return Ok(RimImage { image: one.clone(), source: RimSource::Single(0), rim, range_error: None });
    }
    let range = range_image(images)?;
    let from_range = detect_rim(&range, opts);
    if let Ok(rim) = &from_range
        && rim.outer.support >= RANGE_SUPPORT
    {
        return Ok(RimImage { image: range, source: RimSource::Range, rim: *rim, range_error: None });
    }
    let step = images.len().div_ceil(SINGLE_IMAGES);
    let tried: Vec<usize> = (0..images.len()).step_by(step).collect();
    let singles: Vec<Result<Rim, String>> = tried.par_iter().map(|&k| detect_rim(&images[k], opts)).collect();
    let best = singles
        .iter()
        .zip(&tried)
        .filter_map(|(r, &k)| r.as_ref().ok().map(|r| (k, *r)))
        .max_by(|a, b| a.1.outer.support.total_cmp(&b.1.outer.support));
    match (from_range, best) {
        (Ok(rim), best) if best.is_none_or(|(_, b)| b.outer.support <= rim.outer.support) => {
            Ok(RimImage { image: range, source: RimSource::Range, rim, range_error: None })
        }
        (range_result, Some((k, rim))) => Ok(RimImage {
            image: images[k].clone(),
            source: RimSource::Single(k),
            rim,
            range_error: Some(range_result.map_or_else(
                |e| e,
                |r| {
                    format!(
                        "its best circle (radius {:.1} px) is supported by {:.0} % of the rays",
                        r.outer.radius,
                        100.0 * r.outer.support
                    )
                },
            )),
        }),
        (Err(range_error), None) => Err(format!(
            "range of the {} images: {range_error}; nor in any single image (the first: {})",
            images.len(),
            singles[0].as_ref().err().map_or("", |e| e.as_str())
        )),
        (Ok(_), None) => unreachable!("handled by the first arm"),
    }
}

/// A rim found in the range of several images with at least this support is taken without
/// looking at the single images.
pub const RANGE_SUPPORT: f64 = 0.9;

/// At most this many single images are searched by [`rim_image`].
pub const SINGLE_IMAGES: usize = 5;

/// An edge along one ray: its ray, position (px) and sign (+1 brighter outwards).
#[derive(Debug, Clone, Copy)]
struct Edge {
    ray: usize,
    x: f64,
    y: f64,
    sign: i8,
}

/// Radial sampling step (px).
const STEP_PX: f64 = 0.5;

/// The strongest radial edges along each ray from `centre`, and per ray the largest radius
/// sampled inside the image.
fn radial_edges(img: &GrayF32, centre: [f64; 2], opts: &RimOptions) -> (Vec<Edge>, Vec<f64>) {
    let mut edges = Vec::new();
    let mut reach = Vec::with_capacity(opts.rays);
    let mut profile = Vec::new();
    for ray in 0..opts.rays {
        let a = ray as f64 * std::f64::consts::TAU / opts.rays as f64;
        let (dx, dy) = (a.cos(), a.sin());
        profile.clear();
        loop {
            let r = profile.len() as f64 * STEP_PX;
            let (x, y) = (centre[0] + r * dx, centre[1] + r * dy);
            if !img.inside(x, y, 1.0) {
                break;
            }
            profile.push(img.bilinear(x, y));
        }
        reach.push(profile.len().saturating_sub(1) as f64 * STEP_PX);
        // Central differences over ±1 px (two samples).
        let grad: Vec<f32> = (0..profile.len())
            .map(|i| if i < 2 || i + 2 >= profile.len() { 0.0 } else { profile[i + 2] - profile[i - 2] })
            .collect();
        let mut peaks: Vec<(f32, f64, i8)> = (1..grad.len().saturating_sub(1))
            .filter(|&i| grad[i].abs() > 0.0 && grad[i].abs() >= grad[i - 1].abs() && grad[i].abs() > grad[i + 1].abs())
            .map(|i| {
                let (g0, g1, g2) = (grad[i - 1].abs() as f64, grad[i].abs() as f64, grad[i + 1].abs() as f64);
                let denom = g0 - 2.0 * g1 + g2;
                let offset = if denom < 0.0 { (0.5 * (g0 - g2) / denom).clamp(-0.5, 0.5) } else { 0.0 };
                (grad[i].abs(), (i as f64 + offset) * STEP_PX, if grad[i] > 0.0 { 1 } else { -1 })
            })
            .collect();
        peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
        for &(_, r, sign) in peaks.iter().take(opts.edges_per_ray) {
            edges.push(Edge { ray, x: centre[0] + r * dx, y: centre[1] + r * dy, sign });
        }
    }
    (edges, reach)
}

/// Circle through three points, if they are not (nearly) collinear.
fn circle_through(p: [(f64, f64); 3]) -> Option<([f64; 2], f64)> {
    let [(ax, ay), (bx, by), (cx, cy)] = p;
    let d = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by));
    if d.abs() < 1e-9 {
        return None;
    }
    let (a2, b2, c2) = (ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy);
    let ux = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / d;
    let uy = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / d;
    Some(([ux, uy], (ax - ux).hypot(ay - uy)))
}

/// Per ray, the edge of `sign` nearest the circle within `tol` px (one per ray at most).
fn supporting(edges: &[Edge], rays: usize, centre: [f64; 2], radius: f64, sign: i8, tol: f64) -> Vec<&Edge> {
    let mut best: Vec<Option<(f64, &Edge)>> = vec![None; rays];
    for e in edges.iter().filter(|e| e.sign == sign) {
        let d = ((e.x - centre[0]).hypot(e.y - centre[1]) - radius).abs();
        if d <= tol && best[e.ray].is_none_or(|(b, _)| d < b) {
            best[e.ray] = Some((d, e));
        }
    }
    best.into_iter().flatten().map(|(_, e)| e).collect()
}

/// Number of rays (of `reach`, sampled from `origin`) that cross the circle inside the image.
fn rays_crossing(origin: [f64; 2], reach: &[f64], centre: [f64; 2], radius: f64) -> usize {
    let n = reach.len();
    (0..n)
        .filter(|&k| {
            let a = k as f64 * std::f64::consts::TAU / n as f64;
            // Distance along the ray to the circle (the far intersection from the ray's origin).
            let (dx, dy) = (a.cos(), a.sin());
            let (ox, oy) = (origin[0] - centre[0], origin[1] - centre[1]);
            let b = ox * dx + oy * dy;
            let c = ox * ox + oy * oy - radius * radius;
            let disc = b * b - c;
            disc >= 0.0 && -b + disc.sqrt() <= reach[k]
        })
        .count()
}

/// RANSAC: circles (centre, radius, sign, support count) through same-signed edges on three
/// rays at least 30° apart, best first, radii within `radius_range`.
fn ransac_circles(
    edges: &[Edge],
    opts: &RimOptions,
    radius_range: (f64, f64),
    seed: u64,
) -> Vec<([f64; 2], f64, i8, usize)> {
    let mut rng = SplitMix64::new(seed);
    let mut found: Vec<([f64; 2], f64, i8, usize)> = Vec::new();
    if edges.len() < 3 {
        return found;
    }
    let min_gap = opts.rays / 12;
    let ray_gap = |a: usize, b: usize| {
        let d = a.abs_diff(b);
        d.min(opts.rays - d)
    };
    for _ in 0..opts.trials {
        let pick = |rng: &mut SplitMix64| edges[(rng.next_u64() % edges.len() as u64) as usize];
        let (a, b, c) = (pick(&mut rng), pick(&mut rng), pick(&mut rng));
        if a.sign != b.sign || a.sign != c.sign {
            continue;
        }
        if ray_gap(a.ray, b.ray) < min_gap || ray_gap(a.ray, c.ray) < min_gap || ray_gap(b.ray, c.ray) < min_gap {
            continue;
        }
        let Some((centre, radius)) = circle_through([(a.x, a.y), (b.x, b.y), (c.x, c.y)]) else { continue };
        if !(radius_range.0..=radius_range.1).contains(&radius) {
            continue;
        }
        let support = supporting(edges, opts.rays, centre, radius, a.sign, opts.inlier_px).len();
        // Keep distinct circles only (a better copy replaces a worse one).
        match found.iter_mut().find(|f| {
            f.2 == a.sign && (f.0[0] - centre[0]).hypot(f.0[1] - centre[1]) < 3.0 && (f.1 - radius).abs() < 3.0
        }) {
            Some(f) if f.3 < support => *f = (centre, radius, a.sign, support),
            Some(_) => {}
            None => found.push((centre, radius, a.sign, support)),
        }
    }
    found.sort_by_key(|f| std::cmp::Reverse(f.3));
    found
}

/// Refines a circle hypothesis by re-sampling the rays from its centre and least-squares fits to
/// the per-ray edges nearest to it, with a shrinking tolerance.
fn refine(img: &GrayF32, start: ([f64; 2], f64, i8), opts: &RimOptions) -> Option<RimCircle> {
    let (mut centre, mut radius, sign) = start;
    let mut result = None;
    for tol in [3.0, 1.5, 1.0, 1.0] {
        let (edges, reach) = radial_edges(img, centre, opts);
        let support = supporting(&edges, opts.rays, centre, radius, sign, tol);
        let crossing = rays_crossing(centre, &reach, centre, radius).max(1);
        let pts: Vec<(f64, f64)> = support.iter().map(|e| (e.x, e.y)).collect();
        let ((x, y), r, rms) = omni_geom::fit::fit_circle_2d(&pts)?;
        result = Some(RimCircle {
            centre: [x, y],
            radius: r,
            rms_px: rms,
            support: support.len() as f64 / crossing as f64,
            sign,
        });
        (centre, radius) = ([x, y], r);
    }
    result
}

/// Finds the mirror's outer rim circle and, if visible, the blind-centre circle in a grey image
/// (e.g. a lit scene, or [`range_image`] of the board images). Errors say why no rim was found.
pub fn detect_rim(img: &GrayF32, opts: &RimOptions) -> Result<Rim, String> {
    if img.width < 32 || img.height < 32 {
        return Err(format!("image of {} × {} px is too small to find the mirror rim", img.width, img.height));
    }
    if opts.rays < 36 || opts.edges_per_ray == 0 || !(opts.min_support > 0.0 && opts.min_support <= 1.0) {
        return Err("rim options: need ≥ 36 rays, ≥ 1 edge per ray, 0 < min_support ≤ 1".into());
    }
    let smooth = gaussian_blur(img, opts.blur_sigma_px);
    let guess = [(img.width as f64 - 1.0) / 2.0, (img.height as f64 - 1.0) / 2.0];
    let (edges, _) = radial_edges(&smooth, guess, opts);
    let size = img.width.min(img.height) as f64;
    let hypotheses = ransac_circles(&edges, opts, (0.1 * size, 0.75 * img.width.max(img.height) as f64), 1);
    // Refine the best few distinct hypotheses; keep those supported all around.
    let mut circles: Vec<RimCircle> = hypotheses
        .iter()
        .take(8)
        .filter_map(|&(c, r, s, _)| refine(&smooth, (c, r, s), opts))
        .filter(|c| c.support >= opts.min_support && c.rms_px.is_finite())
        .collect();
    if circles.is_empty() {
        let best = hypotheses.first().map_or(0.0, |h| h.3 as f64 / opts.rays as f64);
        return Err(format!(
            "no mirror rim found: the best circular edge is supported by {:.0} % of the rays (need {:.0} %); \
             use an image of a lit scene or more board images",
            100.0 * best,
            100.0 * opts.min_support
        ));
    }
    // The outer rim: the largest circle that is nearly as well supported as the best.
    let best_support = circles.iter().map(|c| c.support).fold(0.0, f64::max);
    circles.retain(|c| c.support >= 0.8 * best_support);
    let outer = *circles.iter().max_by(|a, b| a.radius.total_cmp(&b.radius)).expect("non-empty");
    let inner = blind_centre(&smooth, &outer, opts);
    Ok(Rim { outer, inner })
}

/// The best-supported circle well inside the rim (≤ 70 % of its radius) about the same centre.
fn blind_centre(smooth: &GrayF32, outer: &RimCircle, opts: &RimOptions) -> Option<RimCircle> {
    let (edges, _) = radial_edges(smooth, outer.centre, opts);
    let near = 3.0 + 0.02 * outer.radius;
    ransac_circles(&edges, opts, (4.0, 0.7 * outer.radius), 2)
        .into_iter()
        .filter(|h| (h.0[0] - outer.centre[0]).hypot(h.0[1] - outer.centre[1]) < near)
        .take(4)
        .filter_map(|(c, r, s, _)| refine(smooth, (c, r, s), opts))
        .filter(|c| {
            c.support >= opts.min_support
                && (c.centre[0] - outer.centre[0]).hypot(c.centre[1] - outer.centre[1]) < near
                && c.radius < 0.7 * outer.radius
        })
        .max_by(|a, b| a.support.total_cmp(&b.support))
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_simulator::{RenderOptions, Scene, Sensor};

    /// The true circles of the rim and of the blind centre: radii from the camera's
    /// `mirror_circle()`; centres as the image of the mirror axis at each circle's own height (with
    /// the camera off the axis by o, a circle at height z about the axis is centred at
    /// c − f·o/(z − o_z); `mirror_circle()` gives it at the vertex).
    struct Truth {
        outer_centre: [f64; 2],
        inner_centre: [f64; 2],
        circle: omni_model::MirrorCircle,
    }

    /// The paper's camera scaled to `width` px with its principal point moved by `offset` px and
    /// the camera off the mirror axis by `off_mm`, and its true circles.
    fn camera(width: u32, offset: [f64; 2], off_mm: [f64; 3]) -> (omni_model::HyperbolicParams, Truth) {
        let mut cam = omni_simulator::paper_camera_scaled(width);
        cam.cx_px += offset[0];
        cam.cy_px += offset[1];
        cam.camera_offset_mm = off_mm;
        let model = omni_model::HyperbolicCamera::new(cam.clone()).unwrap();
        let f = 0.5 * (cam.fx_px + cam.fy_px);
        let centre_at = |r_mm: f64| {
            let z = model.mirror_z(r_mm) - off_mm[2];
            [cam.cx_px - f * off_mm[0] / z, cam.cy_px - f * off_mm[1] / z]
        };
        let truth = Truth {
            outer_centre: centre_at(cam.rim_radius_mm),
            inner_centre: centre_at(cam.inner_radius_mm),
            circle: omni_model::CameraModel::mirror_circle(&model),
        };
        (cam, truth)
    }

    /// The room scene rendered in ambient light (calibration noise) by [`camera`].
    fn lit_room(width: u32, offset: [f64; 2], off_mm: [f64; 3]) -> (GrayF32, Truth) {
        let (cam, truth) = camera(width, offset, off_mm);
        let sensor = Sensor::from_params(cam, omni_model::TransmitterParams::paper()).unwrap();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/scenes/room.json");
        let scene = Scene::load(std::path::Path::new(path)).unwrap();
        let frame = omni_simulator::render_ambient_frame(&sensor, &scene, &RenderOptions::calibration());
        (GrayF32::from_u16(frame.width as usize, frame.height as usize, &frame.data), truth)
    }

    /// Errors (px): outer centre distance, outer radius, inner centre distance, inner radius.
    fn errors(rim: &Rim, truth: &Truth) -> [f64; 4] {
        let dist = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
        let inner = rim.inner.expect("blind centre found");
        [
            dist(rim.outer.centre, truth.outer_centre),
            rim.outer.radius - truth.circle.outer_radius,
            dist(inner.centre, truth.inner_centre),
            inner.radius - truth.circle.inner_radius,
        ]
    }

    /// A lit room seen by an off-centre camera (on the axis, and 0.3 mm off it): rim and blind
    /// centre within 0.5 px (centre and radius) of the true circles. Measured: centres ≤ 0.014 px,
    /// radii −0.013..−0.041 px, fit RMS 0.07–0.09 px.
    #[test]
    fn rim_of_a_lit_scene_matches_the_true_mirror_circle() {
        for (width, offset, off_mm) in [(384, [6.3, -4.1], [0.0; 3]), (512, [-3.7, 2.2], [0.3, -0.2, 0.1])] {
            let (img, truth) = lit_room(width, offset, off_mm);
            let rim = detect_rim(&img, &RimOptions::default()).unwrap();
            let e = errors(&rim, &truth);
            eprintln!(
                "{width} px, camera off axis {off_mm:?} mm: outer centre {:.3} px, radius {:+.3} px; inner centre \
                 {:.3} px, radius {:+.3} px; fit rms {:.3}/{:.3} px",
                e[0],
                e[1],
                e[2],
                e[3],
                rim.outer.rms_px,
                rim.inner.unwrap().rms_px
            );
            if off_mm == [0.0; 3] {
                let c = truth.circle.centre;
                let d = (rim.outer.centre[0] - c.x).hypot(rim.outer.centre[1] - c.y);
                assert!(d <= 0.5, "centre {d} px from mirror_circle()");
            }
            assert!(e.iter().all(|v| v.abs() <= 0.5), "errors {e:?} px (outer centre, radius, inner centre, radius)");
            assert!(rim.outer.support > 0.95 && rim.inner.unwrap().support > 0.95, "{rim:?}");
        }
    }

    /// Only board images (on black): the range of the simulator's calibration board set (close
    /// boards covering the whole mirror) shows the rim wherever a board reached it. Measured:
    /// centre 0.018 px, outer radius −0.022 px, blind centre +0.091 px (68 % of the rays support
    /// the rim). The demo's 20 random, far boards reach it on only ~15 % of the rays: refused.
    #[test]
    fn rim_of_the_board_images_range_matches_the_true_mirror_circle() {
        use omni_simulator::{calibration_board_poses, render_board_image};
        let (cam, t) = camera(384, [2.4, -1.7], [0.0; 3]);
        let sensor = Sensor::from_params(cam, omni_model::TransmitterParams::paper()).unwrap();
        let board = omni_formats::BoardFile::new(9, 6, 30.0);
        let poses = calibration_board_poses(&sensor, &board, 20, 2).unwrap();
        let images: Vec<GrayF32> = poses
            .iter()
            .enumerate()
            .map(|(k, pose)| {
                let opts = RenderOptions { seed: k as u64, ..RenderOptions::calibration() };
                let (frame, _) = render_board_image(&sensor, pose, &board, &opts);
                GrayF32::from_u16(frame.width as usize, frame.height as usize, &frame.data)
            })
            .collect();
        let rim = detect_rim(&range_image(&images).unwrap(), &RimOptions::default()).unwrap();
        // The single images (a board on black) show no better rim: the range is taken.
        let chosen = rim_image(&images, &RimOptions::default()).unwrap();
        assert_eq!((chosen.source, chosen.rim), (RimSource::Range, rim));
        let dc = (rim.outer.centre[0] - t.outer_centre[0]).hypot(rim.outer.centre[1] - t.outer_centre[1]);
        let dr = rim.outer.radius - t.circle.outer_radius;
        let di = rim.inner.map(|i| i.radius - t.circle.inner_radius);
        eprintln!("boards range: centre {dc:.3} px, outer radius {dr:+.3} px, inner {di:?}; {rim:?}");
        assert!(dc <= 0.5 && dr.abs() <= 0.5, "centre {dc} px, radius {dr} px off");
        assert!(di.is_some_and(|d| d.abs() <= 0.5), "blind centre radius off by {di:?} px");
    }

    /// Boards held in a static lit room (the simulator's close calibration boards, rendered in
    /// the room scene): the range shows only where the boards were, not the rim; each single
    /// image shows the rim but where its board covers it, and the best of them is taken.
    #[test]
    fn a_static_lit_room_board_set_shows_the_rim_in_its_best_single_image() {
        use omni_simulator::{board_object, calibration_board_poses, render_ambient_frame};
        use rayon::prelude::*;
        let (cam, t) = camera(320, [3.1, -2.2], [0.0; 3]);
        let sensor = Sensor::from_params(cam, omni_model::TransmitterParams::paper()).unwrap();
        let board = omni_formats::BoardFile::new(9, 6, 30.0);
        let poses = calibration_board_poses(&sensor, &board, 5, 3).unwrap();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/scenes/room.json");
        let room = Scene::load(std::path::Path::new(path)).unwrap().file().clone();
        let images: Vec<GrayF32> = poses
            .par_iter()
            .enumerate()
            .map(|(k, pose)| {
                let mut file = room.clone();
                file.objects.push(board_object(&board, pose));
                let opts = RenderOptions { seed: k as u64, ..RenderOptions::calibration() };
                let frame = render_ambient_frame(&sensor, &Scene::from_file(file).unwrap(), &opts);
                GrayF32::from_u16(frame.width as usize, frame.height as usize, &frame.data)
            })
            .collect();
        let range = detect_rim(&range_image(&images).unwrap(), &RimOptions::default());
        eprintln!("static lit room, range: {range:?}");
        let found = rim_image(&images, &RimOptions::default()).unwrap();
        let e = errors(&found.rim, &t);
        eprintln!(
            "best single image: {:?}, support {:.2}; errors {e:?} px; range: {:?}",
            found.source, found.rim.outer.support, found.range_error
        );
        // The range alone fails: no circle, or a false one well inside the rim.
        assert!(match &range {
            Err(e) => e.contains("supported by"),
            Ok(r) => r.outer.radius < 0.5 * t.circle.outer_radius,
        });
        assert!(matches!(found.source, RimSource::Single(_)) && found.range_error.is_some(), "{:?}", found.source);
        assert!(e.iter().all(|v| v.abs() <= 0.5), "errors {e:?} px (outer centre, radius, inner centre, radius)");
    }

    /// The real MiniOmni set (read from the shared data folder): its rim, a blurred glass ring,
    /// shows all round only in the range of its 15 board images (lit room, hand-held board).
    #[test]
    fn real_miniomni_set_rim_and_its_single_images() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/real-omni-miniomni");
        let images: Vec<GrayF32> = (1..=15)
            .map(|k| crate::corners::load_gray(&std::path::Path::new(dir).join(format!("MiniOmni{k}.jpg"))).unwrap())
            .collect();
        let chosen = rim_image(&images, &RimOptions::default()).unwrap();
        eprintln!("MiniOmni set: {:?} {:?}", chosen.source, chosen.rim);
        // Measured: centre (364.04, 225.16) px, radius 257.29 px, 56 % of the rays; each single
        // image's best circle has 22–33 % (refused), so the fallback keeps the range.
        assert_eq!(chosen.source, RimSource::Range);
        let [cx, cy] = chosen.rim.outer.centre;
        assert!(
            (cx - 364.0).hypot(cy - 225.2) < 1.0 && (chosen.rim.outer.radius - 257.3).abs() < 1.0,
            "{:?}",
            chosen.rim
        );
        let single = detect_rim(&images[0], &RimOptions::default()).unwrap_err();
        assert!(single.contains("supported by"), "{single}");
    }

    #[test]
    fn an_image_without_a_circle_is_refused_with_the_reason() {
        let mut img = GrayF32::new(200, 150);
        for (i, v) in img.data.iter_mut().enumerate() {
            // A vertical step edge: straight, not a circle.
            *v = if i % 200 < 80 { 20.0 } else { 200.0 };
        }
        let err = detect_rim(&img, &RimOptions::default()).unwrap_err();
        assert!(err.contains("no mirror rim found"), "{err}");
        assert!(detect_rim(&GrayF32::new(10, 10), &RimOptions::default()).unwrap_err().contains("too small"));
    }

    #[test]
    fn range_image_is_max_minus_min_and_checks_sizes() {
        let a = GrayF32::from_u8(2, 1, &[10, 200]);
        let b = GrayF32::from_u8(2, 1, &[50, 20]);
        assert_eq!(range_image(&[a.clone(), b]).unwrap().data, vec![40.0, 180.0]);
        assert_eq!(range_image(std::slice::from_ref(&a)).unwrap().data, vec![10.0, 200.0]);
        assert!(range_image(&[a, GrayF32::new(1, 1)]).unwrap_err().contains("image 1 is 1 × 1 px"));
        assert!(range_image(&[]).is_err());
    }
}
