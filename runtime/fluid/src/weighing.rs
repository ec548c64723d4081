//! The fluid-weight pipeline: project, intersect, match sections,
//! distribute — one stage method each.

use crate::column_grid::ColumnGrid;
use crate::distribute::add_weights;
use crate::error::FluidError;
use crate::params::FluidWeightParams;
use crate::projection::ProjectedSurface;
use crate::row_scan::{RowBands, TaskRuns, scan_triangles};
use crate::schedule::{TaskSplit, workers_per_triangle};
use crate::sections::{BandScratch, SectionCount, SectionTally, match_bands};
use crate::triangle_order::TriangleOrder;
use voxflex_core::triangle_surface::TriangleSurface;

/// µN per (kg/m³ · m/s² · mm³): 1e-9 N = 1e-3 µN.
const MICRONEWTON_PER_RHO_G_MM3: f64 = 1e-3;

/// The fluid's weight on the cavity's vertices, and what the grid saw.
#[derive(Clone, Debug, PartialEq)]
pub struct FluidWeights {
    /// Per surface vertex, the weight it carries, µN, acting along gravity
    /// (the force on vertex `i` is `node_weights[i] · ĝ`). They sum to
    /// `ρ·|g|·volume` (to rounding).
    pub node_weights: Vec<f64>,
    /// Fluid volume the columns hold, mm³ (converges to the surface's
    /// signed volume as the grid refines).
    pub volume_mm3: f64,
    /// Total weight, µN (`ρ·|g|·volume`).
    pub total_weight: f64,
    /// Sections, fluid columns and irregular columns (see [`SectionCount`]).
    pub count: SectionCount,
    /// Column–surface crossings found.
    pub crossings: usize,
    /// Workers per triangle used (the leveraging `k`).
    pub workers_per_triangle: usize,
    /// Mean candidate columns per triangle (the paper's `c`).
    pub mean_candidates: f64,
    /// The column grid.
    pub grid: ColumnGrid,
}

/// Computes the weight of the fluid filling the closed `surface` (mm,
/// normals out) on its vertices. Checks `params`; the surface's
/// closedness is the caller's (see [`TriangleSurface::check_closed`]) —
/// an open one shows up as `count.irregular_columns`.
///
/// Allocates its working memory on every call; a caller that weighs every
/// frame keeps a [`FluidWeigher`].
pub fn fluid_weights(
    surface: &TriangleSurface,
    params: &FluidWeightParams,
) -> Result<FluidWeights, FluidError> {
    FluidWeigher::default().weigh(surface, params)
}

/// The CPU fluid weighing with its working memory kept between calls, so
/// a per-frame weighing neither allocates nor faults in fresh pages.
#[derive(Debug, Default)]
pub struct FluidWeigher {
    scratch: Scratch,
}

impl FluidWeigher {
    /// [`fluid_weights`], reusing this weigher's memory.
    pub fn weigh(
        &mut self,
        surface: &TriangleSurface,
        params: &FluidWeightParams,
    ) -> Result<FluidWeights, FluidError> {
        // Its stages are short parallel loops: run them from a worker, so
        // they split without a hand-over each ([`voxflex_core::on_worker`]).
        voxflex_core::on_worker::on_worker(|| {
            let mut w = FluidWeighing::project(surface, params, &mut self.scratch)?;
            w.intersect();
            w.match_sections();
            Ok(w.distribute())
        })
    }
}

/// Working memory of one weighing (capacity reused between calls): the
/// order the row scan visits the triangles in (computed when the
/// triangles change, [`TriangleOrder`]), the projection's vertices and
/// triangles, each row-scan task's runs, each band's matching and weighed
/// runs.
#[derive(Debug, Default)]
pub struct Scratch {
    order: TriangleOrder,
    uvh: Vec<glam::DVec3>,
    triangles: Vec<crate::projection::ProjectedTriangle>,
    tasks: Vec<TaskRuns>,
    bands: Vec<BandScratch>,
}

/// The pipeline's state between stages.
#[derive(Debug)]
pub struct FluidWeighing<'a> {
    params: FluidWeightParams,
    projected: ProjectedSurface<'a>,
    /// Workers per triangle (the leveraging `k`; set once the triangles are
    /// classified).
    k: usize,
    bands: RowBands,
    tally: SectionTally,
    scratch: &'a mut Scratch,
}

