//! How the GPU path splits a volume larger than one storage binding into
//! z-slabs (see `shaders/raycast/raycast.wgsl`).
//!
//! A sample's taps reach the voxel planes `i − 1 … i + 2` around its
//! footprint plane `i` (tricubic's outer fetches, the Sobel block, central
//! differences; trilinear and the opacity map read `i, i + 1`). A slab owns
//! the footprint planes `[z0, z1)` — whole macro-cells, so the macro-cell
//! kernel of a cell (voxels `c·s − 1 … (c+1)·s + 1`) reads inside it too —
//! and binds voxel planes `z0 − 1 … z1 + 1`, at an offset aligned down to
//! `min_storage_buffer_offset_alignment`.

use voxflex_core::error::ModelError;
use voxflex_core::z_slabs::{HALO_PLANES, ZSlab, z_slabs};

/// One z-slab of the volume: it owns the footprint planes `[z0, z1)` and
/// binds voxel planes `v0 ..= v1`.
pub(crate) type Slab = ZSlab;

/// The slabs of an f32 volume of `dims` voxels with macro-cells of edge
/// `cell` voxels ([`z_slabs`]): one when it fits a binding of
/// `max_binding` bytes.
pub(crate) fn plan(
    dims: [usize; 3],
    cell: usize,
    max_binding: u64,
    align: u64,
) -> Result<Vec<Slab>, ModelError> {
    let footprints = dims[2].saturating_sub(1).max(1);
    z_slabs(dims, footprints, cell, max_binding, align).ok_or_else(|| {
        let planes = cell.max(1) as u64 + HALO_PLANES;
        let need = planes * (dims[0] * dims[1]) as u64 * 4 + align.max(4);
        ModelError(format!(
            "one macro-cell of volume z-planes and its halo ({planes} planes of f32) need {:.1} MiB in \
             one GPU binding, above this GPU's max_storage_buffer_binding_size of {:.1} MiB; \
             render on the CPU (backend = \"cpu\") or use a smaller volume",
            need as f64 / 1048576.0,
            max_binding as f64 / 1048576.0
        ))
    })
}

/// The opacity-map words a slab's window reads, for a map box of `origin`
/// and `dims` voxels (u16, two per word): `(byte offset, bytes)`, or a
/// 4-byte stand-in at 0 when the window misses the box (nothing is read).
pub(crate) fn map_window(s: &Slab, origin: [usize; 3], dims: [usize; 3], align: u64) -> (u64, u64) {
    let lo = s.v0.max(origin[2]);
    let hi = s.v1.min((origin[2] + dims[2]).saturating_sub(1));
    if dims[2] == 0 || lo > hi {
        return (0, 4);
    }
    let plane = (dims[0] * dims[1]) as u64;
    let l0 = (lo - origin[2]) as u64 * plane;
    let l1 = (hi - origin[2] + 1) as u64 * plane;
    let align = align.max(4);
    let offset = l0 / 2 * 4 / align * align;
    let end = l1.div_ceil(2) * 4;
    (offset, end.max(offset + 4) - offset)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plan owns the footprint planes `0 .. n − 1` in whole
    /// macro-cells (the tiling itself: `voxflex_core::z_slabs`'s tests),
    /// and says what to do when one macro-cell does not fit.
    #[test]
    fn slabs_own_whole_cells_and_bind_their_taps() {
        let dims = [9, 7, 61];
        let plane = 9 * 7 * 4;
        for (cell, limit) in [(4, 7 * plane + 256), (8, 12 * plane + 256), (4, 30 * plane)] {
            let s = plan(dims, cell, limit, 256).unwrap();
            assert!(s.len() > 1);
            assert_eq!((s[0].z0, s.last().unwrap().z1), (0, 60));
            assert!(s.iter().all(|s| s.z0 % cell == 0 && s.bytes <= limit));
        }
        assert_eq!(plan(dims, 4, 61 * plane, 256).unwrap().len(), 1);
        let e = plan(dims, 4, 7 * plane + 255, 256).unwrap_err();
        assert!(e.to_string().contains("max_storage_buffer_binding_size"));
        // 512³ f32 under 128 MiB with 8-voxel macro-cells: 5 slabs.
        assert_eq!(plan([512; 3], 8, 128 << 20, 256).unwrap().len(), 5);
    }

    #[test]
    fn map_windows_cover_the_planes_in_the_box() {
        let s = Slab {
            z0: 8,
            z1: 16,
            v0: 7,
            v1: 17,
            offset: 0,
            bytes: 0,
        };
        // Box z 10..30 of 5 × 3: planes 10..=17, elements 0..120, words 0..60.
        assert_eq!(map_window(&s, [0, 0, 10], [5, 3, 20], 256), (0, 240));
        // Box z 0..30: planes 7..=17, elements 105..270 → words 52..135.
        let (off, bytes) = map_window(&s, [0, 0, 0], [5, 3, 30], 16);
        assert_eq!(off, 208);
        assert_eq!(off + bytes, 135 * 4);
        // A box beyond the window: nothing read.
        assert_eq!(map_window(&s, [0, 0, 20], [5, 3, 5], 256), (0, 4));
    }
}
