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
//! those where it is end `a` (one contiguous run: springs are sorted by
//! their lower end) and those where it is end `b` (an index list,
//! subtracted), four lanes at a time. A spring's rest length is not
//! stored but recomputed from its rest vector (one square root per 8
//! springs is cheaper than the 4 bytes it would stream). On AVX2 this replaced 15 gathers
//! per 8 springs and their nodes (a gather costs about as much as 8
//! loads).
//!
//! Precision: positions are never subtracted. A spring's current vector is
//! its rest vector plus the difference of its ends' *displacements*, and
//! its stretch is `(|d|² − L²) / (|d| + L)` with `|d|² − L² = 2 e·δ + δ·δ`
//! (`e` the rest vector, `δ` the displacement difference), so a strain of
//! 1e-6 is resolved in f32 on a model 100 mm from the origin.

use super::solver::{Springs, VolumeSprings};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use voxflex_core::glam::DVec3;
use voxflex_mesh::proxy::HangingNode;
use wide::{f32x4, f32x8};

/// Springs per parallel task of [`SpringKernel::spring_pass`] (a multiple of 8).
const CHUNK: usize = 4096;
/// Volume springs per parallel task of [`SpringKernel::spring_pass`].
const TET_CHUNK: usize = 1024;
/// Nodes per parallel task of `SpringKernel::integrate` (tests).
#[cfg(test)]
const NODE_CHUNK: usize = 512;

/// The springs in the kernel's order: each turned so that end `a` is the
/// lower node index, then sorted by `(a, b)`. A node's end-`a` springs are
/// then one contiguous run (summed without an index list), and the spring
/// pass walks the `a` rows in order.
struct SpringArrays {
    /// Ends of each spring, `a < b` (padded to a multiple of 8 with zero
    /// springs between node 0 and itself).
    a: Vec<u32>,
    b: Vec<u32>,
    /// Rest vector `X_b − X_a` (mm; the rest length is its norm, computed
    /// in the pass), stiffness (µN/mm), damping (µN·s/mm).
    e: [Vec<f32>; 3],
    k: Vec<f32>,
    c: Vec<f32>,
    /// Node `n` is end `a` of springs `a_start[n] .. a_start[n + 1]`.
    a_start: Vec<u32>,
    /// Node `n` is end `b` of springs `b_list[b_start[n] .. b_start[n + 1]]`
    /// (ascending).
    b_start: Vec<u32>,
    b_list: Vec<u32>,
    /// Volume springs (one per tetrahedron; none when `volume_stiffness`
    /// is 0): corners, and per tetrahedron its rest edge vectors
    /// `X_c − X_0` (c = 1, 2, 3; mm) with, in the fourth lanes, the
    /// stiffness `κ E / V₀` (µN/mm⁵), the rest volume `V₀` (mm³) and 0.
    tets: Vec<[u32; 4]>,
    tet_geometry: Vec<[f32; 12]>,
    /// Node `n`'s rows of the per-corner volume forces:
    /// `t_list[t_start[n] .. t_start[n + 1]]`, indices into the force
    /// array (after the padded springs: `padded + 4 t + corner`).
    t_start: Vec<u32>,
    t_list: Vec<u32>,
}

/// The springs and the node state as f32 arrays (see the module).
pub struct SpringKernel {
    springs: SpringArrays,
    /// Per node: `[ux, uy, uz, 0, vx, vy, vz, 0]`, displacement (mm) and
    /// velocity (mm/s). At least one row, so the padding springs' ends
    /// exist.
    state: Vec<f32x8>,
    /// Nodes.
    nodes: usize,
    /// Per spring (kernel order, padded): `[fx, fy, fz, 0]`, the force on
    /// end `a`, µN.
    f: Vec<f32x4>,
    /// Per node, with hanging nodes: the total force (µN) of a sub-step.
    totals: Vec<f32x4>,
}

/// What one explicit sub-step applies to the free nodes (symplectic
/// Euler): `v += h ((f_springs + ext) / m − α v)`, `u += h v`.
pub struct Substep<'a> {
    /// Sub-step, s.
    pub h: f32,
    /// External force per node (µN; the fourth lane zero).
    pub ext: &'a [[f32; 4]],
    /// `1 / mass` per node, 1/g.
    pub inv_mass: &'a [f32],
    /// The nodes the integrator moves; the others keep their rows.
    pub free: &'a [bool],
    /// Mass damping α, 1/s.
    pub alpha: f32,
    /// The hanging nodes of an octree proxy, tied to their masters (empty
    /// for a conforming proxy): each sub-step moves their forces onto
    /// their masters before the update, and the fix-up must set their
    /// state from the masters'.
    pub hanging: &'a [HangingNode],
}

/// Sets the imposed nodes' rows after sub-step `s` (numbered from 1), on
/// one thread while the others wait ([`SpringKernel::substeps`]).
pub type Fixup<'a> = &'a (dyn Fn(u32, &mut NodeRows) + Sync);

