//! Where grid tracers usually fail: rays along voxel faces, edges and
//! corners, boxes of zero thickness, objects on the grid's boundary or far
//! larger than a voxel, empty and one-object scenes, a camera inside the
//! grid or inside an object, coincident surfaces. Every scene is rendered by
//! both tracers with several grids, store numbers, budgets and thread
//! counts, and by a one-voxel grid (every ray against every object, nothing
//! for a grid walk to get wrong); all must give the same image and counts.

use sray_engine::bf::StoreNumber;
use sray_engine::nff::read_nff_from;
use sray_engine::progress::NoProgress;
use sray_engine::render::{GridRes, RenderOptions};
use sray_engine::sdb::{Compression, Database, DbWriter};
use std::fmt::Write;
use std::path::Path;

use crate::common;

use common::{Render, bf_render, df_render};

struct Scene {
    db: Database,
    _dir: tempfile::TempDir,
}

fn scene(nff: &str) -> Scene {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.sdb");
    let mut w = DbWriter::create(&path, Compression::None).unwrap();
    read_nff_from(nff.as_bytes(), Path::new("edge.nff"), &mut w, &NoProgress).unwrap();
    w.finish().unwrap();
    Scene {
        db: Database::open(&path).unwrap(),
        _dir: dir,
    }
}

fn opts(side: u32, grid: GridRes, threads: usize, grids: bool) -> RenderOptions {
    RenderOptions {
        width: side,
        height: side,
        threads,
        grid_res: grid,
        multiple_grids: grids,
        ..Default::default()
    }
}

/// Renders `nff` every way; all must agree with the one-voxel depth-first
/// render, which is returned. (Past 64 objects the depth-first tracer
/// gives a voxel a hierarchy of its objects; the one-voxel breadth-first
/// render among the others stays brute force, every ray against every
/// object.)
fn all_agree(what: &str, nff: &str, side: u32, fixed: [u32; 3]) -> Render {
    let s = scene(nff);
    let one = GridRes::Fixed([1, 1, 1]);
    let fixed = GridRes::Fixed(fixed);
    let reference = df_render(&s.db, &opts(side, one, 1, false));
    let plenty = 1 << 30;
    let renders = [
        (
            "df, auto grid",
            df_render(&s.db, &opts(side, GridRes::Auto, 2, true)),
        ),
        (
            "df, fixed grid",
            df_render(&s.db, &opts(side, fixed, 2, true)),
        ),
        (
            "df, fixed grid, one",
            df_render(&s.db, &opts(side, fixed, 1, false)),
        ),
        (
            "bf, auto grid",
            bf_render(
                &s.db,
                &opts(side, GridRes::Auto, 2, true),
                StoreNumber::Adaptive,
                plenty,
            ),
        ),
        (
            "bf, fixed grid, store 1, 600 KiB",
            bf_render(
                &s.db,
                &opts(side, fixed, 2, true),
                StoreNumber::Fixed(1),
                600 << 10,
            ),
        ),
        (
            "bf, fixed grid, one grid, store 2",
            bf_render(
                &s.db,
                &opts(side, fixed, 1, false),
                StoreNumber::Fixed(2),
                plenty,
            ),
        ),
        (
            "bf, one voxel",
            bf_render(
                &s.db,
                &opts(side, one, 2, false),
                StoreNumber::Adaptive,
                plenty,
            ),
        ),
    ];
    for (how, r) in &renders {
        let differing = r.0.iter().zip(&reference.0).filter(|(a, b)| a != b).count();
        assert!(
            differing == 0,
            "{what} ({how}): {differing} channel values differ from the one-voxel render"
        );
        assert_eq!(r.1.rays, reference.1.rays, "{what} ({how}): counts differ");
    }
    reference
}

/// Distinct colours in an RGB image.
fn colours(img: &[u8]) -> usize {
    let mut c: Vec<&[u8]> = img.chunks(3).collect();
    c.sort();
    c.dedup();
    c.len()
}

fn rgb(img: &[u8], side: u32, x: u32, y: u32) -> [u8; 3] {
    let i = 3 * (y * side + x) as usize;
    [img[i], img[i + 1], img[i + 2]]
}

/// Unit cubes, each of six axis-aligned squares, filling every voxel
/// (i, j, k) of [0, 8]^3 with (i + j + k) % 3 == 0: every face lies in a
/// voxel face of the 8x8x8 grid and has a box of zero thickness.
fn cube_lattice() -> String {
    let mut s = String::from("b 0.1 0.1 0.2\nf 0.8 0.6 0.3 0.7 0.3 20 0 1\n");
    for i in 0..8 {
        for j in 0..8 {
            for k in 0..8 {
                if (i + j + k) % 3 != 0 {
                    continue;
                }
                let (a, b) = ([i, j, k], [i + 1, j + 1, k + 1]);
                for axis in 0..3 {
                    for side in [a[axis], b[axis]] {
                        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                        s.push_str("p 4\n");
                        for (du, dv) in [(a[u], a[v]), (b[u], a[v]), (b[u], b[v]), (a[u], b[v])] {
                            let mut p = [0; 3];
                            p[axis] = side;
                            p[u] = du;
                            p[v] = dv;
                            let _ = writeln!(s, "{} {} {}", p[0], p[1], p[2]);
                        }
                    }
                }
            }
        }
    }
    s
}

