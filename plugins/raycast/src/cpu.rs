//! The rayon path: one ray per pixel, 16 × 16-pixel tiles spread over the
//! thread pool. Every formula mirrors `shaders/raycast/raycast.wgsl` (same
//! [`RayUniforms`], same f32 operations in the same order), so the two
//! paths agree to a rounding error.
//!
//! Per ray: clip the ray to the box (voxel-centre box ∩ crop box) and the
//! clip planes → interval `[t0, t1]` (mm, `t ≥ 0` in front of the eye);
//! samples at the midpoints of steps of Δt (the last, shorter step at its
//! own midpoint with its own length, so a homogeneous medium integrates
//! exactly; with `jitter`, a first, shorter step of `ξ·Δt`, ξ the pixel's
//! [`filters::jitter`], sampled likewise, shifts the rest of the ray's
//! samples); empty-space skipping jumps over macro-cells the transfer
//! function makes transparent; front-to-back compositing stops at the
//! termination threshold.

use crate::filters;
use crate::gradient_cache::GradientCache;
use crate::macrocell::MacroCells;
use crate::ray_bounds::RayBounds;
use crate::step_opacity::StepOpacity;
use crate::transfer::Lut;
use crate::uniforms::{
    FLAG_BACKGROUND, FLAG_EARLY_TERMINATION, FLAG_ESS, FLAG_JITTER, FLAG_MAP_NEAREST, FLAG_SHADING,
    FLAG_SOBEL, FLAG_TRICUBIC, RayUniforms,
};
use crate::visible_cells::VisibleCells;
use rayon::prelude::*;
use voxflex_core::glam::Vec3;
use voxflex_core::opacity_map::{OPACITY_ONE, OpacityMap};
use voxflex_core::render::RenderStats;
use voxflex_core::volume::{Sample, VoxelSlice};
use voxflex_core::with_voxels;

/// Tile edge, pixels.
pub const TILE: u32 = 16;

/// Largest ray parameter (mm): "no far limit".
const T_FAR: f32 = 3.0e38;

/// What the CPU path renders: the uniforms and borrowed per-version data.
pub struct Scene<'a> {
    /// The frame's constants.
    pub u: &'a RayUniforms,
    /// The volume, x fastest, in its own scalar type (read as f32, exactly:
    /// [`crate::voxel_store::VoxelStore`]).
    pub values: VoxelSlice<'a>,
    /// The transfer function table.
    pub lut: &'a Lut,
    /// `lut`'s opacity over one step (made for `u.step[0]` mm, the full
    /// steps; a sample of another length computes its own).
    pub step_opacity: &'a StepOpacity,
    /// The macro-cells (min/max).
    pub cells: &'a MacroCells,
    /// Per-cell leap distances under `lut` ([`MacroCells::leap_distances`]).
    pub leap: &'a [u8],
    /// The combined opacity map, if any.
    pub map: Option<&'a OpacityMap>,
    /// Cached Sobel gradients of `values` (bit-identical to computing them
    /// per sample, which is what happens without it).
    pub gradients: Option<&'a GradientCache>,
    /// Which cells `lut` may show ([`VisibleCells`], made for this volume
    /// and `lut`); used when empty-space skipping is on and sampling is
    /// trilinear.
    pub visible: Option<&'a VisibleCells>,
    /// The frame's [`RayBounds`] (made from `u` and `leap`); used in
    /// composite mode when empty-space skipping is on.
    pub bounds: Option<&'a RayBounds>,
}

/// One ray's result: linear premultiplied RGBA (background included).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayResult {
    /// Linear, premultiplied RGBA.
    pub rgba: [f32; 4],
    /// Volume samples taken.
    pub samples: u32,
    /// Stopped by early ray termination.
    pub terminated: bool,
}

/// Where a sample's trilinear footprint sits.
#[derive(Clone, Copy)]
struct Footprint {
    /// Lower corner voxel.
    i: [usize; 3],
    /// Fractions in [0, 1].
    f: Vec3,
    /// Linear index of the lower corner.
    base: usize,
}