/// The node state rows, as [`SpringKernel::substeps`] hands them to its
/// per-sub-step fix-up of imposed nodes.
pub struct NodeRows<'a>(&'a mut [f32x8]);

/// A node's state row as displacement (mm) and velocity (mm/s).
#[inline]
fn split_row(row: f32x8) -> ([f32; 3], [f32; 3]) {
    let r = row.to_array();
    ([r[0], r[1], r[2]], [r[4], r[5], r[6]])
}

impl NodeRows<'_> {
    /// Node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn node(&self, n: usize) -> ([f32; 3], [f32; 3]) {
        split_row(self.0[n])
    }

    /// Sets every hanging node's displacement and velocity from its
    /// masters' (`u = P u`, `v = P v`; the rows' twin of
    /// `Boundary::tie`).
    pub fn tie(&mut self, hanging: &[HangingNode]) {
        for h in hanging {
            let (mut u, mut v) = ([0f32; 3], [0f32; 3]);
            for &(m, w) in &h.masters {
                let (um, vm) = self.node(m as usize);
                for i in 0..3 {
                    u[i] += w * um[i];
                    v[i] += w * vm[i];
                }
            }
            self.set_node(h.node as usize, u, v);
        }
    }

    /// Sets node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn set_node(&mut self, n: usize, u: [f32; 3], v: [f32; 3]) {
        self.0[n] = f32x8::from([u[0], u[1], u[2], 0.0, v[0], v[1], v[2], 0.0]);
    }
}

#[inline]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Tags an incidence entry (GPU twin) where the node is the spring's end `b`.
pub const END_B: u32 = 1 << 31;

/// A spring's rest length (mm) from its rest vector, as the pass computes it.
fn rest_length([x, y, z]: [f32; 3]) -> f32 {
    (x * x + y * y + z * z).sqrt()
}

/// The springs as the GPU twin's buffers hold them.
pub struct SpringTable {
    /// Rest vector `X_b − X_a` (mm) and rest length (mm).
    pub geometry: Vec<[f32; 4]>,
    /// End nodes.
    pub ends: Vec<[u32; 2]>,
    /// Stiffness (µN/mm) and damping (µN·s/mm).
    pub kc: Vec<[f32; 2]>,
}

impl SpringArrays {
    fn new(springs: &Springs, volumes: &VolumeSprings, rest: &[DVec3]) -> Self {
        let n = rest.len();
        // Each spring turned to `a < b`, then sorted by (a, b).
        let mut order: Vec<(u32, u32, usize)> = springs
            .ends
            .iter()
            .enumerate()
            .map(|(s, &[p, q])| (p.min(q), p.max(q), s))
            .collect();
        order.sort_unstable();
        let m = order.len().next_multiple_of(8);
        let column = |value: &dyn Fn(&(u32, u32, usize)) -> f32| {
            let mut v: Vec<f32> = order.iter().map(value).collect();
            v.resize(m, 0.0);
            v
        };
        let e = [0, 1, 2].map(|axis| {
            column(&|&(p, q, _)| (rest[q as usize][axis] - rest[p as usize][axis]) as f32)
        });
        let k = column(&|&(_, _, s)| springs.k[s] as f32);
        let c = column(&|&(_, _, s)| springs.c[s] as f32);
        let ends = |end: fn(&(u32, u32, usize)) -> u32| {
            let mut v: Vec<u32> = order.iter().map(end).collect();
            v.resize(m, 0);
            v
        };
        let (a, b) = (ends(|o| o.0), ends(|o| o.1));
        let mut a_start = vec![0u32; n + 1];
        let mut b_start = vec![0u32; n + 1];
        for &(p, q, _) in &order {
            a_start[p as usize + 1] += 1;
            b_start[q as usize + 1] += 1;
        }
        for i in 0..n {
            a_start[i + 1] += a_start[i];
            b_start[i + 1] += b_start[i];
        }
        let mut fill = b_start.clone();
        let mut b_list = vec![0u32; order.len()];
        for (s, &(_, q, _)) in order.iter().enumerate() {
            b_list[fill[q as usize] as usize] = s as u32;
            fill[q as usize] += 1;
        }
        let tet_geometry = volumes
            .corners
            .iter()
            .zip(&volumes.k)
            .map(|(c, &kv)| {
                let x = c.map(|i| rest[i as usize]);
                let [e1, e2, e3] = [1, 2, 3].map(|i| x[i] - x[0]);
                let v0 = e1.dot(e2.cross(e3)) / 6.0;
                [
                    e1.x, e1.y, e1.z, kv, e2.x, e2.y, e2.z, v0, e3.x, e3.y, e3.z, 0.0,
                ]
                .map(|v| v as f32)
            })
            .collect();
        let padded = m as u32;
        let mut t_start = vec![0u32; n + 1];
        for c in &volumes.corners {
            for &i in c {
                t_start[i as usize + 1] += 1;
            }
        }
        for i in 0..n {
            t_start[i + 1] += t_start[i];
        }
        let mut fill = t_start.clone();
        let mut t_list = vec![0u32; 4 * volumes.corners.len()];
        for (t, c) in volumes.corners.iter().enumerate() {
            for (corner, &i) in c.iter().enumerate() {
                t_list[fill[i as usize] as usize] = padded + 4 * t as u32 + corner as u32;
                fill[i as usize] += 1;
            }
        }
        Self {
            a,
            b,
            e,
            k,
            c,
            a_start,
            b_start,
            b_list,
            tets: volumes.corners.clone(),
            tet_geometry,
            t_start,
            t_list,
        }
    }

