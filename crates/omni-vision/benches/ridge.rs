//! Stripe-centre extraction speed, in ms per megapixel on one core, for every estimator, on
//! 8-bit 1024 × 1024 frames of the virtual sensor already in memory (decoding excluded).
//! Targets (issue 4): ≤ 1 ms/MP for the centroid estimators, ≤ 5 ms/MP for the Hessian one.
//!
//! Frames: the paper sensor in a 1.6 × 1.6 × 1.0 m room (two long stripes around the image) and
//! the paper-bench plane, default camera (noise, dim ambient, no laser-off frame). They are also
//! written as PNG to `$OMNI_RIDGE_BENCH_DIR` (default: a temporary directory) for the Python
//! reference (`scripts/bench_ridge.py`); `scripts/bench_ridge.sh` runs both and prints the ratio.
//! Besides criterion's report, one line per method starts with `SUMMARY`: the wall-clock median
//! of 30 runs, and the thread's CPU time per run over 200 runs (Linux), which other processes
//! on a busy machine do not inflate.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use omni_formats::scene::{SceneFile, SceneObject, Shape};
use omni_simulator::{BenchObject, RenderOptions, Scene, Sensor, paper_bench, render_laser_frame};
use omni_vision::image_io::{GrayImage, write_gray_png};
use omni_vision::stripe::{Frame, Method, RidgeDetector, RidgeParams, Scratch};
use std::path::PathBuf;
use std::time::Instant;

struct BenchFrame {
    name: &'static str,
    pixels: Vec<u8>,
}

fn frames(sensor: &Sensor) -> Vec<BenchFrame> {
    let room = SceneFile::new(vec![SceneObject {
        name: Some("room".into()),
        albedo: 0.8,
        shape: Shape::Room { centre_mm: [0.0, 0.0, 0.0], size_mm: [1600.0, 1600.0, 1000.0] },
    }]);
    let cases = [
        ("room_alpha22", Scene::from_file(room).unwrap(), 22.0f64),
        ("plane_alpha20", Scene::from_file(paper_bench(BenchObject::Plane)).unwrap(), 20.0),
    ];
    let dir = std::env::var_os("OMNI_RIDGE_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("omni-ridge-bench"));
    std::fs::create_dir_all(&dir).unwrap();
    cases
        .into_iter()
        .map(|(name, scene, alpha)| {
            let lf = render_laser_frame(sensor, &scene, alpha.to_radians(), 0, &[0, 1], &RenderOptions::default());
            let img = GrayImage { width: lf.image.width, height: lf.image.height, bit_depth: 8, data: lf.image.data };
            write_gray_png(&dir.join(format!("{name}.png")), &img).unwrap();
            BenchFrame { name, pixels: img.to_u8() }
        })
        .collect()
}

fn ridge(c: &mut Criterion) {
    let sensor = Sensor::paper();
    let (w, h) = sensor.camera.image_size();
    let megapixels = (w * h) as f64 / 1e6;
    let frames = frames(&sensor);
    let circle = sensor.camera.mirror_circle();
    println!("CIRCLE {} {} {} {}", circle.centre.x, circle.centre.y, circle.inner_radius, circle.outer_radius);
    // `OMNI_RIDGE_PROFILE=<method>/<frame>`: only run that case for 10 s (for `perf record`;
    // `OMNI_RIDGE_PROFILE_SECONDS` changes the duration).
    if let Ok(case) = std::env::var("OMNI_RIDGE_PROFILE") {
        profile_one(&case, &sensor, &frames);
        return;
    }
    let mut group = c.benchmark_group("ridge_1024_8bit_one_core");
    group.sample_size(20);
    group.throughput(Throughput::Elements((w * h) as u64));
    for method in Method::ALL {
        let det = RidgeDetector::new(w, h, sensor.camera.mirror_circle(), RidgeParams { method, ..Default::default() });
        for f in &frames {
            let frame = Frame { width: w, height: h, data: &f.pixels, max_value: 255.0 };
            let mut scratch = Scratch::default();
            let points = det.detect_frame(&frame, &mut scratch).len();
            group.bench_function(format!("{}/{}", method.name(), f.name), |b| {
                b.iter(|| det.detect_frame(&frame, &mut scratch))
            });
            let mut times: Vec<f64> = (0..30)
                .map(|_| {
                    let t = Instant::now();
                    std::hint::black_box(det.detect_frame(&frame, &mut scratch));
                    t.elapsed().as_secs_f64()
                })
                .collect();
            times.sort_by(f64::total_cmp);
            // CPU time of this thread over many runs: unaffected by other processes competing
            // for the cores (wall-clock medians are, on a busy machine).
            let cpu = thread_cpu_seconds().and_then(|t0| {
                let runs = 200;
                for _ in 0..runs {
                    std::hint::black_box(det.detect_frame(&frame, &mut scratch));
                }
                thread_cpu_seconds().map(|t1| (t1 - t0) / runs as f64)
            });
            println!(
                "SUMMARY {} {} {:.3} ms/MP ({points} points){}",
                method.name(),
                f.name,
                1e3 * times[times.len() / 2] / megapixels,
                cpu.map_or(String::new(), |c| format!(", thread CPU time {:.3} ms/MP", 1e3 * c / megapixels))
            );
        }
    }
    group.finish();
}

/// Runs one `<method>/<frame>` case for 10 s (or `$OMNI_RIDGE_PROFILE_SECONDS`) and prints its
/// point count and mean time per run.
fn profile_one(case: &str, sensor: &Sensor, frames: &[BenchFrame]) {
    let (w, h) = sensor.camera.image_size();
    let (method, name) = case.split_once('/').expect("OMNI_RIDGE_PROFILE=<method>/<frame>");
    let method: Method = method.parse().unwrap();
    let f = frames.iter().find(|f| f.name == name).expect("frame: room_alpha22 or plane_alpha20");
    let det = RidgeDetector::new(w, h, sensor.camera.mirror_circle(), RidgeParams { method, ..Default::default() });
    let frame = Frame { width: w, height: h, data: &f.pixels, max_value: 255.0 };
    let mut scratch = Scratch::default();
    let points = det.detect_frame(&frame, &mut scratch).len();
    let (start, cpu0, mut runs) = (Instant::now(), thread_cpu_seconds(), 0u32);
    let seconds: f64 = std::env::var("OMNI_RIDGE_PROFILE_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(10.0);
    while start.elapsed().as_secs_f64() < seconds {
        std::hint::black_box(det.detect_frame(&frame, &mut scratch));
        runs += 1;
    }
    let mp = (w * h) as f64 / 1e6;
    let ms = 1e3 * start.elapsed().as_secs_f64() / runs as f64;
    let cpu = cpu0.zip(thread_cpu_seconds()).map(|(a, b)| 1e3 * (b - a) / runs as f64 / mp);
    println!(
        "PROFILE {case} ({points} points): {runs} runs, wall {:.3} ms/MP, thread CPU {:.3} ms/MP",
        ms / mp,
        cpu.unwrap_or(f64::NAN)
    );
}

/// User + system CPU time of the calling thread (s), from `/proc/thread-self/stat` (Linux;
/// 1/100 s resolution, hence the many runs above), or `None` elsewhere.
fn thread_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

criterion_group!(benches, ridge);
criterion_main!(benches);
