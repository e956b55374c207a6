//! The coordinator's work per entry of packed colour, the part of its CPU
//! that grows with the rays when the records stay at the workers
//! (`cargo bench -p sray-coordinator --bench colour`; not run by CI):
//! unpacking a chunk as it arrives (zstd), reading it through for its
//! bounds, and adding it to the frame once the shard is verified.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sray_coordinator::task::TaskOutput;
use sray_engine::bf::Contribution;
use sray_engine::render::{Frame, to_fixed};
use sray_engine::spill::{MemoryShare, Records};
use sray_proto::colour::Reader;
use sray_proto::wire::{decode_bytes, encode};
use std::hint::black_box;

/// The colour a shading of 65,536 eye rays of a 1024x1024 frame adds:
/// about one ray in four adds colour (balls 4 gives 0.25 entries a ray),
/// shades that vary a little from corner to corner, as the wire carries
/// them (packed per slot, in chunks of 32,768 entries, zstd).
fn shading_output() -> (Vec<Vec<u8>>, usize) {
    let mut v = Vec::new();
    let mut z = 0x2545_f491_4f6c_dd1du64;
    for id in 0..65_536u32 {
        z ^= z << 13;
        z ^= z >> 7;
        z ^= z << 17;
        if z.is_multiple_of(4) {
            let shade = 0.3 + (id % 1024) as f32 / 4096.0 + (z >> 40) as f32 * 1e-9;
            v.push(Contribution {
                corner: 300_000 + id,
                run: 0,
                rgb: to_fixed([shade, shade * 0.8, shade * 0.5]),
            });
        }
    }
    let chunks = v
        .chunks(32_768)
        .map(|c| encode(&sray_worker::exec::pack_colour(c)))
        .collect();
    (chunks, v.len())
}

fn colour(c: &mut Criterion) {
    let (chunks, entries) = shading_output();
    let raw: Vec<u8> = chunks
        .iter()
        .flat_map(|w| decode_bytes(w, false, 1 << 26).expect("decodes"))
        .collect();
    let mut g = c.benchmark_group("colour");
    g.throughput(Throughput::Elements(entries as u64));
    g.bench_function("unpack (zstd)", |b| {
        b.iter(|| {
            for w in &chunks {
                black_box(decode_bytes(black_box(w), false, 1 << 26).expect("decodes"));
            }
        })
    });
    g.bench_function("read for bounds", |b| {
        b.iter(|| {
            let mut r = Reader::new(1025 * 1025);
            r.feed(black_box(&raw), &mut |_| ()).expect("reads");
            r.finish().expect("whole");
            black_box(r.slots)
        })
    });
    let out = TaskOutput {
        colour: Some(Records::memory(raw.clone(), MemoryShare::new(0).lease())),
        ..Default::default()
    };
    let mut frame = Frame::new(1024, 1024);
    g.bench_function("add to the frame", |b| {
        b.iter(|| {
            out.for_each_contribution(|x| frame.add_contribution(x))
                .expect("adds")
        })
    });
    g.finish();
}

criterion_group!(benches, colour);
criterion_main!(benches);
