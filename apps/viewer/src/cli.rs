//! The command line: what to open and the screenshot mode for CI.

use clap::Parser;
use std::path::PathBuf;

/// `voxflex-viewer [scene.toml | volume file]`.
#[derive(Parser, Debug, Clone, Default)]
#[command(
    name = "voxflex-viewer",
    version,
    about = "Explore, deform and grow ROI opacity maps on CT/MRI volumes"
)]
pub struct Args {
    /// A scene (`.toml`) or a volume file (NIfTI, MetaImage, NRRD); none
    /// opens the built-in head phantom.
    pub input: Option<PathBuf>,
    /// Save the window as this PNG after `--exit-after-frames` frames, then exit.
    #[arg(long, value_name = "PNG")]
    pub screenshot: Option<PathBuf>,
    /// Frames to draw before the screenshot (or before exiting).
    #[arg(long, value_name = "N")]
    pub exit_after_frames: Option<u64>,
    /// Check that a screenshot PNG is not blank, print its colour count, and exit.
    #[arg(long, value_name = "PNG")]
    pub check_png: Option<PathBuf>,
    /// Backend the session computes on: cpu, gpu or auto.
    #[arg(long, default_value = "cpu")]
    pub backend: String,
}
