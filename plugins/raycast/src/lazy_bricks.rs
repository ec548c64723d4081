//! [`LazyBricks`]: per-brick data of a volume, built on first use by the
//! rendering threads and dropped where the volume changes.
//!
//! A brick is `EDGE³` *cells* (a cell = a trilinear footprint, named by its
//! lower corner voxel `i`, `0 ≤ i ≤ max(n, 2) − 2` per axis), so brick `b`
//! holds the cells `EDGE·b ..= EDGE·b + EDGE − 1`. What a brick stores is
//! up to its user — the Sobel gradients of its corners
//! ([`crate::gradient_cache`]), which of its cells the transfer function
//! may show ([`crate::visible_cells`]), both with `EDGE` 8 — and so is how
//! far beyond its cells it reads (its *reach*, which decides what a change
//! of the volume drops). Indices are voxel indices, x fastest.
//!
//! **Memory.** Only a few bricks of a volume are ever built (a bone
//! transfer function on a head CT builds one gradient brick in fifteen),
//! and in a fresh process every byte written for the first time is a page
//! fault. So a brick's slot is one `u32`, zero when unbuilt, allocated
//! zeroed (the kernel maps untouched pages lazily, so slots nobody reaches
//! cost nothing), and the built bricks sit packed in one pool, handed out
//! in order (a page holds whole bricks, not one malloc'd brick and its
//! neighbour's header), whose pages are mapped one chunk ahead of the
//! bricks written into them (`fresh_memory::populate_ahead`). The pool's
//! capacity is the user's budget; a brick past it is marked over budget
//! and its cells are left to the caller. Places freed by
//! [`LazyBricks::invalidate`] are handed out again first.

use crate::macrocell::IndexBox;
use std::cell::UnsafeCell;
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use voxflex_core::fresh_memory::{populate_ahead, zeroed_atomic_u32};

/// Cells per brick edge of the visible cells (and of the macro cells they
/// narrow).
pub const BRICK: usize = 8;

/// A slot no brick was built for.
const UNBUILT: u32 = 0;
const _: () = assert!(UNBUILT == 0, "slots start from zeroed memory");
/// A slot whose brick a thread is building.
const BUILDING: u32 = 1;
/// A slot whose brick found the pool full.
const OVER_BUDGET: u32 = u32::MAX;
/// Slot values from here on are `FIRST_PLACE + place in the pool`.
const FIRST_PLACE: u32 = 2;

/// Voxels a brick reads beyond its cells' corners: `before` below voxel
/// `EDGE·b` and `after` above voxel `EDGE·b + EDGE`, on every axis.
#[derive(Clone, Copy, Debug)]
pub struct Reach {
    /// Voxels read below the brick's first corner.
    pub before: usize,
    /// Voxels read above the brick's last corner.
    pub after: usize,
}

/// One lazily built `T` per brick of `EDGE³` cells of a volume of `dims`
/// voxels, at most `capacity` of them at a time.
pub struct LazyBricks<T: Copy, const EDGE: usize> {
    dims: [usize; 3],
    counts: [usize; 3],
    /// Per brick (x fastest): [`UNBUILT`], [`BUILDING`], [`OVER_BUDGET`]
    /// or [`FIRST_PLACE`] + its place in `pool`.
    slots: Box<[AtomicU32]>,
    /// The built bricks. A place is written once, by the one thread that
    /// took it, before its slot publishes it (release); read only through
    /// a slot that names it (acquire).
    pool: Box<[UnsafeCell<MaybeUninit<T>>]>,
    /// Places freed by `invalidate`, handed out before fresh ones.
    free: Vec<u32>,
    /// Fresh places handed out before the current `taken` count.
    used: usize,
    /// Places taken since the last `invalidate` (free ones first).
    taken: AtomicUsize,
}

// SAFETY: the pool's cells are written only by the thread that took their
// place (`take_place` hands each out once) and read only after the slot
// naming them was published with release ordering and read with acquire;
// `T: Send + Sync` covers moving and sharing the values themselves.
unsafe impl<T: Copy + Send + Sync, const EDGE: usize> Sync for LazyBricks<T, EDGE> {}

