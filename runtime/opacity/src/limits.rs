//! [`GrowthLimits`]: bounds that stop a growth whatever λ says — an
//! intensity window and a maximum distance from the seed.
//!
//! **How they act.** A voxel outside the window `intensity = [lo, hi]`
//! (value units, inclusive), or whose centre lies farther than
//! `max_distance_mm` from the seed voxel's centre (**Euclidean**, world
//! mm, `|Δindex · spacing|`), is *blocked*: its value is replaced by
//! [`SANE_MAX`] before the growth reads it ([`GrowthLimits::apply`]). The
//! extinction caps `|d_s − d_v|` at `(λ + 2) σ_s`, so a blocked voxel has
//! `e_v ≥ 65535 (1 + 1/λ)` — more than the whole opacity range: it never
//! rises above `o_min` and opacity never passes through it. Because the
//! bound lives in the values, the CPU (rayon) and the WGSL kernels apply it
//! with no change to either: both read the same blocked values, so their
//! maps stay bit-identical (`parity::check_limits_match_cpu`). The cost is a
//! full f32 copy of the volume (4 bytes per voxel) while a bounded map
//! grows.
//!
//! The seed's statistics (`d_s`, σ_s) are measured on the **unbounded**
//! volume. A seed whose own value lies outside the window is refused.

use super::OpacityError;
use super::extinction::{Extinction, SANE_MAX, sanitize};
use crate::opacity_map::OpacityMap;
use crate::volume::{Volume, VolumeView, VoxelData};

/// Bounds on a growth (both optional; the default bounds nothing).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GrowthLimits {
    /// `[lo, hi]`, value units (HU for CT), inclusive: voxels outside never
    /// rise above `o_min`. Scene key `intensity`.
    pub intensity: Option<[f32; 2]>,
    /// Largest Euclidean distance (world mm) from the seed voxel's centre
    /// to a voxel centre the growth may raise. Scene key `max_distance_mm`.
    pub max_distance_mm: Option<f64>,
}

/// Which bound blocks a voxel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// Outside the intensity window.
    Intensity,
    /// Beyond `max_distance_mm`.
    Distance,
}

/// Counts of voxels where a bound stopped the growth: blocked voxels next
/// to a raised voxel (above `o_min`) that the unbounded rule would have
/// lifted above `o_min` from it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LimitHits {
    /// Stopped by the intensity window.
    pub intensity: usize,
    /// Stopped by `max_distance_mm`.
    pub distance: usize,
}

impl LimitHits {
    /// True when some bound stopped the growth somewhere.
    pub fn any(&self) -> bool {
        self.intensity + self.distance > 0
    }
}

impl GrowthLimits {
    /// True when nothing is bounded.
    pub fn is_none(&self) -> bool {
        self.intensity.is_none() && self.max_distance_mm.is_none()
    }

    /// Checks the keys; the error names the key and the value.
    pub fn validate(&self) -> Result<(), OpacityError> {
        if let Some([lo, hi]) = self.intensity
            && !(lo.is_finite() && hi.is_finite() && lo <= hi)
        {
            return Err(OpacityError::BadIntensityWindow { lo, hi });
        }
        if let Some(d) = self.max_distance_mm
            && !(d.is_finite() && d > 0.0)
        {
            return Err(OpacityError::BadMaxDistance { max_distance_mm: d });
        }
        Ok(())
    }

    /// Which bound, if any, blocks voxel `v` (voxel index) of value `value`
    /// for a growth seeded at `seed` on a grid of `spacing` (mm).
    #[inline]
    pub fn blocks(
        &self,
        value: f32,
        v: [usize; 3],
        seed: [usize; 3],
        spacing: [f64; 3],
    ) -> Option<Limit> {
        if let Some([lo, hi]) = self.intensity
            && !(value >= lo && value <= hi)
        {
            return Some(Limit::Intensity);
        }
        if let Some(d) = self.max_distance_mm {
            let r2: f64 = (0..3)
                .map(|a| ((v[a] as f64 - seed[a] as f64) * spacing[a]).powi(2))
                .sum();
            if r2 > d * d {
                return Some(Limit::Distance);
            }
        }
        None
    }

