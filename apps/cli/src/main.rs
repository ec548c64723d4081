//! `voxflex`: run scenes, validate them, list plugins, inspect volumes and
//! benchmark the pipeline.
//!
//! Exit code 0 on success; on failure, one line naming the cause on stderr
//! and exit code 1 (2 for command-line usage errors, from clap).

mod bench_args;
mod peers;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use tracing::Level;
use tracing_subscriber::Layer as _;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;
use voxflex_runtime::pipeline::{RunOptions, run_scene};
use voxflex_runtime::scene::Scene;
use voxflex_runtime::{bench, plugin_loader};

/// `println!` that fails instead of panicking when standard output cannot
/// be written (`voxflex plugins > /dev/full`, a full disk): the caller's `?`
/// turns it into the one-line `error:` and exit code 1. It shadows std's
/// macro in this file, so every command's output goes through it; use it
/// only in functions that return `anyhow::Result`.
macro_rules! println {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout(), $($arg)*).context("writing to standard output")?
    }};
}

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
    /// Check a scene file without running it: every error `run` would give about it
    /// (keys, values, interactions, plugin parameters, source, ROI seeds).
    Validate {
        /// Scene file (TOML).
        scene: PathBuf,
    },
    /// List the plugins found on the search path (name, kind, version, ABI, capabilities, path).
    Plugins {
        /// Extra directories to search first.
        #[arg(long = "dir")]
        dirs: Vec<PathBuf>,
        /// Print the parameter table of plugin NAME instead: every key with its
        /// type, unit, range, default and a one-line doc.
        #[arg(long = "params", value_name = "NAME")]
        params: Option<String>,
    },
    /// Describe a volume file or phantom: dims, spacing, value range, histogram summary.
    Info {
        /// A volume file (.nii, .nii.gz, .mhd, .nrrd) or `phantom:<name>`.
        volume: String,
        #[command(flatten)]
        load: LoadArgs,
    },
    /// Grow a spatial opacity map (ROI) from a seed and write it as NIfTI (u16, 65535 = opacity 1).
    Roi {
        /// A volume file or `phantom:<name>`.
        volume: String,
        /// Seed point, world mm: x,y,z.
        #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
        seed: Vec<f64>,
        /// Output file (.nii or .nii.gz).
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        growth: RoiArgs,
        #[command(flatten)]
        load: LoadArgs,
    },
    /// Render a volume with the `raycast` plugin into a PNG (one image or a turntable).
    Render {
        /// A volume file or `phantom:<name>`.
        volume: String,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Transfer-function preset: ct-bone, ct-soft-tissue, ct-lung, mri-t1.
        #[arg(long, default_value = "ct-bone")]
        preset: String,
        /// Maximum intensity projection instead of compositing.
        #[arg(long)]
        mip: bool,
        /// Image size in pixels: WIDTHxHEIGHT.
        #[arg(long, default_value = "512x512")]
        size: String,
        /// Camera azimuth, degrees about +z (0 = anterior view).
        #[arg(long, default_value_t = 30.0, allow_hyphen_values = true)]
        azimuth: f64,
        /// Camera elevation, degrees.
        #[arg(long, default_value_t = 15.0, allow_hyphen_values = true)]
        elevation: f64,
        /// Perspective field of view in degrees (default: orthographic).
        #[arg(long)]
        perspective: Option<f64>,
        /// Turntable frames (0 = one image); files get _000, _001, … suffixes.
        #[arg(long, default_value_t = 0)]
        turntable: u32,
        /// Backend: cpu, gpu or auto.
        #[arg(long, default_value = "auto")]
        backend: voxflex_runtime::backend::BackendChoice,
        #[command(flatten)]
        load: LoadArgs,
        /// Ray step in voxels (`sample_distance`; default 0.5).
        #[arg(long)]
        step: Option<f64>,
        /// Volume sampling: trilinear or tricubic (cubic B-spline).
        #[arg(long)]
        sampling: Option<String>,
        /// Shading gradient: central or sobel (3×3×3).
        #[arg(long)]
        gradient: Option<String>,
        /// Per-pixel ray-start jitter (fixed per pixel): true or false.
        #[arg(long)]
        jitter: Option<bool>,
        /// After the written image, render the same view N more times (not
        /// written) and print each frame's time: the steady per-frame cost.
        #[arg(long, default_value_t = 0)]
        repeat: u32,
    },
    /// Write a built-in phantom as NIfTI (inputs for other tools, e.g. `bench/peers/`).
    Phantom {
        /// Phantom name: head, cube, rings, ramp, abdomen, finger, cylinder, pendulum.
        name: String,
        /// Resolution, voxels: x,y,z.
        #[arg(long, value_delimiter = ',', default_value = "128,128,128")]
        dims: Vec<usize>,
        /// Output file (.nii or .nii.gz).
        #[arg(long)]
        out: PathBuf,
        /// Also write the organ labels (u8) here; abdomen only.
        #[arg(long)]
        labels: Option<PathBuf>,
    },
    /// Resample a volume under an analytic field on the CPU and time only the resample
    /// stage; `--export` writes the source, the result and the exact backward field.
    Resample {
        /// A volume file or `phantom:<name>`.
        volume: String,
        /// Phantom resolution (x,y,z), phantoms only.
        #[arg(long, value_delimiter = ',')]
        dims: Option<Vec<usize>>,
        /// The deformation, about the volume's centre.
        #[arg(long, value_enum, default_value = "twist")]
        field: peers::FieldKind,
        /// The field's angle, degrees (twist and bend: over the z extent).
        #[arg(long, default_value_t = 40.0, allow_hyphen_values = true)]
        angle_deg: f64,
        /// Timed repetitions after one untimed warm-up.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Interpolation: tetrahedral or trilinear (default: the resampler's, trilinear).
        #[arg(long)]
        interpolation: Option<voxflex_resample::Interpolation>,
        /// Write `source.nii`, `resampled.nii` (f32), `backward_{x,y,z}.nii`
        /// (f32 mm: rest point − output voxel centre, LPS) and `resample.json`
        /// (times, grids) into this directory.
        #[arg(long)]
        export: Option<PathBuf>,
    },
    /// Benchmark the resampling pipeline through the real plugin path.
    Bench(bench_args::BenchArgs),
}

