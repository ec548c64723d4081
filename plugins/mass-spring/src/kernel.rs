//! The spring-force kernel: 8 springs at a time in f32 ([`wide::f32x8`]),
//! then a gather per node (no atomics: each node sums its own springs), the
//! same split the WGSL twin will use.
//!
//! Precision: positions are never subtracted. A spring's current vector is
//! its rest vector plus the difference of its ends' *displacements*, and
//! its stretch is `(|d|² − L²) / (|d| + L)` with `|d|² − L² = 2 e·δ + δ·δ`
//! (`e` the rest vector, `δ` the displacement difference), so a strain of
//! 1e-6 is resolved in f32 on a model 100 mm from the origin.

use super::solver::Springs;
use rayon::prelude::*;
use voxflex_core::glam::DVec3;
use wide::f32x8;

/// Springs per parallel task.
const CHUNK: usize = 4096;

/// The springs and node state as f32 structure-of-arrays.
pub struct SpringKernel {
    /// Ends of each spring as state slots (see `slot_of`; padded to a
    /// multiple of 8 with zero springs).
    a: Vec<u32>,
    b: Vec<u32>,
    /// Rest vector `X_b − X_a` (mm), rest length (mm), stiffness (µN/mm),
    /// damping (µN·s/mm).
    e: [Vec<f32>; 3],
    rest: Vec<f32>,
    k: Vec<f32>,
    c: Vec<f32>,
    /// For the GPU twin: node `n`'s springs in
    /// `incident[incident_start[n] .. incident_start[n + 1]]`:
    /// the spring index, with the top bit set where `n` is its end `b`.
    incident_start: Vec<u32>,
    incident: Vec<u32>,
    /// The nodes' springs for the CPU gather, eight nodes at a time: group
    /// `g` (nodes `8g .. 8g + 8`) has `width[g]` rows of 8 tagged spring
    /// indices (as in `incident`) starting at `table[8 · row[g]]`, lane `l`
    /// holding node `8g + l`'s springs; short lanes are padded with
    /// `zero_spring`, whose force is always zero.
    group_row: Vec<u32>,
    group_width: Vec<u32>,
    table: Vec<u32>,
    /// Displacement per axis and node, mm (padded to a multiple of 8
    /// nodes).
    u: [Vec<f32>; 3],
    /// Velocity per axis and node, mm/s (padded likewise).
    v: [Vec<f32>; 3],
    /// Nodes (unpadded).
    nodes: usize,
    /// The state arrays' slot of each node, and the node in each slot.
    slot_of: Vec<u32>,
    node_at: Vec<u32>,
    /// Per spring: the force on end `a`, µN, per axis.
    f: [Vec<f32>; 3],
}

const END_B: u32 = 1 << 31;

/// The springs as the GPU twin's buffers hold them.
pub struct SpringTable {
    /// Rest vector `X_b − X_a` (mm) and rest length (mm).
    pub geometry: Vec<[f32; 4]>,
    /// End nodes.
    pub ends: Vec<[u32; 2]>,
    /// Stiffness (µN/mm) and damping (µN·s/mm).
    pub kc: Vec<[f32; 2]>,
}

