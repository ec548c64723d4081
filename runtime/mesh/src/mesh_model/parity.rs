//! One CPU/GPU parity pattern for every [`MeshSolver`] (test support): the
//! same model on the same octree proxy, stepped on the rayon and the WGSL
//! backend, compared node by node. Each solver's test gives its parameters,
//! interactions and frames and asserts its own tolerances on the returned
//! [`OctreeParity`].

use super::{MeshModel, MeshSolver, largest_and_difference};
use crate::deformation::{DeformationModel, ExecutionBackend, FrameInfo};
use crate::gpu::GpuService;
use crate::volume::VolumeView;
use glam::DVec3;
use std::sync::Arc;

/// How far the GPU run of a model is from its CPU run (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OctreeParity {
    /// The largest displacement of the CPU run.
    pub largest: f64,
    /// The largest difference between the two runs' node displacements.
    pub worst: f64,
    /// The largest distance, on the GPU run, between a hanging node and the
    /// weighted sum of its masters.
    pub worst_tie: f64,
    /// Hanging nodes of the proxy (the check needs at least one).
    pub hanging: usize,
}

/// Builds `MeshModel<S>` from `params_toml` (an octree `proxy`) on `volume`
/// twice — CPU, and GPU through `gpu` — applies `interactions` to both,
/// steps both `steps` times with `frame`, and compares the displacements.
pub fn octree_parity<S: MeshSolver>(
    volume: VolumeView<'_>,
    gpu: Arc<dyn GpuService>,
    params_toml: &str,
    interactions: &[&str],
    frame: FrameInfo,
    steps: usize,
) -> Result<OctreeParity, String> {
    let make = |gpu: Option<Arc<dyn GpuService>>, backend| -> Result<MeshModel<S>, String> {
        let mut m = MeshModel::<S>::from_toml(params_toml)
            .map_err(|e| e.to_string())?
            .with_gpu(gpu);
        m.init(volume, backend).map_err(|e| e.to_string())?;
        for i in interactions {
            m.interact(i).map_err(|e| e.to_string())?;
        }
        Ok(m)
    };
    let mut cpu = make(None, ExecutionBackend::Cpu)?;
    let mut dev = make(Some(gpu), ExecutionBackend::Gpu)?;
    for _ in 0..steps {
        cpu.step(frame).map_err(|e| e.to_string())?;
        dev.step(frame).map_err(|e| e.to_string())?;
    }
    let (Some(a), Some(b)) = (cpu.state(), dev.state()) else {
        return Err("a model has no node state after stepping".into());
    };
    let (largest, worst) = largest_and_difference(&a.u, &b.u);
    let worst_tie = dev
        .hanging()
        .iter()
        .map(|h| {
            let tied: DVec3 = h
                .masters
                .iter()
                .map(|&(n, w)| w as f64 * b.u[n as usize])
                .sum();
            (b.u[h.node as usize] - tied).length()
        })
        .fold(0.0, f64::max);
    Ok(OctreeParity {
        largest,
        worst,
        worst_tie,
        hanging: dev.hanging().len(),
    })
}
