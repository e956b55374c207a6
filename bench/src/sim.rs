//! Simulated workers for the coordinator's load harness ([`super::load`]):
//! each speaks the real protocol on a connection of its own (registers,
//! beats, asks for tasks, reads their input, sends their output), but
//! traces nothing: it answers each task after `ray_count / rate` seconds
//! (at once with rate 0) with records of the right kinds, counts and
//! sizes, made from the rays' ids alone.
//!
//! The outputs follow a ray tree measured on balls 4 (512x512, depth 5):
//! round r's rays each spawn `RATIOS[r-1]` rays on average, spread evenly
//! (ray `i` spawns `floor((i+1)f) - floor(i f)`), every ray's colour goes
//! to its eye ray's pixel corner, and three in five rays add colour. So
//! every worker gives every ray the same output (a verification sample
//! agrees with its shard), and a round's rays are the spawned rays of the
//! one before, in key order, as the coordinator expects.

use sray_engine::bf::{Contribution, IntersectStats, RayRec, ResultRec, SPAWN_SLOTS, ShadeStats};
use sray_engine::hit::PrimId;
use sray_engine::shapes::{KindCounts, ShapeKind};
use sray_proto::auth::Token;
use sray_proto::net::{Client, Target};
use sray_proto::v1::{self, task_output::Part};
use sray_proto::wire::{encode, records_per_chunk};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Rays spawned per ray, round by round (balls 4, 512x512, depth 5:
/// 263,169 eye rays, then 797,659, 163,403, 89,871, 55,599 and 24,315).
pub const RATIOS: [f64; 5] = [3.031, 0.2049, 0.5500, 0.6187, 0.4373];

/// Of every five rays, this many add colour.
const COLOURED_OF_5: u64 = 3;

/// Task ids whose output a simulated worker says it holds (as a real
/// worker names what it keeps).
const HELD: usize = 64;

/// How the simulated workers behave.
pub struct SimConfig {
    pub url: String,
    pub token: Option<Token>,
    /// Rays per second each traces (0: answers at once).
    pub rate: f64,
    /// Objects of the scene (results name objects below it).
    pub objects: u64,
    /// Whether a worker that keeps its records sends the colour its
    /// shadings add (false: none is sent, as if colour stayed at the
    /// workers too; the frame stays black; a bound on what the
    /// coordinator would save).
    pub send_colour: bool,
}

/// What the simulated workers measured, together.
#[derive(Default)]
pub struct SimStats {
    pub registered: AtomicU64,
    /// Registrations tried again (the coordinator did not take the
    /// connection at once).
    pub register_retries: AtomicU64,
    pub tasks: AtomicU64,
    pub input_bytes: AtomicU64,
    pub output_bytes: AtomicU64,
    pub errors: AtomicU64,
    /// Heartbeat round trips, milliseconds.
    pub heartbeat_ms: Mutex<Vec<f32>>,
    /// Round trips of task requests that returned a task, milliseconds.
    pub next_task_ms: Mutex<Vec<f32>>,
    pub stop: AtomicBool,
}

impl SimStats {
    /// Forgets the latencies so far (a new measurement starts).
    pub fn reset_latencies(&self) {
        self.heartbeat_ms.lock().unwrap().clear();
        self.next_task_ms.lock().unwrap().clear();
    }
}

/// The `q` quantile of `v` (NaN for none).
pub fn quantile(v: &[f32], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f32::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * q).round() as usize] as f64
}

/// Runs simulated worker `i` until `stats.stop` is set.
pub async fn run(i: usize, cfg: Arc<SimConfig>, stats: Arc<SimStats>) {
    if let Err(e) = worker(i, &cfg, &stats).await {
        eprintln!("simulated worker {i}: {e}");
        stats.errors.fetch_add(1, Ordering::Relaxed);
    }
}

