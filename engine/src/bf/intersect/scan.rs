//! The scan of a pass (step 3): each block's candidate objects and
//! aggregates tested against the rays registered in their voxels, the
//! (object, ray) pairs gathered per shard and tested, and each hit offered
//! to its ray (with its surface when the ray carries one).

use super::*;
use crate::intersect::Ray;
use crate::kernels::{Lanes, Need, ShapeLanes, each_lane};

/// A ray's mailbox value while it walks aggregate `index` in pass
/// `pass`: no object's (an object's low half is zero), and no other
/// aggregate's. A ray's mailbox outlives its pass; with the pass in the
/// value, which aggregates a ray walks in a pass depends on that pass's
/// registrations alone.
#[inline(always)]
fn aggregate_tag(index: u32, pass: u64) -> PrimId {
    PrimId(((index as u64) << 32) | (pass % u32::MAX as u64 + 1))
}

/// Tests one block's candidate objects and aggregates against the shard's
/// registered rays.
pub(super) fn scan_block<R: Elem>(
    sh: &mut Shard<R>,
    block: &Block<'_>,
    found: &Found,
    grids: &VoxelGrids,
    models: &Models,
    per_pass: bool,
    carry: bool,
    walk: &ScanPass,
) {
    scan_singles(
        sh,
        block,
        &found.singles,
        grids,
        models,
        per_pass,
        carry,
        walk.isa,
    );
    if !found.aggregates.is_empty() {
        scan_aggregates(sh, block, found, grids, models.cutouts(), carry, walk);
    }
}

/// What a pass's scan needs besides the shard: the pass (which names the
/// aggregates in the rays' mailboxes), how far from its box an object's
/// hit may be computed ([`crate::grid::box_slack`]) and the kernels'
/// instruction set.
#[derive(Clone, Copy, Debug)]
pub(super) struct ScanPass {
    pub(super) pass: u64,
    pub(super) slack: f64,
    pub(super) isa: Isa,
}

