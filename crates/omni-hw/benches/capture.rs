//! Capture throughput: 1024 × 1024 Mono8 camera frames through the frame writer (encode, write
//! a temporary file, rename) into PGM, PGM synced file by file (`scan --sync-frames`) and PNG,
//! with the writer's worker threads as `omni-trigger scan --camera` uses them. Capture alone:
//! the target (≥ 200 frames/s on 2 cores, capture to stripe points) is measured with omni-ridge
//! by `examples/capture_pipeline.rs`.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use omni_hw::frame_writer::{FrameFormat, FrameWriter, RawFrame};
use omni_hw::pairing::CapturedFrame;
use std::path::PathBuf;
use std::time::{Duration, Instant};

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
    for (name, format, sync) in [
        ("pgm", FrameFormat::Pgm, false),
        ("pgm, each file synced", FrameFormat::Pgm, true),
        ("png", FrameFormat::Png, false),
    ] {
        group.bench_function(name, |b| {
            // Each batch into a new directory, as a capture writes new names (rewriting the same
            // names makes each rename free a file, which a capture never does); the directory is
            // made and removed outside the timing.
            b.iter_custom(|batches| {
                let mut total = Duration::ZERO;
                for _ in 0..batches {
                    let dir = tempfile::tempdir().unwrap();
                    let mut writer = FrameWriter::new(dir.path(), format, threads, 16).unwrap();
                    writer.sync_each_frame(sync);
                    let t0 = Instant::now();
                    for k in 0..BATCH {
                        let name = writer.file_name(&format!("{k:06}"));
                        writer.submit(CapturedFrame::new(PathBuf::new(), name, 0), image.clone()).unwrap();
                    }
                    let done = writer.flush(Duration::from_secs(60)).unwrap();
                    total += t0.elapsed();
                    assert_eq!(done.len() as u64, BATCH);
                }
                total
            })
        });
    }
    group.finish();
}

criterion_group!(benches, capture);
criterion_main!(benches);
