//! The element lattice: one element per (down-sampled, cropped) voxel,
//! linked to its six face neighbours, with its material.
//!
//! Coordinates: element indices `[i, j, k]`; world positions in
//! millimetres through [`ElementLattice::world`].
//!
//! **Storage order is red-black** ([`ElementLattice::linear`]): the
//! elements with even `i + j + k` ("red", colour 0) come first, then the
//! odd ones; within a colour, rows run x-fastest with `i / 2` as the slot
//! (`hx = ⌈nx / 2⌉` slots per row; when `nx` is odd one slot of every other
//! row is padding, an absent site). Every neighbour of an element has the
//! other colour, and the neighbours of `8` consecutive slots are `8`
//! consecutive slots of the other colour (same slot on the ±y and ±z rows,
//! slot − 1 + p and slot + p on the same row for row parity `p`), so the
//! relaxation's half-sweeps load and store whole vectors. The GPU kernels
//! index the same way. Displacements are stored
//! per element in mm; the constraint of a link is an axis-aligned box of
//! half-size `D` (mm, per axis) around the rest offset, i.e.
//! `|u_n − u_e|_a ≤ D_a` on every axis `a` (eqs. (4)–(6) of the
//! heterogeneous ChainMail paper written in displacements). Cut links and
//! carved elements are topology changes: [`ElementLattice::neighbour`]
//! skips cut links and absent sites are not elements.

use crate::params::{ChainMailParams, Material};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{Sample, VolumeView};
use voxflex_core::with_voxels;

/// Element flags and material in one byte: bits 0–5 the material index
/// ([`ABSENT`] for no element), bit 6 held by a grab, bit 7 fixed.
pub type Cell = u8;
/// Material index of a lattice site that holds no element.
pub const ABSENT: u8 = 0x3f;
/// Bit set on an element a grab holds at its target.
pub const HELD: u8 = 0x40;
/// Bit set on a fixed element.
pub const FIXED: u8 = 0x80;

/// Added to an [`ElementLattice::interior`] entry: the element lies on the
/// lattice's low or high x face, and is interior otherwise.
pub const X_FACE: u8 = 0x40;

/// The six link directions, `(axis, sign)`, in the order every algorithm
/// visits neighbours: +x, −x, +y, −y, +z, −z.
pub const LINKS: [(usize, isize); 6] = [(0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1)];

/// Arrival-time quanta per unit of constraint fraction (see [`Link::tau`]).
pub const TIME_SCALE: f64 = 64.0;

/// A material as the kernels use it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialEntry {
    /// Constraint half-size per axis, mm.
    pub d: [f32; 3],
    /// Mean constraint fraction (dimensionless), for propagation times and
    /// relaxation weights.
    pub frac: f32,
    /// Relaxation step fraction: the material's `elastic` (1 elastic … 0
    /// plastic) times the over-relaxation factor ω (< 2).
    pub elastic: f32,
}

impl MaterialEntry {
    /// The kernels' entry for material `m` at `spacing` (mm), with the
    /// over-relaxation factor `omega` folded into its elastic fraction.
    fn new(m: &Material, spacing: [f64; 3], omega: f64) -> Self {
        let c = if m.rigid {
            [0.0; 3]
        } else {
            m.constraint.per_axis()
        };
        Self {
            d: [0, 1, 2].map(|a| (c[a] * spacing[a]) as f32),
            frac: ((c[0] + c[1] + c[2]) / 3.0) as f32,
            elastic: (m.elastic * omega) as f32,
        }
    }
}

/// A link between two elements, as the kernels use it.
#[derive(Clone, Copy, Debug)]
pub struct Link {
    /// Half-size of the constraint box, mm per axis (mean of the two ends).
    pub d: [f32; 3],
    /// Propagation time in integer quanta: `round(64 · c)` for the link's
    /// mean constraint fraction `c` (0 for rigid links, which propagate
    /// instantly). Arrival times are sums of these, so the earliest arrival
    /// follows the path of least total slack — the order in which the
    /// sequential algorithm must move elements of a heterogeneous model.
    pub tau: u32,
    /// Relaxation weight `1 / (c + ε)`.
    pub weight: f32,
}

