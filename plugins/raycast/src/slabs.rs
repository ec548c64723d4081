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

/// One z-slab of the volume.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Slab {
    /// First footprint z-plane this slab samples.
    pub z0: usize,
    /// One past its last footprint z-plane.
    pub z1: usize,
    /// First voxel z-plane of the bound window.
    pub v0: usize,
    /// Last voxel z-plane of the bound window (inclusive).
    pub v1: usize,
    /// Byte offset of the bound window (aligned).
    pub offset: u64,
    /// Bytes bound.
    pub bytes: u64,
}

/// Voxel planes a slab binds beyond its footprint planes (one below, two
/// above the last: `z0 − 1 … z1 + 1`).
const HALO_PLANES: u64 = 3;

/// The slabs of an f32 volume of `dims` voxels with macro-cells of edge
/// `cell` voxels: one when it fits a binding of `max_binding` bytes.
pub(crate) fn plan(
    dims: [usize; 3],
    cell: usize,
    max_binding: u64,
    align: u64,
) -> Result<Vec<Slab>, ModelError> {
    let plane = (dims[0] * dims[1]) as u64 * 4;
    let total = plane * dims[2] as u64;
    let last = dims[2].saturating_sub(1);
    let planes = last.max(1);
    if total <= max_binding {
        return Ok(vec![Slab {
            z0: 0,
            z1: planes,
            v0: 0,
            v1: last,
            offset: 0,
            bytes: total,
        }]);
    }
    let align = align.max(4);
    let cell = cell.max(1);
    let fit = (max_binding.saturating_sub(align) / plane.max(1)).saturating_sub(HALO_PLANES);
    let k = fit as usize / cell * cell;
    if k == 0 {
        let need = (cell as u64 + HALO_PLANES) * plane + align;
        return Err(ModelError(format!(
            "one macro-cell of volume z-planes and its halo ({} planes of f32) need {:.1} MiB in \
             one GPU binding, above this GPU's max_storage_buffer_binding_size of {:.1} MiB; \
             render on the CPU (backend = \"cpu\") or use a smaller volume",
            cell as u64 + HALO_PLANES,
            need as f64 / 1048576.0,
            max_binding as f64 / 1048576.0
        )));
    }
    let mut out = Vec::new();
    let mut z0 = 0;
    while z0 < planes {
        let z1 = (z0 + k).min(planes);
        let v0 = z0.saturating_sub(1);
        let v1 = (z1 + 1).min(last);
        let offset = v0 as u64 * plane / align * align;
        out.push(Slab {
            z0,
            z1,
            v0,
            v1,
            offset,
            bytes: (v1 as u64 + 1) * plane - offset,
        });
        z0 = z1;
    }
    Ok(out)
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

    #[test]
    fn slabs_own_whole_cells_and_bind_their_taps() {
        let dims = [9, 7, 61];
        let plane = 9 * 7 * 4;
        for (cell, limit) in [(4, 7 * plane + 256), (8, 12 * plane + 256), (4, 30 * plane)] {
            let s = plan(dims, cell, limit, 256).unwrap();
            assert!(s.len() > 1);
            assert_eq!(s[0].z0, 0);
            assert_eq!(s.last().unwrap().z1, 60);
            for w in s.windows(2) {
                assert_eq!(w[0].z1, w[1].z0);
                assert_eq!(w[0].z1 % cell, 0);
            }
            for s in &s {
                assert!(s.bytes <= limit);
                assert_eq!(s.offset % 256, 0);
                assert_eq!(s.v0, s.z0.saturating_sub(1));
                assert_eq!(s.v1, (s.z1 + 1).min(60));
                assert!(s.offset <= s.v0 as u64 * plane);
                assert_eq!(s.offset + s.bytes, (s.v1 as u64 + 1) * plane);
            }
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
