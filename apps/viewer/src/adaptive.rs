//! The 3D view's resolution while the user drags (adaptive quality):
//! as fine as a render budget allows, between a quarter and half of the
//! full size; full size once idle.

use std::time::Duration;

/// The render time aimed at while dragging, so deform + resample +
/// render keeps up with the pointer.
pub const BUDGET: Duration = Duration::from_millis(30);
/// The coarsest scale while dragging (a quarter of the pixels a side).
pub const MIN_SCALE: f32 = 0.25;
/// The finest scale while dragging.
pub const MAX_SCALE: f32 = 0.5;
/// Scales are multiples of this, so the image size does not change with
/// every small swing of the render time.
const STEP: f32 = 1.0 / 16.0;

/// The resolution scale of the 3D view while dragging, steered by the
/// render times it is told.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveScale {
    scale: f32,
}

impl Default for AdaptiveScale {
    /// Starts at [`MAX_SCALE`].
    fn default() -> Self {
        Self { scale: MAX_SCALE }
    }
}

impl AdaptiveScale {
    /// The scale to render at while dragging (1 = full size).
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// A render at [`Self::scale`] took `wall`: the next scale aims at
    /// [`BUDGET`], a render's cost taken as proportional to its pixels
    /// (the square of the scale), rounded down to a multiple of 1/16 and
    /// kept in [`MIN_SCALE`, `MAX_SCALE`].
    pub fn observe(&mut self, wall: Duration) {
        let ratio = BUDGET.as_secs_f32() / wall.as_secs_f32().max(1e-6);
        let want = self.scale * ratio.sqrt();
        // The small slack keeps an exact multiple (up to f32 rounding) on it.
        self.scale = ((want / STEP + 1e-3).floor() * STEP).clamp(MIN_SCALE, MAX_SCALE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slow_renders_coarsen_the_image_and_fast_ones_refine_it() {
        let mut a = AdaptiveScale::default();
        assert_eq!(a.scale(), MAX_SCALE);
        // Four times the budget: half the pixels a side.
        a.observe(BUDGET * 4);
        assert_eq!(a.scale(), 0.25);
        // Far over budget: no coarser than the floor.
        a.observe(BUDGET * 100);
        assert_eq!(a.scale(), MIN_SCALE);
        // A quarter of the budget at 0.25: 0.5 wanted.
        a.observe(BUDGET / 4);
        assert_eq!(a.scale(), 0.5);
        // Far under budget: no finer than the ceiling.
        a.observe(Duration::from_micros(1));
        assert_eq!(a.scale(), MAX_SCALE);
        // Slightly over budget at 0.5: one step down (0.4375).
        a.observe(BUDGET * 5 / 4);
        assert_eq!(a.scale(), 0.4375);
    }
}