/// Tests the block's aggregates against the shard's registered rays: a
/// ray stored in some voxel of an aggregate's box walks its hierarchy
/// once (the mailbox), entering only the boxes it may meet before its
/// best hit so far, and tests the objects there (except those its last
/// voxel of the previous pass shows it tested then). The hierarchy may
/// lead it to objects outside the voxels it is stored in: their hits are
/// hits all the same, and a hit is kept only if it is the nearest so far,
/// so the ray's final hit, and the image, do not change.
fn scan_aggregates<R: Elem>(
    sh: &mut Shard<R>,
    block: &Block<'_>,
    found: &Found,
    grids: &VoxelGrids,
    cutouts: Option<&Cutouts>,
    carry: bool,
    walk: &ScanPass,
) {
    // One aggregate's objects, each decoded when a ray first tests it: a
    // ray walking the hierarchy tests a few of its 64 objects (tetra12:
    // 15 a walk), and decoding all of them when the first ray came took a
    // fifth of tetra12's scan samples. `decoded` says which entries are this
    // aggregate's; the others are left from earlier ones (clearing all 64
    // for every aggregate cost more than the decoding saved).
    let mut objects: Vec<Option<(ObjectRef<'_>, Option<Prepared>)>> = Vec::new();
    const _: () = assert!(crate::grid::aggregate::SIZE <= 64, "a bit per member");
    for a in &found.aggregates {
        let g = a.group as usize;
        if sh.regs[g].is_empty() {
            continue;
        }
        let (lo, hi) = (a.lo.map(u32::from), a.hi.map(u32::from));
        if !sh.region[g].overlaps(lo, hi) {
            continue;
        }
        let members = &found.members[a.first as usize..(a.first + a.len) as usize];
        let tag = aggregate_tag(a.index, walk.pass);
        if objects.len() < members.len() {
            objects.resize_with(members.len(), || None);
        }
        let mut decoded = 0u64;
        let Shard {
            regs,
            hot,
            cold,
            q,
            counts,
            ..
        } = &mut *sh;
        for slot in registered(&regs[g], &grids.grids[g], lo, hi) {
            let s = &mut hot[slot as usize];
            if s.blocked {
                continue;
            }
            if s.mailbox == tag {
                counts.skipped_mailbox += 1;
                continue;
            }
            s.mailbox = tag;
            counts.aggregate_walks += 1;
            let c = &mut cold[slot as usize];
            let q = &q[slot as usize];
            let r = ray64(q, s, c);
            let (o, inv) = (r.o, r.inv);
            let prev = s.prev[g];
            found
                .trees
                .visit(a.tree, high_first(r.d), (), &mut |e| match e {
                    Entry::Box(b, ()) => {
                        ray_meets(o, inv, s.t_min.to_f64(), s.upper.to_f64(), b, walk.slack)
                            .then_some(())
                    }
                    Entry::Object(id, ()) => {
                        let k = id as usize - a.first as usize;
                        let m = &members[k];
                        if prev[0] != NONE16
                            && grids.grids[g]
                                .spec
                                .cell_range(&found.member_boxes[id as usize])
                                .is_some_and(|(lo, hi)| {
                                    (0..3).all(|i| (lo[i]..=hi[i]).contains(&u32::from(prev[i])))
                                })
                        {
                            // Tested in the previous pass (Fig. 5b).
                            counts.skipped_last_voxel += 1;
                            return Some(());
                        }
                        let object = &mut objects[k];
                        if decoded >> k & 1 == 0 {
                            // Records were checked when the block was read.
                            let o = block.object_at(m.at, m.index, m.rank)?;
                            *object = Some((o, o.shape.prepare()));
                            decoded |= 1 << k;
                        }
                        let (ob, pr) = object.as_ref()?;
                        counts.tests.add(ob.shape.kind());
                        if let Some(t) = ob
                            .shape
                            .intersect(pr.as_ref(), &ob.bbox, q, s.t_min, s.upper)
                            .filter(|_| keeps(cutouts, ob, q))
                        {
                            let t = t.to_f64();
                            offer(s, q, c, t, PrimId::object(m.index), m.rank, carry, |ray| {
                                Some((ob.shape.surface(ray, t), ob.material))
                            });
                        }
                        // A shadow ray is done at its first blocker.
                        (!s.blocked).then_some(())
                    }
                });
        }
    }
}

/// The rays (slots) of a shard stored in the voxels of box `lo..=hi` of
/// `grid` (the shard's registrations there being `regs`), voxel by voxel:
/// a ray stored in several of them comes once from each.
#[inline(always)]
fn registered<'a>(
    regs: &'a RegMap,
    grid: &'a VoxelGrid,
    lo: [u32; 3],
    hi: [u32; 3],
) -> Registered<'a> {
    Registered {
        regs,
        grid,
        dense: regs.is_dense(),
        lo,
        hi,
        // Just before the first voxel.
        at: [lo[0].wrapping_sub(1), lo[1], lo[2]],
        row: grid.spec.index([0, lo[1], lo[2]]),
        slots: [].iter(),
    }
}

/// The iterator of [`registered`]: the nested loops over a box's voxels,
/// unrolled by hand (an iterator of iterators costs a tenth of a scan's
/// instructions).
struct Registered<'a> {
    regs: &'a RegMap,
    grid: &'a VoxelGrid,
    dense: bool,
    lo: [u32; 3],
    hi: [u32; 3],
    /// The voxel whose slots `slots` holds the rest of.
    at: [u32; 3],
    row: usize,
    slots: std::slice::Iter<'a, u32>,
}

/// How many rays ahead the scan asks for a ray's slot (see
/// [`crate::simd::prefetch`]).
const PREFETCH_AHEAD: usize = 12;

impl Registered<'_> {
    /// The slot `k` places after the one `next` gave last, if it is in the
    /// same voxel.
    #[inline(always)]
    fn ahead(&self, k: usize) -> Option<u32> {
        self.slots.as_slice().get(k - 1).copied()
    }
}