/// Where a ray's samples sit in `[t0, t1]` (mm): `lead` (0 or 1) samples
/// of the jitter step `[t0, ts]`, `n_full` steps of Δt from `ts`, then a
/// last step of `rem` if it is not negligible; `n_total` in all.
#[derive(Clone, Copy)]
struct Schedule {
    t0: f32,
    lead: u32,
    ts: f32,
    n_full: u32,
    rem: f32,
    n_total: u32,
}

/// Precomputed integer constants of a [`Scene`] whose voxels are `T`s.
struct Kernel<'a, T> {
    s: &'a Scene<'a>,
    /// The scene's voxels, typed.
    values: &'a [T],
    dims: [usize; 3],
    /// Largest lower-corner index per axis (`max(n, 2) − 2`; the grid's
    /// axes are at most [`crate::MAX_AXIS`] voxels).
    max0: [i32; 3],
    /// Offset to the upper corner per axis (0 on a 1-voxel axis).
    off: [usize; 3],
    /// Voxel-index upper bound `n − 1` per axis.
    upper: Vec3,
    cell: f32,
    inv_cell: f32,
    inv_dt: f32,
    cell_counts: [usize; 3],
    /// The shininess when it is a small whole number (then [`powi`], much
    /// cheaper than `powf`, gives the same value to rounding).
    shininess_int: Option<i32>,
    flags: u32,
    dt: f32,
    /// The scene's [`VisibleCells`] when they apply (skipping on, trilinear).
    visible: Option<&'a VisibleCells>,
    /// The frame's [`RayBounds`] (composite mode, skipping on).
    bounds: Option<&'a RayBounds>,
    /// The scene's [`StepOpacity`] (held here: one load less per sample).
    step_opacity: &'a StepOpacity,
}

#[inline(always)]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + t * (b - a)
}

impl<'a, T: Sample> Kernel<'a, T> {
    fn new(s: &'a Scene<'a>, values: &'a [T]) -> Self {
        let u = s.u;
        let dims = [u.dims[0] as usize, u.dims[1] as usize, u.dims[2] as usize];
        let strides = [1, dims[0], dims[0] * dims[1]];
        Self {
            s,
            values,
            dims,
            max0: dims.map(|n| (n.clamp(2, crate::MAX_AXIS) - 2) as i32),
            off: std::array::from_fn(|a| if dims[a] > 1 { strides[a] } else { 0 }),
            upper: Vec3::new(
                dims[0].max(1) as f32 - 1.0,
                dims[1].max(1) as f32 - 1.0,
                dims[2].max(1) as f32 - 1.0,
            ),
            cell: u.step[3],
            inv_cell: 1.0 / u.step[3],
            inv_dt: 1.0 / u.step[0],
            cell_counts: [
                u.cells[0] as usize,
                u.cells[1] as usize,
                u.cells[2] as usize,
            ],
            shininess_int: {
                let s = u.shading[3];
                (s == s.round() && (0.0..=128.0).contains(&s)).then_some(s as i32)
            },
            flags: u.flags(),
            dt: u.step[0],
            visible: s
                .visible
                .filter(|_| u.flags() & FLAG_ESS != 0 && u.flags() & FLAG_TRICUBIC == 0),
            bounds: s
                .bounds
                .filter(|_| u.flags() & FLAG_ESS != 0 && u.image[3] == 0),
            step_opacity: s.step_opacity,
        }
    }

    /// The primary ray of pixel `(px, py)`: origin (mm) and unit direction.
    #[inline]
    fn ray(&self, px: u32, py: u32) -> (Vec3, Vec3) {
        primary_ray(self.s.u, px, py)
    }