async fn worker(i: usize, cfg: &SimConfig, stats: &Arc<SimStats>) -> Result<(), String> {
    let stopped = || stats.stop.load(Ordering::Relaxed);
    let target = Target {
        url: cfg.url.clone(),
        token: cfg.token.clone(),
        ca: None,
        identity: None,
    };
    // As a real worker does, try again while the coordinator cannot take
    // the connection (a thousand workers connecting at once overflow its
    // accept queue on a loaded machine), spread over time by worker.
    let mut attempt = 0u64;
    let (mut c, reply) = loop {
        let tried = async {
            let mut c = target.connect().await?;
            let reply = c
                .register(v1::RegisterRequest {
                    name: format!("sim-{i}"),
                    threads: 2,
                    memory_bytes: 2 << 30,
                    protocol_version: sray_proto::PROTOCOL_VERSION,
                })
                .await
                .map_err(|s| s.message().to_string())?
                .into_inner();
            Ok::<_, String>((c, reply))
        }
        .await;
        match tried {
            Ok(ok) => break ok,
            Err(e) if attempt >= 30 || stopped() => return Err(e),
            Err(_) => {
                attempt += 1;
                stats.register_retries.fetch_add(1, Ordering::Relaxed);
                let wait = 200 + (i as u64 * 37 + attempt * 101) % 800;
                tokio::time::sleep(Duration::from_millis(wait)).await;
            }
        }
    };
    stats.registered.fetch_add(1, Ordering::Relaxed);
    let session = reply.session;
    let every = Duration::from_millis(reply.heartbeat_ms.max(100) as u64);
    let beat = tokio::spawn(heartbeat(c.clone(), session.clone(), every, stats.clone()));
    let mut held: VecDeque<u64> = VecDeque::new();
    // Whether the last call was made right after a task ended (its round
    // trip is the coordinator's scheduling, not a wait for work).
    let mut after_task = false;
    // The next task, when the last output's reply brought one, and how
    // long that call took (the output's sending and the scheduling: the
    // worker's wait between two tasks).
    let mut given: Option<(v1::NextTaskReply, Duration)> = None;
    while !stopped() {
        let t0 = Instant::now();
        let mut waited = None;
        let reply = match given.take() {
            Some((r, took)) => {
                waited = Some(took);
                r
            }
            None => match c
                .next_task(v1::NextTaskRequest {
                    session: session.clone(),
                    held: held.iter().copied().collect(),
                })
                .await
            {
                Ok(r) => r.into_inner(),
                Err(_) if stopped() => break,
                Err(s) => {
                    stats.errors.fetch_add(1, Ordering::Relaxed);
                    eprintln!("simulated worker {i}: {}", s.message());
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    continue;
                }
            },
        };
        let Some(task) = reply.task else {
            after_task = false;
            continue;
        };
        if after_task {
            stats
                .next_task_ms
                .lock()
                .unwrap()
                .push(waited.unwrap_or_else(|| t0.elapsed()).as_secs_f32() * 1e3);
        }
        after_task = true;
        let input = reply.input_inline.then_some(reply.input);
        match serve(&mut c, &session, task, input, cfg, stats, &mut held).await {
            Ok((next, took)) => given = next.filter(|r| r.task.is_some()).map(|r| (r, took)),
            Err(e) if !stopped() => {
                stats.errors.fetch_add(1, Ordering::Relaxed);
                eprintln!("simulated worker {i}: {e}");
            }
            Err(_) => {}
        }
    }
    beat.abort();
    Ok(())
}

async fn heartbeat(mut c: Client, session: String, every: Duration, stats: Arc<SimStats>) {
    let mut tick = tokio::time::interval(every);
    loop {
        tick.tick().await;
        let t0 = Instant::now();
        let r = c
            .heartbeat(v1::HeartbeatRequest {
                session: session.clone(),
                running_tasks: vec![],
            })
            .await;
        if r.is_ok() {
            stats
                .heartbeat_ms
                .lock()
                .unwrap()
                .push(t0.elapsed().as_secs_f32() * 1e3);
        }
    }
}

