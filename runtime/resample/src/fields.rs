//! Analytic displacement fields (millimetres, world frame) on a source
//! grid: what the accuracy benchmark (`voxflex bench --accuracy`,
//! [`crate::accuracy`]), the CPU/GPU parity checks and the mesh-model tests
//! deform volumes with. A public module (not test support) because the
//! benchmark ships in release builds.

use crate::DisplacementsRef;
use crate::grid::Grid;
use glam::{DMat3, DVec3};

/// A displacement field, millimetres, structure of arrays.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// x displacements, mm.
    pub x: Vec<f32>,
    /// y displacements, mm.
    pub y: Vec<f32>,
    /// z displacements, mm.
    pub z: Vec<f32>,
}

impl Field {
    /// The identity field (all zero) for `grid`.
    pub fn zero(grid: &Grid) -> Self {
        let n = grid.len();
        Self {
            x: vec![0.0; n],
            y: vec![0.0; n],
            z: vec![0.0; n],
        }
    }

    /// The field moving each voxel centre `X` (world mm) to `map(X)`.
    pub fn from_map(grid: &Grid, map: impl Fn(DVec3) -> DVec3 + Sync) -> Self {
        use rayon::prelude::*;
        let n = grid.len();
        let d: Vec<[f32; 3]> = (0..n)
            .into_par_iter()
            .map(|l| {
                let [i, j, k] = grid.unlinear(l);
                let x = grid.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
                let u = map(x) - x;
                [u.x as f32, u.y as f32, u.z as f32]
            })
            .collect();
        Self {
            x: d.iter().map(|v| v[0]).collect(),
            y: d.iter().map(|v| v[1]).collect(),
            z: d.iter().map(|v| v[2]).collect(),
        }
    }

    /// Borrow as resampler input.
    pub fn as_ref(&self) -> DisplacementsRef<'_> {
        DisplacementsRef {
            x: &self.x,
            y: &self.y,
            z: &self.z,
        }
    }
}

/// Twist about the z axis through `centre` (mm): rotation angle
/// `rad_per_mm · (z − centre.z)`. Returns the map and its inverse.
pub fn twist_z(
    centre: DVec3,
    rad_per_mm: f64,
) -> (
    impl Fn(DVec3) -> DVec3 + Sync,
    impl Fn(DVec3) -> DVec3 + Sync,
) {
    let rot = move |p: DVec3, s: f64| {
        let a = s * rad_per_mm * (p.z - centre.z);
        let (sn, cs) = a.sin_cos();
        let d = p - centre;
        centre + DVec3::new(cs * d.x - sn * d.y, sn * d.x + cs * d.y, d.z)
    };
    (move |p| rot(p, 1.0), move |p| rot(p, -1.0))
}

/// Affine map `centre + M (X − centre) + t` (mm) with `M` a rotation by
/// `deg` degrees about `axis` times a uniform `scale`. Returns the map and
/// its inverse.
pub fn affine(
    centre: DVec3,
    axis: DVec3,
    deg: f64,
    scale: f64,
    t: DVec3,
) -> (
    impl Fn(DVec3) -> DVec3 + Sync,
    impl Fn(DVec3) -> DVec3 + Sync,
) {
    let m = DMat3::from_axis_angle(axis.normalize(), deg.to_radians()) * scale;
    let mi = m.inverse();
    (
        move |p| centre + m * (p - centre) + t,
        move |p| centre + mi * (p - t - centre),
    )
}

/// Barr's bend (1984) of the z axis towards x about `centre` (mm) with
/// curvature `k` (1/mm): the line `x = y = 0` (relative to `centre`) goes
/// onto a circle of radius `1/k` through `centre`, lengths along it kept;
/// points with `x < 1/k` keep their distance `1/k − x` from the bend's
/// centre line. The same formula as the `affine` plugin's `bend`. Returns
/// the map and its exact inverse (valid for `x < 1/k` and `|k z| < π`).
pub fn bend_zx(
    centre: DVec3,
    k: f64,
) -> (
    impl Fn(DVec3) -> DVec3 + Sync,
    impl Fn(DVec3) -> DVec3 + Sync,
) {
    let map = move |p: DVec3| {
        let q = p - centre;
        if k == 0.0 {
            return p;
        }
        let (s, c) = (k * q.z).sin_cos();
        let r = 1.0 / k - q.x;
        centre + DVec3::new(1.0 / k - r * c, q.y, r * s)
    };
    let inverse = move |p: DVec3| {
        let q = p - centre;
        if k == 0.0 {
            return p;
        }
        // q.x = 1/k − r cos θ, q.z = r sin θ.
        let (rc, rs) = (1.0 / k - q.x, q.z);
        let theta = rs.atan2(rc);
        let r = rc.hypot(rs);
        centre + DVec3::new(1.0 / k - r, q.y, theta / k)
    };
    (map, inverse)
}

/// A smooth bump confined to the ball of `radius` mm around `at`: moves
/// points by up to `amp` mm (exactly zero outside the ball).
pub fn bump(at: DVec3, radius: f64, amp: DVec3) -> impl Fn(DVec3) -> DVec3 + Sync {
    move |p| {
        let r2 = (p - at).length_squared() / (radius * radius);
        if r2 >= 1.0 {
            p
        } else {
            p + amp * (1.0 - r2).powi(3)
        }
    }
}
