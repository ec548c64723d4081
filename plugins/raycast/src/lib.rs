//! # voxflex-raycast — the ray-casting renderer
//!
//! Direct volume rendering of a regular grid (the resampled volume) into an
//! RGBA8 image, on the CPU (rayon, 16 × 16-pixel tiles) or the GPU (WGSL,
//! one invocation per pixel), with the same parameters and the same f32
//! formulas on both paths ([`uniforms::RayUniforms`] is shared bit for bit).
//!
//! ## The model
//!
//! - **Emission–absorption, front to back.** The transfer function (TF)
//!   gives, per data value, an sRGB colour and an alpha `a` = the opacity of
//!   a slab `opacity_unit_distance` mm thick. The table converts it to the
//!   extinction coefficient `κ = −ln(1 − a) / opacity_unit_distance` (per
//!   mm). A sample standing for a ray segment of length Δt has opacity
//!   `A*ᵢ = (1 − exp(−κ Δt)) · o(i)` — the integral of "Spatial opacity
//!   maps" (CEIG 2016), which equals the classic correction
//!   `1 − (1 − a)^(Δt/unit)` when `o = 1`. `o(i)` is the combined opacity
//!   map factor at the sample ([`maps`]: max over maps, each map's `outside`
//!   beyond its box, trilinear between voxel centres by default); with no
//!   map `o = 1`. Composite: `C += (1 − A) A*ᵢ cᵢ`, `A += (1 − A) A*ᵢ`.
//! - **Sampling.** Rays are clipped to the box of voxel centres (world mm,
//!   [`Grid::world_bounds`]) ∩ the crop box ∩ the clip-plane half-spaces,
//!   and start at the eye (`t ≥ 0`; orthographic rays start at the eye
//!   plane). Samples sit at the midpoints of steps of
//!   `sample_distance × smallest spacing` mm; the last, shorter step is
//!   sampled at its own midpoint with its own Δt, so a homogeneous slab of
//!   length L integrates to exactly `1 − exp(−κ L)`. Values are trilinear in
//!   voxel-index space (voxel centres at integers), or with
//!   `sampling = "tricubic"` the cubic B-spline of the voxels
//!   ([`filters::tricubic`], 8 trilinear fetches). `jitter = true` starts
//!   each pixel's samples a fraction `ξ ∈ [0, 1)` of a step later
//!   ([`filters::jitter`], a hash of the pixel, fixed across frames), the
//!   first step `[t0, t0 + ξΔt]` sampled at its midpoint with its own Δt,
//!   so homogeneous slabs stay exact and step aliasing becomes noise.
//! - **Empty-space skipping.** A min/max macro-cell grid (`macro_cell`³
//!   voxels, including the shared border voxel and a one-voxel halo for the
//!   tricubic footprint) is built once per volume
//!   version and rebuilt only over the dirty region passed to `set_volume`.
//!   A cell is empty when the TF maps its whole `[min, max]` to κ = 0 (a
//!   prefix count over the TF table, one entry of margin). Per TF and
//!   volume version a leap distance is derived for every cell (Chebyshev
//!   distance to the nearest non-empty cell, capped at 16 cells), so a
//!   composite ray in empty space jumps over a whole block of empty cells at
//!   once; MIP rays jump cell by cell over cells whose max cannot beat their
//!   running maximum.
//!   Skipping is exact: it never changes a pixel (up to float rounding at
//!   cell faces). The CPU path skips finer still, without changing a bit
//!   of the image: [`visible_cells`] keeps one bit per trilinear cell
//!   (may the table show a value between its corners?) and skips a
//!   sample in a hidden cell before reading the volume — past the largest
//!   hidden aligned block of 2, 4 or 8 cells around it at once —, and
//!   [`ray_bounds`] projects every non-empty macro cell (narrowed to its
//!   shown cells) per frame, so each ray starts at its first and stops
//!   after its last possibly visible sample.
//! - **Early ray termination** at `termination_threshold` (default
//!   `0.998 = 1 − 0.5/255`, so what is left cannot change an 8-bit pixel).
//! - **Shading.** Blinn–Phong with a headlight (light and eye along the
//!   ray, so the half vector is the light vector) on the normalised
//!   gradient, two-sided: `c·(ambient + diffuse·|n·l|) + specular·|n·l|^shininess`.
//!   The gradient is the 3×3×3 Sobel operator ([`filters::sobel`]: the
//!   central difference along each axis, `[1, 2, 1] / 4` across it) of the
//!   voxels, trilinear in between — or with `gradient = "central"` the
//!   central difference `f(p ± 1 voxel)` of the trilinear field — only at samples with non-zero opacity; where
//!   it vanishes the sample is lit as if facing the light. The CPU path
//!   caches the Sobel gradients of the voxels per 8³-cell brick on first
//!   use ([`gradient_cache`]: bit-identical, at most the volume's own size,
//!   dropped where `set_volume`'s dirty region changes them); the GPU path
//!   computes them per sample.
//! - **MIP**: the largest trilinear value along the ray, then the TF: colour
//!   `c(v_max)`, alpha `a(v_max)` (one unit distance) times `o` at that sample.
//! - **Colour spaces** ([`color`]): sRGB at the interfaces (TF points,
//!   background, output), linear for shading and compositing, encoded to
//!   sRGB once per pixel. Output alpha is straight (not premultiplied).
//!
//! ## Backends and buffers
//!
//! CPU path ([`voxel_store`]): a `RenderVolume::Cpu` volume is copied in its
//! own scalar type once per version (only the dirty voxels afterwards); a
//! `RenderVolume::Shared` one is kept as the host lent it, not copied (an
//! f32 volume holding NaN excepted); `RenderVolume::Gpu` on the CPU backend
//! is read back (the dirty z-slab). GPU path ([`gpu`]): `RenderVolume::Gpu`
//! buffers are bound as they are; CPU volumes, copied or lent, are uploaded
//! once per version (the dirty z-slab of planes). A volume above the GPU's largest
//! storage binding is bound in z-slabs, one pass per slab and ray
//! direction, each ray resuming where it stopped (same image bit for bit;
//! see [`gpu`]); an image, or its 32 bytes per pixel of ray state while the
//! volume is split, above one binding is refused with an error.
//!
//! ## Accuracy and speed (tested in `src/tests.rs`, measured here)
//!
//! - Homogeneous box, κ known: every pixel's opacity equals
//!   `1 − exp(−κ L)` for the analytic chord L (bound 1e-3; measured 2.4e-6).
//! - Default step (0.5 voxel) vs a 16×-oversampled reference, 64³ head,
//!   `ct-soft-tissue`, shaded: RMS error bound 0.01 of the linear RGBA
//!   (measured 3e-3 on the partial-volume phantom), shrinking about 4× per
//!   halving of the step. The filters' error against step size and time:
//!   `voxflex bench --fronts --only render` (docs/BENCHMARKS.md).
//! - Empty-space skipping + early termination vs brute force: ≤ 1/255.
//! - CPU vs GPU (lavapipe): ≤ 2/255 per channel (measured ≤ 1/255).
//! - `cargo bench -p voxflex-raycast --bench render`: 512² image of the 256³
//!   CT head phantom, `ct-bone`, shaded, 0.5-voxel steps, 2 cores: see the
//!   benchmark's docs for the figures.
//!
//! ## Scene usage
//!
//! ```toml
//! [render]
//! plugin = "raycast"
//! [render.params]
//! transfer_function = { preset = "ct-bone", shift = 0.0 }
//! sample_distance = 0.5
//! shading = { enabled = true, ambient = 0.1, diffuse = 0.9, specular = 0.2, shininess = 10.0 }
//! ```
//!
//! Every key and its default: [`params`].