impl Iterator for Registered<'_> {
    type Item = u32;

    #[inline(always)]
    fn next(&mut self) -> Option<u32> {
        loop {
            if let Some(&s) = self.slots.next() {
                return Some(s);
            }
            // The next voxel, x fastest.
            if self.at[0].wrapping_add(1) <= self.hi[0] {
                self.at[0] = self.at[0].wrapping_add(1);
            } else {
                self.at[0] = self.lo[0];
                if self.at[1] < self.hi[1] {
                    self.at[1] += 1;
                } else if self.at[2] < self.hi[2] {
                    self.at[1] = self.lo[1];
                    self.at[2] += 1;
                } else {
                    return None;
                }
                self.row = self.grid.spec.index([0, self.at[1], self.at[2]]);
            }
            let v = self.row + self.at[0] as usize;
            if self.dense || self.grid.is_registered(v) {
                self.slots = self.regs.slots_in(v as u32).iter();
            }
        }
    }
}

/// Tests one block's candidate objects, one by one, against the shard's
/// registered rays: an object's rays are gathered [`LANES`] at a time and
/// tested together by its kind's kernel (an instance's, one at a time).
#[allow(clippy::too_many_arguments)]
fn scan_singles<R: Elem>(
    sh: &mut Shard<R>,
    block: &Block<'_>,
    candidates: &[Candidate],
    grids: &VoxelGrids,
    models: &Models,
    per_pass: bool,
    carry: bool,
    isa: Isa,
) {
    for c in candidates {
        let g = c.group as usize;
        if sh.regs[g].is_empty() {
            continue;
        }
        let (lo, hi) = (c.lo.map(u32::from), c.hi.map(u32::from));
        if !sh.region[g].overlaps(lo, hi) {
            continue;
        }
        // Decoded on the first ray to test, and then kept.
        // (The three apart, each written where it stays: a tuple built and
        // then moved into place was copied with loads wider than the
        // stores that had just written it, which wait for them.)
        let mut object: Option<ObjectRef<'_>> = None;
        let mut prepared: Option<Prepared> = None;
        let mut placement: Option<Placement> = None;
        // Where this instance went in `sh.placed`, when models are read
        // per pass.
        let mut placed_at = u32::MAX;
        let index = c.index;
        let prim = PrimId::object(index);
        // Rays gathered for the object's kernel.
        let mut gathered = 0;
        // Tests the gathered rays against the decoded object and counts
        // the mailbox skips that waited for it (a macro, not a function:
        // the registered rays' iterator holds `sh.regs` meanwhile).
        macro_rules! test_gathered {
            ($o:expr, $pr:expr) => {{
                let t = ObjectTest {
                    o: $o,
                    pr: $pr.as_ref(),
                    prim,
                    rank: c.rank,
                    cutouts: models.cutouts(),
                    carry,
                    isa,
                };
                t.run(&mut sh.gather, gathered, &mut sh.hot, &sh.q, &mut sh.cold);
                sh.counts.skipped_mailbox += sh.gather.count_skipped(&sh.hot);
            }};
        }
        let hot_at = sh.hot.as_ptr();
        let mut rays = registered(&sh.regs[g], &grids.grids[g], lo, hi);
        while let Some(slot) = rays.next() {
            // The rays' slots are all over memory: the slot a few rays on
            // is asked for now, so that it is in cache when its turn comes.
            if let Some(next) = rays.ahead(PREFETCH_AHEAD) {
                crate::simd::prefetch(hot_at.wrapping_add(next as usize));
            }
            let s = &mut sh.hot[slot as usize];
            if s.blocked {
                continue;
            }
            if s.mailbox == prim {
                if s.shadow && gathered > 0 {
                    // Counted once its gathered test is done, unless that
                    // test blocks it (see `Gather::skipped`).
                    sh.gather.skipped.push(slot);
                } else {
                    sh.counts.skipped_mailbox += 1;
                }
                continue;
            }
            s.mailbox = prim;
            let p = s.prev[g];
            if p[0] != NONE16
                && (lo[0]..=hi[0]).contains(&(p[0] as u32))
                && (lo[1]..=hi[1]).contains(&(p[1] as u32))
                && (lo[2]..=hi[2]).contains(&(p[2] as u32))
            {
                // Tested in the previous pass, when the ray was
                // stored in its last voxel, which this object's
                // voxel box contains (Fig. 5b).
                sh.counts.skipped_last_voxel += 1;
                continue;
            }
            if object.is_none() {
                // Records were checked when the block was read.
                let Some(o) = block.object_at(c.at, c.index, c.rank) else {
                    return;
                };
                placement = match &o.shape {
                    Shape::Instance(i) => Some(Placement::of(i)),
                    _ => None,
                };
                if let (true, Some(pl)) = (per_pass, placement) {
                    placed_at = sh.placed.len() as u32;
                    sh.placed.push((index, c.rank, pl));
                }
                prepared = o.shape.prepare();
                object = Some(o);
            }
            let Some(o) = &object else {
                continue;
            };
            let pr = &prepared;
            sh.counts.tests.add(o.shape.kind());
            if placement.is_none() {
                sh.gather.slots[gathered] = slot;
                gathered += 1;
                if gathered == LANES {
                    test_gathered!(o, pr);
                    gathered = 0;
                }
                continue;
            }
            if placed_at != u32::MAX {
                // Tested once the model is read, after the
                // world's objects.
                sh.pairs.push(Pair {
                    slot,
                    placed: placed_at,
                });
                continue;
            }
            let Some(pl) = &placement else {
                continue;
            };
            let q = &sh.q[slot as usize];
            let ray = slot_ray(q, s, &sh.cold[slot as usize]);
            let found = if s.shadow {
                models
                    .blocks(pl, ray, &mut sh.counts.tests)
                    .then_some((s.upper, prim))
            } else {
                models
                    .nearest(pl, ray, &mut sh.counts.tests)
                    .map(|(t, p)| (t, PrimId::instance(index, p)))
            };
            if let Some((t, prim)) = found {
                let t = t.to_f64();
                offer(
                    s,
                    q,
                    &mut sh.cold[slot as usize],
                    t,
                    prim,
                    c.rank,
                    carry,
                    |ray| models.surface(pl, prim.instance_parts()?.1, ray, t),
                );
            }
        }
        if gathered > 0
            && let Some(o) = &object
        {
            test_gathered!(o, &prepared);
        }
    }
}

