//! The CPU path keeps a volume in its own scalar type
//! ([`crate::voxel_store`]): every image is the one its f32 twin gives, bit
//! for bit, in every settings case, from all sides; a volume of another
//! type replaces the store whole; and the store takes the bytes the type
//! says.

use super::*;
use crate::tests::{
    GPU_CASES, assert_same_images, bits, cpu, f32_twin, head, test_maps, with_block, with_volume,
};
use voxflex_core::glam::DVec3;
use voxflex_core::volume::{Volume, VoxelData};

/// The head phantom (i16, HU) as each integer type the store keeps, with
/// values that stay in that type's range: i16 as is, u16 shifted by
/// +1024, u8 as `(v + 1024) / 16` clamped.
fn typed_heads(n: usize) -> Vec<Volume> {
    let vol = head(n);
    let VoxelData::I16(hu) = &vol.data else {
        panic!("the head phantom is i16")
    };
    let u16s = hu
        .iter()
        .map(|&v| (v as i32 + 1024).max(0) as u16)
        .collect();
    let u8s = hu
        .iter()
        .map(|&v| ((v as i32 + 1024) / 16).clamp(0, 255) as u8)
        .collect();
    vec![
        vol.clone(),
        Volume::new(vol.grid, VoxelData::U16(u16s)).unwrap(),
        Volume::new(vol.grid, VoxelData::U8(u8s)).unwrap(),
    ]
}

/// Every settings case the GPU checks use (MIP, tricubic, both gradient
/// filters, jitter, maps, clipping), views from each side and from below,
/// orthographic and perspective: the integer store's linear image and
/// statistics equal the f32 store's exactly.
#[test]
fn every_scalar_type_renders_its_f32_twin_bit_for_bit() {
    let maps = test_maps();
    for vol in typed_heads(40) {
        let ty = vol.scalar_type();
        let twin = f32_twin(&vol);
        let mut views = Vec::new();
        for (az, el) in [(0.0, 0.0), (180.0, -60.0), (270.0, 10.0)] {
            views.push(fit_camera(&vol.grid, 40, 32, az, el, None));
            views.push(fit_camera(&vol.grid, 40, 32, az, el, Some(40.0)));
        }
        let mut shown = 0;
        for (toml, with_maps) in GPU_CASES {
            let mut typed = with_volume(cpu(toml), &vol);
            let mut float = with_volume(cpu(toml), &twin);
            assert_eq!(typed.values.as_slice().scalar_type(), ty);
            assert_eq!(float.values.as_slice().scalar_type(), ScalarType::F32);
            if with_maps {
                typed.set_opacity_maps(&maps).unwrap();
                float.set_opacity_maps(&maps).unwrap();
            }
            let what = format!("{ty:?} {toml:?}");
            shown += assert_same_images(&mut typed, &mut float, &views, &what);
        }
        // Not an empty comparison: the cases show tissue in every type.
        assert!(shown > 10_000, "{ty:?}: {shown} pixels shown");
    }
}

/// The store holds 1, 2, 2 and 4 bytes per voxel for u8, i16, u16, f32.
#[test]
fn the_store_takes_the_bytes_of_its_type() {
    let heads = typed_heads(24);
    let n = heads[0].grid.len();
    for (vol, per) in heads
        .iter()
        .zip([2, 2, 1])
        .chain([(&f32_twin(&heads[0]), 4)])
    {
        let r = with_volume(cpu(""), vol);
        assert_eq!(r.values.bytes(), n * per, "{:?}", vol.scalar_type());
    }
}

/// An update of another scalar type on the same grid replaces the whole
/// store even when its dirty region is small (a dirty-region copy alone
/// would leave the rest of the old type behind): the image is the new
/// volume's, as a fresh renderer draws it, in both directions.
#[test]
fn another_scalar_type_starts_the_store_over() {
    let heads = typed_heads(32);
    let (int, float) = (&heads[0], &f32_twin(&heads[0]));
    // The f32 volume: the same head with a bone block the i16 one lacks.
    let (changed, _) = with_block(float);
    let cam = fit_camera(&int.grid, 40, 32, 30.0, 15.0, None);
    let small = DirtyRegion::Box {
        min: int.grid.index_to_world(DVec3::splat(15.0)),
        max: int.grid.index_to_world(DVec3::splat(16.0)),
    };
    for (first, second) in [(int, &changed), (&changed, int)] {
        let mut r = with_volume(cpu(""), first);
        r.render_linear(&cam).unwrap();
        r.set_volume(RenderVolume::Cpu(second.view()), small)
            .unwrap();
        let (a, _) = r.render_linear(&cam).unwrap();
        let (b, _) = with_volume(cpu(""), second).render_linear(&cam).unwrap();
        assert!(
            bits(&a) == bits(&b),
            "{:?} → {:?}",
            first.scalar_type(),
            second.scalar_type()
        );
        assert_eq!(r.values.as_slice().scalar_type(), second.scalar_type());
    }
}