impl SpringKernel {
    /// The kernel's arrays for `springs` between `rest` node positions.
    pub fn new(springs: &Springs, rest: &[DVec3]) -> Self {
        // At least one padding spring: its force is zero (both ends node 0,
        // no rest vector, no stiffness), and the gather table's short lanes
        // point at it.
        let m = (springs.ends.len() + 1).next_multiple_of(8);
        let pad = |mut v: Vec<f32>| {
            v.resize(m, 0.0);
            v
        };
        let ends = |i: usize| {
            let mut v: Vec<u32> = springs.ends.iter().map(|e| e[i]).collect();
            v.resize(m, 0);
            v
        };
        let (a, b) = (ends(0), ends(1));
        assert!(
            rest.len() < i32::MAX as usize
                && springs
                    .ends
                    .iter()
                    .flatten()
                    .all(|&n| (n as usize) < rest.len()),
            "spring ends must be nodes, and node indices must fit an i32 gather index"
        );
        let e = [0, 1, 2].map(|axis| {
            pad(springs
                .ends
                .iter()
                .map(|[p, q]| (rest[*q as usize][axis] - rest[*p as usize][axis]) as f32)
                .collect())
        });
        let n = rest.len();
        let mut incident_start = vec![0u32; n + 1];
        for [p, q] in &springs.ends {
            incident_start[*p as usize + 1] += 1;
            incident_start[*q as usize + 1] += 1;
        }
        for i in 0..n {
            incident_start[i + 1] += incident_start[i];
        }
        let mut fill = incident_start.clone();
        let mut incident = vec![0u32; 2 * springs.ends.len()];
        for (s, [p, q]) in springs.ends.iter().enumerate() {
            for (node, tag) in [(*p, 0), (*q, END_B)] {
                incident[fill[node as usize] as usize] = s as u32 | tag;
                fill[node as usize] += 1;
            }
        }
        // Slots: within each run of 16 nodes, the nodes ordered by their
        // number of springs, so the 8 nodes of a gather group have about as
        // many springs and the table's rows are nearly full (in the
        // five-tetrahedra split, alternate nodes have 18 and 6 springs),
        // while nodes stay near their mesh neighbours in memory (sorting
        // the whole list by degree measured slower: the spring pass's
        // gathers lose their locality).
        let degree = |node: usize| incident_start[node + 1] - incident_start[node];
        let mut node_at: Vec<u32> = (0..n as u32).collect();
        node_at.sort_by_key(|&node| (node / 16, std::cmp::Reverse(degree(node as usize))));
        let mut slot_of = vec![0u32; n];
        for (slot, &node) in node_at.iter().enumerate() {
            slot_of[node as usize] = slot as u32;
        }
        let (a, b) = (
            a.iter()
                .map(|&x| slot_of.get(x as usize).copied().unwrap_or(0))
                .collect::<Vec<u32>>(),
            b.iter()
                .map(|&x| slot_of.get(x as usize).copied().unwrap_or(0))
                .collect::<Vec<u32>>(),
        );
        // The gather table (see the fields), over slots.
        let zero_spring = springs.ends.len() as u32;
        let groups = n.div_ceil(8);
        let (mut group_row, mut group_width, mut table) = (Vec::new(), Vec::new(), Vec::new());
        for g in 0..groups {
            let nodes = (8 * g..(8 * g + 8).min(n)).map(|slot| node_at[slot] as usize);
            let list = |node: usize| {
                &incident[incident_start[node] as usize..incident_start[node + 1] as usize]
            };
            let width = nodes
                .clone()
                .map(|node| list(node).len())
                .max()
                .unwrap_or(0);
            group_row.push((table.len() / 8) as u32);
            group_width.push(width as u32);
            for j in 0..width {
                for l in 0..8 {
                    let slot = 8 * g + l;
                    let tag = if slot < n {
                        list(node_at[slot] as usize).get(j).copied()
                    } else {
                        None
                    };
                    table.push(tag.unwrap_or(zero_spring));
                }
            }
        }
        let f32s = |v: &[f64]| pad(v.iter().map(|&x| x as f32).collect());
        Self {
            a,
            b,
            e,
            rest: f32s(&springs.rest),
            k: f32s(&springs.k),
            c: f32s(&springs.c),
            incident_start,
            incident,
            group_row,
            group_width,
            table,
            slot_of,
            node_at,
            u: [0, 1, 2].map(|_| vec![0.0; n.next_multiple_of(8)]),
            v: [0, 1, 2].map(|_| vec![0.0; n.next_multiple_of(8)]),
            nodes: n,
            f: [vec![0.0; m], vec![0.0; m], vec![0.0; m]],
        }
    }

    /// Loads displacements (mm) and velocities (mm/s).
    pub fn load(&mut self, u: &[DVec3], v: &[DVec3]) {
        for (n, (un, vn)) in u.iter().zip(v).enumerate() {
            self.set_node(n, un.as_vec3().to_array(), vn.as_vec3().to_array());
        }
    }