#![warn(missing_docs)]

pub mod color;
pub mod cpu;
pub mod filters;
pub mod gpu;
pub mod gradient_cache;
pub mod lazy_bricks;
pub mod leap;
pub mod macrocell;
pub mod maps;
pub mod params;
pub mod ray_bounds;
pub(crate) mod slabs;
pub mod step_opacity;
pub mod transfer;
pub mod uniforms;
pub mod views;
pub mod visible_cells;
pub mod voxel_store;

pub use params::RaycastParams;
pub use views::{fit_camera, turntable};

use gpu::GpuRenderer;
use gradient_cache::GradientCache;
use macrocell::{IndexBox, MacroCells, dirty_voxels};
use ray_bounds::{RayBounds, ShownCells};
use rayon::prelude::*;
use std::sync::Arc;
use step_opacity::StepOpacity;
use transfer::{Lut, TransferFunction, ValueUnits};
use uniforms::RayUniforms;
use visible_cells::VisibleCells;
use voxel_store::VoxelStore;
use voxflex_core::camera::{Camera, Projection};
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::error::ModelError;
use voxflex_core::gpu::{BufferId, GpuService};
use voxflex_core::grid::Grid;
use voxflex_core::opacity_map::OpacityMap;
use voxflex_core::render::{ImageTarget, RenderStats, RenderVolume, Renderer};
use voxflex_core::volume::{ScalarType, VolumeView};
use voxflex_core::with_voxels;

