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
    /// Ends of each spring (padded to a multiple of 8 with zero springs).
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
    /// Node `n`'s springs as end `a`: `a_start[n] .. a_start[n + 1]` (the
    /// springs are sorted by end `a`); as end `b`: the spring indices
    /// `b_list[b_start[n] .. b_start[n + 1]]` (8 words of padding at the
    /// end, for 8-wide reads).
    a_start: Vec<u32>,
    b_start: Vec<u32>,
    b_list: Vec<u32>,
    /// Displacement per node, mm.
    pub u: Vec<[f32; 3]>,
    /// Velocity per node, mm/s.
    pub v: Vec<[f32; 3]>,
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
        let m = springs.ends.len().next_multiple_of(8);
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
            3 * rest.len() < i32::MAX as usize
                && springs
                    .ends
                    .iter()
                    .flatten()
                    .all(|&n| (n as usize) < rest.len()),
            "spring ends must be nodes, and 3 × nodes must fit an i32 gather index"
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
        // For the CPU gather: the springs are sorted by their end `a`, so a
        // node's `a`-end springs are one range; its `b`-end springs a list.
        assert!(
            springs.ends.windows(2).all(|w| w[0] <= w[1]),
            "springs sorted by their ends"
        );
        let mut a_start = vec![0u32; n + 1];
        let mut b_start = vec![0u32; n + 1];
        for [p, q] in &springs.ends {
            a_start[*p as usize + 1] += 1;
            b_start[*q as usize + 1] += 1;
        }
        for i in 0..n {
            a_start[i + 1] += a_start[i];
            b_start[i + 1] += b_start[i];
        }
        let mut fill = b_start.clone();
        let mut b_list = vec![0u32; springs.ends.len() + 8];
        for (s, [_, q]) in springs.ends.iter().enumerate() {
            b_list[fill[*q as usize] as usize] = s as u32;
            fill[*q as usize] += 1;
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
            a_start,
            b_start,
            b_list,
            u: vec![[0.0; 3]; n],
            v: vec![[0.0; 3]; n],
            f: [vec![0.0; m], vec![0.0; m], vec![0.0; m]],
        }
    }

    /// Loads displacements (mm) and velocities (mm/s).
    pub fn load(&mut self, u: &[DVec3], v: &[DVec3]) {
        let f32s = |p: &DVec3| p.as_vec3().to_array();
        self.u.iter_mut().zip(u).for_each(|(d, s)| *d = f32s(s));
        self.v.iter_mut().zip(v).for_each(|(d, s)| *d = f32s(s));
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
            ends: (0..n).map(|s| [self.a[s], self.b[s]]).collect(),
            kc: (0..n).map(|s| [self.k[s], self.c[s]]).collect(),
        }
    }

    /// The node → spring incidence (`start`, `incident`; see the fields).
    pub fn incidence(&self) -> (&[u32], &[u32]) {
        (&self.incident_start, &self.incident)
    }

    /// Stores displacements (mm) and velocities (mm/s) back.
    pub fn store(&self, u: &mut [DVec3], v: &mut [DVec3]) {
        let f64s = |p: &[f32; 3]| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        u.iter_mut().zip(&self.u).for_each(|(d, s)| *d = f64s(s));
        v.iter_mut().zip(&self.v).for_each(|(d, s)| *d = f64s(s));
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
    #[inline]
    pub fn node_force(&self, n: usize) -> [f32; 3] {
        gather(&self.node_springs(), &self.f, n)
    }

    fn node_springs(&self) -> NodeSprings<'_> {
        NodeSprings {
            a_start: &self.a_start,
            b_start: &self.b_start,
            b_list: &self.b_list,
        }
    }

    /// One symplectic Euler step of `h` seconds for the `free` nodes, after
    /// [`SpringKernel::spring_pass`]: `v += h (f_springs + ext − α m v) / m`,
    /// `u += h v`, with `ext` the external force (µN), `mass` (g) and
    /// `alpha` the mass damping (1/s).
    pub fn integrate(&mut self, h: f32, ext: &[[f32; 3]], mass: &[f32], alpha: f32, free: &[bool]) {
        let springs = NodeSprings {
            a_start: &self.a_start,
            b_start: &self.b_start,
            b_list: &self.b_list,
        };
        let f = &self.f;
        self.u
            .par_iter_mut()
            .zip(self.v.par_iter_mut())
            .enumerate()
            .with_min_len(512)
            .for_each(|(n, (un, vn))| {
                if !free[n] {
                    return;
                }
                let fs = gather(&springs, f, n);
                for i in 0..3 {
                    let a = (fs[i] + ext[n][i] - alpha * mass[n] * vn[i]) / mass[n];
                    vn[i] += h * a;
                    un[i] += h * vn[i];
                }
            });
    }
}

