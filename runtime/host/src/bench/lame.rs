//! A pressurised thick-walled sphere against Lamé's solution: the
//! accuracy reference of the pneumatic cavity acting on corotational FEM
//! (issue 16), through the real path — a label volume written to NIfTI, a
//! scene with a `cavity` actuator on `label = 2`, `voxflex run`'s pipeline.
//!
//! A sphere of silicone between radii `a` and `b` (mm) holds a cavity of
//! radius `a` at pressure `p`. Lamé (linear elasticity, small strain): the
//! radial displacement is
//! `u(r) = p a³ / (E (b³ − a³)) · ((1 − 2ν) r + (1 + ν) b³ / (2 r²))`,
//! so the cavity grows by `4/3 π ((a + u(a))³ − a³)`. The body is held
//! only at a small patch around its lowest point (no rigid motion, a
//! local disturbance the cavity's volume barely feels).

use crate::pipeline::{RunError, RunOptions, run_scene};
use crate::scene::Scene;
use std::path::{Path, PathBuf};
use std::time::Instant;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{Volume, VoxelData};

/// The sphere and its load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LameSphere {
    /// Cavity radius, mm.
    pub inner_mm: f64,
    /// Outer radius, mm.
    pub outer_mm: f64,
    /// Young's modulus, Pa.
    pub youngs_modulus: f64,
    /// Poisson ratio.
    pub poisson_ratio: f64,
    /// Cavity pressure, Pa.
    pub pressure_pa: f64,
}

impl Default for LameSphere {
    /// a = 10 mm, b = 20 mm, E = 100 kPa, ν = 0.3, p = 100 Pa: small
    /// strain (u(a) ≈ 0.008 mm), where Lamé's linear solution holds — the
    /// simulation's pressure follows the walls, which at 1 kPa already
    /// adds 1.6 % (the cavity's area grows with it).
    fn default() -> Self {
        Self {
            inner_mm: 10.0,
            outer_mm: 20.0,
            youngs_modulus: 1e5,
            poisson_ratio: 0.3,
            pressure_pa: 100.0,
        }
    }
}

impl LameSphere {
    /// Lamé's radial displacement at radius `r` (mm).
    pub fn radial_displacement(&self, r: f64) -> f64 {
        let (a, b, e, nu, p) = (
            self.inner_mm,
            self.outer_mm,
            self.youngs_modulus,
            self.poisson_ratio,
            self.pressure_pa,
        );
        p * a.powi(3) / (e * (b.powi(3) - a.powi(3)))
            * ((1.0 - 2.0 * nu) * r + (1.0 + nu) * b.powi(3) / (2.0 * r * r))
    }

    /// The cavity's volume growth, mm³.
    pub fn volume_growth(&self) -> f64 {
        let a = self.inner_mm;
        4.0 / 3.0 * std::f64::consts::PI * ((a + self.radial_displacement(a)).powi(3) - a.powi(3))
    }

    /// The label volume (0 air, 1 silicone, 2 cavity) with voxels of
    /// `voxel_mm`, one voxel of air around the sphere.
    pub fn volume(&self, voxel_mm: f64) -> Volume {
        let n = (2.0 * self.outer_mm / voxel_mm).ceil() as usize + 2;
        let origin = DVec3::splat(-(n as f64 - 1.0) / 2.0 * voxel_mm);
        let grid = Grid::new([n; 3], DVec3::splat(voxel_mm), origin);
        let labels: Vec<u8> = (0..grid.len())
            .map(|l| {
                let [i, j, k] = grid.unlinear(l);
                let r = grid
                    .index_to_world(DVec3::new(i as f64, j as f64, k as f64))
                    .length();
                if r <= self.inner_mm {
                    2
                } else if r <= self.outer_mm {
                    1
                } else {
                    0
                }
            })
            .collect();
        Volume::new(grid, VoxelData::U8(labels)).expect("a label volume of its own grid")
    }
}

/// One mesh level's result.
#[derive(Clone, Debug, PartialEq)]
pub struct LameResult {
    /// Voxel size, mm (the proxy's cells are `step` voxels).
    pub voxel_mm: f64,
    /// Proxy cell size, voxels.
    pub step: usize,
    /// Proxy nodes.
    pub nodes: f64,
    /// Wall time of the run (load, mesh, bind, one static solve), s.
    pub seconds: f64,
    /// The cavity's volume growth the run measured, mm³.
    pub volume_growth: f64,
    /// Lamé's, mm³.
    pub analytic: f64,
}

impl LameResult {
    /// Relative error of the volume growth.
    pub fn relative_error(&self) -> f64 {
        (self.volume_growth - self.analytic) / self.analytic
    }
}

