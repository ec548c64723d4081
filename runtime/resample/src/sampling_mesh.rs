//! The implicit sampling mesh: one vertex per source voxel centre, each
//! hexahedral cell split into five tetrahedra. Nothing of it is stored.
//!
//! Cell `(i, j, k)` (cell indices, `0 ≤ i < nx − 1`, …) has the eight corner
//! vertices `(i + cx, j + cy, k + cz)` for `cx, cy, cz ∈ {0, 1}`; corner
//! `c = cx + 2 cy + 4 cz` (so a corner's local number grows with its global
//! vertex id, x fastest). A cell whose `i + j + k` is even is split into the
//! four corner tetrahedra at corners 0, 3, 5, 6 and the central tetrahedron
//! {1, 2, 4, 7}; an odd cell uses the mirrored split (corners XOR 1), so the
//! diagonals of every face shared by two cells match and the mesh is
//! conforming.
//!
//! Every tetrahedron lists its four corners in ascending order. Its face `a`
//! (opposite corner `a`) is then the other three in ascending order, which is
//! also ascending global vertex order: two tetrahedra that share a face
//! compute the face's plane from the same vertices in the same order, bit
//! for bit (see [`super::raster`]).
//!
//! Tetrahedron id = `cell_linear * 5 + t` as `u32`, below `2³¹ − 1`, with
//! `cell_linear = i + (nx−1)·(j + (ny−1)·k)`. Pass 1 of the resampler
//! stores an *owner key* per output voxel: the id, with [`WEAK_OWNER`] set
//! for a tetrahedron that did not move or is inverted (`u32::MAX` = no
//! owner).

use super::ResampleError;
use crate::grid::Grid;

/// Tetrahedra per hexahedral cell.
pub const TETS_PER_CELL: usize = 5;

/// Bit of an owner key marking a *weak* claim of a tetrahedron on a voxel
/// centre: none of the tetrahedron's vertices moved, it is inverted (its
/// orientation opposite to its rest orientation), or the centre is the rest
/// position of one of its vertices that did not move (it touches the centre
/// only there). Where tetrahedra overlap, the smallest key wins, so a
/// moved, positively oriented tetrahedron always beats a weak claim, and
/// the smallest id only decides among equals. Without overlaps nothing
/// changes: a centre on a still vertex is weak for every tetrahedron there,
/// and every one of them gives the vertex's own value (the identity stays
/// bit-exact).
///
/// *Why:* a model that moves tissue into the air around it (ChainMail's air
/// voxels are not elements and never move) leaves the air's cells where
/// they were, under the stretched tissue, with the air vertices' own
/// tetrahedra touching each still vertex, and the cells between the moved
/// surface and the still air inverted. With the smallest id alone, these
/// won wherever their ids were smaller — only when tissue was pulled
/// towards lower voxel indices — and the stretched tissue vanished from the
/// output (issue 12, item 1). The rule is the same in every direction.
pub const WEAK_OWNER: u32 = 1 << 31;

/// The tetrahedron id of an owner key (see [`WEAK_OWNER`]).
pub const OWNER_ID: u32 = WEAK_OWNER - 1;

/// Corners (`c = cx + 2 cy + 4 cz`, ascending) of the five tetrahedra of a
/// cell, for even (`[0]`) and odd (`[1]`) `i + j + k`. Tetrahedron 4 is the
/// central one.
pub const CELL_TETS: [[[u8; 4]; TETS_PER_CELL]; 2] = [
    [
        [0, 1, 2, 4],
        [1, 2, 3, 7],
        [1, 4, 5, 7],
        [2, 4, 6, 7],
        [1, 2, 4, 7],
    ],
    [
        [0, 1, 3, 5],
        [0, 2, 3, 6],
        [0, 4, 5, 6],
        [3, 5, 6, 7],
        [0, 3, 5, 6],
    ],
];

/// Distinct triangular faces of one cell's five tetrahedra (12 on the cube's
/// faces, 4 inside), each as three ascending corners.
pub const FACES_PER_CELL: usize = 16;

