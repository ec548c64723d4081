//! The ROI panel: growth constants for new maps (and the selected one),
//! the list of maps with colour, visibility, Step, Run to end, Save and
//! Delete, and each map's last growth (useful-visit fraction, time).

use crate::protocol::{Command, RoiRow};
use crate::roi_bounds::{BoundsEdit, bounds_ui};
use egui::{Color32, RichText, Slider};
use std::collections::HashMap;
use std::path::PathBuf;
use voxflex_runtime::session::{GrowthParams, MAX_SEED_RADIUS, RoiId};

/// Colours given to new maps, in turn.
const PALETTE: [[u8; 3]; 6] = [
    [255, 80, 80],
    [80, 200, 255],
    [120, 255, 120],
    [255, 200, 60],
    [220, 120, 255],
    [255, 140, 200],
];

/// Room left for the *Browse…* button after the *Save to* field, points.
const BROWSE_WIDTH: f32 = 80.0;

/// How the viewer draws one map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoiStyle {
    /// Overlay colour (sRGB).
    pub colour: [u8; 3],
    /// Drawn over the slices and in the 3D view.
    pub visible: bool,
}

/// The panel's own state.
#[derive(Clone, Debug)]
pub struct RoiPanel {
    /// Constants of the next map, and of the selected one.
    pub params: GrowthParams,
    /// The map the sliders edit.
    pub selected: Option<RoiId>,
    /// Each map's colour and visibility.
    pub styles: HashMap<RoiId, RoiStyle>,
    /// Where Save writes maps (`roi-<id>.nii.gz` in it).
    pub save_dir: String,
    /// Set when *Browse…* next to `save_dir` was clicked (the app opens
    /// the folder dialog and clears it).
    pub browse_save_dir: bool,
    /// Each map's growth bounds being edited.
    pub bounds: HashMap<RoiId, BoundsEdit>,
}

impl Default for RoiPanel {
    fn default() -> Self {
        Self {
            params: GrowthParams::default(),
            selected: None,
            styles: HashMap::new(),
            save_dir: ".".into(),
            browse_save_dir: false,
            bounds: HashMap::new(),
        }
    }
}

impl RoiPanel {
    /// The style of map `id`, given one from the palette when new.
    pub fn style(&mut self, id: RoiId) -> RoiStyle {
        let n = self.styles.len();
        *self.styles.entry(id).or_insert(RoiStyle {
            colour: PALETTE[n % PALETTE.len()],
            visible: true,
        })
    }

    /// The visible maps with their colours, for the slice overlays.
    pub fn overlays(&mut self, rows: &[RoiRow]) -> Vec<(RoiId, [u8; 3])> {
        rows.iter()
            .map(|r| (r.info.id, self.style(r.info.id)))
            .filter(|(_, s)| s.visible)
            .map(|(id, s)| (id, s.colour))
            .collect()
    }

    /// The hidden maps (checkbox off): not handed to the renderer.
    pub fn hidden(&self) -> Vec<RoiId> {
        let mut ids: Vec<RoiId> = self
            .styles
            .iter()
            .filter(|(_, s)| !s.visible)
            .map(|(id, _)| *id)
            .collect();
        ids.sort();
        ids
    }

