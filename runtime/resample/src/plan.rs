//! The backend-independent half of a resampling call: deciding between a
//! full and a dirty-region resample, sizing the output, and choosing the
//! output region `R` and the cell blocks to rasterise.
//!
//! ## Dirty regions
//!
//! The caller's dirty box (rest-space world mm) becomes a box of source
//! vertices (rounded outwards); removed-tetrahedra changes add their cells.
//! Every block whose vertices meet that box has its deformed bounds
//! recomputed; `R` is the integer box around the union of those blocks'
//! **old and new** bounds, grown by one voxel and clipped to the output.
//! Any voxel whose set of containing tetrahedra, or whose owner's vertices,
//! changed lies in `R`. Outside `R` nothing changes, so the old values stay.
//! Inside `R` the owners are recomputed from scratch: `R` is cleared and every
//! block whose (new) bounds meet `R` is rasterised clipped to `R` — a scan
//! of all block bounds (0.375 byte per voxel), which also finds far-away
//! cells folded over `R`. Hence the result is bit-identical to a full
//! resample.

use super::blocks::BlockBounds;
use super::output_grid::{OutputGrid, VoxelBox};
use super::{
    Backend, Job, KernelConsts, Kernels, ResampleError, ResampleParams, ResampleReport, Session,
    TetMask,
};
use crate::deformation::DirtyRegion;
use crate::grid::Grid;
use glam::DVec3;

/// What the resampler saw of the removed-tetrahedra mask at its last call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct MaskState {
    pub generation: Option<u64>,
    pub changed: Option<VertexBox>,
}

/// Inclusive box of source vertices (voxel indices): lower and upper corner.
pub type VertexBox = ([usize; 3], [usize; 3]);

/// The source vertices a rest-space dirty box covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirtyVertices {
    /// The box holds no vertex.
    None,
    /// These vertices (rounded outwards, clipped to the grid).
    Box(VertexBox),
    /// The box is not finite: resample everything.
    All,
}

/// The source vertices inside a rest-space box (world mm), rounded outwards
/// and clipped to the grid.
pub fn dirty_vertex_box(grid: &Grid, min: DVec3, max: DVec3) -> DirtyVertices {
    let a = grid.world_to_index(min);
    let b = grid.world_to_index(max);
    if !(a.is_finite() && b.is_finite()) {
        return DirtyVertices::All;
    }
    let mut lo = [0usize; 3];
    let mut hi = [0usize; 3];
    for ax in 0..3 {
        let n = grid.dims[ax] as f64;
        let l = a[ax].min(b[ax]).floor();
        let h = a[ax].max(b[ax]).ceil();
        if h < 0.0 || l > n - 1.0 {
            return DirtyVertices::None;
        }
        lo[ax] = l.max(0.0) as usize;
        hi[ax] = h.min(n - 1.0) as usize;
    }
    DirtyVertices::Box((lo, hi))
}

fn union_box(a: Option<VertexBox>, b: VertexBox) -> Option<VertexBox> {
    Some(match a {
        None => b,
        Some((lo, hi)) => (
            [0, 1, 2].map(|i| lo[i].min(b.0[i])),
            [0, 1, 2].map(|i| hi[i].max(b.1[i])),
        ),
    })
}

fn check_finite(
    c: &KernelConsts,
    blocks: &[u32],
    bounds: &[BlockBounds],
) -> Result<(), ResampleError> {
    if let Some(i) = bounds.iter().position(|b| !b.is_finite()) {
        return Err(ResampleError::NonFiniteDisplacement {
            near: c.layout.vertices(blocks[i] as usize),
        });
    }
    Ok(())
}

fn union_all(bounds: &[BlockBounds]) -> BlockBounds {
    bounds.iter().fold(BlockBounds::EMPTY, |a, b| a.union(b))
}

