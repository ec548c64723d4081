// voxflex opacity maps: definitions shared by every kernel.
// Mirrors runtime/core/src/opacity/{extinction,frontier,gpu}.rs; keep the
// arithmetic identical (same operations, same order) or the CPU/GPU maps
// stop being bit-identical.
//
// Indices: "box" = linear (x fastest) in the working box, "volume" = linear
// in the volume. Opacities are u16 fixed point (65535 = 1), two per u32
// word of `field` (voxel 2w in the low half of word w).

struct Params {
    vdim: vec4<u32>,  // volume dims x, y, z; w = the device's largest workgroup count per dimension
    blo: vec4<u32>,   // working box lower corner (volume voxel index); w = box voxels
    bdim: vec4<u32>,  // working box dims; w = the volume-linear index of values[0] (the bound window's first value)
    ext: vec4<f32>,   // d_s, sigma_s, K = 65535 / (lambda sigma_s), cap = (lambda + 2) sigma_s
    q: vec4<u32>,     // q_min, q_max; z = 1: face neighbours only (connectivity 6); w unused
}

// Working-box change (regrow, remap).
struct Regrow {
    olo: vec4<u32>,   // old box lower corner; w = frontier entries to remap
    odim: vec4<u32>,  // old box dims; w = q_min
    nlo: vec4<u32>,   // new box lower corner; w = new box voxels
    ndim: vec4<u32>,  // new box dims; w = q_max
}

const WG: u32 = 64u;
const E_BOUND: f32 = 131072.0;   // extinction.rs: E_BOUND
const NONE: u32 = 0xffffffffu;
const MARK_CANDIDATE: u32 = 1u;  // frontier.rs
const MARK_DONE: u32 = 2u;

@group(0) @binding(0) var<storage, read> P: Params;
// Sanitised voxel values: the x-y planes the working box spans, from the
// volume-linear index P.bdim.w on (gpu.rs: values_window).
@group(0) @binding(1) var<storage, read> values: array<f32>;
@group(0) @binding(2) var<storage, read_write> field: array<atomic<u32>>;
// Two marks per box voxel, 16 voxels per word: bit 2i candidate, bit 2i+1 done.
@group(0) @binding(3) var<storage, read_write> marks: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read> front: array<u32>;              // frontier (box indices)
@group(0) @binding(5) var<storage, read_write> cand: array<u32>;         // candidates (box indices)
@group(0) @binding(6) var<storage, read_write> newval: array<u32>;       // new value per candidate
@group(0) @binding(7) var<storage, read_write> next: array<u32>;         // next frontier (box indices)
// 0 frontier length, 1 candidates, 2 next frontier length, 4..6 min x y z,
// 8..10 max x y z of the voxels that rose (volume voxel index).
@group(0) @binding(8) var<storage, read_write> counters: array<atomic<u32>>;
@group(0) @binding(9) var<storage, read> old_field: array<u32>;
@group(0) @binding(10) var<storage, read> R: Regrow;
// Workgroups of the kernels over the candidates (indirect arguments).
@group(0) @binding(11) var<storage, read_write> args: array<u32>;

// Flat invocation index of a folded 3-D dispatch (gpu.rs: workgroups_1d).
fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
}

// The same for an indirect dispatch whose arguments `size_candidates`
// folded as workgroups_1d does (x, then y, then z, each up to the device's
// limit P.vdim.w): without `num_workgroups`, which D3D12 does not report
// for unvalidated indirect dispatches.
fn folded_index(gid: vec3<u32>) -> u32 {
    let limit = P.vdim.w;
    return gid.x + WG * limit * (gid.y + limit * gid.z);
}

// extinction.rs: Extinction::fixed (values are sanitised on upload).
fn extinction(dv: f32) -> i32 {
    let a = min(abs(P.ext.x - dv), P.ext.w);
    let e = clamp((a - P.ext.y) * P.ext.z, -E_BOUND, E_BOUND);
    return i32(round(e));
}

// extinction.rs: Extinction::rise.
fn rise(m: u32, e: i32) -> u32 {
    return u32(clamp(i32(m) - e, i32(P.q.x), i32(P.q.y)));
}

fn field_get(v: u32) -> u32 {
    return (atomicLoad(&field[v >> 1u]) >> ((v & 1u) * 16u)) & 0xffffu;
}

fn box_coords(l: u32) -> vec3<u32> {
    let x = l % P.bdim.x;
    let r = l / P.bdim.x;
    return vec3<u32>(x, r % P.bdim.y, r / P.bdim.y);
}

fn box_linear(c: vec3<u32>) -> u32 {
    return c.x + P.bdim.x * (c.y + P.bdim.y * c.z);
}

fn vol_linear(c: vec3<u32>) -> u32 {
    let p = P.blo.xyz + c;
    return p.x + P.vdim.x * (p.y + P.vdim.y * p.z);
}

// The value of the voxel at box coordinates c (inside the working box).
fn value_at(c: vec3<u32>) -> f32 {
    return values[vol_linear(c) - P.bdim.w];
}

// True when box coordinates p lie inside the working box.
fn inside_box(p: vec3<i32>) -> bool {
    return all(p >= vec3<i32>(0)) && all(p < vec3<i32>(P.bdim.xyz));
}

var<workgroup> w_count: atomic<u32>;
var<workgroup> w_base: u32;

// True when offset d (each component in -1..1) is not a neighbour that
// passes opacity on: the voxel itself, or an edge or corner neighbour
// under connectivity 6 (frontier.rs: Lattice::for_each_neighbour).
fn not_a_neighbour(d: vec3<i32>) -> bool {
    let taxicab = abs(d.x) + abs(d.y) + abs(d.z);
    return taxicab == 0 || (P.q.z == 1u && taxicab > 1);
}
