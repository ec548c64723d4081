//! [`point_slabs`]: per-point GPU arrays (a few bytes per point) bound in
//! windows when one array is larger than one storage binding — a 512³
//! volume's vertices need 512 MiB per displacement axis, and many devices
//! bind at most 128 MiB. Shared by the point fields (`affine`, `template`:
//! [`PointFieldDispatch`] runs their kernels slab by slab) and the mesh
//! models' barycentric map.

use crate::error::GpuError;
use crate::gpu::{BufferBinding, BufferId, GpuLimits, GpuService, GpuServiceExt, PipelineId};
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

/// A point field's kernel and the arrays it reads and writes, by
/// `@binding` number: a constants buffer rewritten per slab, the rest
/// points' x, y, z arrays (f32, one per point; absent for a lattice the
/// kernel enumerates itself), and the x, y, z displacement arrays (f32,
/// one per point). The kernel covers the slab of points whose first point
/// and count its constants give, and indexes every per-point array from
/// that first point (each is bound as a window starting there).
#[derive(Clone, Copy, Debug)]
pub struct PointFieldDispatch {
    /// The compiled kernel.
    pub pipeline: PipelineId,
    /// Invocations per workgroup (one point each).
    pub workgroup: u32,
    /// `(@binding, buffer)` of the constants.
    pub constants: (u32, BufferId),
    /// `@binding`s of the rest points' x, y, z arrays, and the arrays
    /// (`None`: a lattice; `spare` is bound there instead).
    pub points: ([u32; 3], Option<[BufferId; 3]>),
    /// A buffer of at least 4 bytes, bound where there are no point arrays.
    pub spare: BufferId,
    /// `@binding`s of the displacement arrays x, y, z, and the arrays.
    pub out: ([u32; 3], [BufferId; 3]),
}

impl PointFieldDispatch {
    /// Runs the kernel over points `0 .. n` ([`point_slabs`]: one dispatch
    /// when every array fits one storage binding, else one per slab, each
    /// binding a window of every per-point array at an aligned offset),
    /// writing `constants(slab)`'s bytes into the constants buffer before
    /// each dispatch (calls are ordered: each dispatch sees its own). Fails
    /// when a displacement array holds fewer than `n` values or not even an
    /// aligned run of points fits a binding.
    pub fn run(
        &self,
        gpu: &dyn GpuService,
        n: usize,
        mut constants: impl FnMut(Range<usize>) -> Vec<u8>,
    ) -> Result<(), GpuError> {
        for (axis, &buffer) in ["x", "y", "z"].iter().zip(&self.out.1) {
            let bytes = gpu.buffer_size(buffer)?;
            if bytes < n as u64 * 4 {
                return Err(GpuError(format!(
                    "the {axis} displacement buffer holds {} values but the binding has {n} points",
                    bytes / 4
                )));
            }
        }
        let limits = gpu.limits();
        let slabs = point_slabs(n, 4, alignment_unit(&limits, 4), &limits).ok_or_else(|| {
            GpuError(format!(
                "this GPU binds at most {} bytes per storage array, less than one aligned run \
                 of points; use backend = \"cpu\"",
                limits.max_storage_buffer_binding_size
            ))
        })?;
        for slab in slabs {
            gpu.write_buffer(self.constants.1, 0, &constants(slab.clone()))?;
            let window = |binding: u32, buffer: BufferId| BufferBinding {
                binding,
                buffer,
                offset: slab.start as u64 * 4,
                size: slab.len() as u64 * 4,
            };
            let point = |a: usize| match self.points.1 {
                Some(ids) => window(self.points.0[a], ids[a]),
                None => BufferBinding::whole(self.points.0[a], self.spare),
            };
            let bindings = [
                BufferBinding::whole(self.constants.0, self.constants.1),
                point(0),
                point(1),
                point(2),
                window(self.out.0[0], self.out.1[0]),
                window(self.out.0[1], self.out.1[1]),
                window(self.out.0[2], self.out.1[2]),
            ];
            let groups = gpu.workgroups_for(slab.len() as u64, self.workgroup)?;
            gpu.dispatch(self.pipeline, &bindings, groups)?;
        }
        Ok(())
    }
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
