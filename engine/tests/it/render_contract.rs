//! The rendering contract (docs/rendering-contract.md) on scenes simple
//! enough to trace by hand, and the invariances every count must have.

use sray_engine::df;
use sray_engine::nff::read_nff_from;
use sray_engine::progress::NoProgress;
use sray_engine::render::{RenderOptions, RenderStats};
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::source::SceneSource;
use std::path::Path;

/// Renders NFF text with the depth-first tracer; returns RGB bytes and
/// statistics.
fn render_text(nff: &str, opts: &RenderOptions) -> (Vec<u8>, RenderStats) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.sdb");
    let mut w = DbWriter::create(&path, Compression::None).unwrap();
    read_nff_from(nff.as_bytes(), Path::new("scene.nff"), &mut w, &NoProgress).unwrap();
    w.finish().unwrap();
    let db = Database::open(&path).unwrap();
    let out = df::render(&db, opts, &NoProgress).unwrap();
    (out.frame.to_rgb8(), out.stats)
}

fn opts(w: u32, h: u32, depth: u8) -> RenderOptions {
    RenderOptions {
        width: w,
        height: h,
        max_depth: depth,
        threads: 1,
        ..Default::default()
    }
}

fn byte(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// A view from +z toward the origin with a tiny angle: all four corner rays
/// of a 1x1 image are, to within 1e-7, the ray down the -z axis.
fn axis_view(from_z: f64) -> String {
    format!("v\nfrom 0 0 {from_z}\nat 0 0 0\nup 0 1 0\nangle 0.00001\nhither 1\nresolution 1 1\n")
}

#[test]
fn one_diffuse_sphere_by_hand() {
    // Eye at z = 5 looks down -z at a unit sphere; the hit is (0, 0, 1),
    // normal +z. Light at (0, 3, 5), colour (1, 1, 1):
    // L = (0, 3, 4) / 5, N.L = 0.8, colour = Kd N.L C = 0.5 * 0.8 * C.
    let scene = format!(
        "b 0.1 0.2 0.3\n{}l 0 3 5 1 1 1\nf 1 0.5 0.25 0.5 0 0 0 1\ns 0 0 0 1\n",
        axis_view(5.0)
    );
    let (rgb, st) = render_text(&scene, &opts(1, 1, 5));
    let k = 0.5 * 0.8;
    assert_eq!(rgb, vec![byte(k), byte(k * 0.5), byte(k * 0.25)]);
    assert_eq!((st.rays.eye_rays, st.rays.eye_hit_rays), (4, 4));
    assert_eq!(
        (
            st.rays.shadow_rays,
            st.rays.reflect_rays,
            st.rays.refract_rays
        ),
        (4, 0, 0)
    );
}

#[test]
fn highlight_and_light_colour_by_hand() {
    // As above, Ks = 0.5 with Shine 2 and a yellow light at (0, 0, 9): the
    // light is straight above the hit, N.L = 1, R.L = 1, so the colour is
    // I (Kd C + Ks) with no reflection ray counted because depth 1 is the
    // maximum.
    let scene = format!(
        "{}l 0 0 9 1 1 0\nf 0.2 0.42 0.6 0.5 0.5 2 0 1\ns 0 0 0 1\n",
        axis_view(5.0)
    );
    let (rgb, st) = render_text(&scene, &opts(1, 1, 1));
    assert_eq!(rgb, vec![byte(0.5 * 0.2 + 0.5), byte(0.5 * 0.42 + 0.5), 0]);
    assert_eq!(st.rays.reflect_rays, 0);
    // Lights given without a colour are white / sqrt(number of lights).
    let two = format!(
        "{}l 0 0 9\nl 0 0 9\nf 1 1 1 1 0 0 0 1\ns 0 0 0 1\n",
        axis_view(5.0)
    );
    let (rgb, _) = render_text(&two, &opts(1, 1, 1));
    let each = 1.0 / 2f64.sqrt();
    assert_eq!(rgb, vec![byte(2.0 * each); 3]);
}

#[test]
fn surface_facing_away_from_the_light_gets_no_shadow_ray() {
    // The light is behind the sphere: N.L < 0 at the visible point.
    let scene = format!(
        "{}l 0 0 -9 1 1 1\nf 1 1 1 1 0 0 0 1\ns 0 0 0 1\n",
        axis_view(5.0)
    );
    let (rgb, st) = render_text(&scene, &opts(1, 1, 5));
    assert_eq!(rgb, vec![0, 0, 0]);
    assert_eq!(st.rays.shadow_rays, 0);
}

#[test]
fn mirror_sphere_by_hand() {
    // The eye ray hits the mirror sphere at (0, 0, 1) and reflects straight
    // back along +z, past the eye, to a diffuse red-ish wall at z = 10.
    // There the light at (3, 0, 8) gives N.L = 2 / sqrt(13) (N turned
    // toward the incoming ray: -z). The sphere itself has Kd = 0 and a
    // highlight (R.L)^100000 that underflows to 0.
    let scene = format!(
        "{}l 3 0 8 1 1 1\nf 0 0 0 0 1 100000 0 1\ns 0 0 0 1\nf 1 0.5 0.25 1 0 0 0 1\np 4\n-50 -50 10\n50 -50 10\n50 50 10\n-50 50 10\n",
        axis_view(5.0)
    );
    let (rgb, st) = render_text(&scene, &opts(1, 1, 5));
    let k = 2.0 / 13f64.sqrt();
    assert_eq!(rgb, vec![byte(k), byte(k * 0.5), byte(k * 0.25)]);
    assert_eq!(st.rays.reflect_rays, 4);
    assert_eq!(st.rays.shadow_rays, 8); // at the sphere and at the wall
    // With depth 1 there is no reflection: only the (zero) highlight.
    let (rgb, st) = render_text(&scene, &opts(1, 1, 1));
    assert_eq!(rgb, vec![0, 0, 0]);
    assert_eq!(st.rays.reflect_rays, 0);
}

/// A glass sphere of radius 2 around the eye: eye rays leave the glass.
fn inside_glass(eye_y: f64, ks: f64) -> String {
    format!(
        "b 0.2 0.4 0.6\nv\nfrom 0 {eye_y} 0\nat 1 {eye_y} 0\nup 0 0 1\nangle 0.00001\nhither 1\nresolution 1 1\nf 1 1 1 0 {ks} 0 1 1.5\ns 0 0 0 2\n"
    )
}

#[test]
fn glass_refraction_leaves_to_the_background() {
    // From (0, 0.5, 0) along +x the ray meets the sphere at incidence
    // asin(0.25): no total internal reflection, the refracted ray (weight
    // T = 1) escapes to the background.
    let (rgb, st) = render_text(&inside_glass(0.5, 0.0), &opts(1, 1, 5));
    assert_eq!(rgb, vec![byte(0.2), byte(0.4), byte(0.6)]);
    assert_eq!((st.rays.refract_rays, st.rays.reflect_rays), (4, 0));
}

#[test]
fn total_internal_reflection_by_hand() {
    // From (0, 1.8, 0) along +x the ray meets the sphere at sin(i) = 0.9,
    // beyond the critical angle for ior 1.5 (sin = 2/3): no refraction ray,
    // a reflection ray instead (even with Ks = 0). Every bounce in a sphere
    // has the same incidence, so the ray is trapped until the maximum
    // depth and nothing reaches the background.
    let (rgb, st) = render_text(&inside_glass(1.8, 0.0), &opts(1, 1, 5));
    assert_eq!(rgb, vec![0, 0, 0]);
    assert_eq!((st.rays.refract_rays, st.rays.reflect_rays), (0, 4 * 4));

    // The reflection carries Ks + T. Put a light at the centre and give the
    // glass some diffuse colour. Every hit's normal, turned toward the ray,
    // points at the centre, so N.L = 1 everywhere; the highlight (R.L < 1
    // raised to 100000) is 0. With maximum depth 2: the eye ray's hit adds
    // Kd = 0.2, and the trapped reflection (weight Ks + T = 1.25) adds
    // 0.2 * 1.25; with weight Ks alone it would add 0.2 * 0.25, with T
    // alone 0.2.
    let scene = "v\nfrom 0 1.8 0\nat 1 1.8 0\nup 0 0 1\nangle 0.00001\nhither 1\nresolution 1 1\n\
                 l 0 0 0 1 1 1\nf 1 1 1 0.2 0.25 100000 1 1.5\ns 0 0 0 2\n";
    let (rgb, st) = render_text(scene, &opts(1, 1, 2));
    assert_eq!(rgb, vec![byte(0.2 + 0.2 * 1.25); 3]);
    assert_eq!((st.rays.reflect_rays, st.rays.refract_rays), (4, 0));
    assert_eq!(st.rays.shadow_rays, 8);
}

#[test]
fn eye_rays_through_pixel_corners() {
    let empty = "b 0.5 0.5 0.5\nv\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 512 512\n";
    let (rgb, st) = render_text(
        empty,
        &RenderOptions {
            threads: 2,
            ..Default::default()
        },
    );
    assert_eq!(st.rays.eye_rays, 263_169);
    assert_eq!(st.rays.eye_hit_rays, 0);
    assert_eq!(rgb.len(), 512 * 512 * 3);
    assert!(rgb.iter().all(|&c| c == 128));
    let (_, st) = render_text(empty, &opts(7, 3, 5));
    assert_eq!(st.rays.eye_rays, 8 * 4);
}

fn render_db(db: &Database, threads: usize) -> (Vec<u8>, RenderStats) {
    let o = RenderOptions {
        width: 96,
        height: 96,
        threads,
        ..Default::default()
    };
    let out = df::render(db, &o, &NoProgress).unwrap();
    (out.frame.to_rgb8(), out.stats)
}

#[test]
fn image_and_every_count_are_independent_of_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("balls", 3), ("gears", 2), ("tree", 8), ("mount", 4)] {
        let path = dir.path().join("x.sdb");
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        SceneSource::Spd {
            scene: name.parse().unwrap(),
            size,
        }
        .stream_into(&mut w, &NoProgress)
        .unwrap();
        w.finish().unwrap();
        let db = Database::open(&path).unwrap();
        let (a, sa) = render_db(&db, 1);
        for threads in [2, 3, 8] {
            let (b, sb) = render_db(&db, threads);
            assert!(a == b, "{name}: image differs with {threads} threads");
            assert_eq!(sa.rays, sb.rays, "{name}: {threads} threads");
            assert_eq!(
                sa.intersection_tests_by_kind, sb.intersection_tests_by_kind,
                "{name}: {threads} threads"
            );
        }
    }
}
