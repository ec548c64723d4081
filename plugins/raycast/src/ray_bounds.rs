//! [`RayBounds`]: per pixel, the stretch of its ray that can meet a
//! non-empty macro cell — the CPU path's skip over the empty space in
//! front of and behind the tissue.
//!
//! Empty-space skipping walks the macro cells from where a ray enters the
//! volume: on the 512 × 512 × 133 CT with `ct-bone`, ten leaps or cell
//! visits per ray before its first sample, and six rays in ten that enter
//! the volume never meet a shown value. Here every non-empty macro cell
//! (leap distance 0 under the current table) is projected once per frame:
//! its box in voxel space, widened by [`MARGIN`] voxels, gives a pixel
//! rectangle (every pixel whose ray can pass through the box) and a range
//! of the ray parameter `t` (mm) holding every point of the box. Per pixel
//! the bounds are the smallest and the largest `t` of the rectangles that
//! cover it. A sample outside them lies in no non-empty cell, where the
//! transfer function gives κ = 0 (the macro cell's min/max hold every voxel
//! its samples read), so the ray starts at the first sample inside and
//! stops after the last one: **the image does not change, bit for bit**,
//! and a ray whose pixel no rectangle covers costs its clipping alone.
//!
//! With [`ShownCells`] (trilinear sampling, macro cells of one brick) a
//! non-empty macro cell is narrowed to the box of its cells the table may
//! show ([`VisibleCells::shown_cells`]; a cell `i` holds the positions
//! `[i, i + 1]`), and one with none is left out: a κ > 0 sample lies in a
//! shown cell, so the argument above holds for these smaller boxes, and a
//! ray starts about where the tissue starts, not up to a macro cell before.
//!
//! Orthographic rays share the direction `forward`, and `t` of a point `q`
//! is `(q − eye)·forward`. Perspective rays start at the eye, and `t` is the
//! distance to it: the box's range is from its nearest point to its
//! farthest corner; a box reaching behind the eye plane covers the whole
//! image. Used in composite mode with empty-space skipping on (MIP decides
//! per cell by its running maximum, not by the table).
//!
//! Units: `t` in mm along the unit ray direction, as [`crate::cpu`]; pixel
//! `(0, 0)` top-left; voxel index space `p = (x − origin) / spacing`.

use crate::transfer::Lut;
use crate::uniforms::RayUniforms;
use crate::visible_cells::VisibleCells;
use rayon::prelude::*;
use voxflex_core::glam::DVec3;
use voxflex_core::volume::VoxelSlice;
use voxflex_core::with_voxels;

/// Voxels each non-empty cell's box is widened by on every side: far above
/// the f32 rounding of a sample's position (~1e-4 voxel) and of `t`.
pub const MARGIN: f64 = 0.01;

/// Image rows per rayon task when filling the bounds.
const ROWS_PER_TASK: usize = 8;

/// Per pixel `[lo, hi]` (ray parameter, mm) of a frame's rays that may meet
/// a non-empty macro cell; `lo > hi` where none can.
pub struct RayBounds {
    width: usize,
    bounds: Vec<[f32; 2]>,
}

/// A non-empty cell's projection: inclusive pixel rectangle and `t` range.
#[derive(Clone, Copy, Debug)]
struct Footprint {
    x: [usize; 2],
    y: [usize; 2],
    t: [f32; 2],
}

/// What the table may show inside each brick ([`VisibleCells`]), for a
/// trilinear frame: the volume and the table the cells were made for.
#[derive(Clone, Copy)]
pub struct ShownCells<'a> {
    /// The visible cells of `values` under `lut`.
    pub cells: &'a VisibleCells,
    /// The volume (x fastest, in the renderer's scalar type).
    pub values: VoxelSlice<'a>,
    /// The frame's table.
    pub lut: &'a Lut,
}

