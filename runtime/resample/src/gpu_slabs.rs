//! How the GPU path splits arrays larger than one storage binding into
//! z-slabs, each bound at an offset aligned down to
//! `min_storage_buffer_offset_alignment` (the kernels subtract the bound
//! range's first element index).
//!
//! - **Output slabs** ([`output_slabs`]): runs of output z-planes.
//! - **Source slabs** ([`source_slabs`]): runs of cell z-planes `[z0, z1)`
//!   (whole cell blocks); each binds the source values and the three
//!   displacement arrays over the vertex planes `z0 − 1 … z1 + 1` (`voxflex_core::z_slabs`). A cell
//!   `ck` reads vertex planes `ck` and `ck + 1`; the trilinear fill reads
//!   the source at `ck + ⌊r⌋` and the plane above, `r` the rest position in
//!   the cell, which lies in `[−ε, 1]` except in nearly degenerate
//!   tetrahedra (rounding): planes `ck − 1 … ck + 2`. Reads beyond that
//!   halo are counted by the fill kernel and reported as
//!   [`ResampleError::SlabHaloExceeded`], never read from elsewhere.
//! - **Filled bits** ([`filled_bits`]): the word range of the one-bit-per-
//!   output-voxel array that marks voxels already holding a value while
//!   the source is split (the fill overwrites a voxel's owner key with its
//!   value in place, so a later source slab must not read it as a key).

use super::ResampleError;
use crate::blocks::BLOCK_EDGE;
use voxflex_core::z_slabs::{HALO_PLANES, ZSlab, z_slabs};

/// One output z-slab: output planes `z0..=z1` (output voxel indices) bound
/// as `bytes` bytes at byte offset `offset`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct OutputSlab {
    /// First output z-plane.
    pub z0: usize,
    /// Last output z-plane (inclusive).
    pub z1: usize,
    /// Byte offset of the bound range (aligned).
    pub offset: u64,
    /// Bytes bound.
    pub bytes: u64,
}

/// The output z-slabs covering output planes `z0..=z1` of an output of
/// `dims` f32 voxels (one slab when the whole output fits one binding).
pub(crate) fn output_slabs(
    dims: [usize; 3],
    z0: usize,
    z1: usize,
    max_binding: u64,
    align: u64,
) -> Result<Vec<OutputSlab>, ResampleError> {
    let plane = (dims[0] * dims[1]) as u64 * 4;
    let total = plane * dims[2] as u64;
    if total <= max_binding {
        return Ok(vec![OutputSlab {
            z0,
            z1,
            offset: 0,
            bytes: total,
        }]);
    }
    let align = align.max(4);
    let planes = max_binding.saturating_sub(align) / plane;
    if planes == 0 {
        return Err(ResampleError::BindingTooLarge {
            what: "one output z-plane (plus the offset alignment)",
            bytes: plane + align,
            limit: max_binding,
        });
    }
    let mut out = Vec::new();
    let mut z = z0;
    while z <= z1 {
        let e = (z + planes as usize - 1).min(z1);
        let start = z as u64 * plane;
        let offset = start / align * align;
        let end = (e as u64 + 1) * plane;
        out.push(OutputSlab {
            z0: z,
            z1: e,
            offset,
            bytes: end - offset,
        });
        z = e + 1;
    }
    Ok(out)
}

/// One source z-slab: it owns the cell z-planes `[z0, z1)` (whole
/// blocks), and binds source values and displacements over vertex planes
/// `v0 ..= v1` (`z0 − 1`, `z1 + 1`, clamped).
pub(crate) type SourceSlab = ZSlab;

/// The source z-slabs of a sampling mesh of `vdims` vertices (= source
/// voxels, f32 each; [`z_slabs`]): one covering everything when the source
/// fits one binding, else slabs of whole cell blocks whose windows fit it.
pub(crate) fn source_slabs(
    vdims: [usize; 3],
    max_binding: u64,
    align: u64,
) -> Result<Vec<SourceSlab>, ResampleError> {
    let cells = vdims[2].saturating_sub(1);
    z_slabs(vdims, cells, BLOCK_EDGE, max_binding, align).ok_or_else(|| {
        ResampleError::BindingTooLarge {
            what: "one cell block of source z-planes and its halo (7 planes of f32, plus the \
                   offset alignment)",
            bytes: (BLOCK_EDGE as u64 + HALO_PLANES) * (vdims[0] * vdims[1]) as u64 * 4
                + align.max(4),
            limit: max_binding,
        }
    })
}

