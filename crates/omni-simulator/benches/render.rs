//! One 1024 × 1024 laser frame of the paper bench plane (both lasers) on one core and on every
//! core: the realistic sensor (speckle through the lens pupil; target ≤ 0.5 s on one core,
//! issue 16) and the idealised one.

use criterion::{Criterion, criterion_group, criterion_main};
use omni_simulator::{BenchObject, RenderOptions, Scene, Sensor, paper_bench, render_laser_frame};

fn render(c: &mut Criterion) {
    let sensor = Sensor::paper();
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let opts = RenderOptions::default();
    let ideal = RenderOptions::ideal();
    let alpha = 20f64.to_radians();
    let one_core = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let mut group = c.benchmark_group("render_laser_frame_1024");
    group.sample_size(10);
    group.bench_function("paper_plane_one_core", |b| {
        b.iter(|| one_core.install(|| render_laser_frame(&sensor, &scene, alpha, 0, &[0, 1], &opts)))
    });
    group.bench_function("paper_plane_ideal_one_core", |b| {
        b.iter(|| one_core.install(|| render_laser_frame(&sensor, &scene, alpha, 0, &[0, 1], &ideal)))
    });
    group.bench_function("paper_plane_all_cores", |b| {
        b.iter(|| render_laser_frame(&sensor, &scene, alpha, 0, &[0, 1], &opts))
    });
    group.finish();
}

criterion_group!(benches, render);
criterion_main!(benches);
