//! A volume the host lends (`RenderVolume::Shared`) is drawn from the
//! host's own values: the same image as a copy gives, bit for bit, with no
//! copy made; f32 NaN still reads as 0 (such a volume is copied); and
//! updates between shared and copied volumes, in both directions, give
//! the image a fresh renderer draws of the new volume.

use super::*;
use crate::tests::{
    GPU_CASES, assert_same_images, bits, cpu, f32_twin, head, test_maps, with_block, with_volume,
};
use std::sync::Arc;
use voxflex_core::shared_volume::SharedVolume;
use voxflex_core::volume::{Volume, VoxelData};

fn shared(vol: &Volume) -> SharedVolume {
    SharedVolume::new(Arc::new(vol.clone()))
}

fn with_shared(mut r: RaycastRenderer, v: &SharedVolume) -> RaycastRenderer {
    r.set_volume(RenderVolume::Shared(v), DirtyRegion::All)
        .unwrap();
    r
}

/// Views from opposite sides, orthographic and perspective.
fn views(grid: &voxflex_core::grid::Grid) -> Vec<Camera> {
    let mut views = Vec::new();
    for (az, el) in [(30.0, 15.0), (210.0, -15.0)] {
        views.push(fit_camera(grid, 40, 32, az, el, None));
        views.push(fit_camera(grid, 40, 32, az, el, Some(40.0)));
    }
    views
}

/// Every settings case of the GPU checks, an i16 and an f32 volume: the
/// shared store reads the host's bytes (it holds none itself) and draws
/// what the copied store draws.
#[test]
fn a_shared_volume_renders_as_its_copy_without_being_copied() {
    let maps = test_maps();
    let int = head(36);
    for vol in [f32_twin(&int), int] {
        let lent = shared(&vol);
        let mut shown = 0;
        for (toml, with_maps) in GPU_CASES {
            let mut a = with_shared(cpu(toml), &lent);
            let mut b = with_volume(cpu(toml), &vol);
            assert!(a.values.is_shared() && a.values.bytes() == 0, "{toml:?}");
            assert_eq!(
                a.values.as_slice().as_bytes().as_ptr(),
                lent.view().data.as_bytes().as_ptr(),
                "the host's values, not a copy"
            );
            if with_maps {
                a.set_opacity_maps(&maps).unwrap();
                b.set_opacity_maps(&maps).unwrap();
            }
            shown += assert_same_images(&mut a, &mut b, &views(&vol.grid), toml);
        }
        assert!(shown > 5_000, "{shown} pixels shown");
    }
}

/// An f32 volume with a NaN voxel is copied (NaN stored as 0), so it draws
/// what the copied path draws.
#[test]
fn a_shared_volume_with_nan_is_copied_with_nan_as_zero() {
    let mut vol = f32_twin(&head(32));
    let VoxelData::F32(d) = &mut vol.data else {
        unreachable!()
    };
    d[vol.grid.linear(16, 16, 16)] = f32::NAN;
    let a = with_shared(cpu(""), &shared(&vol));
    assert!(!a.values.is_shared());
    assert_eq!(
        a.values.as_slice().get_f32(vol.grid.linear(16, 16, 16)),
        0.0
    );
    let mut a = a;
    let mut b = with_volume(cpu(""), &vol);
    for cam in views(&vol.grid) {
        assert!(bits(&a.render_linear(&cam).unwrap().0) == bits(&b.render_linear(&cam).unwrap().0));
    }
}

