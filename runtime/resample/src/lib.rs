//! # voxflex-resample
//!
//! Its own crate because only the host, ChainMail (the sampling mesh's
//! tetrahedra) and the mesh-model framework (cut and carve topology, the
//! proxy's cell split) use it: the renderer, the affine plugin and the ABI
//! do not recompile when a kernel changes. Test support (the CPU/GPU
//! `parity` checks) is behind the `test-support` feature.
//!
//! The resampling service: turns a source volume plus a displacement field
//! on its voxel centres into a regular output volume, on the CPU (rayon) or
//! the GPU (WGSL through [`GpuService`]).
//!
//! The method is the parallel resampling of *"A parallel resampling method
//! for interactive deformation of volumetric models"* (Computers & Graphics
//! 2015):
//!
//! 1. **Implicit sampling mesh** ([`sampling_mesh`]): one vertex per source
//!    voxel centre, each hexahedral cell split into 5 tetrahedra (mirrored
//!    on odd cells so the mesh is conforming). Never stored.
//! 2. **Deformed vertex** `(i, j, k) + u / spacing` in source voxel index
//!    units, `u` the displacement in millimetres (world axes).
//! 3. **Output grid** ([`output_grid`]): the source's spacing and axes, its
//!    origin an integer number of voxels away, grown (never shrunk) to cover
//!    the deformed mesh. Voxels outside every tetrahedron get
//!    [`ResampleParams::background`].
//! 4. **Two-pass deterministic rasterisation** ([`raster`]): pass 1 runs per
//!    cell, gives every output voxel centre in the cell's deformed bounding
//!    box to the containing tetrahedron of the cell with the smallest *owner
//!    key* and keeps the smallest key per voxel; pass 2 turns each voxel's
//!    owner into the value interpolated with the owner's barycentric
//!    weights: the owner's vertex values ([`Interpolation::Tetrahedral`],
//!    the paper's) or a trilinear sample of the source at the barycentric
//!    rest position ([`Interpolation::Trilinear`]; see [`interpolation`]).
//!    The GPU runs the passes as the paper does — `atomicMin` of the key
//!    into the output viewed as `u32`, then a pass per voxel replacing the
//!    key by the value; the CPU fuses them per output tile (see [`cpu`]):
//!    the claims go into a tile's own key and payload arrays without
//!    atomics, the winning claim's payload is computed from the face values
//!    pass 1 already has (the same bits pass 2 computes), and every output
//!    word is written once. The key is the
//!    tetrahedron id with [`sampling_mesh::WEAK_OWNER`] set on weak claims (a
//!    tetrahedron that did not move, is inverted, or touches the centre only
//!    at a still vertex), so where the deformed mesh overlaps itself moved
//!    tissue wins over the still air and inverted cells beneath it, in every
//!    direction; the smallest id decides among equal claims (shared faces).
//!    The result does not depend on thread timing or tiling and is the same
//!    on CPU and GPU. An unmoved voxel reproduces its source value bit for
//!    bit in both modes.
//! 5. **Removed tetrahedra** ([`TetMask`]) are skipped (cuts).
//! 6. **Dirty-region resampling** ([`plan`]): after a localised change only
//!    the output box `R` that the moved cells covered before or cover now is
//!    re-rasterised (every cell block whose deformed box meets `R`, clipped
//!    to `R`) and re-filled. The result equals a full resample bit
//!    for bit.
//!
//! The CPU ([`cpu`]) and GPU ([`gpu`]) paths share everything but the
//! kernels: parameters, tables, output sizing, the block bounds and the
//! dirty-region plan live here and in the sibling modules.
//!
//! ## Memory (CPU path)
//!
//! Beyond the source volume and the output (4 bytes per output voxel): the
//! caller's displacements (12 bytes per voxel), the optional [`TetMask`]
//! (1 byte per cell, only once something is removed), and the block bounds
//! (24 bytes per 64 cells, 0.375 byte per voxel); per call, the blocks
//! binned to output tiles (4 bytes per block and tile it meets, about
//! 0.1 byte per voxel) and per thread one tile's keys and payloads
//! (640 KiB). Nothing else per voxel: at most 13.5 bytes per voxel beyond
//! source and output.
//!
//! ## GPU path
//!
//! Source values (as f32), each displacement array and the output must each
//! fit one buffer (`max_buffer_size`), not one storage binding
//! ([`voxflex_core::gpu::GpuLimits::max_storage_buffer_binding_size`],
//! 128 MiB on lavapipe: 32 Mi voxels): larger arrays are bound as z-slabs
//! at aligned offsets — the output in runs of output planes, the source in
//! runs of whole cell blocks plus a halo of vertex planes, each kernel run
//! per source slab, with a filled bit per output voxel (4 bytes per 32
//! output voxels, only while the source is split). The result does not
//! depend on the split (bit for bit); a trilinear sample beyond its source
//! slab's halo (only in nearly degenerate tetrahedra) fails the call with
//! [`ResampleError::SlabHaloExceeded`] rather than read elsewhere. The deformed block
//! bounds are computed on the GPU by a workgroup reduction (atomic min/max
//! on order-preserving `u32` encodings of the f32 coordinates) and read back
//! (24 bytes per 64 cells) so the CPU can size the output and plan the
//! dirty region. See [`gpu`].

