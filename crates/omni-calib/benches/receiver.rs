//! Receiver calibration speed: 20 simulated 1024 × 1024 board images (9 × 6 corners, the paper
//! sensor, default calibration lighting and noise) → PNG decode, corner detection (parallel),
//! Mei fit with outlier rejection. Target: ≤ 10 s on the 2-core CI machine.
//!
//! Also writes the detected corners to `target/receiver-bench/corners.json` (+ the board and the
//! true camera) so that `scripts/bench_calib.py` can run OpenCV's omnidir calibration on exactly
//! the same corners, and prints the RMS and ray errors of our fit once.

use criterion::{Criterion, criterion_group, criterion_main};
use omni_calib::receiver::corners_file::{CornersFile, ImageCorners};
use omni_calib::receiver::{Observation, Options, calibrate};
use omni_formats::{BoardFile, CameraFile, CameraSpec, write_doc};
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams};
use omni_simulator::{RenderOptions, Sensor, random_board_poses, render_board_image};
use omni_vision::corners::{DetectorOptions, detect_board, load_gray};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::{Path, PathBuf};

fn render_set(dir: &Path, board: &BoardFile) -> Vec<PathBuf> {
    let sensor = Sensor::paper();
    let poses = random_board_poses(&sensor, board, 20, 11).unwrap();
    poses
        .par_iter()
        .enumerate()
        .map(|(k, pose)| {
            let opts = RenderOptions { seed: 100 + k as u64, ..RenderOptions::calibration() };
            let (frame, _) = render_board_image(&sensor, pose, board, &opts);
            let path = dir.join(format!("board{k:02}.png"));
            frame.to_png(&path).unwrap();
            path
        })
        .collect()
}

/// Load, detect and calibrate: what `omni-calib-receiver` does for these images.
fn run(paths: &[PathBuf], board: &BoardFile) -> (omni_calib::receiver::Calibration, CornersFile) {
    let found: Vec<ImageCorners> = paths
        .par_iter()
        .map(|p| {
            let img = load_gray(p).unwrap();
            let name = p.display().to_string();
            ImageCorners::from_detection(
                name,
                detect_board(&img, board.inner_cols, board.inner_rows, &DetectorOptions::default()),
            )
        })
        .collect();
    let mut file = CornersFile::new(1024, 1024, board.inner_cols, board.inner_rows);
    file.images = found;
    let obs: Vec<Observation> = file.observations(board.square_mm);
    let cal = calibrate(1024, 1024, &obs, &Options::default()).unwrap();
    (cal, file)
}

fn ray_errors_deg(a: &dyn CameraModel, b: &dyn CameraModel) -> (f64, f64) {
    let c = a.mirror_circle().centre;
    let mut e = Vec::new();
    for k in 0..40 {
        let r = 110.0 + 370.0 * k as f64 / 39.0;
        for m in 0..72 {
            let phi = m as f64 * std::f64::consts::TAU / 72.0;
            let px = c + omni_geom::Vector2::new(r * phi.cos(), r * phi.sin());
            if let (Some(ra), Some(rb)) = (a.pixel_to_ray(&px), b.pixel_to_ray(&px)) {
                e.push(ra.dir.angle(&rb.dir).to_degrees());
            }
        }
    }
    e.sort_by(|x, y| x.total_cmp(y));
    (e[e.len() / 2], e[e.len() - 1])
}

fn bench(c: &mut Criterion) {
    let out = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../target/receiver-bench"));
    std::fs::create_dir_all(&out).unwrap();
    let board = BoardFile::new(9, 6, 30.0);
    let paths = render_set(&out, &board);

    let (cal, corners) = run(&paths, &board);
    let truth = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    let (med, max) = ray_errors_deg(&truth, cal.spec.build().unwrap().as_ref());
    eprintln!(
        "omniscan mei: {} of 20 images used, RMS {:.4} px, rays vs truth median {med:.4}°, max {max:.4}° (unaligned)",
        cal.images.iter().filter(|i| i.used).count(),
        cal.rms_px
    );
    write_doc(&out.join("corners.json"), &corners).unwrap();
    write_doc(&out.join("board.json"), &board).unwrap();
    write_doc(&out.join("truth_camera.json"), &CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper())))
        .unwrap();

    let mut group = c.benchmark_group("receiver");
    group.sample_size(10);
    group.bench_function("20 images 1024x1024: load, detect, fit mei", |b| b.iter(|| black_box(run(&paths, &board))));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
