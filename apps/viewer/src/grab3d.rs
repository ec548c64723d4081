//! Grab on the 3D view (*Grab* mode): a primary press asks the session for
//! the world point under the pointer ([`Command::Pick`], the first sample
//! along the pixel's ray at or above the slices' window floor); the drag
//! then moves that point in the plane through it parallel to the image
//! plane, one [`Command::Drag`] per move. The secondary or middle button
//! still pans and the wheel zooms (the *Cursor* mode's primary orbit is
//! off while grabbing).

use crate::protocol::Command;
use crate::view3d::{pan, zoom};
use egui::{PointerButton, Pos2, Rect, Sense, Vec2};
use voxflex_core::camera::{Camera, Projection};
use voxflex_core::glam::DVec3;

/// A press on the 3D image: where, through which camera, and the point
/// the session picked there once it answers.
#[derive(Clone, Copy, Debug)]
struct Press {
    /// Screen position of the press, points.
    at: Pos2,
    /// The camera at the press.
    camera: Camera,
    /// Height of the image on screen, points.
    height_points: f32,
    /// `None` until the session answers; then the point (world mm), or
    /// `None` when the ray hit nothing.
    picked: Option<Option<DVec3>>,
    /// The last target sent (world mm).
    sent: Option<DVec3>,
    /// The pointer's last screen position in the drag.
    last: Pos2,
    /// True once the button is up (kept only while the pick is pending:
    /// the answer then sends the drag to `last`).
    released: bool,
}

/// The 3D grab's state between frames.
#[derive(Clone, Debug, Default)]
pub struct Grab3d {
    press: Option<Press>,
    /// The point the last press picked (world mm).
    last_pick: Option<DVec3>,
}

/// What the 3D grab did this frame.
#[derive(Clone, Debug)]
pub struct Grab3dInput {
    /// The camera after pan and zoom.
    pub camera: Camera,
    /// True while a drag is under way.
    pub dragging: bool,
    /// Commands for the session (a pick, then drags).
    pub commands: Vec<Command>,
}

/// Pixel (x, y) of `camera`'s image under screen point `pos` of the image
/// drawn in `rect` (pixel units as [`Camera::ray`] takes them: pixel
/// centres at +0.5).
pub fn pixel_at(pos: Pos2, rect: Rect, camera: &Camera) -> [f64; 2] {
    let u = ((pos.x - rect.min.x) / rect.width().max(1.0)) as f64;
    let v = ((pos.y - rect.min.y) / rect.height().max(1.0)) as f64;
    [
        u * camera.width as f64 - 0.5,
        v * camera.height as f64 - 0.5,
    ]
}

/// `point` (world mm) moved by a drag of `delta` screen points on an image
/// `height_points` tall seen through `camera`: in the plane through the
/// point parallel to the image plane, so it stays under the pointer
/// (right on screen = the camera's right, down = its −up).
pub fn drag_target(camera: &Camera, point: DVec3, delta: Vec2, height_points: f32) -> DVec3 {
    let (right, up, forward) = camera.basis();
    let height_mm = match camera.projection {
        Projection::Orthographic { height_mm } => height_mm,
        Projection::Perspective { fov_y_deg } => {
            let depth = (point - camera.eye()).dot(forward).max(0.0);
            2.0 * depth * (fov_y_deg.to_radians() / 2.0).tan()
        }
    };
    let mm = height_mm / height_points.max(1.0) as f64;
    point + right * (delta.x as f64 * mm) - up * (delta.y as f64 * mm)
}

impl Grab3d {
    /// The session's answer to the pick sent at the press; the drag to
    /// where the pointer was let go when that came first.
    pub fn on_picked(&mut self, p: Option<[f64; 3]>) -> Option<Command> {
        let press = self.press.as_mut().filter(|p| p.picked.is_none())?;
        let picked = p.map(DVec3::from_array);
        press.picked = Some(picked);
        self.last_pick = picked.or(self.last_pick);
        if !press.released {
            return None;
        }
        let press = self.press.take()?;
        let point = picked?;
        let to = drag_target(
            &press.camera,
            point,
            press.last - press.at,
            press.height_points,
        );
        (to != point).then_some(Command::Drag {
            point: point.to_array(),
            to: to.to_array(),
        })
    }

    /// The point (world mm) the last press on the 3D view picked.
    pub fn last_pick(&self) -> Option<DVec3> {
        self.last_pick
    }