/// Where a cell sits: its brick's slot, the brick, and the cell's index
/// inside the brick (each `0..EDGE`).
#[derive(Clone, Copy, Debug)]
pub struct CellPlace {
    /// Linear index of the brick (x fastest).
    pub slot: usize,
    /// Brick index per axis.
    pub brick: [usize; 3],
    /// The cell's index inside its brick per axis.
    pub local: [usize; 3],
}

impl<T: Copy + Send + Sync, const EDGE: usize> LazyBricks<T, EDGE> {
    /// No brick built yet, for a volume of `dims` voxels; at most
    /// `capacity` bricks built at a time (more than the volume has is
    /// clamped).
    pub fn new(dims: [usize; 3], capacity: usize) -> Self {
        let counts = dims.map(|n| (n.max(2) - 1).div_ceil(EDGE));
        let n = counts.iter().product::<usize>();
        Self {
            dims,
            counts,
            slots: zeroed_atomic_u32(n).into_boxed_slice(),
            // Every place must be nameable by a slot value.
            pool: uninit_pool(capacity.min(n).min((OVER_BUDGET - FIRST_PLACE) as usize)),
            free: Vec::new(),
            used: 0,
            taken: AtomicUsize::new(0),
        }
    }

    /// The volume size (voxels).
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Bricks per axis.
    pub fn counts(&self) -> [usize; 3] {
        self.counts
    }

    /// Bricks built (or being built) now, at most the capacity.
    pub fn built(&self) -> usize {
        let taken = self.taken.load(Ordering::Relaxed);
        let open = self.free.len() + (self.pool.len() - self.used);
        self.used - self.free.len() + taken.min(open)
    }

    /// The brick of the cell whose lower corner is voxel `i`.
    #[inline(always)]
    pub fn place(&self, i: [usize; 3]) -> CellPlace {
        let brick = [i[0] / EDGE, i[1] / EDGE, i[2] / EDGE];
        CellPlace {
            slot: self.slot_of(brick),
            brick,
            local: [
                i[0] - brick[0] * EDGE,
                i[1] - brick[1] * EDGE,
                i[2] - brick[2] * EDGE,
            ],
        }
    }

    /// The slot of brick `b` (x fastest).
    #[inline(always)]
    fn slot_of(&self, b: [usize; 3]) -> usize {
        b[0] + self.counts[0] * (b[1] + self.counts[1] * b[2])
    }

    /// The brick at `place`, built by `build(brick)` if it is not yet;
    /// `None` when the pool was full when it was first asked for.
    #[inline(always)]
    pub fn get_or_build(
        &self,
        place: &CellPlace,
        build: impl FnOnce([usize; 3]) -> T,
    ) -> Option<&T> {
        let slot = &self.slots[place.slot];
        match slot.load(Ordering::Acquire) {
            s if names_place(s) => Some(self.read(s)),
            s => self.build_slow(slot, s, place.brick, build),
        }
    }