/// One object's rays gathered for its kernel: up to [`LANES`] slots,
/// their rays as lanes, and what the kernel finds.
pub(super) struct Gather<R> {
    pub(super) slots: [u32; LANES],
    rays: RayLanes<R>,
    found: Box<LaneHits<R>>,
    /// Shadow rays the mailbox skipped while others waited for their
    /// test. Tested one by one, a shadow ray the object blocks is passed
    /// over as blocked wherever else the object's box lists it, not
    /// counted as a mailbox skip: these are counted once the test is done,
    /// unless it blocked them, so that counts are what one-by-one tests
    /// give.
    pub(super) skipped: Vec<u32>,
}

impl<R: Elem> Gather<R> {
    pub(super) fn new() -> Box<Gather<R>> {
        Box::new(Gather {
            slots: [0; LANES],
            rays: RayLanes::new(),
            found: LaneHits::new(),
            skipped: Vec::new(),
        })
    }

    /// The mailbox skips of `skipped` to count (see there), now that the
    /// gathered rays are tested; forgets them.
    pub(super) fn count_skipped(&mut self, hot: &[Hot<R>]) -> u64 {
        let n = self
            .skipped
            .iter()
            .filter(|&&s| !hot[s as usize].blocked)
            .count();
        self.skipped.clear();
        n as u64
    }
}