/// The distinct faces of a cell and, per tetrahedron and per vertex `a`, the
/// index of the face opposite `a` (for even and odd cells).
pub(crate) struct FaceTables {
    /// `faces[parity][f]`: the three ascending corners of face `f`.
    pub faces: [[[u8; 3]; FACES_PER_CELL]; 2],
    /// `tet_faces[parity][t][a]`: the face opposite corner `CELL_TETS[parity][t][a]`
    /// (mirrored by `TET_FACES` in `raster.wgsl`; the CPU kernels use the
    /// derived [`CORNER_TABLES`]).
    #[cfg_attr(not(test), allow(dead_code))]
    pub tet_faces: [[[u8; 4]; TETS_PER_CELL]; 2],
}

const fn build_faces(
    tets: &[[u8; 4]; TETS_PER_CELL],
) -> ([[u8; 3]; FACES_PER_CELL], [[u8; 4]; TETS_PER_CELL]) {
    let mut faces = [[0u8; 3]; FACES_PER_CELL];
    let mut tet_faces = [[0u8; 4]; TETS_PER_CELL];
    let mut n = 0;
    let mut t = 0;
    while t < TETS_PER_CELL {
        let mut a = 0;
        while a < 4 {
            let mut f = [0u8; 3];
            let mut m = 0;
            let mut b = 0;
            while b < 4 {
                if b != a {
                    f[m] = tets[t][b];
                    m += 1;
                }
                b += 1;
            }
            let mut idx = n;
            let mut s = 0;
            while s < n {
                if faces[s][0] == f[0] && faces[s][1] == f[1] && faces[s][2] == f[2] {
                    idx = s;
                }
                s += 1;
            }
            if idx == n {
                assert!(n < FACES_PER_CELL, "more than 16 distinct faces");
                faces[n] = f;
                n += 1;
            }
            tet_faces[t][a] = idx as u8;
            a += 1;
        }
        t += 1;
    }
    assert!(n == FACES_PER_CELL, "expected 16 distinct faces");
    (faces, tet_faces)
}

const EVEN: ([[u8; 3]; FACES_PER_CELL], [[u8; 4]; TETS_PER_CELL]) = build_faces(&CELL_TETS[0]);
const ODD: ([[u8; 3]; FACES_PER_CELL], [[u8; 4]; TETS_PER_CELL]) = build_faces(&CELL_TETS[1]);

/// Face tables of both parities, computed at compile time from [`CELL_TETS`].
pub(crate) const FACE_TABLES: FaceTables = FaceTables {
    faces: [EVEN.0, ODD.0],
    tet_faces: [EVEN.1, ODD.1],
};

/// Per parity, how each corner tetrahedron (0..4) meets the central one (4).
///
/// - `interior[k] = [face, corner, central_opposite]`: the face corner
///   tetrahedron `k` shares with the central one, the corner vertex of `k`
///   (opposite that face in `k`) and the central tetrahedron's vertex
///   opposite it.
/// - `boundary[k][m] = [face, opposite]`: the three faces of `k` on the
///   cube's surface and the vertex of `k` opposite each.
///
/// The central tetrahedron's four faces are exactly the four interior faces.
pub(crate) struct CornerTables {
    pub interior: [[[u8; 3]; 4]; 2],
    pub boundary: [[[[u8; 2]; 3]; 4]; 2],
}

const fn contains(t: &[u8; 4], c: u8) -> bool {
    t[0] == c || t[1] == c || t[2] == c || t[3] == c
}

const fn build_corner_tables(p: usize) -> ([[u8; 3]; 4], [[[u8; 2]; 3]; 4]) {
    let tets = &CELL_TETS[p];
    let faces = if p == 0 { &EVEN.1 } else { &ODD.1 };
    let mut interior = [[0u8; 3]; 4];
    let mut boundary = [[[0u8; 2]; 3]; 4];
    let mut k = 0;
    while k < 4 {
        let mut m = 0;
        let mut a = 0;
        while a < 4 {
            let v = tets[k][a];
            if !contains(&tets[4], v) {
                // The corner vertex: the face opposite it is interior.
                let f = faces[k][a];
                let mut b = 0;
                let mut opp = 255u8;
                while b < 4 {
                    if faces[4][b] == f {
                        opp = tets[4][b];
                    }
                    b += 1;
                }
                assert!(opp != 255, "interior face not on the central tetrahedron");
                interior[k] = [f, v, opp];
            } else {
                assert!(m < 3, "a corner tetrahedron has exactly one corner vertex");
                boundary[k][m] = [faces[k][a], v];
                m += 1;
            }
            a += 1;
        }
        assert!(m == 3, "three boundary faces per corner tetrahedron");
        k += 1;
    }
    (interior, boundary)
}

