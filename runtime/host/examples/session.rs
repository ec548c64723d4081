//! Drives one `Session` the way a front end does: a phantom, a ChainMail
//! model swapped in, an ROI map grown to the end, a 10-call drag, a cut, a
//! render and a slice click — everything in memory.
//!
//! ```text
//! cargo build --release                      # builds the plugins too
//! VOXFLEX_PLUGIN_PATH=target/release cargo run --release -p voxflex-runtime --example session
//! ```
//!
//! (Plugins are found as for scenes: `SessionDefaults::plugin_dirs`, then
//! `VOXFLEX_PLUGIN_PATH`, then the executable's directory — an example's
//! directory is `target/<profile>/examples`, hence the variable.)

use voxflex_core::glam::DVec3;
use voxflex_io::png::SliceAxis;
use voxflex_opacity::{GrowthParams, Seed};
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::session::{
    Interaction, RenderParams, Session, SessionDefaults, SessionSource,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A 20³ cube phantom (100 mm field, the cube from −25 to 25 mm).
    let mut s = Session::from_volume(
        SessionSource::Phantom {
            name: "cube".into(),
            dims: [20, 20, 20],
        },
        SessionDefaults {
            backend: BackendChoice::Cpu,
            ..Default::default()
        },
    )?;
    s.swap_model(
        "chainmail",
        "materials = [{ range = [50, 200], constraint = 0.01 }]\npropagation_iterations = 40",
    )?;
    let roi = s.add_roi(
        Seed::World(DVec3::new(-12.5, 2.5, 2.5)),
        GrowthParams::default(),
    )?;
    s.roi_run_to_end(roi)?;

    // Drag the +x face 15 mm out over 10 calls: the same grab, a new target each call.
    for k in 1..=10 {
        s.interact(&Interaction::Grab {
            point: [22.5, 2.5, 2.5],
            to: [22.5 + 1.5 * k as f64, 2.5, 2.5],
            frames: 1,
        })?;
        let report = s.step()?;
        println!("{report}"); // what re-ran and why
    }
    s.interact(&Interaction::Cut {
        polygon: vec![
            [20., -60., -60.],
            [20., 60., -60.],
            [20., 60., 60.],
            [20., -60., 60.],
        ],
    })?;
    s.step()?;

    let camera = s.default_camera(256, 256)?;
    let image = s.render(&camera, &RenderParams::default())?; // RGBA8 in memory
    let slice = s.slice(SliceAxis::Axial, 10, None)?; // 8-bit, one pixel per voxel
    let click = slice.pixel_to_world(5, 7); // world mm under a click
    println!(
        "{}×{} render, click at {click:?}",
        image.width, image.height
    );
    println!("{}", s.metrics()?.to_json()); // the metrics.json figures
    Ok(())
}
