//! Sparse scheduling: the lattice split into blocks (e.g. 16×4×4 elements)
//! and the list of active blocks that one launch processes.
//!
//! After an iteration, a block that changed stays active and activates the
//! face neighbours across the faces where one of its border elements
//! changed (the Comput. Biol. Med. paper's neighbour-border activation), so
//! the next iteration visits only blocks a change can reach.

/// Block geometry over the element lattice (element indices).
#[derive(Clone, Copy, Debug)]
pub struct Blocks {
    /// Elements per block along each axis.
    pub size: [usize; 3],
    /// Blocks along each axis.
    pub count: [usize; 3],
    /// Elements along each axis.
    pub dims: [usize; 3],
}

/// A change on the −x, +x, −y, +y, −z, +z border of a block (bits 0–5), or
/// anywhere in it (bit 6).
pub type FaceMask = u8;
/// Bit of [`FaceMask`]: something in the block changed.
pub const CHANGED: FaceMask = 1 << 6;

impl Blocks {
    /// Blocks of `size` over a lattice of `dims` elements.
    pub fn new(dims: [usize; 3], size: [usize; 3]) -> Self {
        Self {
            size,
            count: [0, 1, 2].map(|a| dims[a].div_ceil(size[a])),
            dims,
        }
    }

    /// Number of blocks.
    pub fn len(&self) -> usize {
        self.count[0] * self.count[1] * self.count[2]
    }

    /// True when there is no block.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Block holding element `[i, j, k]`.
    #[inline]
    pub fn of(&self, c: [usize; 3]) -> usize {
        let b = [0, 1, 2].map(|a| c[a] / self.size[a]);
        b[0] + self.count[0] * (b[1] + self.count[1] * b[2])
    }

    /// Element range `[lo, hi)` of block `b`.
    #[inline]
    pub fn range(&self, b: usize) -> ([usize; 3], [usize; 3]) {
        let c = [
            b % self.count[0],
            (b / self.count[0]) % self.count[1],
            b / (self.count[0] * self.count[1]),
        ];
        let lo = [0, 1, 2].map(|a| c[a] * self.size[a]);
        let hi = [0, 1, 2].map(|a| (lo[a] + self.size[a]).min(self.dims[a]));
        (lo, hi)
    }

    /// Face mask bit of element `[i, j, k]` of a block `[lo, hi)` (border
    /// faces it lies on).
    #[inline]
    pub fn border(c: [usize; 3], lo: [usize; 3], hi: [usize; 3]) -> FaceMask {
        let mut m = 0;
        for a in 0..3 {
            if c[a] == lo[a] {
                m |= 1 << (2 * a);
            }
            if c[a] + 1 == hi[a] {
                m |= 1 << (2 * a + 1);
            }
        }
        m
    }

    /// Where propagation from a move imposed on element `c` (a grab) must
    /// start: its block and the blocks across the block borders `c` lies
    /// on. A block whose only moved elements are held never reports a
    /// change of its own, so seeding it alone would leave the neighbours
    /// that the held element pulls idle.
    pub fn seeds(&self, c: [usize; 3]) -> Vec<usize> {
        let b = self.of(c);
        let (lo, hi) = self.range(b);
        let m = Self::border(c, lo, hi);
        let [cx, cy, cz] = self.count;
        let bc = [b % cx, (b / cx) % cy, b / (cx * cy)];
        let mut out = vec![b];
        for a in 0..3 {
            let stride = [1, cx, cx * cy][a];
            if m & (1 << (2 * a)) != 0 && bc[a] > 0 {
                out.push(b - stride);
            }
            if m & (1 << (2 * a + 1)) != 0 && bc[a] + 1 < [cx, cy, cz][a] {
                out.push(b + stride);
            }
        }
        out
    }

    /// The next active list from this iteration's `(block, mask)` results:
    /// changed blocks and their neighbours across changed borders, each
    /// once, in ascending order. `seen` is scratch of [`Self::len`] flags.
    pub fn next_active(&self, results: &[(u32, FaceMask)], seen: &mut [bool]) -> Vec<u32> {
        let mut out = Vec::new();
        let mut push = |b: usize, out: &mut Vec<u32>| {
            if !seen[b] {
                seen[b] = true;
                out.push(b as u32);
            }
        };
        let [cx, cy, cz] = self.count;
        for &(b, m) in results {
            if m & CHANGED == 0 {
                continue;
            }
            let b = b as usize;
            push(b, &mut out);
            let c = [b % cx, (b / cx) % cy, b / (cx * cy)];
            for a in 0..3 {
                let stride = [1, cx, cx * cy][a];
                if m & (1 << (2 * a)) != 0 && c[a] > 0 {
                    push(b - stride, &mut out);
                }
                if m & (1 << (2 * a + 1)) != 0 && c[a] + 1 < [cx, cy, cz][a] {
                    push(b + stride, &mut out);
                }
            }
        }
        if out.len() * 32 >= seen.len() {
            // Dense: reading the flags in order is cheaper than sorting.
            out.clear();
            for (b, s) in seen.iter_mut().enumerate() {
                if std::mem::take(s) {
                    out.push(b as u32);
                }
            }
        } else {
            for &b in &out {
                seen[b as usize] = false;
            }
            out.sort_unstable();
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_cover_the_lattice_and_activation_follows_borders() {
        let b = Blocks::new([10, 5, 3], [4, 4, 2]);
        assert_eq!(b.count, [3, 2, 2]);
        let total: usize = (0..b.len())
            .map(|i| {
                let (lo, hi) = b.range(i);
                (0..3).map(|a| hi[a] - lo[a]).product::<usize>()
            })
            .sum();
        assert_eq!(total, 150);
        assert_eq!(b.of([9, 4, 2]), b.len() - 1);
        let mut seen = vec![false; b.len()];
        // Block 0 changed on its +x border only.
        let next = b.next_active(&[(0, CHANGED | 0b10)], &mut seen);
        assert_eq!(next, vec![0, 1]);
        assert!(seen.iter().all(|s| !s));
        // Unchanged blocks activate nothing.
        assert!(b.next_active(&[(4, 0b11_1111)], &mut seen).is_empty());
    }

    #[test]
    fn sparse_and_dense_activation_lists_are_ascending_and_complete() {
        let b = Blocks::new([64, 64, 64], [4, 4, 4]);
        let mut seen = vec![false; b.len()];
        for every in [1000, 7, 2] {
            // Every `every`-th block changed, with varying borders.
            let results: Vec<(u32, FaceMask)> = (0..b.len() as u32)
                .step_by(every)
                .map(|x| (x, CHANGED | (x % 64) as FaceMask))
                .collect();
            let mut expected = std::collections::BTreeSet::new();
            for &(x, m) in &results {
                let x = x as usize;
                let c = [x % 16, (x / 16) % 16, x / 256];
                expected.insert(x);
                for a in 0..3 {
                    let stride = [1, 16, 256][a];
                    if m & (1 << (2 * a)) != 0 && c[a] > 0 {
                        expected.insert(x - stride);
                    }
                    if m & (1 << (2 * a + 1)) != 0 && c[a] < 15 {
                        expected.insert(x + stride);
                    }
                }
            }
            let next = b.next_active(&results, &mut seen);
            let expected: Vec<u32> = expected.into_iter().map(|x| x as u32).collect();
            assert_eq!(next, expected, "every {every}th block");
            assert!(seen.iter().all(|s| !s));
        }
    }
}