const CORNER_EVEN: ([[u8; 3]; 4], [[[u8; 2]; 3]; 4]) = build_corner_tables(0);
const CORNER_ODD: ([[u8; 3]; 4], [[[u8; 2]; 3]; 4]) = build_corner_tables(1);

/// [`CornerTables`] of both parities, computed at compile time.
pub(crate) const CORNER_TABLES: CornerTables = CornerTables {
    interior: [CORNER_EVEN.0, CORNER_ODD.0],
    boundary: [CORNER_EVEN.1, CORNER_ODD.1],
};

/// The face test whose `D` decides each tetrahedron's orientation, and that
/// `D`'s sign at rest, per parity and tetrahedron: `(slot, positive)`, `D`
/// being the plane of the face opposite corner slot `slot` (ascending
/// corners) evaluated at that corner. For corner tetrahedron `k` it is the
/// interior face at its corner vertex, for the central one the interior face
/// of corner tetrahedron 0 at the central vertex opposite it — the `D`s the
/// CPU kernel already has (`lanes.rs`); `raster.wgsl` mirrors the table as
/// `ORIENT`. A tetrahedron is inverted when its `D` has the other sign.
pub(crate) const ORIENTATION: [[(u8, bool); TETS_PER_CELL]; 2] =
    [build_orientation(0), build_orientation(1)];

/// Per parity, tetrahedron and corner slot `a`: the sign that turns the
/// tetrahedron's one orientation `D` (at its [`ORIENTATION`] slot `o`) into
/// the `D_a` of its face opposite slot `a`, `D_a = sign · D`.
///
/// `D_a` (the plane of the face opposite `a`, ascending corners, at `P_a`)
/// is the determinant `[P_v − P_u, P_w − P_u, P_a − P_u]`, i.e. the
/// tetrahedron's oriented volume (×6) with slot `a` moved last: `(−1)^(3−a)`
/// times that of the ascending corners. So `D_a = (−1)^(a−o) D_o`, and one
/// determinant per tetrahedron gives all four, with one orientation for all
/// its faces even where rounding would give a nearly flat tetrahedron faces
/// of both signs. (Before, each face evaluated its own `D_a`: 20 per cell
/// instead of 5, the same values up to rounding.)
pub(crate) const D_SIGN: [[[f32; 4]; TETS_PER_CELL]; 2] = [build_d_sign(0), build_d_sign(1)];

const fn build_d_sign(p: usize) -> [[f32; 4]; TETS_PER_CELL] {
    let mut out = [[0.0; 4]; TETS_PER_CELL];
    let mut t = 0;
    while t < TETS_PER_CELL {
        let o = ORIENTATION[p][t].0 as usize;
        let mut a = 0;
        while a < 4 {
            out[t][a] = if (a + o) & 1 == 0 { 1.0 } else { -1.0 };
            a += 1;
        }
        t += 1;
    }
    out
}

/// The slot (0..4) of cell corner `corner` in `tet` (its corners
/// ascending); panics (at compile time in const use) if `tet` lacks it.
pub(crate) const fn slot_of(tet: &[u8; 4], corner: u8) -> usize {
    let mut a = 0;
    while a < 4 {
        if tet[a] == corner {
            return a;
        }
        a += 1;
    }
    panic!("corner not in tetrahedron")
}

/// `D` at rest (integer corners) of the face opposite slot `a` of `tet`.
const fn rest_d(p: usize, tet: &[u8; 4], a: usize) -> i32 {
    let f = FACE_TABLES.tet_faces[p][slot_tet(p, tet)][a];
    let [u, v, w] = FACE_TABLES.faces[p][f as usize];
    let (pu, pv, pw, pa) = (rest_pos(u), rest_pos(v), rest_pos(w), rest_pos(tet[a]));
    let x = [pv[0] - pu[0], pv[1] - pu[1], pv[2] - pu[2]];
    let y = [pw[0] - pu[0], pw[1] - pu[1], pw[2] - pu[2]];
    let n = [
        x[1] * y[2] - x[2] * y[1],
        x[2] * y[0] - x[0] * y[2],
        x[0] * y[1] - x[1] * y[0],
    ];
    n[0] * (pa[0] - pu[0]) + n[1] * (pa[1] - pu[1]) + n[2] * (pa[2] - pu[2])
}