    /// The part `[t0, t1]` of the ray inside the box and every clip plane
    /// (`t0 ≥ t1` when none).
    #[inline]
    fn interval(&self, o: Vec3, d: Vec3) -> (f32, f32) {
        let u = self.s.u;
        let (mut t0, mut t1) = (0.0f32, T_FAR);
        for a in 0..3 {
            let (lo, hi) = (u.box_min[a], u.box_max[a]);
            if d[a].abs() < 1e-12 {
                if o[a] < lo || o[a] > hi {
                    return (1.0, 0.0);
                }
            } else {
                let inv = 1.0 / d[a];
                let ta = (lo - o[a]) * inv;
                let tb = (hi - o[a]) * inv;
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        for pl in &u.planes[..u.counts[0] as usize] {
            let n = Vec3::new(pl[0], pl[1], pl[2]);
            let s = n.dot(o) + pl[3];
            let nd = n.dot(d);
            if nd.abs() < 1e-12 {
                if s < 0.0 {
                    return (1.0, 0.0);
                }
            } else {
                let th = -s / nd;
                if nd > 0.0 {
                    t0 = t0.max(th);
                } else {
                    t1 = t1.min(th);
                }
            }
        }
        (t0, t1)
    }

    #[inline(always)]
    fn footprint(&self, p: Vec3) -> Footprint {
        let p = p.clamp(Vec3::ZERO, self.upper);
        let c = [
            whole(p.x).min(self.max0[0]),
            whole(p.y).min(self.max0[1]),
            whole(p.z).min(self.max0[2]),
        ];
        let i = c.map(|c| c as usize);
        Footprint {
            i,
            f: p - Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32),
            base: i[0] + self.dims[0] * (i[1] + self.dims[1] * i[2]),
        }
    }

    /// The value at voxel position `p` (trilinear or tricubic) and the
    /// trilinear footprint (for the opacity map and the gradient).
    #[inline(always)]
    fn sample(&self, p: Vec3) -> (f32, Footprint) {
        let fp = self.footprint(p);
        (self.sample_at(p, &fp), fp)
    }

    /// The value at voxel position `p` whose footprint is `fp`.
    #[inline(always)]
    fn sample_at(&self, p: Vec3, fp: &Footprint) -> f32 {
        if self.flags & FLAG_TRICUBIC != 0 {
            filters::tricubic(p, self.upper, |q| self.value(&self.footprint(q)))
        } else {
            self.value(fp)
        }
    }

    /// 0 unless the sample at footprint `fp` is known to have κ = 0
    /// without reading the volume; then the edge (cells) of the largest
    /// aligned block around its cell that shows nothing
    /// ([`VisibleCells::hidden_block`]).
    #[inline(always)]
    fn hidden_block(&self, fp: &Footprint) -> usize {
        match self.visible {
            Some(cells) => cells.hidden_block(self.values, self.s.lut, fp.i),
            None => 0,
        }
    }

    /// The next sample to look at after sample `k − 1`, whose cell `i` lies
    /// in a hidden block of `edge` cells: past the samples whose
    /// footprints lie in that block too. The exit is estimated in ray
    /// parameters and then checked on the sample itself with the loop's
    /// own arithmetic — positions along the ray are monotone per axis, so
    /// when the last skipped sample's footprint is in the (convex) block,
    /// every sample before it is, and none that may show is passed.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn past_block(
        &self,
        k: u32,
        sch: &Schedule,
        i: [usize; 3],
        edge: usize,
        oi: Vec3,
        di: Vec3,
        inv_di: Vec3,
    ) -> u32 {
        let lo = i.map(|c| c & !(edge - 1));
        let exit = block_exit(i.map(|c| c / edge), 1, edge as f32, oi, di, inv_di);
        let last = self
            .first_sample_at(sch, exit)
            .saturating_sub(1)
            .min(sch.n_total - 1);
        if last < k {
            return k;
        }
        let fp = self.footprint(oi + di * self.at(sch, last).0);
        let inside = (0..3).all(|a| fp.i[a] >= lo[a] && fp.i[a] < lo[a] + edge);
        if inside { last + 1 } else { k }
    }

    /// Trilinear value at a footprint.
    #[inline(always)]
    fn value(&self, fp: &Footprint) -> f32 {
        let [ox, oy, oz] = self.off;
        let b = fp.base;
        let v = &self.values[b..=b + ox + oy + oz];
        let at = |o: usize| v[o].to_f32();
        let x00 = lerp(at(0), at(ox), fp.f.x);
        let x10 = lerp(at(oy), at(ox + oy), fp.f.x);
        let x01 = lerp(at(oz), at(ox + oz), fp.f.x);
        let x11 = lerp(at(oy + oz), at(ox + oy + oz), fp.f.x);
        lerp(lerp(x00, x10, fp.f.y), lerp(x01, x11, fp.f.y), fp.f.z)
    }

