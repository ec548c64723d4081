//! The weight of the fluid in a hydraulic cavity (ICRA 2017, section
//! III): per frame, the column-grid weighing of `voxflex-fluid` at the
//! current surface gives the loads `w_i ĝ` on the cavity's vertices, and
//! `w_i ĝ / v_c` — how they grow per mm³ pumped in — the paper's `J_w`,
//! which the host folds into the unified hydraulic constraint.
//!
//! The weighing runs where the scene computes: on the CPU (rayon,
//! `voxflex_fluid::FluidWeigher`) or, when the host offers the plugin a GPU
//! (the scene's backend resolved to `gpu`), with the WGSL kernels
//! (`voxflex_fluid::GpuFluidWeighing`) on the host's shared device.

use std::sync::Arc;
use std::time::Instant;
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::triangle_surface::TriangleSurface;
use voxflex_fluid::{FluidWeigher, FluidWeightParams, FluidWeights, GpuFluidWeighing};

/// The loads of one weighing (µN per vertex, and µN per mm³ per vertex).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Loads {
    /// The fluid's weight on each vertex, µN, along gravity.
    pub loads: Vec<DVec3>,
    /// `loads / fluid volume`: the weight each vertex gains per mm³ of
    /// fluid pumped in (distributed like the fluid now in the cavity).
    pub load_growth: Vec<DVec3>,
}

/// Where a cavity weighs its fluid; each keeps its memory between frames.
pub enum Weigher {
    /// rayon on the CPU.
    Cpu(FluidWeigher),
    /// The WGSL kernels on the host's device.
    Gpu {
        /// The host's GPU service (shared with the deformation model).
        gpu: Arc<dyn GpuService>,
        /// The kernels' state (crossing slots, working memory).
        weighing: GpuFluidWeighing,
    },
}

impl Weigher {
    /// The GPU weigher when `gpu` is offered, else the CPU's.
    pub fn on(gpu: Option<Arc<dyn GpuService>>) -> Self {
        match gpu {
            Some(gpu) => Self::Gpu {
                gpu,
                weighing: GpuFluidWeighing::new(),
            },
            None => Self::Cpu(FluidWeigher::default()),
        }
    }

    /// True on the GPU.
    pub fn is_gpu(&self) -> bool {
        matches!(self, Self::Gpu { .. })
    }

    fn weigh(
        &mut self,
        surface: &TriangleSurface,
        params: &FluidWeightParams,
    ) -> Result<FluidWeights, voxflex_fluid::FluidError> {
        match self {
            Self::Cpu(w) => w.weigh(surface, params),
            Self::Gpu { gpu, weighing } => weighing.weigh(gpu.as_ref(), surface, params),
        }
    }
}

impl std::fmt::Debug for Weigher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Cpu(_) => f.write_str("Weigher::Cpu"),
            Self::Gpu { gpu, .. } => write!(f, "Weigher::Gpu({})", gpu.adapter_description()),
        }
    }
}

/// A cavity's fluid weighing: the weigher (its memory reused every
/// frame), its parameters and what it has seen over the run.
#[derive(Debug)]
pub struct FluidLoad {
    params: FluidWeightParams,
    weigher: Weigher,
    /// Weighings done.
    pub weighings: u64,
    /// Seconds spent weighing, in total.
    pub weighing_s: f64,
    /// The last weighing's total weight, µN.
    pub last_weight: f64,
    /// The last weighing's fluid volume (what its columns hold), mm³.
    pub last_fluid_volume: f64,
    /// The most irregular columns any weighing saw.
    pub irregular_columns_max: usize,
    /// Weighings that saw irregular columns.
    pub irregular_weighings: u64,
}

impl FluidLoad {
    /// A weighing with checked `params` (gravity not zero) on `weigher`.
    pub fn new(params: FluidWeightParams, weigher: Weigher) -> Self {
        Self {
            params,
            weigher,
            weighings: 0,
            weighing_s: 0.0,
            last_weight: 0.0,
            last_fluid_volume: 0.0,
            irregular_columns_max: 0,
            irregular_weighings: 0,
        }
    }

    /// Weighs the fluid filling `surface` (its current positions) and
    /// returns the loads; refuses a cavity that holds no fluid any more.
    pub fn weigh(&mut self, surface: &TriangleSurface) -> Result<Loads, ModelError> {
        let start = Instant::now();
        let w = self
            .weigher
            .weigh(surface, &self.params)
            .map_err(|e| ModelError(format!("cavity: {e}")))?;
        self.weighing_s += start.elapsed().as_secs_f64();
        self.weighings += 1;
        self.last_weight = w.total_weight;
        self.last_fluid_volume = w.volume_mm3;
        self.note_irregular(w.count.irregular_columns);
        if w.volume_mm3.is_nan() || w.volume_mm3 <= 0.0 {
            return Err(ModelError(format!(
                "cavity: the fluid's columns hold {} mm³: the cavity has collapsed or turned \
                 inside out, so the fluid's weight is undefined",
                w.volume_mm3
            )));
        }
        let down = self.params.gravity_m_s2.normalize();
        let loads: Vec<DVec3> = w.node_weights.iter().map(|&n| n * down).collect();
        let load_growth = loads.iter().map(|&l| l / w.volume_mm3).collect();
        Ok(Loads { loads, load_growth })
    }

    /// True when the weighing runs on the GPU.
    pub fn on_gpu(&self) -> bool {
        self.weigher.is_gpu()
    }

    /// Counts irregular columns, warning the first time any are seen.
    fn note_irregular(&mut self, irregular: usize) {
        if irregular == 0 {
            return;
        }
        if self.irregular_weighings == 0 {
            tracing::warn!(
                irregular_columns = irregular,
                columns_per_side = self.params.columns_per_side,
                "cavity: {irregular} fluid columns crossed the surface irregularly (not \
                 bottom, top, bottom, top…): at this grid the deformed cavity is not closed \
                 or folds through itself; their fluid is left out of the weight (warned once \
                 per run; see the notes' irregular_columns_max)"
            );
        }
        self.irregular_weighings += 1;
        self.irregular_columns_max = self.irregular_columns_max.max(irregular);
    }
}