/// Relaxation weight regulariser: rigid links (c = 0) weigh 1/ε.
pub const WEIGHT_EPS: f32 = 1e-3;

impl Link {
    /// The link between materials `a` and `b`.
    #[inline]
    pub fn between(a: &MaterialEntry, b: &MaterialEntry) -> Self {
        let frac = 0.5 * (a.frac + b.frac);
        Self {
            d: [0, 1, 2].map(|k| 0.5 * (a.d[k] + b.d[k])),
            tau: (frac as f64 * TIME_SCALE).round() as u32,
            weight: 1.0 / (frac + WEIGHT_EPS),
        }
    }

    /// True when `un` lies outside the box around `ue` (per axis).
    #[inline]
    pub fn violated(&self, un: [f32; 3], ue: [f32; 3]) -> bool {
        (0..3).any(|a| un[a] < ue[a] - self.d[a] || un[a] > ue[a] + self.d[a])
    }

    /// `un` moved to the nearest point of the box around `ue`.
    #[inline]
    pub fn clamp(&self, un: [f32; 3], ue: [f32; 3]) -> [f32; 3] {
        let d = &self.d;
        [
            un[0].max(ue[0] - d[0]).min(ue[0] + d[0]),
            un[1].max(ue[1] - d[1]).min(ue[1] + d[1]),
            un[2].max(ue[2] - d[2]).min(ue[2] + d[2]),
        ]
    }
}

/// Element geometry and materials.
#[derive(Clone, Debug)]
pub struct ElementLattice {
    /// Elements per axis.
    pub dims: [usize; 3],
    /// Element spacing, mm.
    pub spacing: [f64; 3],
    /// World position (mm) of element `[0, 0, 0]`.
    pub origin: DVec3,
    /// Source voxel index of element `[0, 0, 0]`.
    pub first_voxel: [usize; 3],
    /// Source voxels per element along each axis.
    pub downsample: usize,
    /// The source grid.
    pub source: Grid,
    /// Material table (index = material byte).
    pub materials: Vec<MaterialEntry>,
    /// Link table: `links[a * materials.len() + b]` for materials `a`, `b`.
    pub links: Vec<Link>,
    /// Slots per colour row, `⌈nx / 2⌉`.
    pub hx: usize,
    /// Sites per colour, `hx · ny · nz` (black sites start here).
    pub half: usize,
    /// Per site (red-black order): material index and flags.
    pub cells: Vec<Cell>,
    /// Per site: bit `l` set when link `l` (in [`LINKS`] order) was cut.
    /// Change it only through [`ElementLattice::cut_link`], which keeps
    /// [`ElementLattice::interior`] in step.
    pub cut: Vec<u8>,
    /// Per site: the material of an *interior* element — present, with all
    /// six links inside the lattice and uncut, each reaching an element of
    /// its own material — and [`ABSENT`] for every other site; elements
    /// that would be interior but for the lattice's x faces (their ±x link
    /// leaves the lattice) have [`X_FACE`] added. The 8-lane
    /// kernels take a window whose 8 bytes here are one material as
    /// uniform with one load instead of re-deriving it from `cells`, `cut`
    /// and the lattice's faces on every sweep. It depends on the topology
    /// only (flags aside), so it is computed once and updated by
    /// [`ElementLattice::cut_link`] and [`ElementLattice::remove`].
    interior: Vec<u8>,
}