    /// Central difference along `axis` of the trilinear field at the
    /// footprint (`f(p + e) − f(p − e)`, voxel units, clamped at the edges).
    #[inline(always)]
    fn diff(&self, fp: &Footprint, axis: usize) -> f32 {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let strides = [1, self.dims[0], self.dims[0] * self.dims[1]];
        let n = self.dims[axis];
        let i0 = fp.i[axis];
        let sa = strides[axis];
        // Indices along `axis`: i0 − 1, i0, i0 + 1, i0 + 2 (clamped).
        let im = i0.saturating_sub(1);
        let i1 = (i0 + 1).min(n - 1);
        let i2 = (i0 + 2).min(n - 1);
        let fa = fp.f[axis];
        let (fb, fc) = (fp.f[b], fp.f[c]);
        let row0 = fp.base - i0 * sa;
        let mut acc = [0f32; 4];
        let ob = [0, self.off[b]];
        let oc = [0, self.off[c]];
        let v = |l: usize| self.values[l].to_f32();
        for (slot, (db, dc)) in acc.iter_mut().zip([(0, 0), (1, 0), (0, 1), (1, 1)]) {
            let r = row0 + ob[db] + oc[dc];
            *slot = (1.0 - fa) * (v(r + i1 * sa) - v(r + im * sa))
                + fa * (v(r + i2 * sa) - v(r + i0 * sa));
        }
        lerp(lerp(acc[0], acc[1], fb), lerp(acc[2], acc[3], fb), fc)
    }

    /// Gradient (value units per mm) at a footprint.
    #[inline(always)]
    fn gradient(&self, fp: &Footprint) -> Vec3 {
        let g = self.s.u.grad_scale;
        if self.flags & FLAG_SOBEL != 0 {
            let cached = self
                .s
                .gradients
                .and_then(|c| c.sobel(self.values, fp.i, fp.f));
            let d = cached.unwrap_or_else(|| {
                filters::sobel(&filters::gather(self.values, self.dims, fp.i), fp.f)
            });
            return Vec3::new(d.x * g[0], d.y * g[1], d.z * g[2]);
        }
        Vec3::new(
            self.diff(fp, 0) * g[0],
            self.diff(fp, 1) * g[1],
            self.diff(fp, 2) * g[2],
        )
    }

    /// Combined opacity-map value of voxel `(i, j, k)`.
    #[inline(always)]
    fn map_at(m: &OpacityMap, i: usize, j: usize, k: usize) -> f32 {
        let x = i.wrapping_sub(m.origin[0]);
        let y = j.wrapping_sub(m.origin[1]);
        let z = k.wrapping_sub(m.origin[2]);
        let q = if x < m.dims[0] && y < m.dims[1] && z < m.dims[2] {
            m.values[x + m.dims[0] * (y + m.dims[1] * z)]
        } else {
            m.outside
        };
        q as f32 / OPACITY_ONE
    }