    /// Stores displacements (mm) and velocities (mm/s) back.
    pub fn store(&self, u: &mut [DVec3], v: &mut [DVec3]) {
        for (n, (un, vn)) in u.iter_mut().zip(v.iter_mut()).enumerate() {
            let (a, b) = self.node(n);
            *un = DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
            *vn = DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64);
        }
    }

    /// Node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn node(&self, n: usize) -> ([f32; 3], [f32; 3]) {
        let n = self.slot_of[n] as usize;
        (
            [self.u[0][n], self.u[1][n], self.u[2][n]],
            [self.v[0][n], self.v[1][n], self.v[2][n]],
        )
    }

    /// Sets node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn set_node(&mut self, n: usize, u: [f32; 3], v: [f32; 3]) {
        let n = self.slot_of[n] as usize;
        for k in 0..3 {
            self.u[k][n] = u[k];
            self.v[k][n] = v[k];
        }
    }

    /// Applies the forces `f` (µN) to the `free` nodes for `h` seconds
    /// (symplectic Euler): the general path, when forces were summed and
    /// moved off hanging nodes on the CPU.
    pub fn apply(&mut self, f: &[DVec3], h: f64, masses: &[f64], free: &[bool]) {
        for (n, fn_) in f.iter().enumerate() {
            if free[n] {
                let a = (*fn_ * (h / masses[n])).as_vec3().to_array();
                let slot = self.slot_of[n] as usize;
                for (k, ak) in a.into_iter().enumerate() {
                    self.v[k][slot] += ak;
                    self.u[k][slot] += h as f32 * self.v[k][slot];
                }
            }
        }
    }

    /// Springs (unpadded count).
    pub fn springs(&self) -> usize {
        self.incident.len() / 2
    }

    /// The GPU twin's spring buffers.
    pub fn spring_table(&self) -> SpringTable {
        let n = self.springs();
        SpringTable {
            geometry: (0..n)
                .map(|s| [self.e[0][s], self.e[1][s], self.e[2][s], self.rest[s]])
                .collect(),
            ends: (0..n)
                .map(|s| {
                    [
                        self.node_at[self.a[s] as usize],
                        self.node_at[self.b[s] as usize],
                    ]
                })
                .collect(),
            kc: (0..n).map(|s| [self.k[s], self.c[s]]).collect(),
        }
    }

    /// The node → spring incidence (`start`, `incident`; see the fields).
    pub fn incidence(&self) -> (&[u32], &[u32]) {
        (&self.incident_start, &self.incident)
    }

    /// Per spring: the force on its end `a` (stretch and damping along it).
    pub fn spring_pass(&mut self) {
        let (u, v) = (&self.u, &self.v);
        let (a, b, e, rest, k, c) = (&self.a, &self.b, &self.e, &self.rest, &self.k, &self.c);
        let [fx, fy, fz] = &mut self.f;
        fx.par_chunks_mut(CHUNK)
            .zip(fy.par_chunks_mut(CHUNK))
            .zip(fz.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(chunk, ((fx, fy), fz))| {
                let first = chunk * CHUNK;
                for w in (0..fx.len()).step_by(8) {
                    let s = first + w;
                    let du = end_difference(u, a, b, s);
                    let dv = end_difference(v, a, b, s);
                    let load = |arr: &[f32]| {
                        f32x8::from(<[f32; 8]>::try_from(&arr[s..s + 8]).expect("8 springs"))
                    };
                    let [du0, du1, du2] = du;
                    let (e0, e1, e2) = (load(&e[0]), load(&e[1]), load(&e[2]));
                    let (d0, d1, d2) = (e0 + du0, e1 + du1, e2 + du2);
                    let len = (d0 * d0 + d1 * d1 + d2 * d2).sqrt();
                    // |d|² − L² without cancellation: 2 e·δ + δ·δ.
                    let grow = f32x8::splat(2.0) * (e0 * du0 + e1 * du1 + e2 * du2)
                        + du0 * du0
                        + du1 * du1
                        + du2 * du2;
                    let sum = len + load(rest);
                    let stretch = sum.simd_gt(f32x8::ZERO).select(grow / sum, f32x8::ZERO);
                    let inv = len
                        .simd_gt(f32x8::ZERO)
                        .select(f32x8::ONE / len, f32x8::ZERO);
                    let (n0, n1, n2) = (d0 * inv, d1 * inv, d2 * inv);
                    let rel = dv[0] * n0 + dv[1] * n1 + dv[2] * n2;
                    let mag = load(k) * stretch + load(c) * rel;
                    fx[w..w + 8].copy_from_slice(&(mag * n0).to_array());
                    fy[w..w + 8].copy_from_slice(&(mag * n1).to_array());
                    fz[w..w + 8].copy_from_slice(&(mag * n2).to_array());
                }
            });
    }

    /// The springs' force on node `n` (µN), after [`SpringKernel::spring_pass`].
    pub fn node_force(&self, n: usize) -> [f32; 3] {
        let slot = self.slot_of[n] as usize;
        let (g, lane) = (slot / 8, slot % 8);
        let row = self.group_row[g] as usize;
        let mut acc = [0f32; 3];
        for j in 0..self.group_width[g] as usize {
            let tagged = self.table[8 * (row + j) + lane];
            let s = (tagged & !END_B) as usize;
            let sign = if tagged & END_B == 0 { 1.0 } else { -1.0 };
            for (k, a) in acc.iter_mut().enumerate() {
                *a += sign * self.f[k][s];
            }
        }
        acc
    }

    /// One symplectic Euler step of `h` seconds for the `free` nodes, after
    /// [`SpringKernel::spring_pass`]: `v += h ((f_springs + ext) / m − α v)`,
    /// `u += h v`, with `ext` the external force (µN) and `inv_mass` (1/g)
    /// per axis and slot ([`SpringKernel::in_slot_order`]), `free` all ones on the
    /// nodes to move, and `alpha` the mass damping (1/s). Eight nodes at a
    /// time: each row of their gather table is one 8-wide gather per axis.
    pub fn integrate(
        &mut self,
        h: f32,
        ext: &[Vec<f32>; 3],
        inv_mass: &[f32],
        free: &[u32],
        alpha: f32,
    ) {
        let (rows, widths, table, f) = (&self.group_row, &self.group_width, &self.table, &self.f);
        let [u0, u1, u2] = &mut self.u;
        let [v0, v1, v2] = &mut self.v;
        let (h, alpha) = (f32x8::splat(h), f32x8::splat(alpha));
        u0.par_chunks_mut(8)
            .zip(u1.par_chunks_mut(8))
            .zip(u2.par_chunks_mut(8))
            .zip(
                v0.par_chunks_mut(8)
                    .zip(v1.par_chunks_mut(8))
                    .zip(v2.par_chunks_mut(8)),
            )
            .enumerate()
            .with_min_len(64)
            .for_each(|(g, (((u0, u1), u2), ((v0, v1), v2)))| {
                let row = rows[g] as usize;
                let forces = gather8(&table[8 * row..8 * (row + widths[g] as usize)], f);
                let at =
                    |a: &[f32]| f32x8::from(<[f32; 8]>::try_from(&a[8 * g..8 * g + 8]).expect("8"));
                let inv_m = at(inv_mass);
                let moves: f32x8 =
                    bytemuck::cast(<[u32; 8]>::try_from(&free[8 * g..8 * g + 8]).expect("8"));
                for (k, (u, v)) in [(u0, v0), (u1, v1), (u2, v2)].into_iter().enumerate() {
                    let (uk, vk) = (
                        f32x8::from(<[f32; 8]>::try_from(&*u).expect("8")),
                        f32x8::from(<[f32; 8]>::try_from(&*v).expect("8")),
                    );
                    let a = (f32x8::from(forces[k]) + at(&ext[k])) * inv_m - alpha * vk;
                    let vn = vk + h * a;
                    let un = uk + h * vn;
                    u.copy_from_slice(&moves.select(un, uk).to_array());
                    v.copy_from_slice(&moves.select(vn, vk).to_array());
                }
            });
    }

    /// Per-node values (node order) in slot order, padded with `pad` to a
    /// multiple of 8: the per-node arrays [`SpringKernel::integrate`] takes.
    pub fn in_slot_order<T: Copy>(&self, per_node: &[T], pad: T) -> Vec<T> {
        let mut out: Vec<T> = self.node_at.iter().map(|&n| per_node[n as usize]).collect();
        out.resize(self.nodes.next_multiple_of(8), pad);
        out
    }
}

