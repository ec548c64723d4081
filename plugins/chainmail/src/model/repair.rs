//! Repair waves: the links a settled wave left violated between two free
//! elements.
//!
//! An element takes the move of its earliest violated neighbour, and a
//! later arrival moves it only when strictly earlier than its key. Arrival
//! times are whole ticks (`τ` rounded from the link's slack), so in a
//! heterogeneous lattice two paths can tie or swap order against their
//! exact slacks, and a wave can settle with a link violated that nothing
//! pins: the `propagation_restores_every_constraint` property test found
//! 0.05 mm on a 9 × 8 × 7 lattice of three materials after a second grab
//! (two elements keyed 70 and 88 ticks, the link's τ 18: a tie). When the
//! wave has settled, the model starts a new wave from the end of each such
//! link that was reached first, with its displacement unchanged: the other
//! end and whatever it drags then follow, as in any wave. Violations with a
//! fixed or held end are conflicts ([`crate::conflicts`]), reported, not
//! repaired.

use super::ChainMail;
use crate::conflicts;
use crate::params::Algorithm;

/// Repair waves one deformation (a frame's grab moves) may start: each
/// settles the links the previous one left; in the property tests one
/// suffices, the cap bounds the cost when violations keep reappearing.
pub(super) const MAX_REPAIR_WAVES: u32 = 8;

impl ChainMail {
    /// When propagation has settled with a link violated between two free
    /// elements, starts a repair wave from the later-moved ends and returns
    /// true; returns false when every such link holds, the cap
    /// [`MAX_REPAIR_WAVES`] is spent, or the algorithm is the sequential
    /// baseline (Gibson's, kept as published).
    pub(super) fn start_repair_wave(&mut self) -> bool {
        if self.repairs_left == 0 || self.params.algorithm != Algorithm::Parallel {
            return false;
        }
        self.repairs_left -= 1;
        if let Err(e) = self.pull() {
            self.gpu_error.get_or_insert(e);
            return false;
        }
        let tol_mm = (conflicts::TOLERANCE * self.lat.smallest_spacing()) as f32;
        self.conflicts
            .check(&self.lat, &self.state, &self.blocks, tol_mm);
        let seeds: Vec<(usize, [f32; 3])> = self
            .conflicts
            .repair_seeds(&self.lat, &self.state, &self.blocks, tol_mm)
            .into_iter()
            .map(|n| (n as usize, self.state.get(self.state.cur, n as usize)))
            .collect();
        if seeds.is_empty() {
            self.repairs_left = 0;
            return false;
        }
        tracing::debug!(seeds = seeds.len(), "chainmail: repair wave");
        self.counts.repair_waves += 1;
        self.start_wave(&seeds);
        true
    }
}