/// Where each node's springs are (see the fields of [`SpringKernel`]).
struct NodeSprings<'a> {
    a_start: &'a [u32],
    b_start: &'a [u32],
    b_list: &'a [u32],
}

/// Node `n`'s spring force: the forces of the springs it is end `a` of
/// (one contiguous range), minus those of the springs it is end `b` of.
#[inline]
fn gather(springs: &NodeSprings<'_>, f: &[Vec<f32>; 3], n: usize) -> [f32; 3] {
    let (a0, a1) = (springs.a_start[n] as usize, springs.a_start[n + 1] as usize);
    let mut acc = [0, 1, 2].map(|k| f[k][a0..a1].iter().sum::<f32>());
    let (first, end) = (springs.b_start[n] as usize, springs.b_start[n + 1] as usize);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{
            __m256, __m256i, _mm256_add_ps, _mm256_castsi256_ps, _mm256_cmpgt_epi32,
            _mm256_loadu_si256, _mm256_mask_i32gather_ps, _mm256_set1_epi32, _mm256_setr_epi32,
            _mm256_setzero_ps,
        };
        // SAFETY: AVX2 is enabled at compile time (this block's cfg); the
        // index loads read 8 words from `first + i`, inside `b_list`, which
        // carries 8 words of padding; lanes past `end` are masked out of
        // the gathers; every listed spring index is below the length of the
        // force arrays.
        unsafe {
            let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let mut sums = [_mm256_setzero_ps(); 3];
            let mut i = first;
            while i < end {
                let count = _mm256_set1_epi32((end - i) as i32);
                let mask = _mm256_castsi256_ps(_mm256_cmpgt_epi32(count, lanes));
                let index = _mm256_loadu_si256(springs.b_list.as_ptr().add(i) as *const __m256i);
                for (k, sum) in sums.iter_mut().enumerate() {
                    let g: __m256 = _mm256_mask_i32gather_ps::<4>(
                        _mm256_setzero_ps(),
                        f[k].as_ptr(),
                        index,
                        mask,
                    );
                    *sum = _mm256_add_ps(*sum, g);
                }
                i += 8;
            }
            for (a, sum) in acc.iter_mut().zip(sums) {
                *a -=
                    bytemuck::cast::<[f32; 8], f32x8>(std::mem::transmute::<__m256, [f32; 8]>(sum))
                        .reduce_add();
            }
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    for &s in &springs.b_list[first..end] {
        for (k, a) in acc.iter_mut().enumerate() {
            *a -= f[k][s as usize];
        }
    }
    acc
}

/// `x[b[s + l]] − x[a[s + l]]` for the 8 springs `s .. s + 8`, per axis.
#[inline(always)]
fn end_difference(x: &[[f32; 3]], a: &[u32], b: &[u32], s: usize) -> [f32x8; 3] {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{
            __m256, __m256i, _mm256_i32gather_ps, _mm256_loadu_si256, _mm256_mullo_epi32,
            _mm256_set1_epi32,
        };
        let (ia, ib) = (&a[s..s + 8], &b[s..s + 8]);
        // SAFETY: AVX2 is enabled at compile time (this block's cfg); the
        // 8-word loads read `ia`/`ib`, which hold 8 `u32` each; every end
        // is a node index below `x.len()` (checked in `SpringKernel::new`,
        // which also keeps `3 · nodes` within `i32`), so each gathered word
        // `3 · node + axis` lies inside `x`.
        unsafe {
            let three = _mm256_set1_epi32(3);
            let oa = _mm256_mullo_epi32(_mm256_loadu_si256(ia.as_ptr() as *const __m256i), three);
            let ob = _mm256_mullo_epi32(_mm256_loadu_si256(ib.as_ptr() as *const __m256i), three);
            let base = x.as_ptr() as *const f32;
            let axis = |k: usize| -> f32x8 {
                let pa: __m256 = _mm256_i32gather_ps::<4>(base.add(k), oa);
                let pb: __m256 = _mm256_i32gather_ps::<4>(base.add(k), ob);
                bytemuck::cast::<[f32; 8], f32x8>(std::mem::transmute::<__m256, [f32; 8]>(pb))
                    - bytemuck::cast::<[f32; 8], f32x8>(std::mem::transmute::<__m256, [f32; 8]>(pa))
            };
            [axis(0), axis(1), axis(2)]
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let mut d = [[0f32; 8]; 3];
        for l in 0..8 {
            let (pa, pb) = (x[a[s + l] as usize], x[b[s + l] as usize]);
            for i in 0..3 {
                d[i][l] = pb[i] - pa[i];
            }
        }
        [f32x8::from(d[0]), f32x8::from(d[1]), f32x8::from(d[2])]
    }
}
