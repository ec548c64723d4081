//! The fluid-weight pipeline: project, intersect, match sections,
//! distribute — one stage method each.

use crate::column_grid::ColumnGrid;
use crate::error::FluidError;
use crate::hits::{Hit, find_hits};
use crate::params::FluidWeightParams;
use crate::projection::{ProjectedSurface, signed_area2};
use crate::schedule::workers_per_triangle;
use crate::sections::{SectionCount, bucket_by_column, match_sections};
use glam::DVec2;
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
        let mut w = FluidWeighing::project(surface, params, &mut self.scratch)?;
        w.intersect();
        w.match_sections();
        Ok(w.distribute())
    }
}

/// Working memory of one weighing (capacity reused between calls).
#[derive(Debug, Default)]
pub struct Scratch {
    uvh: Vec<glam::DVec3>,
    triangles: Vec<crate::projection::ProjectedTriangle>,
    batches: Vec<Vec<Hit>>,
    hits: Vec<Hit>,
    start: Vec<u32>,
}

/// The pipeline's state between stages.
#[derive(Debug)]
pub struct FluidWeighing<'a> {
    params: FluidWeightParams,
    projected: ProjectedSurface<'a>,
    k: usize,
    /// The paper's `c`, from the projection (it sets `k`).
    mean_candidates: f64,
    count: SectionCount,
    scratch: &'a mut Scratch,
}

impl<'a> FluidWeighing<'a> {
    /// Stage 1: the surface in the gravity frame, the grid, each
    /// triangle's side and candidates, and the leveraging `k`.
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
        let projected = ProjectedSurface::new_in(
            surface,
            params.gravity_m_s2,
            params.columns_per_side,
            std::mem::take(&mut scratch.uvh),
            std::mem::take(&mut scratch.triangles),
        );
        let mean_candidates = projected.mean_candidates();
        let k = workers_per_triangle(params.leverage_alpha, mean_candidates);
        Ok(Self {
            params: *params,
            projected,
            k,
            mean_candidates,
            count: SectionCount::default(),
            scratch,
        })
    }

    /// Stage 2: every column–triangle crossing, grouped by column.
    pub fn intersect(&mut self) {
        let s = &mut *self.scratch;
        find_hits(&self.projected, self.k, &mut s.batches);
        bucket_by_column(
            &s.batches,
            self.projected.grid.len(),
            &mut s.start,
            &mut s.hits,
        );
    }

    /// Stage 3: per column, the sections of fluid.
    pub fn match_sections(&mut self) {
        self.count = match_sections(&mut self.scratch.hits);
    }

    /// Stage 4: each section's weight `A·h·ρ·g` onto its bottom triangle's
    /// corners by the barycentric coordinates.
    pub fn distribute(self) -> FluidWeights {
        let p = &self.projected;
        let area = p.grid.column_area();
        let rho_g = self.rho_g();
        let mut node_weights = vec![0.0; p.surface.vertices.len()];
        let mut volume = 0.0;
        let n_u = p.grid.n[0];
        // Bottom crossings carry the height of fluid above them (sections pass).
        for h in self
            .scratch
            .hits
            .iter()
            .filter(|h| !h.top() && h.height > 0.0)
        {
            let v = area * h.height;
            volume += v;
            let tri = p.surface.triangles[h.triangle()];
            let c = h.column as usize;
            let centre = p.grid.centre(c % n_u, c / n_u);
            let bary = barycentric(tri.map(|i| p.uvh[i as usize].truncate()), centre);
            for (corner, b) in tri.iter().zip(bary) {
                node_weights[*corner as usize] += rho_g * v * b;
            }
        }
        let crossings = self.scratch.hits.len();
        let count = self.count;
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
            mean_candidates: self.mean_candidates,
            grid: self.projected.grid,
        };
        (self.scratch.uvh, self.scratch.triangles) = self.projected.into_buffers();
        weights
    }
}

/// Barycentric coordinates of `p` in the 2-D triangle `q` (they sum to 1
/// exactly in the last coordinate's definition).
fn barycentric(q: [DVec2; 3], p: DVec2) -> [f64; 3] {
    let area2 = signed_area2(q[0], q[1], q[2]);
    let b0 = signed_area2(p, q[1], q[2]) / area2;
    let b1 = signed_area2(q[0], p, q[2]) / area2;
    [b0, b1, 1.0 - b0 - b1]
}

#[cfg(test)]
#[path = "weighing_tests.rs"]
mod tests;
