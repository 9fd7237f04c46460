//! Prints a rendered frame's statistics for the paper bench: render time, ground-truth samples,
//! stripe pixels, stripe peak, noise and SNR.
//! `cargo run --release -p omni-simulator --example frame_stats -- [plane|cylinder|sphere|cone] [alpha_deg] [ideal]`
//! (set `RAYON_NUM_THREADS=1` for the one-core figure).

use omni_simulator::{
    BenchObject, Imaging, RenderOptions, Scene, Sensor, paper_bench, render_ambient_frame, render_laser_frame,
};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let object = match args.get(1).map(String::as_str) {
        Some("cylinder") => BenchObject::Cylinder,
        Some("sphere") => BenchObject::Sphere,
        Some("cone") => BenchObject::ConePyramid,
        _ => BenchObject::Plane,
    };
    let alpha: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(20.0);
    let sensor = Sensor::paper();
    let scene = Scene::from_file(paper_bench(object)).unwrap();
    let ideal = args.get(3).is_some_and(|a| a == "ideal");
    let opts = if ideal { RenderOptions::ideal() } else { RenderOptions::default() };
    // The same frame without noise or speckle, and its laser-off frame.
    let quiet = RenderOptions {
        noise: false,
        imaging: match opts.imaging {
            Imaging::Lens { optics, .. } => Imaging::Lens { optics, speckle: false },
            g => g,
        },
        ..opts.clone()
    };
    let (t, cpu0) = (Instant::now(), process_cpu_seconds());
    let frame = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0, 1], &opts);
    let seconds = t.elapsed().as_secs_f64();
    let cpu = process_cpu_seconds().zip(cpu0).map_or(f64::NAN, |(b, a)| b - a);
    let clean = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0, 1], &quiet);
    let ambient = render_ambient_frame(&sensor, &scene, &quiet);
    let laser: Vec<f64> = clean.image.data.iter().zip(&ambient.data).map(|(a, b)| *a as f64 - *b as f64).collect();
    let stripe: Vec<usize> = (0..laser.len()).filter(|&i| laser[i] > 20.0).collect();
    let peak = stripe.iter().map(|&i| clean.image.data[i]).max().unwrap_or(0);
    // Noise at the stripe (photon, read and speckle): rendered − quiet over the stripe pixels.
    let residual: Vec<f64> = stripe.iter().map(|&i| frame.image.data[i] as f64 - clean.image.data[i] as f64).collect();
    let sigma = (residual.iter().map(|r| r * r).sum::<f64>() / residual.len().max(1) as f64).sqrt();
    let peak_laser = stripe.iter().map(|&i| laser[i]).fold(0.0, f64::max);
    println!(
        "{object:?} α = {alpha}°, {} × {} px: render {seconds:.3} s wall, {cpu:.2} s CPU; truth samples {}; stripe pixels (> 20 DN above \
         ambient) {}; stripe peak {peak} of 255 ({peak_laser:.0} DN of laser over ambient); noise at the stripe σ = \
         {sigma:.2} DN; peak SNR {:.0}",
        frame.image.width,
        frame.image.height,
        frame.truth.len(),
        stripe.len(),
        peak_laser / sigma.max(1e-9)
    );
}

/// User + system CPU time of the whole process (s), from /proc (Linux; `None` elsewhere): on a
/// busy machine this, not the wall clock, is the one-core cost.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit(')').next()?.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
