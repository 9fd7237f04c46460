//! Prints a rendered frame's statistics (stripe pixels, peak, SNR, render time) for the paper
//! bench: `cargo run --release -p omni-simulator --example frame_stats -- [plane|cylinder|sphere] [alpha_deg]`.

use omni_simulator::{
    BenchObject, RenderOptions, Scene, Sensor, paper_bench, render_ambient_frame, render_laser_frame,
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
    let alpha: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(15.0);
    let sensor = Sensor::paper();
    let scene = Scene::from_file(paper_bench(object)).unwrap();
    let opts = RenderOptions::default();
    let t = Instant::now();
    let frame = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0, 1], &opts);
    let dt = t.elapsed();
    let ambient = render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 1, ..opts.clone() });
    let diff: Vec<f64> = frame.image.data.iter().zip(&ambient.data).map(|(a, b)| *a as f64 - *b as f64).collect();
    let stripe = diff.iter().filter(|d| **d > 20.0).count();
    let peak = frame.image.data.iter().copied().max().unwrap();
    let bg: Vec<f64> = diff.iter().copied().filter(|d| d.abs() < 20.0).collect();
    let sd = (bg.iter().map(|d| d * d).sum::<f64>() / bg.len() as f64 / 2.0).sqrt();
    let amb_max = ambient.data.iter().copied().max().unwrap();
    println!(
        "{object:?} α={alpha}°: render {:.3} s, truth points {}, stripe pixels (>20 DN over ambient) {stripe}, peak {peak}, ambient max {amb_max}, noise σ {sd:.2} DN, SNR {:.1}",
        dt.as_secs_f64(),
        frame.truth.len(),
        (peak as f64 - amb_max as f64) / sd
    );
}
