//! # voxflex-core
//!
//! The ground every other voxflex crate stands on, and only that: voxel
//! geometry ([`grid::Grid`]), volumes ([`volume::Volume`], and
//! [`shared_volume::SharedVolume`] to lend one without copying), errors, the
//! deformation-field trait ([`deformation::DeformationModel`]), the
//! GPU-service trait ([`gpu::GpuService`]), the renderer trait
//! ([`render::Renderer`]), the camera, the interaction vocabulary, cut
//! polygons, opacity maps as the renderer receives them, the plain
//! tetrahedral mesh that readers and mesh models share, the closed
//! triangle surface of an actuator's cavity, the actuator trait
//! ([`actuator::ActuatorModel`]), and volume statistics.
//!
//! Everything a plugin or the ABI needs lives here; everything only some
//! crates need lives in its own crate above this one: file formats
//! (`voxflex-io`), phantoms (`voxflex-phantom`), resampling
//! (`voxflex-resample`), opacity-map growth (`voxflex-opacity`) and the
//! mesh-model framework (`voxflex-mesh`). Touching one of those recompiles
//! only its dependents, not every plugin.
//!
//! core knows nothing of wgpu, libloading or windows: GPU work goes through
//! the [`gpu::GpuService`] trait that the host implements.
//!
//! Units: world coordinates are millimetres; voxel indices address voxel
//! centres (see [`grid`]).
//!
//! Cargo feature `test-support`: `test_data` (where the real test volumes
//! are), for the tests of the crates above; off in release builds.

#![warn(missing_docs)]

pub mod actuator;
pub mod camera;
pub mod cut_polygon;
pub mod deformation;
pub mod error;
pub mod fast_div;
pub mod fresh_memory;
pub mod gpu;
pub mod grid;
pub mod interaction;
pub mod keyframes;
pub mod non_finite;
pub mod oblique;
pub mod on_worker;
pub mod opacity_map;
pub mod ordered_reduce;
pub mod point_slabs;
pub mod prefetch;
pub mod render;
pub mod shared_volume;
pub mod slice_axis;
pub mod stats;
#[cfg(any(test, feature = "test-support"))]
pub mod test_data;
pub mod tet_mesh;
pub mod triangle_surface;
pub mod volume;
pub mod z_slabs;

pub use glam;
