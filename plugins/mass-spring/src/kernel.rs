//! The spring-force kernel: 8 springs at a time in f32 ([`wide::f32x8`]),
//! then a gather per node (no atomics: each node sums its own springs), the
//! same split the WGSL twin uses.
//!
//! **Layout.** Each node's state is one 32-byte row
//! `[ux, uy, uz, 0, vx, vy, vz, 0]` (displacement mm, velocity mm/s), so a
//! spring end is one aligned 256-bit load; the 8 rows of 8 springs' end
//! differences are transposed in registers into per-axis vectors
//! (20 shuffles), and the 8 forces transposed back into one 16-byte row
//! `[fx, fy, fz, 0]` per spring. Each node then sums its springs' rows,
//! those where it is end `a` first, then those where it is end `b`
//! (subtracted), four lanes at a time. On AVX2 this replaced 15 gathers
//! per 8 springs and their nodes (a gather costs about as much as 8
//! loads).
//!
//! Precision: positions are never subtracted. A spring's current vector is
//! its rest vector plus the difference of its ends' *displacements*, and
//! its stretch is `(|d|² − L²) / (|d| + L)` with `|d|² − L² = 2 e·δ + δ·δ`
//! (`e` the rest vector, `δ` the displacement difference), so a strain of
//! 1e-6 is resolved in f32 on a model 100 mm from the origin.

use super::solver::Springs;
use rayon::prelude::*;
use voxflex_core::glam::DVec3;
use wide::{f32x4, f32x8};

/// Springs per parallel task (a multiple of 8).
const CHUNK: usize = 4096;
/// Nodes per parallel task of the update.
const NODE_CHUNK: usize = 512;

/// The springs and node state as f32 arrays.
pub struct SpringKernel {
    /// Ends of each spring (padded to a multiple of 8 with zero springs
    /// between node 0 and itself).
    a: Vec<u32>,
    b: Vec<u32>,
    /// Rest vector `X_b − X_a` (mm), rest length (mm), stiffness (µN/mm),
    /// damping (µN·s/mm).
    e: [Vec<f32>; 3],
    rest: Vec<f32>,
    k: Vec<f32>,
    c: Vec<f32>,
    /// Node `n`'s springs in `incident[incident_start[n] .. incident_start[n + 1]]`:
    /// the spring index, with the top bit set where `n` is its end `b`;
    /// those where `n` is end `a` come first, up to `incident_mid[n]`.
    incident_start: Vec<u32>,
    incident_mid: Vec<u32>,
    incident: Vec<u32>,
    /// Per node: `[ux, uy, uz, 0, vx, vy, vz, 0]`, displacement (mm) and
    /// velocity (mm/s). At least one row, so the padding springs' ends
    /// exist.
    state: Vec<f32x8>,
    /// Nodes.
    nodes: usize,
    /// Per spring: `[fx, fy, fz, 0]`, the force on end `a`, µN.
    f: Vec<f32x4>,
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
        let n = rest.len();
        assert!(
            n < (u32::MAX / 8) as usize
                && springs
                    .ends
                    .iter()
                    .flatten()
                    .all(|&node| (node as usize) < n),
            "spring ends must be nodes, and 8 × the node count must fit a u32"
        );
        let e = [0, 1, 2].map(|axis| {
            pad(springs
                .ends
                .iter()
                .map(|[p, q]| (rest[*q as usize][axis] - rest[*p as usize][axis]) as f32)
                .collect())
        });
        let mut incident_start = vec![0u32; n + 1];
        let mut incident_mid = vec![0u32; n];
        for [p, q] in &springs.ends {
            incident_start[*p as usize + 1] += 1;
            incident_start[*q as usize + 1] += 1;
            incident_mid[*p as usize] += 1;
        }
        for i in 0..n {
            incident_start[i + 1] += incident_start[i];
            incident_mid[i] += incident_start[i];
        }
        // End-a entries fill from the start, end-b entries from the middle.
        let mut fill_a = incident_start.clone();
        let mut fill_b = incident_mid.clone();
        let mut incident = vec![0u32; 2 * springs.ends.len()];
        for (s, [p, q]) in springs.ends.iter().enumerate() {
            incident[fill_a[*p as usize] as usize] = s as u32;
            fill_a[*p as usize] += 1;
            incident[fill_b[*q as usize] as usize] = s as u32 | END_B;
            fill_b[*q as usize] += 1;
        }
        let f32s = |v: &[f64]| pad(v.iter().map(|&x| x as f32).collect());
        Self {
            a: ends(0),
            b: ends(1),
            e,
            rest: f32s(&springs.rest),
            k: f32s(&springs.k),
            c: f32s(&springs.c),
            incident_start,
            incident_mid,
            incident,
            state: vec![f32x8::ZERO; n.max(1)],
            nodes: n,
            f: vec![f32x4::ZERO; m],
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
        let r = self.state[n].to_array();
        ([r[0], r[1], r[2]], [r[4], r[5], r[6]])
    }