/// Most voxels along one axis of a volume (2³⁰: the CPU path's coordinates
/// truncate to `i32` without range checks, and `2³⁰ − 1` is still below
/// 2³¹ once rounded to f32).
pub const MAX_AXIS: usize = 1 << 30;

/// Largest image, pixels (keeps every index in u32 on both paths).
pub const MAX_PIXELS: u64 = 1 << 28;

/// The cached transfer-function table and what it was built from.
struct LutCache {
    tf: TransferFunction,
    unit: f32,
    range: (f32, f32),
    lut: Lut,
    generation: u64,
    /// CPU backend: `lut`'s opacity over the last frame's full step.
    step_opacity: Option<StepOpacity>,
}

/// The ray-casting renderer (the `raycast` plugin's [`Renderer`]).
pub struct RaycastRenderer {
    params: RaycastParams,
    tf: TransferFunction,
    service: Option<Arc<dyn GpuService>>,
    backend: ExecutionBackend,
    grid: Option<Grid>,
    /// CPU backend: the volume in its own scalar type.
    values: VoxelStore,
    /// CPU backend: the macro-cells.
    cells: MacroCells,
    /// CPU backend: Sobel gradients per brick, built on first use.
    gradients: Option<GradientCache>,
    /// CPU backend: the cells the table may show, per brick, for the LUT
    /// generation kept beside them.
    visible: Option<(u64, VisibleCells)>,
    /// CPU backend: skip with [`VisibleCells`] and [`RayBounds`] (always
    /// on; off only where a test counts samples against the GPU path,
    /// which walks the macro cells alone).
    fine_skipping: bool,
    /// Bumped whenever the cells change.
    cells_version: u64,
    /// The external GPU buffer of the current volume, if any.
    external: Option<BufferId>,
    /// Data range of the current version (cached; `None` = unknown).
    range: Option<(f32, f32)>,
    lut: Option<LutCache>,
    lut_generation: u64,
    /// Leap distances per cell for (cells_version, lut generation).
    leap: Option<(u64, u64, Vec<u8>)>,
    maps: Vec<OpacityMap>,
    /// Combined map for the current dims (`None` = not computed yet).
    combined: Option<Option<OpacityMap>>,
    gpu: Option<GpuRenderer>,
    /// The GPU has the current combined map / LUT generation.
    gpu_map_current: bool,
    gpu_lut_generation: u64,
    /// (cells_version, lut generation) of the GPU's leap distances.
    gpu_leap_key: Option<(u64, u64)>,
}

impl RaycastRenderer {
    /// Parses the parameters (TOML text of the `[render]` params table) and
    /// keeps the GPU service, if the host offers one. Renders on the CPU
    /// until [`Renderer::init`] says otherwise.
    pub fn create(params_toml: &str, gpu: Option<Arc<dyn GpuService>>) -> Result<Self, ModelError> {
        let params = RaycastParams::from_toml(params_toml)?;
        Self::with_params(params, gpu)
    }

    /// A renderer with already parsed parameters (validated here).
    pub fn with_params(
        params: RaycastParams,
        gpu: Option<Arc<dyn GpuService>>,
    ) -> Result<Self, ModelError> {
        params.validate()?;
        let tf = params.transfer_function()?;
        tracing::debug!(?params, "raycast renderer created");
        Ok(Self {
            cells: MacroCells::new([1, 1, 1], params.macro_cell as usize),
            params,
            tf,
            service: gpu,
            backend: ExecutionBackend::Cpu,
            grid: None,
            values: VoxelStore::default(),
            gradients: None,
            visible: None,
            fine_skipping: true,
            cells_version: 0,
            external: None,
            range: None,
            lut: None,
            lut_generation: 0,
            leap: None,
            maps: Vec::new(),
            combined: None,
            gpu: None,
            gpu_map_current: false,
            gpu_lut_generation: u64::MAX,
            gpu_leap_key: None,
        })
    }