impl RayBounds {
    /// The bounds of the frame `u` for the cells whose leap distance
    /// (`leap`, one per macro cell, x fastest) is 0 — each narrowed to the
    /// box of its cells the table may show when `shown` is given (building
    /// those bricks of [`VisibleCells`] that are not built yet), and left
    /// out when it shows none. `shown` requires macro cells of one brick
    /// (edge [`crate::lazy_bricks::BRICK`]): cell `c` is brick `c`.
    pub fn build(u: &RayUniforms, leap: &[u8], shown: Option<ShownCells<'_>>) -> Self {
        assert!(
            shown.is_none() || u.dims[3] as usize == crate::lazy_bricks::BRICK,
            "shown cells narrow macro cells of one brick only"
        );
        let camera = Projector::new(u);
        let non_empty: Vec<usize> = (0..leap.len()).filter(|&l| leap[l] == 0).collect();
        let footprints: Vec<Footprint> = non_empty
            .par_iter()
            .filter_map(|&l| {
                let (lo, hi) = cell_box(u, l, shown)?;
                camera.footprint(lo, hi)
            })
            .collect();
        let (w, h) = (u.image[0] as usize, u.image[1] as usize);
        let mut bounds = vec![[f32::INFINITY, f32::NEG_INFINITY]; w * h];
        bounds
            .par_chunks_mut((w * ROWS_PER_TASK).max(1))
            .enumerate()
            .for_each(|(task, rows)| {
                let y0 = task * ROWS_PER_TASK;
                let y1 = y0 + rows.len() / w.max(1);
                for f in &footprints {
                    for y in f.y[0].max(y0)..=f.y[1].min(y1.saturating_sub(1)) {
                        let row = &mut rows[(y - y0) * w..(y - y0 + 1) * w];
                        for b in &mut row[f.x[0]..=f.x[1]] {
                            b[0] = b[0].min(f.t[0]);
                            b[1] = b[1].max(f.t[1]);
                        }
                    }
                }
            });
        Self { width: w, bounds }
    }

    /// `[lo, hi]` of pixel `(px, py)` (`lo > hi`: the ray meets no
    /// non-empty cell).
    #[inline]
    pub fn at(&self, px: u32, py: u32) -> [f32; 2] {
        self.bounds[py as usize * self.width + px as usize]
    }
}

/// The world box (mm, lower and upper corner) of macro cell `l` (linear,
/// x fastest), widened by [`MARGIN`] voxels: the whole cell, or the box of
/// the positions of its shown cells (`None` when it has none).
fn cell_box(u: &RayUniforms, l: usize, shown: Option<ShownCells<'_>>) -> Option<(DVec3, DVec3)> {
    let counts = [
        u.cells[0] as usize,
        u.cells[1] as usize,
        u.cells[2] as usize,
    ];
    let c = [
        l % counts[0],
        (l / counts[0]) % counts[1],
        l / (counts[0] * counts[1]),
    ];
    let edge = u.step[3] as f64;
    let (lo, hi) = match shown {
        // A trilinear cell i holds the positions [i, i + 1] per axis.
        Some(s) => {
            let cells = with_voxels!(s.values, |v| s.cells.shown_cells(v, s.lut, c))?;
            let lo = DVec3::from_array(cells.lo.map(|i| i as f64));
            let hi = DVec3::from_array(cells.hi.map(|i| i as f64 + 1.0));
            (lo, hi)
        }
        None => {
            let c = DVec3::from_array(c.map(|c| c as f64));
            (c * edge, (c + 1.0) * edge)
        }
    };
    let origin = DVec3::new(u.origin[0] as f64, u.origin[1] as f64, u.origin[2] as f64);
    let spacing = DVec3::new(
        1.0 / u.inv_spacing[0] as f64,
        1.0 / u.inv_spacing[1] as f64,
        1.0 / u.inv_spacing[2] as f64,
    );
    let lo = (lo - MARGIN) * spacing + origin;
    let hi = (hi + MARGIN) * spacing + origin;
    Some((lo.min(hi), lo.max(hi)))
}

/// The camera of a frame, in f64.
struct Projector {
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    size: [f64; 2],
    perspective: bool,
}

impl Projector {
    fn new(u: &RayUniforms) -> Self {
        let v = |a: [f32; 4]| DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
        Self {
            eye: v(u.eye),
            right: v(u.right),
            up: v(u.up),
            forward: v(u.forward),
            size: [u.image[0] as f64, u.image[1] as f64],
            perspective: u.image[2] != 0,
        }
    }

    /// The pixels and `t` range of the box `[lo, hi]` (world mm); `None`
    /// when no pixel's ray can meet it.
    fn footprint(&self, lo: DVec3, hi: DVec3) -> Option<Footprint> {
        let corners = (0..8).map(|c| {
            DVec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            ) - self.eye
        });
        let (mut n_lo, mut n_hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut t = [f64::INFINITY, f64::NEG_INFINITY];
        let (r2, u2) = (self.right.length_squared(), self.up.length_squared());
        for v in corners {
            let z = v.dot(self.forward);
            let (n, depth) = if self.perspective {
                if z <= 1e-9 * v.length() {
                    // Reaches behind the eye plane: every pixel.
                    let far = t[1].max(self.farthest(lo, hi));
                    return Some(self.whole_image(0.0, far));
                }
                (
                    [v.dot(self.right) / (r2 * z), v.dot(self.up) / (u2 * z)],
                    v.length(),
                )
            } else {
                ([v.dot(self.right) / r2, v.dot(self.up) / u2], z)
            };
            for a in 0..2 {
                n_lo[a] = n_lo[a].min(n[a]);
                n_hi[a] = n_hi[a].max(n[a]);
            }
            t = [t[0].min(depth), t[1].max(depth)];
        }
        if self.perspective {
            // The nearest point of the box may lie on a face, not a corner.
            t[0] = (self.eye.clamp(lo, hi) - self.eye).length();
        }
        // Pixel centres: px = (nx + 1)·W/2 − 0.5, py = (1 − ny)·H/2 − 0.5.
        let px = |n: f64| (n + 1.0) * 0.5 * self.size[0] - 0.5;
        let py = |n: f64| (1.0 - n) * 0.5 * self.size[1] - 0.5;
        let x = pixel_span(px(n_lo[0]), px(n_hi[0]), self.size[0])?;
        let y = pixel_span(py(n_hi[1]), py(n_lo[1]), self.size[1])?;
        Some(Footprint {
            x,
            y,
            t: [t[0] as f32, t[1] as f32],
        })
    }

