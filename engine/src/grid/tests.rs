use super::*;
use crate::math::Vec3 as V3;

fn unit_box() -> Aabb {
    Aabb {
        min: [0.0, 0.0, 0.0],
        max: [4.0, 4.0, 4.0],
    }
}

fn walk(g: &GridSpec, o: [f64; 3], d: [f64; 3]) -> Vec<[u32; 3]> {
    let mut v = Vec::new();
    let d = V3::from_array(d);
    let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    if let Some(mut w) = Dda::start(g, V3::from_array(o), d, inv, 0.0, f64::INFINITY) {
        loop {
            v.push(w.voxel());
            assert_eq!(w.index, g.index(w.voxel()));
            if !w.advance() {
                break;
            }
        }
    }
    v
}

#[test]
fn axis_parallel_walks() {
    let g = GridSpec::new(&unit_box(), [4, 4, 4]);
    assert_eq!(
        walk(&g, [-1.0, 0.5, 0.5], [1.0, 0.0, 0.0]),
        (0..4).map(|x| [x, 0, 0]).collect::<Vec<_>>()
    );
    assert_eq!(
        walk(&g, [0.5, 5.0, 2.5], [0.0, -1.0, 0.0]),
        (0..4).rev().map(|y| [0, y, 2]).collect::<Vec<_>>()
    );
    assert_eq!(walk(&g, [3.5, 3.5, -9.0], [0.0, 0.0, 2.0]).len(), 4);
    // Missing the box.
    assert!(walk(&g, [-1.0, 5.0, 0.5], [1.0, 0.0, 0.0]).is_empty());
}

#[test]
fn ray_in_a_voxel_face_and_along_an_edge() {
    let g = GridSpec::new(&unit_box(), [4, 4, 4]);
    // In the plane y = 2 (a voxel face): walks one row of voxels.
    let cells = walk(&g, [-1.0, 2.0, 0.5], [1.0, 0.0, 0.0]);
    assert_eq!(cells.len(), 4);
    // Along the edge y = 2, z = 2.
    let cells = walk(&g, [-1.0, 2.0, 2.0], [1.0, 0.0, 0.0]);
    assert_eq!(cells.len(), 4);
    // Through a voxel corner diagonally: visits each voxel on the diagonal
    // (and zero-length neighbours), never skips one.
    let cells = walk(&g, [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]);
    for k in 0..4 {
        assert!(cells.contains(&[k, k, k]), "{cells:?}");
    }
}

#[test]
fn diagonal_walk_is_connected_and_ordered() {
    let g = GridSpec::new(&unit_box(), [7, 5, 3]);
    let cells = walk(&g, [-0.3, 0.1, 0.2], [1.0, 0.77, 0.31]);
    for w in cells.windows(2) {
        let d: u32 = (0..3).map(|i| w[0][i].abs_diff(w[1][i])).sum();
        assert_eq!(d, 1, "{w:?}");
    }
}

#[test]
fn cell_ranges_are_conservative() {
    let g = GridSpec::new(&unit_box(), [4, 4, 4]);
    // A box ending exactly on the face x = 1 is listed in voxels 0 and 1.
    let b = Aabb {
        min: [0.5, 0.5, 0.5],
        max: [1.0, 0.7, 0.7],
    };
    let (lo, hi) = g.cell_range(&b).unwrap();
    assert_eq!((lo[0], hi[0]), (0, 1));
    // A flat box (zero thickness) still gets a voxel.
    let flat = Aabb {
        min: [0.0, 0.0, 2.5],
        max: [4.0, 4.0, 2.5],
    };
    let (lo, hi) = g.cell_range(&flat).unwrap();
    assert_eq!((lo, hi), ([0, 0, 2], [3, 3, 2]));
    // Outside the grid.
    let far = Aabb {
        min: [9.0, 9.0, 9.0],
        max: [10.0, 10.0, 10.0],
    };
    assert!(g.cell_range(&far).is_none());
}

#[test]
fn flat_scenes_get_flat_grids() {
    let flat = Aabb {
        min: [0.0, 0.0, 0.0],
        max: [10.0, 10.0, 0.0],
    };
    let r = choose_resolution(&flat, 10_000, 1.0, 1 << 24);
    assert_eq!(r[2], 1);
    assert!(r[0] > 50 && r[0] == r[1], "{r:?}");
    let long = Aabb {
        min: [0.0, 0.0, 0.0],
        max: [100.0, 1.0, 1.0],
    };
    let r = choose_resolution(&long, 1000, 1.0, 1 << 24);
    assert!(r[0] > 20 * r[1], "{r:?}");
}

#[test]
fn a_ground_polygon_is_set_apart() {
    let mut s = crate::scene::SizeSummary::default();
    for i in 0..1000 {
        let x = (i % 10) as f32 * 0.1;
        s.add(&Aabb {
            min: [x, 0.0, 0.0],
            max: [x + 0.05, 0.05, 0.05],
        });
    }
    s.add(&Aabb {
        min: [-50.0, -50.0, 0.0],
        max: [50.0, 50.0, 0.0],
    });
    let plan = plan_groups(&s, true);
    assert_eq!(plan.partition.groups(), 2);
    assert_eq!(plan.counts, vec![1000, 1]);
    assert!(plan.bounds[0].diagonal() < 2.0);
    assert_eq!(plan_groups(&s, false).partition, Partition::one());
}

#[test]
fn uniform_scenes_keep_one_grid() {
    let mut s = crate::scene::SizeSummary::default();
    for i in 0..1000 {
        let x = (i % 10) as f32;
        let y = (i / 10 % 10) as f32;
        s.add(&Aabb {
            min: [x, y, 0.0],
            max: [x + 1.0, y + 1.0, 1.0],
        });
    }
    assert_eq!(plan_groups(&s, true).partition, Partition::one());
}

#[test]
fn a_saved_walk_resumes_where_it_stopped() {
    let g = GridSpec::new(&unit_box(), [7, 5, 3]);
    let o = V3::new(-0.3, 0.1, 0.2);
    let d = V3::new(1.0, 0.77, 0.31);
    let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    let mut a = Dda::start(&g, o, d, inv, 0.0, f64::INFINITY).unwrap();
    let mut b = a;
    for _ in 0..3 {
        assert!(a.advance());
    }
    let mut r = Dda::resume(&g, d, inv, &a.save());
    for _ in 0..3 {
        b.advance();
    }
    assert_eq!(r.voxel(), b.voxel());
    loop {
        let (x, y) = (r.advance_axis(), b.advance_axis());
        assert_eq!(x, y);
        assert_eq!(r.voxel(), b.voxel());
        assert_eq!(r.index, b.index);
        if x.is_none() {
            break;
        }
    }
}
