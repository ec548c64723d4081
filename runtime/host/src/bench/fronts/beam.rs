//! The soft beam the `grab` and `cut` fronts share: a 4m × m × m mm block
//! of 1 mm voxels (m = 12, or 4 with `--quick`), one soft material, its
//! end x = 0 fixed and its end face x = 4m grabbed over [`GRAB_FRAMES`]
//! frames; every voxel centre is a probe point.

use super::runner::{self, Settle};
use voxflex_core::glam::DVec3;
use voxflex_core::volume::Volume;

/// Frames over which the grab moves.
pub(super) const GRAB_FRAMES: u64 = 10;

/// The beam's material for the mesh models (E = 3000 Pa, ν = 0.3,
/// 1000 kg/m³).
pub(super) const MATERIAL_MESH: &str = "materials = [{ range = [50, 200], youngs_modulus = 3000, poisson_ratio = 0.3, density = 1000 }]";

/// The beam's material for ChainMail (constraint 0.3 of the spacing).
pub(super) const MATERIAL_CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.3 }]";

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
}

impl Beam {
    /// The full beam (m = 12) or the quick one (m = 4).
    pub fn new(quick: bool) -> Self {
        let m: usize = if quick { 4 } else { 12 };
        let volume = runner::block([4 * m + 1, m + 1, m + 1], 1.0, 100);
        let points = runner::lattice_points(&volume, |_| true);
        Self {
            m,
            length: 4.0 * m as f64,
            width: m as f64,
            volume,
            points,
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
