//! Features smaller than the proxy's cells, end to end: the check both mesh
//! plugins run in their tests (like [`super::cantilever`], shared so the
//! two cannot drift apart).
//!
//! A volume of `dims` voxels (1 mm, background 0) holds value 100 at a few
//! voxels — a one-voxel object, a one-voxel slab. The model is built from
//! the scene's keys, bound to the volume's lattice and stepped; then every
//! node is moved by a whole number of voxels and the volume resampled. The
//! object must be inside the proxy (not bound to other tissue's surface),
//! no labelled voxel may be reported lost, and the resampled volume must
//! hold the object's voxels at the shifted positions with value 100
//! exactly (an integer shift reproduces values bit for bit) and nothing
//! else above background.

use super::{MeshModel, MeshSolver};
use crate::barycentric::BarycentricBinding;
use crate::deformation::{
    DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo, RestPoints,
};
use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use voxflex_resample::fields::Field;
use voxflex_resample::{ResampleParams, Resampler};

/// Runs the check on `object` (voxel indices, value 100) with the plugin
/// table `params` (TOML; its materials must take 100), `frames` frames of
/// 1/30 s, then a shift of `shift` voxels. `Err` says what went wrong.
pub fn object_survives<S: MeshSolver>(
    params: &str,
    dims: [usize; 3],
    object: &[[usize; 3]],
    frames: usize,
    shift: [i32; 3],
) -> Result<(), String> {
    let grid = Grid::new(dims, DVec3::ONE, DVec3::ZERO);
    let mut data = vec![0f32; grid.len()];
    for v in object {
        data[grid.linear(v[0], v[1], v[2])] = 100.0;
    }
    let volume = Volume::new(grid, VoxelData::F32(data)).map_err(|e| e.to_string())?;
    let mut model = MeshModel::<S>::from_toml(params).map_err(|e| e.0)?;
    model
        .init(volume.view(), ExecutionBackend::Cpu)
        .map_err(|e| format!("init: {}", e.0))?;
    let id = model.bind(RestPoints::Lattice(grid)).map_err(|e| e.0)?;
    let lost = model.notes().map_err(|e| e.0)?["labelled_voxels_lost"];
    if lost != 0.0 {
        return Err(format!("{lost} labelled voxels reported lost"));
    }
    let mesh = model.mesh().expect("built").clone();
    let at = |i: usize| {
        let v = object[i];
        DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
    };
    let inside = BarycentricBinding::bind(&mesh, object.len(), at);
    if inside.outside != 0 {
        return Err(format!(
            "{} of {} object voxels lie outside the proxy",
            inside.outside,
            object.len()
        ));
    }
    let frame = FrameInfo {
        frame: 0,
        frames: frames as u64,
        dt_s: 1.0 / 30.0,
    };
    for _ in 0..frames {
        model.step(frame).map_err(|e| e.0)?;
    }
    let d = DVec3::new(shift[0] as f64, shift[1] as f64, shift[2] as f64);
    model
        .set_displacements(&vec![d; mesh.nodes.len()])
        .map_err(|e| e.0)?;
    let mut field = Field::zero(&grid);
    model
        .map(
            id,
            DisplacementTarget::Cpu {
                x: &mut field.x,
                y: &mut field.y,
                z: &mut field.z,
            },
        )
        .map_err(|e| e.0)?;
    let mut r = Resampler::new(ResampleParams::default());
    r.resample_cpu(volume.view(), field.as_ref(), None, DirtyRegion::All)
        .map_err(|e| e.to_string())?;
    let out = r.cpu_output().ok_or("no output")?;
    for (i, voxel) in object.iter().enumerate() {
        let q = out
            .grid
            .world_to_index(grid.index_to_world(at(i)) + d)
            .round();
        let value = out.values[out.grid.linear(q.x as usize, q.y as usize, q.z as usize)];
        if value != 100.0 {
            return Err(format!(
                "object voxel {voxel:?} resamples to {value} at {q} (want 100)"
            ));
        }
    }
    let lit = out.values.iter().filter(|&&v| v != 0.0).count();
    if lit != object.len() {
        return Err(format!(
            "{lit} output voxels are above background for {} object voxels",
            object.len()
        ));
    }
    Ok(())
}

/// [`object_survives`] for a one-voxel object at every offset inside a
/// proxy cell of 4 voxels (`params` must set `step = 4`), along each axis,
/// and for a one-voxel slab at each of those offsets, in a 13³ volume; the
/// object is shifted by `[1, −2, 3]` voxels, the slab by `[−1, 2, 1]`.
pub fn every_offset<S: MeshSolver>(params: &str) -> Result<(), String> {
    const N: usize = 13;
    for axis in 0..3 {
        for offset in 0..4 {
            let mut v = [6usize; 3];
            v[axis] = 4 + offset;
            object_survives::<S>(params, [N; 3], &[v], 3, [1, -2, 3])
                .map_err(|e| format!("voxel {v:?}: {e}"))?;
            let slab: Vec<[usize; 3]> = (0..N * N)
                .map(|i| {
                    let mut p = [0; 3];
                    p[(axis + 1) % 3] = i % N;
                    p[(axis + 2) % 3] = i / N;
                    p[axis] = 4 + offset;
                    p
                })
                .collect();
            object_survives::<S>(params, [N; 3], &slab, 3, [-1, 2, 1])
                .map_err(|e| format!("slab at {axis} = {}: {e}", 4 + offset))?;
        }
    }
    Ok(())
}