impl ElementLattice {
    /// Builds the lattice of a volume: crop, down-sample, and keep the sites
    /// whose intensity matches a material (the first match wins).
    pub fn new(volume: VolumeView<'_>, params: &ChainMailParams) -> Result<Self, ModelError> {
        let g = volume.grid;
        let (lo, hi) = match params.crop {
            Some(c) => {
                if (0..3).any(|a| c.max[a] >= g.dims[a]) {
                    return Err(ModelError(format!(
                        "chainmail `crop`: max {:?} lies outside the volume (dims {:?})",
                        c.max, g.dims
                    )));
                }
                (c.min, c.max)
            }
            None => ([0; 3], g.dims.map(|d| d.saturating_sub(1))),
        };
        if g.is_empty() {
            return Err(ModelError::new("chainmail: the volume is empty"));
        }
        let k = params.downsample;
        let dims = [0, 1, 2].map(|a| (hi[a] - lo[a]) / k + 1);
        let hx = dims[0].div_ceil(2);
        let half = hx * dims[1] * dims[2];
        let n = 2 * half;
        if n > u32::MAX as usize / 2 {
            return Err(ModelError(format!(
                "chainmail: {dims:?} elements is too many; crop or raise `downsample`"
            )));
        }
        let sp = g.spacing.to_array();
        let spacing = sp.map(|s| s * k as f64);
        let omega = params.omega(dims.into_iter().max().unwrap_or(1));
        let materials: Vec<MaterialEntry> = params
            .materials
            .iter()
            .map(|m| MaterialEntry::new(m, spacing, omega))
            .collect();
        let ranges: Vec<[f64; 2]> = params.materials.iter().map(|m| m.range).collect();
        let classify = |v: f64| -> Cell {
            ranges
                .iter()
                .position(|r| v >= r[0] && v < r[1])
                .map_or(ABSENT, |m| m as u8)
        };
        let mut cells = vec![ABSENT; n];
        let order = Order { dims, hx, half };
        with_voxels!(volume.data, |s| fill_cells(
            s, &g, lo, k, order, &classify, &mut cells
        ));
        let origin = g.index_to_world(DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64));
        let links = materials
            .iter()
            .flat_map(|a| materials.iter().map(move |b| Link::between(a, b)))
            .collect();
        Ok(Self {
            links,
            dims,
            hx,
            half,
            spacing,
            origin,
            first_voxel: lo,
            downsample: k,
            source: g,
            materials,
            cut: vec![0; cells.len()],
            interior: Vec::new(),
            cells,
        }
        .with_interior())
    }

    /// The lattice with [`ElementLattice::interior`] computed for every site.
    fn with_interior(mut self) -> Self {
        self.interior = (0..self.len()).map(|n| self.interior_material(n)).collect();
        self
    }

    /// Per site: the material of an interior element, [`ABSENT`] otherwise
    /// (see the field's docs).
    #[inline]
    pub fn interior(&self) -> &[u8] {
        &self.interior
    }

    /// Site `n`'s entry of [`ElementLattice::interior`].
    fn interior_material(&self, n: usize) -> u8 {
        let m = self.cells[n] & ABSENT;
        if m == ABSENT || self.cut[n] != 0 {
            return ABSENT;
        }
        let c = self.coords(n);
        let offsets = self.offsets(c);
        let mut x_face = 0;
        for (l, &(a, s)) in LINKS.iter().enumerate() {
            let inside = if s < 0 {
                c[a] > 0
            } else {
                c[a] + 1 < self.dims[a]
            };
            if !inside && a == 0 {
                x_face = X_FACE;
            } else if !inside || self.cells[offsets[l].wrapping_add(n)] & ABSENT != m {
                return ABSENT;
            }
        }
        m | x_face
    }

    /// Recomputes the interior entries of site `n` and its neighbours after
    /// a topology change at `n`.
    fn refresh_interior(&mut self, n: usize) {
        let c = self.coords(n);
        let offsets = self.offsets(c);
        self.interior[n] = self.interior_material(n);
        for (l, &(a, s)) in LINKS.iter().enumerate() {
            let inside = if s < 0 {
                c[a] > 0
            } else {
                c[a] + 1 < self.dims[a]
            };
            if inside {
                let e = offsets[l].wrapping_add(n);
                self.interior[e] = self.interior_material(e);
            }
        }
    }

    /// Number of lattice sites (elements and absent sites).
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when the lattice has no site.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Storage index of element `[i, j, k]` (red-black order).
    #[inline]
    pub fn linear(&self, c: [usize; 3]) -> usize {
        self.order().linear(c)
    }

    /// Element indices of storage index `n` (of a padding site: `i = nx`).
    #[inline]
    pub fn coords(&self, n: usize) -> [usize; 3] {
        let colour = usize::from(n >= self.half);
        let r = n - colour * self.half;
        let (q, row) = (r % self.hx, r / self.hx);
        let (j, k) = (row % self.dims[1], row / self.dims[1]);
        [2 * q + ((colour + j + k) & 1), j, k]
    }

    /// The storage order's parameters.
    #[inline]
    pub fn order(&self) -> Order {
        Order {
            dims: self.dims,
            hx: self.hx,
            half: self.half,
        }
    }

    /// The neighbour of `n` (coordinates `c`) along link `l`, if inside and
    /// not cut.
    #[inline]
    pub fn neighbour(&self, n: usize, c: [usize; 3], l: usize) -> Option<usize> {
        if self.cut[n] & (1 << l) != 0 {
            return None;
        }
        let (a, s) = LINKS[l];
        if (s < 0 && c[a] == 0) || (s > 0 && c[a] + 1 == self.dims[a]) {
            return None;
        }
        Some(self.offsets(c)[l].wrapping_add(n))
    }

    /// Storage offsets from the element at `c` to its six neighbours, in
    /// [`LINKS`] order (wrapping arithmetic; only meaningful for neighbours
    /// inside the lattice). The neighbours have the other colour, so every
    /// offset crosses `±half`; along x the slot moves by `p` or `p − 1`
    /// for the row parity `p = i mod 2`.
    #[inline]
    pub fn offsets(&self, c: [usize; 3]) -> [usize; 6] {
        let colour = (c[0] + c[1] + c[2]) & 1;
        let to_other = if colour == 0 {
            self.half
        } else {
            self.half.wrapping_neg()
        };
        let p = c[0] & 1;
        let sz = self.hx * self.dims[1];
        [
            to_other.wrapping_add(p),
            to_other.wrapping_add(p).wrapping_sub(1),
            to_other.wrapping_add(self.hx),
            to_other.wrapping_sub(self.hx),
            to_other.wrapping_add(sz),
            to_other.wrapping_sub(sz),
        ]
    }

    /// True when site `n` holds an element.
    #[inline]
    pub fn present(&self, n: usize) -> bool {
        self.cells[n] & ABSENT != ABSENT
    }

    /// The material of a present element.
    #[inline]
    pub fn material(&self, n: usize) -> &MaterialEntry {
        &self.materials[(self.cells[n] & ABSENT) as usize]
    }

    /// The link between present elements `n` and `e`.
    #[inline]
    pub fn link(&self, n: usize, e: usize) -> &Link {
        self.material_link(self.cells[n] & ABSENT, self.cells[e] & ABSENT)
    }

    /// The link between elements of materials `a` and `b`.
    #[inline]
    pub fn material_link(&self, a: u8, b: u8) -> &Link {
        &self.links[a as usize * self.materials.len() + b as usize]
    }

    /// The smallest element spacing of the three axes, mm.
    pub fn smallest_spacing(&self) -> f64 {
        self.spacing.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// World position (mm) at rest of element `[i, j, k]`.
    pub fn world(&self, c: [usize; 3]) -> DVec3 {
        self.origin + DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * DVec3::from(self.spacing)
    }

    /// The present element nearest a world point (mm), by rest position.
    pub fn nearest(&self, p: DVec3) -> Option<usize> {
        let f = (p - self.origin) / DVec3::from(self.spacing);
        let c0 = [0, 1, 2].map(|a| f[a].round().clamp(0.0, (self.dims[a] - 1) as f64) as usize);
        let n0 = self.linear(c0);
        if self.present(n0) {
            return Some(n0);
        }
        // Widen the search shell by shell; the lattice is small enough for
        // a scan in the worst case.
        (0..self.len())
            .filter(|&n| self.present(n))
            .min_by(|&a, &b| {
                let da = (self.world(self.coords(a)) - p).length_squared();
                let db = (self.world(self.coords(b)) - p).length_squared();
                da.total_cmp(&db)
            })
    }

    /// Cuts link `l` of element `n` (both directions).
    pub fn cut_link(&mut self, n: usize, l: usize) {
        let c = self.coords(n);
        if let Some(e) = self.neighbour(n, c, l) {
            self.cut[n] |= 1 << l;
            // The opposite link of the neighbour: +x ↔ −x, …
            self.cut[e] |= 1 << (l ^ 1);
            self.interior[n] = ABSENT;
            self.interior[e] = ABSENT;
        }
    }

    /// Removes element `n` from the model (carving).
    pub fn remove(&mut self, n: usize) {
        self.cells[n] = ABSENT;
        self.refresh_interior(n);
    }

    /// Number of present elements.
    pub fn element_count(&self) -> usize {
        self.cells.iter().filter(|&&c| c & ABSENT != ABSENT).count()
    }
}

