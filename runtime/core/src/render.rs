//! The trait every renderer is seen through (the `raycast` plugin, later
//! others), mirrored across the C ABI like [`crate::deformation::DeformationModel`].
//!
//! A renderer takes a regular grid (the resampled volume, on the CPU or in a
//! GPU buffer), optional spatial opacity maps and a camera, and writes an
//! RGBA8 image.

use crate::camera::Camera;
use crate::deformation::{DirtyRegion, ExecutionBackend};
use crate::error::ModelError;
use crate::gpu::BufferId;
use crate::grid::Grid;
use crate::opacity_map::OpacityMap;
use crate::shared_volume::SharedVolume;
use crate::volume::VolumeView;

/// The volume a renderer draws.
#[derive(Clone, Copy, Debug)]
pub enum RenderVolume<'a> {
    /// Values on the CPU, valid during the call: a renderer that keeps the
    /// volume copies the changed region.
    Cpu(VolumeView<'a>),
    /// Values on the CPU that the renderer may keep (a clone: a reference
    /// count, not a copy) instead of copying them. They never change; a
    /// host with new values hands over a new volume, whose values may
    /// differ from the previous volume's only inside the dirty region.
    Shared(&'a SharedVolume),
    /// f32 values (x fastest) in a host GPU buffer, e.g. the resampler's output.
    Gpu {
        /// Geometry, mm.
        grid: Grid,
        /// Buffer of `grid.len()` f32.
        values: BufferId,
    },
}

impl RenderVolume<'_> {
    /// The volume's geometry (voxel index ↔ world millimetres).
    pub fn grid(&self) -> Grid {
        match self {
            RenderVolume::Cpu(view) => view.grid,
            RenderVolume::Shared(shared) => shared.view().grid,
            RenderVolume::Gpu { grid, .. } => *grid,
        }
    }
}

/// Where [`Renderer::render`] writes the image: `width × height` pixels,
/// row-major from the top-left, RGBA8 (sRGB, straight alpha).
pub enum ImageTarget<'a> {
    /// `width · height · 4` bytes.
    Cpu(&'a mut [u8]),
    /// A host GPU buffer of `width · height` u32, each RGBA8 packed little-endian (R in the low byte).
    Gpu(BufferId),
}

/// What one render did (for metrics and the empty-space-skipping figures).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Primary rays cast.
    pub rays: u64,
    /// Volume samples taken (trilinear lookups).
    pub samples: u64,
    /// Rays stopped early by opacity saturation.
    pub terminated_early: u64,
}

/// A renderer seen as a function of volume, maps and camera.
pub trait Renderer: Send {
    /// Once: the backend to render on.
    fn init(&mut self, backend: ExecutionBackend) -> Result<(), ModelError>;
    /// Changes settings at run time (transfer function, shading, clipping…),
    /// given as TOML text of the same keys as the plugin's parameters.
    fn configure(&mut self, settings_toml: &str) -> Result<(), ModelError>;
    /// The volume to draw and the world-space box (mm) whose values changed
    /// since the previous call (`All` the first time).
    fn set_volume(
        &mut self,
        volume: RenderVolume<'_>,
        dirty: DirtyRegion,
    ) -> Result<(), ModelError>;
    /// Spatial opacity maps (over the volume's voxel grid) multiplied into the
    /// opacity integral; several combine by max. Empty = none.
    fn set_opacity_maps(&mut self, maps: &[OpacityMap]) -> Result<(), ModelError>;
    /// Renders one image.
    fn render(
        &mut self,
        camera: &Camera,
        target: ImageTarget<'_>,
    ) -> Result<RenderStats, ModelError>;
}