/// An object tested against the rays gathered for it: the object, its
/// prepared data, its id and input id, and how hits are offered.
struct ObjectTest<'a, 'o> {
    o: &'a ObjectRef<'o>,
    pr: Option<&'a Prepared>,
    prim: PrimId,
    rank: u32,
    cutouts: Option<&'a Cutouts>,
    carry: bool,
    isa: Isa,
}

impl ObjectTest<'_, '_> {
    /// Tests the object against the first `n` rays of `g.slots` and offers
    /// each ray its hit. One ray is tested alone; more go to the kind's
    /// kernel, which finds the same bits, lane by lane, as the test of one
    /// ray.
    fn run<R: Elem>(
        &self,
        g: &mut Gather<R>,
        n: usize,
        hot: &mut [Hot<R>],
        q: &[RayQ<R>],
        cold: &mut [Cold<R>],
    ) {
        let Gather {
            slots, rays, found, ..
        } = g;
        let slots = &slots[..n];
        let o = self.o;
        let mut hits = None;
        if n > 1 {
            rays.clear();
            let need = match &o.shape {
                Shape::Polygon(p) if p.vertices.len() == 3 => Need::Triangle,
                shape => Need::of(shape.kind()),
            };
            for (i, &slot) in slots.iter().enumerate() {
                let s = &hot[slot as usize];
                rays.set_q(i, &q[slot as usize], s.t_min, s.upper, need);
            }
            rays.n = n;
            let m: Lanes = if n == LANES { Lanes::MAX } else { (1 << n) - 1 };
            let rays = &*rays;
            hits = self.isa.run(ShapeLanes {
                shape: &o.shape,
                prep: self.pr,
                bbox: &o.bbox,
                rays,
                m,
                limit: &rays.t_max,
                out: found,
            });
        }
        let hits = hits.unwrap_or_else(|| {
            // One ray, or a kind without a kernel: the scalar test.
            let mut hits = 0;
            for (i, &slot) in slots.iter().enumerate() {
                let s = &hot[slot as usize];
                if let Some(t) =
                    o.shape
                        .intersect(self.pr, &o.bbox, &q[slot as usize], s.t_min, s.upper)
                {
                    found.t[i] = t;
                    hits |= 1 << i;
                }
            }
            hits
        });
        for i in each_lane(hits) {
            let slot = slots[i] as usize;
            let q = &q[slot];
            if !keeps(self.cutouts, o, q) {
                continue;
            }
            let t = found.t[i].to_f64();
            offer(
                &mut hot[slot],
                q,
                &mut cold[slot],
                t,
                self.prim,
                self.rank,
                self.carry,
                |ray| Some((o.shape.surface(ray, t), o.material)),
            );
        }
    }
}

/// A slot's ray as a placed model's tests take it: its prepared ray `q`,
/// its origin and direction in `f64`, and the interval its tests look in
/// now (up to just above its best hit).
#[inline(always)]
fn slot_ray<'q, R: Elem>(q: &'q RayQ<R>, s: &Hot<R>, c: &Cold<R>) -> Ray<'q, R> {
    let (o, d) = od64(q, c);
    Ray {
        q,
        o,
        d,
        t_min: s.t_min,
        t_max: s.upper,
    }
}

/// Whether object `o` is there where ray `q` meets it: not where an
/// alpha-mask cut-out removes it (see [`Cutouts`]).
#[inline(always)]
fn keeps<R: Elem>(cutouts: Option<&Cutouts>, o: &ObjectRef<'_>, q: &RayQ<R>) -> bool {
    cutouts.is_none_or(|c| c.keeps(&o.shape, o.material, q))
}