    /// The current parameters.
    pub fn params(&self) -> &RaycastParams {
        &self.params
    }

    /// The backend renders run on.
    pub fn backend(&self) -> ExecutionBackend {
        self.backend
    }

    fn cell(&self) -> usize {
        self.params.macro_cell as usize
    }

    fn service(&self) -> Result<Arc<dyn GpuService>, ModelError> {
        self.service.clone().ok_or_else(|| {
            ModelError::new("this needs the GPU, but the host offered no GPU service")
        })
    }

    /// The current macro-cells (the GPU path reads them back).
    pub fn macro_cells(&self) -> Result<MacroCells, ModelError> {
        let grid = self.require_grid()?;
        match (&self.gpu, self.backend) {
            (Some(g), ExecutionBackend::Gpu) => g.read_cells(grid.dims, self.cell()),
            _ => Ok(self.cells.clone()),
        }
    }

    fn require_grid(&self) -> Result<Grid, ModelError> {
        self.grid
            .ok_or_else(|| ModelError::new("no volume: call set_volume before rendering"))
    }

    /// Rebuilds the cells over `voxels` (all when `None`) on the current backend.
    fn rebuild_cells(&mut self, voxels: Option<IndexBox>) -> Result<(), ModelError> {
        let grid = self.require_grid()?;
        let cell = self.cell();
        match self.backend {
            ExecutionBackend::Cpu => {
                let fresh = self.cells.dims != grid.dims || self.cells.cell != cell;
                if fresh {
                    self.cells = MacroCells::new(grid.dims, cell);
                }
                let cells = match voxels {
                    Some(v) if !fresh => self.cells.cells_touching(v),
                    _ => IndexBox::all(self.cells.counts),
                };
                with_voxels!(self.values.as_slice(), |v| self.cells.rebuild(v, cells));
            }
            ExecutionBackend::Gpu => {
                let counts = MacroCells::counts_for(grid.dims, cell);
                let cells = match voxels {
                    Some(v) => MacroCells::touching(grid.dims, cell, v),
                    None => IndexBox::all(counts),
                };
                let gpu = self.gpu.as_mut().expect("GPU state made by init");
                gpu.rebuild_cells(grid.dims, cell, cells)?;
            }
        }
        self.cells_version += 1;
        self.range = None;
        Ok(())
    }

    /// The data range of the current version (only needed by normalised TFs).
    fn data_range(&mut self) -> Result<(f32, f32), ModelError> {
        if let Some(r) = self.range {
            return Ok(r);
        }
        let r = self.macro_cells()?.value_range();
        self.range = Some(r);
        Ok(r)
    }

    /// Makes sure the TF table is current; returns its generation.
    fn ensure_lut(&mut self) -> Result<u64, ModelError> {
        let range = match self.tf.units {
            ValueUnits::Data => (0.0, 0.0),
            ValueUnits::Normalized => self.data_range()?,
        };
        let unit = self.params.opacity_unit_distance as f32;
        if let Some(c) = &self.lut
            && c.tf == self.tf
            && c.unit == unit
            && c.range == range
        {
            return Ok(c.generation);
        }
        self.lut_generation += 1;
        self.lut = Some(LutCache {
            lut: self.tf.lut(range, unit),
            tf: self.tf.clone(),
            unit,
            range,
            generation: self.lut_generation,
            step_opacity: None,
        });
        Ok(self.lut_generation)
    }

    fn ensure_combined(&mut self, dims: [usize; 3]) {
        if self.combined.is_none() {
            self.combined = Some(maps::combine(&self.maps, dims));
            self.gpu_map_current = false;
        }
    }

