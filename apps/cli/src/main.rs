//! `voxflex`: run scenes, validate them, list plugins, inspect volumes and
//! benchmark the pipeline.
//!
//! Exit code 0 on success; on failure, one line naming the cause on stderr
//! and exit code 1 (2 for command-line usage errors, from clap).

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use voxflex_runtime::pipeline::{RunOptions, run_scene};
use voxflex_runtime::scene::Scene;
use voxflex_runtime::{bench, plugin_loader};

#[derive(Parser)]
#[command(
    name = "voxflex",
    version,
    about = "Deform, cut and render volumetric images with swappable plugins."
)]
struct Cli {
    /// Log filter (e.g. `info`, `voxflex=debug`); RUST_LOG also works.
    #[arg(long, global = true, default_value = "warn")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene file: load, deform, resample, write slices, NIfTI and metrics.json.
    Run {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Output directory (overrides `[output] dir`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Re-run even when the outputs are up to date.
        #[arg(long)]
        force: bool,
    },
    /// Check a scene file (keys, values, plugin and source presence) without running it.
    Validate {
        /// Scene file (TOML).
        scene: PathBuf,
    },
    /// List the plugins found on the search path (name, kind, version, ABI, capabilities, path).
    Plugins {
        /// Extra directories to search first.
        #[arg(long = "dir")]
        dirs: Vec<PathBuf>,
    },
    /// Describe a volume file or phantom: dims, spacing, value range, histogram summary.
    Info {
        /// A volume file (.nii, .nii.gz, .mhd, .nrrd) or `phantom:<name>`.
        volume: String,
        /// Phantom resolution (x,y,z), phantoms only.
        #[arg(long, value_delimiter = ',')]
        dims: Option<Vec<usize>>,
    },
    /// Benchmark the resampling pipeline through the real plugin path.
    Bench(bench::BenchArgs),
}

fn main() {
    let cli = Cli::parse();
    quiet_window_system_probes();
    // wgpu's GL backend reports a missing EGL display as an error while it
    // probes adapters; that is not the user's problem unless they ask.
    let filter = std::env::var("RUST_LOG").unwrap_or_else(|_| format!("{},wgpu_hal=off", cli.log));
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(filter))
        .with_writer(std::io::stderr)
        .init();
    if let Err(e) = dispatch(cli.command) {
        // One line: the chain of causes, joined.
        let chain: Vec<String> = e.chain().map(|c| c.to_string()).collect();
        eprintln!("error: {}", chain.join(": "));
        std::process::exit(1);
    }
}

/// Without `XDG_RUNTIME_DIR`, probing GPU adapters makes EGL/Wayland print
/// warnings straight to stderr. Point it at a private directory when unset.
fn quiet_window_system_probes() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("voxflex-xdg-{}", std::process::id()));
    let mut builder = std::fs::DirBuilder::new();
    #[cfg(unix)]
    std::os::unix::fs::DirBuilderExt::mode(&mut builder, 0o700);
    if builder.recursive(true).create(&dir).is_ok() {
        // SAFETY: called first thing in main, before any other thread exists.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    }
}

fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::Run { scene, out, force } => run(scene, out, force),
        Command::Validate { scene } => validate(scene),
        Command::Plugins { dirs } => plugins(dirs),
        Command::Info { volume, dims } => info(volume, dims),
        Command::Bench(args) => {
            let report = bench::run(&args)?;
            println!("{report}");
            Ok(())
        }
    }
}

fn run(path: PathBuf, out: Option<PathBuf>, force: bool) -> Result<()> {
    let scene = Scene::load(&path)?;
    let bar = ProgressBar::new(scene.settings.frames);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{bar:30}] frame {pos}/{len} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(scene.settings.name.clone());
    let progress_bar = bar.clone();
    let metrics = run_scene(
        &scene,
        RunOptions {
            out_dir: out.clone(),
            force,
            progress: Some(Box::new(move |done, _| progress_bar.set_position(done))),
        },
    )?;
    bar.finish_and_clear();
    let dir = out.unwrap_or_else(|| scene.output.clone().unwrap_or_default().dir);
    if metrics.up_to_date {
        println!(
            "{}: up to date in {} (use --force to re-run)",
            scene.settings.name,
            dir.display()
        );
    } else {
        println!(
            "{}: {} frames on the {} path in {:.0} ms → {}",
            scene.settings.name,
            metrics.frames,
            metrics.backend,
            metrics.total_wall_ms,
            dir.display()
        );
        for (name, s) in &metrics.stages {
            println!(
                "  {name:<9} runs {:>4}  skipped {:>4}  {:>9.1} ms  {:>11} voxels",
                s.runs, s.skipped, s.wall_ms, s.voxels_touched
            );
        }
        for f in &metrics.outputs {
            println!("  wrote {}", dir.join(f).display());
        }
    }
    Ok(())
}

fn validate(path: PathBuf) -> Result<()> {
    let scene = Scene::load(&path)?;
    if let Some(m) = &scene.model {
        let dirs = plugin_loader::search_path(&scene.plugin_dirs());
        let p = plugin_loader::load_by_name(&m.plugin, &dirs)
            .with_context(|| format!("{}: [model] plugin", path.display()))?;
        if p.deformation.is_none() {
            bail!(
                "{}: [model] plugin `{}` is a {} plugin, not a deformation plugin",
                path.display(),
                p.name,
                p.kind_name()
            );
        }
    }
    if let voxflex_core::phantom::VolumeSource::File(f) =
        voxflex_core::phantom::parse_source(&scene.volume.source)
    {
        let f = if f.is_absolute() {
            f
        } else {
            scene.base_dir().join(f)
        };
        if !f.is_file() {
            bail!(
                "{}: [volume] source `{}` does not exist",
                path.display(),
                f.display()
            );
        }
    }
    println!("{}: ok", path.display());
    Ok(())
}

fn plugins(dirs: Vec<PathBuf>) -> Result<()> {
    let search = plugin_loader::search_path(&dirs);
    let found = plugin_loader::discover(&search);
    if found.is_empty() {
        println!(
            "no plugins found in: {}",
            search
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
        return Ok(());
    }
    println!(
        "{:<18} {:<12} {:<9} {:<4} {:<10} path",
        "name", "kind", "version", "abi", "backends"
    );
    for p in found {
        match p {
            Ok(p) => println!(
                "{:<18} {:<12} {:<9} v{:<3} {:<10} {}",
                p.name,
                p.kind_name(),
                p.version,
                p.abi_version,
                p.capability_names(),
                p.path.display()
            ),
            Err(e) => println!("(refused) {e}"),
        }
    }
    Ok(())
}

fn info(source: String, dims: Option<Vec<usize>>) -> Result<()> {
    use voxflex_core::phantom::{VolumeSource, parse_source, phantom};
    let volume = match parse_source(&source) {
        VolumeSource::Phantom(name) => {
            let d = match dims.as_deref() {
                Some([x, y, z]) => [*x, *y, *z],
                Some(_) => bail!("--dims needs three numbers: x,y,z"),
                None => [128, 128, 128],
            };
            phantom(&name, d).with_context(|| format!("`{source}`"))?
        }
        VolumeSource::File(p) => {
            if dims.is_some() {
                bail!("--dims applies to phantoms only");
            }
            voxflex_core::io::read_volume(&p, &voxflex_core::io::ReadOptions::default())?
        }
    };
    println!("{source}");
    println!(
        "{}",
        voxflex_core::stats::VolumeStats::compute(volume.view())
    );
    Ok(())
}
