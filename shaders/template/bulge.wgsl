// STEP 5: the GPU path of the `template` plugin — the WGSL twin of
// plugins/template/src/field.rs (FieldUniforms::displacement). Same
// constants, same f32 formula; the parity test compares the two.
//
// Writes one displacement (mm, world axes) per point into three
// structure-of-arrays f32 buffers (the resampler's inputs). The points are
// every node of a lattice (mode 0) or an explicit list (mode 1). One
// dispatch covers the slab of points `mode.y .. mode.y + mode.z`, with every
// per-point array bound from point `mode.y` on: arrays larger than one
// storage binding are written slab by slab.

struct Uniforms {
    centre_radius: vec4<f32>, // ball centre (mm), radius (mm)
    amplitude: vec4<f32>,     // x: ramped amplitude (mm)
    origin: vec4<f32>,        // lattice origin (mm)
    spacing: vec4<f32>,       // lattice spacing (mm)
    counts: vec4<u32>,        // nx, ny, nz (lattice); w unused
    mode: vec4<u32>,          // x: 0 lattice, 1 list; y: first point; z: points
}

@group(0) @binding(0) var<storage, read> u: Uniforms;
@group(0) @binding(1) var<storage, read> px: array<f32>;
@group(0) @binding(2) var<storage, read> py: array<f32>;
@group(0) @binding(3) var<storage, read> pz: array<f32>;
@group(0) @binding(4) var<storage, read_write> ux: array<f32>;
@group(0) @binding(5) var<storage, read_write> uy: array<f32>;
@group(0) @binding(6) var<storage, read_write> uz: array<f32>;

const WG: u32 = 64u;

fn displacement(p: vec3<f32>) -> vec3<f32> {
    let q = (p - u.centre_radius.xyz) / u.centre_radius.w;
    let t2 = dot(q, q);
    if (t2 >= 1.0) {
        return vec3<f32>(0.0);
    }
    let w = 1.0 - t2;
    return q * (u.amplitude.x * w * w);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    // Large point counts are dispatched as a 3-D grid of workgroups
    // (at most 65535 per dimension): fold it back into one index.
    // n: the point within the slab (and the bound windows); g: in all.
    let n = gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
    if (n >= u.mode.z) {
        return;
    }
    let g = u.mode.y + n;
    var p: vec3<f32>;
    if (u.mode.x == 0u) {
        let nx = u.counts.x;
        let ny = u.counts.y;
        let i = g % nx;
        let j = (g / nx) % ny;
        let k = g / (nx * ny);
        p = u.origin.xyz + vec3<f32>(f32(i), f32(j), f32(k)) * u.spacing.xyz;
    } else {
        p = vec3<f32>(px[n], py[n], pz[n]);
    }
    let d = displacement(p);
    ux[n] = d.x;
    uy[n] = d.y;
    uz[n] = d.z;
}
