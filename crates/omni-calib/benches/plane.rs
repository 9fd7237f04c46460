//! Light-plane calibration speed: a 60-frame rig (one facet's sweep, α every 0.5°, ~200 stripe
//! points per frame on two boards) from stripe pixels to the fitted transmitter; target ≤ 10 s.
//! And a 12-facet scan (132 frames) for the full physical model (46 parameters).

use criterion::{Criterion, criterion_group, criterion_main};
use omni_calib::plane::synth::{paper_camera, stripe_frame, two_board_rig};
use omni_calib::plane::{FrameStripes, PlacedBoard, PlaneCalibOptions, calibrate_planes};
use omni_geom::rng::SplitMix64;
use omni_model::{Transmitter, TransmitterParams};
use std::hint::black_box;

fn rig_frames(facets: &[u32], alphas: &[f64]) -> (Vec<PlacedBoard>, Vec<FrameStripes>) {
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let boards: Vec<PlacedBoard> = two_board_rig(550.0).iter().map(|(b, p)| PlacedBoard::new(b, *p)).collect();
    let mut rng = SplitMix64::new(3);
    let mut frames = vec![];
    for &k in facets {
        for &a in alphas {
            frames.push(stripe_frame(&camera, &truth, &boards, frames.len() as u64, a, k, 0.1, 2.0, &mut rng));
        }
    }
    (boards, frames)
}

fn bench(c: &mut Criterion) {
    let camera = paper_camera();
    let initial = TransmitterParams::paper();
    let opts = PlaneCalibOptions::default();
    let mut group = c.benchmark_group("calibrate_planes");
    group.sample_size(10);

    let alphas: Vec<f64> = (0..60).map(|i| 0.25 + 0.5 * i as f64).collect();
    let (boards, frames) = rig_frames(&[0], &alphas);
    group.bench_function("60 frames, one facet", |b| {
        b.iter(|| black_box(calibrate_planes(&camera, &boards, &frames, &initial, &opts).unwrap()))
    });

    let alphas: Vec<f64> = (0..=10).map(|i| 3.0 * i as f64).collect();
    let facets: Vec<u32> = (0..12).collect();
    let (boards, frames) = rig_frames(&facets, &alphas);
    group.bench_function("132 frames, 12 facets", |b| {
        b.iter(|| black_box(calibrate_planes(&camera, &boards, &frames, &initial, &opts).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
