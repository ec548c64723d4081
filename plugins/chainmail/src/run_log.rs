//! What a run of frames did, for the model's notes (`metrics.json`): cost
//! per frame, when the model came to rest, and the conflicting constraints
//! ([`crate::conflicts`]) it met.

use crate::conflicts::{FIXED_END, HELD_END, RIGID_END, Violation};
use crate::model::FrameStats;
use voxflex_core::deformation::ModelNotes;

/// Frames of [`crate::model::ChainMail::step`] so far.
#[derive(Clone, Debug, Default)]
pub struct RunLog {
    /// Frames stepped.
    pub frames: u64,
    /// The frame (1-based) from which the model has stayed at rest: that
    /// frame reported no change and left no propagation or relaxation work.
    /// `None` while work is pending.
    pub rest_frame: Option<u64>,
    /// Wall time of every frame, ms.
    ms: Vec<f32>,
    /// Most blocks one frame's relaxation visited (summed over its sweeps).
    pub max_relaxation_blocks: u64,
    /// The worst conflict measured, and the frame it was measured after.
    pub worst: Option<(Violation, u64)>,
    /// Frames after which a conflict was measured.
    pub conflict_frames: u64,
    /// The violation (mm) last warned about.
    pub last_warned_mm: f32,
}

impl RunLog {
    /// Records one frame; `at_rest` when it left no work pending.
    pub fn frame(&mut self, s: &FrameStats, at_rest: bool) {
        self.frames += 1;
        self.ms.push(s.ms as f32);
        self.max_relaxation_blocks = self.max_relaxation_blocks.max(s.relaxation_blocks);
        if at_rest && !s.changed {
            self.rest_frame.get_or_insert(self.frames);
        } else {
            self.rest_frame = None;
        }
    }

    /// Records a conflict check after the current frame.
    pub fn conflict(&mut self, v: Violation) {
        if v.count == 0 {
            return;
        }
        self.conflict_frames += 1;
        if self.worst.is_none_or(|(w, _)| v.mm > w.mm) {
            self.worst = Some((v, self.frames));
        }
    }

    /// Mean wall time (ms) of the frames in `range` (0-based, clipped).
    pub fn mean_ms(&self, range: std::ops::Range<usize>) -> f64 {
        let r = range.start.min(self.ms.len())..range.end.min(self.ms.len());
        let n = r.len().max(1) as f64;
        self.ms[r].iter().map(|&x| x as f64).sum::<f64>() / n
    }

    /// The notes: `frames`, `at_rest` (1/0), `rest_frame` (only at rest),
    /// `ms_per_frame_first10` / `_last10` / `_max`,
    /// `relaxation_blocks_per_frame_max`, and the conflicts:
    /// `max_constraint_violation_mm` (0 when none), `conflicting_constraints`
    /// (links violated beyond the tolerance at that check),
    /// `conflict_frames`, `conflict_frame` (when the worst was measured)
    /// and `conflict_fixed` / `conflict_grab` / `conflict_rigid` (1 when
    /// fixed, held or rigid elements were among the violated links' ends).
    pub fn notes(&self, notes: &mut ModelNotes) {
        let mut put = |k: &str, v: f64| {
            notes.insert(k.to_owned(), v);
        };
        let n = self.ms.len();
        put("frames", self.frames as f64);
        put("at_rest", f64::from(u8::from(self.rest_frame.is_some())));
        if let Some(f) = self.rest_frame {
            put("rest_frame", f as f64);
        }
        if n > 0 {
            put("ms_per_frame_first10", self.mean_ms(0..10));
            put("ms_per_frame_last10", self.mean_ms(n.saturating_sub(10)..n));
            let max = self.ms.iter().copied().fold(0f32, f32::max);
            put("ms_per_frame_max", max as f64);
        }
        put(
            "relaxation_blocks_per_frame_max",
            self.max_relaxation_blocks as f64,
        );
        let (w, frame) = self.worst.unwrap_or_default();
        put("max_constraint_violation_mm", w.mm.max(0.0) as f64);
        put("conflicting_constraints", w.count as f64);
        put("conflict_frames", self.conflict_frames as f64);
        if self.worst.is_some() {
            put("conflict_frame", frame as f64);
        }
        for (bit, name) in [
            (FIXED_END, "conflict_fixed"),
            (HELD_END, "conflict_grab"),
            (RIGID_END, "conflict_rigid"),
        ] {
            put(name, f64::from(u8::from(w.kinds & bit != 0)));
        }
    }
}