    /// Draws the panel; returns the commands its buttons and sliders gave.
    pub fn ui(&mut self, ui: &mut egui::Ui, rows: &[RoiRow]) -> Vec<Command> {
        let mut out = vec![];
        ui.heading("ROI opacity maps");
        ui.label("Ctrl+click a slice (or the Seed ROI mode) to seed a map.");
        let mut released = false;
        let mut slider = |ui: &mut egui::Ui, s: Slider<'_>| {
            let r = ui.add(s);
            released |= r.drag_stopped() || (r.changed() && !r.dragged());
        };
        slider(
            ui,
            Slider::new(&mut self.params.lambda, 1.0..=300.0)
                .logarithmic(true)
                .text("λ"),
        );
        slider(
            ui,
            Slider::new(&mut self.params.o_min, 0.0..=0.5).text("o_min"),
        );
        slider(
            ui,
            Slider::new(&mut self.params.o_max, 0.1..=1.0).text("o_max"),
        );
        slider(
            ui,
            Slider::new(&mut self.params.seed_radius, 1..=MAX_SEED_RADIUS)
                .text("seed radius (voxels)"),
        );
        let mut faces = self.params.connectivity == 6;
        let r = ui
            .checkbox(&mut faces, "face neighbours only (connectivity 6)")
            .on_hover_text("26 (the paper's) lets opacity cross a diagonal contact between organs");
        if r.changed() {
            self.params.connectivity = if faces { 6 } else { 26 };
            released = true;
        }
        if released && let Some(id) = self.selected {
            out.push(Command::RoiParams(id, self.params));
        }
        ui.horizontal(|ui| {
            let label = ui.label("Save to");
            // The field leaves room for Browse… (the panel keeps its width).
            let field = egui::TextEdit::singleline(&mut self.save_dir)
                .desired_width(ui.available_width() - BROWSE_WIDTH);
            ui.add(field).labelled_by(label.id);
            self.browse_save_dir |= ui.button("Browse…").clicked();
        });
        ui.separator();
        for row in rows {
            self.row_ui(ui, row, &mut out);
        }
        out
    }

    fn row_ui(&mut self, ui: &mut egui::Ui, row: &RoiRow, out: &mut Vec<Command>) {
        let id = row.info.id;
        let mut style = self.style(id);
        ui.horizontal(|ui| {
            ui.color_edit_button_srgb(&mut style.colour);
            ui.checkbox(&mut style.visible, "")
                .on_hover_text("show on the slices and in the 3D view");
            let selected = self.selected == Some(id);
            let text = format!("map {}", id.0);
            if ui.selectable_label(selected, text).clicked() {
                self.selected = Some(id);
                self.params = row.info.params;
            }
        });
        self.styles.insert(id, style);
        let i = &row.info;
        let state = if i.converged { "converged" } else { "growing" };
        // An automatic-λ map is written from its λ scan, not grown.
        let made = if i.lambda_auto {
            "from the λ scan".to_string()
        } else {
            format!("{} steps", i.steps)
        };
        ui.label(format!(
            "{made}, {} voxels ≥ ½, {state}",
            i.voxels_above_half
        ));
        auto_lambda_ui(ui, row, out);
        let edit = self
            .bounds
            .entry(id)
            .or_insert_with(|| BoundsEdit::of(row.info.limits));
        bounds_ui(ui, row, edit, out);
        if let Some((report, wall)) = row.last {
            let ms = wall.as_secs_f64() * 1e3;
            let text = if i.lambda_auto {
                format!(
                    "last map: λ scan, {} relaxations, {ms:.1} ms",
                    report.visits
                )
            } else {
                format!(
                    "last growth: {} steps, useful visits {:.1} %, {ms:.1} ms",
                    report.steps,
                    100.0 * report.useful_fraction()
                )
            };
            ui.label(RichText::new(text).color(Color32::GRAY));
        }
        ui.horizontal(|ui| {
            if ui.button("Step").clicked() {
                out.push(Command::RoiStep(id, 1));
            }
            if ui.button("Run to end").clicked() {
                out.push(Command::RoiRunToEnd(id));
            }
            if ui.button("Save").clicked() {
                let path = PathBuf::from(&self.save_dir).join(format!("roi-{}.nii.gz", id.0));
                out.push(Command::SaveRoi(id, path));
            }
            if ui.button("Delete").clicked() {
                out.push(Command::RemoveRoi(id));
                self.styles.remove(&id);
                self.bounds.remove(&id);
                if self.selected == Some(id) {
                    self.selected = None;
                }
            }
        });
        ui.separator();
    }
}

/// The map's *auto λ* box and the λ in use: ticking it has the session
/// choose λ by the plateau rule and grow the map to the end; unticking
/// keeps that λ as a fixed one.
fn auto_lambda_ui(ui: &mut egui::Ui, row: &RoiRow, out: &mut Vec<Command>) {
    let i = &row.info;
    ui.horizontal(|ui| {
        let mut auto = i.lambda_auto;
        let label = format!("auto λ (map {})", i.id.0);
        if ui
            .checkbox(&mut auto, label)
            .on_hover_text(
                "choose λ where the map's size is flattest in λ, before it runs into a neighbour (the scene's lambda = \"auto\")",
            )
            .changed()
        {
            out.push(if auto {
                Command::RoiAutoLambda(i.id)
            } else {
                Command::RoiParams(i.id, i.params)
            });
        }
        let how = if i.lambda_auto { "chosen" } else { "set" };
        ui.label(format!("λ = {:.2} ({how})", i.params.lambda));
    });
}
