//! `voxflex-viewer [scene.toml | volume file]`: the desktop explorer.

use anyhow::Context;
use clap::Parser;
use voxflex_core::glam::DVec3;
use voxflex_viewer::app::ViewerApp;
use voxflex_viewer::cli::Args;
use voxflex_viewer::gpu_image::{self, GpuImage};
use voxflex_viewer::open::OpenRequest;
use voxflex_viewer::screenshot::Screenshot;

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,wgpu_core=warn,wgpu_hal=warn,naga=warn".into()),
        )
        .init();
    let args = Args::parse();
    if let Some(png) = &args.check_png {
        let n = voxflex_viewer::screenshot::check_not_blank(png)?;
        println!("{}: {n} distinct colours: not blank", png.display());
        return Ok(());
    }
    if let Some(kind) = args.bench {
        let opts = voxflex_viewer::bench::BenchOptions {
            out: args.out.clone(),
            seconds: args.seconds,
            size: args.size,
            render_size: args.render_size,
            plugin_dirs: vec![],
        };
        return voxflex_viewer::bench::run(kind, &opts);
    }
    let backend = args
        .backend
        .parse()
        .map_err(|e| anyhow::anyhow!("--backend {}: {e}", args.backend))?;
    let req = OpenRequest {
        input: args.input.clone(),
        backend,
        plugin_dirs: vec![],
        gpu: None,
        oblique: args.oblique,
    };
    let screenshot = Screenshot::new(args.screenshot.clone(), args.exit_after_frames);
    let outcome = screenshot.outcome();
    let seed = args.seed_roi;
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("voxflex viewer")
            .with_inner_size([1280.0, 860.0]),
        // The session computes on eframe's device: the adapter's own limits.
        wgpu_options: eframe::egui_wgpu::WgpuConfiguration {
            wgpu_setup: gpu_image::wgpu_setup(),
            ..Default::default()
        },
        ..Default::default()
    };
    eframe::run_native(
        "voxflex-viewer",
        options,
        Box::new(move |cc| {
            let mut req = req;
            let gpu = GpuImage::share(cc.wgpu_render_state.as_ref(), &mut req);
            let app = ViewerApp::new(&cc.egui_ctx, req, screenshot)?
                .with_gpu_image(gpu)
                .with_startup_seed(seed.map(DVec3::from_array));
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| anyhow::anyhow!("{e}"))
    .context("running the viewer window")?;
    if args.screenshot.is_some() {
        match outcome.lock().ok().and_then(|o| o.clone()) {
            Some(Ok(())) => {}
            Some(Err(e)) => anyhow::bail!(e),
            None => anyhow::bail!("the window closed before the screenshot was taken"),
        }
    }
    Ok(())
}
