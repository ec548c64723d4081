//! # voxflex-chainmail — heterogeneous, sparse, parallel 3D ChainMail
//!
//! The thesis's deformation model ("SP-ChainMail", J. Supercomputing 2015;
//! "Parallel deformation of heterogeneous ChainMail models", Comput. Biol.
//! Med. 2016) as a deformation plugin: one element per voxel of the
//! (cropped, down-sampled) volume, linked to its six neighbours; materials
//! from intensity ranges; timestamp propagation with wavefront counters over
//! active blocks, then weighted relaxation, interleaved per frame. The
//! sequential Gibson algorithm is selectable as the baseline.
//!
//! Scene usage:
//!
//! ```toml
//! [model]
//! plugin = "chainmail"
//! [model.params]
//! materials = [
//!   { name = "soft tissue", range = [-200, 300], constraint = 0.15, elastic = 0.8 },
//!   { name = "bone", range = [300, 4000], constraint = 0, rigid = true },
//! ]
//! propagation_iterations = 10   # per frame
//! relaxation_iterations = 10    # per frame
//!
//! [[interaction]]
//! frame = 0
//! kind = "grab"
//! point = [0, 60, 0]   # mm; the nearest element is grabbed
//! by = [0, 15, 0]      # mm, over `frames` frames
//! frames = 4
//! ```
//!
//! The plugin runs on the CPU (rayon) for now; its WGSL path is future
//! work (see the README's known gaps).

pub mod blocks;
pub mod lattice;
pub mod mapping;
pub mod model;
pub mod params;
pub mod propagate;
pub mod relax;
pub mod relax_lanes;
pub mod relax_passes;
pub mod removal;
pub mod state;

#[cfg(test)]
mod tests;

use model::ChainMail;
use params::{ChainMailParams, InteractionSpec};
use voxflex_abi::ffi::CAPABILITY_CPU;
use voxflex_abi::{DeformationPlugin, HostContext};
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    RestPoints, StepOutcome,
};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::VolumeView;

enum Binding {
    Lattice(Grid),
    Points(Vec<[f32; 3]>),
}

/// The `chainmail` plugin's model.
pub struct ChainMailPlugin {
    params: ChainMailParams,
    model: Option<ChainMail>,
    bindings: Vec<Binding>,
    /// Rest-space box (mm) changed since the last `map`.
    dirty: Option<(DVec3, DVec3)>,
    /// Everything must be mapped once after `init`.
    mapped_once: bool,
}

impl ChainMailPlugin {
    /// A plugin instance with parsed parameters; the model is built in `init`.
    pub fn new(params: ChainMailParams) -> Self {
        Self {
            params,
            model: None,
            bindings: Vec::new(),
            dirty: None,
            mapped_once: false,
        }
    }

    /// The model (after `init`).
    pub fn model(&self) -> Option<&ChainMail> {
        self.model.as_ref()
    }

    fn model_mut(&mut self) -> Result<&mut ChainMail, ModelError> {
        self.model
            .as_mut()
            .ok_or_else(|| ModelError::new("chainmail: used before init"))
    }
}

impl DeformationModel for ChainMailPlugin {
    fn init(
        &mut self,
        volume: VolumeView<'_>,
        backend: ExecutionBackend,
    ) -> Result<(), ModelError> {
        if backend == ExecutionBackend::Gpu {
            return Err(ModelError::new(
                "chainmail has no GPU path yet; use backend = \"cpu\" (or \"auto\")",
            ));
        }
        let model = ChainMail::new(volume, self.params.clone())?;
        if model.lattice().element_count() == 0 {
            return Err(ModelError::new(
                "chainmail: no voxel matches any material range; check `materials`",
            ));
        }
        self.model = Some(model);
        Ok(())
    }

    fn bind(&mut self, rest: RestPoints<'_>) -> Result<BindingId, ModelError> {
        rest.check_finite()?;
        self.bindings.push(match rest {
            RestPoints::Lattice(g) => Binding::Lattice(g),
            RestPoints::Points(p) => Binding::Points(p.to_vec()),
        });
        Ok(BindingId(self.bindings.len() as u64 - 1))
    }

