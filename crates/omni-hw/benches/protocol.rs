//! Host-side throughput: reading and parsing trigger lines, and pairing events with frames.
//! A controller fires at most a few hundred triggers per second, so both must handle far more
//! than 10 000 per second on one core (target: ≥ 100 000 lines/s and ≥ 100 000 pairs/s).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use omni_hw::framing::{LineReader, encode_line};
use omni_hw::message::{DeviceMessage, TriggerEvent};
use omni_hw::pairing::{CapturedFrame, PairOptions, Pairer};
use omni_hw::schedule::Schedule;
use std::path::PathBuf;

const N: u64 = 10_000;

fn schedule() -> Schedule {
    Schedule {
        counts_per_rev: 36000,
        facets_total: 12,
        facets: (0..12).collect(),
        counts: (0..60).map(|i| i * 50).collect(),
        lasers: vec![0, 1],
        ambient: false,
    }
}

/// 50 Hz worth of counts: 20 µs per count at 1000-count gaps, here 50-count gaps → 1 ms apart.
const US_PER_COUNT: u64 = 20;

fn event(s: &Schedule, seq: u64) -> TriggerEvent {
    let e = s.expected(seq);
    TriggerEvent {
        seq,
        encoder: e.encoder,
        facet: e.facet,
        revolution: e.revolution,
        t_us: s.position(seq) * US_PER_COUNT,
        lasers: e.lasers,
    }
}

fn parse_lines(c: &mut Criterion) {
    let s = schedule();
    let stream: Vec<u8> =
        (0..N).flat_map(|q| encode_line(&DeviceMessage::Trigger(event(&s, q)).to_body()).into_bytes()).collect();
    let mut group = c.benchmark_group("protocol");
    group.throughput(Throughput::Elements(N));
    group.bench_function("read_and_parse_trigger_lines", |b| {
        b.iter(|| {
            let mut r = LineReader::new();
            let mut bodies = Vec::with_capacity(N as usize);
            for chunk in stream.chunks(512) {
                r.push(chunk, &mut bodies);
            }
            bodies.iter().filter(|b| DeviceMessage::parse(b).is_ok()).count()
        })
    });
    group.bench_function("pair_events_with_frames", |b| {
        let rpm = 60e6 / (US_PER_COUNT as f64 * 36000.0);
        b.iter(|| {
            let mut p = Pairer::new(s.clone(), rpm, PairOptions::default());
            let mut paired = 0;
            for q in 0..N {
                let ev = event(&s, q);
                let t = ev.t_us as i64;
                p.on_trigger(ev, t + 100);
                p.on_frame(CapturedFrame::new(PathBuf::new(), format!("f{q}.png"), t), t + 200);
                paired += p.tick(t + 300).len();
            }
            paired
        })
    });
    group.finish();
}

criterion_group!(benches, parse_lines);
criterion_main!(benches);
