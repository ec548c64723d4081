// voxflex resampler: the displacement field (mm, SoA, one value per source voxel),
// bound over the source slab's window (common.wgsl: source_index).

@group(0) @binding(1) var<storage, read> DX: array<f32>;
@group(0) @binding(2) var<storage, read> DY: array<f32>;
@group(0) @binding(3) var<storage, read> DZ: array<f32>;

// Deformed position of vertex (i, j, k): index + displacement / spacing
// (sampling_mesh.rs: deformed_coordinate).
fn vertex_position(i: u32, j: u32, k: u32) -> vec3<f32> {
    let g = source_index(i, j, k);
    return vec3<f32>(
        f32(i) + DX[g] * P.inv.x,
        f32(j) + DY[g] * P.inv.y,
        f32(k) + DZ[g] * P.inv.z,
    );
}