/// The red-black storage order of a lattice (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Order {
    /// Elements per axis.
    pub dims: [usize; 3],
    /// Slots per colour row, `⌈nx / 2⌉`.
    pub hx: usize,
    /// Sites per colour.
    pub half: usize,
}

impl Order {
    /// Storage index of element `[i, j, k]`.
    #[inline]
    pub fn linear(&self, c: [usize; 3]) -> usize {
        let colour = (c[0] + c[1] + c[2]) & 1;
        colour * self.half + (c[2] * self.dims[1] + c[1]) * self.hx + c[0] / 2
    }

    /// Storage index of slot 0 of colour `colour`'s row `(j, k)`, and the
    /// row's parity `p` (its slot `q` holds element `i = 2q + p`).
    #[inline]
    pub fn row(&self, colour: usize, j: usize, k: usize) -> (usize, usize) {
        (
            colour * self.half + (k * self.dims[1] + j) * self.hx,
            (colour + j + k) & 1,
        )
    }
}

fn fill_cells<T: Sample>(
    src: &[T],
    g: &Grid,
    lo: [usize; 3],
    k: usize,
    order: Order,
    classify: &dyn Fn(f64) -> Cell,
    cells: &mut [Cell],
) {
    let dims = order.dims;
    for ek in 0..dims[2] {
        for ej in 0..dims[1] {
            for ei in 0..dims[0] {
                let v = [lo[0] + ei * k, lo[1] + ej * k, lo[2] + ek * k];
                let value = src[g.linear(v[0], v[1], v[2])].to_f32() as f64;
                cells[order.linear([ei, ej, ek])] = classify(value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::volume::{Volume, VoxelData};

    /// A 13 × 9 × 7 lattice of two materials with holes.
    fn lattice() -> ElementLattice {
        let dims = [13, 9, 7];
        let data = (0..dims.iter().product::<usize>())
            .map(|v| match v % 23 {
                0 => 0,
                1..=4 => 200,
                _ => 100,
            })
            .collect();
        let vol = Volume {
            grid: Grid::new(dims, DVec3::ONE, DVec3::ZERO),
            data: VoxelData::U8(data),
        };
        let params = ChainMailParams::from_toml(
            "materials = [{ range = [50, 150], constraint = 0.2 }, \
             { range = [150, 256], constraint = 0.1 }]",
        )
        .unwrap();
        ElementLattice::new(vol.view(), &params).unwrap()
    }

    #[test]
    fn interior_entries_follow_cuts_and_carving() {
        let mut lat = lattice();
        let fresh = |lat: &ElementLattice| lat.clone().with_interior().interior;
        let interior = lat.interior().iter().filter(|&&m| m & ABSENT != ABSENT);
        assert!(
            interior.count() > 50,
            "the test lattice has interior elements"
        );
        assert!(lat.interior().iter().any(|&m| m & X_FACE != 0));
        // Only elements on the x faces carry the flag.
        for n in 0..lat.len() {
            let m = lat.interior()[n];
            if m & X_FACE != 0 {
                let c = lat.coords(n);
                assert!(c[0] == 0 || c[0] + 1 == lat.dims[0], "{c:?}");
            }
        }
        let mut seed = 7u64;
        for step in 0..200 {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let n = (seed >> 33) as usize % lat.len();
            if step % 3 == 0 {
                lat.remove(n);
            } else {
                lat.cut_link(n, (seed >> 20) as usize % 6);
            }
            assert_eq!(lat.interior, fresh(&lat), "after step {step}");
        }
    }
}
