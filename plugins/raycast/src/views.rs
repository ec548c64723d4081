//! Camera helpers: a camera framing a volume, and turntables.

use voxflex_core::camera::{Camera, Projection};
use voxflex_core::grid::Grid;

/// An orbit camera looking at the centre of `grid` from `azimuth_deg` /
/// `elevation_deg` (see [`Camera`]), framing the whole volume (its bounding
/// sphere plus 5 %) in a `width × height` image.
///
/// `perspective`: `Some(fov_y_deg)` for a perspective camera with that
/// vertical field of view, `None` for orthographic. The eye is placed
/// outside the bounding sphere, so orthographic rays (which start at the
/// eye plane) see the whole volume.
pub fn fit_camera(
    grid: &Grid,
    width: u32,
    height: u32,
    azimuth_deg: f64,
    elevation_deg: f64,
    perspective: Option<f64>,
) -> Camera {
    let (lo, hi) = grid.world_bounds();
    let radius = (0.5 * (hi - lo).length()).max(1e-6) * 1.05;
    let aspect = width.max(1) as f64 / height.max(1) as f64;
    let (projection, distance_mm) = match perspective {
        None => (
            Projection::Orthographic {
                height_mm: 2.0 * radius / aspect.min(1.0),
            },
            3.0 * radius,
        ),
        Some(fov) => {
            let half_v = 0.5 * fov.to_radians();
            let half_h = (half_v.tan() * aspect).atan();
            let half = half_v.min(half_h).max(1e-3);
            (
                Projection::Perspective { fov_y_deg: fov },
                radius / half.sin(),
            )
        }
    };
    Camera {
        target: grid.centre(),
        azimuth_deg,
        elevation_deg,
        distance_mm,
        projection,
        width,
        height,
    }
}

/// `n` cameras orbiting `base.target` about world +z: azimuths
/// `base.azimuth_deg + 360° · i / n`, everything else as `base`.
pub fn turntable(base: &Camera, n: usize) -> Vec<Camera> {
    (0..n)
        .map(|i| Camera {
            azimuth_deg: base.azimuth_deg + 360.0 * i as f64 / n as f64,
            ..*base
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DVec3;

    #[test]
    fn turntable_spins_about_the_target() {
        let g = Grid::centred([10, 10, 10], DVec3::ONE);
        let base = fit_camera(&g, 32, 16, 10.0, 20.0, Some(30.0));
        let cams = turntable(&base, 4);
        assert_eq!(cams.len(), 4);
        assert_eq!(cams[2].azimuth_deg, 190.0);
        for c in &cams {
            assert!(((c.eye() - c.target).length() - base.distance_mm).abs() < 1e-9);
            assert_eq!(c.elevation_deg, 20.0);
        }
    }

    #[test]
    fn fitted_cameras_see_the_whole_volume() {
        let g = Grid::centred([20, 30, 40], DVec3::new(1.0, 2.0, 0.5));
        let (lo, hi) = g.world_bounds();
        let radius = 0.5 * (hi - lo).length();
        for persp in [None, Some(40.0)] {
            let c = fit_camera(&g, 64, 32, 30.0, 10.0, persp);
            assert!((c.eye() - g.centre()).length() > radius);
            // The corner rays pass outside the bounding sphere.
            for (px, py) in [(0.0, 0.0), (63.0, 0.0), (0.0, 31.0), (63.0, 31.0)] {
                let r = c.ray(px, py);
                let t = (g.centre() - r.origin).dot(r.dir);
                let miss = (r.origin + r.dir * t - g.centre()).length();
                assert!(miss > radius * 0.99, "{persp:?}: {miss} vs {radius}");
            }
        }
    }
}
