//! The soft beam the `grab`, `cut` and `two_material` fronts share: a
//! 4m × m × m mm block of 1 mm voxels (m = 12, or 4 with `--quick`), one
//! soft material or ([`Beam::two_material`]) a stiff inclusion in it, its
//! end x = 0 fixed and its end face x = 4m grabbed over [`GRAB_FRAMES`]
//! frames; every voxel centre is a probe point.

use super::runner::{self, Settle};
use voxflex_core::glam::DVec3;
use voxflex_core::volume::{Volume, VoxelData};

/// Frames over which the grab moves.
pub(super) const GRAB_FRAMES: u64 = 10;

/// The beam's material for the mesh models (E = 3000 Pa, ν = 0.3,
/// 1000 kg/m³).
pub(super) const MATERIAL_MESH: &str = "materials = [{ range = [50, 200], youngs_modulus = 3000, poisson_ratio = 0.3, density = 1000 }]";

/// The beam's material for ChainMail (constraint 0.3 of the spacing).
pub(super) const MATERIAL_CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.3 }]";

/// The voxel value of the soft material (inside [`MATERIAL_MESH`]'s range).
const SOFT: i16 = 100;
/// The voxel value of the stiff inclusion (inside [`MATERIALS_TWO_MESH`]'s
/// second range).
const STIFF: i16 = 1000;

/// Young's modulus of the stiff inclusion over the soft beam's (bone in
/// soft tissue is stiffer still; 100 keeps the proxy's conditioning usable).
pub(super) const STIFFNESS_RATIO: f64 = 100.0;

/// The two-material beam's materials for the mesh models: the soft one of
/// [`MATERIAL_MESH`] and the inclusion, [`STIFFNESS_RATIO`] × stiffer
/// (3e5 Pa), same ν and density; labelled by voxel value as a scene's
/// `materials` tables label a CT.
pub(super) const MATERIALS_TWO_MESH: &str = "materials = [\n  { name = \"soft\", range = [50, 200], youngs_modulus = 3000, poisson_ratio = 0.3, density = 1000 },\n  { name = \"stiff\", range = [500, 2000], youngs_modulus = 300000, poisson_ratio = 0.3, density = 1000 },\n]";

/// The two-material beam's materials for ChainMail: the soft one of
/// [`MATERIAL_CHAINMAIL`] and the inclusion, whose links stretch a tenth
/// as far (constraint 0.03 of the spacing).
pub(super) const MATERIALS_TWO_CHAINMAIL: &str = "materials = [\n  { name = \"soft\", range = [50, 200], constraint = 0.3 },\n  { name = \"stiff\", range = [500, 2000], constraint = 0.03 },\n]";

/// A stiff box inside the beam: the voxel centres `p` with `lo < p ≤ hi`
/// on every axis (world mm). With integer bounds this is exactly the
/// region a proxy of step 1 (cells between neighbouring voxel centres,
/// each taking the label of the voxel at its upper corner) gives the
/// stiff material, so the interface lies on the step-1 cells' faces; odd
/// bounds that are not multiples of 3 lie on no cell face of steps 2, 3,
/// 4, 6, 8 or 12, whose cells take one material each.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Inclusion {
    /// Lower bounds (exclusive), mm.
    pub lo: [f64; 3],
    /// Upper bounds (inclusive), mm.
    pub hi: [f64; 3],
}

impl Inclusion {
    /// Whether the point `p` (world mm) is inside.
    pub fn contains(&self, p: DVec3) -> bool {
        (0..3).all(|a| p[a] > self.lo[a] && p[a] <= self.hi[a])
    }
}

/// The beam: geometry, volume, probe points, and the fix at x = 0.
pub(super) struct Beam {
    /// Cross-section voxels a side (the beam is 4m long), 1 mm voxels.
    pub m: usize,
    /// Length (mm): the grabbed face lies at x = `length`.
    pub length: f64,
    /// Width and height (mm).
    pub width: f64,
    /// The block volume, one voxel value inside the material's range.
    pub volume: Volume,
    /// Every voxel centre (world mm): the probe points.
    pub points: Vec<[f32; 3]>,
    /// The stiff inclusion, if any.
    pub inclusion: Option<Inclusion>,
}

impl Beam {
    /// The full beam (m = 12) or the quick one (m = 4), one material.
    pub fn new(quick: bool) -> Self {
        Self::build(quick, None, 1.0)
    }

