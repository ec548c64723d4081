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
    /// Node `n`'s springs in `incident[incident_start[n] .. incident_start[n + 1]]`:
    /// the spring index, with the top bit set where `n` is its end `b`.
    incident_start: Vec<u32>,
    incident: Vec<u32>,
    /// Displacement per node, mm.
    pub u: Vec<[f32; 3]>,
    /// Velocity per node, mm/s.
    pub v: Vec<[f32; 3]>,
    /// Per spring: the force on end `a`, µN (`[x, y, z, 0]`, one load).
    f: Vec<[f32; 4]>,
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
            u: vec![[0.0; 3]; n],
            v: vec![[0.0; 3]; n],
            f: vec![[0.0; 4]; m],
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
        self.f
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(chunk, out)| {
                let first = chunk * CHUNK;
                for w in (0..out.len()).step_by(8) {
                    let s = first + w;
                    // Gather the 8 springs' end differences (written out:
                    // array closures are not reliably inlined here).
                    let mut du = [[0f32; 8]; 3];
                    let mut dv = [[0f32; 8]; 3];
                    for l in 0..8 {
                        let (pa, pb) = (a[s + l] as usize, b[s + l] as usize);
                        let (ua, ub, va, vb) = (u[pa], u[pb], v[pa], v[pb]);
                        for i in 0..3 {
                            du[i][l] = ub[i] - ua[i];
                            dv[i][l] = vb[i] - va[i];
                        }
                    }
                    let load = |arr: &[f32]| {
                        f32x8::from(<[f32; 8]>::try_from(&arr[s..s + 8]).expect("8 springs"))
                    };
                    let (du0, du1, du2) =
                        (f32x8::from(du[0]), f32x8::from(du[1]), f32x8::from(du[2]));
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
                    let rel =
                        f32x8::from(dv[0]) * n0 + f32x8::from(dv[1]) * n1 + f32x8::from(dv[2]) * n2;
                    let mag = load(k) * stretch + load(c) * rel;
                    let (f0, f1, f2) = (
                        (mag * n0).to_array(),
                        (mag * n1).to_array(),
                        (mag * n2).to_array(),
                    );
                    for l in 0..8 {
                        out[w + l] = [f0[l], f1[l], f2[l], 0.0];
                    }
                }
            });
    }

    /// The springs' force on node `n` (µN), after [`SpringKernel::spring_pass`].
    #[inline]
    pub fn node_force(&self, n: usize) -> [f32; 3] {
        gather(&self.incident_start, &self.incident, &self.f, n)
    }

    /// One symplectic Euler step of `h` seconds for the `free` nodes, after
    /// [`SpringKernel::spring_pass`]: `v += h (f_springs + ext − α m v) / m`,
    /// `u += h v`, with `ext` the external force (µN), `mass` (g) and
    /// `alpha` the mass damping (1/s).
    pub fn integrate(&mut self, h: f32, ext: &[[f32; 3]], mass: &[f32], alpha: f32, free: &[bool]) {
        let (start, incident, f) = (&self.incident_start, &self.incident, &self.f);
        self.u
            .par_iter_mut()
            .zip(self.v.par_iter_mut())
            .enumerate()
            .with_min_len(2048)
            .for_each(|(n, (un, vn))| {
                if !free[n] {
                    return;
                }
                let fs = gather(start, incident, f, n);
                for i in 0..3 {
                    let a = (fs[i] + ext[n][i] - alpha * mass[n] * vn[i]) / mass[n];
                    vn[i] += h * a;
                    un[i] += h * vn[i];
                }
            });
    }
}

/// Node `n`'s spring force: the sum over its springs of the force on end
/// `a`, negated where `n` is end `b`.
#[inline]
fn gather(start: &[u32], incident: &[u32], f: &[[f32; 4]], n: usize) -> [f32; 3] {
    let (mut x, mut y, mut z) = (0f32, 0f32, 0f32);
    for &tagged in &incident[start[n] as usize..start[n + 1] as usize] {
        let fs = f[(tagged & !END_B) as usize];
        let sign = if tagged & END_B == 0 { 1.0 } else { -1.0 };
        x += sign * fs[0];
        y += sign * fs[1];
        z += sign * fs[2];
    }
    [x, y, z]
}