#![warn(missing_docs)]

pub mod accuracy;
pub mod blocks;
mod counters;
pub mod cpu;
pub mod fields;
mod fill_lanes;
pub mod gpu;
pub mod interpolation;
mod lanes;
pub mod output_grid;
#[cfg(any(test, feature = "test-support"))]
pub mod parity;
#[cfg(any(test, feature = "test-support"))]
pub mod parity_slabs;
pub mod plan;
pub mod raster;
pub mod sampling_mesh;
pub mod tet_mask;

#[cfg(test)]
mod tests;

pub use counters::{RasterCounts, last_raster_counts};
pub use interpolation::Interpolation;
pub use output_grid::{OutputGrid, VoxelBox};
pub use sampling_mesh::SamplingMesh;
pub use tet_mask::{TetMask, tets_at_vertex, tets_cut_by, tets_on_edge};

// The voxflex-core modules this crate builds on, imported at the root so
// `crate::grid`, `crate::volume`, ... read as they did when resampling was
// a module of voxflex-core.
use voxflex_core::{cut_polygon, deformation, error, grid, volume, with_voxels};

use crate::deformation::DirtyRegion;
use crate::error::GpuError;
use crate::grid::Grid;
use crate::volume::VolumeView;
use blocks::{BlockBounds, BlockLayout};
use plan::MaskState;
use voxflex_core::gpu::{BufferId, GpuService};