    /// The beam with a stiff inclusion ([`STIFF`] voxels, the rest
    /// [`SOFT`]) on voxels of `spacing` mm (1 for the fronts' beam; a
    /// divisor of 1 gives the same body on a finer label volume). Full:
    /// x ∈ (13, 35], y ∈ (1, 7], z ∈ (5, 11] mm — a 22 × 6 × 6 mm rod off
    /// the axis in y and z; quick: a layer x ∈ (5, 11], z ∈ (1, 4] across
    /// the 4 mm width (a thinner rod would vanish in every quick proxy).
    pub fn two_material(quick: bool, spacing: f64) -> Self {
        let inclusion = if quick {
            Inclusion {
                lo: [5.0, -1.0, 1.0],
                hi: [11.0, 4.0, 4.0],
            }
        } else {
            Inclusion {
                lo: [13.0, 1.0, 5.0],
                hi: [35.0, 7.0, 11.0],
            }
        };
        Self::build(quick, Some(inclusion), spacing)
    }

    fn build(quick: bool, inclusion: Option<Inclusion>, spacing: f64) -> Self {
        let m: usize = if quick { 4 } else { 12 };
        let n = (1.0 / spacing).round() as usize;
        let mut volume = runner::block([4 * m * n + 1, m * n + 1, m * n + 1], spacing, SOFT);
        if let Some(inc) = inclusion {
            let g = volume.grid;
            let values: Vec<i16> = (0..g.len())
                .map(|l| {
                    let [i, j, k] = g.unlinear(l);
                    let p = g.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
                    if inc.contains(p) { STIFF } else { SOFT }
                })
                .collect();
            volume = Volume::new(g, VoxelData::I16(values)).expect("a beam volume");
        }
        let points = runner::lattice_points(&volume, |_| true);
        Self {
            m,
            length: 4.0 * m as f64,
            width: m as f64,
            volume,
            points,
            inclusion,
        }
    }

    /// How a dynamic run settles: at most `max_frames` more frames (full
    /// run; a quarter with `--quick`), at rest when no probe point moves
    /// 1e-3 mm (1e-2 quick) in 10 frames.
    pub fn settle(&self, quick: bool, max_frames: u64) -> Settle {
        Settle {
            max_frames: if quick { max_frames / 4 } else { max_frames },
            tolerance_mm: if quick { 1e-2 } else { 1e-3 },
            check_every: 10,
        }
    }

    /// The fix of the face x = 0 and a grab of every voxel centre of the
    /// face x = `length` by `by` (mm) over [`GRAB_FRAMES`], all at frame 0,
    /// as interaction TOML.
    pub fn fix_and_grab(&self, by: DVec3) -> Vec<(u64, String)> {
        let mut interactions = vec![(
            0,
            format!(
                "kind = \"fix\"\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, {0}, {0}]",
                self.width + 0.01
            ),
        )];
        let end = self.length;
        for p in runner::lattice_points(&self.volume, |p| (p.x - end).abs() < 1e-6) {
            interactions.push((
                0,
                format!(
                    "kind = \"grab\"\npoint = [{}, {}, {}]\nby = [{}, {}, {}]\nframes = {GRAB_FRAMES}",
                    p[0], p[1], p[2], by.x, by.y, by.z
                ),
            ));
        }
        interactions
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_mesh::proxy::uniform_proxy_with_losses;

    /// Voxels the uniform proxy of `step` gives to the other material
    /// (soft 0, stiff 1, by voxel value as the materials tables do).
    fn lost(beam: &Beam, step: usize) -> usize {
        let g = beam.volume.grid;
        let label = |v: [usize; 3]| {
            let x = beam
                .volume
                .data
                .as_slice()
                .get_f32(g.linear(v[0], v[1], v[2]));
            Some(u16::from(x > 500.0))
        };
        uniform_proxy_with_losses(&g, step, label).unwrap().1
    }

    #[test]
    fn the_inclusion_lies_on_step_one_cell_faces_and_on_no_measured_steps() {
        for quick in [true, false] {
            let beam = Beam::two_material(quick, 1.0);
            let inc = beam.inclusion.unwrap();
            let stiff = beam
                .points
                .iter()
                .filter(|p| inc.contains(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
                .count();
            assert!(stiff > 0, "quick {quick}: no stiff voxel");
            // Step 1, on the 1 mm and the 0.5 mm label volumes: every cell
            // holds one material, so no voxel is lost.
            assert_eq!(lost(&beam, 1), 0, "quick {quick}, 1 mm");
            let fine = Beam::two_material(quick, 0.5);
            assert_eq!(fine.volume.grid.dims[0], 2 * beam.volume.grid.dims[0] - 1);
            assert_eq!(lost(&fine, 1), 0, "quick {quick}, 0.5 mm");
            // Every measured coarser step cuts across the inclusion.
            let steps: &[usize] = if quick {
                &[2, 4, 8]
            } else {
                &[2, 3, 4, 6, 8, 12]
            };
            for &s in steps {
                assert!(lost(&beam, s) > 0, "quick {quick}, step {s}");
            }
        }
        // One material: nothing to lose.
        assert_eq!(lost(&Beam::new(true), 4), 0);
    }
}
