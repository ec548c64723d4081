//! The deformation stages of a session — model, map, resample — built
//! only when the session has a model: the plugin instance, its binding of
//! the source lattice, the displacement field (CPU arrays or GPU buffers)
//! and the resampler with its tetrahedron mask.

use super::model_call::ModelCall;
use super::tracked::TrackId;
use crate::pipeline::RunError;
use crate::plugin_loader::LoadedPlugin;
use std::sync::Arc;
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, RestPoints,
};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{BufferId, GpuService};
use voxflex_core::grid::Grid;
use voxflex_core::volume::Volume;
use voxflex_resample::gpu::GpuSource;
use voxflex_resample::{
    DisplacementsRef, ResampleOutput, ResampleParams, ResampleReport, Resampler, TetMask,
};

/// Where the resampler reads displacements from (mm, one value per source
/// voxel and axis).
pub(crate) enum Displacements {
    /// Three f32 arrays on the CPU.
    Cpu([Vec<f32>; 3]),
    /// Three GPU buffers and the source volume uploaded beside them.
    Gpu {
        disp: [BufferId; 3],
        source: GpuSource,
    },
}

impl Displacements {
    /// Zero displacements for `source` on `backend`.
    pub(crate) fn new(
        source: &Volume,
        backend: ExecutionBackend,
        gpu: &Option<Arc<dyn GpuService>>,
    ) -> Result<Self, RunError> {
        let n = source.grid.len();
        Ok(match (backend, gpu) {
            (ExecutionBackend::Gpu, Some(gpu)) => Displacements::Gpu {
                disp: [
                    gpu.create_buffer(n as u64 * 4, "displacement x")?,
                    gpu.create_buffer(n as u64 * 4, "displacement y")?,
                    gpu.create_buffer(n as u64 * 4, "displacement z")?,
                ],
                source: GpuSource::upload(gpu.as_ref(), source.view())?,
            },
            _ => Displacements::Cpu([vec![0.0; n], vec![0.0; n], vec![0.0; n]]),
        })
    }

    /// The `n` displacements of each axis as CPU arrays (read back from
    /// the GPU there), mm.
    pub(crate) fn to_cpu(
        &self,
        n: usize,
        gpu: &Option<Arc<dyn GpuService>>,
    ) -> Result<[Vec<f32>; 3], RunError> {
        match (self, gpu) {
            (Displacements::Cpu(d), _) => Ok(d.clone()),
            (Displacements::Gpu { disp, .. }, Some(gpu)) => {
                let mut out: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0f32; n]);
                for (id, v) in disp.iter().zip(out.iter_mut()) {
                    gpu.read_buffer(*id, 0, bytemuck::cast_slice_mut(v))?;
                }
                Ok(out)
            }
            (Displacements::Gpu { .. }, None) => {
                Err(RunError::Other("GPU displacements without a GPU".into()))
            }
        }
    }

    /// Frees the GPU buffers (a no-op on the CPU).
    pub(crate) fn release(&self, gpu: &Option<Arc<dyn GpuService>>) {
        if let (Displacements::Gpu { disp, source }, Some(gpu)) = (self, gpu) {
            disp.iter().for_each(|&id| gpu.destroy_buffer(id));
            source.release(gpu.as_ref());
        }
    }
}

/// The model stage's plugin instance and what it maps into.
pub(crate) struct ModelStage {
    /// The plugin it came from.
    pub(crate) plugin: LoadedPlugin,
    /// The TOML text of its parameters.
    pub(crate) params_toml: String,
    pub(crate) model: Box<dyn DeformationModel>,
    pub(crate) binding: BindingId,
    /// The session's tracked point sets bound on this model.
    pub(crate) tracked: Vec<(TrackId, BindingId)>,
    /// Tetrahedra the model removed (cuts, carving); allocated when the
    /// model first reports one, with the cell bytes it writes into.
    pub(crate) mask: Option<(TetMask, Vec<u8>)>,
    pub(crate) source_grid: Grid,
    /// The model's own clock: frames it has stepped (0 when created).
    pub(crate) frame: u64,
    /// The interactions it received, each with the frame of its clock it
    /// was received before (see [`super::Session::interactions_so_far`]).
    pub(crate) received: Vec<AppliedInteraction>,
}

/// An interaction a session's model received: what a scene's
/// `[[interaction]]` table with `frame` replays.
#[derive(Clone, Debug, PartialEq)]
pub struct AppliedInteraction {
    /// The model's frame (from 0, its own clock) the interaction was
    /// received before: the scene's `frame` key.
    pub frame: u64,
    /// The interaction as the plugin received it (scene TOML, without
    /// `frame`).
    pub toml: String,
}

