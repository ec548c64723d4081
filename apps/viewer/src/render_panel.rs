//! The *Rendering* panel: transfer-function preset or control points
//! (the editor over the volume's histogram), composite or MIP, shading,
//! a clip plane per axis and a crop box. Every change reconfigures the
//! renderer through the session with the scene's `[render.params]` keys,
//! throttled: at most one reconfigure is in flight; changes made while it
//! is become one more, sent when the worker acknowledges it.

use crate::protocol::Command;
use crate::render_info::RenderInfo;
use crate::render_options::{RenderOptions, TfSource};
use crate::tf_editor::{TfEditorState, tf_editor};
use crate::tf_points::{TfAxes, TfPoints};
use egui::{Pos2, Slider};

/// The combo box entry that edits control points.
const CUSTOM: &str = "Custom points";
/// Axis names for the clip and crop rows.
const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// The panel's state.
#[derive(Default)]
pub struct RenderPanel {
    info: Option<RenderInfo>,
    /// The opened `[render.params]` table (keys the panel does not set
    /// are kept from it).
    base: toml::Table,
    options: Option<RenderOptions>,
    editor: TfEditorState,
    axes: Option<TfAxes>,
    /// Sequence number of the last reconfigure sent.
    seq: u64,
    /// The reconfigure sent and not yet acknowledged.
    awaiting: Option<u64>,
    /// The options changed since the last reconfigure sent.
    dirty: bool,
    /// The text last sent.
    sent: Option<String>,
}

impl RenderPanel {
    /// Starts from what the worker found (the opened renderer parameters,
    /// presets, histogram). Parameters that are not a TOML table start
    /// from the renderer's defaults.
    pub fn on_info(&mut self, info: RenderInfo) {
        self.base = info.params_toml.parse().unwrap_or_default();
        let options = RenderOptions::from_params(&self.base, info.bounds, info.range);
        self.sent = Some(options.params_toml(&self.base));
        self.options = Some(options);
        self.info = Some(info);
    }

    /// The worker applied (or refused) reconfigure `seq`.
    pub fn applied(&mut self, seq: u64) {
        if self.awaiting == Some(seq) {
            self.awaiting = None;
        }
    }

    /// The value range the editor spans (the source volume's), once open.
    pub fn info_range(&self) -> Option<(f64, f64)> {
        self.info.as_ref().map(|i| i.range)
    }

    /// The options as set, once the volume is open.
    pub fn options(&self) -> Option<&RenderOptions> {
        self.options.as_ref()
    }

    /// Replaces the options (as the panel's widgets do).
    pub fn set_options(&mut self, options: RenderOptions) {
        self.options = Some(options);
        self.dirty = true;
    }

    /// The renderer parameters (TOML) the options give, once open.
    pub fn params_toml(&self) -> Option<String> {
        self.options.as_ref().map(|o| o.params_toml(&self.base))
    }

    /// True when every change was sent and acknowledged (the next image
    /// shows the options as set).
    pub fn settled(&self) -> bool {
        self.awaiting.is_none() && !self.dirty
    }

    /// Where (`value`, `opacity`) lies in the editor as drawn last frame
    /// (screen points).
    pub fn editor_pos(&self, value: f64, opacity: f64) -> Option<Pos2> {
        let [x, y] = self.axes?.to_screen(value, opacity);
        Some(Pos2::new(x, y))
    }

    /// Where control point `i` was drawn last frame (screen points).
    pub fn point_pos(&self, i: usize) -> Option<Pos2> {
        let (Some(axes), Some(TfSource::Points(p))) =
            (self.axes, self.options.as_ref().map(|o| &o.tf))
        else {
            return None;
        };
        let q = p.points().get(i)?;
        let [x, y] = axes.to_screen(q.value, q.opacity);
        Some(Pos2::new(x, y))
    }

    /// The reconfigure to send now: the options changed and none is in
    /// flight (then it is in flight until [`Self::applied`]).
    pub fn take_command(&mut self) -> Option<Command> {
        if !self.dirty || self.awaiting.is_some() {
            return None;
        }
        self.dirty = false;
        let text = self.params_toml()?;
        if self.sent.as_ref() == Some(&text) {
            return None;
        }
        self.seq += 1;
        self.awaiting = Some(self.seq);
        self.sent = Some(text.clone());
        Some(Command::RenderParams {
            seq: self.seq,
            params_toml: text,
        })
    }

    /// Draws the panel (changes are sent by [`Self::take_command`]).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Rendering");
        let (Some(info), Some(mut o)) = (self.info.as_ref(), self.options.clone()) else {
            ui.label("opening…");
            return;
        };
        ui.horizontal(|ui| {
            ui.selectable_value(&mut o.mip, false, "Composite");
            ui.selectable_value(&mut o.mip, true, "MIP");
            ui.add_enabled(!o.mip, egui::Checkbox::new(&mut o.shading, "Shading"));
        });
        ui.separator();
        self.axes = tf_ui(ui, &mut self.editor, &mut o, info);
        ui.separator();
        clip_ui(ui, &mut o, info);
        crop_ui(ui, &mut o, info);
        if Some(&o) != self.options.as_ref() {
            self.set_options(o);
        }
    }
}