/// The spring forces of 8 nodes from their gather-table rows (8 tagged
/// spring indices each): per axis, per lane.
#[inline]
fn gather8(rows: &[u32], f: &[Vec<f32>; 3]) -> [[f32; 8]; 3] {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{
            __m256, __m256i, _mm256_add_ps, _mm256_and_si256, _mm256_castsi256_ps,
            _mm256_i32gather_ps, _mm256_loadu_si256, _mm256_set1_epi32, _mm256_setzero_ps,
            _mm256_xor_ps,
        };
        // SAFETY: AVX2 is enabled at compile time (this block's cfg); each
        // row is 8 words of `rows`; every spring index in the table (the
        // padding's included) is below the length of the force arrays.
        unsafe {
            let index_bits = _mm256_set1_epi32(!END_B as i32);
            let sign_bit = _mm256_set1_epi32(END_B as i32);
            let mut acc = [_mm256_setzero_ps(); 3];
            for row in rows.chunks_exact(8) {
                let tags = _mm256_loadu_si256(row.as_ptr() as *const __m256i);
                let index = _mm256_and_si256(tags, index_bits);
                let sign = _mm256_castsi256_ps(_mm256_and_si256(tags, sign_bit));
                for (k, a) in acc.iter_mut().enumerate() {
                    let g: __m256 = _mm256_i32gather_ps::<4>(f[k].as_ptr(), index);
                    *a = _mm256_add_ps(*a, _mm256_xor_ps(g, sign));
                }
            }
            acc.map(|a| std::mem::transmute::<__m256, [f32; 8]>(a))
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let mut acc = [[0f32; 8]; 3];
        for row in rows.chunks_exact(8) {
            for (l, &tagged) in row.iter().enumerate() {
                let s = (tagged & !END_B) as usize;
                let sign = if tagged & END_B == 0 { 1.0 } else { -1.0 };
                for k in 0..3 {
                    acc[k][l] += sign * f[k][s];
                }
            }
        }
        acc
    }
}