impl ModelStage {
    /// Creates, initialises and binds an instance of `plugin` on `source`.
    pub(crate) fn new(
        context: &str,
        plugin: &LoadedPlugin,
        params_toml: &str,
        services: Arc<HostServices>,
        source: &Volume,
        backend: ExecutionBackend,
    ) -> Result<Self, RunError> {
        let vtable = plugin.deformation.ok_or_else(|| {
            RunError::Other(format!(
                "{context}: plugin `{}` is a {} plugin; [model] needs a deformation plugin",
                plugin.name,
                plugin.kind_name()
            ))
        })?;
        plugin
            .check_params(params_toml)
            .map_err(ModelCall::Create.failed())?;
        // SAFETY: the vtable comes from a checked, never-unloaded library.
        let mut model =
            unsafe { DeformationProxy::create(&plugin.name, vtable, params_toml, services) }
                .map_err(ModelCall::Create.failed())?;
        model
            .init(source.view(), backend)
            .map_err(ModelCall::Init.failed())?;
        let binding = model
            .bind(RestPoints::Lattice(source.grid))
            .map_err(ModelCall::Bind.failed())?;
        Ok(Self {
            plugin: plugin.clone(),
            params_toml: params_toml.to_owned(),
            model: Box::new(model),
            binding,
            tracked: vec![],
            mask: None,
            source_grid: source.grid,
            frame: 0,
            received: vec![],
        })
    }

    /// Maps the model's displacements into `displacements`.
    pub(crate) fn map(&mut self, displacements: &mut Displacements) -> Result<(), RunError> {
        let target = match displacements {
            Displacements::Cpu([x, y, z]) => DisplacementTarget::Cpu { x, y, z },
            Displacements::Gpu {
                disp: [x, y, z], ..
            } => DisplacementTarget::Gpu {
                x: *x,
                y: *y,
                z: *z,
            },
        };
        self.model
            .map(self.binding, target)
            .map_err(ModelCall::Map.failed())?;
        Ok(())
    }

    /// Asks the model for removed tetrahedra (after a map); returns true
    /// when the mask changed. An empty array asks only whether there are
    /// any, so models without topology changes never allocate a mask.
    pub(crate) fn update_mask(&mut self) -> Result<bool, RunError> {
        if self.mask.is_none() {
            if !self
                .model
                .removed_tetrahedra(self.binding, &mut [])
                .map_err(ModelCall::RemovedTetrahedra.failed())?
            {
                return Ok(false);
            }
            let mask = TetMask::new(&self.source_grid)?;
            let bytes = vec![0u8; mask.cell_count()];
            self.mask = Some((mask, bytes));
        }
        let (mask, bytes) = self.mask.as_mut().expect("allocated above");
        if !self
            .model
            .removed_tetrahedra(self.binding, bytes)
            .map_err(ModelCall::RemovedTetrahedra.failed())?
        {
            return Ok(false);
        }
        Ok(mask.replace_bits(bytes)?)
    }
}

/// The resample stage: the resampler and its parameters.
pub(crate) struct ResampleStage {
    pub(crate) resampler: Resampler,
}

impl ResampleStage {
    /// A resampler with `params`.
    pub(crate) fn new(params: ResampleParams) -> Self {
        Self {
            resampler: Resampler::new(params),
        }
    }

    /// Resamples `source` under `displacements` over the dirty region.
    pub(crate) fn run(
        &mut self,
        source: &Volume,
        displacements: &Displacements,
        mask: Option<&TetMask>,
        gpu: &Option<Arc<dyn GpuService>>,
        dirty: DirtyRegion,
        wait_for_gpu: bool,
    ) -> Result<ResampleReport, RunError> {
        let report = match (displacements, gpu) {
            (Displacements::Cpu([x, y, z]), _) => self.resampler.resample_cpu(
                source.view(),
                DisplacementsRef { x, y, z },
                mask,
                dirty,
            )?,
            (Displacements::Gpu { disp, source }, Some(gpu)) => {
                let r = self
                    .resampler
                    .resample_gpu(gpu.as_ref(), source, *disp, mask, dirty)?;
                if wait_for_gpu && let Some(b) = self.resampler.gpu_output_buffer() {
                    // One value read back: the queue has run to here.
                    let mut probe = [0f32; 1];
                    gpu.read_buffer(b, 0, bytemuck::cast_slice_mut(&mut probe))?;
                }
                r
            }
            (Displacements::Gpu { .. }, None) => {
                return Err(RunError::Other("GPU displacements without a GPU".into()));
            }
        };
        Ok(report)
    }

    /// The resampled values, read back from the GPU when they live there.
    pub(crate) fn read_back(
        &self,
        displacements: &Displacements,
        gpu: &Option<Arc<dyn GpuService>>,
    ) -> Result<ResampleOutput, RunError> {
        match (displacements, gpu) {
            (Displacements::Gpu { .. }, Some(gpu)) => {
                Ok(self.resampler.read_gpu_output(gpu.as_ref())?)
            }
            _ => self
                .resampler
                .cpu_output()
                .ok_or_else(|| RunError::Other("no resampled output yet".into())),
        }
    }
}

/// The world box (mm) of the output voxels a resample re-filled.
pub(crate) fn refilled_region(report: &ResampleReport, output: Option<Grid>) -> DirtyRegion {
    match (
        report.full || report.output_grid_changed,
        report.region,
        output,
    ) {
        (false, Some((lo, hi)), Some(g)) => {
            let f = |v: [usize; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
            DirtyRegion::Box {
                min: g.index_to_world(f(lo)),
                max: g.index_to_world(f(hi)),
            }
        }
        (false, None, Some(_)) => DirtyRegion::None,
        _ => DirtyRegion::All,
    }
}
