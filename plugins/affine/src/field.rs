//! The analytic fields, evaluated identically by the rayon path (here) and
//! the WGSL path (`shaders/affine/field.wgsl`): both read the same
//! [`FieldUniforms`] and use the same f32 formulas.

use crate::params::{AffineParams, FieldKind};
use voxflex_core::glam::{DVec3, Vec3};
use voxflex_core::grid::Grid;

/// Field constants for one frame, laid out as the WGSL `array<vec4<f32>, 9>`
/// the kernel reads (u32 values are stored as their bit patterns).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FieldUniforms {
    /// kind (0 affine, 1 twist, 2 bend), axis, towards, mode (0 lattice, 1 list): u32 bits.
    pub header: [u32; 4],
    /// Field centre (mm) and the rate: twist radians per mm, or bend curvature 1/mm.
    pub centre_rate: [f32; 4],
    /// Affine rows `[m0, m1, m2, t]` (t in mm), already blended by the ramp.
    pub rows: [[f32; 4]; 3],
    /// Region ball centre (mm) and radius (mm; 0 = unconfined).
    pub region: [f32; 4],
    /// Lattice origin (mm), unused w.
    pub origin: [f32; 4],
    /// Lattice spacing (mm), unused w.
    pub spacing: [f32; 4],
    /// Lattice dims nx, ny, nz (u32; lattice bindings), w unused (the
    /// points of a dispatch are its `slab`'s).
    pub counts: [u32; 4],
    /// The dispatch's slab of points: its first point and its point count
    /// (u32; the point arrays are bound from that first point on, see
    /// [`FieldUniforms::for_slab`]), unused z, w.
    pub slab: [u32; 4],
}

/// Bytes of [`FieldUniforms`].
pub const UNIFORM_BYTES: usize = std::mem::size_of::<FieldUniforms>();

impl FieldUniforms {
    /// Constants for ramp factor `s` ∈ [0, 1], field centre and the extent
    /// (mm) of the volume along each axis.
    pub fn new(p: &AffineParams, s: f64, centre: DVec3, extent: DVec3) -> Self {
        let axis = p.axis as usize;
        let angle = p.angle_deg.to_radians() * s;
        let len = extent[axis].max(f64::MIN_POSITIVE);
        let rate = match p.field {
            FieldKind::Affine => 0.0,
            FieldKind::Twist | FieldKind::Bend => angle / len,
        };
        let mut rows = [[0f32; 4]; 3];
        for (r, row) in rows.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                let id = if c == r { 1.0 } else { 0.0 };
                *v = (id + s * (p.matrix[r][c] - id)) as f32;
            }
        }
        let region = p.region.map_or([0.0; 4], |g| {
            [
                g.centre[0] as f32,
                g.centre[1] as f32,
                g.centre[2] as f32,
                g.radius as f32,
            ]
        });
        Self {
            header: [
                match p.field {
                    FieldKind::Affine => 0,
                    FieldKind::Twist => 1,
                    FieldKind::Bend => 2,
                },
                p.axis as u32,
                p.towards as u32,
                0,
            ],
            centre_rate: [
                centre.x as f32,
                centre.y as f32,
                centre.z as f32,
                rate as f32,
            ],
            rows,
            region,
            ..Default::default()
        }
    }

    /// Sets the lattice the kernel enumerates (mode 0).
    pub fn with_lattice(mut self, g: &Grid) -> Self {
        self.header[3] = 0;
        self.origin = [g.origin.x as f32, g.origin.y as f32, g.origin.z as f32, 0.0];
        self.spacing = [
            g.spacing.x as f32,
            g.spacing.y as f32,
            g.spacing.z as f32,
            0.0,
        ];
        self.counts = [g.dims[0] as u32, g.dims[1] as u32, g.dims[2] as u32, 0];
        self
    }

    /// These constants for the dispatch over points `first .. first +
    /// count`, whose point and displacement arrays are bound from point
    /// `first` on (a window of each array, so that none exceeds the
    /// device's storage binding limit).
    pub fn for_slab(mut self, first: usize, count: usize) -> Self {
        self.slab = [first as u32, count as u32, 0, 0];
        self
    }

    /// Sets an explicit point list (mode 1).
    pub fn with_list(mut self) -> Self {
        self.header[3] = 1;
        self.counts = [0; 4];
        self
    }

    /// Displacement (mm) of rest point `p` (mm).
    #[inline]
    pub fn displacement(&self, p: Vec3) -> Vec3 {
        let rc = Vec3::new(self.region[0], self.region[1], self.region[2]);
        let radius = self.region[3];
        let mut w = 1.0f32;
        if radius > 0.0 {
            let r2 = (p - rc).length_squared() / (radius * radius);
            if r2 >= 1.0 {
                return Vec3::ZERO;
            }
            let t = 1.0 - r2;
            w = t * t * t;
        }
        let c = Vec3::new(
            self.centre_rate[0],
            self.centre_rate[1],
            self.centre_rate[2],
        );
        let q = p - c;
        let moved = match self.header[0] {
            0 => {
                let row = |r: [f32; 4]| r[0] * q.x + r[1] * q.y + r[2] * q.z + r[3];
                Vec3::new(row(self.rows[0]), row(self.rows[1]), row(self.rows[2]))
            }
            1 => twist(q, self.header[1] as usize, self.centre_rate[3]),
            _ => bend(
                q,
                self.header[1] as usize,
                self.header[2] as usize,
                self.centre_rate[3],
            ),
        };
        (moved - q) * w
    }
}

