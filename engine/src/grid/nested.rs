//! Voxels too full for a list: a bounding volume hierarchy over the
//! objects of each such voxel.
//!
//! A uniform grid sized for a whole scene puts a dense model that fills a
//! small part of it into a handful of voxels: the full Stanford dragon
//! (871,306 triangles) in a unit box on a 200 x 200 floor strewn with
//! 20,000 spheres lands in about a hundred voxels of thousands of
//! triangles each, and every ray crossing one tests them all. The paper's
//! Section 2.4 answer is an aggregate: objects at roughly the same place
//! handled as one object with an acceleration structure of its own. Here
//! a voxel listing more than [`MIN_OBJECTS`] objects lists one entry
//! instead, tagged [`NESTED`], that stands for a hierarchy of boxes over
//! those objects (cut along a Morton curve through their centres, at most
//! [`LEAF`] objects per leaf); a ray or packet descends only into the
//! boxes it may meet.
//!
//! Images do not change: a box is passed over only when no object inside
//! it can give a hit the ray would keep (the tests of [`ray_meets`] and
//! the packets' culling are conservative), and which of several hits
//! wins does not depend on the order of the tests (nearest, ties to the
//! smaller id).

use crate::math::Vec3;
use crate::scene::Aabb;

/// Objects' bounding boxes by id, as a grid's build reads them.
pub trait Boxes: Sync {
    fn count(&self) -> usize;
    fn bbox(&self, id: u32) -> Aabb;

    /// The object's input id, by which ties go: its id, unless the
    /// database is in spatial order.
    fn rank(&self, id: u32) -> u32 {
        id
    }

    /// Whether some object's input id is not its id.
    fn ranked(&self) -> bool {
        false
    }

    /// Gives `f` the id and box of each object of `ids`, in id order.
    fn each_in(&self, ids: std::ops::Range<u32>, mut f: impl FnMut(u32, Aabb)) {
        for id in ids {
            f(id, self.bbox(id));
        }
    }

    /// Gives `f` every object's id and box, in id order.
    fn each(&self, f: impl FnMut(u32, Aabb)) {
        self.each_in(0..self.count() as u32, f)
    }
}

impl Boxes for [Aabb] {
    fn count(&self) -> usize {
        self.len()
    }

    fn bbox(&self, id: u32) -> Aabb {
        self[id as usize]
    }
}

/// Tag of a voxel entry that stands for a hierarchy; the other bits are
/// the index of its root node. Object ids stay below it (a database holds
/// fewer than 2^31 objects in memory).
pub const NESTED: u32 = 1 << 31;
/// Voxels listing more objects than this get a hierarchy. Chosen so that
/// the voxels of the SPD scenes keep their lists (their fullest hold a
/// few dozen objects) and only crowds pay the descent.
pub const MIN_OBJECTS: usize = 64;
/// Most objects in a leaf (4 and 16 were slower on the dragon).
const LEAF: usize = 8;

/// `count` of an interior node: this bit, and its split axis below it.
const INTERIOR: u32 = 1 << 31;

#[derive(Clone, Copy, Debug)]
struct Node {
    bbox: Aabb,
    /// A leaf's first object in `objects`; an interior node's first child
    /// (the second follows it).
    first: u32,
    /// A leaf's object count, or `INTERIOR | axis`.
    count: u32,
}

/// What a traversal meets, with the state (say, the lanes of a packet
/// still in the running) it reached it with: a box to descend into or not,
/// or an object.
pub enum Entry<'a, S> {
    Box(&'a Aabb, S),
    Object(u32, S),
}

/// What a node of a hierarchy holds.
pub enum Holds<'a> {
    /// A leaf's entries: objects, and (tagged [`NESTED`]) the roots of
    /// aggregates' hierarchies, walked as its children.
    Leaf(&'a [u32]),
    /// Two children, the nearer (for the walk's direction) first.
    Children(u32, u32),
}

/// How many times its box's half-area an aggregate's leaves may add up
/// to and keep the order it was given (see
/// [`Hierarchies::build_aggregate`]): a group in no order has leaves
/// about as large as itself, eight times its box; one in order, far less
/// (every aggregate of tetra12 and mount11 keeps its order).
const COHERENT: f64 = 4.0;

/// Most nodes a walk of one voxel's hierarchy keeps pending (see
/// [`Hierarchies::visit`]).
pub const MAX_PENDING: usize = 106;

