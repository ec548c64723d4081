//! Window/level presets for CT (Hounsfield units) and MRI (fractions of
//! the volume's value range), and the drag that adjusts them.

use voxflex_runtime::session::Window;

/// A named window for the slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Preset {
    /// The volume's whole value range.
    FullRange,
    /// CT brain (level 40 HU, width 80 HU).
    CtBrain,
    /// CT soft tissue (level 40 HU, width 400 HU).
    CtSoftTissue,
    /// CT bone (level 400 HU, width 1800 HU).
    CtBone,
    /// MRI: the lower 60 % of the value range (T1-like tissue contrast).
    MriTissue,
    /// MRI: the upper half of the value range (bright structures).
    MriBright,
}

impl Preset {
    /// Every preset, in menu order.
    pub const ALL: [Preset; 6] = [
        Preset::FullRange,
        Preset::CtBrain,
        Preset::CtSoftTissue,
        Preset::CtBone,
        Preset::MriTissue,
        Preset::MriBright,
    ];

    /// Its menu name.
    pub fn name(self) -> &'static str {
        match self {
            Preset::FullRange => "Full range",
            Preset::CtBrain => "CT brain",
            Preset::CtSoftTissue => "CT soft tissue",
            Preset::CtBone => "CT bone",
            Preset::MriTissue => "MRI tissue",
            Preset::MriBright => "MRI bright",
        }
    }

    /// The preset a volume of values in `lo..=hi` opens with: CT soft
    /// tissue when the values look like Hounsfield units (air near
    /// −1000), else the full range.
    pub fn default_for((lo, hi): (f32, f32)) -> Preset {
        if lo <= -500.0 && hi > 0.0 {
            Preset::CtSoftTissue
        } else {
            Preset::FullRange
        }
    }

    /// The window it gives a volume of values in `lo..=hi`.
    pub fn window(self, (lo, hi): (f32, f32)) -> Window {
        let span = hi - lo;
        match self {
            Preset::FullRange => Window::from_range(lo, hi),
            Preset::CtBrain => Window::CT_BRAIN,
            Preset::CtSoftTissue => Window::CT_SOFT_TISSUE,
            Preset::CtBone => Window::CT_BONE,
            Preset::MriTissue => Window::from_range(lo, lo + 0.6 * span),
            Preset::MriBright => Window::from_range(lo + 0.5 * span, hi),
        }
    }
}

/// `window` after a drag of (`dx`, `dy`) points: right widens, up raises
/// the level, both in proportion to the width (so the feel is the same on
/// any value scale).
pub fn drag_window(window: Window, dx: f32, dy: f32) -> Window {
    let width = (window.width * (dx * 0.005).exp()).max(f32::MIN_POSITIVE);
    Window {
        level: window.level - dy * 0.002 * width,
        width,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drags_widen_and_raise_and_presets_follow_the_range() {
        let w = Window::new(40.0, 400.0);
        let wider = drag_window(w, 100.0, 0.0);
        assert!(wider.width > w.width && wider.level == w.level);
        let up = drag_window(w, 0.0, -50.0);
        assert!(up.level > w.level && up.width == w.width);
        let full = Preset::FullRange.window((-1000.0, 1000.0));
        assert_eq!((full.level, full.width), (0.0, 2000.0));
        assert_eq!(Preset::CtBone.window((0.0, 1.0)), Window::CT_BONE);
        assert_eq!(Preset::default_for((-1000.0, 1200.0)), Preset::CtSoftTissue);
        assert_eq!(Preset::default_for((0.0, 700.0)), Preset::FullRange);
    }
}
