//! `Session::render_to_gpu` through the real raycast library: on a device
//! a front end offered (`SessionDefaults::gpu`, as the viewer offers
//! eframe's), the image in the session's GPU buffer is the image
//! `Session::render` returns, before and after a deformation, and the CPU
//! session's within the ray caster's CPU/GPU tolerance. Skips without an
//! adapter (fails under CI=true, as every GPU test).

use voxflex_core::gpu::GpuService;
use voxflex_integration_tests::{plugin_dir, session_on};
use voxflex_phantom::phantom;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::gpu_context::testing::test_gpu;
use voxflex_runtime::session::{Interaction, RenderParams, Session, SessionDefaults};

const CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.01 }]\n\
                         propagation_iterations = 40\n";
const RENDER: &str = "transfer_function = { points = [[0, 0, 0, 0, 0], [100, 1, 0.5, 0.2, 0.3], [150, 1, 1, 1, 1]] }\n";

fn session(
    backend: BackendChoice,
    gpu: Option<std::sync::Arc<voxflex_runtime::gpu_context::WgpuService>>,
) -> Session {
    let cube = phantom("cube", [20, 20, 20]).unwrap();
    session_on(cube, backend, gpu, &["chainmail", "raycast"])
}

fn max_diff(a: &[u8], b: &[u8]) -> u8 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap_or(0)
}

#[test]
fn render_to_gpu_writes_the_image_render_returns() {
    let Some(gpu) = test_gpu() else { return };
    let params = RenderParams {
        plugin: "raycast".into(),
        params_toml: RENDER.into(),
    };
    let mut cpu = session(BackendChoice::Cpu, Some(gpu.clone()));
    let camera = cpu.default_camera(64, 48).unwrap();
    let e = cpu.render_to_gpu(&camera, &params).unwrap_err().to_string();
    assert!(e.contains("set_backend"), "{e}");
    let on_cpu = cpu.render(&camera, &params).unwrap();

    let mut s = session(BackendChoice::Gpu, Some(gpu.clone()));
    assert!(
        s.wgpu().is_some_and(|g| g.same_device(&gpu)),
        "the offered device"
    );
    let read = |s: &mut Session, w: u32, h: u32| {
        let camera = s.default_camera(w, h).unwrap();
        let id = s.render_to_gpu(&camera, &params).unwrap();
        let mut bytes = vec![0u8; (w * h * 4) as usize];
        gpu.read_buffer(id, 0, &mut bytes).unwrap();
        (id, bytes)
    };
    let (id, on_gpu) = read(&mut s, 64, 48);
    assert_eq!(on_gpu, s.render(&camera, &params).unwrap().pixels);
    let lit = on_gpu.chunks(4).filter(|p| p[3] > 0).count();
    let alpha = on_gpu.chunks(4).map(|p| p[3]).max();
    assert!(
        lit > 100,
        "the cube shows: {lit} pixels, largest alpha {alpha:?}"
    );
    let d = max_diff(&on_gpu, &on_cpu.pixels);
    assert!(d <= 2, "GPU vs CPU render: largest difference {d}");
    // The buffer is the session's: reused at the same size, replaced at another.
    assert_eq!(read(&mut s, 64, 48).0, id);
    assert_ne!(read(&mut s, 32, 32).0, id);

    // After a deformation: only the re-filled region is handed over, and
    // the buffer still holds what `render` returns.
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    s.step().unwrap();
    s.interact(&Interaction::Grab {
        point: [22.5, 2.5, 2.5],
        to: [35.0, 2.5, 2.5],
        frames: 1,
    })
    .unwrap();
    for _ in 0..5 {
        s.step().unwrap();
    }
    let (last, moved) = read(&mut s, 64, 48);
    assert_ne!(moved, on_gpu, "the drag shows");
    assert_eq!(moved, s.render(&camera, &params).unwrap().pixels);
    // Drawn from the resampler's GPU buffer, it is the image of the same
    // volume read back and uploaded by a fresh GPU session.
    let volume = s.volume().unwrap().clone();
    let mut fresh = Session::from_volume(
        volume,
        SessionDefaults {
            backend: BackendChoice::Gpu,
            plugin_dirs: vec![plugin_dir(&["raycast"])],
            gpu: Some(gpu.clone()),
            ..SessionDefaults::default()
        },
    )
    .unwrap();
    let d = max_diff(&moved, &fresh.render(&camera, &params).unwrap().pixels);
    assert!(
        d <= 1,
        "from the GPU buffer vs uploaded: largest difference {d}"
    );
    // A backend switch frees the buffer; the CPU path refuses again.
    s.set_backend(BackendChoice::Cpu).unwrap();
    assert!(gpu.buffer_size(last).is_err(), "the image buffer was freed");
    assert!(s.render_to_gpu(&camera, &params).is_err());
}