/// The hierarchies of one grid's crowded voxels, in two flat arrays.
#[derive(Default)]
pub struct Hierarchies {
    nodes: Vec<Node>,
    objects: Vec<u32>,
}

impl Hierarchies {
    /// Forgets every hierarchy, keeping the memory.
    pub fn clear(&mut self) {
        self.nodes.clear();
        self.objects.clear();
    }

    /// Objects listed in the leaves.
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    /// Room for `nodes` nodes and `objects` leaf entries more.
    pub fn reserve(&mut self, nodes: usize, objects: usize) {
        self.nodes.reserve_exact(nodes);
        self.objects.reserve_exact(objects);
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * size_of::<Node>() + self.objects.len() * 4
    }

    /// Nodes in all the hierarchies.
    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }

    /// The box of the hierarchy of entry `entry` (tagged [`NESTED`]).
    pub fn bbox(&self, entry: u32) -> Aabb {
        self.nodes[(entry & !NESTED) as usize].bbox
    }

    /// Appends `other` (built on its own), returning the voxel entry of
    /// its first hierarchy, or `None` if the nodes would outgrow the
    /// entry's 31 bits.
    pub fn append(&mut self, other: Hierarchies) -> Option<u32> {
        let nodes = u32::try_from(self.nodes.len()).ok()?;
        let objects = u32::try_from(self.objects.len()).ok()?;
        let total = self.nodes.len() + other.nodes.len();
        if total > NESTED as usize {
            return None;
        }
        self.nodes.extend(other.nodes.iter().map(|n| Node {
            first: n.first
                + if n.count & INTERIOR == 0 {
                    objects
                } else {
                    nodes
                },
            ..*n
        }));
        self.objects.extend_from_slice(&other.objects);
        Some(NESTED | nodes)
    }

    /// Builds a hierarchy over the objects `ids`, returning its voxel
    /// entry. The objects are put in order along a Morton curve through
    /// their centres and halved recursively in that order (a balanced tree
    /// of nearby objects), and the boxes are gathered bottom-up: a sort
    /// and one pass, where splitting by the widest spread of centres at
    /// each level moved every object once per level (and cost the dragon
    /// scene twice the build time for the same number of tests).
    pub fn build(&mut self, ids: &[u32], boxes: &(impl Boxes + ?Sized)) -> u32 {
        self.build_with(ids, boxes, &mut Vec::new())
    }

    /// [`Hierarchies::build`], with `order` as room to sort in (kept by a
    /// caller that builds many small hierarchies).
    pub fn build_with(
        &mut self,
        ids: &[u32],
        boxes: &(impl Boxes + ?Sized),
        order: &mut Vec<(u32, u32)>,
    ) -> u32 {
        let mut centres = Aabb::EMPTY;
        for &id in ids {
            centres.add_point(centre(&boxes.bbox(id)));
        }
        let scale: [f32; 3] = std::array::from_fn(|i| {
            let e = centres.max[i] - centres.min[i];
            if e > 0.0 { 1023.0 / e } else { 0.0 }
        });
        order.clear();
        order.extend(ids.iter().map(|&id| {
            let c = centre(&boxes.bbox(id));
            let q: [u32; 3] =
                std::array::from_fn(|i| (((c[i] - centres.min[i]) * scale[i]) as u32).min(1023));
            (morton(q), id)
        }));
        // By code, then input id: the same tree on every run, and in a
        // database in spatial order the tree of the input's order.
        // (One u64 compare rather than a pair's two.)
        order.sort_unstable_by_key(|&(code, id)| (code as u64) << 32 | boxes.rank(id) as u64);
        let root = self.push_blank();
        self.split(root, order, boxes);
        NESTED | root as u32
    }

    /// Builds the hierarchy of an aggregate, a group of objects `ids`
    /// consecutive in the database, returning its voxel entry. A group
    /// crowded into a few voxels was almost always written near to near
    /// (a generator's recursion, a mesh's strips, a database in spatial
    /// order), so it is first halved in the order given: no curve codes
    /// and no sort, which were half of what building a pass's aggregates
    /// cost (tetra 15 under 2 GiB: a tenth of its passes' time, for the
    /// same tests within 1 %). Only if its leaves' boxes add up to more
    /// than [`COHERENT`] times the group's (in half-area, the cost a ray
    /// pays to reach a leaf) is the order taken as scattered and the
    /// group built along a Morton curve instead ([`Hierarchies::build_with`]).
    /// Both the tracers build through here, so their trees are the same.
    pub fn build_aggregate(
        &mut self,
        ids: &[u32],
        boxes: &(impl Boxes + ?Sized),
        order: &mut Vec<(u32, u32)>,
    ) -> u32 {
        let (nodes, objects) = (self.nodes.len(), self.objects.len());
        let root = self.push_blank();
        let (bbox, leaves) = self.halve(root, ids, boxes);
        if leaves <= COHERENT * half_area(&bbox) {
            return NESTED | root as u32;
        }
        self.nodes.truncate(nodes);
        self.objects.truncate(objects);
        self.build_with(ids, boxes, order)
    }

    fn push_blank(&mut self) -> usize {
        self.nodes.push(Node {
            bbox: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        self.nodes.len() - 1
    }

    /// Makes `node` the tree of `ids` halved in their order; returns its
    /// box and its leaves' summed half-areas.
    fn halve(&mut self, node: usize, ids: &[u32], boxes: &(impl Boxes + ?Sized)) -> (Aabb, f64) {
        if ids.len() <= LEAF {
            let bbox = self.leaf(node, ids.iter().copied(), boxes);
            return (bbox, half_area(&bbox));
        }
        let mid = ids.len() / 2;
        let left = self.push_children(node);
        let (a, la) = self.halve(left, &ids[..mid], boxes);
        let (b, lb) = self.halve(left + 1, &ids[mid..], boxes);
        (self.interior(node, left, a, b), la + lb)
    }

    /// Makes `node` a leaf of the objects `ids`; returns its box.
    fn leaf(
        &mut self,
        node: usize,
        ids: impl ExactSizeIterator<Item = u32> + Clone,
        boxes: &(impl Boxes + ?Sized),
    ) -> Aabb {
        let mut bbox = Aabb::EMPTY;
        for id in ids.clone() {
            bbox.union(&boxes.bbox(id));
        }
        self.nodes[node] = Node {
            bbox,
            first: self.objects.len() as u32,
            count: ids.len() as u32,
        };
        self.objects.extend(ids);
        bbox
    }

    /// Two blank children of `node`, placed together; the first's index.
    fn push_children(&mut self, node: usize) -> usize {
        let left = self.nodes.len();
        let blank = self.nodes[node];
        self.nodes.push(blank);
        self.nodes.push(blank);
        left
    }

    /// Makes `node` the parent of `left` and the node after it, of boxes
    /// `a` and `b`; returns its box.
    fn interior(&mut self, node: usize, left: usize, a: Aabb, b: Aabb) -> Aabb {
        let mut bbox = a;
        bbox.union(&b);
        // The axis along which the children lie furthest apart orders
        // them for the walk.
        let apart = |i: usize| ((b.min[i] + b.max[i]) - (a.min[i] + a.max[i])).abs();
        let axis = (0..3)
            .max_by(|&x, &y| apart(x).total_cmp(&apart(y)))
            .unwrap_or(0);
        self.nodes[node] = Node {
            bbox,
            first: left as u32,
            count: INTERIOR | axis as u32,
        };
        bbox
    }

    /// Makes `node` the tree of `items` (in curve order); returns its box.
    fn split(&mut self, node: usize, items: &[(u32, u32)], boxes: &(impl Boxes + ?Sized)) -> Aabb {
        if items.len() <= LEAF {
            return self.leaf(node, items.iter().map(|&(_, id)| id), boxes);
        }
        // Where the codes' highest differing bit turns on (the curve's
        // cut through space); the middle when all codes are equal.
        let (first, last) = (items[0].0, items[items.len() - 1].0);
        let mid = if first == last {
            items.len() / 2
        } else {
            let bit = 31 - (first ^ last).leading_zeros();
            items.partition_point(|&(c, _)| c & (1 << bit) == 0)
        };
        let left = self.push_children(node);
        let a = self.split(left, &items[..mid], boxes);
        let b = self.split(left + 1, &items[mid..], boxes);
        self.interior(node, left, a, b)
    }

    /// Node `n`'s box and what it holds; `high_first` orders an interior
    /// node's children as [`Hierarchies::visit`] does. (For walks that
    /// keep their own stack, with no closure in their inner loop.)
    #[inline(always)]
    pub fn node(&self, n: u32, high_first: u8) -> (&Aabb, Holds<'_>) {
        let node = &self.nodes[n as usize];
        let holds = if node.count & INTERIOR == 0 {
            let first = node.first as usize;
            Holds::Leaf(&self.objects[first..first + node.count as usize])
        } else if high_first >> (node.count & 3) & 1 != 0 {
            Holds::Children(node.first + 1, node.first)
        } else {
            Holds::Children(node.first, node.first + 1)
        };
        (&node.bbox, holds)
    }

    /// Walks the hierarchy of voxel entry `entry` (tagged [`NESTED`]),
    /// starting in state `state`: `f` is given each box with its parent's
    /// state and returns the state to descend with (`None`: pass over the
    /// box), and each object of the leaves it reaches with the leaf's
    /// state, returning `None` to stop the walk. `high_first` has bit
    /// `axis` set where the upper child along that axis should be visited
    /// first (toward where the rays go). Returns `false` if `f` stopped it.
    #[inline(always)]
    pub fn visit<S: Copy>(
        &self,
        entry: u32,
        high_first: u8,
        state: S,
        f: &mut impl FnMut(Entry<'_, S>) -> Option<S>,
    ) -> bool {
        // Pending entries: one far child per level of the current path.
        // Each level splits on a bit of the 30-bit codes below the
        // parent's, or halves the objects: fewer than 30 + 32 levels. A
        // leaf (at most 8 entries) may push as many aggregates'
        // hierarchies (of 64 objects: fewer than 30 + 6 levels each, and
        // no aggregate in their leaves): 62 + 8 + 36 = 106 at most.
        let mut stack = [(0u32, state); MAX_PENDING];
        let mut sp = 0;
        let (mut n, mut st) = ((entry & !NESTED) as usize, state);
        loop {
            let node = &self.nodes[n];
            if let Some(inner) = f(Entry::Box(&node.bbox, st)) {
                if node.count & INTERIOR == 0 {
                    let first = node.first as usize;
                    for &id in &self.objects[first..first + node.count as usize] {
                        if id & NESTED != 0 {
                            // Another hierarchy of this store (an
                            // aggregate's, in a crowded voxel's): walked
                            // next, as a child.
                            stack[sp] = ((id & !NESTED), inner);
                            sp += 1;
                        } else if f(Entry::Object(id, inner)).is_none() {
                            return false;
                        }
                    }
                } else {
                    let axis = node.count & 3;
                    let (near, far) = if high_first >> axis & 1 != 0 {
                        (node.first + 1, node.first)
                    } else {
                        (node.first, node.first + 1)
                    };
                    stack[sp] = (far, inner);
                    sp += 1;
                    (n, st) = (near as usize, inner);
                    continue;
                }
            }
            if sp == 0 {
                return true;
            }
            sp -= 1;
            let (k, s) = stack[sp];
            (n, st) = (k as usize, s);
        }
    }
}

/// The Morton code of a point quantized to 10 bits per axis.
fn morton(q: [u32; 3]) -> u32 {
    let spread = |mut x: u32| {
        x &= 0x3ff;
        x = (x | x << 16) & 0x0300_00ff;
        x = (x | x << 8) & 0x0300_f00f;
        x = (x | x << 4) & 0x030c_30c3;
        x = (x | x << 2) & 0x0924_9249;
        x
    };
    spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2
}

/// Half the surface area of `b` (0 when empty): by the usual argument,
/// proportional to the chance that a ray meeting a box around it meets it.
fn half_area(b: &Aabb) -> f64 {
    let [x, y, z] = b.extent();
    x * y + y * z + z * x
}

#[inline(always)]
fn centre(b: &Aabb) -> [f32; 3] {
    std::array::from_fn(|i| 0.5 * b.min[i] + 0.5 * b.max[i])
}

/// Bits for [`Hierarchies::visit`]: the axes along which `d` points up.
#[inline(always)]
pub fn high_first(d: Vec3) -> u8 {
    (d.x > 0.0) as u8 | ((d.y > 0.0) as u8) << 1 | ((d.z > 0.0) as u8) << 2
}

/// Whether the ray `o + t d` (`inv` = 1/d) may meet box `b` grown by `pad`
/// for some t in `[t0, t1]`. Conservative: along an axis where the ray's
/// direction is zero, the box is ruled out only when the origin lies
/// outside its slab (the arithmetic gives 0 x inf = NaN for an origin
/// exactly on a face, which must rule nothing out; `f64::min` and `max`
/// would pass over the NaN and keep the infinity instead).
#[inline(always)]
pub fn ray_meets(o: Vec3, inv: Vec3, t0: f64, t1: f64, b: &Aabb, pad: f64) -> bool {
    let (mut lo, mut hi) = (t0, t1);
    for i in 0..3 {
        let a = (b.min[i] as f64 - pad - o[i]) * inv[i];
        let c = (b.max[i] as f64 + pad - o[i]) * inv[i];
        let (near, far) = slab(a, c);
        lo = lo.max(near);
        hi = hi.min(far);
    }
    lo <= hi
}

/// The parameter range `[near, far]` of a slab whose faces the ray meets
/// at `a` and `c`: all of it if either is NaN (a zero direction with the
/// origin on a face, so inside the slab).
#[inline(always)]
pub fn slab(a: f64, c: f64) -> (f64, f64) {
    if a.is_nan() || c.is_nan() {
        (f64::NEG_INFINITY, f64::INFINITY)
    } else {
        (a.min(c), a.max(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_boxes(n: usize) -> Vec<Aabb> {
        // A 3D lattice of small boxes, in a scrambled order.
        (0..n)
            .map(|i| {
                let j = (i * 7919) % n;
                let p = [(j % 10) as f32, (j / 10 % 10) as f32, (j / 100) as f32];
                Aabb {
                    min: p,
                    max: [p[0] + 0.5, p[1] + 0.5, p[2] + 0.5],
                }
            })
            .collect()
    }

    #[test]
    fn every_object_is_in_one_leaf_and_inside_its_boxes() {
        let boxes = unit_boxes(1000);
        let ids: Vec<u32> = (0..1000).collect();
        let mut h = Hierarchies::default();
        let e = h.build(&ids, boxes.as_slice());
        assert_ne!(e & NESTED, 0);
        let mut seen = vec![0u32; 1000];
        // Descend everywhere, carrying the box entered last: each object
        // must lie inside its leaf's box, which must lie inside its parent.
        let everything = Aabb {
            min: [-1e9; 3],
            max: [1e9; 3],
        };
        let inside =
            |a: &Aabb, b: &Aabb| (0..3).all(|i| b.min[i] <= a.min[i] && b.max[i] >= a.max[i]);
        h.visit(e, 0, everything, &mut |x| match x {
            Entry::Box(b, parent) => {
                assert!(inside(b, &parent), "a box inside its parent");
                Some(*b)
            }
            Entry::Object(id, leaf) => {
                assert!(
                    inside(&boxes[id as usize], &leaf),
                    "an object inside its leaf"
                );
                seen[id as usize] += 1;
                Some(leaf)
            }
        });
        assert!(seen.iter().all(|&c| c == 1), "each object once");
        assert!(h.nodes.len() < 1000, "leaves hold several objects");
    }

    /// The leaves of the hierarchy of entry `e`, in node order.
    fn leaves(h: &Hierarchies, e: u32) -> Vec<Vec<u32>> {
        let mut out = Vec::new();
        let mut stack = vec![e & !NESTED];
        while let Some(n) = stack.pop() {
            match h.node(n, 0).1 {
                Holds::Leaf(ids) => out.push(ids.to_vec()),
                Holds::Children(a, b) => stack.extend([b, a]),
            }
        }
        out
    }

    #[test]
    fn an_aggregate_in_order_keeps_it_and_a_scattered_one_follows_the_curve() {
        // A patch of 8 x 8 unit squares listed row by row: halved as
        // given, its leaves are its rows (the curve would cut it into
        // 4 x 2 blocks).
        let patch: Vec<Aabb> = (0..64)
            .map(|i| {
                let (x, y) = ((i % 8) as f32, (i / 8) as f32);
                Aabb {
                    min: [x, y, 0.0],
                    max: [x + 1.0, y + 1.0, 0.0],
                }
            })
            .collect();
        let ids: Vec<u32> = (0..64).collect();
        let (mut h, mut order) = (Hierarchies::default(), Vec::new());
        let e = h.build_aggregate(&ids, patch.as_slice(), &mut order);
        let rows: Vec<Vec<u32>> = (0..8).map(|r| (8 * r..8 * r + 8).collect()).collect();
        assert_eq!(leaves(&h, e), rows);
        // The same squares in a scattered order: each leaf of that order
        // would span the whole patch, so the group is built along the
        // curve, as `build_with` builds it: leaves of neighbours again.
        let scattered: Vec<Aabb> = (0..64).map(|i| patch[(i * 37) % 64]).collect();
        let mut h = Hierarchies::default();
        let e = h.build_aggregate(&ids, scattered.as_slice(), &mut order);
        let mut curve = Hierarchies::default();
        let c = curve.build_with(&ids, scattered.as_slice(), &mut order);
        assert_eq!(leaves(&h, e), leaves(&curve, c));
        assert_eq!(h.nodes(), curve.nodes());
        for leaf in leaves(&h, e) {
            let mut leaf_box = Aabb::EMPTY;
            for &i in &leaf {
                leaf_box.union(&scattered[i as usize]);
            }
            assert!(
                half_area(&leaf_box) <= 8.0,
                "a leaf of neighbours: {leaf_box:?}"
            );
        }
        // After another hierarchy, the scattered group's first try leaves
        // nothing behind.
        let mut both = Hierarchies::default();
        let first = both.build_aggregate(&ids, patch.as_slice(), &mut order);
        let second = both.build_aggregate(&ids, scattered.as_slice(), &mut order);
        assert_eq!(leaves(&both, first), rows);
        assert_eq!(leaves(&both, second), leaves(&curve, c));
        assert_eq!(both.len(), 128);
    }

    #[test]
    fn a_ray_reaches_exactly_the_boxes_it_crosses() {
        let boxes = unit_boxes(1000);
        let ids: Vec<u32> = (0..1000).collect();
        let mut h = Hierarchies::default();
        let e = h.build(&ids, boxes.as_slice());
        let o = Vec3::new(-1.0, 3.25, 4.25);
        let d = Vec3::new(1.0, 0.0, 0.0);
        let inv = Vec3::new(1.0, f64::INFINITY, f64::INFINITY);
        let mut found = Vec::new();
        h.visit(e, high_first(d), (), &mut |x| match x {
            Entry::Box(b, ()) => ray_meets(o, inv, 0.0, f64::INFINITY, b, 0.0).then_some(()),
            Entry::Object(id, ()) => {
                if ray_meets(o, inv, 0.0, f64::INFINITY, &boxes[id as usize], 0.0) {
                    found.push(id);
                }
                Some(())
            }
        });
        let mut expect: Vec<u32> = (0..1000u32)
            .filter(|&i| ray_meets(o, inv, 0.0, f64::INFINITY, &boxes[i as usize], 0.0))
            .collect();
        found.sort();
        expect.sort();
        assert_eq!(found, expect);
        assert_eq!(found.len(), 10, "the row of boxes at y = 3, z = 4");
    }

    #[test]
    fn a_ray_along_a_face_meets_the_box() {
        let b = Aabb {
            min: [0.0, 0.0, 0.0],
            max: [1.0, 1.0, 1.0],
        };
        let inf = f64::INFINITY;
        // Along x, in the planes y = 0 and z = 1 (both faces): 0 x inf.
        for (o, d) in [
            (Vec3::new(-2.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 0.0)),
            (Vec3::new(-2.0, 1.0, 0.0), Vec3::new(1.0, 0.0, -0.0)),
            (Vec3::new(0.5, 0.0, 1.0), Vec3::new(0.0, 0.0, -0.0)),
        ] {
            let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
            assert!(ray_meets(o, inv, 0.0, inf, &b, 0.0), "{o:?} {d:?}");
        }
        // Just outside a face, with a zero direction: missed.
        let o = Vec3::new(-2.0, -1e-9, 0.5);
        let inv = Vec3::new(1.0, inf, inf);
        assert!(!ray_meets(o, inv, 0.0, inf, &b, 0.0));
        assert!(ray_meets(o, inv, 0.0, inf, &b, 1e-8), "the pad reaches it");
    }

    #[test]
    fn morton_codes_interleave_the_axes() {
        assert_eq!(morton([1, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]), 2);
        assert_eq!(morton([0, 0, 1]), 4);
        assert_eq!(morton([3, 0, 0]), 0b1001);
        assert_eq!(morton([1023, 1023, 1023]), (1 << 30) - 1);
    }

    #[test]
    fn identical_boxes_are_all_found() {
        let boxes = vec![
            Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            };
            100
        ];
        let ids: Vec<u32> = (0..100).collect();
        let mut h = Hierarchies::default();
        let e = h.build(&ids, boxes.as_slice());
        let mut n = 0;
        h.visit(e, 0, (), &mut |x| {
            if let Entry::Object(..) = x {
                n += 1;
            }
            Some(())
        });
        assert_eq!(n, 100);
    }
}
