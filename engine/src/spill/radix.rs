//! Stable least-significant-digit radix sort of records by an integer key:
//! linear in the number of records, which comparison sorts are not, and
//! keys of dense ids (ray ids, object ids) need few digits.

const BITS: u32 = 11;
const BUCKETS: usize = 1 << BITS;

/// Working memory of the sort, kept between calls so that sorting
/// allocates nothing once warm.
#[derive(Default)]
pub struct Scratch {
    keys: Vec<u64>,
    keys2: Vec<u64>,
    idx: Vec<u32>,
    idx2: Vec<u32>,
}

impl Scratch {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        8 * (self.keys.capacity() + self.keys2.capacity())
            + 4 * (self.idx.capacity() + self.idx2.capacity())
    }
}

/// Sorts `v` by `key`, keeping the order of equal keys.
pub fn sort_by_key<T: Copy>(v: &mut [T], key: impl Fn(&T) -> u64, sc: &mut Scratch) {
    let n = v.len();
    if n < 2 {
        return;
    }
    sc.keys.clear();
    sc.keys.extend(v.iter().map(&key));
    if sc.keys.windows(2).all(|w| w[0] <= w[1]) {
        return;
    }
    let max = sc.keys.iter().copied().max().unwrap_or(0);
    let bits = 64 - max.leading_zeros();
    sc.idx.clear();
    sc.idx.extend(0..n as u32);
    sc.keys2.resize(n, 0);
    sc.idx2.resize(n, 0);
    let mut shift = 0;
    while shift < bits {
        let mut count = [0usize; BUCKETS + 1];
        for k in &sc.keys {
            count[((k >> shift) as usize & (BUCKETS - 1)) + 1] += 1;
        }
        for b in 0..BUCKETS {
            count[b + 1] += count[b];
        }
        for i in 0..n {
            let k = sc.keys[i];
            let b = (k >> shift) as usize & (BUCKETS - 1);
            let at = count[b];
            count[b] += 1;
            sc.keys2[at] = k;
            sc.idx2[at] = sc.idx[i];
        }
        std::mem::swap(&mut sc.keys, &mut sc.keys2);
        std::mem::swap(&mut sc.idx, &mut sc.idx2);
        shift += BITS;
    }
    permute(v, &mut sc.idx);
}

/// Rearranges `v` so that `v[i]` becomes the old `v[from[i]]`, following
/// the permutation's cycles (no second copy of the records).
fn permute<T: Copy>(v: &mut [T], from: &mut [u32]) {
    const DONE: u32 = u32::MAX;
    for start in 0..v.len() {
        if from[start] == DONE {
            continue;
        }
        let first = v[start];
        let mut i = start;
        loop {
            let j = from[i] as usize;
            from[i] = DONE;
            if j == start {
                v[i] = first;
                break;
            }
            v[i] = v[j];
            i = j;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_stably() {
        let mut state = 99u64;
        let mut v: Vec<(u64, u32)> = (0..5000)
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                ((state >> 40) % 300, i)
            })
            .collect();
        let mut expect = v.clone();
        expect.sort_by_key(|x| x.0); // stable
        let mut sc = Scratch::default();
        sort_by_key(&mut v, |x| x.0, &mut sc);
        assert_eq!(v, expect);
        let mut big: Vec<u64> = (0..3000).map(|i| (i * 7919) % 3001 * (1 << 40)).collect();
        let mut e = big.clone();
        e.sort();
        sort_by_key(&mut big, |x| *x, &mut sc);
        assert_eq!(big, e);
    }
}