/// Gives ray `s` (its ray `q`, its cold part `c`) a hit at `t` on `prim`, whose object
/// has input id `rank`: a shadow ray is blocked; another keeps the hit if
/// it wins, and with `carry` the surface there (exactly what the shading
/// join would compute from the ray and this hit), which `surface` gives
/// from the ray.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn offer<R: Elem>(
    s: &mut Hot<R>,
    q: &RayQ<R>,
    c: &mut Cold<R>,
    t: f64,
    prim: PrimId,
    rank: u32,
    carry: bool,
    surface: impl FnOnce(&RayQ<f64>) -> Option<(crate::intersect::Surface, u32)>,
) {
    if s.shadow {
        s.blocked = true;
        s.best = Hit { t, prim };
    } else if s.best.loses_to_ranked(c.rank, t, prim, rank) {
        s.best = Hit { t, prim };
        c.rank = rank;
        s.upper = R::from_f64(t).next_up();
        let ray = || {
            let (o, d) = od64(q, c);
            RayQ::from_vec3(o, d)
        };
        if carry && let Some((surf, material)) = surface(&ray()) {
            c.ng = surf.ng;
            c.ns = surf.ns;
            // A surface with attributes (texture coordinates, colours)
            // is not carried: the shading join works it out again, so
            // that slots need no room for attributes.
            c.material = if surf.attrs == Attrs::NONE {
                material
            } else {
                JOIN
            };
        }
    }
}

/// Bytes the shards' pending (ray, instance) pairs and placements take.
pub(super) fn pair_bytes<R: Elem>(shards: &[Shard<R>]) -> usize {
    use std::mem::size_of;
    shards
        .iter()
        .map(|sh| {
            sh.pairs.len() * size_of::<Pair>()
                + sh.placed.len() * size_of::<(u32, u32, Placement)>()
        })
        .sum()
}

/// Reads, one at a time and in file order, the models this pass's
/// instances place, and tests each instance's rays against its model:
/// the same tests, hits and surfaces as a model held in memory gives
/// (see [`crate::models`]), and which hit is nearest does not depend on
/// the order of the tests.
pub(super) fn test_pairs<R: Elem>(
    shards: &mut [Shard<R>],
    db: &Database,
    models: &Models,
    pool: &rayon::ThreadPool,
    carry: bool,
    st: &mut IntersectStats,
) -> Result<(), Error> {
    let mut wanted: Vec<u32> = Vec::new();
    for sh in shards.iter_mut() {
        let placed = &sh.placed;
        // By model, then ray, then instance: each ray meets its
        // instances in the database's order whatever shard it is in, so
        // that counts do not depend on the number of threads.
        sh.pairs.sort_unstable_by_key(|p| {
            let (index, _, pl) = &placed[p.placed as usize];
            (pl.model, p.slot, *index)
        });
        wanted.extend(sh.placed.iter().map(|(_, _, pl)| pl.model));
    }
    wanted.sort_unstable();
    wanted.dedup();
    for m in wanted {
        let model = models.read_model(db, m as usize, &crate::progress::NoProgress)?;
        st.model_reads += 1;
        pool.install(|| {
            shards.par_iter_mut().for_each(|sh| {
                let Shard {
                    hot,
                    q,
                    cold,
                    placed,
                    pairs,
                    counts,
                    ..
                } = sh;
                let from = pairs.partition_point(|p| placed[p.placed as usize].2.model < m);
                for p in &pairs[from..] {
                    let (index, rank, pl) = &placed[p.placed as usize];
                    if pl.model != m {
                        break;
                    }
                    let slot = p.slot as usize;
                    let (s, c) = (&mut hot[slot], &mut cold[slot]);
                    if s.blocked {
                        continue;
                    }
                    let q = &q[slot];
                    let ray = slot_ray(q, s, c);
                    let found = if s.shadow {
                        model
                            .blocks(pl, ray, &mut counts.tests)
                            .then(|| (s.upper.to_f64(), PrimId::object(*index)))
                    } else {
                        model
                            .nearest(pl, ray, &mut counts.tests)
                            .map(|(t, k)| (t.to_f64(), PrimId::instance(*index, k)))
                    };
                    if let Some((t, prim)) = found {
                        offer(s, q, c, t, prim, *rank, carry, |ray| {
                            model.surface(pl, prim.instance_parts()?.1, ray, t)
                        });
                    }
                }
            })
        });
    }
    for sh in shards.iter_mut() {
        sh.pairs.clear();
        sh.placed.clear();
    }
    Ok(())
}
