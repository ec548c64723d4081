//! Commands that hand the side-by-side harness (`bench/peers/`) the exact
//! inputs and outputs of voxflex, so a peer library can be given the same
//! work and its answer compared voxel for voxel:
//!
//! - `voxflex phantom NAME --dims X,Y,Z --out FILE` writes a built-in
//!   phantom as NIfTI (with `--labels`, the abdomen's organ labels too);
//! - `voxflex resample VOLUME --field twist --angle-deg A --export DIR`
//!   resamples a volume under an analytic field, times only the resample
//!   stage, and writes the source, the result and the field's exact
//!   **backward** displacement on the output grid (what an ITK-style
//!   resampler takes).
//!
//! All coordinates are voxflex's world frame: LPS millimetres, written to
//! NIfTI in its RAS convention (x and y negated), which ITK reads back as
//! the same LPS points.

use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_resample::fields::{Field, affine, bend_zx, twist_z};
use voxflex_resample::{Interpolation, ResampleParams, Resampler};

/// An analytic deformation of `voxflex resample`, about the grid centre.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FieldKind {
    /// Twist about z: the rotation grows linearly along z, `--angle-deg`
    /// degrees over the z extent (as `voxflex bench`, whose angle is 40°).
    Twist,
    /// Barr bend of z towards x: `--angle-deg` degrees over the z extent.
    Bend,
    /// Rotation by `--angle-deg` about (0.2, 0.3, 1), ×1.05, translated by
    /// (2.3, −1.7, 0.9) mm (the accuracy benchmark's affine map).
    Affine,
}

/// Options of `voxflex resample`.
pub struct ResampleArgs {
    /// A volume file or `phantom:<name>`.
    pub volume: String,
    /// Phantom resolution (voxels), phantoms only.
    pub dims: Option<Vec<usize>>,
    /// The analytic deformation.
    pub field: FieldKind,
    /// Its angle, degrees.
    pub angle_deg: f64,
    /// Timed repetitions after one untimed warm-up.
    pub repeat: usize,
    /// Resampler interpolation (default: the resampler's default).
    pub interpolation: Option<Interpolation>,
    /// Directory to write the source, the result, the backward field and
    /// `resample.json` into.
    pub export: Option<PathBuf>,
}

/// A map (rest → deformed, mm) and its exact inverse.
type MapPair = (
    Box<dyn Fn(DVec3) -> DVec3 + Sync + Send>,
    Box<dyn Fn(DVec3) -> DVec3 + Sync + Send>,
);

/// The map and inverse of `kind` at `angle_deg` on `grid` (mm, about its centre).
fn analytic(kind: FieldKind, angle_deg: f64, grid: &Grid) -> MapPair {
    let c = grid.centre();
    let (lo, hi) = grid.world_bounds();
    let rate = angle_deg.to_radians() / (hi.z - lo.z).max(f64::MIN_POSITIVE);
    match kind {
        FieldKind::Twist => {
            let (m, i) = twist_z(c, rate);
            (Box::new(m), Box::new(i))
        }
        FieldKind::Bend => {
            let (m, i) = bend_zx(c, rate);
            (Box::new(m), Box::new(i))
        }
        FieldKind::Affine => {
            let (m, i) = affine(
                c,
                DVec3::new(0.2, 0.3, 1.0),
                angle_deg,
                1.05,
                DVec3::new(2.3, -1.7, 0.9),
            );
            (Box::new(m), Box::new(i))
        }
    }
}

