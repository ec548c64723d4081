//! `voxflex-viewer --bench drag|interactive|open [--out DIR]`: the
//! viewer's performance requirements (issue 15) as benchmarks anyone can
//! run. Each drives the real viewer — [`crate::app::ViewerApp`]'s update
//! loop, its worker thread and the `Session` — headless (an egui context
//! fed scripted input at 60 Hz, no window), and writes its figures as
//! `<bench>.json` and `<bench>.md` into the output folder with the
//! command, the cores and the load average. Timing lives here, never in
//! tests. See docs/BENCHMARKS.md#viewer-performance.

pub mod drag;
pub mod headless;
pub mod interactive;
pub mod open;
pub mod report;
pub mod scene;
pub mod script;
pub mod stats;

use std::path::PathBuf;

/// Which benchmark to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchKind {
    /// UI-thread frame times during a scripted grab drag.
    Drag,
    /// Deform + resample + render cycles per second while dragging, and
    /// the idle full-quality render.
    Interactive,
    /// A CT-like volume file to the first rendered 3D frame.
    Open,
}

/// What a benchmark runs on.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Where the tables (and the benchmark's inputs) are written.
    pub out: PathBuf,
    /// Length of the scripted drag, s.
    pub seconds: f64,
    /// Volume size, voxels a side (`None`: the benchmark's default).
    pub size: Option<usize>,
    /// The 3D view's full-quality size, pixels a side.
    pub render_size: u32,
    /// Directories searched for plugins first.
    pub plugin_dirs: Vec<PathBuf>,
}

/// Runs benchmark `kind`, writes its tables into `opts.out` and prints
/// the Markdown table.
pub fn run(kind: BenchKind, opts: &BenchOptions) -> anyhow::Result<()> {
    anyhow::ensure!(
        opts.seconds > 0.0 && opts.seconds.is_finite(),
        "--seconds {}: give a positive number of seconds",
        opts.seconds
    );
    anyhow::ensure!(
        opts.size.is_none_or(|n| n >= 8),
        "--size {}: give at least 8 voxels a side",
        opts.size.unwrap_or(0)
    );
    anyhow::ensure!(
        opts.render_size >= 16,
        "--render-size {}: give at least 16 pixels",
        opts.render_size
    );
    let report = match kind {
        BenchKind::Drag => drag::run(opts)?,
        BenchKind::Interactive => interactive::run(opts)?,
        BenchKind::Open => open::run(opts)?,
    };
    let (json, md) = report.write(&opts.out)?;
    print!("{}", std::fs::read_to_string(&md)?);
    tracing::info!("wrote {} and {}", json.display(), md.display());
    Ok(())
}
