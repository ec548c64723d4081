//! The resampler's error against an f64 reference, for the benchmark
//! (`voxflex bench --accuracy`) and the tests.
//!
//! The reference of an output voxel at world point `X` (mm) is the
//! trilinear sample, in f64, of the source at the **exact** preimage
//! `inverse(X)` of the analytic field — what an ITK-style resampler computes
//! with the exact backward map. Only output voxels whose preimage lies at
//! least [`INTERIOR_MARGIN`] source voxels inside the source box are
//! compared, so the mesh's piecewise-linear outline (which the curved
//! analytic outline does not follow exactly) never decides a voxel.

use super::ResampleOutput;
use crate::fields::{Field, affine, bend_zx, twist_z};
use crate::grid::Grid;
use crate::volume::Volume;
use glam::DVec3;
use voxflex_core::ordered_reduce::ordered_reduce;

/// Output voxels per partial sum of [`errors`].
const ERROR_CHUNK: usize = 1 << 14;

/// Compared voxels lie this many source voxels inside the source box.
pub const INTERIOR_MARGIN: f64 = 1.0;

/// Absolute error of a resampled volume against the f64 reference, in the
/// volume's units (HU for CT).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    /// Output voxels compared.
    pub compared: usize,
    /// Mean absolute error.
    pub mean_abs: f64,
    /// Largest absolute error.
    pub max_abs: f64,
    /// Output voxels compared that hold a non-finite value (holes).
    pub non_finite: usize,
}

/// An analytic deformation (world mm → world mm) with its exact inverse.
pub struct AnalyticField {
    /// Short name (`affine`, `twist`, `bend`).
    pub name: &'static str,
    /// What it does, for reports.
    pub description: String,
    /// Rest point → deformed point (mm).
    pub map: Box<dyn Fn(DVec3) -> DVec3 + Sync + Send>,
    /// Deformed point → rest point (mm).
    pub inverse: Box<dyn Fn(DVec3) -> DVec3 + Sync + Send>,
}

impl AnalyticField {
    /// The displacement field (mm) of [`Self::map`] on `grid`'s voxel centres.
    pub fn field(&self, grid: &Grid) -> Field {
        Field::from_map(grid, &self.map)
    }
}

/// The benchmark's three fields on `grid`, each about its centre: an affine
/// map (10° about (0.2, 0.3, 1), ×1.05, translated by (2.3, −1.7, 0.9) mm),
/// a 40° twist about z over the z extent (as `voxflex bench`), and a 40°
/// bend of z towards x over the z extent (Barr, as the `affine` plugin's
/// `field = "bend"`).
pub fn bench_fields(grid: &Grid) -> Vec<AnalyticField> {
    let c = grid.centre();
    let (lo, hi) = grid.world_bounds();
    let len_z = (hi.z - lo.z).max(f64::MIN_POSITIVE);
    let rate = 40f64.to_radians() / len_z;
    let (am, ai) = affine(
        c,
        DVec3::new(0.2, 0.3, 1.0),
        10.0,
        1.05,
        DVec3::new(2.3, -1.7, 0.9),
    );
    let (tm, ti) = twist_z(c, rate);
    let (bm, bi) = bend_zx(c, rate);
    vec![
        AnalyticField {
            name: "affine",
            description: "10° rotation, ×1.05, 3 mm translation".into(),
            map: Box::new(am),
            inverse: Box::new(ai),
        },
        AnalyticField {
            name: "twist",
            description: "40° twist about z".into(),
            map: Box::new(tm),
            inverse: Box::new(ti),
        },
        AnalyticField {
            name: "bend",
            description: "40° bend of z towards x".into(),
            map: Box::new(bm),
            inverse: Box::new(bi),
        },
    ]
}

/// Trilinear sample (f64) of `volume` at `index` (source voxel index
/// units), clamped to the grid faces.
pub fn trilinear_f64(volume: &Volume, index: DVec3) -> f64 {
    let d = volume.grid.dims;
    let mut i0 = [0usize; 3];
    let mut i1 = [0usize; 3];
    let mut f = [0f64; 3];
    for a in 0..3 {
        let last = d[a] as f64 - 1.0;
        let x = index[a].clamp(0.0, last);
        let lo = x.floor();
        i0[a] = lo as usize;
        i1[a] = (i0[a] + 1).min(d[a] - 1);
        f[a] = x - lo;
    }
    let mut v = 0.0;
    for c in 0..8 {
        let pick = [c & 1, (c >> 1) & 1, c >> 2];
        let mut w = 1.0;
        let mut at = [0usize; 3];
        for a in 0..3 {
            w *= if pick[a] == 1 { f[a] } else { 1.0 - f[a] };
            at[a] = if pick[a] == 1 { i1[a] } else { i0[a] };
        }
        if w != 0.0 {
            v += w * volume.get_f32(at[0], at[1], at[2]) as f64;
        }
    }
    v
}