/// Rest position of corner `c` (cell-local voxel index units).
const fn rest_pos(c: u8) -> [i32; 3] {
    let o = corner_offset(c);
    [o[0] as i32, o[1] as i32, o[2] as i32]
}

/// Which of the parity's five tetrahedra `tet` is.
const fn slot_tet(p: usize, tet: &[u8; 4]) -> usize {
    let mut t = 0;
    while t < TETS_PER_CELL {
        let c = &CELL_TETS[p][t];
        if c[0] == tet[0] && c[1] == tet[1] && c[2] == tet[2] && c[3] == tet[3] {
            return t;
        }
        t += 1;
    }
    panic!("not a tetrahedron of the cell")
}

const fn build_orientation(p: usize) -> [(u8, bool); TETS_PER_CELL] {
    let mut out = [(0u8, false); TETS_PER_CELL];
    let mut k = 0;
    while k < 4 {
        let tet = &CELL_TETS[p][k];
        let a = slot_of(tet, CORNER_TABLES.interior[p][k][1]);
        let d = rest_d(p, tet, a);
        assert!(d != 0, "a rest tetrahedron is not degenerate");
        out[k] = (a as u8, d > 0);
        k += 1;
    }
    let central = &CELL_TETS[p][4];
    let a = slot_of(central, CORNER_TABLES.interior[p][0][2]);
    let d = rest_d(p, central, a);
    assert!(d != 0, "a rest tetrahedron is not degenerate");
    out[4] = (a as u8, d > 0);
    out
}

/// Offset `[cx, cy, cz]` of cell corner `c` (`c = cx + 2 cy + 4 cz`).
#[inline]
pub const fn corner_offset(c: u8) -> [usize; 3] {
    [
        (c & 1) as usize,
        ((c >> 1) & 1) as usize,
        ((c >> 2) & 1) as usize,
    ]
}

/// `0` for a cell with even `i + j + k` (cell indices), `1` for odd.
#[inline]
pub const fn cell_parity(cell: [usize; 3]) -> usize {
    (cell[0] + cell[1] + cell[2]) & 1
}

/// Deformed position of a mesh vertex along one axis, in **source voxel
/// index** units: `index + displacement_mm * inv_spacing_per_mm`.
///
/// Every kernel (CPU and WGSL) computes vertex positions with exactly this
/// expression, so a zero displacement gives the exact integer index.
/// (`index` is below 2³², as every grid dimension is: the conversion goes
/// through `u32`, which rounds the same and needs no branch on x86-64.)
#[inline(always)]
pub fn deformed_coordinate(index: usize, displacement_mm: f32, inv_spacing_per_mm: f32) -> f32 {
    debug_assert!(u32::try_from(index).is_ok());
    index as u32 as f32 + displacement_mm * inv_spacing_per_mm
}

/// Indexing of the implicit sampling mesh of one source grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SamplingMesh {
    vertex_dims: [usize; 3],
}

impl SamplingMesh {
    /// The mesh of `grid`: at least 2 voxels per axis, and every tetrahedron
    /// id must fit [`OWNER_ID`] (below `2³¹ − 1`: 429 million cells, e.g.
    /// 512 × 512 × 1,600 voxels).
    pub fn new(grid: &Grid) -> Result<Self, ResampleError> {
        let d = grid.dims;
        if d.iter().any(|&n| n < 2) {
            return Err(ResampleError::GridTooSmall { dims: d });
        }
        let cells = (d[0] as u128 - 1) * (d[1] as u128 - 1) * (d[2] as u128 - 1);
        let tets = cells * TETS_PER_CELL as u128;
        if tets >= OWNER_ID as u128 {
            return Err(ResampleError::TooManyCells {
                dims: d,
                tetrahedra: tets as u64,
            });
        }
        Ok(Self { vertex_dims: d })
    }

    /// Vertices (= source voxels) along x, y, z.
    pub fn vertex_dims(&self) -> [usize; 3] {
        self.vertex_dims
    }

    /// Cells along x, y, z (one fewer than vertices).
    pub fn cell_dims(&self) -> [usize; 3] {
        let d = self.vertex_dims;
        [d[0] - 1, d[1] - 1, d[2] - 1]
    }

