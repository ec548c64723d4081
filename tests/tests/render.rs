//! Rendering through the real path: the `raycast` plugin loaded from its
//! shared library by the runtime, from scenes, from `voxflex render`, and on
//! both backends.

use std::sync::Arc;
use voxflex_abi::host_side::HostServices;
use voxflex_abi::renderer::RendererProxy;
use voxflex_core::camera::{Camera, Projection};
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::gpu::{GpuService, GpuServiceExt};
use voxflex_core::render::{ImageTarget, RenderVolume, Renderer};
use voxflex_integration_tests::*;
use voxflex_opacity::{CpuGrowth, GrowthParams, Seed};
use voxflex_runtime::gpu_context::testing::test_gpu;

fn raycast(
    gpu: Option<Arc<dyn GpuService>>,
    params: &str,
    backend: ExecutionBackend,
) -> RendererProxy {
    let p = voxflex_runtime::plugin_loader::load_by_name("raycast", &[plugin_dir(&["raycast"])])
        .unwrap();
    // SAFETY: checked, never-unloaded library.
    let mut r = unsafe {
        RendererProxy::create(
            "raycast",
            p.renderer.unwrap(),
            params,
            HostServices::new(gpu, 2),
        )
    }
    .unwrap();
    r.init(backend).unwrap();
    r
}

fn camera(grid: &voxflex_core::grid::Grid) -> Camera {
    Camera {
        target: grid.centre(),
        azimuth_deg: 25.0,
        elevation_deg: 10.0,
        distance_mm: 600.0,
        projection: Projection::Orthographic { height_mm: 300.0 },
        width: 96,
        height: 80,
    }
}