/// The backward displacement `inverse(X) − X` (mm, LPS) at every voxel
/// centre `X` of `grid`, one f32 volume per component.
fn backward_field(grid: &Grid, inverse: &(dyn Fn(DVec3) -> DVec3 + Sync)) -> Result<[Volume; 3]> {
    let f = Field::from_map(grid, inverse);
    let vol = |v: Vec<f32>| Volume::new(*grid, VoxelData::F32(v)).context("backward field");
    Ok([vol(f.x)?, vol(f.y)?, vol(f.z)?])
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn grid_json(g: &Grid) -> serde_json::Value {
    serde_json::json!({
        "dims": g.dims,
        "spacing_mm": g.spacing.to_array(),
        "origin_mm": g.origin.to_array(),
        "frame": "LPS",
    })
}

/// `voxflex resample`: returns the report to print.
pub fn resample(a: ResampleArgs) -> Result<String> {
    if a.repeat == 0 || a.repeat > 1000 {
        bail!("--repeat {} is out of range; use 1 to 1000", a.repeat);
    }
    if !a.angle_deg.is_finite() || a.angle_deg.abs() > 180.0 {
        bail!(
            "--angle-deg {} is out of range; use -180 to 180",
            a.angle_deg
        );
    }
    let t = Instant::now();
    let load = crate::LoadArgs {
        dims: a.dims.clone(),
        ..Default::default()
    };
    let volume = crate::load_volume(&a.volume, load)?;
    let load = t.elapsed();
    let (map, inverse) = analytic(a.field, a.angle_deg, &volume.grid);
    let field = Field::from_map(&volume.grid, &map);
    let background = volume.value_range().0;
    let params = ResampleParams {
        background,
        interpolation: a
            .interpolation
            .unwrap_or(ResampleParams::default().interpolation),
        ..Default::default()
    };
    let mut r = Resampler::new(params);
    let mut times = vec![];
    // Run 0 allocates the output and its scratch: the warm-up, untimed.
    for i in 0..=a.repeat {
        let t = Instant::now();
        r.resample_cpu(volume.view(), field.as_ref(), None, DirtyRegion::All)
            .context("resample")?;
        if i > 0 {
            times.push(ms(t.elapsed()));
        }
    }
    let out = r.cpu_output().context("the resampler kept no output")?;
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let (min, median) = (sorted[0], sorted[sorted.len() / 2]);
    let mut report = String::new();
    let _ = writeln!(
        report,
        "{}: {:?} voxels, {} {}° ({}), {} thread(s); output {:?} voxels",
        a.volume,
        volume.grid.dims,
        format!("{:?}", a.field).to_lowercase(),
        a.angle_deg,
        params.interpolation,
        rayon::current_num_threads(),
        out.grid.dims,
    );
    let _ = write!(
        report,
        "resample: min {min:.1} ms, median {median:.1} ms over {} run(s) (load {:.0} ms, not timed)",
        a.repeat,
        ms(load)
    );
    if let Some(dir) = &a.export {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let write = |name: &str, v: &Volume| -> Result<()> {
            voxflex_io::write_volume(&dir.join(name), v.view())
                .with_context(|| format!("writing {}", dir.join(name).display()))
        };
        write("source.nii", &volume)?;
        let result = Volume::new(out.grid, VoxelData::F32(out.values)).context("output")?;
        write("resampled.nii", &result)?;
        let [bx, by, bz] = backward_field(&out.grid, &inverse)?;
        write("backward_x.nii", &bx)?;
        write("backward_y.nii", &by)?;
        write("backward_z.nii", &bz)?;
        let json = serde_json::json!({
            "volume": a.volume,
            "field": format!("{:?}", a.field).to_lowercase(),
            "angle_deg": a.angle_deg,
            "interpolation": params.interpolation.name(),
            "background": background,
            "threads": rayon::current_num_threads(),
            "resample_ms": times,
            "min_ms": min,
            "median_ms": median,
            "source_grid": grid_json(&volume.grid),
            "output_grid": grid_json(&out.grid),
            "files": {
                "source": "source.nii",
                "resampled": "resampled.nii",
                "backward_mm": ["backward_x.nii", "backward_y.nii", "backward_z.nii"],
            },
        });
        write_json(&dir.join("resample.json"), &json)?;
        let _ = write!(report, "\nwrote {}", dir.display());
    }
    Ok(report)
}

fn write_json(path: &Path, v: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(v)?;
    voxflex_io::write_atomically(path, |w| w.write_all(text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}

/// `voxflex phantom`: writes phantom `name` at `dims` voxels to `out`, and
/// with `labels` the abdomen's organ labels (u8, see
/// `voxflex_phantom::abdomen::label`) on the same grid.
pub fn phantom(name: &str, dims: &[usize], out: &Path, labels: Option<&Path>) -> Result<String> {
    let &[x, y, z] = dims else {
        bail!("--dims needs three numbers: x,y,z");
    };
    for p in std::iter::once(out).chain(labels) {
        let s = p.to_string_lossy();
        if !(s.ends_with(".nii") || s.ends_with(".nii.gz")) {
            bail!("`{s}` must end in .nii or .nii.gz");
        }
    }
    let (volume, label_volume) = match labels {
        None => (
            voxflex_phantom::phantom(name, [x, y, z]).with_context(|| format!("`{name}`"))?,
            None,
        ),
        Some(_) if name == "abdomen" => {
            let l = voxflex_phantom::abdomen_labelled([x, y, z]);
            let lv = Volume::new(l.volume.grid, VoxelData::U8(l.labels)).context("labels")?;
            (l.volume, Some(lv))
        }
        Some(_) => bail!("--labels: only the abdomen phantom has labels"),
    };
    voxflex_io::write_volume(out, volume.view())
        .with_context(|| format!("writing {}", out.display()))?;
    let mut report = format!(
        "phantom:{name} {:?} voxels, spacing {:?} mm → {}",
        volume.grid.dims,
        volume.grid.spacing.to_array(),
        out.display()
    );
    if let (Some(p), Some(lv)) = (labels, label_volume) {
        voxflex_io::write_volume(p, lv.view())
            .with_context(|| format!("writing {}", p.display()))?;
        let _ = write!(report, "; labels → {}", p.display());
    }
    Ok(report)
}
