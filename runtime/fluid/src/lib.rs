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
//! (2-D point-in-triangle test with a fill rule, [`fill_rule`]), which records
//! the surface's height there. Per column the crossings are sorted by
//! height and matched bottom → top into sections (several in a non-convex
//! cavity, [`sections`]); each section's weight `W = A·h·ρ·g` goes to its
//! bottom triangle's corners by the barycentric coordinates
//! ([`distribute`]).
//!
//! The triangle–column candidates are irregular (a large triangle covers
//! many columns, a small one none), so the paper gives each triangle
//! `k = max(1, ⌊α·c⌋)` workers, `c` the mean number of candidate columns
//! per triangle ("parallel leveraging", [`schedule`]). The WGSL path
//! ([`gpu`]) runs one GPU invocation per worker, worker `j` of a triangle
//! testing its candidates `j, j + k, j + 2k, …`; `α = 0` is one worker per
//! triangle.
//!
//! The CPU path (rayon) scans rows instead of testing every candidate: in
//! a row the centres inside a triangle are one run of consecutive columns
//! ([`hits::Run`]). It works in the grid's index space, where the centres
//! are integer points ([`index_space`]), visits the triangles along a
//! Z-order curve so neighbours are scanned together
//! ([`triangle_order`]), and reads the barycentric coordinates and heights
//! of a run from the fill rule's own edge functions. A row of up to eight
//! candidates tests each, four at a time in SIMD lanes (a triangle of
//! three rows or more computes the column half of each edge function once,
//! [`fill_rule::RowTest`]); a wider one is cut by the triangle's edges and
//! tests only the run's ends exactly. One pass over the triangles
//! classifies each and scans its rows while its corners are at hand
//! ([`row_scan`]), storing each run with its height (and a bottom run with
//! its barycentric coordinates) in a bucket for its band of rows. The
//! section pass then takes a band at a time: a cell of one bottom and one
//! top crossing takes its section directly, the others' crossings are
//! grouped by cell in a counting sort and sorted by height; the weight
//! pass sums each bottom run's sections and puts them on its triangle's
//! corners ([`distribute`]). No pass sorts the whole grid's crossings, and
//! no two tasks write to one place. On the CPU a task takes hundreds of
//! triangles, so `k` changes nothing there (see
//! [`schedule::TaskSplit`]).
//!
//! Units: lengths mm, density kg/m³, gravity m/s², weights µN (the
//! corotational FEM's force unit: Pa · mm²).
//!
//! Coordinates: everything is in the world frame (mm); the column grid
//! lives in a frame whose third axis points up, against gravity
//! ([`GravityFrame`]).

#![warn(missing_docs)]

pub mod column_grid;
pub mod distribute;
pub mod error;
pub mod fill_rule;
pub mod gpu;
pub mod gravity_frame;
pub mod hits;
pub mod index_space;
pub mod params;
#[cfg(feature = "test-support")]
pub mod parity;
pub mod projection;
pub mod row_scan;
pub mod schedule;
pub mod sections;
#[cfg(feature = "test-support")]
pub mod test_surfaces;
pub mod triangle_order;
pub mod weighing;

pub use column_grid::ColumnGrid;
pub use error::FluidError;
pub use gpu::GpuFluidWeighing;
pub use gravity_frame::GravityFrame;
pub use params::FluidWeightParams;
pub use weighing::{FluidWeigher, FluidWeighing, FluidWeights, Scratch, fluid_weights};