    /// Rows of the force array: the padded springs, then four per volume
    /// spring.
    fn rows(&self) -> usize {
        self.padded() + 4 * self.tets.len()
    }

    /// The per-corner forces (µN) of volume springs `first .. first +
    /// out.len() / 4` at node state `state`, into `out` (four rows per
    /// tetrahedron). A tetrahedron of current volume `V < V₀` pushes its
    /// corners along `−k_v (V − V₀) ∂V/∂x_c`; one at or above its rest
    /// volume exerts nothing (see `solver.rs`). Edges are the rest vectors
    /// plus displacement differences, as for the springs.
    fn tet_forces(&self, state: &[f32x8], first: usize, out: &mut [f32x4]) {
        for (i, rows) in out.chunks_exact_mut(4).enumerate() {
            let t = first + i;
            let [c0, c1, c2, c3] = self.tets[t].map(|n| n as usize);
            let g = &self.tet_geometry[t];
            let u0 = split_row(state[c0]).0;
            let edge = |c: usize, e: usize| -> [f32; 3] {
                let u = split_row(state[c]).0;
                [0, 1, 2].map(|k| g[4 * e + k] + (u[k] - u0[k]))
            };
            let (d1, d2, d3) = (edge(c1, 0), edge(c2, 1), edge(c3, 2));
            let g1 = cross(d2, d3);
            let v = dot(d1, g1) / 6.0;
            let (kv, v0) = (g[3], g[7]);
            if v >= v0 {
                rows.fill(f32x4::ZERO);
                continue;
            }
            // −k_v (V − V₀) ∂V/∂x, with ∂V/∂x_1 = (d2 × d3) / 6 and so on.
            let s = -kv * (v - v0) / 6.0;
            let (g2, g3) = (cross(d3, d1), cross(d1, d2));
            let f = [g1, g2, g3].map(|gc| gc.map(|x| s * x));
            let f0 = [0, 1, 2].map(|k| -(f[0][k] + f[1][k] + f[2][k]));
            rows[0] = f32x4::from([f0[0], f0[1], f0[2], 0.0]);
            for c in 0..3 {
                rows[c + 1] = f32x4::from([f[c][0], f[c][1], f[c][2], 0.0]);
            }
        }
    }

    /// Springs, padding included.
    fn padded(&self) -> usize {
        self.a.len()
    }

