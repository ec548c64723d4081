//! A slice's gray pixels with ROI maps blended over them, as RGBA.

use voxflex_core::opacity_map::{OpacityMap, from_fixed};
use voxflex_runtime::session::SliceImage;

/// Largest share of a pixel an overlay covers (at opacity `o_max`).
const OVERLAY_ALPHA: f32 = 0.6;

/// The slice as RGBA bytes with each map of `overlays` drawn in its colour,
/// its weight rising from 0 at the map's `outside` opacity to
/// [`OVERLAY_ALPHA`] at 1.
pub fn compose_slice(slice: &SliceImage, overlays: &[(&OpacityMap, [u8; 3])]) -> Vec<u8> {
    let mut rgba: Vec<u8> = slice
        .image
        .pixels
        .iter()
        .flat_map(|&g| [g, g, g, 255])
        .collect();
    for (map, colour) in overlays {
        let floor = from_fixed(map.outside);
        let span = (1.0 - floor).max(f32::EPSILON);
        for (px, o) in rgba.chunks_exact_mut(4).zip(slice.overlay(map)) {
            let a = OVERLAY_ALPHA * ((o - floor) / span).clamp(0.0, 1.0);
            for (c, &tint) in px.iter_mut().zip(colour) {
                *c = (*c as f32 * (1.0 - a) + tint as f32 * a).round() as u8;
            }
        }
    }
    rgba
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DVec3;
    use voxflex_core::grid::Grid;
    use voxflex_runtime::session::{GrayImage, SliceAxis};

    #[test]
    fn a_map_tints_only_where_it_grew() {
        let grid = Grid::new([2, 1, 1], DVec3::ONE, DVec3::ZERO);
        let slice = SliceImage {
            image: GrayImage {
                width: 2,
                height: 1,
                pixels: vec![100, 100],
            },
            axis: SliceAxis::Axial,
            index: 0,
            grid,
        };
        let map = OpacityMap {
            origin: [0, 0, 0],
            dims: [1, 1, 1],
            outside: voxflex_core::opacity_map::to_fixed(0.03),
            values: vec![voxflex_core::opacity_map::to_fixed(1.0)],
        };
        let rgba = compose_slice(&slice, &[(&map, [255, 0, 0])]);
        assert_eq!(&rgba[4..8], &[100, 100, 100, 255], "outside: untouched");
        // 60 % red over gray 100 at full opacity.
        assert_eq!(&rgba[0..4], &[193, 40, 40, 255]);
    }
}