    fn check_camera(camera: &Camera) -> Result<(), ModelError> {
        let bad = |why: &str| Err(ModelError(format!("camera: {why}")));
        if camera.width == 0 || camera.height == 0 {
            return bad("width and height must be at least 1 pixel");
        }
        if camera.width as u64 * camera.height as u64 > MAX_PIXELS {
            return bad("image larger than 2^28 pixels");
        }
        let finite = camera.target.is_finite()
            && camera.azimuth_deg.is_finite()
            && camera.elevation_deg.is_finite()
            && camera.distance_mm.is_finite();
        if !finite {
            return bad("target, angles and distance must be finite");
        }
        if camera.distance_mm <= 0.0 {
            return bad("distance_mm must be > 0");
        }
        match camera.projection {
            Projection::Orthographic { height_mm }
                if !(height_mm > 0.0 && height_mm.is_finite()) =>
            {
                bad("orthographic height_mm must be finite and > 0")
            }
            Projection::Perspective { fov_y_deg } if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) => {
                bad("perspective fov_y_deg must be in (0, 180)")
            }
            _ => Ok(()),
        }
    }

    /// The frame constants for `camera` (TF table made current first).
    fn frame(&mut self, camera: &Camera) -> Result<RayUniforms, ModelError> {
        Self::check_camera(camera)?;
        let grid = self.require_grid()?;
        self.ensure_lut()?;
        self.ensure_combined(grid.dims);
        let lut = &self.lut.as_ref().expect("made above").lut;
        let map = self.combined.as_ref().and_then(|m| m.as_ref());
        Ok(RayUniforms::new(
            &self.params,
            &grid,
            camera,
            lut,
            self.cell(),
            map,
        ))
    }

    /// Renders on the CPU path into linear, premultiplied RGBA (before the
    /// sRGB encode; background composited if set), row-major from the
    /// top-left. Only on the CPU backend.
    pub fn render_linear(
        &mut self,
        camera: &Camera,
    ) -> Result<(Vec<[f32; 4]>, RenderStats), ModelError> {
        if self.backend != ExecutionBackend::Cpu {
            return Err(ModelError::new(
                "render_linear is the CPU path's; this renderer was initialised for the GPU",
            ));
        }
        let u = self.frame(camera)?;
        let clock = std::time::Instant::now();
        self.ensure_cpu_acceleration();
        let cache = self.lut.as_mut().expect("made by frame");
        if cache
            .step_opacity
            .as_ref()
            .is_none_or(|t| t.step_mm() != u.step[0])
        {
            cache.step_opacity = Some(StepOpacity::new(&cache.lut, u.step[0]));
        }
        let cache = self.lut.as_ref().expect("made by frame");
        let lut = &cache.lut;
        let step_opacity = cache.step_opacity.as_ref().expect("made above");
        let leap = &self.leap.as_ref().expect("made above").2;
        // Visible cells hold for trilinear footprints only; they narrow the
        // ray bounds where a macro cell is one brick (the default edge).
        let visible = (self.fine_skipping && self.params.sampling == params::Sampling::Trilinear)
            .then(|| &self.visible.as_ref().expect("made above").1);
        let shown = visible
            .filter(|_| self.cell() == lazy_bricks::BRICK)
            .map(|cells| ShownCells {
                cells,
                values: self.values.as_slice(),
                lut,
            });
        let tables_ms = clock.elapsed().as_secs_f64() * 1e3;
        // The bounds serve composite rays with skipping on (MIP rays skip
        // by their running maximum, not by the table).
        let composite = self.params.mode == params::RenderMode::Composite;
        let bounds = (self.fine_skipping && composite && self.params.empty_space_skipping)
            .then(|| RayBounds::build(&u, leap, shown));
        let bounds_ms = clock.elapsed().as_secs_f64() * 1e3 - tables_ms;
        let scene = cpu::Scene {
            u: &u,
            values: self.values.as_slice(),
            lut,
            step_opacity,
            cells: &self.cells,
            leap,
            map: self.combined.as_ref().and_then(|m| m.as_ref()),
            gradients: self.gradients.as_ref(),
            visible,
            bounds: bounds.as_ref(),
        };
        let out = cpu::render(&scene);
        let rays_ms = clock.elapsed().as_secs_f64() * 1e3 - tables_ms - bounds_ms;
        let gradient_bricks = self.gradients.as_ref().map_or(0, GradientCache::built);
        tracing::debug!(
            tables_ms,
            bounds_ms,
            rays_ms,
            gradient_bricks,
            "raycast cpu frame"
        );
        Ok(out)
    }

    /// Makes the CPU path's per-table state current: the leap distances
    /// (per cells version and table) and the visible cells (per table and
    /// grid; their bricks are built on use).
    fn ensure_cpu_acceleration(&mut self) {
        let generation = self.lut.as_ref().expect("made by frame").generation;
        let lut = &self.lut.as_ref().expect("made by frame").lut;
        if !matches!(&self.leap, Some((c, g, _)) if *c == self.cells_version && *g == generation) {
            self.leap = Some((
                self.cells_version,
                generation,
                self.cells.leap_distances(lut),
            ));
        }
        let dims = self.grid.as_ref().expect("checked by frame").dims;
        if !matches!(&self.visible, Some((g, v)) if *g == generation && v.dims() == dims) {
            self.visible = Some((generation, VisibleCells::new(dims)));
        }
    }

    fn set_volume_cpu(
        &mut self,
        volume: RenderVolume<'_>,
        grid: Grid,
        fresh: bool,
        region: IndexBox,
    ) -> Result<(), ModelError> {
        if fresh {
            if !matches!(volume, RenderVolume::Shared(_)) {
                self.values = VoxelStore::zeroed(stored_type(&volume), grid.len());
            }
            // At most as many bytes of gradients as the volume as f32.
            self.gradients = Some(GradientCache::new(grid.dims, 4 * grid.len()));
            self.visible = None;
        } else {
            if let Some(g) = &mut self.gradients {
                g.invalidate(region);
            }
            if let Some((_, v)) = &mut self.visible {
                v.invalidate(region);
            }
        }
        match volume {
            RenderVolume::Cpu(view) => self.values.copy_region(&view, region),
            RenderVolume::Shared(shared) => self.values.share(shared, region),
            RenderVolume::Gpu { values, .. } => {
                let service = self.service()?;
                let plane = grid.dims[0] * grid.dims[1];
                let (a, b) = (region.lo[2] * plane, (region.hi[2] + 1) * plane);
                let have = service.buffer_size(values)?;
                if have < grid.len() as u64 * 4 {
                    return Err(ModelError(format!(
                        "RenderVolume::Gpu buffer {} holds {have} bytes but the grid needs {}",
                        values.0,
                        grid.len() * 4
                    )));
                }
                // `set_volume` made the store f32 for a device volume.
                let store = self.values.f32_mut().ok_or_else(|| {
                    ModelError::new("internal: the CPU store of a device volume is not f32")
                })?;
                service.read_buffer(
                    values,
                    a as u64 * 4,
                    bytemuck::cast_slice_mut(&mut store[a..b]),
                )?;
                for v in &mut store[a..b] {
                    if v.is_nan() {
                        *v = 0.0;
                    }
                }
            }
        }
        Ok(())
    }

    fn set_volume_gpu(
        &mut self,
        volume: RenderVolume<'_>,
        grid: Grid,
        region: IndexBox,
    ) -> Result<(), ModelError> {
        let gpu = self.gpu.as_mut().expect("GPU state made by init");
        match volume {
            RenderVolume::Gpu { values, .. } => gpu.set_external_volume(values, grid.len()),
            RenderVolume::Cpu(view) => gpu.upload_volume(&view, region),
            RenderVolume::Shared(shared) => gpu.upload_volume(&shared.view(), region),
        }
    }

    fn write_target(
        &self,
        pixels: &[[f32; 4]],
        camera: &Camera,
        target: ImageTarget<'_>,
    ) -> Result<(), ModelError> {
        let n = camera.width as usize * camera.height as usize;
        match target {
            ImageTarget::Cpu(bytes) => {
                check_len(bytes.len(), n)?;
                bytes
                    .par_chunks_mut(4 * 1024)
                    .zip(pixels.par_chunks(1024))
                    .for_each(|(out, px)| {
                        for (o, p) in out.chunks_mut(4).zip(px) {
                            o.copy_from_slice(&color::encode_pixel(*p));
                        }
                    });
            }
            ImageTarget::Gpu(id) => {
                let service = self.service()?;
                // RGBA bytes in memory order = little-endian u32 with R low.
                let bytes: Vec<u8> = pixels
                    .par_iter()
                    .flat_map_iter(|p| color::encode_pixel(*p))
                    .collect();
                let have = service.buffer_size(id)?;
                if have < n as u64 * 4 {
                    return Err(ModelError(format!(
                        "ImageTarget::Gpu buffer {} holds {have} bytes but the image needs {}",
                        id.0,
                        n * 4
                    )));
                }
                service.write_buffer(id, 0, &bytes)?;
            }
        }
        Ok(())
    }
}

