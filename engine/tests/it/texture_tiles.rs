//! Textures stored as tiles of their mip chains (database version 9) and
//! read through a cache: the image does not depend on the cache's size,
//! on the tracer or on the compression; a minified texture reads its
//! coarse levels, not its finest; a corrupt tile fails the render.

use crate::common::{self, write_converted};
use crate::gltf_textures::{Look, quad};
use sray_engine::bf::StoreNumber;
use sray_engine::render::RenderOptions;
use sray_engine::scene::ImageData;
use sray_engine::sdb::{Compression, Database};
use sray_engine::source::SceneSource;
use std::path::{Path, PathBuf};

/// A `w` x `h` PNG of texels that differ from their neighbours (a hash of
/// their place), so that every tile and level is its own.
pub(crate) fn noise_png(w: u32, h: u32) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(w, h, |i, j| {
        let v = (i.wrapping_mul(2_654_435_761) ^ j.wrapping_mul(40_503)).rotate_left(i % 13);
        image::Rgba([v as u8, (v >> 8) as u8, (v >> 16) as u8, 255])
    });
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

fn convert(dir: &Path, gltf: &Path, c: Compression) -> PathBuf {
    let db = dir.join(format!("scene-{}.sdb", c.name()));
    write_converted(
        &SceneSource::parse(gltf.to_str().unwrap()).unwrap(),
        &db,
        c,
        true,
    );
    db
}

fn options(size: u32) -> RenderOptions {
    RenderOptions {
        width: size,
        height: size,
        threads: 2,
        ..Default::default()
    }
}

/// Tiles a render read.
fn tiles_read(s: &sray_engine::render::RenderStats) -> u64 {
    s.textures
        .expect("a render of tiled textures reports them")
        .texture_tiles_read
}

#[test]
fn a_texture_larger_than_its_cache_renders_as_one_held_whole() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = quad(dir.path(), Look::Png(noise_png(1024, 1024)));
    let zstd = Database::open(&convert(dir.path(), &gltf, Compression::Zstd(3))).unwrap();
    let raw = Database::open(&convert(dir.path(), &gltf, Compression::None)).unwrap();
    let ImageData::Tiled(t) = &zstd.scene().textures[0].data else {
        panic!("a version 9 database stores its images as tiles");
    };
    // 16 x 16 tiles, then 8 x 8, 4 x 4, 2 x 2, and one a level for the
    // seven levels from 64 x 64 texels to 1 x 1.
    assert_eq!(t.tiles.len(), 256 + 64 + 16 + 4 + 7);
    // 512 x 512 pixels over 1024 texels (the quad spans two thirds of the
    // view): level 1, 64 tiles.
    let o = options(512);
    let df = common::df_render(&zstd, &o);
    let bf = common::bf_render(&zstd, &o, StoreNumber::Adaptive, 48 << 20);
    let bf_raw = common::bf_render(&raw, &o, StoreNumber::Adaptive, 48 << 20);
    assert!(
        df.0 == bf.0,
        "breadth-first with a small cache differs from depth-first"
    );
    assert!(bf.0 == bf_raw.0, "the compression changed the image");
    assert_eq!(df.1.rays, bf.1.rays);
    // Every level-1 tile is read at least once; shading sorted by tile
    // reads each about once a set, not once a hit.
    let (d, b) = (tiles_read(&df.1), tiles_read(&bf.1));
    assert!(d >= 64 && b >= 64, "tiles read: df {d}, bf {b}");
    let hits = bf.1.rays.eye_hit_rays;
    assert!(b * 50 < hits, "{b} tiles read for {hits} hits");
    // The same scene with the image held whole (as a version 8 database
    // keeps it) gives the same image.
    let held = sray_engine::texture::Texture::decode(
        &std::fs::read(dir.path().join("pattern.png")).unwrap(),
        "pattern",
        sray_engine::texture::Encoding::Srgb,
    )
    .unwrap();
    // Through the smallest cache (16 tiles, a 1 MiB budget's), every
    // texel of every level twice over: the cache forgets and reads again,
    // and every sample is the held one's.
    let s = sray_engine::texture::Sampler::default();
    let (tiled, _) = sray_engine::render::ShadeScene::open(&zstd, 5, 1e-6, 1 << 20).unwrap();
    for _ in 0..2 {
        for level in 0..held.levels() {
            let n = 1024 >> level;
            for j in (0..n).step_by(7) {
                for i in (0..n).step_by(5) {
                    let uv = [(i as f32 + 0.25) / n as f32, (j as f32 + 0.75) / n as f32];
                    assert_eq!(
                        tiled.textures[0].sample_level(&s, uv, level),
                        held.sample_level(&s, uv, level),
                        "level {level} at {uv:?}"
                    );
                }
            }
        }
    }
    let read = tiled.tile_reads().unwrap().texture_tiles_read;
    assert!(read >= 2 * 347, "{read} tiles read");
    assert!(tiled.texture_error().is_none());
}

#[test]
fn a_minified_texture_reads_its_coarse_levels() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = quad(dir.path(), Look::Png(noise_png(1024, 1024)));
    let db = Database::open(&convert(dir.path(), &gltf, Compression::Zstd(3))).unwrap();
    // 48 pixels over 1024 texels: about 32 texels a pixel, level 4 or 5
    // (one tile each); the finest level alone has 256.
    let (img, st) = common::df_render(&db, &options(48));
    let n = tiles_read(&st);
    assert!((1..=4).contains(&n), "{n} tiles read");
    // Not one flat colour: the quad shows the coarse levels' texels
    // (means of noise, so close to one another).
    let distinct: std::collections::BTreeSet<&[u8]> = img.chunks(3).collect();
    assert!(distinct.len() > 10, "{} colours", distinct.len());
}

#[test]
fn a_corrupt_tile_fails_the_render_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = quad(dir.path(), Look::Png(noise_png(256, 256)));
    let path = convert(dir.path(), &gltf, Compression::None);
    let db = Database::open(&path).unwrap();
    let ImageData::Tiled(t) = &db.scene().textures[0].data else {
        panic!("tiled");
    };
    // The finest level's tiles: every pixel of a 256-pixel image reads one.
    let mut bytes = std::fs::read(&path).unwrap();
    for r in &t.tiles[..16] {
        bytes[r.offset as usize + 100] ^= 0x55;
    }
    let bad = dir.path().join("bad.sdb");
    std::fs::write(&bad, &bytes).unwrap();
    let db = Database::open(&bad).unwrap();
    let o = options(256);
    for e in [
        sray_engine::df::render(&db, &o, &sray_engine::progress::NoProgress).err(),
        sray_engine::bf::render(
            &db,
            &o,
            &sray_engine::bf::BfOptions {
                memory: 8 << 20,
                store: StoreNumber::Adaptive,
                spill_dir: None,
                shading: Default::default(),
                models: Default::default(),
            },
            &sray_engine::progress::NoProgress,
        )
        .err(),
    ] {
        let e = e
            .expect("a render that read a corrupt tile must fail")
            .to_string();
        assert!(e.contains("tile") && e.contains("checksum"), "{e}");
    }
}