/// Runs one task: reads its input (unless `inline` brought it), waits as
/// long as tracing would take, sends its output and asks for the next
/// task with it, as a real worker does; returns the reply's next task.
async fn serve(
    c: &mut Client,
    session: &str,
    task: v1::Task,
    inline: Option<Vec<v1::RecordChunk>>,
    cfg: &SimConfig,
    stats: &SimStats,
    held: &mut VecDeque<u64>,
) -> Result<(Option<v1::NextTaskReply>, Duration), String> {
    let started = Instant::now();
    let tref = v1::TaskRef {
        task_id: task.task_id,
        attempt: task.attempt,
        session: session.to_string(),
        held: Vec::new(),
    };
    let shade = task.stage == v1::Stage::Shade as i32;
    if let Some(chunks) = inline {
        let bytes: usize = chunks.iter().map(prost::Message::encoded_len).sum();
        stats.input_bytes.fetch_add(bytes as u64, Ordering::Relaxed);
    } else if shade || !task.eye_rays {
        let mut r = tref.clone();
        r.held = held.iter().copied().collect();
        let mut s = c
            .task_input(r)
            .await
            .map_err(|s| format!("task input: {}", s.message()))?
            .into_inner();
        while let Some(chunk) = s
            .message()
            .await
            .map_err(|s| format!("task input: {}", s.message()))?
        {
            stats.input_bytes.fetch_add(
                prost::Message::encoded_len(&chunk) as u64,
                Ordering::Relaxed,
            );
        }
    }
    if cfg.rate > 0.0 {
        let left = Duration::from_secs_f64(task.ray_count as f64 / cfg.rate)
            .saturating_sub(started.elapsed());
        tokio::time::sleep(left).await;
    }
    let objects = cfg.objects;
    let send_colour = cfg.send_colour || !task.keep_output;
    let t2 = task.clone();
    let tr = tref.clone();
    let msgs = tokio::task::spawn_blocking(move || output(&t2, tr, objects, send_colour, started))
        .await
        .map_err(|e| e.to_string())??;
    let bytes: u64 = msgs
        .iter()
        .map(|m| prost::Message::encoded_len(m) as u64)
        .sum();
    stats.output_bytes.fetch_add(bytes, Ordering::Relaxed);
    held.push_back(task.task_id);
    if held.len() > HELD {
        held.pop_front();
    }
    let mut msgs = msgs;
    msgs.push(v1::TaskOutput {
        part: Some(Part::Next(v1::NextTaskRequest {
            session: session.to_string(),
            held: held.iter().copied().collect(),
        })),
    });
    let sent = Instant::now();
    let reply = c
        .complete_task(tokio_stream::iter(msgs))
        .await
        .map_err(|s| format!("output: {}", s.message()))?
        .into_inner();
    stats.tasks.fetch_add(1, Ordering::Relaxed);
    Ok((reply.next, sent.elapsed()))
}

/// The rays of round `round`'s ray `i` spawns: how many, and its first
/// child's index in the next round.
fn spawned(round: u32, i: u64) -> (u64, u64) {
    let Some(&f) = RATIOS.get(round as usize - 1) else {
        return (0, 0);
    };
    let a = (i as f64 * f).floor() as u64;
    let b = ((i + 1) as f64 * f).floor() as u64;
    (b - a, a)
}

/// The ray of round `r` that spawned round `r + 1`'s ray `i`.
fn parent(r: u32, i: u64) -> u64 {
    let f = RATIOS[r as usize - 1];
    let mut j = (((i + 1) as f64 / f).ceil() as u64).saturating_sub(1);
    while j > 0 && spawned(r, j).1 > i {
        j -= 1;
    }
    loop {
        let (k, at) = spawned(r, j);
        if at + k > i {
            return j;
        }
        j += 1;
    }
}

/// The pixel corner of round `round`'s ray `i`: its eye ray's.
fn corner(round: u32, i: u64, per_slot: u64, slots: u64) -> u32 {
    let mut i = i;
    for r in (1..round).rev() {
        i = parent(r, i);
    }
    ((i / per_slot.max(1)).min(slots.saturating_sub(1))) as u32
}

/// The colour ray `id` of round `round` adds to `corner`, in fixed
/// point: a shade that varies smoothly across the image plus a little of
/// the ray's own, weaker at each bounce, in single precision as a shader
/// makes it. Packed per slot, it takes about the bytes real colour does
/// (a real worker's of balls 4, 512x512: 2.55 a ray after zstd, 3.2
/// before; these about 3 after zstd). Colour that barely changed from
/// corner to corner (before 2026-12-06) took a third of a byte.
fn colour(round: u32, corner: u32, id: u64) -> [i64; 3] {
    let smooth = (corner % 1031) as f32 / 1031.0;
    let weight = 0.25f32.powi(round as i32 - 1);
    sray_engine::render::to_fixed(std::array::from_fn(|k| {
        weight * (0.2 + 0.003 * smooth / (k + 1) as f32 + NOISE * unit(id, 11 + k as u64) as f32)
    }))
}

