//! Renders one scene depth-first several times and prints the trace time,
//! a hash of the frame and the counts: a quick harness for the speed work
//! on the depth-first tracer that builds without the rest of the
//! workspace.
//!
//! `cargo run --release -p sray-engine --example dfbench -- SCENE.nff
//! [--size N] [--precision single|double] [--threads N] [--reps N]
//! [--depth N] [--density VOXELS_PER_OBJECT]`

use sray_engine::df;
use sray_engine::progress::NoProgress;
use sray_engine::render::{Precision, RenderOptions};
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::source::SceneSource;
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = PathBuf::from(&args[0]);
    let mut opts = RenderOptions {
        threads: 1,
        ..RenderOptions::default()
    };
    let mut reps = 1;
    let mut i = 1;
    while i < args.len() {
        let v = &args[i + 1];
        match args[i].as_str() {
            "--size" => {
                opts.width = v.parse().expect("size");
                opts.height = opts.width;
            }
            "--precision" => {
                opts.precision = match v.as_str() {
                    "single" => Precision::Single,
                    _ => Precision::Double,
                }
            }
            "--threads" => opts.threads = v.parse().expect("threads"),
            "--reps" => reps = v.parse().expect("reps"),
            "--depth" => opts.max_depth = v.parse().expect("depth"),
            "--density" => opts.grid_density = v.parse().expect("density"),
            a => panic!("unknown argument {a}"),
        }
        i += 2;
    }
    // The database of the scene, made once.
    let dir = PathBuf::from("/tmp/dfbench-sdb");
    std::fs::create_dir_all(&dir).expect("dir");
    let sdb = dir
        .join(scene.file_stem().expect("name"))
        .with_extension("sdb");
    if !sdb.exists() {
        let tmp = sdb.with_extension("tmp");
        let mut w = DbWriter::create(&tmp, Compression::None).expect("create");
        SceneSource::nff(&scene)
            .stream_into(&mut w, &NoProgress)
            .expect("convert");
        w.finish().expect("finish");
        std::fs::rename(&tmp, &sdb).expect("rename");
    }
    let db = Database::open(&sdb).expect("open");
    for _ in 0..reps {
        let out = df::render(&db, &opts, &NoProgress).expect("render");
        // FNV-1a over the frame's fixed-point sums.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for s in &out.frame.slots {
            for v in s {
                for b in v.to_le_bytes() {
                    h = (h ^ b as u64).wrapping_mul(0x100_0000_01b3);
                }
            }
        }
        let r = &out.stats.rays;
        println!(
            "{} {:?} trace {:.4} s hash {h:016x} rays {} {} {} {} {} tests {} res {:?}",
            scene.file_stem().unwrap().to_string_lossy(),
            opts.precision,
            out.stats.trace_seconds,
            r.eye_rays,
            r.eye_hit_rays,
            r.reflect_rays,
            r.refract_rays,
            r.shadow_rays,
            out.stats.intersection_tests,
            out.stats.grid_res,
        );
    }
}