    fn interact(&mut self, interaction_toml: &str) -> Result<(), ModelError> {
        let spec = InteractionSpec::from_toml(interaction_toml)?;
        self.model_mut()?.interact(&spec)
    }

    fn step(&mut self, _frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        let model = self.model_mut()?;
        let changed = model.step();
        if let Some((lo, hi)) = model.take_dirty() {
            self.dirty = Some(match self.dirty {
                Some((a, b)) => (a.min(lo), b.max(hi)),
                None => (lo, hi),
            });
        }
        Ok(StepOutcome {
            changed: changed || !self.mapped_once,
        })
    }

    fn dirty_region(&self) -> DirtyRegion {
        if !self.mapped_once {
            return DirtyRegion::All;
        }
        match self.dirty {
            Some((min, max)) => DirtyRegion::Box { min, max },
            None => DirtyRegion::None,
        }
    }

    fn map(&mut self, binding: BindingId, out: DisplacementTarget<'_>) -> Result<(), ModelError> {
        let model = self
            .model
            .as_ref()
            .ok_or_else(|| ModelError::new("chainmail: map before init"))?;
        let DisplacementTarget::Cpu { x, y, z } = out else {
            return Err(ModelError::new(
                "chainmail has no GPU path yet; use backend = \"cpu\"",
            ));
        };
        let b = self
            .bindings
            .get(binding.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", binding.0)))?;
        let n = match b {
            Binding::Lattice(g) => g.len(),
            Binding::Points(p) => p.len(),
        };
        if x.len() != n || y.len() != n || z.len() != n {
            return Err(ModelError(format!(
                "displacement arrays hold {} values but the binding has {n} points",
                x.len()
            )));
        }
        let (lat, state) = (model.lattice(), model.state());
        match b {
            Binding::Lattice(g) if mapping::is_identity(lat, g) => {
                mapping::copy_identity(lat, state, [x, y, z])
            }
            Binding::Lattice(g) => mapping::sample_lattice(lat, state, g, [x, y, z]),
            Binding::Points(p) => {
                for (i, q) in p.iter().enumerate() {
                    let f = mapping::element_coords(
                        lat,
                        DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64),
                    );
                    let u = mapping::sample(lat, state, f);
                    (x[i], y[i], z[i]) = (u[0], u[1], u[2]);
                }
            }
        }
        self.mapped_once = true;
        self.dirty = None;
        Ok(())
    }

    fn removed_tetrahedra(
        &mut self,
        binding: BindingId,
        cell_bits: &mut [u8],
    ) -> Result<bool, ModelError> {
        self.removed(binding, cell_bits)
    }
}

impl ChainMailPlugin {
    fn removed(&mut self, binding: BindingId, cell_bits: &mut [u8]) -> Result<bool, ModelError> {
        let model = self
            .model
            .as_mut()
            .ok_or_else(|| ModelError::new("chainmail: removed_tetrahedra before init"))?;
        match self.bindings.get(binding.0 as usize) {
            // The cuts refer to the source volume's sampling mesh.
            Some(Binding::Lattice(g)) if *g == model.lattice().source => {
                Ok(model.removed_tetrahedra(cell_bits))
            }
            Some(_) => Ok(false),
            None => Err(ModelError(format!("unknown binding id {}", binding.0))),
        }
    }
}

impl DeformationPlugin for ChainMailPlugin {
    const NAME: &'static str = "chainmail";
    const DESCRIPTION: &'static str =
        "heterogeneous sparse parallel 3D ChainMail (timestamps, wavefronts, relaxation)";
    const CAPABILITIES: u32 = CAPABILITY_CPU;

    fn create(params_toml: &str, _host: HostContext) -> Result<Self, ModelError> {
        let params = ChainMailParams::from_toml(params_toml)?;
        tracing::debug!(?params, "chainmail plugin created");
        Ok(Self::new(params))
    }
}

voxflex_abi::export_deformation_plugin!(ChainMailPlugin);
