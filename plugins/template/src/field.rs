//! STEP 3: the deformation itself, as one function of a rest point — the
//! rayon path calls it per point, and `shaders/template/bulge.wgsl`
//! computes the same formula in the same f32 operations, so the two paths
//! agree to rounding (the parity test holds them to 1e-5 mm).
//!
//! A model with state (a solver) keeps that state in its model struct and
//! maps it here; the shape stays: one `#[repr(C)]` block of constants both
//! paths read, one displacement function.

use crate::params::TemplateParams;
use voxflex_core::glam::{DVec3, Vec3};
use voxflex_core::grid::Grid;

/// The constants of one frame, laid out exactly as the WGSL `Uniforms`
/// struct (vec4 rows; u32 fields as u32). Change both together.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FieldUniforms {
    /// Ball centre (world mm) and radius (mm).
    pub centre_radius: [f32; 4],
    /// x: the ramped amplitude (mm); y, z, w unused.
    pub amplitude: [f32; 4],
    /// Lattice origin (world mm), w unused (lattice bindings only).
    pub origin: [f32; 4],
    /// Lattice spacing (mm), w unused (lattice bindings only).
    pub spacing: [f32; 4],
    /// Lattice dims nx, ny, nz (lattice bindings), w unused (the points of
    /// a dispatch are its slab's, in `mode`).
    pub counts: [u32; 4],
    /// x: 0 = the points are every node of the lattice, 1 = an explicit
    /// list (the kernel reads them from its point buffers); y, z: the
    /// dispatch's slab of points, its first point and its point count
    /// ([`FieldUniforms::for_slab`]); w unused.
    pub mode: [u32; 4],
}

/// Bytes of [`FieldUniforms`].
pub const UNIFORM_BYTES: usize = std::mem::size_of::<FieldUniforms>();

impl FieldUniforms {
    /// Constants for ramp factor `s` ∈ [0, 1] and the ball centre (mm).
    pub fn new(p: &TemplateParams, s: f64, centre: DVec3) -> Self {
        Self {
            centre_radius: [
                centre.x as f32,
                centre.y as f32,
                centre.z as f32,
                p.radius_mm as f32,
            ],
            amplitude: [(p.amplitude_mm * s) as f32, 0.0, 0.0, 0.0],
            ..Default::default()
        }
    }

    /// The same constants, enumerating every node of lattice `g` (mode 0).
    pub fn with_lattice(mut self, g: &Grid) -> Self {
        self.mode[0] = 0;
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

    /// The same constants for the dispatch over points `first .. first +
    /// count`, whose point and displacement arrays are bound from point
    /// `first` on: windows of each array, so that none exceeds the device's
    /// storage binding limit (`voxflex_core::point_slabs`).
    pub fn for_slab(mut self, first: usize, count: usize) -> Self {
        self.mode[1] = first as u32;
        self.mode[2] = count as u32;
        self
    }

    /// The same constants, for an explicit list of points (mode 1).
    pub fn with_list(mut self) -> Self {
        self.mode[0] = 1;
        self.counts = [0; 4];
        self
    }

    /// Rest position (world mm) of lattice node `n`, in the f32 operations
    /// the kernel uses.
    #[inline]
    pub fn lattice_point(&self, n: usize) -> Vec3 {
        let (nx, ny) = (self.counts[0] as usize, self.counts[1] as usize);
        let index = Vec3::new(
            (n % nx) as f32,
            ((n / nx) % ny) as f32,
            (n / (nx * ny)) as f32,
        );
        Vec3::from_slice(&self.origin[..3]) + index * Vec3::from_slice(&self.spacing[..3])
    }

    /// Displacement (mm, world axes) of rest point `p` (world mm):
    /// `a · (p − c)/R · (1 − |p − c|²/R²)²` inside the ball, 0 outside. It
    /// is 0 at the centre and on the sphere, and C¹ across it.
    #[inline]
    pub fn displacement(&self, p: Vec3) -> Vec3 {
        let c = Vec3::from_slice(&self.centre_radius[..3]);
        let radius = self.centre_radius[3];
        let q = (p - c) / radius;
        let t2 = q.length_squared();
        if t2 >= 1.0 {
            return Vec3::ZERO;
        }
        let w = 1.0 - t2;
        q * (self.amplitude[0] * w * w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniforms(text: &str, s: f64) -> FieldUniforms {
        let p = TemplateParams::from_toml(text).unwrap();
        FieldUniforms::new(&p, s, DVec3::new(1.0, 2.0, 3.0))
    }

    #[test]
    fn nothing_moves_outside_the_ball_at_the_centre_or_at_zero_ramp() {
        let u = uniforms("radius_mm = 10\namplitude_mm = 5", 1.0);
        for p in [Vec3::new(12.0, 2.0, 3.0), Vec3::new(1.0, 2.0, -7.0)] {
            assert_eq!(u.displacement(p), Vec3::ZERO, "{p}");
        }
        assert_eq!(u.displacement(Vec3::new(1.0, 2.0, 3.0)), Vec3::ZERO);
        let u0 = uniforms("radius_mm = 10\namplitude_mm = 5", 0.0);
        assert_eq!(u0.displacement(Vec3::new(3.0, 2.0, 3.0)), Vec3::ZERO);
    }

    #[test]
    fn points_move_radially_by_the_formula_and_the_peak_is_where_documented() {
        let u = uniforms("radius_mm = 10\namplitude_mm = 5", 1.0);
        // 4 mm out along +x: t = 0.4, move 5 · 0.4 · (1 − 0.16)² = 1.4112 mm.
        let d = u.displacement(Vec3::new(5.0, 2.0, 3.0));
        assert!((d - Vec3::new(1.4112, 0.0, 0.0)).length() < 1e-5, "{d}");
        // The largest move is 0.286 · amplitude, at t = 1/√5.
        let peak = (0..=1000)
            .map(|i| u.displacement(Vec3::new(1.0 + i as f32 * 0.01, 2.0, 3.0)).x)
            .fold(0f32, f32::max);
        assert!((peak / 5.0 - 0.2862).abs() < 1e-3, "{peak}");
        // A negative amplitude dents.
        let dent = uniforms("radius_mm = 10\namplitude_mm = -5", 1.0);
        assert!(dent.displacement(Vec3::new(5.0, 2.0, 3.0)).x < 0.0);
    }

    #[test]
    fn the_ramp_scales_the_field_linearly() {
        let full = uniforms("radius_mm = 10\namplitude_mm = 5", 1.0);
        let half = uniforms("radius_mm = 10\namplitude_mm = 5", 0.5);
        let p = Vec3::new(4.0, 5.0, 1.0);
        assert!((full.displacement(p) * 0.5 - half.displacement(p)).length() < 1e-6);
    }
}