    /// The force on end `a` of springs `first .. first + out.len()` (a
    /// multiple of 8, `first` too) at node state `state`, into `out`.
    fn forces(&self, state: &[f32x8], first: usize, out: &mut [f32x4]) {
        let (a, b, e, k, c) = (&self.a, &self.b, &self.e, &self.k, &self.c);
        for w in (0..out.len()).step_by(8) {
            let s = first + w;
            let [du0, du1, du2, dv0, dv1, dv2] = end_differences(state, a, b, s);
            let load =
                |arr: &[f32]| f32x8::from(<[f32; 8]>::try_from(&arr[s..s + 8]).expect("8 springs"));
            let (e0, e1, e2) = (load(&e[0]), load(&e[1]), load(&e[2]));
            let (d0, d1, d2) = (e0 + du0, e1 + du1, e2 + du2);
            let len = (d0 * d0 + d1 * d1 + d2 * d2).sqrt();
            // |d|² − L² without cancellation: 2 e·δ + δ·δ.
            let grow = f32x8::splat(2.0) * (e0 * du0 + e1 * du1 + e2 * du2)
                + du0 * du0
                + du1 * du1
                + du2 * du2;
            // One division for both `grow / (|d| + L)` and `1 / |d|` (zero
            // for a spring of zero length, whose direction is undefined: it
            // exerts no force).
            let rest = (e0 * e0 + e1 * e1 + e2 * e2).sqrt();
            let sum = len + rest;
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
    }

    /// The springs' force on node `n` (µN) from the per-spring forces `f`.
    #[inline(always)]
    fn node_force(&self, f: &[f32x4], n: usize) -> f32x4 {
        // End a: one contiguous run. End b: a list. Each summed with two
        // independent accumulators, so the loads' latency overlaps instead
        // of queueing behind one chain of additions.
        let run = &f[self.a_start[n] as usize..self.a_start[n + 1] as usize];
        let (mut a0, mut a1) = (f32x4::ZERO, f32x4::ZERO);
        let pairs = run.chunks_exact(2);
        if let [last] = pairs.remainder() {
            a1 = *last;
        }
        for pair in pairs {
            a0 += pair[0];
            a1 += pair[1];
        }
        let list = &self.b_list[self.b_start[n] as usize..self.b_start[n + 1] as usize];
        let (mut b0, mut b1) = (f32x4::ZERO, f32x4::ZERO);
        let pairs = list.chunks_exact(2);
        if let [last] = pairs.remainder() {
            b1 = f[*last as usize];
        }
        for pair in pairs {
            b0 += f[pair[0] as usize];
            b1 += f[pair[1] as usize];
        }
        let mut sum = (a0 + a1) - (b0 + b1);
        for &row in &self.t_list[self.t_start[n] as usize..self.t_start[n + 1] as usize] {
            sum += f[row as usize];
        }
        sum
    }

    /// One sub-step for the nodes `first .. first + rows.len()`, whose state
    /// rows are `rows`, from the per-spring forces `f`.
    fn integrate(&self, f: &[f32x4], first: usize, rows: &mut [f32x8], step: &Substep) {
        let (h, alpha) = (f32x4::splat(step.h), f32x4::splat(step.alpha));
        for (i, row) in rows.iter_mut().enumerate() {
            let n = first + i;
            if !step.free[n] {
                continue;
            }
            let [u, v]: [f32x4; 2] = bytemuck::cast(*row);
            let a = (self.node_force(f, n) + f32x4::from(step.ext[n]))
                * f32x4::splat(step.inv_mass[n])
                - alpha * v;
            let v = v + h * a;
            *row = bytemuck::cast([u + h * v, v]);
        }
    }

    /// The total force (springs, external, mass damping; µN) on the nodes
    /// `first .. first + out.len()`, into `out`, from the per-spring forces
    /// `f` and the node state `rows` (all nodes).
    fn totals(&self, f: &[f32x4], rows: &[f32x8], first: usize, out: &mut [f32x4], step: &Substep) {
        let alpha = f32x4::splat(step.alpha);
        for (i, o) in out.iter_mut().enumerate() {
            let n = first + i;
            let [_, v]: [f32x4; 2] = bytemuck::cast(rows[n]);
            *o = self.node_force(f, n) + f32x4::from(step.ext[n])
                - alpha * v / f32x4::splat(step.inv_mass[n]);
        }
    }

    /// Symplectic Euler for the free nodes `first .. first + rows.len()`
    /// from their total forces `total` (all nodes).
    fn apply_totals(&self, total: &[f32x4], first: usize, rows: &mut [f32x8], step: &Substep) {
        let h = f32x4::splat(step.h);
        for (i, row) in rows.iter_mut().enumerate() {
            let n = first + i;
            if !step.free[n] {
                continue;
            }
            let [u, v]: [f32x4; 2] = bytemuck::cast(*row);
            let v = v + h * total[n] * f32x4::splat(step.inv_mass[n]);
            *row = bytemuck::cast([u + h * v, v]);
        }
    }

    /// `parts` node ranges and the spring ranges that go with them (the
    /// springs whose end `a` is in the node range, boundaries rounded to
    /// 8; the last takes the padding), balanced by spring count.
    fn partition(&self, nodes: usize, parts: usize) -> Vec<(Range<usize>, Range<usize>)> {
        let springs = self.b_list.len();
        let cut = |t: usize| {
            if t == parts {
                return (nodes, self.padded());
            }
            let node = self
                .a_start
                .partition_point(|&s| (s as usize) < springs * t / parts)
                .min(nodes);
            (node, (self.a_start[node] as usize / 8) * 8)
        };
        (0..parts)
            .map(|t| {
                let ((n0, s0), (n1, s1)) = (cut(t), cut(t + 1));
                (n0..n1.max(n0), s0..s1.max(s0))
            })
            .collect()
    }
}

/// Moves the hanging nodes' forces `total` (µN per node) onto their
/// masters and clears them, deepest ties first (`f ← Pᵀ f`; the f32 twin of
/// `Boundary::untie`).
fn untie_rows(hanging: &[HangingNode], total: &mut [f32x4]) {
    for h in hanging.iter().rev() {
        let f = std::mem::replace(&mut total[h.node as usize], f32x4::ZERO);
        for &(m, w) in &h.masters {
            total[m as usize] += f32x4::splat(w) * f;
        }
    }
}

/// An array that the threads of [`SpringKernel::substeps`] share between
/// barriers: within one phase it is either only read, or written in
/// disjoint ranges.
struct Shared<T>(*mut T, usize);

// SAFETY: `Shared` only hands out slices under the phase discipline its
// methods' callers uphold (see there).
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T> Shared<T> {
    fn new(v: &mut [T]) -> Self {
        Self(v.as_mut_ptr(), v.len())
    }

    /// The whole array, to read.
    ///
    /// # Safety
    /// No thread writes the array while the slice lives.
    unsafe fn all(&self) -> &[T] {
        // SAFETY: the pointer and length come from a live `&mut [T]` that
        // outlives `self`; the caller rules out writers.
        unsafe { std::slice::from_raw_parts(self.0, self.1) }
    }

    /// `range` of the array, to write.
    ///
    /// # Safety
    /// No other thread reads or writes `range` while the slice lives.
    #[allow(clippy::mut_from_ref)]
    unsafe fn part(&self, range: Range<usize>) -> &mut [T] {
        assert!(range.start <= range.end && range.end <= self.1);
        // SAFETY: in bounds (asserted); the caller rules out other access.
        unsafe { std::slice::from_raw_parts_mut(self.0.add(range.start), range.len()) }
    }
}

/// A reusable barrier that spins briefly, then yields: a sub-step's two
/// phases take tens of microseconds, shorter than putting a thread to
/// sleep and waking it (what a parallel call per phase costs: about 14 %
/// of the sub-step in a profile).
struct SpinBarrier {
    threads: usize,
    arrived: AtomicUsize,
    generation: AtomicUsize,
}

impl SpinBarrier {
    fn new(threads: usize) -> Self {
        Self {
            threads,
            arrived: AtomicUsize::new(0),
            generation: AtomicUsize::new(0),
        }
    }