    fn farthest(&self, lo: DVec3, hi: DVec3) -> f64 {
        let d = (lo - self.eye).abs().max((hi - self.eye).abs());
        d.length()
    }

    fn whole_image(&self, near: f64, far: f64) -> Footprint {
        Footprint {
            x: [0, self.size[0] as usize - 1],
            y: [0, self.size[1] as usize - 1],
            t: [near as f32, far as f32],
        }
    }
}

/// The pixels `floor(a) ..= ceil(b)` clipped to `0 .. n` (`None` if none).
fn pixel_span(a: f64, b: f64, n: f64) -> Option<[usize; 2]> {
    let (a, b) = (a.floor().max(0.0), b.ceil().min(n - 1.0));
    (a <= b).then_some([a as usize, b as usize])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RaycastRenderer;
    use crate::cpu::primary_ray;
    use crate::views::fit_camera;
    use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
    use voxflex_core::render::{RenderVolume, Renderer};

    /// The part of ray `o + t·d` (voxel space) inside the box `[lo, hi]`,
    /// in f64 by slabs (`None` when it misses).
    fn chord(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for a in 0..3 {
            if d[a] == 0.0 {
                if o[a] < lo[a] || o[a] > hi[a] {
                    return None;
                }
                continue;
            }
            let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// One non-empty cell at a time, cameras on every side (orthographic,
    /// perspective, an eye 3 mm in front of a cell's face, where the box's
    /// nearest point is on the face and not a corner, and an eye inside the
    /// volume): every pixel's ray meets the cell's box (exact chord, f64)
    /// only between the pixel's bounds.
    #[test]
    fn bounds_hold_every_chord_through_the_non_empty_cells() {
        let vol = voxflex_phantom::phantom("head", [26, 20, 18]).unwrap();
        let mut r = RaycastRenderer::create("", None).unwrap();
        r.init(ExecutionBackend::Cpu).unwrap();
        r.set_volume(RenderVolume::Cpu(vol.view()), DirtyRegion::All)
            .unwrap();
        let g = vol.grid;
        let mut cameras = Vec::new();
        for (az, el) in [(0.0, 0.0), (90.0, 40.0), (200.0, -70.0), (300.0, 15.0)] {
            cameras.push(fit_camera(&g, 24, 20, az, el, None));
            cameras.push(fit_camera(&g, 24, 20, az, el, Some(50.0)));
        }
        let mut close = fit_camera(&g, 24, 20, 0.0, 0.0, Some(100.0));
        close.target = g.index_to_world(DVec3::new(12.0, 8.0, 12.0));
        close.distance_mm = 3.0;
        cameras.push(close);
        let mut inside = close;
        inside.target = g.index_to_world(DVec3::new(9.0, 9.0, 9.0));
        inside.distance_mm = 0.5;
        cameras.push(inside);
        let u0 = r.frame(&cameras[0]).unwrap();
        let counts = [u0.cells[0], u0.cells[1], u0.cells[2]].map(|n| n as usize);
        let edge = u0.step[3] as f64;
        let (mut hits, mut misses) = (0, 0);
        for cell in [[0, 0, 0], [1, 1, 1], [2, 2, 2], [1, 0, 2]] {
            let mut leap = vec![1u8; counts.iter().product()];
            leap[cell[0] + counts[0] * (cell[1] + counts[1] * cell[2])] = 0;
            let lo = DVec3::from_array(cell.map(|c| c as f64 * edge));
            let hi = lo + DVec3::splat(edge);
            for cam in &cameras {
                let u = r.frame(cam).unwrap();
                let bounds = RayBounds::build(&u, &leap, None);
                let v = |a: [f32; 4]| DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
                let (origin, inv) = (v(u.origin), v(u.inv_spacing));
                for py in 0..u.image[1] {
                    for px in 0..u.image[0] {
                        let (o, d) = primary_ray(&u, px, py);
                        let o = (o.as_dvec3() - origin) * inv;
                        let d = d.as_dvec3() * inv;
                        let [b_lo, b_hi] = bounds.at(px, py).map(|b| b as f64);
                        let Some((t0, t1)) = chord(o, d, lo, hi) else {
                            misses += 1;
                            continue;
                        };
                        hits += 1;
                        assert!(
                            b_lo <= t0 && t1 <= b_hi,
                            "cell {cell:?} {cam:?} pixel {px},{py}: chord {t0}..{t1} outside {b_lo}..={b_hi}"
                        );
                    }
                }
            }
        }
        assert!(hits > 100 && misses > 100, "{hits} hits, {misses} misses");
    }

    /// With the shown cells: a volume of soft tissue with a few bone
    /// voxels, every camera of the test above; every chord through a cell
    /// the table may show (`[i, i + 1]³`, voxel space) lies within its
    /// pixel's bounds, and the bounds are narrower than the macro cells'.
    #[test]
    fn narrowed_bounds_hold_every_chord_through_the_shown_cells() {
        let dims = [26, 20, 18];
        let mut vol = voxflex_phantom::phantom("head", dims).unwrap();
        let g = vol.grid;
        let voxflex_core::volume::VoxelData::I16(d) = &mut vol.data else {
            panic!("an i16 phantom")
        };
        d.fill(40);
        for (n, at) in [[3, 4, 5], [12, 9, 9], [13, 9, 9], [22, 17, 2]]
            .iter()
            .enumerate()
        {
            d[g.linear(at[0], at[1], at[2])] = 700 + 100 * n as i16;
        }
        let mut r = RaycastRenderer::create("", None).unwrap();
        r.init(ExecutionBackend::Cpu).unwrap();
        r.set_volume(RenderVolume::Cpu(vol.view()), DirtyRegion::All)
            .unwrap();
        let mut cameras = Vec::new();
        for (az, el) in [(0.0, 0.0), (90.0, 40.0), (200.0, -70.0), (300.0, 15.0)] {
            cameras.push(fit_camera(&g, 24, 20, az, el, None));
            cameras.push(fit_camera(&g, 24, 20, az, el, Some(50.0)));
        }
        let mut close = fit_camera(&g, 24, 20, 0.0, 0.0, Some(100.0));
        close.target = g.index_to_world(DVec3::new(12.5, 7.0, 9.5));
        close.distance_mm = 3.0;
        cameras.push(close);
        r.render_linear(&cameras[0]).unwrap();
        let frames: Vec<RayUniforms> = cameras.iter().map(|c| r.frame(c).unwrap()).collect();
        let leap = r.leap.as_ref().unwrap().2.clone();
        let cells = &r.visible.as_ref().unwrap().1;
        let lut = r.lut.as_ref().unwrap().lut.clone();
        let shown: Vec<[usize; 3]> = (0..dims[2] - 1)
            .flat_map(|k| {
                (0..dims[1] - 1).flat_map(move |j| (0..dims[0] - 1).map(move |i| [i, j, k]))
            })
            .filter(|&i| with_voxels!(r.values.as_slice(), |v| cells.may_show(v, &lut, i)))
            .collect();
        assert!(
            !shown.is_empty() && shown.len() < 200,
            "{} shown cells",
            shown.len()
        );
        let (mut narrower, mut chords) = (0, 0);
        for (u, cam) in frames.iter().zip(&cameras) {
            let whole = RayBounds::build(u, &leap, None);
            let narrow = RayBounds::build(
                u,
                &leap,
                Some(ShownCells {
                    cells,
                    values: r.values.as_slice(),
                    lut: &lut,
                }),
            );
            let v = |a: [f32; 4]| DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
            let (origin, inv) = (v(u.origin), v(u.inv_spacing));
            for py in 0..u.image[1] {
                for px in 0..u.image[0] {
                    let [n_lo, n_hi] = narrow.at(px, py).map(|b| b as f64);
                    let [w_lo, w_hi] = whole.at(px, py).map(|b| b as f64);
                    narrower += (n_lo > w_lo || n_hi < w_hi) as usize;
                    let (o, d) = primary_ray(u, px, py);
                    let o = (o.as_dvec3() - origin) * inv;
                    let d = d.as_dvec3() * inv;
                    for i in &shown {
                        let lo = DVec3::from_array(i.map(|i| i as f64));
                        let Some((t0, t1)) = chord(o, d, lo, lo + 1.0) else {
                            continue;
                        };
                        chords += 1;
                        assert!(
                            n_lo <= t0 && t1 <= n_hi,
                            "cell {i:?} {cam:?} pixel {px},{py}: chord {t0}..{t1} outside {n_lo}..={n_hi}"
                        );
                    }
                }
            }
        }
        assert!(
            chords > 100 && narrower > 100,
            "{chords} chords, {narrower} narrower pixels"
        );
    }
}
