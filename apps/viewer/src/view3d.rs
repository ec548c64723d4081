//! The 3D view: the ray-cast image, and the camera's orbit (primary
//! drag), pan (secondary or middle drag) and zoom (wheel).

use egui::{Color32, PointerButton, Pos2, Rect, Sense, TextureHandle, TextureId, Vec2};
use voxflex_core::camera::{Camera, Projection};

/// Degrees of orbit per point dragged.
const ORBIT_DEG_PER_POINT: f64 = 0.4;
/// Zoom factor per point of wheel.
const ZOOM_PER_POINT: f64 = 0.002;

/// `camera` orbited by a drag of (`dx`, `dy`) points: right turns the
/// volume right, up tilts the view down onto it; the elevation stays in
/// (−89°, 89°).
pub fn orbit(camera: &Camera, dx: f32, dy: f32) -> Camera {
    Camera {
        azimuth_deg: (camera.azimuth_deg - dx as f64 * ORBIT_DEG_PER_POINT).rem_euclid(360.0),
        elevation_deg: (camera.elevation_deg + dy as f64 * ORBIT_DEG_PER_POINT).clamp(-89.0, 89.0),
        ..*camera
    }
}

/// `camera` zoomed by `wheel` points (positive: closer).
pub fn zoom(camera: &Camera, wheel: f32) -> Camera {
    let f = (-(wheel as f64) * ZOOM_PER_POINT).exp();
    let mut c = *camera;
    match &mut c.projection {
        Projection::Orthographic { height_mm } => *height_mm *= f,
        Projection::Perspective { .. } => c.distance_mm *= f,
    }
    c
}

/// The world height (mm) the image spans at the target.
fn view_height_mm(camera: &Camera) -> f64 {
    match camera.projection {
        Projection::Orthographic { height_mm } => height_mm,
        Projection::Perspective { fov_y_deg } => {
            2.0 * camera.distance_mm * (fov_y_deg.to_radians() / 2.0).tan()
        }
    }
}

/// `camera` panned so the scene follows a drag of (`dx`, `dy`) points
/// on an image `height_points` tall.
pub fn pan(camera: &Camera, dx: f32, dy: f32, height_points: f32) -> Camera {
    let (right, up, _) = camera.basis();
    let mm = view_height_mm(camera) / height_points.max(1.0) as f64;
    Camera {
        target: camera.target - right * (dx as f64 * mm) + up * (dy as f64 * mm),
        ..*camera
    }
}

/// Where the 3D image of `camera` is drawn in the view `avail`: centred,
/// as large as fits with square pixels.
pub fn image_rect(avail: Rect, camera: &Camera) -> Rect {
    let aspect = camera.width as f32 / camera.height.max(1) as f32;
    let h = avail.height().min(avail.width() / aspect);
    Rect::from_center_size(avail.center(), Vec2::new(h * aspect, h))
}

/// Draws the 3D image `tex` in the space left in `ui` (square pixels) and
/// returns the camera after the mouse's orbit, pan and zoom, and whether
/// a drag is under way.
pub fn view3d(ui: &mut egui::Ui, tex: Option<&TextureHandle>, camera: &Camera) -> (Camera, bool) {
    view3d_texture(ui, tex.map(TextureHandle::id), camera)
}

/// [`view3d`] drawing the texture `tex` by id: a CPU image uploaded to
/// egui, or the GPU path's texture on the device the session shares
/// ([`crate::gpu_image::GpuImage`]).
pub fn view3d_texture(
    ui: &mut egui::Ui,
    tex: Option<TextureId>,
    camera: &Camera,
) -> (Camera, bool) {
    let avail = ui.available_rect_before_wrap();
    let (_, response) = ui.allocate_exact_size(avail.size(), Sense::click_and_drag());
    let painter = ui.painter_at(avail);
    painter.rect_filled(avail, 0.0, Color32::BLACK);
    let rect = image_rect(avail, camera);
    if let Some(tex) = tex {
        let uv = Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0));
        painter.image(tex, rect, uv, Color32::WHITE);
    }
    let mut c = *camera;
    let d = response.drag_delta();
    if response.dragged_by(PointerButton::Primary) {
        c = orbit(&c, d.x, d.y);
    }
    if response.dragged_by(PointerButton::Secondary) || response.dragged_by(PointerButton::Middle) {
        c = pan(&c, d.x, d.y, rect.height());
    }
    if response.hovered() {
        let wheel = ui.input(|i| i.smooth_scroll_delta.y);
        if wheel != 0.0 {
            c = zoom(&c, wheel);
        }
    }
    (c, response.dragged())
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DVec3;

    fn camera() -> Camera {
        Camera {
            target: DVec3::ZERO,
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            distance_mm: 500.0,
            projection: Projection::Orthographic { height_mm: 200.0 },
            width: 100,
            height: 100,
        }
    }

    #[test]
    fn orbit_zoom_and_pan_move_the_camera_as_the_mouse_does() {
        let c = orbit(&camera(), 10.0, 1000.0);
        assert_eq!((c.azimuth_deg, c.elevation_deg), (356.0, 89.0));
        let Projection::Orthographic { height_mm } = zoom(&camera(), 100.0).projection else {
            panic!()
        };
        assert!(height_mm < 200.0, "wheel up zooms in");
        // A 50-point drag right on a 100-point image spanning 200 mm moves
        // the scene 100 mm right: the target 100 mm left (−x seen from −y).
        let p = pan(&camera(), 50.0, 0.0, 100.0);
        assert!(
            (p.target - DVec3::new(-100.0, 0.0, 0.0)).length() < 1e-9,
            "{:?}",
            p.target
        );
    }
}