/// The scene of `sphere` on the volume file `volume` (voxels of
/// `voxel_mm`, proxy cells of `step` voxels), plugins from `plugin_dirs`.
fn scene_text(
    sphere: &LameSphere,
    volume: &Path,
    voxel_mm: f64,
    step: usize,
    plugin_dirs: &[PathBuf],
    out: &Path,
) -> String {
    let dirs: Vec<String> = plugin_dirs
        .iter()
        .map(|d| format!("{:?}", d.display().to_string()))
        .collect();
    let b = sphere.outer_mm;
    let patch = 1.5 * step as f64 * voxel_mm;
    format!(
        r#"[scene]
name = "lame"
backend = "cpu"
frames = 1
plugin_dirs = [{dirs}]

[volume]
source = {volume:?}

[model]
plugin = "corotational-fem"
[model.params]
solver = "static"
static_tolerance = 1e-9
cg_tolerance = 1e-10
proxy = {{ kind = "uniform", step = {step} }}
materials = [{{ range = [0.5, 1.5], youngs_modulus = {e}, poisson_ratio = {nu} }}]

[[interaction]]
frame = 0
kind = "fix"
min = [{lo}, {lo}, {zlo}]
max = [{hi}, {hi}, {zhi}]

[[actuator]]
plugin = "cavity"
cavity = {{ label = 2 }}
[actuator.params]
pressure_pa = [[0, {p}]]

[output]
dir = {out:?}
"#,
        dirs = dirs.join(", "),
        volume = volume.display().to_string(),
        e = sphere.youngs_modulus,
        nu = sphere.poisson_ratio,
        p = sphere.pressure_pa,
        lo = -patch,
        hi = patch,
        zlo = -b - patch,
        zhi = -b + patch,
        out = out.display().to_string(),
    )
}

/// Runs `sphere` at voxels of `voxel_mm` with proxy cells of `step`
/// voxels, in `work` (a directory it writes the volume, scene and outputs
/// into), loading plugins from `plugin_dirs` (empty: the default search
/// path).
pub fn run_lame(
    sphere: &LameSphere,
    voxel_mm: f64,
    step: usize,
    plugin_dirs: &[PathBuf],
    work: &Path,
) -> Result<LameResult, RunError> {
    std::fs::create_dir_all(work)
        .map_err(|e| RunError::Other(format!("{}: {e}", work.display())))?;
    let volume = work.join(format!("lame_{voxel_mm}.nii"));
    voxflex_io::nifti::write_nifti(&volume, sphere.volume(voxel_mm).view())?;
    let out = work.join(format!("out_{voxel_mm}_{step}"));
    let path = work.join(format!("lame_{voxel_mm}_{step}.toml"));
    let text = scene_text(sphere, &volume, voxel_mm, step, plugin_dirs, &out);
    std::fs::write(&path, &text)
        .map_err(|e| RunError::Other(format!("{}: {e}", path.display())))?;
    let scene = Scene::parse(&text, &path)?;
    let t = Instant::now();
    let metrics = run_scene(
        &scene,
        RunOptions {
            out_dir: Some(out),
            force: true,
            progress: None,
        },
    )?;
    let seconds = t.elapsed().as_secs_f64();
    let growth = metrics
        .actuation
        .as_ref()
        .and_then(|a| a.actuators.first())
        .and_then(|s| s.measure.last().copied())
        .ok_or_else(|| RunError::Other("lame: the run reported no actuator".into()))?;
    let nodes = metrics
        .stages
        .get("model")
        .and_then(|m| m.notes.get("proxy_nodes"))
        .and_then(|v| v.as_f64())
        .unwrap_or(0.0);
    Ok(LameResult {
        voxel_mm,
        step,
        nodes,
        seconds,
        volume_growth: growth,
        analytic: sphere.volume_growth(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lames_solution_has_the_textbook_limits() {
        let s = LameSphere::default();
        // Thin shell limit check: u(b) < u(a), both positive.
        assert!(s.radial_displacement(20.0) > 0.0);
        assert!(s.radial_displacement(20.0) < s.radial_displacement(10.0));
        // Incompressible: u(r) r² is constant.
        let inc = LameSphere {
            poisson_ratio: 0.5,
            ..s
        };
        let (ua, ub) = (inc.radial_displacement(10.0), inc.radial_displacement(20.0));
        assert!((ua * 100.0 - ub * 400.0).abs() < 1e-12 * ua * 100.0);
        // Linear in the pressure.
        let twice = LameSphere {
            pressure_pa: 2.0 * s.pressure_pa,
            ..s
        };
        assert!(
            (twice.radial_displacement(15.0) - 2.0 * s.radial_displacement(15.0)).abs() < 1e-15
        );
    }

    #[test]
    fn the_volume_labels_the_shell_and_the_cavity() {
        let v = LameSphere::default().volume(2.0);
        let counts = v
            .data
            .as_slice()
            .to_f32_vec()
            .iter()
            .fold([0usize; 3], |mut c, &l| {
                c[l as usize] += 1;
                c
            });
        // 4/3 π 10³ / 8 ≈ 524 cavity voxels, 4/3 π (20³ − 10³) / 8 ≈ 3665 shell.
        assert!((counts[2] as f64 - 524.0).abs() < 60.0, "{counts:?}");
        assert!((counts[1] as f64 - 3665.0).abs() < 200.0, "{counts:?}");
    }
}