#[test]
fn cpu_and_gpu_images_agree_through_the_plugin() {
    let Some(gpu) = test_gpu() else { return };
    let gpu: Arc<dyn GpuService> = gpu;
    let volume = voxflex_phantom::phantom("head", [48, 56, 52]).unwrap();
    let mut growth = CpuGrowth::new(
        volume.view(),
        &Seed::World(volume.grid.centre()),
        GrowthParams::default(),
    )
    .unwrap();
    growth.run(volume.view()).unwrap();
    let maps = [growth.map()];
    for params in [
        "transfer_function = { preset = \"ct-bone\" }",
        "mode = \"mip\"\ntransfer_function = { preset = \"ct-soft-tissue\" }",
    ] {
        for with_maps in [false, true] {
            let cam = camera(&volume.grid);
            let n = (cam.width * cam.height) as usize;
            let mut cpu = raycast(Some(gpu.clone()), params, ExecutionBackend::Cpu);
            cpu.set_volume(RenderVolume::Cpu(volume.view()), DirtyRegion::All)
                .unwrap();
            let mut a = vec![0u8; n * 4];
            let mut g = raycast(Some(gpu.clone()), params, ExecutionBackend::Gpu);
            g.set_volume(RenderVolume::Cpu(volume.view()), DirtyRegion::All)
                .unwrap();
            if with_maps {
                cpu.set_opacity_maps(&maps).unwrap();
                g.set_opacity_maps(&maps).unwrap();
            }
            cpu.render(&cam, ImageTarget::Cpu(&mut a)).unwrap();
            let out = gpu.create_buffer(n as u64 * 4, "image").unwrap();
            g.render(&cam, ImageTarget::Gpu(out)).unwrap();
            let mut packed = vec![0u32; n];
            gpu.download(out, &mut packed).unwrap();
            gpu.destroy_buffer(out);
            let b: Vec<u8> = packed.iter().flat_map(|p| p.to_le_bytes()).collect();
            let worst = a.iter().zip(&b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            assert!(a.iter().any(|&v| v > 0), "{params}: empty image");
            assert!(
                worst <= 2,
                "{params}, maps {with_maps}: CPU and GPU differ by {worst}/255"
            );
        }
    }
}

/// A volume the host lends crosses into the built plugin without a copy:
/// the CPU image is the copied volume's, byte for byte, on a view from
/// each side, and the plugin gives the host's values back (releases its
/// loan) when it takes another volume and when it is dropped.
#[test]
fn a_shared_volume_renders_as_a_copied_one_through_the_plugin() {
    use voxflex_core::shared_volume::SharedVolume;
    let volume = Arc::new(voxflex_phantom::phantom("head", [48, 56, 52]).unwrap());
    let shared = SharedVolume::new(volume.clone());
    let holders = || Arc::strong_count(&volume);
    let params = "transfer_function = { preset = \"ct-bone\" }";
    let mut lent = raycast(None, params, ExecutionBackend::Cpu);
    lent.set_volume(RenderVolume::Shared(&shared), DirtyRegion::All)
        .unwrap();
    let mut copied = raycast(None, params, ExecutionBackend::Cpu);
    copied
        .set_volume(RenderVolume::Cpu(volume.view()), DirtyRegion::All)
        .unwrap();
    drop(shared);
    assert_eq!(holders(), 2, "the plugin holds the host's volume");
    for azimuth in [25.0, 205.0] {
        let cam = Camera {
            azimuth_deg: azimuth,
            ..camera(&volume.grid)
        };
        let n = (cam.width * cam.height) as usize * 4;
        let (mut a, mut b) = (vec![0u8; n], vec![0u8; n]);
        lent.render(&cam, ImageTarget::Cpu(&mut a)).unwrap();
        copied.render(&cam, ImageTarget::Cpu(&mut b)).unwrap();
        assert!(a.iter().any(|&v| v > 0), "empty image");
        assert!(a == b, "azimuth {azimuth}: the shared image differs");
    }
    lent.set_volume(RenderVolume::Cpu(volume.view()), DirtyRegion::All)
        .unwrap();
    assert_eq!(holders(), 1, "released on a copied volume");
    lent.set_volume(
        RenderVolume::Shared(&SharedVolume::new(volume.clone())),
        DirtyRegion::All,
    )
    .unwrap();
    assert_eq!(holders(), 2);
    drop(lent);
    assert_eq!(holders(), 1, "released when the plugin is dropped");
}

#[test]
fn a_scene_renders_with_its_roi_maps() {
    plugin_dir(&["affine", "raycast"]);
    let tmp = tempfile::tempdir().unwrap();
    let base = scene(
        "cpu",
        "head",
        40,
        1,
        "affine",
        "field = \"twist\"\nangle_deg = 20",
        &tmp.path().join("plain"),
    );
    let render = "\n[render]\nwidth = 64\nheight = 64\nfile = \"r.png\"\n[render.params]\ntransfer_function = { preset = \"ct-soft-tissue\" }\n";
    std::fs::write(tmp.path().join("a.toml"), format!("{base}{render}")).unwrap();
    let o = voxflex(&["run", "a.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let plain = image_bytes(&tmp.path().join("plain/r.png"));

    let with_roi = format!(
        "{}\n[[roi]]\nseed = [0.0, 0.0, 0.0]\n{render}",
        base.replace("/plain", "/roi")
    );
    std::fs::write(tmp.path().join("b.toml"), with_roi).unwrap();
    let o = voxflex(&["run", "b.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&tmp.path().join("roi"));
    assert_eq!(m["stages"]["render"]["runs"], 1, "{m}");
    assert_eq!(m["stages"]["roi"]["runs"], 1, "{m}");
    let roi = image_bytes(&tmp.path().join("roi/r.png"));
    assert_ne!(plain, roi, "an opacity map must change the rendering");

    // The automatic Gaussian transfer function around the seed's intensity.
    let gauss = format!(
        "{}\n[[roi]]\nseed = [0.0, 0.0, 0.0]\ngaussian_tf = true\n{render}",
        base.replace("/plain", "/gauss")
    );
    std::fs::write(tmp.path().join("c.toml"), gauss).unwrap();
    let o = voxflex(&["run", "c.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_ne!(
        image_bytes(&tmp.path().join("gauss/r.png")),
        roi,
        "the Gaussian TF must change the rendering"
    );
}

fn image_bytes(p: &std::path::Path) -> Vec<u8> {
    let bytes = std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    assert_eq!(&bytes[1..4], b"PNG");
    bytes
}

#[test]
fn render_command_writes_a_png_and_names_bad_presets() {
    plugin_dir(&["raycast"]);
    let tmp = tempfile::tempdir().unwrap();
    let o = voxflex(
        &[
            "render",
            "phantom:head",
            "--dims",
            "32,32,32",
            "--out",
            "shots/head.png",
            "--size",
            "64x48",
            "--backend",
            "cpu",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    image_bytes(&tmp.path().join("shots/head.png"));
    let o = voxflex(
        &[
            "render",
            "phantom:head",
            "--dims",
            "16,16,16",
            "--out",
            "x.png",
            "--preset",
            "ct-bones",
            "--backend",
            "cpu",
        ],
        tmp.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("unknown preset `ct-bones`") && err.lines().count() == 1,
        "{err}"
    );
}

/// `voxflex render` of a CT as its file holds it (i16) and of the same
/// values written as f32 gives the same PNG, byte for byte (the renderer
/// keeps integer volumes in their own type and reads them exactly); the
/// same for an 8-bit volume, and for views from the other side.
#[test]
fn render_command_draws_integer_files_as_their_f32_twins() {
    use voxflex_core::volume::{Volume, VoxelData};
    plugin_dir(&["raycast"]);
    let tmp = tempfile::tempdir().unwrap();
    let head = voxflex_phantom::phantom("head", [40, 44, 36]).unwrap();
    let VoxelData::I16(hu) = &head.data else {
        panic!("the head phantom is i16")
    };
    let bytes: Vec<u8> = hu
        .iter()
        .map(|&v| ((v as i32 + 1024) / 16).clamp(0, 255) as u8)
        .collect();
    let byte_head = Volume::new(head.grid, VoxelData::U8(bytes)).unwrap();
    // `mri-t1` is placed on the data range: it shows the bytes too.
    for (name, vol, preset) in [("ct", &head, "ct-bone"), ("bytes", &byte_head, "mri-t1")] {
        let twin = Volume::new(vol.grid, VoxelData::F32(vol.view().data.to_f32_vec())).unwrap();
        let paths = [format!("{name}.nii"), format!("{name}_f32.nii")];
        for (p, v) in paths.iter().zip([vol, &twin]) {
            voxflex_io::write_volume(&tmp.path().join(p), v.view()).unwrap();
        }
        let mut views = Vec::new();
        for azimuth in ["30", "210"] {
            let pngs: Vec<Vec<u8>> = paths
                .iter()
                .map(|p| {
                    let out = format!("{p}_{azimuth}.png");
                    let args = [
                        "render",
                        p,
                        "--out",
                        &out,
                        "--size",
                        "64x48",
                        "--backend",
                        "cpu",
                        "--preset",
                        preset,
                        "--azimuth",
                        azimuth,
                    ];
                    let o = voxflex(&args, tmp.path());
                    assert!(o.status.success(), "{}", text(&o));
                    image_bytes(&tmp.path().join(&out))
                })
                .collect();
            assert!(pngs[0] == pngs[1], "{name}, azimuth {azimuth}: PNGs differ");
            views.push(pngs[0].clone());
        }
        // Not two blank images: the two sides of the head differ.
        assert!(views[0] != views[1], "{name}: both views alike");
    }
}
