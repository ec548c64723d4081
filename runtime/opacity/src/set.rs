//! Several opacity maps at once: [`OpacityMapSet`] and [`combine_max`].

use super::OpacityError;
use super::cpu::CpuGrowth;
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::Seed;
use crate::opacity_map::OpacityMap;
use crate::volume::VolumeView;
use rayon::prelude::*;

/// Independent region growings in one volume (one map per seed), grown
/// together on the CPU. The renderer combines them by maximum
/// ([`combine_max`]).
#[derive(Debug, Default)]
pub struct OpacityMapSet {
    growths: Vec<CpuGrowth>,
}

impl OpacityMapSet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Seeds one more map; returns its index.
    pub fn add(
        &mut self,
        volume: VolumeView<'_>,
        seed: &Seed,
        params: GrowthParams,
    ) -> Result<usize, OpacityError> {
        self.growths.push(CpuGrowth::new(volume, seed, params)?);
        Ok(self.growths.len() - 1)
    }

    /// Removes map `i` (later indices shift down); `None` if there is none.
    pub fn remove(&mut self, i: usize) -> Option<CpuGrowth> {
        (i < self.growths.len()).then(|| self.growths.remove(i))
    }

    /// The growths.
    pub fn growths(&self) -> &[CpuGrowth] {
        &self.growths
    }

    /// Number of maps.
    pub fn len(&self) -> usize {
        self.growths.len()
    }

    /// True when the set holds no map.
    pub fn is_empty(&self) -> bool {
        self.growths.is_empty()
    }

    /// Runs up to `n` steps of every map (in parallel); the report sums them
    /// (`steps` is the largest count, `converged` true when all are).
    pub fn step_all(
        &mut self,
        volume: VolumeView<'_>,
        n: usize,
    ) -> Result<GrowthReport, OpacityError> {
        let reps: Vec<Result<GrowthReport, OpacityError>> = self
            .growths
            .par_iter_mut()
            .map(|g| g.step(volume, n))
            .collect();
        let mut total = GrowthReport {
            converged: true,
            ..Default::default()
        };
        for r in reps {
            let r = r?;
            total.steps = total.steps.max(r.steps);
            total.visits += r.visits;
            total.useful += r.useful;
            total.regrows += r.regrows;
            total.converged &= r.converged;
        }
        Ok(total)
    }

    /// Runs every map to convergence.
    pub fn run_all(&mut self, volume: VolumeView<'_>) -> Result<GrowthReport, OpacityError> {
        self.step_all(volume, usize::MAX)
    }

    /// Every map, in index order.
    pub fn maps(&self) -> Vec<OpacityMap> {
        self.growths.iter().map(CpuGrowth::map).collect()
    }

    /// All maps combined by maximum; `None` for an empty set.
    pub fn combined(&self) -> Option<OpacityMap> {
        combine_max(&self.maps())
    }
}

/// The voxel-wise maximum of several maps of one volume, over the union of
/// their boxes (`outside` the largest `outside`); `None` for no map. Maps
/// whose `values` do not match their `dims` are ignored.
pub fn combine_max(maps: &[OpacityMap]) -> Option<OpacityMap> {
    let maps: Vec<&OpacityMap> = maps
        .iter()
        .filter(|m| m.values.len() == m.dims.iter().product::<usize>() && !m.values.is_empty())
        .collect();
    let first = maps.first()?;
    let mut lo = first.origin;
    let mut hi = [0, 1, 2].map(|a| first.origin[a] + first.dims[a]);
    for m in &maps {
        for a in 0..3 {
            lo[a] = lo[a].min(m.origin[a]);
            hi[a] = hi[a].max(m.origin[a] + m.dims[a]);
        }
    }
    let dims = [0, 1, 2].map(|a| hi[a] - lo[a]);
    let outside = maps.iter().map(|m| m.outside).max().unwrap_or(0);
    let mut values = vec![outside; dims.iter().product()];
    for m in &maps {
        let [mx, my, mz] = m.dims;
        for z in 0..mz {
            for y in 0..my {
                let dst = (m.origin[0] - lo[0])
                    + dims[0] * ((m.origin[1] + y - lo[1]) + dims[1] * (m.origin[2] + z - lo[2]));
                let src = mx * (y + my * z);
                for (o, &v) in values[dst..dst + mx]
                    .iter_mut()
                    .zip(&m.values[src..src + mx])
                {
                    *o = (*o).max(v);
                }
            }
        }
    }
    Some(OpacityMap {
        origin: lo,
        dims,
        outside,
        values,
    })
}
