//! Receiver calibration speed: 20 simulated 1024 × 1024 board images (9 × 6 corners, the paper
//! sensor, the simulator's calibration board set, default calibration lighting and noise) → PNG
//! decode, corner detection inside the mirror annulus (parallel), Mei fit with outlier rejection.
//! Target: ≤ 10 s on the 2-core CI machine.
//!
//! Also writes the detected corners to `$CARGO_TARGET_DIR/receiver-bench/corners.json` (default
//! `target/`; + the board, the true camera and the annulus) so that `scripts/bench_calib.py` can
//! run OpenCV's omnidir calibration on exactly the same corners, and prints the RMS and ray
//! errors (over the whole mirror image, after the best common rotation) of our Mei and
//! hyperbolic fits once.

use criterion::{Criterion, criterion_group, criterion_main};
use omni_calib::receiver::corners_file::{CornersFile, ImageCorners};
use omni_calib::receiver::{ModelKind, Observation, Options, calibrate};
use omni_formats::{BoardFile, CameraFile, CameraSpec, write_doc};
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams};
use omni_simulator::{RenderOptions, Sensor, calibration_board_poses, render_board_image};
use omni_vision::corners::{DetectorOptions, detect_board, load_gray};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::{Path, PathBuf};

fn render_set(dir: &Path, board: &BoardFile) -> Vec<PathBuf> {
    let sensor = Sensor::paper();
    let poses = calibration_board_poses(&sensor, board, 20, 11).unwrap();
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
fn run(
    paths: &[PathBuf],
    board: &BoardFile,
    annulus: [f64; 4],
    model: ModelKind,
) -> (omni_calib::receiver::Calibration, CornersFile) {
    let detector = DetectorOptions { annulus: Some(annulus), ..Default::default() };
    let found: Vec<ImageCorners> = paths
        .par_iter()
        .map(|p| {
            let img = load_gray(p).unwrap();
            let name = p.display().to_string();
            ImageCorners::from_detection(name, detect_board(&img, board.inner_cols, board.inner_rows, &detector))
        })
        .collect();
    let mut file = CornersFile::new(1024, 1024, board.inner_cols, board.inner_rows);
    file.images = found;
    let obs: Vec<Observation> = file.observations(board.square_mm);
    let cal = calibrate(1024, 1024, &obs, &Options { model, annulus: Some(annulus), ..Default::default() }).unwrap();
    (cal, file)
}

/// Median and max angle (degrees) between the rays of two models over the annulus
/// [cx, cy, inner, outer] px, after the best common rotation (Kabsch): board images cannot
/// observe the camera frame's rotation (the board poses absorb it).
fn ray_errors_deg(a: &dyn CameraModel, b: &dyn CameraModel, annulus: [f64; 4]) -> (f64, f64) {
    let c = omni_geom::Vector2::new(annulus[0], annulus[1]);
    let (r0, r1) = (annulus[2] + 0.5, annulus[3] - 0.5);
    let mut pairs = Vec::new();
    for k in 0..40 {
        let r = r0 + (r1 - r0) * k as f64 / 39.0;
        for m in 0..72 {
            let phi = m as f64 * std::f64::consts::TAU / 72.0;
            let px = c + omni_geom::Vector2::new(r * phi.cos(), r * phi.sin());
            if let (Some(ra), Some(rb)) = (a.pixel_to_ray(&px), b.pixel_to_ray(&px)) {
                pairs.push((rb.dir.into_inner(), ra.dir.into_inner()));
            }
        }
    }
    let h = pairs.iter().fold(omni_geom::Matrix3::zeros(), |h, (x, y)| h + x * y.transpose());
    let svd = h.svd(true, true);
    let (u, v) = (svd.u.unwrap(), svd.v_t.unwrap().transpose());
    let d = omni_geom::Matrix3::from_diagonal(&omni_geom::Vector3::new(1.0, 1.0, (v * u.transpose()).determinant()));
    let rot = v * d * u.transpose();
    let mut e: Vec<f64> = pairs.iter().map(|(x, y)| (rot * x).angle(y).to_degrees()).collect();
    e.sort_by(|x, y| x.total_cmp(y));
    (e[e.len() / 2], e[e.len() - 1])
}

fn bench(c: &mut Criterion) {
    // Beside the build: $CARGO_TARGET_DIR when set (`make bench` passes it absolute; a relative one
    // is taken from the workspace root), else target/.
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    let out = root.join(std::env::var_os("CARGO_TARGET_DIR").unwrap_or_else(|| "target".into())).join("receiver-bench");
    std::fs::create_dir_all(&out).unwrap();
    let board = BoardFile::new(9, 6, 30.0);
    let paths = render_set(&out, &board);
    let truth = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    let circle = truth.mirror_circle();
    let annulus = [circle.centre.x, circle.centre.y, circle.inner_radius, circle.outer_radius];

    let mut corners = None;
    for model in [ModelKind::Mei, ModelKind::Hyperbolic] {
        let (cal, found) = run(&paths, &board, annulus, model);
        let (med, max) = ray_errors_deg(&truth, cal.spec.build().unwrap().as_ref(), annulus);
        eprintln!(
            "omniscan {model:?}: {} of 20 images used, RMS {:.4} px, rays vs truth median {med:.4}°, max {max:.4}°",
            cal.images.iter().filter(|i| i.used).count(),
            cal.rms_px
        );
        corners = Some(found);
    }
    write_doc(&out.join("corners.json"), &corners.unwrap()).unwrap();
    std::fs::write(out.join("annulus.txt"), annulus.map(|v| v.to_string()).join(",")).unwrap();
    write_doc(&out.join("board.json"), &board).unwrap();
    write_doc(&out.join("truth_camera.json"), &CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper())))
        .unwrap();

    let mut group = c.benchmark_group("receiver");
    group.sample_size(10);
    group.bench_function("20 images 1024x1024: load, detect, fit mei", |b| {
        b.iter(|| black_box(run(&paths, &board, annulus, ModelKind::Mei)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