    /// Returns once all `threads` have called it (in this generation).
    fn wait(&self) {
        let generation = self.generation.load(Ordering::Acquire);
        if self.arrived.fetch_add(1, Ordering::AcqRel) + 1 == self.threads {
            self.arrived.store(0, Ordering::Relaxed);
            self.generation.fetch_add(1, Ordering::Release);
            return;
        }
        let mut spins = 0u32;
        while self.generation.load(Ordering::Acquire) == generation {
            if spins < 1 << 12 {
                std::hint::spin_loop();
                spins += 1;
            } else {
                std::thread::yield_now();
            }
        }
    }
}

impl SpringKernel {
    /// The kernel's arrays for `springs` and `volumes` between `rest` node
    /// positions.
    pub fn new(springs: &Springs, volumes: &VolumeSprings, rest: &[DVec3]) -> Self {
        let n = rest.len();
        assert!(
            n < (u32::MAX / 8) as usize
                && springs
                    .ends
                    .iter()
                    .flatten()
                    .all(|&node| (node as usize) < n)
                && volumes.corners.iter().flatten().all(|&c| (c as usize) < n)
                && springs.ends.len() + 4 * volumes.corners.len() < (u32::MAX / 2) as usize,
            "spring ends and tetrahedron corners must be nodes, and 8 × the node count and the \
             force rows must fit a u32"
        );
        let springs = SpringArrays::new(springs, volumes, rest);
        let f = vec![f32x4::ZERO; springs.rows()];
        Self {
            springs,
            state: vec![f32x8::ZERO; n.max(1)],
            nodes: n,
            f,
            totals: Vec::new(),
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

    /// The node state rows.
    pub fn rows(&mut self) -> NodeRows<'_> {
        NodeRows(&mut self.state)
    }

    /// Node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn node(&self, n: usize) -> ([f32; 3], [f32; 3]) {
        split_row(self.state[n])
    }

    /// Sets node `n`'s displacement (mm) and velocity (mm/s).
    #[inline]
    pub fn set_node(&mut self, n: usize, u: [f32; 3], v: [f32; 3]) {
        self.rows().set_node(n, u, v);
    }

    /// Springs (unpadded count).
    pub fn springs(&self) -> usize {
        self.springs.b_list.len()
    }

    /// The GPU twin's spring buffers, in the kernel's spring order.
    pub fn spring_table(&self) -> SpringTable {
        let (s, n) = (&self.springs, self.springs());
        SpringTable {
            geometry: (0..n)
                .map(|i| {
                    let e = [s.e[0][i], s.e[1][i], s.e[2][i]];
                    [e[0], e[1], e[2], rest_length(e)]
                })
                .collect(),
            ends: (0..n).map(|i| [s.a[i], s.b[i]]).collect(),
            kc: (0..n).map(|i| [s.k[i], s.c[i]]).collect(),
        }
    }

    /// The node → spring incidence as the GPU twin reads it: node `n`'s
    /// springs are `incident[start[n] .. start[n + 1]]`, each a spring
    /// index with [`END_B`] set where `n` is its end `b`, then its
    /// volume-spring corners as rows `springs + 4 t + corner` of the force
    /// buffer (added).
    pub fn incidence(&self) -> (Vec<u32>, Vec<u32>) {
        let s = &self.springs;
        let mut start = Vec::with_capacity(self.nodes + 1);
        let mut incident = Vec::with_capacity(2 * self.springs());
        start.push(0);
        for n in 0..self.nodes {
            incident.extend(s.a_start[n]..s.a_start[n + 1]);
            let bs = &s.b_list[s.b_start[n] as usize..s.b_start[n + 1] as usize];
            incident.extend(bs.iter().map(|i| i | END_B));
            // Volume-spring corners: rows after the unpadded springs.
            let ts = &s.t_list[s.t_start[n] as usize..s.t_start[n + 1] as usize];
            let shift = (s.padded() - self.springs()) as u32;
            incident.extend(ts.iter().map(|i| i - shift));
            start.push(incident.len() as u32);
        }
        (start, incident)
    }

    /// Volume springs (tetrahedra).
    pub fn tets(&self) -> usize {
        self.springs.tets.len()
    }

