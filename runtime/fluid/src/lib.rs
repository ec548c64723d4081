//! # voxflex-fluid
//!
//! The fluid inside an actuator's cavity, from Rodríguez, Coevoet and
//! Duriez, "Real-time simulation of hydraulic components for interactive
//! control of soft robots" (ICRA 2017): the **fluid-weight distribution**
//! on a grid of vertical columns, which also gives the cavity's volume.
//!
//! The cavity is a closed [`TriangleSurface`](voxflex_core::triangle_surface::TriangleSurface)
//! (mm, normals out). The plane perpendicular to gravity is split into a
//! grid of columns of cross-section `A = w·d` over the cavity's projected
//! bounding box ([`ColumnGrid`]). Triangles whose normal points up are
//! *top* triangles, those pointing down *bottom* ones. Each column centre
//! is tested against every projected triangle whose bounding box holds it
//! (2-D barycentric test, [`hits`]), which records the surface's height
//! there (and, for bottom triangles, the triangle and the barycentric
//! coordinates). Per column the intersections are sorted by height and
//! matched bottom → top into sections (several in a non-convex cavity,
//! [`sections`]); each section's weight `W = A·h·ρ·g` goes to its bottom
//! triangle's corners by the barycentric coordinates.
//!
//! The triangle–column candidates are irregular (a large triangle covers
//! many columns, a small one none), so the paper gives each triangle
//! `k = max(1, ⌊α·c⌋)` workers, `c` the mean number of candidate columns
//! per triangle ("parallel leveraging", [`schedule`]); worker `j` of a
//! triangle tests its candidates `j, j + k, j + 2k, …`. The CPU path runs
//! the workers on rayon, the WGSL path ([`gpu`]) on GPU invocations;
//! `α = 0` is one worker per triangle.
//!
//! Units: lengths mm, density kg/m³, gravity m/s², weights µN (the
//! corotational FEM's force unit: Pa · mm²).
//!
//! Coordinates: everything is in the world frame (mm); the column grid
//! lives in a frame whose third axis points up, against gravity
//! ([`GravityFrame`]).

#![warn(missing_docs)]

pub mod column_grid;
pub mod error;
pub mod gpu;
pub mod gravity_frame;
pub mod hits;
pub mod params;
#[cfg(feature = "test-support")]
pub mod parity;
pub mod projection;
pub mod schedule;
pub mod sections;
#[cfg(feature = "test-support")]
pub mod test_surfaces;
pub mod weighing;

pub use column_grid::ColumnGrid;
pub use error::FluidError;
pub use gpu::GpuFluidWeighing;
pub use gravity_frame::GravityFrame;
pub use params::FluidWeightParams;
pub use weighing::{FluidWeigher, FluidWeighing, FluidWeights, Scratch, fluid_weights};