    /// Opacity-map factor `o` at a sample.
    #[inline]
    fn map_factor(&self, m: &OpacityMap, fp: &Footprint, p: Vec3) -> f32 {
        if self.flags & FLAG_MAP_NEAREST != 0 {
            let q = (p + Vec3::splat(0.5)).floor().clamp(Vec3::ZERO, self.upper);
            return Self::map_at(m, q.x as usize, q.y as usize, q.z as usize);
        }
        let [i0, j0, k0] = fp.i;
        let i1 = (i0 + 1).min(self.dims[0] - 1);
        let j1 = (j0 + 1).min(self.dims[1] - 1);
        let k1 = (k0 + 1).min(self.dims[2] - 1);
        let f = fp.f;
        let x00 = lerp(
            Self::map_at(m, i0, j0, k0),
            Self::map_at(m, i1, j0, k0),
            f.x,
        );
        let x10 = lerp(
            Self::map_at(m, i0, j1, k0),
            Self::map_at(m, i1, j1, k0),
            f.x,
        );
        let x01 = lerp(
            Self::map_at(m, i0, j0, k1),
            Self::map_at(m, i1, j0, k1),
            f.x,
        );
        let x11 = lerp(
            Self::map_at(m, i0, j1, k1),
            Self::map_at(m, i1, j1, k1),
            f.x,
        );
        lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z)
    }

    /// Linear index of the macro-cell holding voxel position `p`.
    #[inline]
    fn cell_of(&self, p: Vec3) -> ([usize; 3], usize) {
        let p = p.clamp(Vec3::ZERO, self.upper);
        let c = [
            ((p.x * self.inv_cell) as usize).min(self.cell_counts[0] - 1),
            ((p.y * self.inv_cell) as usize).min(self.cell_counts[1] - 1),
            ((p.z * self.inv_cell) as usize).min(self.cell_counts[2] - 1),
        ];
        let l = c[0] + self.cell_counts[0] * (c[1] + self.cell_counts[1] * c[2]);
        (c, l)
    }

    /// Ray parameter (mm) where the ray `oi + t·di` (voxel space, `inv_di`
    /// = 1/di) leaves the block of macro cells within `d − 1` of macro
    /// cell `c` (`d = 1`: the cell itself).
    #[inline]
    fn cell_exit(&self, c: [usize; 3], d: u32, oi: Vec3, di: Vec3, inv_di: Vec3) -> f32 {
        block_exit(c, d, self.cell, oi, di, inv_di)
    }

    /// Casts the ray of pixel `(px, py)`.
    fn cast(&self, px: u32, py: u32) -> RayResult {
        let u = self.s.u;
        let (o, d) = self.ray(px, py);
        let (t0, t1) = self.interval(o, d);
        let reach = self.bounds.map_or([t0, t1], |b| b.at(px, py));
        let mut out = if t0 < t1 && reach[0] <= reach[1] {
            let sch = self.schedule(t0, t1, px, py);
            if u.image[3] == 0 {
                self.composite(o, d, &sch, reach)
            } else {
                self.mip(o, d, &sch)
            }
        } else {
            RayResult::default()
        };
        if self.flags & FLAG_BACKGROUND != 0 {
            let k = 1.0 - out.rgba[3];
            for (c, b) in out.rgba.iter_mut().zip(u.background) {
                *c += k * b;
            }
        }
        out
    }

    /// Sample schedule of `[t0, t1]` for pixel `(px, py)`.
    #[inline]
    fn schedule(&self, t0: f32, t1: f32, px: u32, py: u32) -> Schedule {
        let xi = if self.flags & FLAG_JITTER != 0 {
            filters::jitter(px, py)
        } else {
            0.0
        };
        let a = (xi * self.dt).min(t1 - t0);
        let lead = (a > 1e-4 * self.dt) as u32;
        let ts = t0 + a;
        let span = t1 - ts;
        // span ≥ 0: truncation is floor (and avoids a libm call).
        let n_full = (span * self.inv_dt) as u32;
        let rem = span - n_full as f32 * self.dt;
        let n_total = lead + n_full + (rem > 1e-4 * self.dt) as u32;
        Schedule {
            t0,
            lead,
            ts,
            n_full,
            rem,
            n_total,
        }
    }

    /// Ray parameter (mm) and step length of sample `k`.
    #[inline(always)]
    fn at(&self, s: &Schedule, k: u32) -> (f32, f32) {
        if k < s.lead {
            let a = s.ts - s.t0;
            (s.t0 + 0.5 * a, a)
        } else if k - s.lead < s.n_full {
            (s.ts + ((k - s.lead) as f32 + 0.5) * self.dt, self.dt)
        } else {
            (s.ts + s.n_full as f32 * self.dt + 0.5 * s.rem, s.rem)
        }
    }

    /// Index of the first sample past sample `k` at or past ray parameter
    /// `t_exit`.
    #[inline]
    fn next_sample(&self, k: u32, s: &Schedule, t_exit: f32) -> u32 {
        self.first_sample_at(s, t_exit).max(k + 1)
    }

    /// Index of the first sample at or past ray parameter `t` (to a
    /// rounding: callers that must not miss one start a sample earlier).
    #[inline]
    fn first_sample_at(&self, s: &Schedule, t: f32) -> u32 {
        let x = ((t - s.ts) * self.inv_dt - 0.5 + s.lead as f32).clamp(0.0, s.n_total as f32);
        // ceil(x) for x ≥ 0 without a libm call.
        let i = x as u32;
        if (i as f32) < x { i + 1 } else { i }
    }

    /// Composites the samples of `sch` within `reach` (ray parameters,
    /// mm; samples outside it have κ = 0: [`RayBounds`]).
    fn composite(&self, o: Vec3, d: Vec3, sch: &Schedule, reach: [f32; 2]) -> RayResult {
        let u = self.s.u;
        let lut = self.s.lut;
        let origin = Vec3::from_slice(&u.origin[..3]);
        let inv_sp = Vec3::from_slice(&u.inv_spacing[..3]);
        let oi = (o - origin) * inv_sp;
        let di = d * inv_sp;
        let inv_di = Vec3::ONE / di;
        let n_total = sch.n_total;
        let ess = self.flags & FLAG_ESS != 0;
        let et = self.flags & FLAG_EARLY_TERMINATION != 0;
        let shade = self.flags & FLAG_SHADING != 0;
        let threshold = u.step[1];
        let [ka, kd, ks, shininess] = u.shading;
        let map = self.s.map;
        let (mut c_acc, mut a_acc) = (Vec3::ZERO, 0.0f32);
        let mut samples = 0u32;
        let mut terminated = false;
        let mut cell_exit = -1.0f32;
        let mut k = self.first_sample_at(sch, reach[0]).saturating_sub(1);
        while k < n_total {
            let (t, len) = self.at(sch, k);
            if t > reach[1] {
                break;
            }
            let p = oi + di * t;
            if ess && t >= cell_exit {
                let (c, l) = self.cell_of(p);
                let d = self.s.leap[l] as u32;
                if d > 0 {
                    let exit = self.cell_exit(c, d, oi, di, inv_di);
                    k = self.next_sample(k, sch, exit);
                    cell_exit = -1.0;
                    continue;
                }
                cell_exit = self.cell_exit(c, 1, oi, di, inv_di);
            }
            k += 1;
            let fp = self.footprint(p);
            let hidden = self.hidden_block(&fp);
            if hidden > 0 {
                // A single cell holds a sample or two: step on.
                if hidden > 1 {
                    k = self.past_block(k, sch, fp.i, hidden, oi, di, inv_di);
                }
                continue;
            }
            let v = self.sample_at(p, &fp);
            samples += 1;
            let Some(([r, g, b, kappa], place)) = lut.lookup_visible_placed(v) else {
                continue;
            };
            if kappa <= 0.0 {
                continue;
            }
            let mut alpha = if len == self.step_opacity.step_mm() {
                self.step_opacity.at(place)
            } else {
                1.0 - (-kappa * len).exp()
            };
            if let Some(m) = map {
                alpha *= self.map_factor(m, &fp, p);
            }
            if alpha <= 0.0 {
                continue;
            }
            let mut col = Vec3::new(r, g, b);
            if shade {
                let grad = self.gradient(&fp);
                let len2 = grad.length_squared();
                let ndl = if len2 > 1e-20 {
                    (grad.dot(d) / len2.sqrt()).abs()
                } else {
                    1.0
                };
                let spec = match self.shininess_int {
                    _ if ndl <= 0.0 => 0.0,
                    Some(n) => powi(ndl, n as u32),
                    None => ndl.powf(shininess),
                };
                col = col * (ka + kd * ndl) + Vec3::splat(ks * spec);
            }
            let w = (1.0 - a_acc) * alpha;
            c_acc += col * w;
            a_acc += w;
            if et && a_acc >= threshold {
                terminated = true;
                break;
            }
        }
        RayResult {
            rgba: [c_acc.x, c_acc.y, c_acc.z, a_acc],
            samples,
            terminated,
        }
    }

    fn mip(&self, o: Vec3, d: Vec3, sch: &Schedule) -> RayResult {
        let u = self.s.u;
        let origin = Vec3::from_slice(&u.origin[..3]);
        let inv_sp = Vec3::from_slice(&u.inv_spacing[..3]);
        let oi = (o - origin) * inv_sp;
        let di = d * inv_sp;
        let inv_di = Vec3::ONE / di;
        let n_total = sch.n_total;
        let ess = self.flags & FLAG_ESS != 0;
        let mut vmax = f32::MIN;
        let mut pmax = Vec3::ZERO;
        let mut samples = 0u32;
        let mut cell_exit = -1.0f32;
        let mut k = 0u32;
        while k < n_total {
            let (t, _) = self.at(sch, k);
            let p = oi + di * t;
            if ess && t >= cell_exit {
                let (c, l) = self.cell_of(p);
                let exit = self.cell_exit(c, 1, oi, di, inv_di);
                if samples > 0 && self.s.cells.max[l] <= vmax {
                    k = self.next_sample(k, sch, exit);
                    cell_exit = -1.0;
                    continue;
                }
                cell_exit = exit;
            }
            k += 1;
            let (v, _) = self.sample(p);
            samples += 1;
            if v > vmax {
                vmax = v;
                pmax = p;
            }
        }
        if samples == 0 {
            return RayResult::default();
        }
        let [r, g, b, kappa] = self.s.lut.lookup(vmax);
        let mut alpha = 1.0 - (-kappa * u.step[2]).exp();
        if let Some(m) = self.s.map {
            alpha *= self.map_factor(m, &self.footprint(pmax), pmax);
        }
        RayResult {
            rgba: [r * alpha, g * alpha, b * alpha, alpha],
            samples,
            terminated: false,
        }
    }
}