impl<'a> FluidWeighing<'a> {
    /// Stage 1: the surface's vertices in the gravity frame and the grid
    /// over their bounds.
    pub fn project(
        surface: &'a TriangleSurface,
        params: &FluidWeightParams,
        scratch: &'a mut Scratch,
    ) -> Result<Self, FluidError> {
        params.check()?;
        if surface.triangles.len() >= crate::hits::TOP as usize {
            return Err(FluidError::Surface(format!(
                "{} triangles: at most 2³¹ − 1 fit the crossing records; simplify the cavity",
                surface.triangles.len()
            )));
        }
        // Made once per mesh; its corner ids are checked when it is made,
        // so both paths index the vertices safely from here on.
        if !scratch.order.fits(surface) {
            scratch.order = TriangleOrder::of(surface)?;
        }
        let projected = ProjectedSurface::frame_in(
            surface,
            params.gravity_m_s2,
            params.columns_per_side,
            std::mem::take(&mut scratch.uvh),
            std::mem::take(&mut scratch.triangles),
        )?;
        let bands = RowBands::new(
            projected.grid.n[1],
            projected.grid.n[0],
            BANDS_PER_THREAD * rayon::current_num_threads(),
        );
        Ok(Self {
            params: *params,
            projected,
            k: 1,
            bands,
            tally: SectionTally::default(),
            scratch,
        })
    }

    /// Each triangle's side and candidates and the leveraging `k`, without
    /// the row scan (what the GPU path uploads).
    pub(crate) fn classify(&mut self) {
        self.projected.classify();
        self.set_workers();
    }

    fn set_workers(&mut self) {
        self.k = workers_per_triangle(self.params.leverage_alpha, self.projected.mean_candidates);
    }

    /// Stage 2: each triangle's side and candidates, and its run of crossed
    /// columns in each of its candidate rows (the row scan,
    /// [`crate::row_scan`]).
    pub fn intersect(&mut self) {
        let split = TaskSplit::new(
            self.projected.surface.triangles.len(),
            TASKS_PER_THREAD * rayon::current_num_threads(),
            MIN_TASK_TRIANGLES,
        );
        let s = &mut *self.scratch;
        self.projected.mean_candidates = scan_triangles(
            &self.projected,
            split,
            self.bands,
            &mut s.tasks,
            s.order.visits(),
        );
        self.set_workers();
    }

    /// Stage 3: per column, the sections of fluid, and each bottom run's
    /// weight on its triangle's corners ([`crate::sections`],
    /// [`crate::distribute`]).
    pub fn match_sections(&mut self) {
        let scale = self.rho_g() * self.projected.grid.column_area();
        let s = &mut *self.scratch;
        let n_u = self.projected.grid.n[0];
        self.tally = match_bands(n_u, self.bands, &s.tasks, scale, &mut s.bands);
    }

    /// Stage 4: the weights onto the vertices, and the volume.
    pub fn distribute(self) -> FluidWeights {
        let p = &self.projected;
        let mut node_weights = vec![0.0; p.surface.vertices.len()];
        add_weights(
            &mut node_weights,
            self.scratch.bands.iter().flat_map(|b| &b.weighted),
        );
        let volume = p.grid.column_area() * self.tally.fluid_height;
        let (count, crossings) = (self.tally.count, self.tally.crossings);
        self.finish(node_weights, volume, count, crossings)
    }

    /// The projection stage's result (for the GPU twin, which uploads it).
    pub(crate) fn projected(&self) -> &ProjectedSurface<'a> {
        &self.projected
    }

    /// Workers per triangle (the leveraging `k`).
    pub(crate) fn workers(&self) -> usize {
        self.k
    }

    /// `ρ·|g|` in µN per mm³.
    pub(crate) fn rho_g(&self) -> f64 {
        self.params.density_kg_m3 * self.params.gravity_m_s2.length() * MICRONEWTON_PER_RHO_G_MM3
    }

    /// The result of either path's last stages.
    pub(crate) fn finish(
        self,
        node_weights: Vec<f64>,
        volume_mm3: f64,
        count: SectionCount,
        crossings: usize,
    ) -> FluidWeights {
        let weights = FluidWeights {
            total_weight: self.rho_g() * volume_mm3,
            node_weights,
            volume_mm3,
            count,
            crossings,
            workers_per_triangle: self.k,
            mean_candidates: self.projected.mean_candidates,
            grid: self.projected.grid,
        };
        (self.scratch.uvh, self.scratch.triangles) = self.projected.into_buffers();
        weights
    }
}

/// Row-scan tasks per rayon thread: a few, so a thread that finishes early
/// steals work.
const TASKS_PER_THREAD: usize = 4;

/// Row bands per rayon thread, at least (the section pass's tasks; a large
/// grid has more, [`RowBands::new`]).
const BANDS_PER_THREAD: usize = 8;

/// The fewest triangles a row-scan task takes, so a small surface is not
/// cut finer than its work.
const MIN_TASK_TRIANGLES: usize = 512;

#[cfg(test)]
#[path = "weighing_tests.rs"]
mod tests;
