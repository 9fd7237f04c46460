//! The stripe detector on the virtual sensor's frames against their ground truth: accuracy
//! across the stripe, coverage of the visible stripe in every direction, false points.

use omni_simulator::{
    BenchObject, RenderOptions, Scene, Sensor, TruthPoint, paper_bench, render_laser_frame, truth_polylines,
};
use omni_vision::image_io::GrayImage;
use omni_vision::stripe::{RidgeDetector, RidgeParams, StripePoint};

const SIZE: u32 = 1024;

/// A detection farther than this (px) from every truth curve is false.
const FALSE_PX: f64 = 2.0;
/// A truth sample is covered by a detection within this distance (px).
const COVER_PX: f64 = 1.0;

#[derive(Default)]
struct Tally {
    /// Signed perpendicular errors (px; + away from the mirror centre).
    errors: Vec<f64>,
    false_points: usize,
    /// Truth samples per 10° band of stripe-to-ray angle, and how many are covered.
    band_total: [usize; 9],
    band_covered: [usize; 9],
}

impl Tally {
    fn rms_bias(&self) -> (f64, f64) {
        let n = self.errors.len().max(1) as f64;
        let rms = (self.errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        (rms, self.errors.iter().sum::<f64>() / n)
    }
    fn coverage(&self, band: usize) -> Option<f64> {
        (self.band_total[band] >= 40).then(|| self.band_covered[band] as f64 / self.band_total[band] as f64)
    }
    fn line(&self, name: &str) -> String {
        let (rms, bias) = self.rms_bias();
        let mut a: Vec<f64> = self.errors.iter().map(|e| e.abs()).collect();
        a.sort_by(f64::total_cmp);
        let q = |f: f64| a.get(((a.len() as f64 - 1.0) * f) as usize).cloned().unwrap_or(0.0);
        let rms = format!("{rms:.4} (p50 {:.3} p90 {:.3} p99 {:.3})", q(0.5), q(0.9), q(0.99));
        let cov: Vec<String> =
            (0..9).map(|b| self.coverage(b).map_or("  -  ".into(), |c| format!("{:5.1}", 100.0 * c))).collect();
        format!(
            "{name:<24} {:6} pts rms {rms} bias {bias:+.4} false {:5.2}% | coverage by 10° band: {}",
            self.errors.len(),
            100.0 * self.false_points as f64 / (self.errors.len() + self.false_points).max(1) as f64,
            cov.join(" ")
        )
    }
}

fn add(t: &mut Tally, points: &[StripePoint], truth: &[TruthPoint], centre: (f64, f64)) {
    let lines = truth_polylines(truth);
    let segs: Vec<([f64; 2], [f64; 2])> =
        lines.iter().flat_map(|l| l.windows(2).map(|w| (w[0].pixel, w[1].pixel))).collect();
    for p in points {
        let mut best: Option<(f64, f64)> = None; // (distance, signed)
        for (a, b) in &segs {
            let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
            let len2 = ex * ex + ey * ey;
            if len2 == 0.0 {
                continue;
            }
            let s = (((p.u - a[0]) * ex + (p.v - a[1]) * ey) / len2).clamp(0.0, 1.0);
            let (qx, qy) = (a[0] + s * ex, a[1] + s * ey);
            let d = (p.u - qx).hypot(p.v - qy);
            if best.is_none_or(|b| d < b.0) {
                let outward = (p.u - qx) * (qx - centre.0) + (p.v - qy) * (qy - centre.1);
                best = Some((d, if outward >= 0.0 { d } else { -d }));
            }
        }
        match best {
            Some((d, signed)) if d <= FALSE_PX => t.errors.push(signed),
            _ => t.false_points += 1,
        }
    }
    for line in &lines {
        for i in 1..line.len().saturating_sub(1) {
            let (a, b) = (line[i - 1].pixel, line[i + 1].pixel);
            let q = line[i].pixel;
            let (tx, ty) = (b[0] - a[0], b[1] - a[1]);
            let (rx, ry) = (q[0] - centre.0, q[1] - centre.1);
            let cos = ((tx * rx + ty * ry) / (tx.hypot(ty) * rx.hypot(ry)).max(1e-12)).abs().min(1.0);
            let beta = cos.acos().to_degrees();
            let band = ((beta / 10.0) as usize).min(8);
            t.band_total[band] += 1;
            if points.iter().any(|p| (p.u - q[0]).hypot(p.v - q[1]) <= COVER_PX) {
                t.band_covered[band] += 1;
            }
        }
    }
}

fn to_gray(f: &omni_simulator::Frame16) -> GrayImage {
    GrayImage { width: f.width, height: f.height, bit_depth: f.bit_depth, data: f.data.clone() }
}

fn bench(object: BenchObject, opts: &RenderOptions, params: RidgeParams) -> Tally {
    let sensor = Sensor::paper_scaled(SIZE);
    let scene = Scene::from_file(paper_bench(object)).unwrap();
    let circle = sensor.camera.mirror_circle();
    let det = RidgeDetector::new(SIZE, SIZE, circle, params);
    let mut t = Tally::default();
    for (i, alpha) in [15.0f64, 17.5, 20.0, 22.5, 25.0, 27.5].into_iter().enumerate() {
        let o = RenderOptions { seed: i as u64, ..opts.clone() };
        let f = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0, 1], &o);
        add(&mut t, &det.detect(&to_gray(&f.image)), &f.truth, (circle.centre.x, circle.centre.y));
    }
    t
}