/// Ray parameter (mm) where the ray `oi + t·di` (voxel space, `inv_di` =
/// 1/di) leaves the blocks of `size` voxels within `d − 1` blocks of block
/// `c` (the grid of blocks starting at voxel position 0; `d = 1`: block
/// `c` itself).
#[inline(always)]
fn block_exit(c: [usize; 3], d: u32, size: f32, oi: Vec3, di: Vec3, inv_di: Vec3) -> f32 {
    let mut t = T_FAR;
    for a in 0..3 {
        if di[a] > 0.0 {
            t = t.min(((c[a] as u32 + d) as f32 * size - oi[a]) * inv_di[a]);
        } else if di[a] < 0.0 {
            t = t.min(((c[a] as f32 + 1.0 - d as f32) * size - oi[a]) * inv_di[a]);
        }
    }
    t
}

/// The whole part of `x`, a coordinate already clamped to `[0, n − 1]` of
/// a grid axis: one truncating conversion, without the range fix-ups of
/// `as usize` (3–4 % of a steady frame, docs/BENCHMARKS.md).
#[inline(always)]
fn whole(x: f32) -> i32 {
    debug_assert!((0.0..=crate::MAX_AXIS as f32).contains(&x), "{x}");
    // SAFETY: the caller clamps `x` to `[0, n − 1]` with glam's `clamp`
    // (which maps NaN to the lower bound), and the renderer refuses axes
    // longer than `MAX_AXIS` = 2³⁰ voxels (`check_grid`), so `x` is finite
    // and in [0, 2³⁰] — truncation to `i32` is defined there.
    unsafe { x.to_int_unchecked::<i32>() }
}