/// A resampling call failed. Nothing is half-written: after an error the
/// next call resamples in full.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ResampleError {
    /// The source grid has fewer than 2 voxels along some axis, so the
    /// sampling mesh has no cell.
    #[error("resampling needs at least 2 voxels along each axis, the source grid has {dims:?}")]
    GridTooSmall {
        /// Source grid dimensions.
        dims: [usize; 3],
    },
    /// The sampling mesh has more tetrahedra than a `u32` id can name.
    #[error(
        "source grid {dims:?} has {tetrahedra} sampling tetrahedra, more than the u32 ids allow \
         (about 859 million cells, e.g. 950³ voxels); crop or downsample the volume"
    )]
    TooManyCells {
        /// Source grid dimensions.
        dims: [usize; 3],
        /// Tetrahedra the mesh would have.
        tetrahedra: u64,
    },
    /// An input's length does not match the source grid.
    #[error("{what} has {actual} values but the source grid {dims:?} needs {expected}")]
    SizeMismatch {
        /// The input at fault.
        what: &'static str,
        /// Source grid dimensions.
        dims: [usize; 3],
        /// Values needed.
        expected: usize,
        /// Values supplied.
        actual: usize,
    },
    /// The source spacing is not positive and finite.
    #[error("source spacing {spacing:?} mm must be positive and finite")]
    BadSpacing {
        /// The spacing, mm.
        spacing: [f64; 3],
    },
    /// A displacement is NaN or infinite.
    #[error(
        "the displacement field holds a non-finite value (NaN or ∞) near source voxels {near:?}"
    )]
    NonFiniteDisplacement {
        /// Inclusive box of source voxel indices (a cell block) that holds it.
        near: ([usize; 3], [usize; 3]),
    },
    /// The deformed volume would need a larger output than allowed.
    #[error(
        "the deformed volume needs an output grid of {dims:?} voxels, more than the {max_voxels} \
         allowed by `[resample] max_output_factor` = {max_output_factor} (times the source's \
         voxels); check the displacement field (millimetres?) or raise `[resample] \
         max_output_factor` (ResampleParams::max_output_factor)"
    )]
    OutputTooLarge {
        /// Output dimensions that would be needed.
        dims: [usize; 3],
        /// The limit, voxels.
        max_voxels: u64,
        /// The limit as a multiple of the source's voxel count
        /// ([`ResampleParams::max_output_factor`] as applied, ≥ 1).
        max_output_factor: f64,
    },
    /// A tetrahedron address is out of range.
    #[error(
        "tetrahedron {tet} of cell {cell:?} does not exist (cells {cell_dims:?}, 5 tetrahedra each)"
    )]
    BadTet {
        /// Cell indices given.
        cell: [usize; 3],
        /// Local tetrahedron given.
        tet: usize,
        /// Cells along x, y, z.
        cell_dims: [usize; 3],
    },
    /// The tetrahedron mask belongs to another grid.
    #[error("the tetrahedron mask has {mask:?} cells but the source mesh has {mesh:?}")]
    MaskMismatch {
        /// The mask's cell dimensions.
        mask: [usize; 3],
        /// The mesh's cell dimensions.
        mesh: [usize; 3],
    },
    /// Allocating the output failed.
    #[error("cannot allocate the output of {voxels} voxels ({bytes} bytes)")]
    OutOfMemory {
        /// Voxels requested.
        voxels: usize,
        /// Bytes requested.
        bytes: usize,
    },
    /// A GPU buffer is too large for one storage binding or the device.
    #[error(
        "GPU: {what} needs {bytes} bytes in one binding but the device allows {limit} \
         (max_storage_buffer_binding_size); use the CPU backend or a smaller volume"
    )]
    BindingTooLarge {
        /// The buffer at fault.
        what: &'static str,
        /// Bytes needed.
        bytes: u64,
        /// The device limit, bytes.
        limit: u64,
    },
    /// With the source split into z-slabs, trilinear samples fell outside
    /// their slab's halo of vertex planes (rest positions more than a cell
    /// outside the owner's cell: only nearly degenerate tetrahedra, through
    /// rounding); the output is incomplete.
    #[error(
        "GPU: {voxels} trilinear samples fall outside their source slab's halo (nearly \
         degenerate tetrahedra); use the CPU backend, tetrahedral interpolation, or a device \
         whose storage bindings hold the whole source"
    )]
    SlabHaloExceeded {
        /// Output voxels left without a value.
        voxels: u32,
    },
    /// A GPU service call failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Parameters of the resampler.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResampleParams {
    /// Value of output voxels that no tetrahedron covers (in the volume's
    /// units, e.g. Hounsfield units: `-1000.0` for air in CT).
    pub background: f32,
    /// Inclusion slack, relative to the tetrahedron (dimensionless): a voxel
    /// centre counts as inside when every barycentric coordinate is
    /// `≥ −inclusion_epsilon`. Shared faces never leave holes even at `0`
    /// (see [`raster`]); the slack only makes boundary decisions generous.
    pub inclusion_epsilon: f32,
    /// Extra output voxels added on each side that has to grow, so a steadily
    /// growing deformation does not reallocate every frame.
    pub growth_margin: usize,
    /// Largest output allowed, as a multiple of the source's voxel count
    /// (guards against displacements given in the wrong units; values below
    /// 1 act as 1). Scene key `[resample] max_output_factor`.
    pub max_output_factor: f64,
    /// The interpolant of pass 2 (see [`interpolation`]). Scene key
    /// `[resample] interpolation`.
    pub interpolation: Interpolation,
}

impl Default for ResampleParams {
    fn default() -> Self {
        Self {
            background: 0.0,
            inclusion_epsilon: 1e-6,
            growth_margin: 4,
            max_output_factor: 8.0,
            interpolation: Interpolation::default(),
        }
    }
}

/// The displacement field on the source voxel centres, millimetres along
/// the world axes, structure of arrays, x fastest, one value per source voxel.
#[derive(Clone, Copy, Debug)]
pub struct DisplacementsRef<'a> {
    /// x displacements, mm.
    pub x: &'a [f32],
    /// y displacements, mm.
    pub y: &'a [f32],
    /// z displacements, mm.
    pub z: &'a [f32],
}

/// A resampled volume: f32 values on an output grid.
#[derive(Clone, Debug, PartialEq)]
pub struct ResampleOutput {
    /// Output geometry (mm): the source's spacing and axes.
    pub grid: Grid,
    /// Values, `grid.len()` of them, x fastest.
    pub values: Vec<f32>,
}