/// How much of a ray's colour is its own.
const NOISE: f32 = 1e-6;

/// A number in [0, 1) that looks random, from `id` and `salt`.
fn unit(id: u64, salt: u64) -> f64 {
    let mut z = id
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .wrapping_add(salt.wrapping_mul(0xbf58_476d_1ce4_e5b9));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    // At single precision: a real tracer's neighbouring records share
    // their high bits, which the wire's deltas and zstd find; these
    // compress to about the bytes per ray measured on real renders.
    ((z >> 40) as f32 / (1u32 << 24) as f32) as f64
}

fn coloured(round: u32, i: u64) -> bool {
    (i.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ round as u64) % 5 < COLOURED_OF_5
}

/// A task's output messages: the header, records in chunks, the summary.
fn output(
    task: &v1::Task,
    tref: v1::TaskRef,
    objects: u64,
    // Send the colour shadings add (false: keep it, see `SimConfig`).
    send_colour: bool,
    started: Instant,
) -> Result<Vec<v1::TaskOutput>, String> {
    let params = task.params.as_ref().ok_or("a task without settings")?;
    let (opts, _) = sray_worker::params::from_proto(params, 1)?;
    let slots = opts.frame_slots();
    let per_slot = (opts.eye_rays() / slots.max(1)).max(1);
    let mut msgs = vec![v1::TaskOutput {
        part: Some(Part::Header(tref)),
    }];
    let push = |msgs: &mut Vec<v1::TaskOutput>, kind: v1::RecordKind, data: Vec<u8>| {
        msgs.push(v1::TaskOutput {
            part: Some(Part::Records(v1::RecordChunk {
                kind: kind as i32,
                data,
                held: None,
                raw: false,
            })),
        })
    };
    let (first, n) = (task.first_ray, task.ray_count);
    let mut summary = v1::TaskSummary {
        stats_json: stats_json(task),
        ..Default::default()
    };
    // Every kind, as a real worker names them.
    let mut tests = KindCounts::default();
    tests.add_n(ShapeKind::Sphere, 10 * n);
    summary.tests_by_kind = tests.named().map(|(k, n)| (k.to_string(), n)).collect();
    if task.stage == v1::Stage::Intersect as i32 {
        let hit = |id: u64| coloured(task.round + 7, id);
        let hits = (first..first + n).filter(|&id| hit(id)).count() as u64;
        if task.keep_output {
            summary.kept_records = n;
            summary.kept_hits = hits;
        } else {
            let per = records_per_chunk::<ResultRec>() as u64;
            let mut at = first;
            while at < first + n {
                let end = (at + per).min(first + n);
                let recs: Vec<ResultRec> = (at..end)
                    .map(|id| ResultRec {
                        ray: id,
                        prim: if hit(id) {
                            PrimId::object((id % objects.max(1)) as u32)
                        } else {
                            PrimId::NONE
                        },
                        t: 1.0 + 10.0 * unit(id, 1),
                    })
                    .collect();
                push(&mut msgs, v1::RecordKind::Results, encode(&recs));
                at = end;
            }
        }
        if task.round == 1 {
            summary.eye_hit_rays = hits;
        }
    } else {
        // Colour: one contribution per coloured ray, to its corner; a
        // worker that keeps its records sums a corner's in a row and
        // sends them packed per slot, as a real worker does.
        let mut contribs: Vec<Contribution> = Vec::new();
        let per = records_per_chunk::<Contribution>();
        for id in first..first + n {
            if !send_colour || !coloured(task.round, id) {
                continue;
            }
            let c = corner(task.round, id, per_slot, slots);
            let rgb = colour(task.round, c, id);
            match contribs.last_mut() {
                Some(l) if task.keep_output && l.corner == c => {
                    for (x, v) in l.rgb.iter_mut().zip(rgb) {
                        *x += v;
                    }
                }
                _ => contribs.push(Contribution {
                    corner: c,
                    run: 0,
                    rgb,
                }),
            }
            if contribs.len() == per {
                push_colour(&mut msgs, task.keep_output, &contribs);
                contribs.clear();
            }
        }
        if !contribs.is_empty() {
            push_colour(&mut msgs, task.keep_output, &contribs);
        }
        // Spawned rays, in key order.
        let per = records_per_chunk::<RayRec>();
        let mut rays: Vec<RayRec> = Vec::new();
        let (mut count, mut first_key, mut last_key) = (0u64, 0u64, 0u64);
        for id in first..first + n {
            let (k, _) = spawned(task.round, id);
            for s in 0..k.min(SPAWN_SLOTS) {
                let key = id * SPAWN_SLOTS + s;
                if count == 0 {
                    first_key = key;
                }
                last_key = key;
                count += 1;
                if task.keep_output {
                    continue;
                }
                rays.push(RayRec {
                    // Computed values: their low bits are noise, as a
                    // real tracer's are (the records compress as little).
                    o: [unit(key, 2), unit(key, 3), unit(key, 4)],
                    d: [unit(key, 5) - 0.5, unit(key, 6) - 0.5, 1.0],
                    t_max: 1e30,
                    key,
                    payload: [
                        unit(key, 7) as f32,
                        unit(key, 8) as f32,
                        unit(key, 9) as f32,
                    ],
                    corner: corner(task.round, id, per_slot, slots),
                    depth: (task.round + 1).min(255) as u8,
                    kind: 0,
                    _pad: [0; 6],
                });
                if rays.len() == per {
                    push(&mut msgs, v1::RecordKind::Rays, encode(&rays));
                    rays.clear();
                }
            }
        }
        if !rays.is_empty() {
            push(&mut msgs, v1::RecordKind::Rays, encode(&rays));
        }
        if task.keep_output {
            summary.kept_records = count;
            summary.kept_first_key = first_key;
            summary.kept_last_key = last_key;
        }
        summary.shadow_rays = count;
    }
    summary.seconds = started.elapsed().as_secs_f64();
    msgs.push(v1::TaskOutput {
        part: Some(Part::Summary(summary)),
    });
    Ok(msgs)
}

