//! # voxflex-core
//!
//! The ground every other voxflex crate stands on: voxel geometry
//! ([`grid::Grid`]), volumes ([`volume::Volume`]), file readers and writers,
//! built-in phantoms, the deformation-field trait
//! ([`deformation::DeformationModel`]), the GPU-service trait
//! ([`gpu::GpuService`]) and the CPU + WGSL kernels of the shared services.
//!
//! core knows nothing of wgpu, libloading or windows: GPU work goes through
//! the [`gpu::GpuService`] trait that the host implements.
//!
//! Units: world coordinates are millimetres; voxel indices address voxel
//! centres (see [`grid`]).

#![warn(missing_docs)]

pub mod barycentric;
pub mod camera;
pub mod cut_polygon;
pub mod deformation;
pub mod error;
mod fast_div;
pub mod gpu;
pub mod grid;
pub mod interaction;
pub mod io;
pub mod mesh_model;
pub mod non_finite;
pub mod opacity;
pub mod opacity_map;
pub mod phantom;
pub mod proxy;
pub mod render;
pub mod resample;
pub mod stats;
pub mod test_data;
pub mod tet_mesh;
pub mod volume;

pub use glam;
