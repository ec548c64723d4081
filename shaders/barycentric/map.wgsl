// Barycentric map: the WGSL twin of `BarycentricBinding::map`
// (runtime/core/src/barycentric/mod.rs). Per bound point, its tetrahedron's
// four node displacements (mm) weighted by its barycentric weights, stored
// as 16-bit fractions of corners 1–3 (corner 0 takes the rest).
//
// One slab of points per dispatch: every per-point buffer is bound from the
// slab's first point on.

struct Params {
    count: vec4<u32>, // points in the slab, unused ×3
}

@group(0) @binding(0) var<storage, read> p: Params;
@group(0) @binding(1) var<storage, read> tet_of: array<u32>;
@group(0) @binding(2) var<storage, read> w12: array<u32>;      // w1 | w2 << 16
@group(0) @binding(3) var<storage, read> w3: array<u32>;       // two points per word
@group(0) @binding(4) var<storage, read> tets: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read> nodes: array<vec4<f32>>; // x, y, z, unused (mm)
@group(0) @binding(6) var<storage, read_write> out_x: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_y: array<f32>;
@group(0) @binding(8) var<storage, read_write> out_z: array<f32>;

const WG: u32 = 64u;
const UNIT: f32 = 1.0 / 65535.0;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
    if (i >= p.count.x) {
        return;
    }
    let t = tets[tet_of[i]];
    let q = w12[i];
    let w1 = f32(q & 0xffffu) * UNIT;
    let w2 = f32(q >> 16u) * UNIT;
    let w3v = f32((w3[i / 2u] >> (16u * (i % 2u))) & 0xffffu) * UNIT;
    let w0 = 1.0 - w1 - w2 - w3v;
    let u = nodes[t.x] * w0 + nodes[t.y] * w1 + nodes[t.z] * w2 + nodes[t.w] * w3v;
    out_x[i] = u.x;
    out_y[i] = u.y;
    out_z[i] = u.z;
}