/// The scalar type the CPU path keeps `volume` in: its own for a CPU
/// view, f32 for a device buffer (read back as f32).
fn stored_type(volume: &RenderVolume<'_>) -> ScalarType {
    match volume {
        RenderVolume::Cpu(view) => view.data.scalar_type(),
        RenderVolume::Shared(shared) => shared.view().data.scalar_type(),
        RenderVolume::Gpu { .. } => ScalarType::F32,
    }
}

fn check_len(have: usize, pixels: usize) -> Result<(), ModelError> {
    if have != pixels * 4 {
        return Err(ModelError(format!(
            "ImageTarget::Cpu holds {have} bytes but the camera's image needs {} (width · height · 4)",
            pixels * 4
        )));
    }
    Ok(())
}

/// The grid of a CPU volume whose grid [`check_grid`] accepts and whose
/// values fill it.
fn check_view(view: &VolumeView<'_>) -> Result<Grid, ModelError> {
    check_grid(&view.grid)?;
    if view.data.len() != view.grid.len() {
        return Err(ModelError(format!(
            "volume has {} values but dims {:?} need {}",
            view.data.len(),
            view.grid.dims,
            view.grid.len()
        )));
    }
    Ok(view.grid)
}

fn check_grid(grid: &Grid) -> Result<(), ModelError> {
    if grid.dims.contains(&0) {
        return Err(ModelError(format!(
            "volume dims {:?} hold no voxel",
            grid.dims
        )));
    }
    if grid.dims.iter().any(|&n| n > MAX_AXIS) || grid.len() > u32::MAX as usize {
        return Err(ModelError(format!(
            "volume dims {:?} exceed the renderer's voxel indices (at most {MAX_AXIS} voxels \
             per axis and {} in all); crop or downsample the volume",
            grid.dims,
            u32::MAX
        )));
    }
    if !(grid.spacing.is_finite() && grid.spacing.min_element() > 0.0 && grid.origin.is_finite()) {
        return Err(ModelError(format!(
            "volume spacing {:?} must be finite and > 0 and origin {:?} finite (mm)",
            grid.spacing, grid.origin
        )));
    }
    Ok(())
}

