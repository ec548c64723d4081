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
//! Both paths live here: rayon (8-wide kernels over the red-black storage
//! order) and WGSL (`gpu.rs`, `shaders/chainmail/chainmail.wgsl`) over the
//! same layout, chosen by the scene's `backend`.

#![warn(missing_docs)]

pub mod blocks;
pub mod conflicts;
pub mod gpu;
pub mod gpu_schedule;
pub mod lattice;
pub mod mapping;
pub mod model;
pub mod params;
pub mod propagate;
pub mod relax;
pub mod relax_lanes;
pub mod relax_passes;
pub mod removal;
pub mod row_moves;
pub mod run_log;
#[cfg(any(test, feature = "test-support"))]
pub mod scenes;
pub mod state;

#[cfg(test)]
mod conflict_tests;
#[cfg(test)]
mod gpu_tests;
#[cfg(test)]
mod rest_tests;
#[cfg(test)]
mod tests;

use model::ChainMail;
use params::{ChainMailParams, InteractionSpec};
use std::sync::Arc;
use voxflex_abi::ffi::{CAPABILITY_CPU, CAPABILITY_GPU};
use voxflex_abi::{DeformationPlugin, HostContext};
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    ModelNotes, RestPoints, StepOutcome,
};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferId, GpuService};
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
    /// The host's GPU service, if it offered one.
    gpu: Option<Arc<dyn GpuService>>,
}

impl ChainMailPlugin {
    /// A plugin instance with parsed parameters; the model is built in `init`.
    pub fn new(params: ChainMailParams, gpu: Option<Arc<dyn GpuService>>) -> Self {
        Self {
            params,
            model: None,
            bindings: Vec::new(),
            dirty: None,
            mapped_once: false,
            gpu,
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
        let mut model = ChainMail::new(volume, self.params.clone())?;
        if model.lattice().element_count() == 0 {
            return Err(ModelError::new(
                "chainmail: no voxel matches any material range; check `materials`",
            ));
        }
        if backend == ExecutionBackend::Gpu {
            let gpu = self.gpu.clone().ok_or_else(|| {
                ModelError::new("chainmail: backend is gpu but the host offered no GPU service")
            })?;
            model.use_gpu(gpu)?;
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
        match self.model.as_mut() {
            Some(model) => model.interact(&spec),
            // Before init: a dry run (parsed and validated, nothing applied).
            None => Ok(()),
        }
    }

    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        let model = self.model_mut()?;
        let changed = model.step();
        if frame.frame + 1 == frame.frames {
            model.warn_if_not_at_rest();
        }
        if let Some(e) = model.take_gpu_error() {
            return Err(e);
        }
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
            .as_mut()
            .ok_or_else(|| ModelError::new("chainmail: map before init"))?;
        let b = self
            .bindings
            .get(binding.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", binding.0)))?;
        let n = match b {
            Binding::Lattice(g) => g.len(),
            Binding::Points(p) => p.len(),
        };
        match out {
            DisplacementTarget::Cpu { x, y, z } => {
                if x.len() != n || y.len() != n || z.len() != n {
                    return Err(ModelError(format!(
                        "displacement arrays hold {} values but the binding has {n} points",
                        x.len()
                    )));
                }
                model.pull()?;
                map_cpu(model, b, [x, y, z]);
            }
            DisplacementTarget::Gpu { x, y, z } => {
                let identity =
                    matches!(b, Binding::Lattice(g) if mapping::is_identity(model.lattice(), g));
                if identity && model.on_gpu() {
                    model.map_identity_gpu([x, y, z])?;
                } else {
                    // Interpolated bindings are mapped on the CPU and
                    // uploaded (the identity binding is the one a scene
                    // renders at full resolution).
                    let gpu = self.gpu.as_ref().ok_or_else(|| {
                        ModelError::new("chainmail: a GPU target but no GPU service")
                    })?;
                    model.pull()?;
                    let mut cols = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
                    let [cx, cy, cz] = &mut cols;
                    map_cpu(model, b, [cx, cy, cz]);
                    for (col, id) in cols.iter().zip([x, y, z]) {
                        upload_into(gpu.as_ref(), id, col)?;
                    }
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

    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        Ok(self
            .model
            .as_ref()
            .map(ChainMail::notes)
            .unwrap_or_default())
    }
}

/// Maps the model's current (CPU) displacements onto a binding's points.
fn map_cpu(model: &ChainMail, b: &Binding, [x, y, z]: [&mut [f32]; 3]) {
    let (lat, state) = (model.lattice(), model.state());
    match b {
        Binding::Lattice(g) if mapping::is_identity(lat, g) => {
            mapping::copy_identity(lat, state, [x, y, z])
        }
        Binding::Lattice(g) => mapping::sample_lattice(lat, state, g, [x, y, z]),
        Binding::Points(p) => {
            for (i, q) in p.iter().enumerate() {
                let f =
                    mapping::element_coords(lat, DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64));
                let u = mapping::sample(lat, state, f);
                (x[i], y[i], z[i]) = (u[0], u[1], u[2]);
            }
        }
    }
}

/// Writes `values` at the start of a host buffer.
fn upload_into(gpu: &dyn GpuService, id: BufferId, values: &[f32]) -> Result<(), ModelError> {
    gpu.write_buffer(id, 0, bytemuck::cast_slice(values))
        .map_err(|e| ModelError(format!("chainmail: writing displacements to the GPU: {e}")))
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

impl voxflex_abi::DeclaresParams for ChainMailPlugin {
    fn params_schema() -> Result<String, String> {
        voxflex_abi::params_schema::json(&schemars::schema_for!(params::ChainMailParams))
    }
}

impl DeformationPlugin for ChainMailPlugin {
    const NAME: &'static str = "chainmail";
    const DESCRIPTION: &'static str =
        "heterogeneous sparse parallel 3D ChainMail (timestamps, wavefronts, relaxation)";
    const CAPABILITIES: u32 = CAPABILITY_CPU | CAPABILITY_GPU;

    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError> {
        let params = ChainMailParams::from_toml(params_toml)?;
        tracing::debug!(?params, "chainmail plugin created");
        Ok(Self::new(params, host.gpu()))
    }
}

voxflex_abi::export_deformation_plugin!(ChainMailPlugin);