/// The preset combo box and the editor; the axes it was drawn on.
fn tf_ui(
    ui: &mut egui::Ui,
    editor: &mut TfEditorState,
    o: &mut RenderOptions,
    info: &RenderInfo,
) -> Option<TfAxes> {
    let current = match &o.tf {
        TfSource::Preset(name) => name.clone(),
        TfSource::Points(_) => CUSTOM.into(),
    };
    let mut choice = current.clone();
    egui::ComboBox::from_label("Transfer function")
        .selected_text(&choice)
        .show_ui(ui, |ui| {
            for name in info.presets.iter().map(String::as_str).chain([CUSTOM]) {
                ui.selectable_value(&mut choice, name.to_owned(), name);
            }
        });
    let ramp = || TfSource::Points(TfPoints::ramp(info.range.0, info.range.1));
    if choice != current {
        o.tf = if choice == CUSTOM {
            ramp()
        } else {
            TfSource::Preset(choice)
        };
        *editor = TfEditorState::default();
    }
    if matches!(o.tf, TfSource::Preset(_)) {
        ui.label("A preset: click the curve area to edit points instead.");
    }
    let points = match &mut o.tf {
        TfSource::Points(p) => Some(p),
        TfSource::Preset(_) => None,
    };
    let out = tf_editor(ui, editor, points, Some(&info.histogram), info.range);
    if let Some((value, opacity)) = out.clicked_empty {
        let mut p = TfPoints::ramp(info.range.0, info.range.1);
        editor.selected = Some(p.add(value, opacity));
        o.tf = TfSource::Points(p);
    }
    Some(out.axes)
}

/// One clip plane per axis: on/off, which side is kept, where (mm).
fn clip_ui(ui: &mut egui::Ui, o: &mut RenderOptions, info: &RenderInfo) {
    ui.label("Clip planes (keep the side shown)");
    let (lo, hi) = info.bounds;
    for (a, name) in AXIS_NAMES.iter().enumerate() {
        let c = &mut o.clips[a];
        ui.horizontal(|ui| {
            ui.checkbox(&mut c.enabled, format!("clip {name}"));
            let side = if c.keep_below { "keep -" } else { "keep +" };
            if ui.small_button(format!("{side}{name}")).clicked() {
                c.keep_below = !c.keep_below;
            }
            ui.add_enabled(
                c.enabled,
                Slider::new(&mut c.at_mm, lo[a]..=hi[a]).suffix(" mm"),
            );
        });
    }
}

/// The crop box: on/off and min/max per axis (mm, within the volume).
fn crop_ui(ui: &mut egui::Ui, o: &mut RenderOptions, info: &RenderInfo) {
    ui.checkbox(&mut o.crop.enabled, "Crop box");
    let (lo, hi) = info.bounds;
    ui.add_enabled_ui(o.crop.enabled, |ui| {
        for (a, name) in AXIS_NAMES.iter().enumerate() {
            ui.horizontal(|ui| {
                ui.label(*name);
                ui.add(Slider::new(&mut o.crop.min[a], lo[a]..=hi[a]).suffix(" mm"));
                ui.add(Slider::new(&mut o.crop.max[a], lo[a]..=hi[a]).suffix(" mm"));
            });
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DVec3;
    use voxflex_runtime::session::Histogram;

    fn panel() -> RenderPanel {
        let mut p = RenderPanel::default();
        p.on_info(RenderInfo {
            params_toml: "transfer_function = { preset = \"ct-bone\" }\nbackground = [0, 0, 0]"
                .into(),
            presets: vec!["ct-bone".into()],
            histogram: Histogram {
                min: -1000.0,
                max: 1000.0,
                counts: vec![1; 8],
            },
            bounds: (DVec3::splat(-50.0), DVec3::splat(50.0)),
            range: (-1000.0, 1000.0),
        });
        p
    }

    fn sent(c: Option<Command>) -> Option<(u64, String)> {
        match c {
            Some(Command::RenderParams { seq, params_toml }) => Some((seq, params_toml)),
            None => None,
            Some(other) => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_drag_keeps_at_most_one_reconfigure_in_flight() {
        let mut p = panel();
        assert!(sent(p.take_command()).is_none(), "nothing changed yet");
        let mut o = p.options().unwrap().clone();
        o.mip = true;
        p.set_options(o.clone());
        let (seq, text) = sent(p.take_command()).unwrap();
        assert!(
            text.contains("mode = \"mip\"") && text.contains("background"),
            "{text}"
        );
        // A drag's many changes while that one is in flight…
        for at in [1.0, 2.0, 3.0] {
            o.clips[0].enabled = true;
            o.clips[0].at_mm = at;
            p.set_options(o.clone());
            assert!(p.take_command().is_none());
        }
        // …become one reconfigure with the last, once it is acknowledged.
        p.applied(seq + 7);
        assert!(
            p.take_command().is_none(),
            "another sequence number is no ack"
        );
        p.applied(seq);
        let (seq2, text) = sent(p.take_command()).unwrap();
        assert_eq!(seq2, seq + 1);
        assert!(text.contains("3.0"), "{text}");
        p.applied(seq2);
        p.set_options(o);
        assert!(
            p.take_command().is_none(),
            "the same text is not sent again"
        );
    }
}
