//! The transfer-function editor widget: the volume's histogram
//! (log-scaled) behind the opacity curve through the control points, a
//! colour bar under it, and one row per point (colour button, value,
//! opacity). Drag a point to move it (value across, opacity up), click
//! empty space to add one, right-click or double-click a point to delete
//! it. The editing itself is [`crate::tf_points`].

use crate::histogram;
use crate::tf_points::{TfAxes, TfPoints};
use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2};
use voxflex_runtime::session::Histogram;

/// Height of the curve area, points.
const CANVAS_HEIGHT: f32 = 120.0;
/// Height of the colour bar under it, points.
const BAR_HEIGHT: f32 = 10.0;
/// Radius of a drawn point, points.
const POINT_RADIUS: f32 = 5.0;
/// Room left on the right for the panel's floating scroll bar, points.
const SCROLL_BAR_ROOM: f32 = 16.0;
/// How near a press must be to grab a point, points.
const HIT_RADIUS: f32 = 8.0;

/// The editor's own state between frames.
#[derive(Clone, Debug, Default)]
pub struct TfEditorState {
    /// The point last pressed (outlined; its row is highlighted).
    pub selected: Option<usize>,
    /// The point being dragged.
    pub dragging: Option<usize>,
}

/// What a frame of the editor did.
#[derive(Clone, Copy, Debug)]
pub struct TfEditorOutput {
    /// The points changed.
    pub changed: bool,
    /// The axes it was drawn on (screen points), for tests to aim at.
    pub axes: TfAxes,
    /// A click on the canvas, as (value, opacity), when there are no
    /// points to edit yet (a preset is shown).
    pub clicked_empty: Option<(f64, f64)>,
}

/// Draws the editor over `range` (volume units) with `histogram` behind;
/// `points` is `None` while a preset is shown (nothing to drag; a click
/// is reported in [`TfEditorOutput::clicked_empty`]).
pub fn tf_editor(
    ui: &mut egui::Ui,
    state: &mut TfEditorState,
    points: Option<&mut TfPoints>,
    histogram: Option<&Histogram>,
    range: (f64, f64),
) -> TfEditorOutput {
    // Clear of the scroll bar, which floats over the panel's right edge.
    let width = (ui.available_width() - SCROLL_BAR_ROOM).max(100.0);
    let (rect, response) =
        ui.allocate_exact_size(Vec2::new(width, CANVAS_HEIGHT), Sense::click_and_drag());
    let axes = TfAxes {
        lo: range.0,
        hi: range.1,
        left: rect.left() + POINT_RADIUS,
        right: rect.right() - POINT_RADIUS,
        top: rect.top() + POINT_RADIUS,
        bottom: rect.bottom() - POINT_RADIUS,
    };
    let painter = ui.painter_at(rect.expand(1.0));
    painter.rect_filled(rect, 2.0, Color32::from_gray(25));
    if let Some(h) = histogram {
        histogram::paint(&painter, &axes, h);
    }
    let mut out = TfEditorOutput {
        changed: false,
        axes,
        clicked_empty: None,
    };
    let Some(points) = points else {
        if response.clicked()
            && let Some(p) = response.interact_pointer_pos()
        {
            out.clicked_empty = Some((axes.x_to_value(p.x), axes.y_to_opacity(p.y)));
        }
        return out;
    };
    out.changed = edit(&response, state, points, &axes);
    paint_curve(&painter, &axes, points, state.selected);
    colour_bar(ui, &axes, points);
    out.changed |= point_rows(ui, state, points);
    out
}

