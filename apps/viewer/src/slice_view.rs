//! One slice view: the slice drawn in millimetre proportions with the
//! crosshair and LPS labels, and what the mouse did on it (in world mm).

use crate::orientation::{axis_name, edge_labels};
use crate::protocol::SliceFrame;
use egui::{
    Align2, Color32, FontId, PointerButton, Pos2, Rect, Sense, Stroke, TextureHandle, Vec2,
};
use voxflex_core::glam::DVec3;

/// What a primary click or drag on a slice does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClickMode {
    /// Move the cursor (the crosshair) to the point.
    Cursor,
    /// Seed a new ROI map at the point (Ctrl+click in any mode).
    SeedRoi,
    /// Grab the tissue at the point and drag it in the view plane.
    Grab,
    /// Drag a line: the tissue is cut by the plane through it,
    /// perpendicular to the slice.
    Cut,
    /// Click or drag a ball brush that removes the tissue under it.
    Carve,
}

impl ClickMode {
    /// The modes whose primary drag is a tool stroke, not a cursor move.
    pub fn is_tool(self) -> bool {
        matches!(self, Self::Grab | Self::Cut | Self::Carve)
    }
}

/// What the user did on a slice view this frame.
#[derive(Clone, Debug, Default)]
pub struct SliceInput {
    /// Where the slice was drawn (screen points).
    pub rect: Option<Rect>,
    /// Move the cursor here (world mm).
    pub cursor: Option<DVec3>,
    /// Seed an ROI map here (world mm).
    pub seed: Option<DVec3>,
    /// A tool drag (grab, cut, carve) started at this point (world mm).
    pub grab_start: Option<DVec3>,
    /// The tool drag's pointer is here now (world mm, in the view plane).
    pub grab_to: Option<DVec3>,
    /// The tool drag ended this frame.
    pub drag_end: bool,
    /// A click in carve mode (world mm).
    pub carve_click: Option<DVec3>,
    /// Slices to move through (wheel; + towards the axis' far end).
    pub wheel: f32,
    /// A window/level drag (secondary button), points.
    pub window_drag: Option<Vec2>,
    /// True while any drag on this view is under way.
    pub dragging: bool,
}

/// The screen rectangle showing a `frame` in true proportions (each pixel
/// `pixel_mm` wide and high), as large as fits `avail`, centred.
fn fit_rect(frame: &SliceFrame, avail: Rect) -> Rect {
    let img = &frame.slice.image;
    let [pw, ph] = frame.slice.pixel_mm();
    let (w_mm, h_mm) = (img.width as f64 * pw, img.height as f64 * ph);
    let scale = (avail.width() as f64 / w_mm).min(avail.height() as f64 / h_mm);
    let size = Vec2::new((w_mm * scale) as f32, (h_mm * scale) as f32);
    Rect::from_center_size(avail.center(), size)
}

/// Continuous pixel coordinates (pixel centres at whole numbers) of
/// screen point `pos` over a slice drawn in `rect`.
fn to_pixel(frame: &SliceFrame, rect: Rect, pos: Pos2) -> (f64, f64) {
    let img = &frame.slice.image;
    let u = ((pos.x - rect.min.x) / rect.width()) as f64 * img.width as f64 - 0.5;
    let v = ((pos.y - rect.min.y) / rect.height()) as f64 * img.height as f64 - 0.5;
    (u, v)
}

fn to_screen(frame: &SliceFrame, rect: Rect, [c, r]: [f64; 2]) -> Pos2 {
    let img = &frame.slice.image;
    Pos2::new(
        rect.min.x + ((c + 0.5) / img.width as f64) as f32 * rect.width(),
        rect.min.y + ((r + 0.5) / img.height as f64) as f32 * rect.height(),
    )
}