/// What one resampling call did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct ResampleReport {
    /// The whole output was recomputed (first call, `DirtyRegion::All`,
    /// output growth, backend or source change, or after an error).
    pub full: bool,
    /// The output grid was (re)allocated with a new geometry.
    pub output_grid_changed: bool,
    /// Output voxels cleared and re-filled.
    pub voxels_touched: u64,
    /// Cells whose tetrahedra were rasterised.
    pub cells_rasterised: u64,
    /// The re-filled output box, inclusive, in **output voxel indices**.
    pub region: Option<([usize; 3], [usize; 3])>,
}

/// Which kernels produced the current output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Backend {
    Cpu,
    Gpu,
}

/// Per-call constants every kernel needs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct KernelConsts {
    pub mesh: SamplingMesh,
    pub layout: BlockLayout,
    /// `1 / spacing` per axis, voxels per mm.
    pub inv_spacing: [f32; 3],
    pub eps: f32,
    pub background: f32,
    pub interpolation: Interpolation,
}

/// One rasterisation: clear `region`, rasterise `blocks` clipped to it, fill it.
pub(crate) struct Job<'a> {
    pub consts: &'a KernelConsts,
    pub output: &'a OutputGrid,
    /// Output voxels to recompute, source index units, inside the output.
    pub region: VoxelBox,
    /// Selected blocks (linear ids).
    pub blocks: &'a [u32],
    /// Bounds of every block (for per-slab selection on the GPU).
    pub bounds: &'a [BlockBounds],
}

/// The backend-specific half of a resampling call.
pub(crate) trait Kernels {
    /// Deformed bounds of the listed blocks, in list order.
    fn block_bounds(
        &mut self,
        c: &KernelConsts,
        blocks: &[u32],
        out: &mut [BlockBounds],
    ) -> Result<(), ResampleError>;
    /// (Re)allocates the output (contents undefined until rasterised).
    fn allocate_output(&mut self, output: &OutputGrid) -> Result<(), ResampleError>;
    /// Clears, rasterises and fills one region.
    fn rasterise(&mut self, job: &Job<'_>) -> Result<(), ResampleError>;
}

/// State kept between calls for dirty-region resampling.
#[derive(Clone, Debug)]
pub(crate) struct Session {
    pub source_grid: Grid,
    pub backend: Backend,
    pub bounds: Vec<BlockBounds>,
    pub output: OutputGrid,
    pub mask: MaskState,
}

/// The resampling service. Keeps the output (on the CPU or in a GPU buffer)
/// and what it needs to re-resample only a dirty region on the next call.
///
/// One `Resampler` follows one source volume and one displacement field;
/// each call's dirty region must cover every displacement change since the
/// previous call (union the model's regions when frames are skipped), and a
/// change of source values needs [`DirtyRegion::All`].
#[derive(Debug, Default)]
pub struct Resampler {
    params: ResampleParams,
    session: Option<Session>,
    cpu_values: Vec<f32>,
    gpu: gpu::GpuState,
}

impl Resampler {
    /// A resampler with the given parameters.
    pub fn new(params: ResampleParams) -> Self {
        Self {
            params,
            ..Default::default()
        }
    }

    /// The parameters.
    pub fn params(&self) -> &ResampleParams {
        &self.params
    }

    /// Changes the parameters; the next call resamples in full.
    pub fn set_params(&mut self, params: ResampleParams) {
        self.params = params;
        self.session = None;
    }

    /// World geometry (mm) of the current output, if any.
    pub fn output_grid(&self) -> Option<Grid> {
        self.session
            .as_ref()
            .map(|s| s.output.world_grid(&s.source_grid))
    }

    /// The current output lattice relative to the source (index units).
    pub fn output_lattice(&self) -> Option<OutputGrid> {
        self.session.as_ref().map(|s| s.output)
    }

    /// The output values of the last CPU resample (x fastest, on
    /// [`Self::output_grid`]); `None` before one or after a GPU resample.
    pub fn cpu_values(&self) -> Option<&[f32]> {
        match &self.session {
            Some(s) if s.backend == Backend::Cpu => Some(&self.cpu_values),
            _ => None,
        }
    }

    /// A copy of the output of the last CPU resample.
    pub fn cpu_output(&self) -> Option<ResampleOutput> {
        Some(ResampleOutput {
            grid: self.output_grid()?,
            values: self.cpu_values()?.to_vec(),
        })
    }