    /// The GPU twin's volume-spring buffers: corners (`[a, b, c, d]`) and
    /// three rows per tetrahedron (rest edge vectors `X_c − X_0`, mm, with
    /// `κ E / V₀`, `V₀` and 0 in the fourth lanes).
    pub fn tet_table(&self) -> (Vec<[u32; 4]>, Vec<[f32; 4]>) {
        let s = &self.springs;
        let rows = s
            .tet_geometry
            .iter()
            .flat_map(|g| [0, 1, 2].map(|r| [g[4 * r], g[4 * r + 1], g[4 * r + 2], g[4 * r + 3]]))
            .collect();
        (s.tets.clone(), rows)
    }

    /// Per spring: the force on its end `a` (stretch and damping along it);
    /// per volume spring: the force on each corner.
    pub fn spring_pass(&mut self) {
        let (springs, state) = (&self.springs, &self.state);
        let (f, ft) = self.f.split_at_mut(springs.padded());
        f.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(chunk, out)| springs.forces(state, chunk * CHUNK, out));
        ft.par_chunks_mut(4 * TET_CHUNK)
            .enumerate()
            .for_each(|(chunk, out)| springs.tet_forces(state, chunk * TET_CHUNK, out));
    }

    /// The springs' force on node `n` (µN), after [`SpringKernel::spring_pass`].
    pub fn node_force(&self, n: usize) -> [f32; 3] {
        let f = self.springs.node_force(&self.f, n).to_array();
        [f[0], f[1], f[2]]
    }

    /// One sub-step of the free nodes, after [`SpringKernel::spring_pass`]
    /// (what [`SpringKernel::substeps`] does per sub-step; its reference in
    /// tests).
    #[cfg(test)]
    pub fn integrate(&mut self, step: &Substep) {
        let (springs, f) = (&self.springs, &self.f);
        self.state[..self.nodes]
            .par_chunks_mut(NODE_CHUNK)
            .enumerate()
            .for_each(|(chunk, rows)| springs.integrate(f, chunk * NODE_CHUNK, rows, step));
    }

