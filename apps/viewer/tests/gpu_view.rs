//! The 3D view's GPU path on the device egui's wgpu renderer and the
//! session share (lavapipe in CI): the texture kernel premultiplies as
//! egui's CPU upload does, and switching the *Backend* combo box to GPU
//! makes the 3D view draw the texture the session's render wrote, equal to
//! the CPU render within the ray caster's CPU/GPU tolerance. The textures
//! are read back here, in the tests only. Skips without a GPU adapter
//! unless `CI=true`.

use eframe::egui_wgpu::{RenderState, RendererOptions};
use eframe::wgpu;
use egui::{Color32, ColorImage};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use egui_kittest::wgpu::{WgpuTestRenderer, create_render_state, default_wgpu_setup};
use std::time::{Duration, Instant};
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::gpu_context::testing::test_gpu;
use voxflex_viewer::app::ViewerApp;
use voxflex_viewer::backend_panel::SOFTWARE_WARNING;
use voxflex_viewer::gpu_image::{GpuFrame, GpuImage, with_adapter_limits};
use voxflex_viewer::open::OpenRequest;
use voxflex_viewer::screenshot::Screenshot;

/// How long a test waits for the worker before failing.
const PATIENCE: Duration = Duration::from_secs(180);
/// Largest channel difference between the ray caster's CPU and GPU images
/// (its own parity tests allow 2; premultiplying can add 1).
const TOLERANCE: u8 = 3;

/// egui's wgpu renderer on the device the viewer opens (the adapter's own
/// limits), or `None` (skip) without an adapter outside CI.
fn render_state() -> Option<RenderState> {
    test_gpu()?;
    Some(create_render_state(
        with_adapter_limits(default_wgpu_setup()),
        RendererOptions::PREDICTABLE,
    ))
}

/// The RGBA8 texels of `texture`, row by row (the test's read-back).
fn read_texture(state: &RenderState, texture: &wgpu::Texture) -> Vec<u8> {
    let (w, h) = (texture.width(), texture.height());
    let row = (w * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let staging = state.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test read-back"),
        size: row as u64 * h as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = state
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(h),
            },
        },
        texture.size(),
    );
    state.queue.submit([encoder.finish()]);
    let slice = staging.slice(..);
    slice.map_async(wgpu::MapMode::Read, |r| r.expect("map the read-back"));
    state
        .device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("wait for the read-back");
    let data = slice.get_mapped_range().expect("the mapped read-back");
    data.chunks(row as usize)
        .flat_map(|r| &r[..w as usize * 4])
        .copied()
        .collect()
}

/// `rgba` (straight alpha) premultiplied as egui's CPU upload does.
fn premultiplied(size: [usize; 2], rgba: &[u8]) -> Vec<u8> {
    ColorImage::from_rgba_unmultiplied(size, rgba)
        .pixels
        .iter()
        .flat_map(|c: &Color32| c.to_array())
        .collect()
}

#[test]
fn the_texture_kernel_premultiplies_as_egui_does() {
    let Some(state) = render_state() else { return };
    // Every alpha (rows) against colours covering 0..=255 in each channel;
    // 250 wide: neither a multiple of the kernel's tile nor of the row
    // alignment.
    let (w, h) = (250u32, 256u32);
    let rgba: Vec<u8> = (0..h)
        .flat_map(|a| (0..w).flat_map(move |x| [x as u8, 255 - x as u8, (x * 7) as u8, a as u8]))
        .collect();
    let buffer = state.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test image"),
        size: rgba.len() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    state.queue.write_buffer(&buffer, 0, &rgba);
    let mut image = GpuImage::new(state.clone()).expect("the kernel compiles");
    let frame = GpuFrame {
        buffer,
        width: w,
        height: h,
    };
    image.show(&frame).expect("the copy runs");
    let got = read_texture(&state, image.texture().expect("made by show"));
    let want = premultiplied([w as usize, h as usize], &rgba);
    let wrong = got.iter().zip(&want).filter(|(a, b)| a != b).count();
    assert_eq!(wrong, 0, "{wrong} channel values differ from egui's");
    assert!(image.texture_id().is_some());
    // A buffer too small for the image is refused, not a panic.
    let small = GpuFrame {
        width: w + 1,
        ..frame
    };
    assert!(image.show(&small).is_err());
}