/// The error of `out` (a resample of `source` under the field whose exact
/// inverse is `inverse`) against the f64 reference (see the module docs).
pub fn errors(
    source: &Volume,
    out: &ResampleOutput,
    inverse: &(dyn Fn(DVec3) -> DVec3 + Sync),
) -> ErrorStats {
    let g = source.grid;
    let hi = DVec3::new(
        g.dims[0] as f64 - 1.0,
        g.dims[1] as f64 - 1.0,
        g.dims[2] as f64 - 1.0,
    ) - INTERIOR_MARGIN;
    // One voxel's share: (compared, |error|, |error|, non-finite).
    let voxel = |l: usize| -> (usize, f64, f64, usize) {
        let [i, j, k] = out.grid.unlinear(l);
        let w = out
            .grid
            .index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        let r = g.world_to_index(inverse(w));
        if r.cmplt(DVec3::splat(INTERIOR_MARGIN)).any() || r.cmpgt(hi).any() {
            return (0, 0.0, 0.0, 0);
        }
        let v = out.values[l];
        if !v.is_finite() {
            return (1, 0.0, 0.0, 1);
        }
        let e = (v as f64 - trilinear_f64(source, r)).abs();
        (1, e, e, 0)
    };
    let add = |a: (usize, f64, f64, usize), b: (usize, f64, f64, usize)| {
        (a.0 + b.0, a.1 + b.1, a.2.max(b.2), a.3 + b.3)
    };
    // Summed in a fixed order (`ordered_reduce`), so the mean error is the
    // same bits on any thread count.
    let (compared, sum, max, non_finite) = ordered_reduce(
        out.values.len(),
        ERROR_CHUNK,
        true,
        |r| r.map(voxel).fold((0, 0.0, 0.0, 0), add),
        (0, 0.0, 0.0, 0),
        add,
    );
    ErrorStats {
        compared,
        mean_abs: sum / compared.saturating_sub(non_finite).max(1) as f64,
        max_abs: max,
        non_finite,
    }
}

#[cfg(test)]
mod tests {
    use super::super::parity::head_i16;
    use super::super::{Interpolation, ResampleParams, Resampler};
    use super::*;
    use crate::deformation::DirtyRegion;

    #[test]
    fn inverses_invert() {
        let grid = Grid::new([30, 20, 40], DVec3::new(1.0, 1.2, 0.8), DVec3::ZERO);
        for f in bench_fields(&grid) {
            for l in (0..grid.len()).step_by(97) {
                let [i, j, k] = grid.unlinear(l);
                let p = grid.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
                let back = (f.inverse)((f.map)(p));
                assert!((back - p).length() < 1e-9, "{}: {p} → {back}", f.name);
            }
        }
    }

    #[test]
    fn reference_interpolates_and_clamps() {
        let grid = Grid::new([4, 3, 3], DVec3::ONE, DVec3::ZERO);
        let vol = super::super::parity::ramp(&grid, DVec3::new(1.0, 10.0, 100.0));
        assert_eq!(trilinear_f64(&vol, DVec3::new(1.25, 0.5, 1.75)), 181.25);
        // Clamped at the faces: the nearest face value.
        assert_eq!(trilinear_f64(&vol, DVec3::new(-3.0, 2.0, 9.0)), 220.0);
    }

    /// The identity field has zero error in both modes; a twist of the head
    /// has a smaller error in trilinear mode than in tetrahedral mode.
    #[test]
    fn trilinear_mode_is_closer_to_the_reference() {
        let grid = Grid::new([40, 40, 36], DVec3::ONE, DVec3::splat(-20.0));
        let vol = head_i16(&grid);
        let fields = bench_fields(&grid);
        let mut means = vec![];
        for interpolation in Interpolation::ALL {
            let mut r = Resampler::new(ResampleParams {
                background: f32::NAN,
                interpolation,
                ..Default::default()
            });
            let zero = Field::zero(&grid);
            r.resample_cpu(vol.view(), zero.as_ref(), None, DirtyRegion::All)
                .unwrap();
            let e = errors(&vol, &r.cpu_output().unwrap(), &|p| p);
            assert_eq!((e.max_abs, e.non_finite), (0.0, 0), "{interpolation}");
            assert!(e.compared > grid.len() / 2);
            let f = fields[1].field(&grid);
            r.resample_cpu(vol.view(), f.as_ref(), None, DirtyRegion::All)
                .unwrap();
            let e = errors(&vol, &r.cpu_output().unwrap(), &fields[1].inverse);
            assert_eq!(e.non_finite, 0);
            means.push(e.mean_abs);
        }
        assert!(means[1] * 5.0 < means[0], "{means:?}");
    }
}