/// Rotates `q` about world axis `a` by `rate · q[a]` radians.
#[inline]
fn twist(q: Vec3, a: usize, rate: f32) -> Vec3 {
    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
    let theta = rate * q[a];
    let (s, c) = theta.sin_cos();
    let mut out = q;
    out[u] = c * q[u] - s * q[v];
    out[v] = s * q[u] + c * q[v];
    out
}

/// Barr's bend of axis `a` towards axis `b` with curvature `k` (1/mm),
/// written with `sin θ / θ` and `2 sin²(θ/2) / θ` so it stays exact at k → 0.
#[inline]
fn bend(q: Vec3, a: usize, b: usize, k: f32) -> Vec3 {
    let theta = k * q[a];
    let (s, c) = theta.sin_cos();
    let (sinc, versc) = if theta == 0.0 {
        (1.0, 0.0)
    } else {
        let h = (0.5 * theta).sin();
        (s / theta, 2.0 * h * h / theta)
    };
    let mut out = q;
    out[a] = q[a] * sinc - q[b] * s;
    out[b] = q[b] * c + q[a] * versc;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::AffineParams;

    fn uniforms(text: &str, s: f64) -> FieldUniforms {
        let p = AffineParams::from_toml(text).unwrap();
        FieldUniforms::new(&p, s, DVec3::ZERO, DVec3::splat(100.0))
    }

    #[test]
    fn zero_amount_is_exactly_identity() {
        for text in [
            "field = \"twist\"\nangle_deg = 90",
            "field = \"bend\"\nangle_deg = 90",
            "field = \"affine\"\nmatrix = [[2,0,0,5],[0,1,0,0],[0,0,1,0]]",
        ] {
            let u = uniforms(text, 0.0);
            for p in [Vec3::new(1.5, -2.25, 7.0), Vec3::new(-40.0, 33.3, -12.1)] {
                assert_eq!(u.displacement(p), Vec3::ZERO, "{text}");
            }
        }
    }

    #[test]
    fn twist_rotates_by_rate_times_height() {
        let u = uniforms("field = \"twist\"\nangle_deg = 90", 1.0);
        // 90° over 100 mm: at z = 50 mm the rotation is 45°.
        let p = Vec3::new(10.0, 0.0, 50.0);
        let q = p + u.displacement(p);
        let a = std::f32::consts::FRAC_PI_4;
        assert!((q - Vec3::new(10.0 * a.cos(), 10.0 * a.sin(), 50.0)).length() < 1e-4);
    }

    #[test]
    fn bend_maps_axis_onto_an_arc_of_the_right_length() {
        let u = uniforms("field = \"bend\"\nangle_deg = 60", 1.0);
        // Points on the axis keep their arc length: |q(z)| chord of a circle.
        let k = (60f32).to_radians() / 100.0;
        let p = Vec3::new(0.0, 0.0, 30.0);
        let q = p + u.displacement(p);
        let theta = k * 30.0;
        let chord = 2.0 / k * (theta / 2.0).sin();
        assert!((q.length() - chord).abs() < 1e-4, "{q}");
    }

    #[test]
    fn region_confines_the_field() {
        let text = "field = \"twist\"\nangle_deg = 90\nregion = { centre = [0,0,0], radius = 10 }";
        let u = uniforms(text, 1.0);
        assert_eq!(u.displacement(Vec3::new(20.0, 0.0, 20.0)), Vec3::ZERO);
        assert_ne!(u.displacement(Vec3::new(2.0, 0.0, 2.0)), Vec3::ZERO);
    }
}