    /// Number of hexahedral cells.
    pub fn cell_count(&self) -> usize {
        let c = self.cell_dims();
        c[0] * c[1] * c[2]
    }

    /// Number of tetrahedra (`5 × cells`).
    pub fn tet_count(&self) -> usize {
        self.cell_count() * TETS_PER_CELL
    }

    /// Linear index of a cell (x fastest).
    #[inline]
    pub fn cell_linear(&self, cell: [usize; 3]) -> usize {
        let c = self.cell_dims();
        cell[0] + c[0] * (cell[1] + c[1] * cell[2])
    }

    /// Cell indices of a linear cell index.
    #[inline]
    pub fn cell_of_linear(&self, l: usize) -> [usize; 3] {
        let c = self.cell_dims();
        let i = l % c[0];
        let r = l / c[0];
        [i, r % c[1], r / c[1]]
    }

    /// Id of tetrahedron `t` (0..5) of a cell.
    #[inline]
    pub fn tet_id(&self, cell: [usize; 3], t: usize) -> u32 {
        (self.cell_linear(cell) * TETS_PER_CELL + t) as u32
    }

    /// Cell and local tetrahedron of a tetrahedron id.
    #[inline]
    pub fn decode_tet(&self, id: u32) -> ([usize; 3], usize) {
        let id = id as usize;
        (self.cell_of_linear(id / TETS_PER_CELL), id % TETS_PER_CELL)
    }