    /// Sets node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn set_node(&mut self, n: usize, u: [f32; 3], v: [f32; 3]) {
        self.state[n] = f32x8::from([u[0], u[1], u[2], 0.0, v[0], v[1], v[2], 0.0]);
    }

    /// Applies the forces `f` (µN) to the `free` nodes for `h` seconds
    /// (symplectic Euler): the general path, when forces were summed and
    /// moved off hanging nodes on the CPU.
    pub fn apply(&mut self, f: &[DVec3], h: f64, masses: &[f64], free: &[bool]) {
        for (n, fn_) in f.iter().enumerate() {
            if free[n] {
                let a = (*fn_ * (h / masses[n])).as_vec3().to_array();
                let (mut u, mut v) = self.node(n);
                for k in 0..3 {
                    v[k] += a[k];
                    u[k] += h as f32 * v[k];
                }
                self.set_node(n, u, v);
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
            ends: (0..n).map(|s| [self.a[s], self.b[s]]).collect(),
            kc: (0..n).map(|s| [self.k[s], self.c[s]]).collect(),
        }
    }

    /// The node → spring incidence (`start`, `incident`; see the fields).
    pub fn incidence(&self) -> (&[u32], &[u32]) {
        (&self.incident_start, &self.incident)
    }

    /// Per spring: the force on its end `a` (stretch and damping along it).
    pub fn spring_pass(&mut self) {
        let state = &self.state;
        let (a, b, e, rest, k, c) = (&self.a, &self.b, &self.e, &self.rest, &self.k, &self.c);
        self.f
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(chunk, out)| {
                let first = chunk * CHUNK;
                for w in (0..out.len()).step_by(8) {
                    let s = first + w;
                    let [du0, du1, du2, dv0, dv1, dv2] = end_differences(state, a, b, s);
                    let load = |arr: &[f32]| {
                        f32x8::from(<[f32; 8]>::try_from(&arr[s..s + 8]).expect("8 springs"))
                    };
                    let (e0, e1, e2) = (load(&e[0]), load(&e[1]), load(&e[2]));
                    let (d0, d1, d2) = (e0 + du0, e1 + du1, e2 + du2);
                    let len = (d0 * d0 + d1 * d1 + d2 * d2).sqrt();
                    // |d|² − L² without cancellation: 2 e·δ + δ·δ.
                    let grow = f32x8::splat(2.0) * (e0 * du0 + e1 * du1 + e2 * du2)
                        + du0 * du0
                        + du1 * du1
                        + du2 * du2;
                    // One division for both `grow / (|d| + L)` and `1 / |d|`
                    // (zero for a spring of zero length, whose direction is
                    // undefined: it exerts no force).
                    let sum = len + load(rest);
                    let q = len
                        .simd_gt(f32x8::ZERO)
                        .select(f32x8::ONE / (len * sum), f32x8::ZERO);
                    let stretch = grow * len * q;
                    let inv = sum * q;
                    let (n0, n1, n2) = (d0 * inv, d1 * inv, d2 * inv);
                    let rel = dv0 * n0 + dv1 * n1 + dv2 * n2;
                    let mag = load(k) * stretch + load(c) * rel;
                    store_rows(&mut out[w..w + 8], [mag * n0, mag * n1, mag * n2]);
                }
            });
    }

    /// The springs' force on node `n` (µN), after [`SpringKernel::spring_pass`].
    #[inline(always)]
    fn node_force4(&self, n: usize) -> f32x4 {
        let (start, mid, end) = (
            self.incident_start[n] as usize,
            self.incident_mid[n] as usize,
            self.incident_start[n + 1] as usize,
        );
        // Four independent sums (even/odd entries, end a/end b), so the
        // loads' latency overlaps instead of queueing behind one chain of
        // additions.
        let f = &self.f;
        let sum = |list: &[u32]| {
            let (mut even, mut odd) = (f32x4::ZERO, f32x4::ZERO);
            let pairs = list.chunks_exact(2);
            if let [last] = pairs.remainder() {
                odd = f[(last & !END_B) as usize];
            }
            for pair in pairs {
                even += f[(pair[0] & !END_B) as usize];
                odd += f[(pair[1] & !END_B) as usize];
            }
            even + odd
        };
        sum(&self.incident[start..mid]) - sum(&self.incident[mid..end])
    }

    /// The springs' force on node `n` (µN), after [`SpringKernel::spring_pass`].
    pub fn node_force(&self, n: usize) -> [f32; 3] {
        let f = self.node_force4(n).to_array();
        [f[0], f[1], f[2]]
    }

    /// One symplectic Euler step of `h` seconds for the `free` nodes, after
    /// [`SpringKernel::spring_pass`]: `v += h ((f_springs + ext) / m − α v)`,
    /// `u += h v`, with `ext` the external force per node (µN, the fourth
    /// lane zero), `inv_mass` per node (1/g) and `alpha` the mass damping
    /// (1/s).
    pub fn integrate(
        &mut self,
        h: f32,
        ext: &[[f32; 4]],
        inv_mass: &[f32],
        free: &[bool],
        alpha: f32,
    ) {
        let (h, alpha) = (f32x4::splat(h), f32x4::splat(alpha));
        let mut state = std::mem::take(&mut self.state);
        let this = &*self;
        state[..self.nodes]
            .par_chunks_mut(NODE_CHUNK)
            .enumerate()
            .for_each(|(chunk, rows)| {
                let first = chunk * NODE_CHUNK;
                for (i, row) in rows.iter_mut().enumerate() {
                    let n = first + i;
                    if !free[n] {
                        continue;
                    }
                    let [u, v]: [f32x4; 2] = bytemuck::cast(*row);
                    let a = (this.node_force4(n) + f32x4::from(ext[n])) * f32x4::splat(inv_mass[n])
                        - alpha * v;
                    let v = v + h * a;
                    *row = bytemuck::cast([u + h * v, v]);
                }
            });
        self.state = state;
    }
}