/// `x[b[s + l]] − x[a[s + l]]` for the 8 springs `s .. s + 8`, per axis.
#[inline(always)]
fn end_difference(x: &[Vec<f32>; 3], a: &[u32], b: &[u32], s: usize) -> [f32x8; 3] {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{__m256, __m256i, _mm256_i32gather_ps, _mm256_loadu_si256};
        let (ia, ib) = (&a[s..s + 8], &b[s..s + 8]);
        // SAFETY: AVX2 is enabled at compile time (this block's cfg); the
        // 8-word loads read `ia`/`ib`, which hold 8 `u32` each; every end
        // is a node index below the per-axis arrays' length (checked in
        // `SpringKernel::new`, which also keeps node indices within `i32`).
        unsafe {
            let oa = _mm256_loadu_si256(ia.as_ptr() as *const __m256i);
            let ob = _mm256_loadu_si256(ib.as_ptr() as *const __m256i);
            let axis = |k: usize| -> f32x8 {
                let pa: __m256 = _mm256_i32gather_ps::<4>(x[k].as_ptr(), oa);
                let pb: __m256 = _mm256_i32gather_ps::<4>(x[k].as_ptr(), ob);
                bytemuck::cast::<[f32; 8], f32x8>(std::mem::transmute::<__m256, [f32; 8]>(pb))
                    - bytemuck::cast::<[f32; 8], f32x8>(std::mem::transmute::<__m256, [f32; 8]>(pa))
            };
            [axis(0), axis(1), axis(2)]
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let d = |k: usize| {
            f32x8::from(std::array::from_fn::<f32, 8, _>(|l| {
                x[k][b[s + l] as usize] - x[k][a[s + l] as usize]
            }))
        };
        [d(0), d(1), d(2)]
    }
}