    /// Handles the pointer over the 3D view `avail` (the image drawn in
    /// `image`) in *Grab* mode; `min_value` is the value a sample must
    /// reach to be picked (volume units).
    pub fn input(
        &mut self,
        ui: &mut egui::Ui,
        avail: Rect,
        image: Rect,
        camera: &Camera,
        min_value: f32,
    ) -> Grab3dInput {
        let response = ui.interact(avail, ui.scope_id().with("grab3d"), Sense::click_and_drag());
        let mut out = Grab3dInput {
            camera: *camera,
            dragging: response.dragged(),
            commands: vec![],
        };
        let pointer = response.interact_pointer_pos();
        // Where the button went down (a drag starts a few points later).
        let origin = ui.input(|i| i.pointer.press_origin());
        if response.drag_started_by(PointerButton::Primary)
            && let Some(at) = origin.or(response.interact_pointer_pos())
            && image.contains(at)
        {
            let pixel = pixel_at(at, image, camera);
            self.press = Some(Press {
                at,
                camera: *camera,
                height_points: image.height(),
                picked: None,
                sent: None,
                last: at,
                released: false,
            });
            out.commands.push(Command::Pick {
                camera: *camera,
                pixel,
                min_value,
            });
        }
        if let (Some(press), Some(pos)) = (&mut self.press, pointer) {
            press.last = pos;
        }
        if let (Some(press), Some(pos)) = (&mut self.press, pointer)
            && let Some(Some(point)) = press.picked
        {
            let to = drag_target(&press.camera, point, pos - press.at, press.height_points);
            if press.sent.is_none_or(|s| (s - to).length() > 1e-3) && to != point {
                press.sent = Some(to);
                out.commands.push(Command::Drag {
                    point: point.to_array(),
                    to: to.to_array(),
                });
            }
        }
        if response.drag_stopped_by(PointerButton::Primary) {
            match &mut self.press {
                Some(p) if p.picked.is_none() => p.released = true,
                _ => self.press = None,
            }
        }
        let d = response.drag_delta();
        if response.dragged_by(PointerButton::Secondary)
            || response.dragged_by(PointerButton::Middle)
        {
            out.camera = pan(&out.camera, d.x, d.y, image.height());
        }
        if response.hovered() {
            let wheel = ui.input(|i| i.smooth_scroll_delta.y);
            if wheel != 0.0 {
                out.camera = zoom(&out.camera, wheel);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn front(projection: Projection) -> Camera {
        Camera {
            target: DVec3::ZERO,
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            distance_mm: 500.0,
            projection,
            width: 100,
            height: 100,
        }
    }

    #[test]
    fn a_drag_moves_the_point_with_the_pointer_in_the_image_plane() {
        // Seen from the front (−y), right on screen is +x, up is +z.
        let c = front(Projection::Orthographic { height_mm: 200.0 });
        let p = DVec3::new(0.0, -100.0, 0.0);
        let to = drag_target(&c, p, Vec2::new(50.0, -25.0), 100.0);
        assert!(
            (to - DVec3::new(100.0, -100.0, 50.0)).length() < 1e-9,
            "{to}"
        );
        // Perspective: the scale is the one at the point's depth (400 mm
        // from the eye at y = −500), 2 · 400 · tan 30° / 100 mm a point.
        let c = front(Projection::Perspective { fov_y_deg: 60.0 });
        let to = drag_target(&c, p, Vec2::new(10.0, 0.0), 100.0);
        let mm = 2.0 * 400.0 * 30f64.to_radians().tan() / 100.0;
        assert!((to.x - 10.0 * mm).abs() < 1e-9 && (to.y + 100.0).abs() < 1e-9);
    }

    #[test]
    fn the_pixel_under_the_pointer_is_the_rays_pixel() {
        let c = front(Projection::Orthographic { height_mm: 200.0 });
        let rect = Rect::from_min_size(Pos2::new(10.0, 20.0), Vec2::splat(200.0));
        assert_eq!(pixel_at(Pos2::new(110.0, 120.0), rect, &c), [49.5, 49.5]);
        assert_eq!(pixel_at(rect.min, rect, &c), [-0.5, -0.5]);
        // The image centre's ray passes through the target.
        let [x, y] = pixel_at(rect.center(), rect, &c);
        let ray = c.ray(x, y);
        assert!((ray.origin.x).abs() < 1e-9 && (ray.origin.z).abs() < 1e-9);
    }
}
