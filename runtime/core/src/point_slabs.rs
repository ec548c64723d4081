//! [`point_slabs`]: per-point GPU arrays (a few bytes per point) bound in
//! windows when one array is larger than one storage binding — a 512³
//! volume's vertices need 512 MiB per displacement axis, and many devices
//! bind at most 128 MiB. Shared by the point fields (`affine`, `template`)
//! and the mesh models' barycentric map; pure arithmetic (no device).

use crate::gpu::GpuLimits;
use std::ops::Range;

/// The points whose window of `bytes_per_point` bytes per point starts on
/// the device's storage offset alignment: a slab starting at a multiple of
/// this many points binds every per-point array of at least
/// `bytes_per_point` bytes per point at an aligned offset.
pub fn alignment_unit(limits: &GpuLimits, bytes_per_point: u64) -> usize {
    let align = u64::from(limits.min_storage_buffer_offset_alignment).max(4);
    (align / bytes_per_point.max(1)).max(1) as usize
}

/// The consecutive ranges of points covering `0 .. points` such that each
/// range's window of an array of `bytes_per_point` bytes per point fits
/// one storage binding of `limits`, every range but the first starting at
/// a multiple of `unit` points (≥ 1; see [`alignment_unit`]). One range
/// when everything fits, none when `points` is 0; `None` when not even
/// `unit` points fit a binding.
pub fn point_slabs(
    points: usize,
    bytes_per_point: u64,
    unit: usize,
    limits: &GpuLimits,
) -> Option<Vec<Range<usize>>> {
    let unit = unit.max(1);
    let fit = limits.max_storage_buffer_binding_size / bytes_per_point.max(1);
    let per = (fit / unit as u64).saturating_mul(unit as u64);
    if per == 0 {
        return None;
    }
    let per = usize::try_from(per).unwrap_or(usize::MAX);
    Some(
        (0..points.div_ceil(per))
            .map(|s| s * per..((s + 1) * per).min(points))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(binding: u64, align: u32) -> GpuLimits {
        GpuLimits {
            max_storage_buffer_binding_size: binding,
            max_buffer_size: u64::MAX,
            max_compute_workgroups_per_dimension: 65_535,
            min_storage_buffer_offset_alignment: align,
        }
    }

    /// The slabs cover every point once, in order; each window fits the
    /// binding and starts on the alignment; one slab when it all fits.
    #[test]
    fn slabs_cover_the_points_within_the_binding_on_the_alignment() {
        for (points, bpp, binding, align) in [
            (11_220, 4, 4096, 256),
            (11_221, 4, 4096, 64),
            (1000, 4, 1 << 27, 256),
            (5, 2, 256, 256),
            (0, 4, 4096, 256),
        ] {
            let l = limits(binding, align);
            let unit = alignment_unit(&l, bpp);
            let slabs = point_slabs(points, bpp, unit, &l).unwrap();
            let mut next = 0;
            for r in &slabs {
                assert_eq!(r.start, next, "{points} points: contiguous");
                assert!(r.end > r.start, "{points} points: no empty slab");
                assert!((r.len() as u64) * bpp <= binding, "{r:?} fits");
                assert_eq!(
                    (r.start as u64 * bpp) % u64::from(align),
                    0,
                    "{r:?} aligned"
                );
                next = r.end;
            }
            assert_eq!(next, points);
            if points as u64 * bpp <= binding {
                assert!(slabs.len() <= 1, "{points} points fit one binding");
            }
        }
    }

    /// A binding smaller than one aligned unit of points cannot be split.
    #[test]
    fn a_binding_below_one_unit_is_refused() {
        let l = limits(128, 256);
        assert_eq!(alignment_unit(&l, 4), 64);
        assert_eq!(point_slabs(1000, 4, 64, &l), None);
    }
}
