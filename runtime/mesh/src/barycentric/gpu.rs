//! The WGSL path of the barycentric map (`shaders/barycentric/map.wgsl`):
//! the binding uploaded once, mapped every frame from a node buffer, in
//! slabs of points so that no binding exceeds the device's
//! `max_storage_buffer_binding_size`.
//!
//! Per point the device holds the tetrahedron index (4 B) and the weights
//! (corners 1 and 2 in one word, corner 3 packed two points to a word):
//! 10 bytes, as on the CPU.

use super::BarycentricBinding;
use crate::error::GpuError;
use crate::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt};
use crate::tet_mesh::TetMesh;
use voxflex_core::point_slabs::{alignment_unit, point_slabs};

/// The map kernel.
pub const MAP_WGSL: &str = include_str!("../../../../shaders/barycentric/map.wgsl");

/// Threads per workgroup of the map kernel (`@workgroup_size` in `map.wgsl`).
const WORKGROUP: u32 = 64;
/// Bytes of the kernel's `Params` (the point count and three unused words).
const PARAMS_BYTES: u64 = 16;

/// Binding numbers of `map.wgsl`'s variables (named as there; `PARAMS` is `p`).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const TET_OF: u32 = 1;
    pub const W12: u32 = 2;
    pub const W3: u32 = 3;
    pub const TETS: u32 = 4;
    pub const NODES: u32 = 5;
    pub const OUT_X: u32 = 6;
    pub const OUT_Y: u32 = 7;
    pub const OUT_Z: u32 = 8;
}

/// A binding on the device.
#[derive(Debug)]
pub struct GpuBinding {
    tet_of: BufferId,
    w12: BufferId,
    w3: BufferId,
    tets: BufferId,
    params: BufferId,
    points: usize,
}

impl BarycentricBinding {
    /// Uploads the binding and `mesh`'s tetrahedra. Refuses (with what to
    /// do) a mesh whose tetrahedron list exceeds one storage binding.
    pub fn upload(&self, mesh: &TetMesh, gpu: &dyn GpuService) -> Result<GpuBinding, GpuError> {
        let limit = gpu.limits().max_storage_buffer_binding_size;
        if 16 * mesh.tets.len() as u64 > limit {
            return Err(GpuError(format!(
                "barycentric map: {} tetrahedra need {} bytes in one binding, above this \
                 device's {limit}; use a coarser proxy or the CPU path",
                mesh.tets.len(),
                16 * mesh.tets.len()
            )));
        }
        let w12: Vec<u32> = self
            .weights
            .iter()
            .map(|q| q[0] as u32 | (q[1] as u32) << 16)
            .collect();
        let w3: Vec<u32> = self
            .weights
            .chunks(2)
            .map(|pair| pair[0][2] as u32 | pair.get(1).map_or(0, |q| (q[2] as u32) << 16))
            .collect();
        Ok(GpuBinding {
            tet_of: gpu.upload(&self.tet, "barycentric tetrahedra of points")?,
            w12: gpu.upload(&w12, "barycentric weights 1-2")?,
            w3: gpu.upload(&w3, "barycentric weights 3")?,
            tets: gpu.upload(&mesh.tets, "barycentric tetrahedra")?,
            params: gpu.create_buffer(PARAMS_BYTES, "barycentric params")?,
            points: self.len(),
        })
    }
}

impl GpuBinding {
    /// Maps the points from `nodes` (one `[x, y, z, _]` f32 vector per node,
    /// mm; at most one binding) into `out` (x, y, z buffers of at least one
    /// f32 per point).
    pub fn map(
        &self,
        gpu: &dyn GpuService,
        nodes: BufferId,
        out: [BufferId; 3],
    ) -> Result<(), GpuError> {
        let limits = gpu.limits();
        // A slab's first point must start every per-point binding on the
        // offset alignment: the 4-byte arrays need multiples of align / 4
        // points, the two-points-per-word array multiples of align / 2.
        let unit = alignment_unit(&limits, 2).max(2);
        let slabs = point_slabs(self.points, 4, unit, &limits).ok_or_else(|| {
            GpuError(format!(
                "this GPU binds at most {} bytes per storage array, less than {unit} points",
                limits.max_storage_buffer_binding_size
            ))
        })?;
        let pipeline = gpu.compile(MAP_WGSL, "main")?;
        for points in slabs {
            let (first, count) = (points.start, points.len());
            gpu.write_buffer(
                self.params,
                0,
                bytemuck::cast_slice(&[count as u32, 0, 0, 0]),
            )?;
            let slab = |binding: u32, buffer: BufferId, bytes_per_point: u64| BufferBinding {
                binding,
                buffer,
                offset: first as u64 * bytes_per_point,
                size: (count as u64 * bytes_per_point).next_multiple_of(4),
            };
            let bindings = [
                BufferBinding::whole(bind::PARAMS, self.params),
                slab(bind::TET_OF, self.tet_of, 4),
                slab(bind::W12, self.w12, 4),
                BufferBinding {
                    binding: bind::W3,
                    buffer: self.w3,
                    offset: first as u64 * 2,
                    size: (count as u64).div_ceil(2) * 4,
                },
                BufferBinding::whole(bind::TETS, self.tets),
                BufferBinding::whole(bind::NODES, nodes),
                slab(bind::OUT_X, out[0], 4),
                slab(bind::OUT_Y, out[1], 4),
                slab(bind::OUT_Z, out[2], 4),
            ];
            gpu.dispatch(
                pipeline,
                &bindings,
                gpu.workgroups_for(count as u64, WORKGROUP)?,
            )?;
        }
        Ok(())
    }

    /// Frees the device buffers.
    pub fn release(self, gpu: &dyn GpuService) {
        for id in [self.tet_of, self.w12, self.w3, self.tets, self.params] {
            gpu.destroy_buffer(id);
        }
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;