fn main() {
    restore_sigpipe();
    let cli = Cli::parse();
    // Removed when main returns or before it exits with an error.
    let runtime_dir = if may_open_a_gpu(&cli.command) {
        quiet_window_system_probes()
    } else {
        None
    };
    // wgpu's GL backend reports a missing EGL display as an error while it
    // probes adapters; that is not the user's problem unless they ask.
    let filter = std::env::var("RUST_LOG").unwrap_or_else(|_| format!("{},wgpu_hal=off", cli.log));
    // The terminal shows what RUST_LOG / --log asks for; every warning of a
    // run also goes into its metrics.json, whatever the filter.
    tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                .with_filter(tracing_subscriber::EnvFilter::new(filter)),
        )
        .with(
            // voxflex's own crates and plugins (a prefix match), not the
            // GPU stack's adapter probing.
            voxflex_runtime::warnings::WarningLayer
                .with_filter(Targets::new().with_target("voxflex", Level::WARN)),
        )
        .init();
    if let Err(e) = dispatch(cli.command) {
        // One line: the chain of causes, joined, skipping a cause whose text
        // the message before it already carries.
        let mut line = String::new();
        for cause in e.chain().map(|c| c.to_string()) {
            if !line.contains(&cause) {
                if !line.is_empty() {
                    line.push_str(": ");
                }
                line.push_str(&cause);
            }
        }
        eprintln!("error: {line}");
        drop(runtime_dir);
        std::process::exit(1);
    }
    drop(runtime_dir);
}

/// Whether `command` may probe GPU adapters (only then is a runtime
/// directory for the window-system probes needed).
fn may_open_a_gpu(command: &Command) -> bool {
    use voxflex_runtime::backend::BackendChoice;
    match command {
        // A scene that cannot be read fails later with the full message.
        Command::Run { scene, .. } => {
            Scene::load(scene).map_or(true, |s| s.settings.backend != BackendChoice::Cpu)
        }
        Command::Bench(_) => true,
        Command::Render { backend, .. } => *backend != BackendChoice::Cpu,
        _ => false,
    }
}

