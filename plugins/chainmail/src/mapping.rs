//! `map`: element displacements onto bound rest points.
//!
//! Elements sit on voxels, so the sampling mesh of the full-resolution,
//! uncropped model is bound by identity: voxel `v` takes element `v`'s
//! displacement, copied from the model's arrays (red-black order) into
//! voxel order. With
//! `downsample > 1`, a crop, or an explicit point list, a point takes the
//! trilinear interpolation of the 8 surrounding elements (absent elements
//! and sites outside the lattice count as still, displacement 0).

use crate::lattice::ElementLattice;
use crate::state::State;
use rayon::prelude::*;
use std::sync::atomic::Ordering::Relaxed;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;

/// True when `grid` is the model's own voxel lattice, element for voxel.
pub fn is_identity(lat: &ElementLattice, grid: &Grid) -> bool {
    *grid == lat.source && lat.downsample == 1 && lat.first_voxel == [0; 3] && lat.dims == grid.dims
}

/// Copies the current displacements (identity binding) into voxel order
/// (x fastest), interleaving each row's red and black slots.
pub fn copy_identity(lat: &ElementLattice, state: &State, out: [&mut [f32]; 3]) {
    let cur = state.cur;
    let order = lat.order();
    let [nx, ny, _] = lat.dims;
    for (a, o) in out.into_iter().enumerate() {
        let u = &state.u[cur][a];
        o.par_chunks_mut(nx).enumerate().for_each(|(row, o)| {
            let (j, k) = (row % ny, row / ny);
            for colour in 0..2 {
                let (start, p) = order.row(colour, j, k);
                for (q, s) in u[start..start + lat.hx].iter().enumerate() {
                    if let Some(o) = o.get_mut(2 * q + p) {
                        *o = f32::from_bits(s.load(Relaxed));
                    }
                }
            }
        });
    }
}

/// Displacement (mm) at continuous element coordinates `f`.
pub fn sample(lat: &ElementLattice, state: &State, f: [f64; 3]) -> [f32; 3] {
    let cur = state.cur;
    let base = f.map(|v| v.floor());
    let t = [0, 1, 2].map(|a| (f[a] - base[a]) as f32);
    let mut out = [0f32; 3];
    for corner in 0..8 {
        let o = [corner & 1, (corner >> 1) & 1, corner >> 2];
        let mut w = 1f32;
        let mut c = [0usize; 3];
        let mut inside = true;
        for a in 0..3 {
            let p = base[a] as i64 + o[a] as i64;
            inside &= p >= 0 && (p as usize) < lat.dims[a];
            c[a] = p.max(0) as usize;
            w *= if o[a] == 1 { t[a] } else { 1.0 - t[a] };
        }
        if !inside || w == 0.0 {
            continue;
        }
        let n = lat.linear(c);
        if !lat.present(n) {
            continue;
        }
        let u = state.get(cur, n);
        for a in 0..3 {
            out[a] += w * u[a];
        }
    }
    out
}

/// Interpolated displacements at every voxel of `grid` (x fastest).
pub fn sample_lattice(lat: &ElementLattice, state: &State, grid: &Grid, out: [&mut [f32]; 3]) {
    let [ox, oy, oz] = out;
    let k = lat.downsample as f64;
    let f0 = lat.first_voxel.map(|v| v as f64);
    let nx = grid.dims[0];
    let same = *grid == lat.source;
    ox.par_chunks_mut(nx)
        .zip(oy.par_chunks_mut(nx))
        .zip(oz.par_chunks_mut(nx))
        .enumerate()
        .for_each(|(row, ((x, y), z))| {
            let (j, kk) = (row % grid.dims[1], row / grid.dims[1]);
            for i in 0..nx {
                let f = if same {
                    [
                        (i as f64 - f0[0]) / k,
                        (j as f64 - f0[1]) / k,
                        (kk as f64 - f0[2]) / k,
                    ]
                } else {
                    let p = grid.index_to_world(DVec3::new(i as f64, j as f64, kk as f64));
                    element_coords(lat, p)
                };
                let u = sample(lat, state, f);
                (x[i], y[i], z[i]) = (u[0], u[1], u[2]);
            }
        });
}

/// Continuous element coordinates of a world point (mm).
pub fn element_coords(lat: &ElementLattice, p: DVec3) -> [f64; 3] {
    ((p - lat.origin) / DVec3::from(lat.spacing)).to_array()
}