fn wait(h: &mut Harness<'static, ViewerApp>, what: &str, done: impl Fn(&ViewerApp) -> bool) {
    let t = Instant::now();
    while !done(h.state()) {
        assert!(
            t.elapsed() < PATIENCE,
            "timed out waiting for {what}; viewer messages: {:?}, backend: {:?}",
            h.state().messages(),
            h.state().backend_panel()
        );
        h.step();
        std::thread::sleep(Duration::from_millis(10));
    }
    h.step();
}

#[test]
fn switching_to_gpu_draws_the_sessions_texture_equal_to_the_cpu_render() {
    let Some(state) = render_state() else { return };
    let mut req = OpenRequest {
        input: None,
        backend: BackendChoice::Cpu,
        plugin_dirs: vec![voxflex_integration_tests::plugin_dir(&[
            "chainmail",
            "raycast",
        ])],
        gpu: None,
        oblique: Default::default(),
    };
    let gpu = GpuImage::share(Some(&state), &mut req);
    assert!(gpu.is_some() && req.gpu.is_some(), "the device is shared");
    let app = ViewerApp::new(&egui::Context::default(), req, Screenshot::new(None, None))
        .expect("start the viewer")
        .with_gpu_image(gpu);
    let mut h = Harness::builder()
        .with_size([1280.0, 860.0])
        .renderer(WgpuTestRenderer::from_render_state(state.clone()))
        .build_ui_state(|ui, app: &mut ViewerApp| app.show(ui), app);
    wait(&mut h, "the CPU images", |a| a.ready());
    let cpu = h.state().render_image().0.expect("a CPU image").clone();
    let cpu_tex = h.state().view3d_texture();
    assert!(
        matches!(cpu_tex, Some(egui::TextureId::Managed(_))),
        "{cpu_tex:?}"
    );
    let status = h.state().backend_panel().status.clone().expect("reported");
    assert_eq!(status.choice, BackendChoice::Cpu);
    assert!(status.computing.is_none());
    let shared = status.shared.expect("the shared adapter is reported");
    assert_eq!(shared.name, state.adapter.get_info().name);

    h.get_by_role_and_label(egui::accesskit::Role::ComboBox, "Backend")
        .click();
    h.run_steps(3);
    h.get_by_label("GPU").click();
    let renders = h.state().render_image().1;
    wait(&mut h, "the GPU image", |a| {
        a.render_image().1 > renders
            && a.ready()
            && a.gpu_image().and_then(GpuImage::texture_id).is_some()
    });
    let app = h.state();
    let status = app.backend_panel().status.clone().expect("reported");
    assert_eq!(status.choice, BackendChoice::Gpu);
    assert_eq!(status.computing.as_ref(), Some(&shared));
    let image = app.gpu_image().expect("shared");
    // The 3D view draws the texture the GPU path wrote, not an upload.
    assert_eq!(app.view3d_texture(), image.texture_id());
    assert!(matches!(
        app.view3d_texture(),
        Some(egui::TextureId::User(_))
    ));
    let texture = image.texture().expect("written");
    assert_eq!((texture.width(), texture.height()), (cpu.width, cpu.height));
    let got = read_texture(&state, texture);
    let want = premultiplied([cpu.width as usize, cpu.height as usize], &cpu.pixels);
    let worst = got
        .iter()
        .zip(&want)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap_or(0);
    assert!(
        worst <= TOLERANCE,
        "GPU vs CPU image: largest difference {worst}"
    );
    // The image is not blank: the phantom shows.
    assert!(want.chunks(4).filter(|p| p[3] > 0).count() > 1000);
    // The warning shows exactly on a software adapter.
    let warned = h.query_by_label_contains(SOFTWARE_WARNING).is_some();
    assert_eq!(warned, shared.software, "{shared}");
    assert!(
        app.render_image().0.is_none(),
        "no image came back to the CPU"
    );
    // egui's renderer draws the frame with the native texture.
    h.render().expect("egui draws the shared texture");

    // Back to the CPU: the image is uploaded again and drawn from there.
    h.get_by_role_and_label(egui::accesskit::Role::ComboBox, "Backend")
        .click();
    h.run_steps(3);
    h.get_by_label("CPU").click();
    wait(&mut h, "the CPU image again", |a| {
        a.render_image().0.is_some() && a.ready()
    });
    let app = h.state();
    assert!(app.gpu_image().and_then(GpuImage::texture_id).is_none());
    assert!(matches!(
        app.view3d_texture(),
        Some(egui::TextureId::Managed(_))
    ));
    assert_eq!(app.render_image().0, Some(&cpu), "the same CPU render");
}