/// Without `XDG_RUNTIME_DIR`, probing GPU adapters makes EGL/Wayland print
/// warnings straight to stderr. Point it at a fresh private directory when
/// unset: created with mode 0700 under a random name (`voxflex-xdg-XXXXXX`
/// in the temp directory, never a predictable path another user could
/// create first), and removed when the returned guard drops. A process
/// killed by a signal leaves it behind.
fn quiet_window_system_probes() -> Option<tempfile::TempDir> {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return None;
    }
    let dir = private_runtime_dir().ok()?;
    // SAFETY: called first thing in main, before any other thread exists.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir.path()) };
    Some(dir)
}

/// A new directory only this user can enter, with an unpredictable name.
fn private_runtime_dir() -> std::io::Result<tempfile::TempDir> {
    let mut b = tempfile::Builder::new();
    b.prefix("voxflex-xdg-");
    #[cfg(unix)]
    b.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o700));
    b.tempdir()
}

fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::Run { scene, out, force } => run(scene, out, force),
        Command::Validate { scene } => validate(scene),
        Command::Plugins {
            dirs,
            params: Some(name),
        } => plugin_params(&name, dirs),
        Command::Plugins { dirs, params: None } => plugins(dirs),
        Command::Info { volume, load } => info(volume, load),
        Command::Roi {
            volume,
            seed,
            out,
            growth,
            load,
        } => roi(volume, load, seed, out, growth),
        Command::Render {
            volume,
            out,
            preset,
            mip,
            size,
            azimuth,
            elevation,
            perspective,
            turntable,
            backend,
            load,
            step,
            sampling,
            gradient,
            jitter,
            repeat,
        } => {
            let (width, height) = size
                .split_once('x')
                .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                .with_context(|| format!("--size `{size}`: use WIDTHxHEIGHT, e.g. 512x512"))?;
            let camera = voxflex_runtime::scene::CameraSettings {
                azimuth_deg: azimuth,
                elevation_deg: elevation,
                projection: if perspective.is_some() {
                    voxflex_runtime::scene::ProjectionName::Perspective
                } else {
                    voxflex_runtime::scene::ProjectionName::Orthographic
                },
                fov_deg: perspective.unwrap_or(30.0),
                ..Default::default()
            };
            let mut params = format!(
                "mode = \"{}\"\ntransfer_function = {{ preset = \"{preset}\" }}\nbackground = [0, 0, 0]\n",
                if mip { "mip" } else { "composite" }
            );
            params.push_str(&filter_keys(step, sampling, gradient, jitter));
            render(
                volume, load, out, params, width, height, camera, turntable, backend, repeat,
            )
        }
        Command::Phantom {
            name,
            dims,
            out,
            labels,
        } => {
            let report = peers::phantom(&name, &dims, &out, labels.as_deref())?;
            println!("{report}");
            Ok(())
        }
        Command::Resample {
            volume,
            dims,
            field,
            angle_deg,
            repeat,
            interpolation,
            export,
        } => {
            let report = peers::resample(peers::ResampleArgs {
                volume,
                dims,
                field,
                angle_deg,
                repeat,
                interpolation,
                export,
            })?;
            println!("{report}");
            Ok(())
        }
        Command::Bench(args) => {
            let report = bench::run(&args.into())?;
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

/// Everything `run` would refuse about the scene file, without running it
/// (see `voxflex_runtime::preflight`): keys and values, every interaction,
/// the plugins' own parameter tables, the source, and the ROI seeds.
fn validate(path: PathBuf) -> Result<()> {
    let scene = Scene::load(&path)?;
    voxflex_runtime::preflight::check(&scene)?;
    println!("{}: ok", path.display());
    Ok(())
}

/// `voxflex plugins --params NAME`: the keys of a plugin's parameter table.
fn plugin_params(name: &str, dirs: Vec<PathBuf>) -> Result<()> {
    let p = plugin_loader::load_by_name(name, &plugin_loader::search_path(&dirs))?;
    let table = match p.kind_name() {
        "renderer" => "[render.params]",
        "actuator" => "[actuator.params]",
        _ => "[model.params]",
    };
    println!(
        "{} {} — the keys of its {table} table:\n",
        p.name, p.version
    );
    print!("{}", p.params.to_text());
    Ok(())
}

fn plugins(dirs: Vec<PathBuf>) -> Result<()> {
    let search = plugin_loader::search_path(&dirs);
    let found = plugin_loader::list(&search);
    if found.plugins.is_empty() && found.refused.is_empty() {
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
    for l in &found.plugins {
        let p = &l.plugin;
        println!(
            "{:<18} {:<12} {:<9} v{:<3} {:<10} {}",
            p.name,
            p.kind_name(),
            p.version,
            p.abi_version,
            p.capability_names(),
            p.path.display()
        );
        if !l.loads {
            println!(
                "  (not loadable as `{}`: scenes look for the file name {})",
                p.name,
                plugin_loader::library_file_name(&p.name)
            );
        }
        for s in &l.shadowed {
            if l.loads {
                println!(
                    "  (shadowed) {} also declares `{}`; scenes get {}",
                    s.display(),
                    p.name,
                    p.path.display()
                );
            } else {
                println!("  (also) {} declares `{}`", s.display(), p.name);
            }
        }
    }
    for e in &found.refused {
        println!("(refused) {e}");
    }
    Ok(())
}

/// How a command that reads a volume directly loads it.
#[derive(clap::Args, Clone, Debug, Default)]
pub(crate) struct LoadArgs {
    /// Phantom resolution (x,y,z), phantoms only.
    #[arg(long, value_delimiter = ',')]
    pub dims: Option<Vec<usize>>,
    /// A file whose header is oblique (axes rotated by other than multiples
    /// of 90°): closest-axes (voxels kept, placed along the closest axes,
    /// with a warning), linear or nearest (resampled where the header puts
    /// it; nearest for label maps).
    #[arg(long, default_value = "closest-axes")]
    pub oblique: voxflex_io::ObliquePlacement,
}

pub(crate) fn load_volume(source: &str, load: LoadArgs) -> Result<voxflex_core::volume::Volume> {
    use voxflex_phantom::{VolumeSource, parse_source, phantom};
    let LoadArgs { dims, oblique } = load;
    Ok(match parse_source(source) {
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
            let opts = voxflex_io::ReadOptions {
                oblique,
                ..Default::default()
            };
            voxflex_io::read_volume(&p, &opts)?
        }
    })
}

fn info(source: String, load: LoadArgs) -> Result<()> {
    let volume = load_volume(&source, load)?;
    println!("{source}");
    println!(
        "{}",
        voxflex_core::stats::VolumeStats::compute(volume.view())
    );
    Ok(())
}

/// The growth options of `voxflex roi`.
#[derive(clap::Args)]
struct RoiArgs {
    /// Extinction scale λ: `auto` (the plateau rule; default) or a
    /// positive number (the paper's is 30).
    #[arg(long, default_value = "auto")]
    lambda: String,
    /// Intensity window lo,hi (volume units): voxels outside never rise above o_min.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    intensity: Option<Vec<f32>>,
    /// Largest Euclidean distance from the seed (mm) a raised voxel may have.
    #[arg(long, allow_hyphen_values = true)]
    max_distance_mm: Option<f64>,
    /// Opacity outside the region.
    #[arg(long, default_value_t = 0.03)]
    o_min: f32,
    /// Opacity of the seed.
    #[arg(long, default_value_t = 1.0)]
    o_max: f32,
    /// Half-width (voxels) of the cube around the seed whose mean and σ set
    /// the extinction: 1 is the paper's 1-ring; 2 measures σ on 125 voxels.
    #[arg(long, default_value_t = 2)]
    seed_radius: u32,
    /// Neighbours that pass opacity on: 6 (faces only: no leak through a
    /// diagonal contact) or 26 (the paper's).
    #[arg(long, default_value_t = 6)]
    connectivity: u32,
    /// Growth steps (default: run to convergence).
    #[arg(long)]
    steps: Option<usize>,
}

fn roi(source: String, load: LoadArgs, seed: Vec<f64>, out: PathBuf, a: RoiArgs) -> Result<()> {
    use voxflex_opacity::{GrowthLimits, GrowthParams, LambdaChoice, RoiRequest, Seed, grow_roi};
    let [x, y, z] = seed[..] else {
        bail!("--seed needs three millimetre coordinates: x,y,z");
    };
    let name = out.to_string_lossy();
    if !(name.ends_with(".nii") || name.ends_with(".nii.gz")) {
        bail!("--out `{name}` must end in .nii or .nii.gz");
    }
    let lambda = match a.lambda.trim() {
        "auto" => LambdaChoice::Auto,
        l => match l.parse::<f32>() {
            Ok(v) if v.is_finite() && v > 0.0 => LambdaChoice::Fixed(v),
            _ => bail!("--lambda `{l}` must be a positive number or `auto`"),
        },
    };
    let intensity = match a.intensity.as_deref() {
        None => None,
        Some(&[lo, hi]) => Some([lo, hi]),
        Some(_) => bail!("--intensity needs two values: lo,hi"),
    };
    let volume = load_volume(&source, load)?;
    let req = RoiRequest {
        seed: Seed::World(voxflex_core::glam::DVec3::new(x, y, z)),
        params: GrowthParams {
            o_min: a.o_min,
            o_max: a.o_max,
            seed_radius: a.seed_radius,
            connectivity: a.connectivity,
            ..GrowthParams::default()
        },
        lambda,
        limits: GrowthLimits {
            intensity,
            max_distance_mm: a.max_distance_mm,
        },
        steps: a.steps,
    };
    let grow = std::time::Instant::now();
    let o = grow_roi(volume.view(), &req, None)?;
    let grow_ms = grow.elapsed().as_secs_f64() * 1e3;
    for w in o.warnings() {
        eprintln!("warning: {w}");
    }
    let (report, map) = (o.grown.report, &o.grown.map);
    let written = voxflex_runtime::visualise::map_volume(&volume.grid, map);
    voxflex_io::write_volume(&out, written.view())?;
    println!(
        "{}: lambda {}{}, {} ({}), {} voxels ≥ 0.5, {} visits ({:.0}% useful), map box {:?} ({} bytes), made in {grow_ms:.1} ms → {}",
        source,
        o.lambda,
        if o.auto.is_some() { " (auto)" } else { "" },
        o.stop(),
        if o.from_scan() {
            "written from the lambda scan".to_string()
        } else {
            format!("{} steps", report.steps)
        },
        o.voxels,
        report.visits,
        100.0 * report.useful as f64 / report.visits.max(1) as f64,
        map.dims,
        map.bytes(),
        out.display()
    );
    Ok(())
}

/// The `[render]` keys of `voxflex render`'s filter flags (the renderer
/// checks the values and names the key in its error).
fn filter_keys(
    step: Option<f64>,
    sampling: Option<String>,
    gradient: Option<String>,
    jitter: Option<bool>,
) -> String {
    let mut out = String::new();
    if let Some(s) = step {
        out.push_str(&format!("sample_distance = {s:?}\n"));
    }
    for (key, v) in [("sampling", sampling), ("gradient", gradient)] {
        if let Some(v) = v {
            out.push_str(&format!("{key} = {v:?}\n"));
        }
    }
    if let Some(j) = jitter {
        out.push_str(&format!("jitter = {j}\n"));
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn render(
    source: String,
    load: LoadArgs,
    out: PathBuf,
    params_toml: String,
    width: u32,
    height: u32,
    camera: voxflex_runtime::scene::CameraSettings,
    turntable: u32,
    backend: voxflex_runtime::backend::BackendChoice,
    repeat: u32,
) -> Result<()> {
    use voxflex_runtime::scene::RenderSettings;
    let name = out.to_string_lossy().into_owned();
    if !name.ends_with(".png") {
        bail!("--out `{name}` must end in .png");
    }
    use voxflex_runtime::scene::{MAX_IMAGE_SIDE, MAX_TURNTABLE_FRAMES};
    if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        bail!("--size {width}x{height} is out of range; use 1 to {MAX_IMAGE_SIDE} pixels per side");
    }
    if repeat > 1000 {
        bail!("--repeat {repeat} is out of range; use 0 to 1000");
    }
    if turntable > MAX_TURNTABLE_FRAMES {
        bail!("--turntable {turntable} frames is absurd; use 0 to {MAX_TURNTABLE_FRAMES}");
    }
    // Shared with the renderer, not copied: it never changes here.
    let volume = voxflex_core::shared_volume::SharedVolume::new(std::sync::Arc::new(load_volume(
        &source, load,
    )?));
    let grid = volume.view().grid;
    let resolved = voxflex_runtime::backend::resolve(backend)?;
    let plugin = plugin_loader::load_by_name("raycast", &plugin_loader::search_path(&[]))?;
    let services = voxflex_abi::host_side::HostServices::new(
        resolved.gpu_service(),
        rayon::current_num_threads(),
    );
    let mut stage = voxflex_runtime::visualise::RenderStage::new(
        "voxflex render",
        &plugin,
        &params_toml,
        services,
        resolved.backend,
    )?;
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let file = out
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or(name);
    let settings = RenderSettings {
        plugin: "raycast".into(),
        width,
        height,
        camera,
        turntable,
        file,
        params: Default::default(),
    };
    let mut metrics = voxflex_runtime::metrics::RunMetrics::default();
    let written = stage.render(
        &settings,
        voxflex_core::render::RenderVolume::Shared(&volume),
        voxflex_core::deformation::DirtyRegion::All,
        &[],
        &dir,
        &mut metrics,
    )?;
    let wall = metrics.stages.get("render").map_or(0.0, |s| s.wall_ms);
    for f in written {
        println!("wrote {}", dir.join(f).display());
    }
    println!("{} in {wall:.0} ms", resolved.reason);
    if repeat > 0 {
        // The same view again, the scene already handed over: each frame's
        // time is the rays' alone.
        let camera = voxflex_runtime::visualise::camera_for(&settings, &grid, 0.0);
        let mut times = vec![];
        for _ in 0..repeat {
            let t = std::time::Instant::now();
            stage.render_image(&camera)?;
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let list: Vec<String> = times.iter().map(|t| format!("{t:.1}")).collect();
        println!("repeat frames (ms): {}", list.join(" "));
    }
    Ok(())
}

/// Output piped into a reader that stops early (`voxflex info … | head`)
/// ends the process quietly, as it does for other Unix tools, instead of
/// `println!` panicking on the broken pipe: Rust starts programs with
/// SIGPIPE ignored, so the default action is put back.
fn restore_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any other thread
    // exists; setting a signal's disposition to its default is
    // async-signal-safe and affects nothing else.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn only_commands_that_may_probe_a_gpu_get_a_runtime_dir() {
        use clap::Parser as _;
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("s.toml");
        let may = |args: &[&str]| {
            let cli = super::Cli::try_parse_from(args).unwrap();
            super::may_open_a_gpu(&cli.command)
        };
        let s = scene.to_str().unwrap();
        for (backend, expect) in [("cpu", false), ("auto", true), ("gpu", true)] {
            std::fs::write(
                &scene,
                format!("[scene]\nbackend = \"{backend}\"\n[volume]\nsource = \"phantom:cube\"\n"),
            )
            .unwrap();
            assert_eq!(may(&["voxflex", "run", s]), expect, "{backend}");
            let r = [
                "voxflex",
                "render",
                "phantom:cube",
                "--out",
                "r.png",
                "--backend",
                backend,
            ];
            assert_eq!(may(&r), expect, "render {backend}");
        }
        assert!(!may(&["voxflex", "plugins"]));
        assert!(may(&["voxflex", "run", "missing.toml"]));
    }

    #[cfg(unix)]
    #[test]
    fn runtime_dirs_are_private_unpredictable_and_removed() {
        use std::os::unix::fs::PermissionsExt as _;
        let a = super::private_runtime_dir().unwrap();
        let b = super::private_runtime_dir().unwrap();
        let path = a.path().to_path_buf();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o700, "{mode:o}");
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.starts_with("voxflex-xdg-"), "{name}");
        assert!(!name.contains(&std::process::id().to_string()), "{name}");
        assert_ne!(a.path(), b.path());
        drop(a);
        assert!(!path.exists());
    }
}