#[test]
fn explore_params() {
    let opts = RenderOptions::default();
    for (label, params) in [
        ("dbg", RidgeParams::default()),
        ("default", RidgeParams::default()),
        ("min_width 0.2", RidgeParams { min_width: 0.2, ..Default::default() }),
        ("thr 30", RidgeParams { threshold: Some(30.0), ..Default::default() }),
        ("thr 30 minw 0.2", RidgeParams { threshold: Some(30.0), min_width: 0.2, ..Default::default() }),
    ] {
        for sampling in [omni_vision::stripe::Sampling::Rays, omni_vision::stripe::Sampling::Normal] {
            let t = bench(BenchObject::Plane, &opts, RidgeParams { sampling, ..params });
            eprintln!("{}", t.line(&format!("{label} {}", sampling.name())));
        }
    }
}

#[test]
fn explore() {
    for (name, opts) in [("ideal", RenderOptions::ideal()), ("realistic", RenderOptions::default())] {
        for object in [BenchObject::Plane, BenchObject::Cylinder, BenchObject::Sphere] {
            for (sampling, along) in [
                (omni_vision::stripe::Sampling::Rays, 0.0),
                (omni_vision::stripe::Sampling::Normal, 0.0),
                (omni_vision::stripe::Sampling::Normal, 3.0),
            ] {
                let t = bench(object, &opts, RidgeParams { sampling, along_stripe_px: along, ..Default::default() });
                eprintln!("{}", t.line(&format!("{name} {object:?} {} {along}", sampling.name())));
            }
        }
    }
}

#[test]
fn peek() {
    let sensor = Sensor::paper_scaled(SIZE);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let f = render_laser_frame(&sensor, &scene, 20f64.to_radians(), 0, &[0, 1], &RenderOptions::default());
    let g = to_gray(&f.image);
    let lines = truth_polylines(&f.truth);
    let mut peaks = vec![];
    for l in &lines {
        for q in l.iter().step_by(8) {
            let (x, y) = (q.pixel[0].round() as i64, q.pixel[1].round() as i64);
            let mut m = 0;
            for dy in -2..=2 {
                for dx in -2..=2 {
                    m = m.max(g.data[((y + dy) * SIZE as i64 + x + dx) as usize]);
                }
            }
            peaks.push(m);
        }
    }
    peaks.sort();
    eprintln!(
        "bit depth {} peaks: p10 {} p50 {} p90 {}",
        g.bit_depth,
        peaks[peaks.len() / 10],
        peaks[peaks.len() / 2],
        peaks[peaks.len() * 9 / 10]
    );
    let bg: Vec<u16> = g.data.iter().step_by(997).cloned().collect();
    eprintln!("background median {}", {
        let mut b = bg.clone();
        b.sort();
        b[b.len() / 2]
    });
    image::save_buffer(
        "/tmp/peek.png",
        &g.data.iter().map(|v| *v as u8).collect::<Vec<u8>>(),
        SIZE,
        SIZE,
        image::ColorType::L8,
    )
    .unwrap();
}

#[test]
fn outliers() {
    let sensor = Sensor::paper_scaled(SIZE);
    let object = if std::env::var("OBJ").is_ok() { BenchObject::Sphere } else { BenchObject::Cylinder };
    let scene = Scene::from_file(paper_bench(object)).unwrap();
    let circle = sensor.camera.mirror_circle();
    let det = RidgeDetector::new(SIZE, SIZE, circle, RidgeParams::default());
    for alpha in [15.0f64, 17.5, 20.0, 22.5, 25.0, 27.5] {
        let f = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0, 1], &RenderOptions::ideal());
        let pts = det.detect(&to_gray(&f.image));
        let lines = truth_polylines(&f.truth);
        for p in &pts {
            let mut t = Tally::default();
            add(&mut t, &[*p], &f.truth, (circle.centre.x, circle.centre.y));
            let e = t.errors.first().cloned().unwrap_or(9.0);
            if e.abs() > 0.05 {
                let end = lines
                    .iter()
                    .flat_map(|l| [l[0].pixel, l[l.len() - 1].pixel])
                    .map(|q| (q[0] - p.u).hypot(q[1] - p.v))
                    .fold(f64::INFINITY, f64::min);
                eprintln!(
                    "alpha {alpha} ({:.1}, {:.1}) err {e:+.3} width {:.2} int {:.0} end-dist {end:.1}",
                    p.u, p.v, p.width, p.intensity
                );
            }
        }
    }
}
