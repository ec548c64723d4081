//! Non-finite voxels (NaN, ±∞ in f32 volumes) and what loading does with
//! them.
//!
//! **Policy.** A source volume's non-finite voxels are counted when it is
//! loaded (`voxflex_io::read_volume`); under the default
//! [`NonFinitePolicy::Replace`] a warning gives the counts and they are
//! replaced — NaN by the background (the scene's `[resample] background`,
//! else the smallest finite value), +∞ by the largest and −∞ by the
//! smallest finite value — so nothing downstream (resampling, windows,
//! transfer functions, the written NIfTI) ever sees one. Under
//! [`NonFinitePolicy::Refuse`] (`[volume] non_finite = "refuse"`) the load
//! fails with the counts instead. A volume with no finite voxel at all is
//! refused under either policy: there is nothing to replace with.
//! Integer volumes cannot hold non-finite values and are left untouched.

use crate::volume::VoxelData;
use rayon::prelude::*;
use serde::Deserialize;

/// What loading does with NaN and ±∞ voxels.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum NonFinitePolicy {
    /// Warn with the counts and replace them (NaN → background, ±∞ → the
    /// finite range's ends).
    #[default]
    Replace,
    /// Fail with the counts.
    Refuse,
}

/// Non-finite voxels of a volume, and its finite value range.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NonFiniteCount {
    /// NaN voxels.
    pub nan: usize,
    /// +∞ voxels.
    pub pos_inf: usize,
    /// −∞ voxels.
    pub neg_inf: usize,
    /// Smallest and largest finite value (volume units); `None` when no
    /// voxel is finite.
    pub finite_range: Option<(f32, f32)>,
}

impl NonFiniteCount {
    /// Counts the non-finite voxels of `data` (always zero for integer
    /// types) and finds its finite range.
    pub fn of(data: &VoxelData) -> Self {
        let VoxelData::F32(v) = data else {
            let range = crate::volume::finite_range(data.as_slice());
            return Self {
                finite_range: range,
                ..Self::default()
            };
        };
        let zero = || (0usize, 0usize, 0usize, f32::INFINITY, f32::NEG_INFINITY);
        let (nan, pos_inf, neg_inf, lo, hi) = v
            .par_chunks(1 << 16)
            .map(|c| {
                c.iter().fold(zero(), |(n, p, m, lo, hi), &x| {
                    if x.is_finite() {
                        (n, p, m, lo.min(x), hi.max(x))
                    } else if x.is_nan() {
                        (n + 1, p, m, lo, hi)
                    } else if x > 0.0 {
                        (n, p + 1, m, lo, hi)
                    } else {
                        (n, p, m + 1, lo, hi)
                    }
                })
            })
            .reduce(zero, |a, b| {
                (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3.min(b.3), a.4.max(b.4))
            });
        Self {
            nan,
            pos_inf,
            neg_inf,
            finite_range: (lo <= hi).then_some((lo, hi)),
        }
    }

    /// All non-finite voxels.
    pub fn total(&self) -> usize {
        self.nan + self.pos_inf + self.neg_inf
    }

    /// "3 NaN, 1 +inf, 0 −inf voxels".
    pub fn describe(&self) -> String {
        format!(
            "{} NaN, {} +inf and {} -inf voxels",
            self.nan, self.pos_inf, self.neg_inf
        )
    }
}

/// Applies `policy` to `data` in place: returns what was found, or an
/// error message (naming the counts and the scene key) when the policy
/// refuses them or no voxel is finite. `nan_to` replaces NaN (default: the
/// smallest finite value); it must be finite.
pub fn apply_policy(
    data: &mut VoxelData,
    policy: NonFinitePolicy,
    nan_to: Option<f32>,
) -> Result<NonFiniteCount, String> {
    let count = NonFiniteCount::of(data);
    if count.total() == 0 {
        return Ok(count);
    }
    let Some((lo, hi)) = count.finite_range else {
        return Err(format!(
            "every voxel is non-finite ({}): the volume holds no value",
            count.describe()
        ));
    };
    if policy == NonFinitePolicy::Refuse {
        return Err(format!(
            "holds {} and `[volume] non_finite = \"refuse\"`; fix the file, or remove the key \
             to replace them (NaN → background, ±inf → the finite range's ends)",
            count.describe()
        ));
    }
    let nan = nan_to.filter(|v| v.is_finite()).unwrap_or(lo);
    if let VoxelData::F32(v) = data {
        v.par_iter_mut().for_each(|x| {
            if x.is_nan() {
                *x = nan;
            } else if *x == f32::INFINITY {
                *x = hi;
            } else if *x == f32::NEG_INFINITY {
                *x = lo;
            }
        });
    }
    Ok(count)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data() -> VoxelData {
        VoxelData::F32(vec![
            1.0,
            f32::NAN,
            -2.0,
            f32::INFINITY,
            5.0,
            f32::NEG_INFINITY,
            f32::NAN,
        ])
    }

    #[test]
    fn replace_counts_and_maps_each_kind_to_its_value() {
        let mut d = data();
        let c = apply_policy(&mut d, NonFinitePolicy::Replace, None).unwrap();
        assert_eq!((c.nan, c.pos_inf, c.neg_inf), (2, 1, 1));
        assert_eq!(c.finite_range, Some((-2.0, 5.0)));
        assert_eq!(
            d,
            VoxelData::F32(vec![1.0, -2.0, -2.0, 5.0, 5.0, -2.0, -2.0]),
            "NaN → min, +inf → max, -inf → min"
        );
        let mut d = data();
        apply_policy(&mut d, NonFinitePolicy::Replace, Some(-1000.0)).unwrap();
        assert_eq!(
            d,
            VoxelData::F32(vec![1.0, -1000.0, -2.0, 5.0, 5.0, -2.0, -1000.0]),
            "NaN → the given background"
        );
    }

    #[test]
    fn refuse_names_the_counts_and_the_key_and_leaves_the_data() {
        let mut d = data();
        let e = apply_policy(&mut d, NonFinitePolicy::Refuse, None).unwrap_err();
        assert!(
            e.contains("2 NaN, 1 +inf and 1 -inf") && e.contains("non_finite"),
            "{e}"
        );
        let mut all_bad = VoxelData::F32(vec![f32::NAN; 3]);
        let e = apply_policy(&mut all_bad, NonFinitePolicy::Replace, None).unwrap_err();
        assert!(e.contains("every voxel"), "{e}");
    }

    #[test]
    fn finite_and_integer_volumes_are_untouched() {
        let mut d = VoxelData::F32(vec![1.0, 2.0]);
        let c = apply_policy(&mut d, NonFinitePolicy::Refuse, None).unwrap();
        assert_eq!((c.total(), c.finite_range), (0, Some((1.0, 2.0))));
        let mut i = VoxelData::I16(vec![-5, 7]);
        let c = apply_policy(&mut i, NonFinitePolicy::Refuse, None).unwrap();
        assert_eq!((c.total(), c.finite_range), (0, Some((-5.0, 7.0))));
    }
}