/// `x^n` by squaring, inlined: the multiplications of the runtime's
/// `__powisf2`, which `f32::powi` calls for an exponent known only at run
/// time (the call was 1.2 % of a shaded frame), in the same order, so the
/// result is the same bit for bit.
#[inline(always)]
fn powi(mut x: f32, mut n: u32) -> f32 {
    let mut y = if n % 2 == 1 { x } else { 1.0 };
    loop {
        n >>= 1;
        if n == 0 {
            return y;
        }
        x *= x;
        if n % 2 == 1 {
            y *= x;
        }
    }
}

/// The primary ray of pixel `(px, py)` (top-left origin) of the frame `u`:
/// origin (world mm) and unit direction.
#[inline]
pub fn primary_ray(u: &RayUniforms, px: u32, py: u32) -> (Vec3, Vec3) {
    let nx = 2.0 * (px as f32 + 0.5) / u.image[0] as f32 - 1.0;
    let ny = 1.0 - 2.0 * (py as f32 + 0.5) / u.image[1] as f32;
    let eye = Vec3::from_slice(&u.eye[..3]);
    let right = Vec3::from_slice(&u.right[..3]);
    let up = Vec3::from_slice(&u.up[..3]);
    let fwd = Vec3::from_slice(&u.forward[..3]);
    if u.image[2] == 0 {
        (eye + right * nx + up * ny, fwd)
    } else {
        (eye, (fwd + right * nx + up * ny).normalize())
    }
}

