//! The deformation panel: the model combo box (the plugins the runtime
//! discovered), its parameters as a form generated from the plugin's
//! schema ([`crate::param_form`]), Release / Reset / Step, and the stage
//! times from the session's metrics.

use crate::param_form::{Field, FieldValue, ParamForm};
use crate::protocol::{Command, StageTime};
use egui::{Color32, ComboBox, DragValue, RichText, TextEdit};
use voxflex_runtime::param_schema::{ParamKind, ParamSchema};
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
    /// Each deformation plugin's parameter schema.
    pub schemas: Vec<(String, ParamSchema)>,
    /// The form of the model in use (from its schema).
    pub form: Option<ParamForm>,
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
            self.rebuild_form(&plugin);
            out.push(Command::SwapModel { plugin, params });
        }
        egui::CollapsingHeader::new("Parameters")
            .default_open(true)
            .show(ui, |ui| {
                if let Some(c) = self.form_ui(ui) {
                    out.push(c);
                }
            });
        ui.label("Grab: drag on a slice to pull the tissue; Cut: drag a line; Carve: click or drag the brush.");
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

impl ModelPanel {
    /// Builds the form of `plugin` from its schema, filled from
    /// [`Self::params`] (the scene's table).
    pub fn rebuild_form(&mut self, plugin: &str) {
        let current: toml::Table = self.params.parse().unwrap_or_default();
        self.form = self
            .schemas
            .iter()
            .find(|(n, _)| n == plugin)
            .map(|(_, s)| ParamForm::new(plugin, s, &current));
    }

    /// The model now in use is `plugin` (rebuilds the form when it changed).
    pub fn set_current(&mut self, plugin: String) {
        if self.form.as_ref().map(|f| f.plugin.as_str()) != Some(plugin.as_str()) {
            self.rebuild_form(&plugin);
        }
        self.current = Some(plugin);
    }

    /// The session refused the parameters: files its message under the
    /// key it names.
    pub fn model_error(&mut self, message: &str) {
        if let Some(f) = &mut self.form {
            f.file_issues(&[message.to_owned()]);
        }
    }

    /// The form's rows and Apply; returns the swap Apply asks for.
    fn form_ui(&mut self, ui: &mut egui::Ui) -> Option<Command> {
        let form = self.form.as_mut()?;
        let mut edited = false;
        for f in &mut form.fields {
            edited |= field_ui(ui, f);
        }
        if edited {
            form.check();
        }
        for g in &form.general {
            ui.colored_label(Color32::LIGHT_RED, g);
        }
        ui.small("* required; hover a key for its doc");
        let text = form.toml_text();
        if ui
            .add_enabled(text.is_ok(), egui::Button::new("Apply"))
            .clicked()
            && let Ok(params) = text
        {
            self.params = params.clone();
            return Some(Command::SwapModel {
                plugin: form.plugin.clone(),
                params,
            });
        }
        None
    }
}

/// One key's row (an on/off box for optional keys, the key with its doc as
/// hover text, the widget of its kind) and its problems below it; returns
/// whether the user changed it.
fn field_ui(ui: &mut egui::Ui, f: &mut Field) -> bool {
    let mut changed = false;
    let spec = &f.spec;
    ui.horizontal(|ui| {
        let name = if spec.required {
            format!("{} *", spec.name)
        } else {
            spec.name.clone()
        };
        let label = if spec.required {
            ui.label(RichText::new(name).strong())
                .on_hover_text(&spec.doc)
        } else {
            let r = ui.checkbox(&mut f.on, name).on_hover_text(&spec.doc);
            changed |= r.changed();
            r
        };
        ui.add_enabled_ui(f.on, |ui| {
            changed |= value_ui(ui, spec, &mut f.value, label.id);
        });
    });
    for issue in &f.issues {
        ui.colored_label(Color32::LIGHT_RED, format!("  {issue}"));
    }
    changed
}

/// The widget of one value; returns whether it changed.
fn value_ui(
    ui: &mut egui::Ui,
    spec: &voxflex_runtime::param_schema::ParamSpec,
    value: &mut FieldValue,
    label: egui::Id,
) -> bool {
    let kind = &spec.kind;
    let lo = spec.minimum.unwrap_or(f64::NEG_INFINITY);
    let hi = spec.maximum.unwrap_or(f64::INFINITY);
    let unit = spec
        .unit
        .as_deref()
        .map(|u| format!(" {u}"))
        .unwrap_or_default();
    match value {
        FieldValue::Bool(b) => ui.checkbox(b, "").labelled_by(label).changed(),
        FieldValue::Integer(i) => ui
            .add(DragValue::new(i).range(lo..=hi).suffix(unit))
            .labelled_by(label)
            .changed(),
        FieldValue::Number(x) => ui
            .add(DragValue::new(x).range(lo..=hi).speed(0.01).suffix(unit))
            .labelled_by(label)
            .changed(),
        FieldValue::Choice(c) => {
            let ParamKind::Choice(names) = kind else {
                return ui.text_edit_singleline(c).labelled_by(label).changed();
            };
            let before = c.clone();
            ComboBox::from_id_salt(&spec.name)
                .selected_text(c.as_str())
                .show_ui(ui, |ui| {
                    for n in names {
                        ui.selectable_value(c, n.clone(), n);
                    }
                })
                .response
                .labelled_by(label);
            *c != before
        }
        FieldValue::Text(t) => ui.text_edit_singleline(t).labelled_by(label).changed(),
        FieldValue::Numbers { values, integer } => {
            let mut changed = false;
            for x in values.iter_mut() {
                let speed = if *integer { 1.0 } else { 0.01 };
                changed |= ui
                    .add(DragValue::new(x).speed(speed).suffix(unit.clone()))
                    .labelled_by(label)
                    .changed();
                if *integer {
                    *x = x.round();
                }
            }
            changed
        }
        FieldValue::Toml(t) => ui
            .add(TextEdit::multiline(t).code_editor().desired_rows(2))
            .labelled_by(label)
            .changed(),
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