/// The filled-bit words of the output elements `[e0, e1)` (bit `e % 32` of
/// word `e / 32`): `(byte offset, bytes)` of the aligned binding.
pub(crate) fn filled_bits(e0: u64, e1: u64, align: u64) -> (u64, u64) {
    let align = align.max(4);
    let offset = e0 / 32 * 4 / align * align;
    let end = e1.div_ceil(32) * 4;
    (offset, end.max(offset + 4) - offset)
}

/// Bytes of the filled-bit array of an output of `voxels` voxels.
pub(crate) fn filled_bytes(voxels: u64) -> u64 {
    voxels.div_ceil(32) * 4
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_slabs_cover_the_region_within_the_binding() {
        let dims = [10, 7, 50];
        let plane = 10 * 7 * 4;
        let s = output_slabs(dims, 3, 44, 5 * plane + 256, 256).unwrap();
        assert!(s.len() > 1);
        assert_eq!(s[0].z0, 3);
        assert_eq!(s.last().unwrap().z1, 44);
        for w in s.windows(2) {
            assert_eq!(w[0].z1 + 1, w[1].z0);
        }
        for s in &s {
            assert_eq!(s.offset % 256, 0);
            assert!(s.bytes <= 5 * plane + 256);
            assert!(s.offset <= s.z0 as u64 * plane);
            assert_eq!(s.offset + s.bytes, (s.z1 as u64 + 1) * plane);
        }
        assert_eq!(
            output_slabs(dims, 0, 49, 1 << 30, 256).unwrap(),
            vec![OutputSlab {
                z0: 0,
                z1: 49,
                offset: 0,
                bytes: 50 * plane
            }]
        );
        assert!(output_slabs(dims, 0, 49, 100, 256).is_err());
    }

    /// Source slabs own the cell planes `0 .. n − 1` in whole blocks (the
    /// tiling itself: `voxflex_core::z_slabs`'s tests, on these dims and
    /// limits too), and a source too large for one block is refused.
    #[test]
    fn source_slabs_are_whole_blocks_with_their_halo_inside_the_binding() {
        let v = [11, 6, 31];
        let plane = 11 * 6 * 4;
        for limit in [7 * plane + 256, 10 * plane + 256, 20 * plane + 300] {
            let s = source_slabs(v, limit, 256).unwrap();
            assert!(s.len() > 1, "{limit}");
            assert_eq!((s[0].z0, s.last().unwrap().z1), (0, 30));
            assert!(s.iter().all(|s| s.z0 % BLOCK_EDGE == 0 && s.bytes <= limit));
        }
        assert_eq!(source_slabs(v, 7 * plane + 256, 256).unwrap().len(), 8);
        let one = source_slabs(v, 31 * plane, 256).unwrap();
        assert_eq!(
            one,
            vec![SourceSlab {
                z0: 0,
                z1: 30,
                v0: 0,
                v1: 30,
                offset: 0,
                bytes: 31 * plane
            }]
        );
        let err = source_slabs(v, 7 * plane + 255, 256).unwrap_err();
        assert!(err.to_string().contains("max_storage_buffer_binding_size"));
        // 512³ f32 under lavapipe's 128 MiB: 5 slabs of ≤ 124 cell planes.
        let big = source_slabs([512; 3], 128 << 20, 256).unwrap();
        assert_eq!(big.len(), 5);
        assert!(big.iter().all(|s| s.bytes <= 128 << 20));
    }

    #[test]
    fn filled_bits_cover_their_elements() {
        assert_eq!(filled_bits(0, 1, 256), (0, 4));
        assert_eq!(filled_bits(0, 64, 256), (0, 8));
        // Elements 70 000.. start in word 2187 (byte 8748), aligned down to 8704.
        let (off, bytes) = filled_bits(70_000, 80_000, 256);
        assert_eq!(off, 8704);
        assert_eq!(off + bytes, 80_000u64.div_ceil(32) * 4);
        assert_eq!(filled_bytes(65), 12);
    }
}
