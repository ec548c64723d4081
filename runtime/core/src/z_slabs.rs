//! [`z_slabs`]: splitting a z-stacked f32 array that is larger than one GPU
//! storage binding into z-slabs, each bound as one aligned window. Shared
//! by the resampler's source slabs and the ray caster's volume slabs; pure
//! arithmetic (no device).
//!
//! A slab *owns* the planes `[z0, z1)` — the footprint (ray caster) or
//! cell (resampler) planes whose work it does, in whole groups of `unit`
//! planes (a macro-cell, a cell block) — and binds the voxel planes
//! `v0 = z0 − 1 … v1 = z1 + 1` (clamped to the array), one below and two
//! above, which is what a trilinear, tricubic or Sobel tap of an owned
//! plane reads. The window starts at `v0`'s first byte aligned down to the
//! device's storage offset alignment.

/// One z-slab (indices are z-planes of the array; bytes of the bound window).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ZSlab {
    /// First plane this slab owns.
    pub z0: usize,
    /// One past its last owned plane.
    pub z1: usize,
    /// First plane of the bound window.
    pub v0: usize,
    /// Last plane of the bound window (inclusive).
    pub v1: usize,
    /// Byte offset of the bound window (aligned).
    pub offset: u64,
    /// Bytes bound.
    pub bytes: u64,
}

/// Planes a slab binds beyond the ones it owns: one below, two above.
pub const HALO_PLANES: u64 = 3;

/// The z-slabs of an array of `dims` f32 values (x fastest) whose owned
/// planes are `0 .. owned`, in whole groups of `unit` planes: one slab
/// binding everything when the array fits `max_binding` bytes, else as
/// many as it takes for each window to fit. `None` when not even one group
/// and its halo fit (the caller says what to do in its own terms: one
/// group needs `(unit + HALO_PLANES) · plane + align` bytes).
pub fn z_slabs(
    dims: [usize; 3],
    owned: usize,
    unit: usize,
    max_binding: u64,
    align: u64,
) -> Option<Vec<ZSlab>> {
    let plane = (dims[0] * dims[1]) as u64 * 4;
    let total = plane * dims[2] as u64;
    let last = dims[2].saturating_sub(1);
    if total <= max_binding {
        return Some(vec![ZSlab {
            z0: 0,
            z1: owned,
            v0: 0,
            v1: last,
            offset: 0,
            bytes: total,
        }]);
    }
    let align = align.max(4);
    let unit = unit.max(1);
    let fit = (max_binding.saturating_sub(align) / plane.max(1)).saturating_sub(HALO_PLANES);
    let k = fit as usize / unit * unit;
    if k == 0 {
        return None;
    }
    let mut out = Vec::new();
    let mut z0 = 0;
    while z0 < owned {
        let z1 = (z0 + k).min(owned);
        let v0 = z0.saturating_sub(1);
        let v1 = (z1 + 1).min(last);
        let offset = v0 as u64 * plane / align * align;
        out.push(ZSlab {
            z0,
            z1,
            v0,
            v1,
            offset,
            bytes: (v1 as u64 + 1) * plane - offset,
        });
        z0 = z1;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every slab owns whole units, the slabs tile the owned planes, and
    /// each window holds its halo within the binding — on the ray caster's
    /// cases (61 planes, macro-cells of 4 and 8) and the resampler's (31
    /// vertex planes, cell blocks of 4).
    #[test]
    fn slabs_own_whole_units_and_bind_their_halo_inside_the_binding() {
        let cases = |d: [usize; 3]| (d, (d[0] * d[1]) as u64 * 4);
        let (ray, p) = cases([9, 7, 61]);
        let (src, q) = cases([11, 6, 31]);
        for (dims, unit, limit) in [
            (ray, 4, 7 * p + 256),
            (ray, 8, 12 * p + 256),
            (ray, 4, 30 * p),
            (src, 4, 7 * q + 256),
            (src, 4, 10 * q + 256),
            (src, 4, 20 * q + 300),
        ] {
            let (plane, last) = ((dims[0] * dims[1]) as u64 * 4, dims[2] - 1);
            let s = z_slabs(dims, last, unit, limit, 256).unwrap();
            assert!(s.len() > 1);
            assert_eq!((s[0].z0, s.last().unwrap().z1), (0, last));
            for w in s.windows(2) {
                assert_eq!(w[0].z1, w[1].z0);
                assert_eq!(w[0].z1 % unit, 0);
            }
            for s in &s {
                assert!(s.z1 > s.z0);
                assert!(s.bytes <= limit && s.offset % 256 == 0);
                assert_eq!(s.v0, s.z0.saturating_sub(1));
                assert_eq!(s.v1, (s.z1 + 1).min(last));
                // The window holds every plane the slab's kernels read.
                assert!(s.offset <= s.v0 as u64 * plane);
                assert_eq!(s.offset + s.bytes, (s.v1 as u64 + 1) * plane);
            }
        }
        assert_eq!(z_slabs(ray, 60, 4, 61 * p, 256).unwrap().len(), 1);
        assert_eq!(z_slabs(ray, 60, 4, 7 * p + 255, 256), None);
        assert_eq!(z_slabs(src, 30, 4, 7 * q + 256, 256).unwrap().len(), 8);
    }
}
