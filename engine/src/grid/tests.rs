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
    let plan = plan_groups(&s, None, true);
    assert_eq!(plan.partition.groups(), 2);
    assert_eq!(plan.counts, vec![1000, 1]);
    assert!(plan.bounds[0].diagonal() < 2.0);
    assert_eq!(plan_groups(&s, None, false).partition, Partition::one());
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
    assert_eq!(plan_groups(&s, None, true).partition, Partition::one());
}

#[test]
fn a_walk_started_at_a_voxel_is_the_walk_that_got_there() {
    let g = GridSpec::new(&unit_box(), [7, 5, 3]);
    let mut rng = Lcg(7);
    for k in 0..200 {
        let (o, d) = random_ray(&mut rng);
        let d = flattened(d, k);
        if d.x == 0.0 && d.y == 0.0 && d.z == 0.0 {
            continue;
        }
        let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        let Some(mut a) = Dda::start(&g, o, d, inv, 0.0, f64::INFINITY) else {
            continue;
        };
        let stop = k % 9;
        for _ in 0..stop {
            if !a.advance() {
                break;
            }
        }
        let mut r = Dda::start_at(&g, o, d, inv, 0.0, f64::INFINITY, a.voxel()).unwrap();
        assert_eq!(r.voxel(), a.voxel());
        assert_eq!(r.index, a.index);
        assert_eq!(r.t_exit().to_bits(), a.t_exit().to_bits(), "ray {k}");
        loop {
            let (x, y) = (r.advance_axis(), a.advance_axis());
            assert_eq!(x, y);
            if x.is_none() {
                break;
            }
            assert_eq!(r.voxel(), a.voxel());
            assert_eq!(r.index, a.index);
            assert_eq!(r.t_enter.to_bits(), a.t_enter.to_bits(), "ray {k}");
            assert_eq!(r.t_exit().to_bits(), a.t_exit().to_bits(), "ray {k}");
        }
    }
}

#[test]
fn leaving_a_block_is_stepping_out_of_it() {
    // A grid whose sides are not multiples of the blocks, cubic voxels
    // (rays along diagonals tie), and rays that end inside it.
    for (res, diag) in [([37, 23, 19], false), ([8, 8, 8], true)] {
        let g = GridSpec::new(&unit_box(), res);
        let mut rng = Lcg(11);
        for k in 0..400 {
            let (o, mut d) = random_ray(&mut rng);
            if diag {
                // From a voxel corner along a diagonal: faces met at once.
                let o = V3::new(1.0, 0.5, 0.0);
                let s = |v: f64| if v < 0.0 { -1.0 } else { 1.0 };
                d = V3::new(s(d.x), s(d.y), 1.0);
                let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
                check_blocks(&g, o, d, inv, f64::INFINITY, k);
                continue;
            }
            let d = flattened(d, k);
            if d.x == 0.0 && d.y == 0.0 && d.z == 0.0 {
                continue;
            }
            let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
            let t_max = if k % 3 == 0 {
                f64::from(rng.next()) * 2.0
            } else {
                f64::INFINITY
            };
            check_blocks(&g, o, d, inv, t_max, k);
        }
    }
}

/// A ray for walks through the unit box's grids: an origin in or beside
/// the box, any direction (six numbers drawn, in this order).
fn random_ray(rng: &mut Lcg) -> (V3, V3) {
    let o = V3::new(
        f64::from(rng.next()) * 1.6 - 0.3,
        f64::from(rng.next()),
        f64::from(rng.next()),
    );
    let d = V3::new(
        f64::from(rng.next()) - 0.5,
        f64::from(rng.next()) - 0.5,
        f64::from(rng.next()) - 0.5,
    );
    (o, d)
}

/// Ray `k`'s direction `d`, made parallel to a plane (one ray in five) or
/// an axis (another one in five): the walks whose faces never come.
fn flattened(d: V3, k: u32) -> V3 {
    match k % 5 {
        0 => V3::new(d.x, d.y, 0.0),
        1 => V3::new(0.0, 0.0, d.z),
        _ => d,
    }
}

/// From every voxel of a walk and for blocks of 2, 4, 8 and 16 voxels a side,
/// [`Dda::leave_block`] leaves the walk as stepping out of the block does,
/// and [`Dda::entered_block`] tells each step into another block.
fn check_blocks(g: &GridSpec, o: V3, d: V3, inv: V3, t_max: f64, k: u32) {
    let Some(mut walk) = Dda::start(g, o, d, inv, 0.0, t_max) else {
        return;
    };
    loop {
        for shift in 1..=4 {
            let block = walk.voxel().map(|c| c >> shift);
            let mut stepped = walk;
            let out = loop {
                let was = stepped.voxel().map(|c| c >> shift);
                let Some(a) = stepped.advance_axis() else {
                    break None;
                };
                // A step says whether it entered another block.
                let now = stepped.voxel().map(|c| c >> shift);
                assert_eq!(stepped.entered_block(a, shift), now != was, "ray {k}");
                if now != block {
                    break Some(a);
                }
            };
            let mut jumped = walk;
            let got = jumped.leave_block(shift);
            assert_eq!(got, out, "ray {k}, shift {shift}, from {:?}", walk.voxel());
            if got.is_some() {
                assert_eq!(jumped, stepped, "ray {k}, shift {shift}");
                assert_eq!(jumped.t_enter.to_bits(), stepped.t_enter.to_bits());
                assert_eq!(jumped.t_exit().to_bits(), stepped.t_exit().to_bits());
            }
        }
        if !walk.advance() {
            break;
        }
    }
}

