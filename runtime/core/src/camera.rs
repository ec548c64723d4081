//! [`Camera`]: an orbit camera around a target point, orthographic or
//! perspective. World coordinates in millimetres; image in pixels with the
//! origin at the top-left corner, x to the right, y down.

use glam::DVec3;

/// How rays leave the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Parallel rays; the image spans `height_mm` vertically.
    Orthographic {
        /// World height of the image, mm.
        height_mm: f64,
    },
    /// Rays through the eye point with a vertical field of view.
    Perspective {
        /// Vertical field of view, degrees (0, 180).
        fov_y_deg: f64,
    },
}

/// An orbit camera: the eye sits at `distance_mm` from `target`, at
/// `azimuth_deg` about the world +z axis (0° looks along −y… see
/// [`Camera::eye`]) and `elevation_deg` above the x–y plane. World +z is up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Point looked at, world mm.
    pub target: DVec3,
    /// Rotation about world +z, degrees.
    pub azimuth_deg: f64,
    /// Angle above the x–y plane, degrees, in (−90, 90).
    pub elevation_deg: f64,
    /// Eye–target distance, mm (> 0).
    pub distance_mm: f64,
    /// Ray geometry.
    pub projection: Projection,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// One primary ray: origin (mm) and unit direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin, world mm.
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
}

impl Camera {
    /// Eye position, world mm: azimuth 0 and elevation 0 put the eye on the
    /// −y side of the target (looking along +y, the anterior view of an LPS
    /// volume), azimuth rotates it counter-clockwise seen from +z.
    pub fn eye(&self) -> DVec3 {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        let dir_to_eye = DVec3::new(az.sin() * el.cos(), -az.cos() * el.cos(), el.sin());
        self.target + dir_to_eye * self.distance_mm
    }

    /// Orthonormal camera basis `(right, up, forward)`; forward points from
    /// the eye to the target.
    pub fn basis(&self) -> (DVec3, DVec3, DVec3) {
        let forward = (self.target - self.eye()).normalize();
        let world_up = DVec3::Z;
        let mut right = forward.cross(world_up);
        if right.length_squared() < 1e-12 {
            right = DVec3::X;
        }
        let right = right.normalize();
        let up = right.cross(forward);
        (right, up, forward)
    }

    /// The ray through the centre of pixel `(px, py)` (pixel units, top-left origin).
    pub fn ray(&self, px: f64, py: f64) -> Ray {
        let (right, up, forward) = self.basis();
        let aspect = self.width as f64 / self.height.max(1) as f64;
        // Normalised device coordinates in [-1, 1], y up.
        let nx = (2.0 * (px + 0.5) / self.width.max(1) as f64) - 1.0;
        let ny = 1.0 - (2.0 * (py + 0.5) / self.height.max(1) as f64);
        match self.projection {
            Projection::Orthographic { height_mm } => {
                let half_h = 0.5 * height_mm;
                let origin = self.eye() + right * (nx * half_h * aspect) + up * (ny * half_h);
                Ray {
                    origin,
                    dir: forward,
                }
            }
            Projection::Perspective { fov_y_deg } => {
                let t = (0.5 * fov_y_deg.to_radians()).tan();
                let dir = (forward + right * (nx * t * aspect) + up * (ny * t)).normalize();
                Ray {
                    origin: self.eye(),
                    dir,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(projection: Projection) -> Camera {
        Camera {
            target: DVec3::new(1.0, 2.0, 3.0),
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            distance_mm: 100.0,
            projection,
            width: 64,
            height: 32,
        }
    }

    #[test]
    fn default_view_looks_along_plus_y_with_z_up() {
        let c = cam(Projection::Orthographic { height_mm: 50.0 });
        assert!((c.eye() - DVec3::new(1.0, -98.0, 3.0)).length() < 1e-9);
        let (r, u, f) = c.basis();
        assert!((f - DVec3::Y).length() < 1e-12 && (u - DVec3::Z).length() < 1e-12);
        assert!((r - DVec3::new(1.0, 0.0, 0.0)).length() < 1e-12);
    }

    #[test]
    fn central_rays_hit_the_target() {
        for p in [
            Projection::Orthographic { height_mm: 50.0 },
            Projection::Perspective { fov_y_deg: 40.0 },
        ] {
            let mut c = cam(p);
            c.width = 1;
            c.height = 1;
            c.azimuth_deg = 37.0;
            c.elevation_deg = 20.0;
            let r = c.ray(0.0, 0.0);
            let t = (c.target - r.origin).dot(r.dir);
            assert!((r.origin + r.dir * t - c.target).length() < 1e-9);
        }
    }
}
