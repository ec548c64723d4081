//! GPU-versus-CPU checks of the barycentric map, written against
//! [`GpuService`] so the integration tests can run them on the host's
//! device (lavapipe in CI). Each returns `Err(description)` on the first
//! disagreement beyond `1e-5` mm (GPUs may fuse multiply-adds).

use super::BarycentricBinding;
use crate::gpu::{BufferId, GpuService, GpuServiceExt, LimitedDevice};
use crate::grid::Grid;
use crate::proxy::uniform_proxy;
use crate::tet_mesh::TetMesh;
use glam::DVec3;

/// A two-label proxy, rest points inside and around it, and node
/// displacements (mm) with rotation, stretch and a ripple.
fn setup() -> (TetMesh, BarycentricBinding, [Vec<f32>; 3]) {
    let grid = Grid::new(
        [13, 10, 9],
        DVec3::new(1.0, 1.2, 0.9),
        DVec3::new(-6.0, -5.0, -4.0),
    );
    let mesh = uniform_proxy(&grid, 3, |v| {
        (v[2] < 6 || v[0] < 8).then_some((v[0] / 6) as u16)
    })
    .expect("test proxy");
    let (lo, hi) = mesh.bounds();
    let n = 20_011; // odd: the last word of packed weights holds one point
    let points: Vec<DVec3> = (0..n)
        .map(|i| {
            let f = |k: usize, m: usize| ((i * k) % m) as f64 / m as f64;
            let t = DVec3::new(f(7919, 997), f(104_729, 991), f(1_299_709, 983));
            (lo - DVec3::splat(1.5)) + (hi - lo + DVec3::splat(3.0)) * t
        })
        .collect();
    let binding = BarycentricBinding::bind(&mesh, n, |i| points[i]);
    let u = [0, 1, 2].map(|a| {
        mesh.nodes
            .iter()
            .map(|p| (0.03 * p[(a + 1) % 3] - 0.02 * p[a] + (0.4 * p[(a + 2) % 3]).sin()) as f32)
            .collect()
    });
    (mesh, binding, u)
}

fn cpu_map(mesh: &TetMesh, b: &BarycentricBinding, u: &[Vec<f32>; 3]) -> [Vec<f32>; 3] {
    let mut out = [0, 1, 2].map(|_| vec![0f32; b.len()]);
    let [x, y, z] = &mut out;
    b.map(mesh, [&u[0], &u[1], &u[2]], [x, y, z]);
    out
}

fn gpu_map(
    gpu: &dyn GpuService,
    mesh: &TetMesh,
    b: &BarycentricBinding,
    u: &[Vec<f32>; 3],
) -> Result<[Vec<f32>; 3], String> {
    let err = |e: crate::error::GpuError| e.to_string();
    let nodes: Vec<[f32; 4]> = (0..mesh.nodes.len())
        .map(|n| [u[0][n], u[1][n], u[2][n], 0.0])
        .collect();
    let nodes = gpu.upload(&nodes, "parity nodes").map_err(err)?;
    let out: [BufferId; 3] = [0, 1, 2].map(|_| {
        gpu.create_buffer(4 * b.len() as u64, "parity out")
            .expect("buffer")
    });
    let on_device = b.upload(mesh, gpu).map_err(err)?;
    on_device.map(gpu, nodes, out).map_err(err)?;
    let mut got = [0, 1, 2].map(|_| vec![0f32; b.len()]);
    for (g, id) in got.iter_mut().zip(out) {
        gpu.download(id, g).map_err(err)?;
        gpu.destroy_buffer(id);
    }
    gpu.destroy_buffer(nodes);
    on_device.release(gpu);
    Ok(got)
}

fn compare(what: &str, want: &[Vec<f32>; 3], got: &[Vec<f32>; 3]) -> Result<(), String> {
    for a in 0..3 {
        for (i, (w, g)) in want[a].iter().zip(&got[a]).enumerate() {
            if (w - g).abs() > 1e-5 {
                return Err(format!(
                    "{what}: point {i} axis {a}: CPU {w} mm, GPU {g} mm"
                ));
            }
        }
    }
    Ok(())
}

/// The WGSL map equals the rayon map, points outside the mesh included.
pub fn check_map_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    let (mesh, b, u) = setup();
    if b.outside == 0 {
        return Err("the test binds no point outside the mesh".into());
    }
    compare(
        "map",
        &cpu_map(&mesh, &b, &u),
        &gpu_map(gpu, &mesh, &b, &u)?,
    )
}

/// Under a storage binding limit far below the point arrays, the map runs
/// in slabs and still equals the rayon map; a tetrahedron list above the
/// limit is refused with what to do.
pub fn check_map_slabs(gpu: &dyn GpuService) -> Result<(), String> {
    let (mesh, b, u) = setup();
    let small = LimitedDevice::binding(gpu, (16 * mesh.tets.len() as u64).max(4096));
    if 4 * b.len() as u64 <= small.limits().max_storage_buffer_binding_size {
        return Err("slab test is not slabbed".into());
    }
    compare(
        "slabbed map",
        &cpu_map(&mesh, &b, &u),
        &gpu_map(&small, &mesh, &b, &u)?,
    )?;
    let tiny = LimitedDevice::binding(gpu, 256);
    match b.upload(&mesh, &tiny) {
        Err(e) if e.to_string().contains("coarser proxy") => Ok(()),
        Err(e) => Err(format!("unclear refusal: {e}")),
        Ok(_) => Err("a tetrahedron list above the binding limit was accepted".into()),
    }
}
