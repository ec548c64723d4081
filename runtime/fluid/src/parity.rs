//! CPU/GPU parity checks of the fluid weights, run by the integration
//! tests on a real device (`tests/tests/fluid_gpu_parity.rs`; lavapipe in
//! CI). Feature `test-support` only.

use crate::gpu::GpuFluidWeighing;
use crate::test_surfaces::{BUNNY_GRAVITY, bunny_2cm, icosphere};
use crate::{FluidWeightParams, FluidWeights, fluid_weights};
use glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::triangle_surface::TriangleSurface;

/// Both paths on one surface: volume within 1e-5 relative, every vertex
/// weight within 1e-5 of the largest, the same sections (±0.1 %: a column
/// grazing the silhouette may cross on one path only), weights summing to
/// the fluid's weight.
fn compare(label: &str, cpu: &FluidWeights, gpu: &FluidWeights) -> Result<(), String> {
    let rel = |a: f64, b: f64| ((a - b) / b.abs().max(1e-30)).abs();
    if rel(gpu.volume_mm3, cpu.volume_mm3) > 1e-5 {
        return Err(format!(
            "{label}: volume {} (GPU) vs {} (CPU) mm³",
            gpu.volume_mm3, cpu.volume_mm3
        ));
    }
    let largest = cpu.node_weights.iter().copied().fold(0.0, f64::max);
    let (worst, at) = cpu
        .node_weights
        .iter()
        .zip(&gpu.node_weights)
        .enumerate()
        .map(|(i, (a, b))| ((a - b).abs(), i))
        .fold((0.0, 0), |m, x| if x.0 > m.0 { x } else { m });
    if worst > 1e-5 * largest {
        return Err(format!(
            "{label}: vertex {at} weighs {} µN on the GPU, {} on the CPU (largest {largest})",
            gpu.node_weights[at], cpu.node_weights[at]
        ));
    }
    let sum: f64 = gpu.node_weights.iter().sum();
    if rel(sum, gpu.total_weight) > 1e-5 {
        return Err(format!(
            "{label}: GPU weights sum to {sum}, the fluid weighs {}",
            gpu.total_weight
        ));
    }
    let (a, b) = (cpu.count.sections as f64, gpu.count.sections as f64);
    if (a - b).abs() > 1e-3 * a || gpu.count.irregular_columns != cpu.count.irregular_columns {
        return Err(format!(
            "{label}: sections {:?} (GPU) vs {:?} (CPU)",
            gpu.count, cpu.count
        ));
    }
    Ok(())
}

fn check(
    gpu: &dyn GpuService,
    label: &str,
    s: &TriangleSurface,
    p: &FluidWeightParams,
) -> Result<(), String> {
    let cpu = fluid_weights(s, p).map_err(|e| e.to_string())?;
    let on_gpu = GpuFluidWeighing::new()
        .weigh(gpu, s, p)
        .map_err(|e| e.to_string())?;
    compare(label, &cpu, &on_gpu)
}

/// The icosphere at 30² and 200², with leveraging and one worker per
/// triangle, and under a slanted gravity.
pub fn check_sphere_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    let Some(s) = icosphere()? else {
        return Ok(());
    };
    for n in [30, 200] {
        for alpha in [0.25, 0.0] {
            let p = FluidWeightParams {
                columns_per_side: n,
                leverage_alpha: alpha,
                ..Default::default()
            };
            check(gpu, &format!("sphere {n}² α {alpha}"), &s, &p)?;
        }
    }
    let slanted = FluidWeightParams {
        gravity_m_s2: DVec3::new(2.0, -3.0, -9.0),
        ..Default::default()
    };
    check(gpu, "sphere, slanted gravity", &s, &slanted)
}

/// The non-convex bunny (2 cm tall): several sections per column, so the GPU must grow
/// its crossing slots beyond the first guess and still agree.
pub fn check_bunny_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    let Some(s) = bunny_2cm()? else {
        return Ok(());
    };
    let p = FluidWeightParams {
        gravity_m_s2: BUNNY_GRAVITY,
        ..Default::default()
    };
    let cpu = fluid_weights(&s, &p).map_err(|e| e.to_string())?;
    if cpu.count.sections <= cpu.count.columns_with_fluid {
        return Err(format!(
            "the bunny should hold several sections per column somewhere: {:?}",
            cpu.count
        ));
    }
    let mut w = GpuFluidWeighing::new();
    let first = w.weigh(gpu, &s, &p).map_err(|e| e.to_string())?;
    compare("bunny 200²", &cpu, &first)?;
    // a second call starts from the grown slot count
    let again = w.weigh(gpu, &s, &p).map_err(|e| e.to_string())?;
    compare("bunny 200², second call", &cpu, &again)
}
