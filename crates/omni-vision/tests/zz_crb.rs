use omni_simulator::{
    BenchObject, RenderOptions, Scene, Sensor, SheetProfile, paper_bench, render_laser_frame, truth_polylines,
};

#[test]
fn zz_crb() {
    let sensor = Sensor::paper_scaled(1024);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let fwhms: Vec<f64> = std::env::var("CRB_W")
        .map(|s| s.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or(vec![2.0, 5.0, 10.0, 20.0]);
    for fwhm in fwhms {
        let ideal = RenderOptions::ideal();
        let gaussian = std::env::var_os("CRB_GAUSS").is_some();
        let opts = RenderOptions {
            profile: if gaussian { SheetProfile::Gaussian } else { SheetProfile::real() },
            stripe_fwhm_px: Some(fwhm),
            laser_strength: ideal.laser_strength * fwhm / 2.0,
            noise: false,
            bit_depth: 16,
            ..ideal.clone()
        };
        let e_per_dn = opts.full_well_e / 65535.0;
        let q8 = opts.full_well_e / 255.0;
        let extra = opts.read_noise_e.powi(2) + q8 * q8 / 12.0;
        let (mut info, mut length, mut peak) = (0.0, 0.0, 0.0f64);
        for i in 0..8 {
            let alpha = 15.0 + 12.5 * i as f64 / 8.0;
            let f1 = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0, 1], &opts);
            let f2 = render_laser_frame(&sensor, &scene, (alpha + 0.01).to_radians(), 0, &[0, 1], &opts);
            let (w, h) = (f1.image.width as usize, f1.image.height as usize);
            let lines1 = truth_polylines(&f1.truth);
            let pts2: Vec<[f64; 2]> = f2.truth.iter().map(|t| t.pixel).collect();
            // samples: (x, y, nx, ny, delta, arc)
            let mut samples = Vec::new();
            for l in &lines1 {
                for k in 1..l.len().saturating_sub(1) {
                    let (a, b) = (l[k - 1].pixel, l[k + 1].pixel);
                    let (tx, ty) = (b[0] - a[0], b[1] - a[1]);
                    let n = (tx * tx + ty * ty).sqrt();
                    if n == 0.0 {
                        continue;
                    }
                    let (nx, ny) = (-ty / n, tx / n);
                    let p = l[k].pixel;
                    // signed shift: nearest f2 truth point's offset along n
                    let mut best = (f64::INFINITY, 0.0);
                    for q in &pts2 {
                        let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
                        let d2 = dx * dx + dy * dy;
                        if d2 < 9.0 {
                            let along = -ny * dx + nx * dy;
                            let across = nx * dx + ny * dy;
                            if along.abs() < best.0 {
                                best = (along.abs(), across);
                            }
                        }
                    }
                    if best.0 > 0.3 {
                        continue;
                    }
                    samples.push((p[0], p[1], nx, ny, best.1, 0.5 * n));
                }
            }
            // nearest sample per pixel
            let reach = (1.5 * fwhm + 4.0).ceil() as i64;
            let mut owner = vec![(f64::INFINITY, usize::MAX); w * h];
            for (s, &(x, y, ..)) in samples.iter().enumerate() {
                for yy in (y as i64 - reach).max(0)..=(y as i64 + reach).min(h as i64 - 1) {
                    for xx in (x as i64 - reach).max(0)..=(x as i64 + reach).min(w as i64 - 1) {
                        let d2 = (xx as f64 - x).powi(2) + (yy as f64 - y).powi(2);
                        let o = &mut owner[yy as usize * w + xx as usize];
                        if d2 < o.0 {
                            *o = (d2, s);
                        }
                    }
                }
            }
            let mut per_sample = vec![0.0; samples.len()];
            for (i, &(_, s)) in owner.iter().enumerate() {
                if s == usize::MAX {
                    continue;
                }
                let delta = samples[s].4;
                if delta.abs() < 1e-4 {
                    continue;
                }
                let m1 = f1.image.data[i] as f64 * e_per_dn;
                let m2 = f2.image.data[i] as f64 * e_per_dn;
                peak = peak.max(m1);
                let d = (m2 - m1) / delta;
                per_sample[s] += d * d / (m1 + extra);
            }
            for (s, v) in per_sample.iter().enumerate() {
                // drop the curve's ends (pixels beyond them are owned by the end samples)
                let _ = s;
                info += v;
            }
            length += samples.iter().map(|s| s.5).sum::<f64>();
            let deltas: Vec<f64> = samples.iter().map(|s| s.4).collect();
            if i == 0 {
                eprintln!(
                    "  delta {:.4}..{:.4} px, {} samples",
                    deltas.iter().cloned().fold(f64::INFINITY, f64::min),
                    deltas.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
                    samples.len()
                );
            }
        }
        let per_px = info / length;
        eprintln!(
            "CRB {fwhm} px (peak {:.0} e-): 1 px of stripe {:.4} px, 2.84 px {:.4} px",
            peak,
            1.0 / per_px.sqrt(),
            1.0 / (2.84 * per_px).sqrt()
        );
    }
}