/// Applies the mouse on the canvas to `points`; true when they changed.
fn edit(
    response: &egui::Response,
    state: &mut TfEditorState,
    points: &mut TfPoints,
    axes: &TfAxes,
) -> bool {
    let pos = response.interact_pointer_pos().map(|p| [p.x, p.y]);
    let hit = pos.and_then(|p| points.hit(axes, p, HIT_RADIUS));
    if response.drag_started() {
        // The point under the press, not under the pointer by now.
        let origin = response.ctx.input(|i| i.pointer.press_origin());
        let grabbed = origin.and_then(|p| points.hit(axes, [p.x, p.y], HIT_RADIUS));
        state.dragging = grabbed;
        state.selected = grabbed.or(state.selected);
    }
    let mut changed = false;
    if let (true, Some(i), Some([x, y])) = (response.dragged(), state.dragging, pos) {
        changed |= points
            .move_point(i, axes.x_to_value(x), axes.y_to_opacity(y))
            .is_some();
    }
    if response.drag_stopped() {
        state.dragging = None;
    }
    let delete = response.secondary_clicked() || response.double_clicked();
    match (hit, pos) {
        (Some(i), _) if delete && points.delete(i) => {
            state.selected = None;
            changed = true;
        }
        (Some(_), _) if delete => {}
        (Some(i), _) if response.clicked() => state.selected = Some(i),
        (None, Some([x, y])) if response.clicked() => {
            state.selected = Some(points.add(axes.x_to_value(x), axes.y_to_opacity(y)));
            changed = true;
        }
        _ => {}
    }
    changed
}

fn colour32(c: [u8; 3]) -> Color32 {
    Color32::from_rgb(c[0], c[1], c[2])
}

fn paint_curve(painter: &egui::Painter, axes: &TfAxes, points: &TfPoints, selected: Option<usize>) {
    let at = |v: f64, o: f64| {
        let [x, y] = axes.to_screen(v, o);
        Pos2::new(x, y)
    };
    let line: Vec<Pos2> = points
        .points()
        .iter()
        .map(|p| at(p.value, p.opacity))
        .collect();
    painter.add(egui::Shape::line(
        line,
        Stroke::new(1.5, Color32::LIGHT_GRAY),
    ));
    for (i, p) in points.points().iter().enumerate() {
        let outline = if selected == Some(i) {
            Stroke::new(2.0, Color32::YELLOW)
        } else {
            Stroke::new(1.0, Color32::WHITE)
        };
        painter.circle(
            at(p.value, p.opacity),
            POINT_RADIUS,
            colour32(p.colour),
            outline,
        );
    }
}

/// The function's colour along the value axis.
fn colour_bar(ui: &mut egui::Ui, axes: &TfAxes, points: &TfPoints) {
    let width = (ui.available_width() - SCROLL_BAR_ROOM).max(100.0);
    let (rect, _) = ui.allocate_exact_size(Vec2::new(width, BAR_HEIGHT), Sense::hover());
    let painter = ui.painter_at(rect);
    let steps = ((axes.right - axes.left) / 2.0).max(1.0) as usize;
    for s in 0..steps {
        let x0 = axes.left + s as f32 * 2.0;
        let v = axes.x_to_value(x0 + 1.0);
        let r = Rect::from_min_max(
            Pos2::new(x0, rect.top()),
            Pos2::new(x0 + 2.0, rect.bottom()),
        );
        painter.rect_filled(r, 0.0, colour32(points.colour_at(v)));
    }
}

/// One row per point: colour button, value and opacity fields, delete.
fn point_rows(ui: &mut egui::Ui, state: &mut TfEditorState, points: &mut TfPoints) -> bool {
    let mut changed = false;
    let mut delete = None;
    for i in 0..points.points().len() {
        let p = points.points()[i];
        ui.horizontal(|ui| {
            let mut colour = p.colour;
            if ui.color_edit_button_srgb(&mut colour).changed() {
                points.set_colour(i, colour);
                changed = true;
            }
            let (mut value, mut opacity) = (p.value, p.opacity);
            let v = ui.add(egui::DragValue::new(&mut value).speed(1.0).prefix("value "));
            let o = ui.add(
                egui::DragValue::new(&mut opacity)
                    .speed(0.005)
                    .range(0.0..=1.0)
                    .prefix("opacity "),
            );
            if v.changed() || o.changed() {
                changed |= points.move_point(i, value, opacity).is_some();
            }
            if ui
                .small_button("×")
                .on_hover_text("delete this point")
                .clicked()
            {
                delete = Some(i);
            }
            if state.selected == Some(i) {
                ui.weak("selected");
            }
        });
    }
    if let Some(i) = delete
        && points.delete(i)
    {
        state.selected = None;
        changed = true;
    }
    changed
}