    #[cold]
    fn build_slow(
        &self,
        slot: &AtomicU32,
        mut s: u32,
        brick: [usize; 3],
        build: impl FnOnce([usize; 3]) -> T,
    ) -> Option<&T> {
        if s == UNBUILT {
            match slot.compare_exchange(UNBUILT, BUILDING, Ordering::Acquire, Ordering::Acquire) {
                Ok(_) => {
                    let unwinding = ResetOnUnwind(slot);
                    let published = match self.take_place() {
                        Some(place) => {
                            // SAFETY: `take_place` handed `place` to this
                            // thread alone and no slot names it yet.
                            unsafe { (*self.pool[place].get()).write(build(brick)) };
                            FIRST_PLACE + place as u32
                        }
                        None => OVER_BUDGET,
                    };
                    std::mem::forget(unwinding);
                    slot.store(published, Ordering::Release);
                    s = published;
                }
                Err(now) => s = now,
            }
        }
        let mut spins = 0u32;
        while s == BUILDING {
            // Another thread builds it: microseconds.
            spins += 1;
            if spins < 64 {
                std::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
            s = slot.load(Ordering::Acquire);
        }
        (s != OVER_BUDGET).then(|| self.read(s))
    }

    /// The brick a slot value names.
    #[inline(always)]
    fn read(&self, s: u32) -> &T {
        // SAFETY: a slot names a place only after its brick was written
        // (release store, paired with the caller's acquire load), and the
        // place is not written again before `invalidate` (`&mut self`).
        unsafe { (*self.pool[(s - FIRST_PLACE) as usize].get()).assume_init_ref() }
    }

    /// A pool place for a new brick: a freed one first, then a fresh one;
    /// `None` when the pool is full.
    fn take_place(&self) -> Option<usize> {
        let k = self.taken.fetch_add(1, Ordering::Relaxed);
        match self.free.get(k) {
            Some(&p) => Some(p as usize),
            None => {
                let p = self.used + (k - self.free.len());
                (p < self.pool.len()).then(|| {
                    // Fresh places are handed out in order.
                    let size = std::mem::size_of::<T>();
                    let pool = self.pool.as_ptr() as usize;
                    populate_ahead(pool, self.pool.len() * size, p * size, (p + 1) * size);
                    p
                })
            }
        }
    }

    /// Drops every brick that reads a voxel of `region` (its place is
    /// handed out again), and forgets which bricks were over budget there.
    pub fn invalidate(&mut self, region: IndexBox, reach: Reach) {
        self.settle();
        let range = |a: usize| {
            // Brick b reads voxels EDGE·b − before ..= EDGE·b + EDGE + after.
            let lo = region.lo[a]
                .saturating_sub(EDGE + reach.after)
                .div_ceil(EDGE);
            let hi = ((region.hi[a] + reach.before) / EDGE).min(self.counts[a] - 1);
            lo..=hi
        };
        for bz in range(2) {
            for by in range(1) {
                for bx in range(0) {
                    let slot = self.slots[self.slot_of([bx, by, bz])].get_mut();
                    if names_place(*slot) {
                        self.free.push(*slot - FIRST_PLACE);
                    }
                    *slot = UNBUILT;
                }
            }
        }
    }

    /// Folds the places taken since the last call into `free` and `used`.
    fn settle(&mut self) {
        let taken = std::mem::take(self.taken.get_mut());
        let from_free = taken.min(self.free.len());
        self.free.drain(..from_free);
        self.used = (self.used + (taken - from_free)).min(self.pool.len());
    }
}

/// Whether slot value `s` names a built brick's place in the pool.
#[inline(always)]
fn names_place(s: u32) -> bool {
    (FIRST_PLACE..OVER_BUDGET).contains(&s)
}

/// Puts a slot back to [`UNBUILT`] when its builder unwinds (a panic in
/// `build`), so that no other thread waits for that brick forever; the
/// place it took stays unused until the next `invalidate`.
struct ResetOnUnwind<'a>(&'a AtomicU32);

impl Drop for ResetOnUnwind<'_> {
    fn drop(&mut self) {
        self.0.store(UNBUILT, Ordering::Release);
    }
}

