//! The per-element state, structure of arrays, with both Jacobi copies.
//!
//! Per element: displacement `u` (mm, x/y/z f32) and an arrival key (u32),
//! each twice (read and write copies of a Jacobi iteration on the GPU and
//! in the frontier schedule; the CPU's block propagation and relaxation
//! work in the current copy alone), plus the
//! lattice's material byte and cut-link byte: 2 × (12 + 4) + 2 = **34
//! bytes**.
//!
//! **Arrival keys** (Algorithm 1's timestamps with Algorithm 2's wavefront
//! counters in one word): the top [`WAVE_BITS`] bits are the wave (the
//! deformation that moved the element; 0 = never reached) and the low
//! [`TIME_BITS`] the arrival time in integer quanta (sums of link times, so
//! comparisons are exact and order-independent). A newer wave always wins;
//! within a wave the earlier arrival wins ([`earlier`]).
//!
//! Values are stored as `AtomicU32` (f32 bits for displacements) so the
//! rayon kernels can write disjoint elements from several blocks at once in
//! safe code; relaxed loads and stores compile to plain moves.

use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
use voxflex_core::fresh_memory::{advise_huge_pages, zeroed_atomic_u32};

/// Bits of the arrival time.
pub const TIME_BITS: u32 = 20;
/// Bits of the wave number.
pub const WAVE_BITS: u32 = 32 - TIME_BITS;
/// Largest arrival time (longer paths saturate: the wave stops there).
pub const MAX_TIME: u32 = (1 << TIME_BITS) - 1;
/// Largest wave number before keys are renumbered ([`State::rebase`]).
pub const MAX_WAVE: u32 = (1 << WAVE_BITS) - 1;

/// Wave of a key.
#[inline]
pub fn wave(key: u32) -> u32 {
    key >> TIME_BITS
}

/// The key of wave `w` at time `t`.
#[inline]
pub fn key(w: u32, t: u32) -> u32 {
    (w << TIME_BITS) | t.min(MAX_TIME)
}

/// Arrival through a link of time `tau` from an element holding `k`
/// (`None` from an element no wave reached, or past [`MAX_TIME`]).
#[inline]
pub fn arrival(k: u32, tau: u32) -> Option<u32> {
    if k == 0 {
        return None;
    }
    let t = (k & MAX_TIME) + tau;
    (t <= MAX_TIME).then(|| key(wave(k), t))
}

/// True when arrival `a` beats key `b`: a newer wave, or the same wave
/// earlier.
#[inline]
pub fn earlier(a: u32, b: u32) -> bool {
    let (wa, wb) = (wave(a), wave(b));
    wa > wb || (wa == wb && a < b)
}

/// Both Jacobi copies of the element state.
#[derive(Debug)]
pub struct State {
    /// `u[copy][axis][element]`: displacement, mm, as f32 bits.
    pub u: [[Vec<AtomicU32>; 3]; 2],
    /// `key[copy][element]`.
    pub key: [Vec<AtomicU32>; 2],
    /// The copy holding the current state.
    pub cur: usize,
}

/// `n` zeros, in memory the kernel is asked to back with huge pages.
///
/// The kernels stream 8 to 10 arrays of several MiB at once; with 4 KiB
/// pages their neighbour rows miss the TLB on almost every window. The
/// zeros come from the allocator's zeroed memory (fresh pages for arrays
/// this large), so no page is backed before its first write: the advice,
/// given before that, makes the first writes fault the pages in huge where
/// the system allows it (`madvise` mode of transparent huge pages;
/// elsewhere it is ignored), and a copy that is never written — the second
/// copy, on the CPU's block path — costs no memory.
fn zeros(n: usize) -> Vec<AtomicU32> {
    let v = zeroed_atomic_u32(n);
    advise_huge_pages(v.as_ptr() as usize, n * 4);
    v
}

impl State {
    /// All elements at rest, never reached.
    pub fn new(n: usize) -> Self {
        Self {
            u: [0, 1].map(|_| [0, 1, 2].map(|_| zeros(n))),
            key: [zeros(n), zeros(n)],
            cur: 0,
        }
    }

