//! Lends a volume to the ray caster instead of handing it a copy: the
//! renderer keeps a reference count on the host's `Arc<Volume>`, so the
//! volume is in memory once and the first frame skips the copy.
//!
//! ```text
//! cargo build --release                      # builds the plugins too
//! VOXFLEX_PLUGIN_PATH=target/release cargo run --release -p voxflex-runtime --example lend_volume
//! ```

use std::sync::Arc;
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::render::RenderVolume;
use voxflex_core::shared_volume::SharedVolume;
use voxflex_runtime::plugin_loader;
use voxflex_runtime::visualise::{RenderStage, camera_for, write_rgba_png};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A 256 × 256 × 96 head phantom (i16 HU), never changed: it can be lent.
    let volume = Arc::new(voxflex_phantom::phantom("head", [256, 256, 96])?);
    let lent = SharedVolume::new(volume.clone());

    let plugin = plugin_loader::load_by_name("raycast", &plugin_loader::search_path(&[]))?;
    let services = voxflex_abi::host_side::HostServices::new(None, rayon::current_num_threads());
    let params = "transfer_function = { preset = \"ct-bone\" }";
    let mut stage = RenderStage::new(
        "lend_volume",
        &plugin,
        params,
        services,
        ExecutionBackend::Cpu,
    )?;

    let t = std::time::Instant::now();
    stage.set_scene_on(RenderVolume::Shared(&lent), DirtyRegion::All, &[])?;
    println!(
        "handed over in {:.1} ms; holders of the volume: {} (this program, its SharedVolume, the renderer)",
        t.elapsed().as_secs_f64() * 1e3,
        Arc::strong_count(&volume)
    );
    let settings = voxflex_runtime::scene::RenderSettings {
        plugin: "raycast".into(),
        width: 384,
        height: 384,
        camera: Default::default(),
        turntable: 0,
        file: "lent.png".into(),
        params: Default::default(),
    };
    let (image, stats) = stage.render_image(&camera_for(&settings, &volume.grid, 0.0))?;
    let out = std::env::temp_dir().join("voxflex_lent.png");
    write_rgba_png(&out, &image)?;
    println!(
        "{} rays, {} samples → {}",
        stats.rays,
        stats.samples,
        out.display()
    );

    // The renderer lets go of the loan when it is dropped.
    drop(stage);
    println!("after the renderer: {} holders", Arc::strong_count(&volume));
    Ok(())
}
