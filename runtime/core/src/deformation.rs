//! The one trait every deformation model is seen through: a **deformation
//! field** that moves bound rest points.
//!
//! Life cycle, driven by the scene pipeline (and, for plugins, forwarded
//! unchanged across the C ABI by `voxflex-abi`):
//!
//! 1. [`DeformationModel::init`] once, with the source volume and the backend.
//! 2. [`DeformationModel::bind`] once per point set: precompute static mapping
//!    data (containing tetrahedron and barycentric weights, octree cell and
//!    local coordinates, or identity for models whose elements sit on voxels).
//! 3. Every frame: [`DeformationModel::interact`] for the frame's scripted
//!    interactions, [`DeformationModel::step`], and — only when the step
//!    reports a change — [`DeformationModel::dirty_region`] and
//!    [`DeformationModel::map`].
//!
//! **Decision (see docs/DESIGN.md, "Decisions"):** `map` writes *displacements*
//! `u = x − X` in millimetres, not absolute positions. The two carry the same
//! information, but displacements are exactly zero where nothing moved, so
//! the identity field resamples a volume bit-exactly and small motions keep
//! their float precision far from the world origin.

use crate::error::ModelError;
use crate::gpu::BufferId;
use crate::grid::Grid;
use crate::volume::VolumeView;
use glam::DVec3;

/// Where a model computes: the rayon path or the WGSL path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum ExecutionBackend {
    /// rayon on the CPU.
    Cpu = 0,
    /// WGSL compute through the host's [`crate::gpu::GpuService`].
    Gpu = 1,
}

/// The rest points a model binds to.
#[derive(Clone, Copy, Debug)]
pub enum RestPoints<'a> {
    /// Every voxel centre of this grid, x fastest: the vertices of the
    /// implicit sampling mesh. Never materialised as a list.
    Lattice(Grid),
    /// An explicit list of points, world millimetres.
    Points(&'a [[f32; 3]]),
}

impl RestPoints<'_> {
    /// Number of points.
    pub fn len(&self) -> usize {
        match self {
            RestPoints::Lattice(g) => g.len(),
            RestPoints::Points(p) => p.len(),
        }
    }
    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Checks that every explicit point is finite (a lattice always is):
    /// the one validation every `bind` needs.
    pub fn check_finite(&self) -> Result<(), ModelError> {
        if let RestPoints::Points(p) = self
            && p.iter().flatten().any(|v| !v.is_finite())
        {
            return Err(ModelError::new(
                "a rest point is not finite (NaN or infinite)",
            ));
        }
        Ok(())
    }

    /// World position (mm) of point `n`.
    #[inline]
    pub fn point(&self, n: usize) -> DVec3 {
        match self {
            RestPoints::Lattice(g) => {
                let [i, j, k] = g.unlinear(n);
                g.index_to_world(DVec3::new(i as f64, j as f64, k as f64))
            }
            RestPoints::Points(p) => DVec3::new(p[n][0] as f64, p[n][1] as f64, p[n][2] as f64),
        }
    }
}

/// Handle of a binding made by [`DeformationModel::bind`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BindingId(pub u64);

/// Where [`DeformationModel::map`] writes displacements (mm, world axes),
/// structure-of-arrays, one entry per bound point.
pub enum DisplacementTarget<'a> {
    /// CPU slices, each `points.len()` long.
    Cpu {
        /// x displacements, mm.
        x: &'a mut [f32],
        /// y displacements, mm.
        y: &'a mut [f32],
        /// z displacements, mm.
        z: &'a mut [f32],
    },
    /// GPU buffers (host-owned), each holding at least `points.len()` f32.
    Gpu {
        /// x displacements, mm.
        x: BufferId,
        /// y displacements, mm.
        y: BufferId,
        /// z displacements, mm.
        z: BufferId,
    },
}

/// The part of the rest configuration whose mapped displacements changed
/// since the previous `map`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DirtyRegion {
    /// Nothing moved.
    None,
    /// Everything may have moved.
    All,
    /// Only rest points inside this world-space box (mm, inclusive) moved.
    Box {
        /// Lower corner, mm.
        min: DVec3,
        /// Upper corner, mm.
        max: DVec3,
    },
}

impl DirtyRegion {
    /// The smallest region holding both.
    pub fn union(self, other: DirtyRegion) -> DirtyRegion {
        match (self, other) {
            (DirtyRegion::None, o) | (o, DirtyRegion::None) => o,
            (DirtyRegion::All, _) | (_, DirtyRegion::All) => DirtyRegion::All,
            (DirtyRegion::Box { min: a0, max: a1 }, DirtyRegion::Box { min: b0, max: b1 }) => {
                DirtyRegion::Box {
                    min: a0.min(b0),
                    max: a1.max(b1),
                }
            }
        }
    }
}

/// Timing of the frame a model steps to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameInfo {
    /// Frame number, from 0.
    pub frame: u64,
    /// Total frames the scene runs.
    pub frames: u64,
    /// Simulated time step of one frame, seconds.
    pub dt_s: f64,
}

/// What one [`DeformationModel::step`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StepOutcome {
    /// The field changed: downstream stages must re-map and re-resample.
    pub changed: bool,
}

/// Figures a model reports about its own work, by name, for the run's
/// `metrics.json` (under the `model` stage's notes): counts, iterations,
/// residuals. Each name says its unit where it has one. Names hold no tab
/// or line break (they cross the plugin boundary as `name<TAB>value` lines).
pub type ModelNotes = std::collections::BTreeMap<String, f64>;

