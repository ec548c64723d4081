//! CPU/GPU parity of a field plugin through the real path: the plugin
//! loaded from its `.so`, initialised on the GPU backend, maps the same
//! rest points (a lattice and an explicit list) once into CPU slices and
//! once into GPU buffers; the two answers are compared. The `affine` and
//! `template` plugins' parity tests share it.

use crate::plugin_dir;
use std::sync::Arc;
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_core::deformation::{
    DeformationModel, DisplacementTarget, ExecutionBackend, FrameInfo, RestPoints,
};
use voxflex_core::gpu::{GpuService, GpuServiceExt};
use voxflex_core::grid::Grid;
use voxflex_core::volume::{VolumeView, VoxelSlice};

/// Plugin `name` loaded from its `.so` (built into the target directory),
/// created with `params` (TOML) and initialised on the GPU backend over an
/// all-zero u8 volume on `grid`.
pub fn field_plugin_on_gpu(
    gpu: Arc<dyn GpuService>,
    name: &str,
    params: &str,
    grid: Grid,
) -> DeformationProxy {
    let p = voxflex_runtime::plugin_loader::load_by_name(name, &[plugin_dir(&[name])]).unwrap();
    let services = HostServices::new(Some(gpu), 2);
    // SAFETY: the loader checked the library's ABI version and layout hash,
    // and plugin libraries are never unloaded, so the vtable outlives the proxy.
    let mut m = unsafe { DeformationProxy::create(name, p.deformation.unwrap(), params, services) }
        .unwrap();
    let data = vec![0u8; grid.len()];
    let view = VolumeView {
        grid,
        data: VoxelSlice::U8(&data),
    };
    m.init(view, ExecutionBackend::Gpu).unwrap();
    m
}

/// What one parity run found, mm.
#[derive(Clone, Copy, Debug)]
pub struct FieldParity {
    /// Largest displacement component of the CPU answer (the field must
    /// move something for the comparison to mean anything).
    pub largest: f32,
    /// Largest CPU/GPU difference over every point and axis.
    pub worst: f32,
}

/// Binds every lattice node of `grid`, then every `stride`-th node as an
/// explicit point list, steps frame 0 and compares the CPU and GPU maps of
/// each binding; returns one [`FieldParity`] per binding.
pub fn field_parity(
    m: &mut DeformationProxy,
    gpu: &dyn GpuService,
    grid: Grid,
    stride: usize,
) -> Vec<FieldParity> {
    let pts: Vec<[f32; 3]> = (0..grid.len())
        .step_by(stride)
        .map(|n| RestPoints::Lattice(grid).point(n).as_vec3().to_array())
        .collect();
    let mut out = vec![];
    for rest in [RestPoints::Lattice(grid), RestPoints::Points(&pts)] {
        let n = rest.len();
        let b = m.bind(rest).unwrap();
        let frame = FrameInfo {
            frame: 0,
            frames: 1,
            dt_s: 0.0,
        };
        m.step(frame).unwrap();
        let mut cpu = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
        let [x, y, z] = &mut cpu;
        m.map(b, DisplacementTarget::Cpu { x, y, z }).unwrap();
        let ids = [0, 1, 2].map(|_| gpu.create_buffer(n as u64 * 4, "d").unwrap());
        let target = DisplacementTarget::Gpu {
            x: ids[0],
            y: ids[1],
            z: ids[2],
        };
        m.map(b, target).unwrap();
        let mut worst = 0f32;
        for (a, id) in ids.iter().enumerate() {
            let mut g = vec![0f32; n];
            gpu.download(*id, &mut g).unwrap();
            gpu.destroy_buffer(*id);
            for (c, g) in cpu[a].iter().zip(&g) {
                worst = worst.max((c - g).abs());
            }
        }
        let largest = cpu.iter().flatten().fold(0f32, |a, v| a.max(v.abs()));
        out.push(FieldParity { largest, worst });
    }
    out
}

/// For each device of `devices` and each parameter table of `params`:
/// plugin `name` on `grid`, its lattice and every `stride`-th point
/// ([`field_parity`]); asserts that the field moves something (more than
/// 0.1 mm) and that GPU and CPU agree within `tolerance_mm`.
pub fn assert_field_parity(
    devices: &[Arc<dyn GpuService>],
    name: &str,
    params: &[&str],
    grid: Grid,
    stride: usize,
    tolerance_mm: f32,
) {
    for device in devices {
        for p in params {
            let mut m = field_plugin_on_gpu(device.clone(), name, p, grid);
            for r in field_parity(&mut m, device.as_ref(), grid, stride) {
                assert!(r.largest > 0.1, "{p}: the field must move something");
                assert!(
                    r.worst <= tolerance_mm,
                    "{p}: GPU and CPU fields differ by {} mm",
                    r.worst
                );
            }
        }
    }
}