fn view(from: [f64; 3], at: [f64; 3], up: [f64; 3], angle: f64) -> String {
    format!(
        "v\nfrom {} {} {}\nat {} {} {}\nup {} {} {}\nangle {angle}\nhither 0.001\nresolution 32 32\n",
        from[0], from[1], from[2], at[0], at[1], at[2], up[0], up[1], up[2]
    )
}

#[test]
fn rays_along_voxel_faces_edges_and_corners() {
    // Lights on voxel planes, so shadow rays run along them too.
    let lights = "l 4 4 30\nl 30 8 0\n";
    let views = [
        // The centre eye ray runs down the voxel edge x = 4, y = 4, and
        // each row and column of corners lies in a voxel face.
        (
            "down an edge",
            [4.0, 4.0, 20.0],
            [4.0, 4.0, 4.0],
            [0.0, 1.0, 0.0],
            60.0,
        ),
        (
            "along +x",
            [-12.0, 4.0, 4.0],
            [4.0, 4.0, 4.0],
            [0.0, 0.0, 1.0],
            60.0,
        ),
        (
            "along -y",
            [3.0, 20.0, 5.0],
            [3.0, 4.0, 5.0],
            [0.0, 0.0, 1.0],
            60.0,
        ),
        // Through the voxel corners (k, k, k).
        (
            "diagonal",
            [20.0, 20.0, 20.0],
            [4.0, 4.0, 4.0],
            [0.0, 0.0, 1.0],
            40.0,
        ),
        // From a voxel corner inside the grid, along a voxel edge.
        (
            "inside, from a corner",
            [4.0, 4.0, 4.0],
            [8.0, 4.0, 4.0],
            [0.0, 0.0, 1.0],
            90.0,
        ),
        // From inside a cube (voxel 0,0,0), looking out through its face.
        (
            "inside a cube",
            [0.5, 0.5, 0.5],
            [8.0, 0.5, 0.5],
            [0.0, 0.0, 1.0],
            90.0,
        ),
    ];
    let lattice = cube_lattice();
    for (what, from, at, up, angle) in views {
        let nff = format!("{}{lights}{lattice}", view(from, at, up, angle));
        let r = all_agree(what, &nff, 32, [8, 8, 8]);
        assert!(colours(&r.0) > 10, "{what}: a flat image proves nothing");
        assert!(
            r.1.rays.shadow_rays > 0 && r.1.rays.eye_hit_rays > 0,
            "{what}"
        );
    }
}