/// `n` uninitialised places: allocated, not one byte written (or faulted
/// in) — in a debug build too, where building it element by element would
/// write every page.
///
/// Where the system refuses that much address space (a budget of gigabytes
/// on a small machine), fewer: the bricks past them are over budget.
fn uninit_pool<T>(n: usize) -> Box<[UnsafeCell<MaybeUninit<T>>]> {
    let mut pool = Vec::new();
    let mut n = n;
    while n > 0 && pool.try_reserve_exact(n).is_err() {
        n /= 2;
    }
    // SAFETY: `UnsafeCell<MaybeUninit<T>>` is valid uninitialised, and the
    // capacity holds at least `n` of them.
    unsafe { pool.set_len(n) };
    pool.into_boxed_slice()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;
    use std::sync::atomic::AtomicUsize;

    /// Builds every brick of `bricks` (each holds its own index), counting
    /// the builds.
    fn fill<const E: usize>(bricks: &LazyBricks<[usize; 3], E>, builds: &AtomicUsize) {
        let [nx, ny, nz] = bricks.counts();
        for bz in 0..nz {
            for by in 0..ny {
                for bx in 0..nx {
                    let p = bricks.place([E * bx, E * by, E * bz]);
                    bricks.get_or_build(&p, |b| {
                        builds.fetch_add(1, Ordering::Relaxed);
                        b
                    });
                }
            }
        }
    }

    /// A region drops exactly the bricks whose read span (cells plus reach)
    /// holds one of its voxels, with and without a reach: those, and only
    /// those, are built again, into the places they freed.
    #[test]
    fn invalidation_drops_exactly_the_bricks_that_read_the_region() {
        let dims = [33, 26, 20];
        for reach in [
            Reach {
                before: 0,
                after: 0,
            },
            Reach {
                before: 1,
                after: 1,
            },
        ] {
            for x in [0, 7, 8, 9, 10, 16, 17, 31, 32] {
                let mut bricks = LazyBricks::<[usize; 3], 8>::new(dims, usize::MAX);
                let builds = AtomicUsize::new(0);
                fill(&bricks, &builds);
                let all = bricks.built();
                assert_eq!(all, bricks.counts().iter().product::<usize>());
                let region = IndexBox {
                    lo: [x, 12, 4],
                    hi: [x, 12, 4],
                };
                bricks.invalidate(region, reach);
                let reads =
                    |v: usize, b: usize| 8 * b <= v + reach.before && v <= 8 * b + 8 + reach.after;
                let [nx, ny, nz] = bricks.counts();
                let mut dropped = 0;
                for bz in 0..nz {
                    for by in 0..ny {
                        for bx in 0..nx {
                            let want = reads(x, bx) && reads(12, by) && reads(4, bz);
                            dropped += usize::from(want);
                            let p = bricks.place([8 * bx, 8 * by, 8 * bz]);
                            let mut rebuilt = false;
                            let got = bricks.get_or_build(&p, |b| {
                                rebuilt = true;
                                b
                            });
                            assert_eq!(got, Some(&[bx, by, bz]));
                            assert_eq!(rebuilt, want, "{reach:?} x = {x}, brick {bx} {by} {bz}");
                        }
                    }
                }
                assert!(dropped > 0);
                // The rebuilt bricks reused the freed places: the pool grew
                // by none.
                bricks.settle();
                assert_eq!((bricks.used, bricks.free.len()), (all, 0));
            }
        }
    }

    /// Past the capacity a brick is over budget (not built, `None`) until
    /// a change of the volume reaches it; freed places are handed out
    /// again.
    #[test]
    fn bricks_past_the_capacity_are_over_budget_until_invalidated() {
        let mut bricks = LazyBricks::<u32, 4>::new([17, 5, 5], 2);
        assert_eq!(bricks.counts(), [4, 1, 1]);
        // Brick x along the row, built as `v` if it is not yet.
        let get = |bricks: &LazyBricks<u32, 4>, x: usize, v: u32| {
            bricks
                .get_or_build(&bricks.place([4 * x, 0, 0]), |_| v)
                .copied()
        };
        let voxel = |x: usize| IndexBox {
            lo: [x, 0, 0],
            hi: [x, 0, 0],
        };
        let no_reach = Reach {
            before: 0,
            after: 0,
        };
        assert_eq!(get(&bricks, 0, 10), Some(10));
        assert_eq!(get(&bricks, 1, 11), Some(11));
        assert_eq!(get(&bricks, 2, 12), None);
        assert_eq!(get(&bricks, 2, 12), None, "stays over budget");
        assert_eq!(bricks.built(), 2);
        // Dropping brick 0 (voxel 1 is read by brick 0 alone) frees a place
        // for brick 3, which was never asked for, but not for brick 2.
        bricks.invalidate(voxel(1), no_reach);
        assert_eq!(bricks.built(), 1);
        assert_eq!(get(&bricks, 2, 12), None);
        assert_eq!(get(&bricks, 3, 13), Some(13));
        assert_eq!(get(&bricks, 0, 20), None, "the pool is full again");
        assert_eq!(get(&bricks, 1, 21), Some(11));
        // A change reaching brick 2 (voxel 9) lets it try again: the pool
        // still holds bricks 1 and 3, so it is over budget once more.
        bricks.invalidate(voxel(9), no_reach);
        assert_eq!(get(&bricks, 2, 22), None);
        // A change reaching brick 1 (voxel 5) rebuilds it into its place.
        bricks.invalidate(voxel(5), no_reach);
        assert_eq!(bricks.built(), 1);
        assert_eq!(get(&bricks, 1, 31), Some(31));
        assert_eq!(bricks.built(), 2);
        // A change everywhere empties the pool.
        bricks.invalidate(IndexBox::all([17, 5, 5]), no_reach);
        assert_eq!(bricks.built(), 0);
        assert_eq!(get(&bricks, 2, 42), Some(42));
        assert_eq!(get(&bricks, 0, 40), Some(40));
        assert_eq!(get(&bricks, 3, 43), None);
    }

    /// Threads asking for the same unbuilt bricks at once: each brick is
    /// built once and every thread reads that one value.
    #[test]
    fn concurrent_requests_build_each_brick_once() {
        let bricks = LazyBricks::<[u64; 16], 2>::new([9, 9, 9], usize::MAX);
        let builds = AtomicUsize::new(0);
        let seen: Vec<u64> = (0..20_000usize)
            .into_par_iter()
            .map(|k| {
                let p = bricks.place([k % 8, k / 8 % 8, k / 64 % 8]);
                bricks
                    .get_or_build(&p, |b| {
                        builds.fetch_add(1, Ordering::Relaxed);
                        std::thread::yield_now();
                        [(b[0] + 10 * b[1] + 100 * b[2]) as u64; 16]
                    })
                    .expect("within capacity")[15]
            })
            .collect();
        assert_eq!(builds.load(Ordering::Relaxed), 64);
        for (k, v) in seen.iter().enumerate() {
            let b = [k % 8 / 2, k / 8 % 8 / 2, k / 64 % 8 / 2];
            assert_eq!(*v, (b[0] + 10 * b[1] + 100 * b[2]) as u64);
        }
    }

    /// A build that panics leaves its brick unbuilt, not "being built":
    /// the next request builds it.
    #[test]
    fn a_panicking_build_leaves_the_brick_to_the_next_request() {
        let bricks = LazyBricks::<u32, 8>::new([33, 9, 9], usize::MAX);
        let p = bricks.place([0, 0, 0]);
        let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            bricks.get_or_build(&p, |_| panic!("build failed"));
        }));
        assert!(panicked.is_err());
        let again = std::thread::scope(|s| {
            s.spawn(|| bricks.get_or_build(&p, |_| 7).copied())
                .join()
                .unwrap()
        });
        assert_eq!(again, Some(7));
    }

    #[test]
    fn places_name_the_brick_and_the_cell_inside_it() {
        let bricks = LazyBricks::<(), 8>::new([20, 9, 1], 0);
        assert_eq!(bricks.counts(), [3, 1, 1]);
        let p = bricks.place([17, 7, 0]);
        assert_eq!((p.slot, p.brick, p.local), (2, [2, 0, 0], [1, 7, 0]));
        let fine = LazyBricks::<(), 4>::new([20, 9, 1], 0);
        assert_eq!(fine.counts(), [5, 2, 1]);
        let p = fine.place([17, 7, 0]);
        assert_eq!((p.slot, p.brick, p.local), (4 + 5, [4, 1, 0], [1, 3, 0]));
    }
}
