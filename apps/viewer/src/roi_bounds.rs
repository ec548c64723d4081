//! A map's growth bounds in the ROI panel: an intensity window and a
//! largest distance from the seed (the scene's `intensity` and
//! `max_distance_mm`), edited per map and applied with *Apply bounds*
//! (the session grows the map again within them).

use crate::protocol::{Command, RoiRow};
use egui::DragValue;
use voxflex_runtime::session::GrowthLimits;

/// The bounds being edited for one map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundsEdit {
    /// Bound the values to `[lo, hi]`.
    pub intensity_on: bool,
    /// Lowest value let in, volume units.
    pub lo: f32,
    /// Highest value let in, volume units.
    pub hi: f32,
    /// Bound the distance from the seed.
    pub distance_on: bool,
    /// Largest distance from the seed voxel's centre, mm.
    pub distance_mm: f64,
}

impl BoundsEdit {
    /// The fields for `limits` (the ranges' defaults where unbounded: a
    /// window of ±100 about 0 and 50 mm).
    pub fn of(limits: GrowthLimits) -> Self {
        let [lo, hi] = limits.intensity.unwrap_or([-100.0, 100.0]);
        Self {
            intensity_on: limits.intensity.is_some(),
            lo,
            hi,
            distance_on: limits.max_distance_mm.is_some(),
            distance_mm: limits.max_distance_mm.unwrap_or(50.0),
        }
    }

    /// The bounds these fields give.
    pub fn limits(&self) -> GrowthLimits {
        GrowthLimits {
            intensity: self.intensity_on.then_some([self.lo, self.hi]),
            max_distance_mm: self.distance_on.then_some(self.distance_mm),
        }
    }
}

/// Draws map `row`'s bounds (collapsed until opened); *Apply bounds*
/// pushes [`Command::RoiLimits`].
pub fn bounds_ui(ui: &mut egui::Ui, row: &RoiRow, edit: &mut BoundsEdit, out: &mut Vec<Command>) {
    let id = row.info.id;
    egui::CollapsingHeader::new(format!("bounds (map {})", id.0)).show(ui, |ui| {
        ui.horizontal(|ui| {
            ui.checkbox(&mut edit.intensity_on, format!("intensity (map {})", id.0));
            ui.add_enabled(edit.intensity_on, DragValue::new(&mut edit.lo).speed(1.0));
            ui.label("to");
            ui.add_enabled(edit.intensity_on, DragValue::new(&mut edit.hi).speed(1.0));
        });
        ui.horizontal(|ui| {
            ui.checkbox(
                &mut edit.distance_on,
                format!("max distance (map {})", id.0),
            );
            ui.add_enabled(
                edit.distance_on,
                DragValue::new(&mut edit.distance_mm)
                    .range(0.1..=1000.0)
                    .suffix(" mm"),
            );
        });
        if ui.button(format!("Apply bounds (map {})", id.0)).clicked() {
            out.push(Command::RoiLimits(id, edit.limits()));
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fields_give_back_the_bounds_they_show() {
        for limits in [
            GrowthLimits::default(),
            GrowthLimits {
                intensity: Some([-50.0, 80.0]),
                max_distance_mm: Some(12.5),
            },
        ] {
            assert_eq!(BoundsEdit::of(limits).limits(), limits);
        }
        let mut e = BoundsEdit::of(GrowthLimits::default());
        e.distance_on = true;
        assert_eq!(e.limits().max_distance_mm, Some(50.0));
        assert_eq!(e.limits().intensity, None);
    }
}