#[test]
fn boxes_of_zero_thickness_and_rays_in_their_plane() {
    // A checkerboard of squares in z = 0, a sphere above it, and eye rays
    // that lie exactly in the board's plane (the middle row): those miss
    // the squares (a ray in a polygon's plane does not hit it).
    let mut s = String::from("b 0 0 0\nl 0 0 10\n");
    s.push_str(&view(
        [-10.0, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        45.0,
    ));
    s.push_str("f 1 1 1 1 0 0 0 1\n");
    for i in -3..3 {
        for j in -3..3 {
            if (i + j) % 2 == 0 {
                let _ = writeln!(
                    s,
                    "p 4\n{i} {j} 0\n{} {j} 0\n{} {} 0\n{i} {} 0",
                    i + 1,
                    i + 1,
                    j + 1,
                    j + 1
                );
            }
        }
    }
    s.push_str("f 1 0 0 1 0 0 0 1\ns 0 0 1.5 1.5\n");
    let r = all_agree("checkerboard", &s, 32, [6, 6, 1]);
    assert!(colours(&r.0) > 3, "{} colours", colours(&r.0));
    // From above, the same board: every square's box is flat in z.
    let above = s.replace(
        "from -10 0 0\nat 0 0 0\nup 0 0 1",
        "from 0.5 0.5 10\nat 0.5 0.5 0\nup 0 1 0",
    );
    assert_ne!(above, s);
    all_agree("checkerboard from above", &above, 32, [6, 6, 1]);
}

#[test]
fn objects_on_the_grid_boundary_and_far_larger_than_a_voxel() {
    // A ground polygon 10^4 times wider than the small spheres on it, a
    // sphere touching each face of the small objects' box, and a cone
    // lying along the box's edge.
    let mut s = String::from("b 0.2 0.3 0.5\nl 5 -5 20\nl -10 3 6\n");
    s.push_str(&view(
        [12.0, -14.0, 9.0],
        [0.0, 0.0, 0.5],
        [0.0, 0.0, 1.0],
        40.0,
    ));
    s.push_str(
        "f 0.4 0.8 0.4 1 0 0 0 1\np 4\n-5000 -5000 0\n5000 -5000 0\n5000 5000 0\n-5000 5000 0\n",
    );
    s.push_str("f 0.9 0.9 0.9 0.5 0.5 30 0 1\n");
    for i in 0..10 {
        for j in 0..10 {
            let _ = writeln!(s, "s {} {} 0.25 0.25", i as f64 - 4.5, j as f64 - 4.5);
        }
    }
    s.push_str("s 0 0 3 1\nc\n-5 -5 0.25 0.1\n5 -5 0.25 0.1\n");
    let r = all_agree("ground and spheres", &s, 32, [10, 10, 4]);
    assert!(colours(&r.0) > 10);
    // The multiple-grid rule put the ground in a grid of its own.
    let sc = scene(&s);
    let o = opts(32, GridRes::Auto, 2, true);
    let got = bf_render(&sc.db, &o, StoreNumber::Adaptive, 1 << 30);
    assert!(
        got.1.grids.len() > 1,
        "expected the ground apart: {:?}",
        got.1.grids
    );
}

#[test]
fn a_scene_of_one_object_and_a_scene_of_none() {
    let v = view([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0);
    let none = format!("b 0.25 0.5 0.75\n{v}l 1 1 5\n");
    let r = all_agree("no objects", &none, 16, [4, 4, 4]);
    assert_eq!(colours(&r.0), 1);
    assert_eq!(rgb(&r.0, 16, 3, 3), [64, 128, 191]);
    assert_eq!(r.1.rays.eye_rays, 17 * 17);
    assert_eq!(r.1.rays.eye_hit_rays, 0);
    let one = format!("{none}f 1 0 0 1 0 0 0 1\ns 0 0 0 1\n");
    let r = all_agree("one sphere", &one, 16, [4, 4, 4]);
    assert!(r.1.rays.eye_hit_rays > 0 && r.1.rays.shadow_rays > 0);
    // A one-object scene whose box is flat: a single square.
    let flat = format!("{none}p 4\n-1 -1 0\n1 -1 0\n1 1 0\n-1 1 0\n");
    let r = all_agree("one square", &flat, 16, [4, 4, 4]);
    assert!(r.1.rays.eye_hit_rays > 0);
}

#[test]
fn the_camera_inside_an_object() {
    // Inside a glass sphere that holds three small spheres, and inside an
    // opaque one: the eye rays start inside a surface.
    for (what, t) in [
        ("inside glass", "0.9 1.5"),
        ("inside an opaque sphere", "0 1"),
    ] {
        let nff = format!(
            "b 0 0 0\n{}l 0 0 0.5\nl 4 4 4\nf 0.7 0.7 1 0.2 0.3 10 {t}\ns 0 0 0 3\n\
             f 1 0 0 1 0 0 0 1\ns 0 0 -1.5 0.4\ns 1 0 -1.5 0.3\ns -1 0.5 -2 0.3\n",
            view([0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 90.0)
        );
        let r = all_agree(what, &nff, 24, [5, 5, 5]);
        assert_eq!(
            r.1.rays.eye_hit_rays, r.1.rays.eye_rays,
            "{what}: every eye ray hits"
        );
        assert!(colours(&r.0) > 5, "{what}");
    }
}

#[test]
fn coincident_surfaces_go_to_the_first_object() {
    // Two identical squares and two identical spheres, each pair with two
    // materials. Exact ties go to the smaller object id in every tracer,
    // grid and thread count; swapping the order swaps the winner.
    let v = view([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 60.0);
    let square = "p 4\n-2 -2 0\n0 -2 0\n0 2 0\n-2 2 0\n";
    let sphere = "s 1 0 0 0.9\n";
    let red = "f 1 0 0 1 0 0 0 1\n";
    let green = "f 0 1 0 1 0 0 0 1\n";
    let text =
        |a: &str, b: &str| format!("b 0 0 0\n{v}l 0 0 10\n{a}{square}{sphere}{b}{square}{sphere}");
    let first = all_agree("red first", &text(red, green), 16, [3, 3, 3]);
    let second = all_agree("green first", &text(green, red), 16, [3, 3, 3]);
    for (x, y) in [(4, 8), (12, 8)] {
        let (a, b) = (rgb(&first.0, 16, x, y), rgb(&second.0, 16, x, y));
        assert!(
            a[0] > 100 && a[1] == 0,
            "red should win at ({x}, {y}): {a:?}"
        );
        assert!(
            b[1] > 100 && b[0] == 0,
            "green should win at ({x}, {y}): {b:?}"
        );
    }
}