/// A deformation model seen as a field that moves points.
///
/// Implemented by every deformation plugin, by the host's proxy around a
/// loaded plugin, and by anything in-process that deforms a volume.
pub trait DeformationModel: Send {
    /// Once, before anything else: the source volume (for materials and
    /// proxies) and the backend the model must compute on.
    fn init(&mut self, volume: VolumeView<'_>, backend: ExecutionBackend)
    -> Result<(), ModelError>;
    /// Precomputes static mapping data for a rest point set.
    fn bind(&mut self, rest: RestPoints<'_>) -> Result<BindingId, ModelError>;
    /// Applies one scripted interaction, given as the TOML text of its table
    /// (the model parses it and names the offending key on error).
    ///
    /// Called **before** `init` (on an instance only created), it is a dry
    /// run: the model parses and validates the interaction and applies
    /// nothing. `voxflex validate` checks a scene's interactions this way,
    /// so every error `run` would give for one is given first.
    fn interact(&mut self, interaction_toml: &str) -> Result<(), ModelError>;
    /// Advances one frame.
    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError>;
    /// The rest-space region whose displacements changed since the last `map`.
    fn dirty_region(&self) -> DirtyRegion;
    /// Writes the current displacements (mm) of a binding's points.
    fn map(&mut self, binding: BindingId, out: DisplacementTarget<'_>) -> Result<(), ModelError>;
    /// Topology changes for the resampler: sets the bits of the sampling-mesh
    /// tetrahedra the model removed (cuts, carving) in `cell_bits` — one byte
    /// per cell of a lattice binding's mesh, x fastest, 5 bits as in
    /// `resample::TetMask` — and returns true when it set any that were not
    /// set. An empty `cell_bits` asks only whether the model has removed
    /// any tetrahedron (the host then allocates the array and asks again),
    /// so scenes without cuts never hold a mask. Models without topology
    /// changes keep the default (nothing).
    fn removed_tetrahedra(
        &mut self,
        binding: BindingId,
        cell_bits: &mut [u8],
    ) -> Result<bool, ModelError> {
        let _ = (binding, cell_bits);
        Ok(false)
    }
    /// What the model reports about its work so far (see [`ModelNotes`]);
    /// asked once at the end of a run. Models with nothing to report keep
    /// the default (no notes).
    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        Ok(ModelNotes::new())
    }

    /// **Optional capability (actuators):** sets the external forces (µN,
    /// world axes) on a binding's points, one per point, replacing what
    /// this binding had; they act from the next [`DeformationModel::step`]
    /// on, until set again. A mesh model spreads each force over the
    /// corners of the element holding the point by the point's
    /// barycentric weights — the transpose of its `map`, so the work a
    /// force does is the work of the nodal forces. Models that cannot take
    /// loads keep the default, which refuses ([`NO_ACTUATION`]).
    fn set_point_loads(&mut self, binding: BindingId, forces: &[DVec3]) -> Result<(), ModelError> {
        let _ = (binding, forces);
        Err(ModelError::new(NO_ACTUATION))
    }

    /// **Optional capability (actuators):** the compliance `C f = K⁻¹ f`
    /// with the current tangent stiffness `K` and the current constraints
    /// (fixed and grabbed nodes do not move): the displacements (mm) of a
    /// binding's points under forces (µN) on the same points, written
    /// into `out` (one per point). One linear solve; the state does not
    /// change. Pairs with [`DeformationModel::set_point_loads`]: the
    /// forces are spread and the displacements read by the same weights,
    /// so `C` is symmetric. The default refuses ([`NO_ACTUATION`]).
    fn compliance(
        &mut self,
        binding: BindingId,
        forces: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), ModelError> {
        let _ = (binding, forces, out);
        Err(ModelError::new(NO_ACTUATION))
    }

    /// **Optional capability (actuators):** repeats the last
    /// [`DeformationModel::step`] from the state it started from, with the
    /// point loads as they are set now — the frame's grabs, ramped loads
    /// and clock unchanged. Forces that follow the body (a pressure on the
    /// walls it moves) reach the equilibrium of their effort this way
    /// within one frame. Returns whether the field changed. The default
    /// refuses ([`NO_ACTUATION`]).
    fn resolve(&mut self) -> Result<StepOutcome, ModelError> {
        Err(ModelError::new(NO_ACTUATION))
    }
}

/// What a model without the actuation capability answers
/// [`DeformationModel::set_point_loads`] and
/// [`DeformationModel::compliance`] with (the host names the plugin).
pub const NO_ACTUATION: &str = "this deformation model cannot be actuated (it takes no point loads \
     and has no compliance solve); use a mesh model such as corotational-fem";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rest_points_must_be_finite() {
        let grid = Grid::new([2, 2, 2], DVec3::ONE, DVec3::ZERO);
        assert!(RestPoints::Lattice(grid).check_finite().is_ok());
        assert!(
            RestPoints::Points(&[[0.0, 1.0, 2.0]])
                .check_finite()
                .is_ok()
        );
        let e = RestPoints::Points(&[[0.0, f32::NAN, 2.0]])
            .check_finite()
            .unwrap_err();
        assert!(e.0.contains("not finite"), "{e}");
    }
}