    /// Resamples on the CPU (rayon).
    ///
    /// `disp` holds one displacement (mm) per source voxel; `mask` the
    /// removed tetrahedra, if any; `dirty` what changed since the previous
    /// call ([`DirtyRegion::Box`] in rest-space world mm; `All` forces a full
    /// resample; `None` does nothing unless the mask changed). The first call
    /// and any change of source grid or backend resample in full.
    pub fn resample_cpu(
        &mut self,
        source: VolumeView<'_>,
        disp: DisplacementsRef<'_>,
        mask: Option<&TetMask>,
        dirty: DirtyRegion,
    ) -> Result<ResampleReport, ResampleError> {
        let grid = source.grid;
        check_len("source volume", &grid, source.data.len())?;
        check_len("x displacements", &grid, disp.x.len())?;
        check_len("y displacements", &grid, disp.y.len())?;
        check_len("z displacements", &grid, disp.z.len())?;
        let mut k = cpu::CpuKernels {
            source: source.data,
            disp,
            mask,
            out: &mut self.cpu_values,
            fill: true,
            still_shortcut: true,
        };
        let r = plan::drive(
            &self.params,
            &mut self.session,
            &mut k,
            &grid,
            Backend::Cpu,
            mask,
            dirty,
        );
        if r.is_err() {
            self.session = None;
        }
        r
    }

    /// Resamples on the GPU. `source` holds the source values as f32 (see
    /// [`gpu::GpuSource::upload`]), `disp` the x, y, z displacement buffers
    /// (f32, mm, one per source voxel). The output stays in a GPU buffer
    /// ([`Self::gpu_output_buffer`], f32, x fastest, on
    /// [`Self::output_grid`]); [`Self::read_gpu_output`] copies it back.
    /// Same `mask` and `dirty` rules as [`Self::resample_cpu`].
    pub fn resample_gpu(
        &mut self,
        gpu: &dyn GpuService,
        source: &gpu::GpuSource,
        disp: [BufferId; 3],
        mask: Option<&TetMask>,
        dirty: DirtyRegion,
    ) -> Result<ResampleReport, ResampleError> {
        let r = self.gpu.prepare(gpu, source, disp, mask).and_then(|()| {
            let mut k = self
                .gpu
                .kernels(gpu, source, disp, mask.is_some_and(|m| !m.is_empty()));
            plan::drive(
                &self.params,
                &mut self.session,
                &mut k,
                &source.grid,
                Backend::Gpu,
                mask,
                dirty,
            )
        });
        if r.is_err() {
            self.session = None;
        }
        r
    }

    /// The GPU buffer holding the output of the last GPU resample (f32
    /// values, x fastest, on [`Self::output_grid`]).
    pub fn gpu_output_buffer(&self) -> Option<BufferId> {
        match &self.session {
            Some(s) if s.backend == Backend::Gpu => self.gpu.output_buffer(),
            _ => None,
        }
    }

    /// Bytes of CPU scratch this resampler keeps beyond its output values
    /// (the per-block deformed bounds). The displacement field (12 bytes per
    /// source voxel) and the optional [`TetMask`] (1 byte per cell) are the
    /// caller's and are not included.
    pub fn scratch_bytes(&self) -> usize {
        self.session.as_ref().map_or(0, |s| {
            s.bounds.capacity() * std::mem::size_of::<BlockBounds>()
        })
    }

    /// Reads the output of the last GPU resample back to the CPU.
    pub fn read_gpu_output(&self, gpu: &dyn GpuService) -> Result<ResampleOutput, ResampleError> {
        let (Some(grid), Some(buf)) = (self.output_grid(), self.gpu_output_buffer()) else {
            return Err(ResampleError::Gpu(GpuError(
                "no GPU resample output yet: call Resampler::resample_gpu first".into(),
            )));
        };
        let mut values = vec![0f32; grid.len()];
        gpu::read_f32(gpu, buf, &mut values)?;
        Ok(ResampleOutput { grid, values })
    }

    /// Frees the GPU buffers this resampler created (the output included).
    /// Call before dropping a resampler that used [`Self::resample_gpu`].
    pub fn release_gpu(&mut self, gpu: &dyn GpuService) {
        self.gpu.release(gpu);
        if matches!(&self.session, Some(s) if s.backend == Backend::Gpu) {
            self.session = None;
        }
    }
}

fn check_len(what: &'static str, grid: &Grid, actual: usize) -> Result<(), ResampleError> {
    if actual != grid.len() {
        return Err(ResampleError::SizeMismatch {
            what,
            dims: grid.dims,
            expected: grid.len(),
            actual,
        });
    }
    Ok(())
}