impl Renderer for RaycastRenderer {
    fn init(&mut self, backend: ExecutionBackend) -> Result<(), ModelError> {
        if backend == ExecutionBackend::Gpu {
            let service = self.service.clone().ok_or_else(|| {
                ModelError::new("backend is gpu but the host offered no GPU service")
            })?;
            self.gpu = Some(GpuRenderer::new(service)?);
        } else {
            self.gpu = None;
        }
        self.backend = backend;
        // Volume state belongs to the previous backend: start over.
        self.grid = None;
        self.values = VoxelStore::default();
        self.cells = MacroCells::new([1, 1, 1], self.cell());
        self.external = None;
        self.range = None;
        self.leap = None;
        self.visible = None;
        self.combined = None;
        self.gpu_map_current = false;
        self.gpu_lut_generation = u64::MAX;
        self.gpu_leap_key = None;
        tracing::debug!(?backend, "raycast renderer initialised");
        Ok(())
    }

    fn configure(&mut self, settings_toml: &str) -> Result<(), ModelError> {
        let params = self.params.merged(settings_toml)?;
        let tf = params.transfer_function()?;
        let cell_changed = params.macro_cell != self.params.macro_cell;
        self.params = params;
        self.tf = tf;
        if cell_changed && self.grid.is_some() {
            self.rebuild_cells(None)?;
        }
        Ok(())
    }

