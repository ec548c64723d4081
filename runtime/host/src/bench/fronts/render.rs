//! The `render` front: image error of the `raycast` plugin against a
//! converged reference, per ray step and filter option, against the time
//! of a frame (CPU path).
//!
//! Scene: the partial-volume head phantom, `ct-bone`, shaded, black
//! background, the demo's camera (azimuth 30°, elevation 15°,
//! orthographic). Reference: step 1/16 voxel, tricubic B-spline sampling,
//! Sobel gradients, no jitter — the best filters at a step where a further
//! halving changes the 8-bit image by less than the errors measured here;
//! jitter is off because it trades structured error for per-pixel noise
//! that does not vanish within one frame, and a reference must be the
//! limit the configurations converge to. Error: RMS (and max) over the
//! R, G, B, A channels in [0, 1] of the 8-bit images (sRGB, straight
//! alpha — what the PNG holds). Time: median wall time of a frame after a
//! warm-up, CPU backend. GPU timings are not taken: on a software adapter
//! (lavapipe) they say nothing.

use super::runner::Plugins;
use super::{Front, Point};
use crate::bench::{BenchError, err};
use crate::plugin_loader;
use crate::scene::{CameraSettings, RenderSettings};
use crate::visualise::{RenderStage, RgbaImage, camera_for};
use std::time::Instant;
use voxflex_abi::host_side::HostServices;
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::volume::Volume;
use voxflex_phantom::phantom;

/// Ray steps, voxels.
const STEPS: [f64; 4] = [0.25, 0.5, 1.0, 2.0];

/// The reference's step, voxels.
const REFERENCE_STEP: f64 = 1.0 / 16.0;

/// The option sets compared: series name and `[render]` keys.
const OPTIONS: [(&str, &str); 6] = [
    ("central trilinear", "gradient = \"central\""),
    ("sobel", "gradient = \"sobel\""),
    (
        "tricubic",
        "sampling = \"tricubic\"\ngradient = \"central\"",
    ),
    ("jitter", "jitter = true\ngradient = \"central\""),
    (
        "tricubic sobel",
        "sampling = \"tricubic\"\ngradient = \"sobel\"",
    ),
    (
        "tricubic sobel jitter",
        "sampling = \"tricubic\"\ngradient = \"sobel\"\njitter = true",
    ),
];

/// The renderer's defaults: step 0.5, Sobel gradients, trilinear, no jitter.
const DEFAULT: (&str, f64) = ("sobel", 0.5);

/// The scene's `[render.params]` apart from the step and the filters.
const BASE: &str = "transfer_function = { preset = \"ct-bone\" }\nbackground = [0, 0, 0]\n";

/// RMS and max absolute difference over all channels, in [0, 1].
fn image_error(a: &RgbaImage, b: &RgbaImage) -> (f64, f64) {
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for (x, y) in a.pixels.iter().zip(&b.pixels) {
        let d = (*x as f64 - *y as f64).abs() / 255.0;
        sum += d * d;
        max = max.max(d);
    }
    ((sum / a.pixels.len().max(1) as f64).sqrt(), max)
}

/// Renders `volume` with `params` (`repeat` timed frames after a warm-up):
/// the image, the median frame time (ms) and the samples of a frame.
fn render(
    plugins: &Plugins,
    volume: &Volume,
    settings: &RenderSettings,
    params: &str,
    repeat: usize,
) -> Result<(RgbaImage, f64, u64), BenchError> {
    let what = |e: &dyn std::fmt::Display| err(format!("render front ({params:?}): {e}"));
    let plugin =
        plugin_loader::load_by_name("raycast", &plugins.search_path()).map_err(|e| what(&e))?;
    let services = HostServices::new(None, rayon::current_num_threads());
    let mut stage = RenderStage::new(
        "render front",
        &plugin,
        params,
        services,
        ExecutionBackend::Cpu,
    )
    .map_err(|e| what(&e))?;
    stage
        .set_scene(volume, DirtyRegion::All, &[])
        .map_err(|e| what(&e))?;
    let camera = camera_for(settings, &volume.grid, 0.0);
    let (mut image, stats) = stage.render_image(&camera).map_err(|e| what(&e))?;
    let mut times = Vec::with_capacity(repeat);
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        image = stage.render_image(&camera).map_err(|e| what(&e))?.0;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok((image, times[times.len() / 2], stats.samples))
}

/// The render front.
pub(super) fn front(plugins: &Plugins, quick: bool) -> Result<Front, BenchError> {
    let (dims, side, repeat) = if quick {
        ([40, 48, 44], 64, 1)
    } else {
        ([100, 120, 110], 384, 5)
    };
    let volume = phantom("head", dims).map_err(err)?;
    let settings = RenderSettings {
        plugin: "raycast".into(),
        width: side,
        height: side,
        camera: CameraSettings {
            azimuth_deg: 30.0,
            elevation_deg: 15.0,
            ..CameraSettings::default()
        },
        turntable: 0,
        file: "render.png".into(),
        params: Default::default(),
    };
    let reference_params = format!(
        "{BASE}sample_distance = {REFERENCE_STEP}\n{}\n",
        OPTIONS[4].1
    );
    let (reference, ref_ms, _) = render(plugins, &volume, &settings, &reference_params, 1)?;
    let mut points = vec![];
    for (series, keys) in OPTIONS {
        for step in STEPS {
            let params = format!("{BASE}sample_distance = {step}\n{keys}\n");
            let (image, time_ms, samples) = render(plugins, &volume, &settings, &params, repeat)?;
            let (rms, max) = image_error(&image, &reference);
            points.push(Point {
                series: series.to_string(),
                config: format!("step {step}"),
                time_ms,
                error: rms,
                is_default: (series, step) == DEFAULT,
                group: String::new(),
                extra: vec![
                    ("step_voxels", step.to_string()),
                    ("max_abs", format!("{max:.4}")),
                    ("samples", samples.to_string()),
                ],
                tuning: None,
            });
        }
    }
    Ok(Front {
        key: "render",
        title: "ray casting: image error vs time per frame, per step and filter".into(),
        error_label: "RMS error, RGBA 0–1".into(),
        description: format!(
            "`phantom:head` (partial-volume edges) at {dims:?} voxels, `ct-bone`, shaded, the \
             demo's camera, {side}² pixels, CPU path ({} threads). Reference: step \
             {REFERENCE_STEP} voxel, tricubic B-spline sampling, Sobel gradients, no jitter \
             ({ref_ms:.0} ms). Error: RMS over R, G, B, A in [0, 1] of the 8-bit images \
             (`max_abs`: the largest channel difference). Time: median of {repeat} frames \
             after a warm-up. One series per option set over steps {STEPS:?} voxels; the \
             renderer's default (step 0.5, Sobel gradients, trilinear, no jitter) is \
             ringed. GPU timings are not taken (meaningless on a software adapter).",
            rayon::current_num_threads()
        ),
        points,
    })
}
