//! The sampling-mesh tetrahedra a cut or a carve removes, for any model.
//!
//! The resampler's removed-tetrahedra mask lives on the source volume's
//! sampling mesh (one vertex per source voxel). When the elements are the
//! source voxels one for one, a cut link *is* a mesh edge and a carved
//! element *is* a mesh vertex ([`crate::model::ChainMail`] marks those
//! directly). A down-sampled or cropped model has fewer elements than mesh
//! vertices, so the same interaction is applied to the mesh itself: every
//! source vertex takes the model's displacement (trilinear, as `map` gives
//! it), and the mesh edges that cross the cut polygon, or the vertices the
//! carve region holds, lose their tetrahedra. Only the source vertices
//! that can reach the region are visited: its box, grown by the largest
//! displacement of the model and two voxels, in rest space.

use crate::lattice::ElementLattice;
use crate::mapping;
use crate::state::State;
use voxflex_core::cut_polygon::CutPolygon;
use voxflex_core::glam::DVec3;
use voxflex_resample::{tets_at_vertex, tets_cut_by};

/// Source voxels (inclusive index box) whose rest position lies within the
/// world box `[lo, hi]` grown by the model's largest displacement and two
/// voxels, clipped to the part of the source the model covers.
fn candidate_voxels(
    lat: &ElementLattice,
    state: &State,
    lo: DVec3,
    hi: DVec3,
) -> Option<([usize; 3], [usize; 3])> {
    let g = &lat.source;
    let cur = state.cur;
    let max_u = (0..lat.len())
        .filter(|&n| lat.present(n))
        .map(|n| {
            let u = state.get(cur, n);
            u[0].abs().max(u[1].abs()).max(u[2].abs()) as f64
        })
        .fold(0.0, f64::max);
    let grow = DVec3::splat(max_u) + g.spacing * 2.0;
    let (a, b) = (g.world_to_index(lo - grow), g.world_to_index(hi + grow));
    // The index box of a world box (the grid may flip axes).
    let (a, b) = (a.min(b), a.max(b));
    let span = lat.dims.map(|d| (d - 1) * lat.downsample);
    let mut out = ([0; 3], [0; 3]);
    for ax in 0..3 {
        let first = lat.first_voxel[ax] as f64;
        let last = first + span[ax] as f64;
        let (l, h) = (a[ax].floor().max(first), b[ax].ceil().min(last));
        if l > h {
            return None;
        }
        (out.0[ax], out.1[ax]) = (l as usize, h as usize);
    }
    Some(out)
}

/// Deformed world position (mm) of source voxel `v`.
fn deformed(lat: &ElementLattice, state: &State, v: [usize; 3]) -> DVec3 {
    let k = lat.downsample as f64;
    let f = [0, 1, 2].map(|a| (v[a] as f64 - lat.first_voxel[a] as f64) / k);
    let u = mapping::sample(lat, state, f);
    lat.source
        .index_to_world(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        + DVec3::new(u[0] as f64, u[1] as f64, u[2] as f64)
}

/// The deformed positions (mm) of the source voxels in the inclusive index
/// box `[a, b]`, x fastest, each computed once.
fn deformed_box(lat: &ElementLattice, state: &State, a: [usize; 3], b: [usize; 3]) -> Vec<DVec3> {
    let mut out = Vec::with_capacity((0..3).map(|k| b[k] - a[k] + 1).product());
    for k in a[2]..=b[2] {
        for j in a[1]..=b[1] {
            for i in a[0]..=b[0] {
                out.push(deformed(lat, state, [i, j, k]));
            }
        }
    }
    out
}

/// The voxel indices of entry `n` of a [`deformed_box`] over `[a, b]`.
fn box_voxel(a: [usize; 3], b: [usize; 3], n: usize) -> [usize; 3] {
    let (sx, sy) = (b[0] - a[0] + 1, b[1] - a[1] + 1);
    [a[0] + n % sx, a[1] + (n / sx) % sy, a[2] + n / (sx * sy)]
}

/// The mesh tetrahedra on edges that cross `cut` (deformed positions),
/// `(cell, bits)`.
pub fn cut_tets(lat: &ElementLattice, state: &State, cut: &CutPolygon) -> Vec<(usize, u8)> {
    let Some((a, b)) = candidate_voxels(lat, state, cut.lo, cut.hi) else {
        return Vec::new();
    };
    let cells = lat.source.dims.map(|d| d.saturating_sub(1));
    tets_cut_by(cells, (a, b), &deformed_box(lat, state, a, b), cut)
}

/// The mesh tetrahedra around vertices whose deformed position `inside`
/// holds, within the world box `[lo, hi]`, `(cell, bits)`.
pub fn carve_tets(
    lat: &ElementLattice,
    state: &State,
    (lo, hi): (DVec3, DVec3),
    inside: impl Fn(DVec3) -> bool,
) -> Vec<(usize, u8)> {
    let Some((a, b)) = candidate_voxels(lat, state, lo, hi) else {
        return Vec::new();
    };
    let cells = lat.source.dims.map(|d| d.saturating_sub(1));
    deformed_box(lat, state, a, b)
        .into_iter()
        .enumerate()
        .filter(|&(_, p)| inside(p))
        .flat_map(|(n, _)| tets_at_vertex(cells, box_voxel(a, b, n)))
        .collect()
}