/// Shared → shared, shared → copied and copied → shared updates with the
/// changed box as dirty region, each way round (the block added, then
/// taken away): the image is the new volume's, as a fresh renderer draws
/// it, and the store shares exactly when the new volume is shared.
#[test]
fn updates_between_shared_and_copied_volumes_draw_the_new_volume() {
    let plain = f32_twin(&head(32));
    let (block, dirty) = with_block(&plain);
    let cams = views(&plain.grid);
    for (first, second) in [(&plain, &block), (&block, &plain)] {
        let fresh: Vec<Vec<u32>> = {
            let mut r = with_volume(cpu(""), second);
            cams.iter()
                .map(|c| bits(&r.render_linear(c).unwrap().0))
                .collect()
        };
        for (share_first, share_second) in [(true, true), (true, false), (false, true)] {
            let (a, b) = (shared(first), shared(second));
            let mut r = cpu("");
            let v = if share_first {
                RenderVolume::Shared(&a)
            } else {
                RenderVolume::Cpu(first.view())
            };
            r.set_volume(v, DirtyRegion::All).unwrap();
            for c in &cams {
                r.render_linear(c).unwrap();
            }
            let v = if share_second {
                RenderVolume::Shared(&b)
            } else {
                RenderVolume::Cpu(second.view())
            };
            r.set_volume(v, dirty).unwrap();
            assert_eq!(r.values.is_shared(), share_second);
            for (c, want) in cams.iter().zip(&fresh) {
                let got = bits(&r.render_linear(c).unwrap().0);
                assert!(
                    &got == want,
                    "{share_first} → {share_second}: image differs"
                );
            }
        }
    }
}

/// A NaN outside the dirty region of a shared update is found when the
/// store owned a copy before (its 0 hid the NaN): the store stays a copy,
/// and the NaN still reads as 0.
#[test]
fn a_nan_outside_the_dirty_region_keeps_an_owned_store_a_copy() {
    let mut plain = f32_twin(&head(32));
    let VoxelData::F32(d) = &mut plain.data else {
        unreachable!()
    };
    let nan_at = plain.grid.linear(25, 25, 25);
    d[nan_at] = f32::NAN;
    let (mut block, dirty) = with_block(&plain);
    let VoxelData::F32(d) = &mut block.data else {
        unreachable!()
    };
    d[nan_at] = f32::NAN;
    let mut r = with_shared(cpu(""), &shared(&plain));
    assert!(!r.values.is_shared());
    r.set_volume(RenderVolume::Shared(&shared(&block)), dirty)
        .unwrap();
    assert!(!r.values.is_shared());
    assert_eq!(r.values.as_slice().get_f32(nan_at), 0.0);
    let mut fresh = with_volume(cpu(""), &block);
    for cam in views(&block.grid) {
        assert!(
            bits(&r.render_linear(&cam).unwrap().0) == bits(&fresh.render_linear(&cam).unwrap().0)
        );
    }
}

/// On the GPU backend a shared volume is uploaded like a copied one: the
/// same device image, and a shared update after it (dirty region only)
/// draws the new volume as a fresh upload does.
#[test]
fn the_gpu_path_uploads_a_shared_volume_as_a_copied_one() {
    use crate::tests::{gpu_renderer, rgba8, test_gpu};
    let Some(service) = test_gpu() else { return };
    let plain = f32_twin(&head(32));
    let (block, dirty) = with_block(&plain);
    let cam = fit_camera(&plain.grid, 40, 32, 30.0, 15.0, None);
    let mut a = gpu_renderer("", &service);
    a.set_volume(RenderVolume::Shared(&shared(&plain)), DirtyRegion::All)
        .unwrap();
    let mut b = gpu_renderer("", &service);
    b.set_volume(RenderVolume::Cpu(plain.view()), DirtyRegion::All)
        .unwrap();
    assert_eq!(rgba8(&mut a, &cam).0, rgba8(&mut b, &cam).0);
    a.set_volume(RenderVolume::Shared(&shared(&block)), dirty)
        .unwrap();
    let mut fresh = gpu_renderer("", &service);
    fresh
        .set_volume(RenderVolume::Cpu(block.view()), DirtyRegion::All)
        .unwrap();
    let (x, y) = (rgba8(&mut a, &cam).0, rgba8(&mut fresh, &cam).0);
    assert_eq!(x, y);
    assert!(x != rgba8(&mut b, &cam).0, "the block shows");
}