/// A deterministic generator for the scenes below.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) as f32
    }
}

fn cube(c: [f32; 3], r: f32) -> Aabb {
    Aabb {
        min: c.map(|x| x - r),
        max: c.map(|x| x + r),
    }
}

/// Plans the grids of `boxes` as a database would (size and density
/// summaries written in order), and checks the plan against the objects:
/// every object's group counts it, and lies within that group's bounds.
fn plan_of(boxes: &[Aabb]) -> GroupPlan {
    let mut sizes = crate::scene::SizeSummary::default();
    let mut density = crate::scene::DensitySummary::default();
    for b in boxes {
        sizes.add(b);
        density.add(b);
    }
    let plan = plan_groups(&sizes, Some(&density), true);
    let n = plan.partition.groups();
    assert_eq!(plan.counts.len(), n);
    assert_eq!(plan.bounds.len(), n);
    let mut counts = vec![0u64; n];
    for b in boxes {
        let g = plan.partition.group(b);
        counts[g] += 1;
        let within =
            (0..3).all(|i| plan.bounds[g].min[i] <= b.min[i] && b.max[i] <= plan.bounds[g].max[i]);
        assert!(
            within,
            "{b:?} outside group {g}'s bounds {:?}",
            plan.bounds[g]
        );
    }
    assert_eq!(counts, plan.counts);
    assert_eq!(
        plan_groups(&sizes, Some(&density), false).partition,
        Partition::one()
    );
    plan
}

#[test]
fn a_dense_model_in_a_sparse_world_gets_a_grid_of_its_own() {
    let mut r = Lcg(5);
    let mut boxes = Vec::new();
    // A floor first (the lattice must not take its size), then small
    // spheres over it, then a model of tiny triangles in a unit box, then
    // spheres again.
    boxes.push(Aabb {
        min: [-100.0, 0.0, -100.0],
        max: [100.0, 0.0, 100.0],
    });
    let spheres = |r: &mut Lcg, boxes: &mut Vec<Aabb>, n: usize| {
        for _ in 0..n {
            let (x, z) = (200.0 * r.next() - 100.0, 200.0 * r.next() - 100.0);
            boxes.push(cube([x, 0.1, z], 0.1));
        }
    };
    spheres(&mut r, &mut boxes, 1500);
    for _ in 0..20_000 {
        let c = [r.next() - 0.5, r.next(), r.next() - 0.5];
        boxes.push(cube(c, 0.002 + 0.002 * r.next()));
    }
    spheres(&mut r, &mut boxes, 1500);
    let plan = plan_of(&boxes);
    let regions = plan.partition.regions.as_ref().expect("a dense region");
    assert_eq!(regions.count(), 1);
    assert_eq!(plan.counts[1], 20_000, "{:?}", plan.counts);
    assert!(plan.bounds[1].diagonal() < 2.0, "{:?}", plan.bounds[1]);
    assert!(plan.bounds[0].diagonal() > 200.0);
}

#[test]
fn evenly_spread_objects_and_surfaces_get_no_region() {
    let mut r = Lcg(6);
    // Objects filling a box.
    let boxes: Vec<Aabb> = (0..20_000)
        .map(|_| cube([r.next(), r.next(), r.next()].map(|x| 10.0 * x), 0.01))
        .collect();
    assert!(plan_of(&boxes).partition.regions.is_none());
    // Small triangles over a sphere's surface (most cells empty, the
    // occupied ones far denser than the box's average, but the region
    // they make is the whole box).
    let boxes: Vec<Aabb> = (0..20_000)
        .map(|_| {
            let (u, v) = (std::f32::consts::TAU * r.next(), 2.0 * r.next() - 1.0);
            let s = (1.0 - v * v).sqrt();
            cube([5.0 * s * u.cos(), 5.0 * s * u.sin(), 5.0 * v], 0.01)
        })
        .collect();
    assert!(plan_of(&boxes).partition.regions.is_none());
}

#[test]
fn two_dense_models_and_huge_objects_make_at_most_three_grids() {
    let mut r = Lcg(7);
    let mut boxes = Vec::new();
    for centre in [[-40.0f32, 0.5, 30.0], [60.0, 0.5, -20.0]] {
        for _ in 0..10_000 {
            let c = [0, 1, 2].map(|i| centre[i] + r.next() - 0.5);
            boxes.push(cube(c, 0.003));
        }
    }
    for _ in 0..3000 {
        boxes.push(cube(
            [200.0 * r.next() - 100.0, 0.2, 200.0 * r.next() - 100.0],
            0.2,
        ));
    }
    // Two walls far larger than everything else.
    boxes.push(Aabb {
        min: [-500.0, 0.0, -500.0],
        max: [500.0, 300.0, -500.0],
    });
    boxes.push(Aabb {
        min: [-500.0, 0.0, 500.0],
        max: [500.0, 300.0, 500.0],
    });
    // Main, one region and the huge objects: a plan makes three grids at
    // most, so the other model stays in the main grid.
    let plan = plan_of(&boxes);
    assert_eq!(plan.partition.regions.as_ref().map(|r| r.count()), Some(1));
    assert_eq!(plan.counts, vec![13_000, 10_000, 2]);
    // Without the walls, both models get a grid.
    let plan = plan_of(&boxes[..boxes.len() - 2]);
    assert_eq!(plan.partition.regions.as_ref().map(|r| r.count()), Some(2));
    assert_eq!(plan.counts, vec![3000, 10_000, 10_000]);
}