    /// `count` sub-steps (spring pass, then integration), numbered from 1;
    /// after each, `fixup` (if any) sets the imposed nodes' rows on one
    /// thread. The same as a [`SpringKernel::spring_pass`] and an
    /// integration of every free node per sub-step (bit for bit, tested),
    /// in one parallel region:
    /// each thread keeps one range of springs and the nodes they start
    /// from (so the forces it writes are mostly the ones it reads back),
    /// and the phases meet at a spinning barrier instead of parking the
    /// threads twice per sub-step.
    pub fn substeps(&mut self, count: u32, step: &Substep, fixup: Option<Fixup>) {
        let threads = rayon::current_num_threads().max(1);
        let parts = self.springs.partition(self.nodes, threads);
        let (padded, tets) = (self.springs.padded(), self.springs.tets.len());
        let tet_part = |t: usize| tets * t / threads..tets * (t + 1) / threads;
        let barrier = SpinBarrier::new(threads);
        let springs = &self.springs;
        let nodes = self.nodes;
        let tied = !step.hanging.is_empty();
        if tied {
            self.totals.resize(nodes, f32x4::ZERO);
        }
        let (state, f) = (Shared::new(&mut self.state), Shared::new(&mut self.f));
        let totals = Shared::new(&mut self.totals);
        rayon::broadcast(|ctx| {
            let (node_range, spring_range) = parts[ctx.index()].clone();
            for s in 1..=count {
                // SAFETY (every phase and the fix-up): the barriers separate
                // them; in the spring phase `state` is only read and each
                // thread writes its own range of `f`; in the node phases `f`
                // (and `totals` once written) is only read and each thread
                // writes its own range of `state` or `totals` (the ranges
                // are disjoint: `partition`); moving the hanging nodes'
                // forces and the fix-up run on one thread while the others
                // wait.
                // SAFETY: spring phase (see above): `state` is read only and
                // this thread writes only its own spring range of `f`.
                unsafe {
                    springs.forces(
                        state.all(),
                        spring_range.start,
                        f.part(spring_range.clone()),
                    )
                };
                let tr = tet_part(ctx.index());
                if !tr.is_empty() {
                    // SAFETY: spring phase: `state` is read only and this
                    // thread writes only its own tetrahedron range of `f`.
                    unsafe {
                        springs.tet_forces(
                            state.all(),
                            tr.start,
                            f.part(padded + 4 * tr.start..padded + 4 * tr.end),
                        )
                    };
                }
                barrier.wait();
                if tied {
                    // Total forces, the hanging nodes' moved onto their
                    // masters, then the update from them.
                    // SAFETY: after the barrier `f` and `state` are read only
                    // and this thread writes only its own node range of `totals`.
                    unsafe {
                        springs.totals(
                            f.all(),
                            state.all(),
                            node_range.start,
                            totals.part(node_range.clone()),
                            step,
                        )
                    };
                    barrier.wait();
                    if ctx.index() == 0 {
                        // SAFETY: the other threads wait at the next barrier;
                        // only this one touches `totals` now.
                        let t = unsafe { totals.part(0..nodes) };
                        untie_rows(step.hanging, t);
                    }
                    barrier.wait();
                    // SAFETY: `totals` is read only after the barrier and this
                    // thread writes only its own node range of `state`.
                    unsafe {
                        springs.apply_totals(
                            totals.all(),
                            node_range.start,
                            state.part(node_range.clone()),
                            step,
                        )
                    };
                } else {
                    // SAFETY: node phase: `f` is read only after the barrier
                    // and this thread writes only its own node range of `state`.
                    unsafe {
                        springs.integrate(
                            f.all(),
                            node_range.start,
                            state.part(node_range.clone()),
                            step,
                        )
                    };
                }
                barrier.wait();
                if let Some(fixup) = fixup {
                    if ctx.index() == 0 {
                        // SAFETY: the other threads wait at the next barrier;
                        // only this one touches `state` now.
                        let rows = unsafe { state.part(0..nodes) };
                        fixup(s, &mut NodeRows(rows));
                    }
                    barrier.wait();
                }
            }
        });
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
    use voxflex_mesh::mesh_model::Boundary;

    /// Random springs between random nodes, and a random node state.
    struct Case {
        rest: Vec<DVec3>,
        springs: Springs,
        volumes: VolumeSprings,
        u: Vec<DVec3>,
        v: Vec<DVec3>,
        ext: Vec<[f32; 4]>,
        inv_mass: Vec<f32>,
        free: Vec<bool>,
    }

    fn case(n: usize, springs: usize) -> Case {
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
        let mut list = Springs::default();
        for _ in 0..springs {
            let p = (rnd() * n as f64) as u32 % n as u32;
            let q = (p + 1 + (rnd() * (n - 1) as f64) as u32 % (n as u32 - 1)) % n as u32;
            list.ends.push([p, q]);
            list.rest
                .push((rest[q as usize] - rest[p as usize]).length());
            list.k.push(1.0 + rnd());
            list.c.push(0.1 * rnd());
        }
        // Volume springs on random corner quadruples (distinct corners).
        let mut volumes = VolumeSprings::default();
        for t in 0..springs / 3 {
            let p = (rnd() * n as f64) as u32 % n as u32;
            let c = [
                p,
                (p + 1 + t as u32 % 7) % n as u32,
                (p + 9) % n as u32,
                (p + 17 + t as u32 % 3) % n as u32,
            ];
            volumes.corners.push(c);
            volumes.k.push(1e-3 * (1.0 + rnd()));
        }
        let mut vectors = || -> Vec<DVec3> {
            (0..n)
                .map(|_| DVec3::new(rnd(), rnd(), rnd()) - 0.5)
                .collect()
        };
        let (u, v) = (vectors(), vectors());
        Case {
            rest,
            springs: list,
            volumes,
            u,
            v,
            ext: (0..n)
                .map(|_| [rnd() as f32, rnd() as f32, rnd() as f32, 0.0])
                .collect(),
            inv_mass: (0..n).map(|_| 1.0 + rnd() as f32).collect(),
            free: (0..n).map(|i| i % 5 != 0).collect(),
        }
    }

    /// The kernel's sub-step against the same sums in f64, one spring and
    /// node at a time, on springs with random ends and a random state.
    #[test]
    fn the_vector_kernel_matches_a_spring_by_spring_step() {
        let n = 37;
        let Case {
            rest,
            springs,
            volumes,
            u,
            v,
            ext,
            inv_mass,
            free,
        } = case(n, 61);
        let (h, alpha) = (1e-3, 0.5);

        let mut kernel = SpringKernel::new(&springs, &volumes, &rest);
        kernel.load(&u, &v);
        let step = Substep {
            h: h as f32,
            ext: &ext,
            inv_mass: &inv_mass,
            free: &free,
            alpha: alpha as f32,
            hanging: &[],
        };
        kernel.spring_pass();
        kernel.integrate(&step);

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
        // Volume springs: −k (V − V₀) ∂V/∂x where V < V₀.
        let mut compressed = 0;
        for (c, &k) in volumes.corners.iter().zip(&volumes.k) {
            let c = c.map(|i| i as usize);
            let x = c.map(|i| rest[i] + u[i]);
            let x0 = c.map(|i| rest[i]);
            let vol = |x: [DVec3; 4]| (x[1] - x[0]).dot((x[2] - x[0]).cross(x[3] - x[0])) / 6.0;
            let (now, v0) = (vol(x), vol(x0));
            if now >= v0 {
                continue;
            }
            compressed += 1;
            let g1 = (x[2] - x[0]).cross(x[3] - x[0]) / 6.0;
            let g2 = (x[3] - x[0]).cross(x[1] - x[0]) / 6.0;
            let g3 = (x[1] - x[0]).cross(x[2] - x[0]) / 6.0;
            let s = -k * (now - v0);
            force[c[0]] -= s * (g1 + g2 + g3);
            force[c[1]] += s * g1;
            force[c[2]] += s * g2;
            force[c[3]] += s * g3;
        }
        assert!(
            compressed > 2 && compressed < volumes.k.len(),
            "both sides of the one-sided volume term are covered ({compressed})"
        );
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

    /// Sub-steps in one parallel region (static ranges, spinning barrier,
    /// a fix-up between sub-steps) are bit-identical to a spring pass and
    /// an integration per sub-step, for any number of threads.
    #[test]
    fn one_parallel_region_equals_a_pass_per_phase() {
        let c = case(500, 2_003);
        let step = Substep {
            h: 1e-3,
            ext: &c.ext,
            inv_mass: &c.inv_mass,
            free: &c.free,
            alpha: 0.5,
            hanging: &[],
        };
        let pull =
            |s: u32, rows: &mut NodeRows| rows.set_node(0, [0.01 * s as f32, 0.0, 0.0], [0.0; 3]);
        let mut expected = SpringKernel::new(&c.springs, &c.volumes, &c.rest);
        expected.load(&c.u, &c.v);
        for s in 1..=7 {
            expected.spring_pass();
            expected.integrate(&step);
            pull(s, &mut expected.rows());
        }
        for threads in [1, 2, 3, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut kernel = SpringKernel::new(&c.springs, &c.volumes, &c.rest);
            kernel.load(&c.u, &c.v);
            pool.install(|| kernel.substeps(7, &step, Some(&pull)));
            for n in 0..c.rest.len() {
                assert_eq!(
                    kernel.node(n),
                    expected.node(n),
                    "node {n} with {threads} threads"
                );
            }
        }
    }

    /// With hanging nodes, the one-region sub-step (total forces, the
    /// hanging nodes' moved onto their masters, update, ties) matches the
    /// same sequence done in f64, one node at a time.
    #[test]
    fn hanging_nodes_pass_their_forces_to_their_masters() {
        let c = case(300, 1_201);
        // Nodes 0..30 hang on three later nodes each (weights summing to
        // one); nodes 30..40 are fixed; the rest are free.
        let hanging: Vec<HangingNode> = (0..30)
            .map(|n| HangingNode {
                node: n,
                masters: vec![(40 + 3 * n, 0.5), (41 + 3 * n, 0.3), (42 + 3 * n, 0.2)],
            })
            .collect();
        let free: Vec<bool> = (0..300).map(|n| n >= 40).collect();
        let step = Substep {
            h: 1e-3,
            ext: &c.ext,
            inv_mass: &c.inv_mass,
            free: &free,
            alpha: 0.5,
            hanging: &hanging,
        };
        let tie = |_: u32, rows: &mut NodeRows| rows.tie(&hanging);
        let mut untie = Boundary::new(300);
        untie.hanging = hanging.clone();
        let mut kernel = SpringKernel::new(&c.springs, &c.volumes, &c.rest);
        kernel.load(&c.u, &c.v);
        let mut reference = SpringKernel::new(&c.springs, &c.volumes, &c.rest);
        reference.load(&c.u, &c.v);
        for s in 1..=5 {
            reference.spring_pass();
            let mut f: Vec<DVec3> = (0..300)
                .map(|n| {
                    let spring = DVec3::from_array(reference.node_force(n).map(f64::from));
                    let ext =
                        DVec3::new(c.ext[n][0] as f64, c.ext[n][1] as f64, c.ext[n][2] as f64);
                    let v = DVec3::from_array(reference.node(n).1.map(f64::from));
                    spring + ext - 0.5 * v / c.inv_mass[n] as f64
                })
                .collect();
            untie.untie(&mut f);
            for n in (0..300).filter(|&n| free[n]) {
                let (u, v) = reference.node(n);
                let v = DVec3::from_array(v.map(f64::from)) + 1e-3 * f[n] * c.inv_mass[n] as f64;
                let u = DVec3::from_array(u.map(f64::from)) + 1e-3 * v;
                reference.set_node(n, u.as_vec3().to_array(), v.as_vec3().to_array());
            }
            tie(s, &mut reference.rows());
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        pool.install(|| kernel.substeps(5, &step, Some(&tie)));
        for n in 0..300 {
            let (a, b) = (kernel.node(n), reference.node(n));
            for k in 0..3 {
                assert!(
                    (a.0[k] - b.0[k]).abs() <= 1e-5 * (1.0 + b.0[k].abs()),
                    "node {n}: u {a:?} vs {b:?}"
                );
                assert!(
                    (a.1[k] - b.1[k]).abs() <= 1e-4 * (1.0 + b.1[k].abs()),
                    "node {n}: v {a:?} vs {b:?}"
                );
            }
        }
        // The hanging nodes moved with their masters, and forces reached
        // the masters (they moved differently from an untied run).
        let mut untied = SpringKernel::new(&c.springs, &c.volumes, &c.rest);
        untied.load(&c.u, &c.v);
        let plain = Substep {
            hanging: &[],
            ..step
        };
        untied.substeps(5, &plain, None);
        assert!((40..130).any(|n| untied.node(n).0 != kernel.node(n).0));
    }
}