    /// Displacement of element `n` in copy `c`, mm.
    #[inline]
    pub fn get(&self, c: usize, n: usize) -> [f32; 3] {
        // Written out: array `map` closures are not reliably inlined in
        // the kernels' hot loops.
        let u = &self.u[c];
        [
            f32::from_bits(u[0][n].load(Relaxed)),
            f32::from_bits(u[1][n].load(Relaxed)),
            f32::from_bits(u[2][n].load(Relaxed)),
        ]
    }

    /// Sets element `n`'s displacement in copy `c`, mm.
    #[inline]
    pub fn set(&self, c: usize, n: usize, v: [f32; 3]) {
        for (a, x) in v.into_iter().enumerate() {
            self.u[c][a][n].store(x.to_bits(), Relaxed);
        }
    }

    /// Arrival key of element `n` in copy `c`.
    #[inline]
    pub fn key(&self, c: usize, n: usize) -> u32 {
        self.key[c][n].load(Relaxed)
    }

    /// Sets element `n`'s key in copy `c`.
    #[inline]
    pub fn set_key(&self, c: usize, n: usize, k: u32) {
        self.key[c][n].store(k, Relaxed);
    }

    /// Sets both copies of element `n`.
    #[inline]
    pub fn set_both(&self, n: usize, v: [f32; 3], k: u32) {
        for c in 0..2 {
            self.set(c, n, v);
            self.set_key(c, n, k);
        }
    }

    /// Copies element `n` from copy `from` to the other.
    #[inline]
    pub fn carry(&self, from: usize, n: usize) {
        self.copy_u(from, n);
        self.key[1 - from][n].store(self.key[from][n].load(Relaxed), Relaxed);
    }

    /// Copies element `n`'s displacement from copy `from` to the other.
    #[inline]
    pub fn copy_u(&self, from: usize, n: usize) {
        let to = 1 - from;
        for a in 0..3 {
            self.u[to][a][n].store(self.u[from][a][n].load(Relaxed), Relaxed);
        }
    }

    /// Renumbers the waves so that the newest `keep` stay distinct and older
    /// ones become "never reached" (converged long ago: nothing left to
    /// propagate). Returns the new current wave.
    pub fn rebase(&mut self, current: u32, keep: u32) -> u32 {
        let shift = current.saturating_sub(keep);
        for c in 0..2 {
            for k in &mut self.key[c] {
                let v = *k.get_mut();
                let w = wave(v);
                *k.get_mut() = if w > shift {
                    key(w - shift, v & MAX_TIME)
                } else {
                    0
                };
            }
        }
        current - shift
    }

    /// Bytes held in the state's arrays (both copies).
    pub fn bytes(&self) -> usize {
        let words: usize = self.u.iter().flatten().chain(&self.key).map(Vec::len).sum();
        words * std::mem::size_of::<AtomicU32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_order_by_wave_then_time() {
        assert!(earlier(key(2, 900), key(1, 3)));
        assert!(earlier(key(1, 3), key(1, 4)));
        assert!(!earlier(key(1, 4), key(1, 4)));
        assert!(earlier(key(1, 0), 0));
        assert_eq!(arrival(0, 5), None);
        assert_eq!(arrival(key(3, 10), 5), Some(key(3, 15)));
        assert_eq!(arrival(key(3, MAX_TIME - 1), 5), None);
    }

    #[test]
    fn rebase_keeps_recent_waves_in_order() {
        let mut s = State::new(3);
        s.set_key(0, 0, key(100, 7));
        s.set_key(0, 1, key(97, 9));
        s.set_key(0, 2, key(50, 1));
        let w = s.rebase(100, 4);
        assert_eq!(w, 4);
        assert_eq!(s.key(0, 0), key(4, 7));
        assert_eq!(s.key(0, 1), key(1, 9));
        assert_eq!(s.key(0, 2), 0);
    }
}
