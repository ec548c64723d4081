//! The command line: what to open, the screenshot mode for CI and the
//! performance benchmarks (`--bench`).

use crate::bench::BenchKind;
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
    /// Seed an ROI map at this world point (mm, `X,Y,Z`) and grow it to
    /// the end once the volume is open.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point)]
    pub seed_roi: Option<[f64; 3]>,
    /// Check that a screenshot PNG is not blank, print its colour count, and exit.
    #[arg(long, value_name = "PNG")]
    pub check_png: Option<PathBuf>,
    /// Backend the session computes on: cpu, gpu or auto.
    #[arg(long, default_value = "cpu")]
    pub backend: String,
    /// A volume file whose header is oblique (axes rotated by other than
    /// multiples of 90°): closest-axes (voxels kept, placed along the
    /// closest axes, with a warning), linear or nearest (resampled where
    /// the header puts it). A scene says this in `[volume] oblique`.
    #[arg(long, default_value = "closest-axes")]
    pub oblique: voxflex_io::ObliquePlacement,
    /// Run a performance benchmark headless (no window) through the real
    /// viewer (its update loop, worker and session), write its tables
    /// (JSON and Markdown) into `--out` and exit: `drag` (UI-thread frame
    /// times during a scripted grab drag), `interactive` (deform +
    /// resample + render cycles per second while dragging, and the idle
    /// full-quality frame) or `open` (a CT-like volume file to the first
    /// rendered 3D frame). See docs/BENCHMARKS.md.
    #[arg(long, value_name = "KIND")]
    pub bench: Option<BenchKind>,
    /// Folder the benchmark writes its tables into (created).
    #[arg(long, value_name = "DIR", default_value = "out/viewer-bench")]
    pub out: PathBuf,
    /// Length of the benchmark's scripted drag, seconds.
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub seconds: f64,
    /// Benchmark volume size, voxels a side: the head phantom N³ for
    /// `drag` and `interactive`; N × N × (N·133/512) for `open`
    /// (default 128 and 512).
    #[arg(long, value_name = "N")]
    pub size: Option<usize>,
    /// Pixels a side of the 3D view at full quality during `drag` and
    /// `interactive` (it renders at half while dragging).
    #[arg(long, value_name = "PX", default_value_t = 512)]
    pub render_size: u32,
}

/// Parses `X,Y,Z` (mm).
fn parse_point(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}; give X,Y,Z in mm, e.g. 40,0,15"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!(
            "`{s}`: give three finite numbers X,Y,Z in mm, e.g. 40,0,15"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_point_is_three_numbers() {
        assert_eq!(parse_point("40, 0,-15.5"), Ok([40.0, 0.0, -15.5]));
        assert!(parse_point("1,2").unwrap_err().contains("three"));
        assert!(parse_point("1,x,2").unwrap_err().contains("X,Y,Z"));
        assert!(parse_point("1,inf,2").is_err());
    }
}