    /// The values a bounded growth seeded at voxel `seed` reads: the
    /// volume as sanitised f32 with every blocked voxel at [`SANE_MAX`];
    /// `None` when nothing is bounded (grow on the volume itself). Fails
    /// when a key is invalid or the seed itself is outside the window.
    pub fn apply(
        &self,
        volume: VolumeView<'_>,
        seed: [usize; 3],
    ) -> Result<Option<Volume>, OpacityError> {
        self.validate()?;
        if self.is_none() {
            return Ok(None);
        }
        let g = volume.grid;
        let sv = volume.data.get_f32(g.linear(seed[0], seed[1], seed[2]));
        if let Some([lo, hi]) = self.intensity
            && self.blocks(sv, seed, seed, [0.0; 3]) == Some(Limit::Intensity)
        {
            return Err(OpacityError::SeedOutsideWindow {
                voxel: seed,
                value: sv,
                lo,
                hi,
            });
        }
        let sp = g.spacing.to_array();
        let mut values = volume.data.to_f32_vec();
        use rayon::prelude::*;
        let plane = (g.dims[0] * g.dims[1]).max(1);
        values
            .par_chunks_mut(plane)
            .enumerate()
            .for_each(|(k, slab)| {
                for (o, x) in slab.iter_mut().enumerate() {
                    let v = [o % g.dims[0], o / g.dims[0], k];
                    *x = if self.blocks(*x, v, seed, sp).is_some() {
                        SANE_MAX
                    } else {
                        sanitize(*x)
                    };
                }
            });
        Ok(Some(Volume {
            grid: g,
            data: VoxelData::F32(values),
        }))
    }

    /// Where the bounds stopped a grown `map` (seeded at `seed` on
    /// `volume`, the unbounded values, with extinction `ext`): see
    /// [`LimitHits`]. Scans the map's box grown by one voxel.
    pub fn hits(
        &self,
        volume: VolumeView<'_>,
        map: &OpacityMap,
        seed: [usize; 3],
        ext: &Extinction,
    ) -> LimitHits {
        let mut hits = LimitHits::default();
        if self.is_none() {
            return hits;
        }
        let g = volume.grid;
        let sp = g.spacing.to_array();
        let lo = map.origin.map(|o| o.saturating_sub(1));
        let hi = [0, 1, 2].map(|a| (map.origin[a] + map.dims[a]).min(g.dims[a] - 1));
        let q = |v: [usize; 3]| -> u16 {
            let inside =
                (0..3).all(|a| v[a] >= map.origin[a] && v[a] < map.origin[a] + map.dims[a]);
            if inside {
                let l = (v[0] - map.origin[0])
                    + map.dims[0] * ((v[1] - map.origin[1]) + map.dims[1] * (v[2] - map.origin[2]));
                map.values[l]
            } else {
                ext.q_min
            }
        };
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    let v = [i, j, k];
                    let x = volume.data.get_f32(g.linear(i, j, k));
                    let Some(limit) = self.blocks(x, v, seed, sp) else {
                        continue;
                    };
                    let e = ext.fixed(x);
                    let mut best = ext.q_min;
                    for dz in -1isize..=1 {
                        for dy in -1isize..=1 {
                            for dx in -1isize..=1 {
                                let n = [i as isize + dx, j as isize + dy, k as isize + dz];
                                if n.iter()
                                    .zip(g.dims)
                                    .all(|(&c, d)| c >= 0 && (c as usize) < d)
                                {
                                    best = best.max(q(n.map(|c| c as usize)));
                                }
                            }
                        }
                    }
                    if best > ext.q_min && ext.rise(best, e) > ext.q_min {
                        match limit {
                            Limit::Intensity => hits.intensity += 1,
                            Limit::Distance => hits.distance += 1,
                        }
                    }
                }
            }
        }
        hits
    }
}
