//! Finding the tetrahedron of a point: a uniform grid of tetrahedron
//! bounding boxes, containment by barycentric weights, and for points
//! outside the mesh the nearest point of its surface triangles by exact
//! point–triangle distance ([`SurfaceGrid`]).

#[cfg(test)]
use super::{CONTAINED, weights};
use crate::tet_mesh::TetMesh;
use glam::DVec3;

/// A uniform grid over the mesh bounds; each cell lists the tetrahedra
/// whose bounding boxes overlap it (compressed rows).
pub(super) struct TetGrid {
    pub(super) lo: DVec3,
    pub(super) cell: f64,
    pub(super) dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl TetGrid {
    pub(super) fn new(mesh: &TetMesh) -> Self {
        let (lo, cell, dims) = Self::layout(mesh);
        Self::from_boxes(lo, cell, dims, mesh.tets.len(), |t| {
            corner_box(&mesh.corners(t))
        })
    }

    /// The cells over `mesh`'s bounds: lower corner (mm), cell size (mm)
    /// and cells per axis, about one tetrahedron per cell (at most 1024
    /// cells per axis).
    fn layout(mesh: &TetMesh) -> (DVec3, f64, [usize; 3]) {
        let (lo, hi) = mesh.bounds();
        let extent = hi - lo;
        let volume = extent.x.max(1e-9) * extent.y.max(1e-9) * extent.z.max(1e-9);
        let cell = (volume / mesh.tets.len() as f64)
            .cbrt()
            .max(extent.max_element() / 1024.0)
            .max(1e-9);
        let dims = [0, 1, 2].map(|a| ((extent[a] / cell).floor() as usize + 1).min(1024));
        (lo, cell, dims)
    }

    /// A grid of `dims` cells of size `cell` from `lo` listing items
    /// `0..n` in the cells their bounding box `bounds(i)` overlaps.
    fn from_boxes(
        lo: DVec3,
        cell: f64,
        dims: [usize; 3],
        n: usize,
        bounds: impl Fn(usize) -> (DVec3, DVec3),
    ) -> Self {
        let range = |t: usize| {
            let (a, b) = bounds(t);
            (
                Self::cell_of(lo, cell, dims, a),
                Self::cell_of(lo, cell, dims, b),
            )
        };
        let linear = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
        let mut count = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for t in 0..n {
            let (a, b) = range(t);
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        count[linear([i, j, k]) + 1] += 1;
                    }
                }
            }
        }
        for c in 1..count.len() {
            count[c] += count[c - 1];
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; *count.last().unwrap_or(&0) as usize];
        for t in 0..n {
            let (a, b) = range(t);
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        let c = linear([i, j, k]);
                        items[fill[c] as usize] = t as u32;
                        fill[c] += 1;
                    }
                }
            }
        }
        Self {
            lo,
            cell,
            dims,
            start: count,
            items,
        }
    }

    pub(super) fn cell_of(lo: DVec3, cell: f64, dims: [usize; 3], p: DVec3) -> [usize; 3] {
        [0, 1, 2].map(|a| (((p[a] - lo[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1))
    }

    /// The tetrahedra listed in the cells at Chebyshev distance `ring` from
    /// cell `c` (cell indices).
    pub(super) fn ring(&self, c: [usize; 3], ring: usize, mut visit: impl FnMut(u32)) {
        let r = ring as isize;
        for dk in -r..=r {
            for dj in -r..=r {
                for di in -r..=r {
                    if di.abs().max(dj.abs()).max(dk.abs()) != r {
                        continue;
                    }
                    let q = [c[0] as isize + di, c[1] as isize + dj, c[2] as isize + dk];
                    if (0..3).any(|a| q[a] < 0 || q[a] >= self.dims[a] as isize) {
                        continue;
                    }
                    let l = q[0] as usize
                        + self.dims[0] * (q[1] as usize + self.dims[1] * q[2] as usize);
                    for &t in &self.items[self.start[l] as usize..self.start[l + 1] as usize] {
                        visit(t);
                    }
                }
            }
        }
    }
}

/// `w` with negative weights set to zero, renormalised (rounding on shared
/// faces).
pub(super) fn clamped(w: [f64; 4]) -> [f64; 4] {
    let c = w.map(|v| v.max(0.0));
    let s: f64 = c.iter().sum();
    c.map(|v| v / s)
}

/// The point of triangle `t` nearest `p` (Ericson, *Real-Time Collision
/// Detection*, 5.1.5), as weights of the triangle's corners.
fn nearest_on_triangle(t: [DVec3; 3], p: DVec3) -> [f64; 3] {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
}

/// The weights of the point of tetrahedron `x` nearest `p` (`p`'s own
/// weights when it is inside), and the squared distance (mm²).
#[cfg(test)]
fn nearest_in_tet(x: [DVec3; 4], p: DVec3) -> ([f64; 4], f64) {
    let w = weights(x, p);
    if w.iter().all(|&v| v >= -CONTAINED) {
        return (clamped(w), 0.0);
    }
    let mut best = ([0.0; 4], f64::INFINITY);
    for skip in 0..4 {
        let idx: Vec<usize> = (0..4).filter(|&k| k != skip).collect();
        let f = nearest_on_triangle([x[idx[0]], x[idx[1]], x[idx[2]]], p);
        let q = x[idx[0]] * f[0] + x[idx[1]] * f[1] + x[idx[2]] * f[2];
        let d = (q - p).length_squared();
        if d < best.1 {
            let mut w = [0.0; 4];
            for (m, &k) in idx.iter().enumerate() {
                w[k] = f[m];
            }
            best = (w, d);
        }
    }
    best
}

/// The bounding box of some points.
fn corner_box(x: &[DVec3]) -> (DVec3, DVec3) {
    x.iter()
        .fold((x[0], x[0]), |(a, b), p| (a.min(*p), b.max(*p)))
}

/// The mesh's surface ([`TetMesh::surface`]), in a grid of the same cells
/// as its [`TetGrid`]. The point of the mesh nearest a point
/// outside it lies on one of them, so that search tests a few triangles
/// per cell instead of every tetrahedron near the surface (four triangles
/// each). At 2:1 level changes of an octree proxy the fine and coarse
/// faces do not match and count as surface too (and a mesh that is not a
/// manifold lists every face): real faces of real tetrahedra, so the
/// nearest one found is still the nearest point.
pub(super) struct SurfaceGrid {
    grid: TetGrid,
    /// Per face: its tetrahedron and that tetrahedron's corner opposite it.
    faces: Vec<(u32, u8)>,
}

impl SurfaceGrid {
    pub(super) fn new(mesh: &TetMesh) -> Self {
        let faces = mesh.surface().unwrap_or_else(|_| {
            (0..mesh.tets.len() as u32)
                .flat_map(|t| (0..4).map(move |opp| (t, opp)))
                .collect()
        });
        let (lo, cell, dims) = TetGrid::layout(mesh);
        let grid = TetGrid::from_boxes(lo, cell, dims, faces.len(), |f| {
            let (t, opp) = faces[f];
            corner_box(&face(mesh, t, opp))
        });
        Self { grid, faces }
    }

    /// The tetrahedron nearest `p` (a point outside the mesh) and the
    /// weights of its nearest point.
    pub(super) fn nearest(&self, mesh: &TetMesh, p: DVec3) -> (u32, [f64; 4]) {
        let g = &self.grid;
        let c = TetGrid::cell_of(g.lo, g.cell, g.dims, p);
        let (f, w) = search_rings(g, c, p, |f| {
            let (t, opp) = self.faces[f as usize];
            let x = face(mesh, t, opp);
            let b = nearest_on_triangle(x, p);
            let q = x[0] * b[0] + x[1] * b[1] + x[2] * b[2];
            let mut w = [0.0; 4];
            let mut m = 0;
            for (k, wk) in w.iter_mut().enumerate() {
                if k != opp as usize {
                    *wk = b[m];
                    m += 1;
                }
            }
            (w, (q - p).length_squared())
        })
        .expect("a mesh has a surface");
        (self.faces[f as usize].0, w)
    }
}

/// The corners of tetrahedron `t` but `opp`, in order (mm).
fn face(mesh: &TetMesh, t: u32, opp: u8) -> [DVec3; 3] {
    mesh.face(t as usize, opp as usize)
        .map(|n| mesh.nodes[n as usize])
}

/// The item of `grid` nearest `p` by `distance(item) -> (weights, squared
/// distance)`, searching rings of cells outward from cell `c` (`p`'s cell,
/// or the nearest one when `p` lies outside the grid). With `q` the
/// projection of `p` onto the grid's box (in cell `c`), every point `y` of
/// the box has `|p − y|² ≥ |p − q|² + |q − y|²`, so cells of ring `r + 1`
/// lie at least `√(o² + (r · cell)²)` from `p` (`o = |p − q|`), and the
/// search stops once that bound passes the best distance found: a point
/// far outside the grid does not walk as many rings as it is far.
fn search_rings(
    grid: &TetGrid,
    c: [usize; 3],
    p: DVec3,
    mut distance: impl FnMut(u32) -> ([f64; 4], f64),
) -> Option<(u32, [f64; 4])> {
    let mut best: Option<(f64, u32, [f64; 4])> = None;
    let max_ring = grid.dims.iter().copied().max().unwrap_or(1);
    let hi = grid.lo + DVec3::from_array(grid.dims.map(|d| d as f64)) * grid.cell;
    let off = ((grid.lo - p).max(DVec3::ZERO) + (p - hi).max(DVec3::ZERO)).length_squared();
    for r in 0..=max_ring {
        grid.ring(c, r, |t| {
            let (w, d) = distance(t);
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, t, w));
            }
        });
        if let Some((d, ..)) = best
            && off + (r as f64 * grid.cell).powi(2) >= d
        {
            break;
        }
    }
    best.map(|(_, t, w)| (t, w))
}

