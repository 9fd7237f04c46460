//! Capture throughput: 1024 × 1024 Mono8 camera frames through the frame writer (encode, write
//! a temporary file, rename) into PGM and PNG, with the writer's worker threads as
//! `omni-trigger scan --camera` uses them. Target: ≥ 200 frames/s on 2 cores.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use omni_hw::frame_writer::{FrameFormat, FrameWriter, RawFrame};
use omni_hw::pairing::CapturedFrame;
use std::path::PathBuf;
use std::time::Duration;

const SIDE: u32 = 1024;
const BATCH: u64 = 40;

/// A frame like a stripe image: dark with a bright band, so PNG compresses it realistically.
fn frame() -> RawFrame {
    let data = (0..SIDE * SIDE)
        .map(|i| {
            let (x, y) = (i % SIDE, i / SIDE);
            if (x as i64 - y as i64 / 2 - 300).abs() < 3 { 220 } else { (x * 7 + y * 13) as u8 % 16 }
        })
        .collect();
    RawFrame { width: SIDE, height: SIDE, bit_depth: 8, data }
}

fn capture(c: &mut Criterion) {
    let image = frame();
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get().min(4));
    let mut group = c.benchmark_group(format!("capture 1024x1024 Mono8, {threads} writer threads"));
    group.throughput(Throughput::Elements(BATCH));
    group.sample_size(10);
    for format in [FrameFormat::Pgm, FrameFormat::Png] {
        let dir = tempfile::tempdir().unwrap();
        group.bench_function(format.extension(), |b| {
            let mut writer = FrameWriter::new(dir.path(), format, threads, 16).unwrap();
            b.iter(|| {
                for k in 0..BATCH {
                    let name = writer.file_name(&format!("{k:06}"));
                    writer.submit(CapturedFrame::new(PathBuf::new(), name, 0), image.clone()).unwrap();
                }
                let done = writer.flush(Duration::from_secs(60)).unwrap();
                assert_eq!(done.len() as u64, BATCH);
            })
        });
    }
    group.finish();
}

criterion_group!(benches, capture);
criterion_main!(benches);