/// Renders the whole image: linear premultiplied RGBA per pixel (row-major
/// from the top-left), background composited, and the statistics.
pub fn render(scene: &Scene<'_>) -> (Vec<[f32; 4]>, RenderStats) {
    with_voxels!(scene.values, |values| render_typed(scene, values))
}

/// [`render`] with the scene's voxels as `T`s (one copy of the kernel per
/// scalar type, so a sample reads its type and converts in registers).
///
/// Each tile writes its pixels straight into the image, which starts as
/// zeroed memory the system maps as the tiles first write it — in
/// parallel, and without a second copy of the image (a first frame used to
/// fault in both per-tile buffers and the image, and copy one into the
/// other on one thread).
fn render_typed<T: Sample>(scene: &Scene<'_>, values: &[T]) -> (Vec<[f32; 4]>, RenderStats) {
    let k = Kernel::new(scene, values);
    let (w, h) = (scene.u.image[0], scene.u.image[1]);
    let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let mut image = vec![[0f32; 4]; w as usize * h as usize];
    let out = ImagePtr(image.as_mut_ptr());
    let stats = (0..tx * ty)
        .into_par_iter()
        .map(|t| {
            let (x0, y0) = ((t % tx) * TILE, (t / tx) * TILE);
            let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
            let mut stats = RenderStats::default();
            for y in y0..y1 {
                for x in x0..x1 {
                    let r = k.cast(x, y);
                    stats.rays += 1;
                    stats.samples += r.samples as u64;
                    stats.terminated_early += r.terminated as u64;
                    out.write(y as usize * w as usize + x as usize, r.rgba);
                }
            }
            stats
        })
        .reduce(RenderStats::default, |a, b| RenderStats {
            rays: a.rays + b.rays,
            samples: a.samples + b.samples,
            terminated_early: a.terminated_early + b.terminated_early,
        });
    (image, stats)
}

/// The image's pixels, written by the tiles in parallel.
struct ImagePtr(*mut [f32; 4]);

// SAFETY: each pixel lies in exactly one tile and is written once, by the
// task rendering that tile; the image outlives the parallel loop, and
// nothing reads it until the loop has finished.
unsafe impl Sync for ImagePtr {}

impl ImagePtr {
    /// Writes pixel `i` (row-major index, inside the image).
    #[inline]
    fn write(&self, i: usize, rgba: [f32; 4]) {
        // SAFETY: see the `Sync` impl; `i` is a pixel of the image (the
        // caller's tile lies inside it).
        unsafe { self.0.add(i).write(rgba) }
    }
}

#[cfg(test)]
mod tests {
    use super::{powi, whole};
    use voxflex_core::glam::Vec3;

    /// `whole`'s safety rests on glam's `clamp` turning every f32 —
    /// NaN and the infinities included — into a finite value inside the
    /// bounds; and on its truncation matching `as` there.
    #[test]
    fn clamped_coordinates_are_finite_and_truncate_like_as() {
        let upper = Vec3::new(511.0, 1.0, crate::MAX_AXIS as f32 - 1.0);
        for x in [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            -3.5,
            0.49,
            7.99,
            1e12,
        ] {
            let p = Vec3::splat(x).clamp(Vec3::ZERO, upper);
            for (c, hi) in p.to_array().into_iter().zip(upper.to_array()) {
                assert!((0.0..=hi).contains(&c), "{x} → {c}");
                assert_eq!(whole(c) as i64, c as i64, "{x} → {c}");
            }
        }
    }

    /// The inlined power is `f32::powi`, bit for bit, for every whole
    /// shininess the renderer uses it for and bases across [0, 1].
    #[test]
    fn powi_is_the_runtimes() {
        for n in 0..=128u32 {
            // A run-time exponent, so `f32::powi` calls the runtime.
            let m = std::hint::black_box(n as i32);
            for k in 0..=1000 {
                let x = k as f32 / 1000.0 + 1.0e-4 * (k % 7) as f32;
                assert_eq!(powi(x, n).to_bits(), x.powi(m).to_bits(), "{x}^{n}");
            }
        }
    }
}