    fn set_volume(
        &mut self,
        volume: RenderVolume<'_>,
        dirty: DirtyRegion,
    ) -> Result<(), ModelError> {
        let grid = match volume {
            RenderVolume::Cpu(view) => check_view(&view)?,
            RenderVolume::Shared(shared) => check_view(&shared.view())?,
            RenderVolume::Gpu { grid, .. } => {
                check_grid(&grid)?;
                grid
            }
        };
        let external = match volume {
            RenderVolume::Gpu { values, .. } => Some(values),
            RenderVolume::Cpu(_) | RenderVolume::Shared(_) => None,
        };
        // A volume of another scalar type (or a copied volume after a
        // shared one) starts the CPU store over.
        let retyped =
            self.backend == ExecutionBackend::Cpu && !self.values.updatable_by(&volume, grid.len());
        let fresh = self.grid != Some(grid) || self.external != external || retyped;
        let region = if fresh {
            Some(IndexBox::all(grid.dims))
        } else {
            dirty_voxels(&grid, dirty)
        };
        let Some(region) = region else {
            return Ok(());
        };
        let dims_changed = self.grid.map(|g| g.dims) != Some(grid.dims);
        match self.backend {
            ExecutionBackend::Cpu => self.set_volume_cpu(volume, grid, fresh, region)?,
            ExecutionBackend::Gpu => self.set_volume_gpu(volume, grid, region)?,
        }
        self.grid = Some(grid);
        self.external = external;
        if dims_changed {
            self.combined = None;
        }
        self.rebuild_cells(if fresh { None } else { Some(region) })?;
        tracing::debug!(?region, fresh, "raycast volume updated");
        Ok(())
    }

    fn set_opacity_maps(&mut self, maps: &[OpacityMap]) -> Result<(), ModelError> {
        maps::validate(maps)?;
        self.maps = maps.to_vec();
        self.combined = None;
        self.gpu_map_current = false;
        Ok(())
    }

    fn render(
        &mut self,
        camera: &Camera,
        target: ImageTarget<'_>,
    ) -> Result<RenderStats, ModelError> {
        let stats = match self.backend {
            ExecutionBackend::Cpu => {
                let (pixels, stats) = self.render_linear(camera)?;
                self.write_target(&pixels, camera, target)?;
                stats
            }
            ExecutionBackend::Gpu => {
                let u = self.frame(camera)?;
                let cache = self.lut.as_ref().expect("made by frame");
                let gpu = self.gpu.as_mut().expect("GPU state made by init");
                if self.gpu_lut_generation != cache.generation {
                    gpu.set_lut(&cache.lut)?;
                    self.gpu_lut_generation = cache.generation;
                }
                let key = (self.cells_version, cache.generation);
                if self.gpu_leap_key != Some(key) {
                    let grid = self.grid.expect("checked by frame");
                    let counts = MacroCells::counts_for(grid.dims, self.params.macro_cell as usize);
                    gpu.update_leap(&cache.lut, counts)?;
                    self.gpu_leap_key = Some(key);
                }
                if !self.gpu_map_current {
                    gpu.set_map(self.combined.as_ref().and_then(|m| m.as_ref()))?;
                    self.gpu_map_current = true;
                }
                match target {
                    ImageTarget::Gpu(id) => gpu.render(&u, &cache.lut, Some(id))?.1,
                    ImageTarget::Cpu(bytes) => {
                        let n = camera.width as usize * camera.height as usize;
                        check_len(bytes.len(), n)?;
                        let (id, stats) = gpu.render(&u, &cache.lut, None)?;
                        gpu.service().read_buffer(id, 0, bytes)?;
                        stats
                    }
                }
            }
        };
        tracing::debug!(?stats, "raycast frame");
        Ok(stats)
    }
}

#[cfg(test)]
mod shared_volume_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod voxel_store_tests;

impl voxflex_abi::DeclaresParams for RaycastRenderer {
    fn params_schema() -> Result<String, String> {
        voxflex_abi::params_schema::json(&schemars::schema_for!(params::RaycastParams))
    }
}

impl voxflex_abi::RendererPlugin for RaycastRenderer {
    const NAME: &'static str = "raycast";
    const DESCRIPTION: &'static str =
        "emission-absorption ray casting: transfer functions, shading, MIP, opacity maps, clipping";
    const CAPABILITIES: u32 = voxflex_abi::ffi::CAPABILITY_CPU | voxflex_abi::ffi::CAPABILITY_GPU;

    fn create(params_toml: &str, host: voxflex_abi::HostContext) -> Result<Self, ModelError> {
        RaycastRenderer::create(params_toml, host.gpu())
    }
}

voxflex_abi::export_renderer_plugin!(RaycastRenderer);