/// The tetrahedron nearest `p` and the weights of its nearest point, by
/// every tetrahedron near it ([`search_rings`]): the reference that
/// [`SurfaceGrid::nearest`] is tested against.
#[cfg(test)]
pub(super) fn nearest(mesh: &TetMesh, grid: &TetGrid, c: [usize; 3], p: DVec3) -> (u32, [f64; 4]) {
    search_rings(grid, c, p, |t| nearest_in_tet(mesh.corners(t as usize), p))
        .expect("a mesh has at least one tetrahedron")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::proxy::{octree_proxy, uniform_proxy};

    /// The surface search finds as near a point as the search over every
    /// tetrahedron, for points around and inside the concave parts of a
    /// uniform proxy and of an octree proxy with level changes.
    #[test]
    fn the_surface_search_finds_the_nearest_point_of_every_tetrahedron() {
        let grid = Grid::new([13, 11, 9], DVec3::splat(2.0), DVec3::ZERO);
        // An L-shaped body (concave), two labels so the octree refines at
        // their border.
        let label = |v: [usize; 3]| (v[0] < 6 || v[1] < 4).then_some(u16::from(v[2] > 4));
        let uniform = uniform_proxy(&grid, 2, label).unwrap();
        let octree = octree_proxy(&grid, 4, label).unwrap().mesh;
        let mut seed = 0x2545_f491_u32;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f64 / u32::MAX as f64
        };
        for mesh in [&uniform, &octree] {
            let tets = TetGrid::new(mesh);
            let surface = SurfaceGrid::new(mesh);
            let mut outside = 0;
            for _ in 0..400 {
                let p = DVec3::new(rnd(), rnd(), rnd()) * DVec3::new(40.0, 36.0, 32.0)
                    - DVec3::splat(8.0);
                let c = TetGrid::cell_of(tets.lo, tets.cell, tets.dims, p);
                let (t, w) = nearest(mesh, &tets, c, p);
                let at = |t: u32, w: [f64; 4]| {
                    let x = mesh.corners(t as usize);
                    (0..4).map(|k| x[k] * w[k]).sum::<DVec3>()
                };
                let want = (at(t, w) - p).length();
                if want < 1e-9 {
                    continue; // inside: not the surface search's case
                }
                outside += 1;
                let (ts, ws) = surface.nearest(mesh, p);
                let got = (at(ts, ws) - p).length();
                assert!(
                    (got - want).abs() < 1e-9,
                    "{p}: surface {got} vs every tetrahedron {want}"
                );
                assert!((ws.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            }
            assert!(outside > 100, "the test needs points outside: {outside}");
        }
    }
}