/// Draws `frame` (its texture `tex`) in the space left in `ui`, with the
/// crosshair through `cursor` (world mm), and returns what the mouse did.
pub fn slice_view(
    ui: &mut egui::Ui,
    frame: &SliceFrame,
    tex: &TextureHandle,
    cursor: DVec3,
    mode: ClickMode,
    brush_mm: f64,
) -> SliceInput {
    let avail = ui.available_rect_before_wrap();
    let (_, response) = ui.allocate_exact_size(avail.size(), Sense::click_and_drag());
    let rect = fit_rect(frame, avail);
    let painter = ui.painter_at(avail);
    painter.rect_filled(avail, 0.0, Color32::BLACK);
    let uv = Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0));
    painter.image(tex.id(), rect, uv, Color32::WHITE);
    draw_crosshair(&painter, frame, rect, cursor);
    draw_labels(&painter, frame, rect, avail);

    let mut out = SliceInput {
        rect: Some(rect),
        ..SliceInput::default()
    };
    let world_at = |pos: Pos2| {
        let (u, v) = to_pixel(frame, rect, pos);
        frame.slice.point_to_world(u, v)
    };
    let ctrl = ui.input(|i| i.modifiers.command);
    let pos = response.interact_pointer_pos();
    if response.clicked_by(PointerButton::Primary)
        && let Some(p) = pos.filter(|p| rect.contains(*p))
    {
        match (mode, ctrl) {
            (ClickMode::SeedRoi, _) | (_, true) => out.seed = Some(world_at(p)),
            (ClickMode::Carve, _) => out.carve_click = Some(world_at(p)),
            _ => {}
        }
        out.cursor = Some(world_at(p));
    }
    if response.dragged_by(PointerButton::Primary)
        && let Some(p) = pos
    {
        out.dragging = true;
        if mode.is_tool() {
            let origin = ui.input(|i| i.pointer.press_origin()).unwrap_or(p);
            if response.drag_started() {
                out.grab_start = Some(world_at(origin));
            }
            out.grab_to = Some(world_at(p));
            if mode == ClickMode::Cut {
                painter.line_segment([origin, p], Stroke::new(2.0, Color32::RED));
            }
        } else if rect.contains(p) {
            out.cursor = Some(world_at(p));
        }
    }
    if response.drag_stopped_by(PointerButton::Primary) && mode.is_tool() {
        out.drag_end = true;
    }
    if mode == ClickMode::Carve
        && let Some(p) = response.hover_pos()
    {
        let [pw, _] = frame.slice.pixel_mm();
        let px_per_mm = rect.width() as f64 / (frame.slice.image.width as f64 * pw);
        let r = (brush_mm * px_per_mm) as f32;
        painter.circle_stroke(p, r, Stroke::new(1.5, Color32::from_rgb(255, 120, 0)));
    }
    if response.dragged_by(PointerButton::Secondary) {
        out.dragging = true;
        out.window_drag = Some(response.drag_delta());
    }
    if response.hovered() {
        out.wheel = ui.input(|i| i.smooth_scroll_delta.y);
    }
    out
}

fn draw_crosshair(painter: &egui::Painter, frame: &SliceFrame, rect: Rect, cursor: DVec3) {
    let p = to_screen(frame, rect, frame.slice.world_to_point(cursor));
    let stroke = Stroke::new(1.0, Color32::from_rgba_unmultiplied(255, 220, 0, 160));
    painter.line_segment(
        [Pos2::new(rect.min.x, p.y), Pos2::new(rect.max.x, p.y)],
        stroke,
    );
    painter.line_segment(
        [Pos2::new(p.x, rect.min.y), Pos2::new(p.x, rect.max.y)],
        stroke,
    );
}

fn draw_labels(painter: &egui::Painter, frame: &SliceFrame, rect: Rect, avail: Rect) {
    let [left, right, top, bottom] = edge_labels(frame.slice.axis);
    let font = FontId::proportional(14.0);
    let c = Color32::from_rgb(120, 200, 255);
    let m = 4.0;
    let mid = rect.center();
    painter.text(
        Pos2::new(rect.min.x + m, mid.y),
        Align2::LEFT_CENTER,
        left,
        font.clone(),
        c,
    );
    painter.text(
        Pos2::new(rect.max.x - m, mid.y),
        Align2::RIGHT_CENTER,
        right,
        font.clone(),
        c,
    );
    painter.text(
        Pos2::new(mid.x, rect.min.y + m),
        Align2::CENTER_TOP,
        top,
        font.clone(),
        c,
    );
    painter.text(
        Pos2::new(mid.x, rect.max.y - m),
        Align2::CENTER_BOTTOM,
        bottom,
        font.clone(),
        c,
    );
    let title = format!("{} {}", axis_name(frame.slice.axis), frame.slice.index);
    painter.text(
        avail.min + Vec2::splat(m),
        Align2::LEFT_TOP,
        title,
        font,
        Color32::WHITE,
    );
}