/// A chunk of contributions: packed per slot where the records stay at
/// the worker (`keep`), else as records.
/// A task's statistics as a real worker sends them, with counts of the
/// right size (the coordinator reads every task's): an intersection in
/// three passes, or a shading's join.
fn stats_json(task: &v1::Task) -> String {
    let n = task.ray_count;
    let scan = 12 << 20;
    let r = if task.stage == v1::Stage::Intersect as i32 {
        let mut tests = KindCounts::default();
        tests.add_n(ShapeKind::Sphere, 10 * n);
        serde_json::to_string(&IntersectStats {
            rays: n,
            passes: 3,
            remaining_rays_per_pass: vec![n, n / 3, n / 20],
            store_numbers: vec![4.25, 3.5, 2.75],
            registrations: 6 * n,
            registered_voxels: n,
            registered_rays: n + n / 3 + n / 20,
            intersection_tests: tests,
            tests_skipped_mailbox: n / 2,
            tests_skipped_last_voxel: n / 4,
            aggregate_walks: 0,
            db_scans: 3,
            db_bytes_read: 3 * scan,
            db_blocks_skipped: 7,
            model_reads: 0,
        })
    } else {
        serde_json::to_string(&ShadeStats {
            hits: n / 2,
            sets: 1,
            db_scans: 1,
            db_bytes_read: scan,
            db_blocks_skipped: 3,
            model_reads: 0,
        })
    };
    r.unwrap_or_default()
}

fn push_colour(msgs: &mut Vec<v1::TaskOutput>, keep: bool, recs: &[Contribution]) {
    let (kind, data) = if keep {
        (
            v1::RecordKind::Colour,
            encode(&sray_worker::exec::pack_colour(recs)),
        )
    } else {
        (v1::RecordKind::Contributions, encode(recs))
    };
    msgs.push(v1::TaskOutput {
        part: Some(Part::Records(v1::RecordChunk {
            kind: kind as i32,
            data,
            held: None,
            raw: false,
        })),
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rays_corner_is_its_eye_rays() {
        // Round 2's rays are round 1's children in order: the parent of
        // each child is the ray whose range holds it.
        let mut child = 0;
        for parent in 0..1000u64 {
            let (k, at) = spawned(1, parent);
            assert_eq!(at, child);
            for _ in 0..k {
                assert_eq!(corner(2, child, 1, 1 << 20), parent as u32);
                child += 1;
            }
        }
    }
}
