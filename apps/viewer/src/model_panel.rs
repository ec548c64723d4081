//! The deformation panel: the model combo box (the plugins the runtime
//! discovered), its parameters as TOML, Release / Reset / Step, and the
//! stage times from the session's metrics.

use crate::protocol::{Command, StageTime};
use egui::{ComboBox, TextEdit};
use voxflex_runtime::session::StepReport;

/// The panel's own state.
#[derive(Clone, Debug, Default)]
pub struct ModelPanel {
    /// Deformation plugins with the parameters the scene gives each.
    pub models: Vec<(String, String)>,
    /// The model in use.
    pub current: Option<String>,
    /// The parameters being edited (TOML).
    pub params: String,
    /// The adapter computing.
    pub adapter: String,
}

impl ModelPanel {
    /// Draws the panel; returns the commands it gave.
    pub fn ui(
        &mut self,
        ui: &mut egui::Ui,
        stages: &[StageTime],
        last_step: Option<&StepReport>,
    ) -> Vec<Command> {
        let mut out = vec![];
        ui.heading("Deformation");
        ui.label(format!("Computing on: {}", self.adapter));
        let shown = self.current.clone().unwrap_or_else(|| "none".into());
        let mut chosen = None;
        ComboBox::from_label("Model")
            .selected_text(shown)
            .show_ui(ui, |ui| {
                for (name, params) in &self.models {
                    let on = self.current.as_deref() == Some(name);
                    if ui.selectable_label(on, name).clicked() && !on {
                        chosen = Some((name.clone(), params.clone()));
                    }
                }
            });
        if let Some((plugin, params)) = chosen {
            self.params = params.clone();
            out.push(Command::SwapModel { plugin, params });
        }
        ui.collapsing("Parameters (TOML)", |ui| {
            ui.add(
                TextEdit::multiline(&mut self.params)
                    .code_editor()
                    .desired_rows(6),
            );
            if let Some(plugin) = &self.current
                && ui.button("Apply").clicked()
            {
                out.push(Command::SwapModel {
                    plugin: plugin.clone(),
                    params: self.params.clone(),
                });
            }
        });
        ui.label("Grab mode: drag on a slice to pull the tissue.");
        ui.horizontal(|ui| {
            for (label, c) in [
                ("Release", Command::Release),
                ("Reset", Command::Reset),
                ("Step", Command::Step),
            ] {
                if ui.button(label).clicked() {
                    out.push(c);
                }
            }
        });
        stage_table(ui, stages);
        if let Some(r) = last_step {
            ui.label(format!("last step: frame {}", r.frame));
            for s in &r.stages {
                let verb = if s.ran { "ran" } else { "skipped" };
                ui.small(format!("{} {verb}: {}", s.stage, s.why));
            }
        }
        out
    }
}

fn stage_table(ui: &mut egui::Ui, stages: &[StageTime]) {
    egui::Grid::new("stage-times").striped(true).show(ui, |ui| {
        ui.strong("stage");
        ui.strong("runs");
        ui.strong("total ms");
        ui.strong("mean ms");
        ui.end_row();
        for s in stages {
            ui.label(&s.stage);
            ui.label(s.runs.to_string());
            ui.label(format!("{:.1}", s.wall_ms));
            let mean = if s.runs > 0 {
                s.wall_ms / s.runs as f64
            } else {
                0.0
            };
            ui.label(format!("{mean:.2}"));
            ui.end_row();
        }
    });
}