    /// The four vertex indices (source voxel indices, ascending corner order)
    /// of tetrahedron `t` of a cell.
    pub fn tet_vertices(&self, cell: [usize; 3], t: usize) -> [[usize; 3]; 4] {
        let corners = CELL_TETS[cell_parity(cell)][t];
        corners.map(|c| {
            let o = corner_offset(c);
            [cell[0] + o[0], cell[1] + o[1], cell[2] + o[2]]
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::needless_range_loop)]
    use super::*;
    use glam::DVec3;
    use std::collections::HashMap;

    fn det(p: [[f64; 3]; 4]) -> f64 {
        let a = DVec3::from(p[1]) - DVec3::from(p[0]);
        let b = DVec3::from(p[2]) - DVec3::from(p[0]);
        let c = DVec3::from(p[3]) - DVec3::from(p[0]);
        a.dot(b.cross(c))
    }

    #[test]
    fn tets_are_sorted_and_fill_the_cube() {
        for parity in 0..2 {
            let mut vol = 0.0;
            for tet in CELL_TETS[parity] {
                assert!(tet.windows(2).all(|w| w[0] < w[1]), "{tet:?} not ascending");
                let p = tet.map(|c| corner_offset(c).map(|v| v as f64));
                let v = det(p).abs() / 6.0;
                assert!(v > 0.1, "degenerate tet {tet:?}");
                vol += v;
            }
            assert!((vol - 1.0).abs() < 1e-12, "parity {parity}: volume {vol}");
        }
        // Mirrored: odd = even with corners XOR 1.
        for t in 0..TETS_PER_CELL {
            let mut m = CELL_TETS[0][t].map(|c| c ^ 1);
            m.sort();
            assert_eq!(m, CELL_TETS[1][t]);
        }
    }

    #[test]
    fn face_tables_match_tets() {
        for parity in 0..2 {
            for t in 0..TETS_PER_CELL {
                for a in 0..4 {
                    let f = FACE_TABLES.faces[parity][FACE_TABLES.tet_faces[parity][t][a] as usize];
                    let mut rest: Vec<u8> = CELL_TETS[parity][t].to_vec();
                    rest.remove(a);
                    assert_eq!(f.to_vec(), rest);
                }
            }
        }
    }

    /// Every interior triangle of a 3×3×3 block of cells belongs to exactly two
    /// tetrahedra (same vertex set), every boundary triangle to one, and every
    /// boundary triangle lies on the block's surface: the mesh is conforming.
    #[test]
    fn mirrored_decomposition_is_conforming() {
        let grid = Grid::new([4, 4, 4], DVec3::ONE, DVec3::ZERO);
        let mesh = SamplingMesh::new(&grid).unwrap();
        let mut faces: HashMap<[[usize; 3]; 3], usize> = HashMap::new();
        for k in 0..3 {
            for j in 0..3 {
                for i in 0..3 {
                    for t in 0..TETS_PER_CELL {
                        let v = mesh.tet_vertices([i, j, k], t);
                        for a in 0..4 {
                            let mut f: Vec<[usize; 3]> = v.to_vec();
                            f.remove(a);
                            f.sort_by_key(|p| grid.linear(p[0], p[1], p[2]));
                            *faces.entry([f[0], f[1], f[2]]).or_default() += 1;
                        }
                    }
                }
            }
        }
        let on_surface = |f: &[[usize; 3]; 3]| {
            (0..3).any(|ax| f.iter().all(|p| p[ax] == 0) || f.iter().all(|p| p[ax] == 3))
        };
        let mut interior = 0;
        for (f, n) in &faces {
            if on_surface(f) {
                assert_eq!(*n, 1, "surface face {f:?} used {n} times");
            } else {
                assert_eq!(*n, 2, "interior face {f:?} used {n} times: non-conforming");
                interior += 1;
            }
        }
        // 27 cells × 4 inner faces + 3 axes × 2 inner planes × 9 squares × 2 triangles.
        assert_eq!(interior, 27 * 4 + 3 * 2 * 9 * 2);
        // Surface: 6 sides × 9 squares × 2 triangles.
        assert_eq!(faces.len() - interior, 6 * 9 * 2);
    }

    #[test]
    fn ids_round_trip_and_limits() {
        let grid = Grid::new([5, 6, 7], DVec3::ONE, DVec3::ZERO);
        let mesh = SamplingMesh::new(&grid).unwrap();
        assert_eq!(mesh.cell_dims(), [4, 5, 6]);
        let id = mesh.tet_id([3, 2, 5], 4);
        assert_eq!(mesh.decode_tet(id), ([3, 2, 5], 4));
        assert_eq!(mesh.tet_count(), 4 * 5 * 6 * 5);
        assert!(matches!(
            SamplingMesh::new(&Grid::new([1, 4, 4], DVec3::ONE, DVec3::ZERO)),
            Err(ResampleError::GridTooSmall { .. })
        ));
        assert!(matches!(
            SamplingMesh::new(&Grid::new([1025, 1025, 1025], DVec3::ONE, DVec3::ZERO)),
            Err(ResampleError::TooManyCells { .. })
        ));
    }

    #[test]
    fn d_sign_turns_the_orientation_into_every_faces_rest_d() {
        for p in 0..2 {
            for (t, tet) in CELL_TETS[p].iter().enumerate() {
                let o = ORIENTATION[p][t].0 as usize;
                let d_o = rest_d(p, tet, o);
                for a in 0..4 {
                    assert_eq!(
                        rest_d(p, tet, a) as f32,
                        D_SIGN[p][t][a] * d_o as f32,
                        "parity {p}, tetrahedron {t}, slot {a}"
                    );
                }
            }
        }
    }

    #[test]
    fn corner_tables_split_each_cell() {
        for p in 0..2 {
            let central: Vec<u8> = FACE_TABLES.tet_faces[p][4].to_vec();
            let mut interior: Vec<u8> = CORNER_TABLES.interior[p].iter().map(|i| i[0]).collect();
            interior.sort();
            let mut c = central.clone();
            c.sort();
            assert_eq!(
                interior, c,
                "the central tetrahedron's faces are the interior faces"
            );
            let mut all: Vec<u8> = interior.clone();
            for k in 0..4 {
                let [f, corner, opp] = CORNER_TABLES.interior[p][k];
                assert!(!CELL_TETS[p][4].contains(&corner));
                assert!(CELL_TETS[p][4].contains(&opp));
                assert!(!FACE_TABLES.faces[p][f as usize].contains(&opp));
                for [bf, bo] in CORNER_TABLES.boundary[p][k] {
                    assert!(FACE_TABLES.faces[p][bf as usize].contains(&corner));
                    assert!(!FACE_TABLES.faces[p][bf as usize].contains(&bo));
                    all.push(bf);
                }
            }
            all.sort();
            assert_eq!(all, (0..16).collect::<Vec<u8>>(), "every face once");
        }
    }

    #[test]
    fn zero_displacement_gives_exact_index() {
        for i in [0usize, 1, 255, 4095, 16_000_000] {
            assert_eq!(deformed_coordinate(i, 0.0, 1.0 / 0.7), i as f32);
        }
    }
}