/// For the 8 springs `s .. s + 8`, the difference of their ends' state
/// rows (end `b` minus end `a`) per component: displacement x, y, z, then
/// velocity x, y, z.
#[inline(always)]
fn end_differences(state: &[f32x8], a: &[u32], b: &[u32], s: usize) -> [f32x8; 6] {
    let (ia, ib) = (&a[s..s + 8], &b[s..s + 8]);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{
            __m256, _mm256_load_ps, _mm256_permute2f128_ps, _mm256_shuffle_ps, _mm256_sub_ps,
            _mm256_unpackhi_ps, _mm256_unpacklo_ps,
        };
        let base = state.as_ptr() as *const f32;
        // SAFETY: AVX2 is enabled at compile time (this block's cfg); every
        // end is a node index below `state.len()` (checked in
        // `SpringKernel::new`; padding springs use node 0, and `state` has
        // at least one row), and each row is a 32-byte-aligned `f32x8`.
        unsafe {
            let row = |l: usize| -> __m256 {
                _mm256_sub_ps(
                    _mm256_load_ps(base.add(8 * ib[l] as usize)),
                    _mm256_load_ps(base.add(8 * ia[l] as usize)),
                )
            };
            let r: [__m256; 8] = std::array::from_fn(row);
            // 8 × 8 transpose, skipping the two zero columns (3 and 7).
            let t0 = _mm256_unpacklo_ps(r[0], r[1]);
            let t1 = _mm256_unpackhi_ps(r[0], r[1]);
            let t2 = _mm256_unpacklo_ps(r[2], r[3]);
            let t3 = _mm256_unpackhi_ps(r[2], r[3]);
            let t4 = _mm256_unpacklo_ps(r[4], r[5]);
            let t5 = _mm256_unpackhi_ps(r[4], r[5]);
            let t6 = _mm256_unpacklo_ps(r[6], r[7]);
            let t7 = _mm256_unpackhi_ps(r[6], r[7]);
            // Per 128-bit half: component 0|4, 1|5, 2|6 of springs 0..4
            // (from t0..t3) and 4..8 (from t4..t7).
            let c0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let c1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
            let c2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let c4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let c5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
            let c6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let lo = |x, y| _mm256_permute2f128_ps::<0x20>(x, y);
            let hi = |x, y| _mm256_permute2f128_ps::<0x31>(x, y);
            [
                lo(c0, c4),
                lo(c1, c5),
                lo(c2, c6),
                hi(c0, c4),
                hi(c1, c5),
                hi(c2, c6),
            ]
            .map(bytemuck::cast::<__m256, f32x8>)
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let d: [[f32; 8]; 8] =
            std::array::from_fn(|l| (state[ib[l] as usize] - state[ia[l] as usize]).to_array());
        [0, 1, 2, 4, 5, 6].map(|c| f32x8::from(std::array::from_fn::<f32, 8, _>(|l| d[l][c])))
    }
}