/// One resampling call: plan, then run the kernels.
pub(crate) fn drive<K: Kernels>(
    params: &ResampleParams,
    session: &mut Option<Session>,
    k: &mut K,
    grid: &Grid,
    backend: Backend,
    mask: Option<&TetMask>,
    dirty: DirtyRegion,
) -> Result<ResampleReport, ResampleError> {
    let t_start = std::time::Instant::now();
    let mesh = super::SamplingMesh::new(grid)?;
    let sp = grid.spacing;
    if !(sp.x > 0.0 && sp.y > 0.0 && sp.z > 0.0 && sp.is_finite()) {
        return Err(ResampleError::BadSpacing {
            spacing: sp.to_array(),
        });
    }
    if let Some(m) = mask
        && m.cell_dims() != mesh.cell_dims()
    {
        return Err(ResampleError::MaskMismatch {
            mask: m.cell_dims(),
            mesh: mesh.cell_dims(),
        });
    }
    let layout = super::BlockLayout::new(&mesh);
    let consts = KernelConsts {
        mesh,
        layout,
        inv_spacing: [
            (1.0 / sp.x) as f32,
            (1.0 / sp.y) as f32,
            (1.0 / sp.z) as f32,
        ],
        eps: params.inclusion_epsilon.max(0.0),
        background: params.background,
        interpolation: params.interpolation,
    };
    let mask_now = MaskState {
        generation: mask.map(|m| m.generation()),
        changed: mask.and_then(|m| m.changed_cells()),
    };
    let factor = params.max_output_factor.max(1.0);
    let max_voxels = (factor * grid.len() as f64).min(u32::MAX as f64 - 1.0) as u64;
    // Names the factor (and so the scene key) in the output-size error.
    let name_factor = |e: ResampleError| match e {
        ResampleError::OutputTooLarge {
            dims, max_voxels, ..
        } => ResampleError::OutputTooLarge {
            dims,
            max_voxels,
            max_output_factor: factor,
        },
        e => e,
    };
    let nblocks = layout.count();

    // Decide: full, dirty, or nothing.
    let reusable = session.as_ref().is_some_and(|s| {
        s.source_grid == *grid && s.backend == backend && s.bounds.len() == nblocks
    });
    let mut changed_vertices = None;
    let mut full = !reusable;
    if reusable {
        let s = session.as_ref().expect("reusable session");
        match dirty {
            DirtyRegion::All => full = true,
            DirtyRegion::None => {}
            DirtyRegion::Box { min, max } => match dirty_vertex_box(grid, min, max) {
                DirtyVertices::Box(b) => changed_vertices = Some(b),
                DirtyVertices::None => {}
                DirtyVertices::All => full = true,
            },
        }
        if s.mask.generation != mask_now.generation {
            for (lo, hi) in [s.mask.changed, mask_now.changed].into_iter().flatten() {
                changed_vertices = union_box(changed_vertices, (lo, hi.map(|v| v + 1)));
            }
        }
        if !full && changed_vertices.is_none() {
            if let Some(s) = session.as_mut() {
                s.mask = mask_now;
            }
            return Ok(ResampleReport::default());
        }
    }

    let mut report = ResampleReport {
        full,
        ..Default::default()
    };
    let region;
    let output;
    let mut selected: Vec<u32>;
    if full {
        let all: Vec<u32> = (0..nblocks as u32).collect();
        let mut bounds = vec![BlockBounds::EMPTY; nblocks];
        k.block_bounds(&consts, &all, &mut bounds)?;
        check_finite(&consts, &all, &bounds)?;
        let u = union_all(&bounds);
        let need = VoxelBox::from_continuous(u.min, u.max, 0);
        let previous = session
            .as_ref()
            .filter(|s| s.source_grid == *grid)
            .map(|s| s.output);
        let base = previous.unwrap_or(OutputGrid::same_as_source(grid.dims));
        output = base
            .grown_to_cover(&need, params.growth_margin, max_voxels)
            .map_err(name_factor)?
            .unwrap_or(base);
        report.output_grid_changed = previous != Some(output);
        k.allocate_output(&output)?;
        region = output.index_box();
        selected = all;
        *session = Some(Session {
            source_grid: *grid,
            backend,
            bounds,
            output,
            mask: mask_now,
        });
    } else {
        let s = session.as_mut().expect("reusable session");
        let (vlo, vhi) = changed_vertices.expect("dirty vertices");
        let list = layout.blocks_touching_vertices(vlo, vhi);
        let mut newb = vec![BlockBounds::EMPTY; list.len()];
        k.block_bounds(&consts, &list, &mut newb)?;
        check_finite(&consts, &list, &newb)?;
        let mut old_u = BlockBounds::EMPTY;
        for (&b, nb) in list.iter().zip(&newb) {
            old_u = old_u.union(&s.bounds[b as usize]);
            s.bounds[b as usize] = *nb;
        }
        let new_u = union_all(&newb);
        s.mask = mask_now;
        let need = VoxelBox::from_continuous(new_u.min, new_u.max, 0);
        if let Some(grown) = s
            .output
            .grown_to_cover(&need, params.growth_margin, max_voxels)
            .map_err(name_factor)?
        {
            s.output = grown;
            k.allocate_output(&grown)?;
            report.full = true;
            report.output_grid_changed = true;
            region = grown.index_box();
            selected = (0..nblocks as u32).collect();
        } else {
            let u = old_u.union(&new_u);
            region = VoxelBox::from_continuous(u.min, u.max, 1).intersect(&s.output.index_box());
            if region.is_empty() {
                return Ok(report);
            }
            selected = Vec::new();
            for (b, bb) in s.bounds.iter().enumerate() {
                if bb.touches(region.lo, region.hi) {
                    selected.push(b as u32);
                }
            }
        }
        output = s.output;
    }
    selected.retain(|&b| layout.cell_count(b as usize) > 0);
    let s = session.as_ref().expect("session set above");
    let job = Job {
        consts: &consts,
        output: &output,
        region,
        blocks: &selected,
        bounds: &s.bounds,
    };
    tracing::trace!(elapsed = ?t_start.elapsed(), "resample: planned (bounds, output grid, blocks)");
    k.rasterise(&job)?;
    report.voxels_touched = region.count();
    report.cells_rasterised = selected
        .iter()
        .map(|&b| layout.cell_count(b as usize) as u64)
        .sum();
    let o = output.origin_index;
    report.region = Some((
        [0, 1, 2].map(|a| (region.lo[a] - o[a]) as usize),
        [0, 1, 2].map(|a| (region.hi[a] - o[a]) as usize),
    ));
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dirty_box_rounds_outwards_and_clips() {
        let g = Grid::new([10, 10, 10], DVec3::splat(2.0), DVec3::splat(-10.0));
        let b = dirty_vertex_box(
            &g,
            DVec3::new(-7.0, -10.0, 5.0),
            DVec3::new(-3.0, -10.0, 100.0),
        );
        assert_eq!(b, DirtyVertices::Box(([1, 0, 7], [4, 0, 9])));
        assert_eq!(
            dirty_vertex_box(&g, DVec3::splat(50.0), DVec3::splat(60.0)),
            DirtyVertices::None
        );
        assert_eq!(
            dirty_vertex_box(&g, DVec3::splat(f64::NAN), DVec3::ZERO),
            DirtyVertices::All
        );
    }
}