/// Writes 8 springs' forces, given per axis, as 8 rows `[fx, fy, fz, 0]`.
#[inline(always)]
fn store_rows(out: &mut [f32x4], [fx, fy, fz]: [f32x8; 3]) {
    let out: &mut [f32x4; 8] = out.try_into().expect("8 springs");
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{
            __m256, _mm256_permute2f128_ps, _mm256_setzero_ps, _mm256_shuffle_ps, _mm256_storeu_ps,
            _mm256_unpackhi_ps, _mm256_unpacklo_ps,
        };
        // SAFETY: AVX2 is enabled at compile time (this block's cfg); `out`
        // is 8 rows of 4 f32 (128 bytes), written as four unaligned
        // 32-byte stores.
        unsafe {
            let [x, y, z]: [__m256; 3] = [fx, fy, fz].map(bytemuck::cast::<f32x8, __m256>);
            let zero = _mm256_setzero_ps();
            let xy_lo = _mm256_unpacklo_ps(x, y);
            let xy_hi = _mm256_unpackhi_ps(x, y);
            let z_lo = _mm256_unpacklo_ps(z, zero);
            let z_hi = _mm256_unpackhi_ps(z, zero);
            // Springs 0|4, 1|5, 2|6, 3|7.
            let s04 = _mm256_shuffle_ps::<0x44>(xy_lo, z_lo);
            let s15 = _mm256_shuffle_ps::<0xEE>(xy_lo, z_lo);
            let s26 = _mm256_shuffle_ps::<0x44>(xy_hi, z_hi);
            let s37 = _mm256_shuffle_ps::<0xEE>(xy_hi, z_hi);
            let p = out.as_mut_ptr() as *mut f32;
            _mm256_storeu_ps(p, _mm256_permute2f128_ps::<0x20>(s04, s15));
            _mm256_storeu_ps(p.add(8), _mm256_permute2f128_ps::<0x20>(s26, s37));
            _mm256_storeu_ps(p.add(16), _mm256_permute2f128_ps::<0x31>(s04, s15));
            _mm256_storeu_ps(p.add(24), _mm256_permute2f128_ps::<0x31>(s26, s37));
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let (x, y, z) = (fx.to_array(), fy.to_array(), fz.to_array());
        for (l, row) in out.iter_mut().enumerate() {
            *row = f32x4::from([x[l], y[l], z[l], 0.0]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernel's sub-step against the same sums in f64, one spring and
    /// node at a time, on springs with random ends and a random state.
    #[test]
    fn the_vector_kernel_matches_a_spring_by_spring_step() {
        let n = 37;
        let mut seed = 0x9e37_79b9_u32;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f64 / u32::MAX as f64
        };
        let rest: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(rnd(), rnd(), rnd()) * 10.0)
            .collect();
        let mut springs = Springs::default();
        for _ in 0..61 {
            let p = (rnd() * n as f64) as u32 % n as u32;
            let q = (p + 1 + (rnd() * (n - 1) as f64) as u32 % (n as u32 - 1)) % n as u32;
            springs.ends.push([p, q]);
            springs
                .rest
                .push((rest[q as usize] - rest[p as usize]).length());
            springs.k.push(1.0 + rnd());
            springs.c.push(0.1 * rnd());
        }
        let u: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(rnd(), rnd(), rnd()) - 0.5)
            .collect();
        let v: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(rnd(), rnd(), rnd()) - 0.5)
            .collect();
        let ext: Vec<[f32; 4]> = (0..n)
            .map(|_| [rnd() as f32, rnd() as f32, rnd() as f32, 0.0])
            .collect();
        let inv_mass: Vec<f32> = (0..n).map(|_| 1.0 + rnd() as f32).collect();
        let free: Vec<bool> = (0..n).map(|i| i % 5 != 0).collect();
        let (h, alpha) = (1e-3, 0.5);

        let mut kernel = SpringKernel::new(&springs, &rest);
        kernel.load(&u, &v);
        kernel.spring_pass();
        kernel.integrate(h as f32, &ext, &inv_mass, &free, alpha as f32);

        let mut force = vec![DVec3::ZERO; n];
        for (s, &[p, q]) in springs.ends.iter().enumerate() {
            let (p, q) = (p as usize, q as usize);
            let d = rest[q] + u[q] - rest[p] - u[p];
            let dir = d / d.length();
            let mag = springs.k[s] * (d.length() - springs.rest[s])
                + springs.c[s] * (v[q] - v[p]).dot(dir);
            force[p] += mag * dir;
            force[q] -= mag * dir;
        }
        for i in 0..n {
            let (ku, kv) = kernel.node(i);
            let (ku, kv) = (
                DVec3::from_array(ku.map(f64::from)),
                DVec3::from_array(kv.map(f64::from)),
            );
            let (want_u, want_v) = if free[i] {
                let e = DVec3::from_array(ext[i].map(f64::from).first_chunk().copied().unwrap());
                let a = (force[i] + e) * inv_mass[i] as f64 - alpha * v[i];
                let vn = v[i] + h * a;
                (u[i] + h * vn, vn)
            } else {
                (u[i], v[i])
            };
            assert!(
                (ku - want_u).length() < 1e-5,
                "node {i}: u {ku} vs {want_u}"
            );
            assert!(
                (kv - want_v).length() < 1e-4,
                "node {i}: v {kv} vs {want_v}"
            );
            let f = DVec3::from_array(kernel.node_force(i).map(f64::from));
            assert!(
                (f - force[i]).length() < 1e-4 * (1.0 + force[i].length()),
                "node {i}: force {f} vs {}",
                force[i]
            );
        }
    }
}
