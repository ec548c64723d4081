// Block-Jacobi preconditioned conjugate gradients on the GPU: the WGSL twin
// of runtime/core/src/mesh_model/pcg.rs (without hanging nodes). The matrix
// is the CPU's assembled block-sparse matrix in f32: row i's 3 × 3 blocks
// are blocks[row_start[i] .. row_start[i + 1]], of the nodes col[k], each
// stored as three vec4 columns. Vectors hold one vec4 per node (xyz used).
// free[i]: 0 for a constrained node (fixed or driven: keeps x, carries zero
// r, z, p), 1 for a free node, 2 for a hanging node, tied to its masters
// (x and p follow them; its rows of A p and b − A x are moved onto them
// before they are used: the system is Pᵀ A P on the free nodes, as in
// runtime/core/src/mesh_model/pcg.rs).
// Dot products reduce in two passes (per workgroup, then one workgroup)
// into scalar slots, and the updates read α and β from those slots on the
// device, so an iteration needs no read-back.

struct Params {
    nodes: u32,
    partials: u32, // workgroups of the first reduction pass
    pad0: u32,
    pad1: u32,
}

// Scalar slots, 64 words apart (256-byte binding offsets).
const RZ: u32 = 0u;     // r·z of the current iteration
const PQ: u32 = 64u;    // p·q
const RZ_NEW: u32 = 128u;
const RR: u32 = 192u;   // r·r, for the stopping test

@group(0) @binding(0) var<storage, read> p_: Params;
@group(0) @binding(1) var<storage, read> row_start: array<u32>;
@group(0) @binding(2) var<storage, read> col: array<u32>;
@group(0) @binding(3) var<storage, read> blocks: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> inv: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> free: array<u32>;
@group(0) @binding(6) var<storage, read_write> x: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> r: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> z: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> p: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> q: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> scalars: array<f32>;
@group(0) @binding(12) var<storage, read_write> partial: array<f32>;
@group(0) @binding(13) var<storage, read> b: array<vec4<f32>>;
// Ties: hanging node n's masters are tie_list[tie_start[n] .. tie_start[n + 1]]
// and the hanging nodes master n carries are untie_list[untie_start[n] ..],
// each as (node, weight as f32 bits).
@group(0) @binding(14) var<storage, read> tie_start: array<u32>;
@group(0) @binding(15) var<storage, read> tie_list: array<vec2<u32>>;
@group(0) @binding(16) var<storage, read> untie_start: array<u32>;
@group(0) @binding(17) var<storage, read> untie_list: array<vec2<u32>>;

const WG: u32 = 64u;
const RED: u32 = 256u;
const MAX_PARTIALS: u32 = 1024u; // first-pass partials per product (pcg_gpu.rs)

fn flat(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    let row = nwg.x * WG;
    return gid.x + gid.y * row + gid.z * row * nwg.y;
}

fn block_times(k: u32, v: vec3<f32>) -> vec3<f32> {
    return blocks[3u * k].xyz * v.x + blocks[3u * k + 1u].xyz * v.y + blocks[3u * k + 2u].xyz * v.z;
}

fn precondition(i: u32, v: vec3<f32>) -> vec3<f32> {
    return inv[3u * i].xyz * v.x + inv[3u * i + 1u].xyz * v.y + inv[3u * i + 2u].xyz * v.z;
}

// Row i of A times x (`of_p` false) or p (`of_p` true).
fn row_times(i: u32, of_p: bool) -> vec3<f32> {
    var acc = vec3<f32>(0.0);
    for (var k = row_start[i]; k < row_start[i + 1u]; k = k + 1u) {
        var v = x[col[k]].xyz;
        if (of_p) {
            v = p[col[k]].xyz;
        }
        acc = acc + block_times(k, v);
    }
    return acc;
}

// r = b − A x on free and hanging nodes (the hanging rows are moved onto
// their masters by `untie_r`, then cleared by `begin_search`).
@compute @workgroup_size(64)
fn start(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes) {
        return;
    }
    var ri = vec3<f32>(0.0);
    if (free[i] != 0u) {
        ri = b[i].xyz - row_times(i, false);
    }
    r[i] = vec4<f32>(ri, 0.0);
}

// r on free nodes only; z = M⁻¹ r; p = z (then `tie_p`).
@compute @workgroup_size(64)
fn begin_search(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes) {
        return;
    }
    var ri = r[i].xyz;
    if (free[i] != 1u) {
        ri = vec3<f32>(0.0);
    }
    let zi = precondition(i, ri);
    r[i] = vec4<f32>(ri, 0.0);
    z[i] = vec4<f32>(zi, 0.0);
    p[i] = vec4<f32>(zi, 0.0);
}

// The hanging rows onto their free masters: v[m] += Σ w v[h] (Pᵀ).
fn untie_into(i: u32, v: vec3<f32>, of_q: bool) -> vec3<f32> {
    var acc = v;
    for (var k = untie_start[i]; k < untie_start[i + 1u]; k = k + 1u) {
        let e = untie_list[k];
        var vh = r[e.x].xyz;
        if (of_q) {
            vh = q[e.x].xyz;
        }
        acc = acc + bitcast<f32>(e.y) * vh;
    }
    return acc;
}

@compute @workgroup_size(64)
fn untie_r(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes || free[i] != 1u) {
        return;
    }
    r[i] = vec4<f32>(untie_into(i, r[i].xyz, false), 0.0);
}

@compute @workgroup_size(64)
fn untie_q(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes || free[i] != 1u) {
        return;
    }
    q[i] = vec4<f32>(untie_into(i, q[i].xyz, true), 0.0);
}

// Hanging nodes of p follow their masters (P).
@compute @workgroup_size(64)
fn tie_p(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes || free[i] != 2u) {
        return;
    }
    var acc = vec3<f32>(0.0);
    for (var k = tie_start[i]; k < tie_start[i + 1u]; k = k + 1u) {
        let e = tie_list[k];
        acc = acc + bitcast<f32>(e.y) * p[e.x].xyz;
    }
    p[i] = vec4<f32>(acc, 0.0);
}

// q = A p on free and hanging nodes.
@compute @workgroup_size(64)
fn spmv(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes) {
        return;
    }
    var qi = vec3<f32>(0.0);
    if (free[i] != 0u) {
        qi = row_times(i, true);
    }
    q[i] = vec4<f32>(qi, 0.0);
}

// x += α p, r −= α q, z = M⁻¹ r, with α = r·z / p·q.
@compute @workgroup_size(64)
fn update_xr(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes) {
        return;
    }
    // Converged (or broken down): p·q is 0 and the step stops.
    var alpha = 0.0;
    if (scalars[PQ] > 0.0) {
        alpha = scalars[RZ] / scalars[PQ];
    }
    // x follows p everywhere (p is zero on constrained nodes and tied on
    // hanging ones); r and z live on free nodes only.
    x[i] = vec4<f32>(x[i].xyz + alpha * p[i].xyz, 0.0);
    if (free[i] != 1u) {
        return;
    }
    let ri = r[i].xyz - alpha * q[i].xyz;
    r[i] = vec4<f32>(ri, 0.0);
    z[i] = vec4<f32>(precondition(i, ri), 0.0);
}

// p = z + β p, with β = r·z (new) / r·z (old).
@compute @workgroup_size(64)
fn update_p(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat(gid, nwg);
    if (i >= p_.nodes) {
        return;
    }
    var beta = 0.0;
    if (scalars[RZ] > 0.0) {
        beta = scalars[RZ_NEW] / scalars[RZ];
    }
    p[i] = vec4<f32>(z[i].xyz + beta * p[i].xyz, 0.0);
}

// The new r·z becomes the current one (one thread).
@compute @workgroup_size(1)
fn advance() {
    scalars[RZ] = scalars[RZ_NEW];
}

var<workgroup> sums: array<f32, RED>;

fn reduce_into(lid: u32, value: f32) -> f32 {
    sums[lid] = value;
    workgroupBarrier();
    for (var s = RED / 2u; s > 0u; s = s / 2u) {
        if (lid < s) {
            sums[lid] = sums[lid] + sums[lid + s];
        }
        workgroupBarrier();
    }
    return sums[0];
}

// First pass of a dot product: each workgroup's share into partial[wg].
fn dot_partial(wg: u32, lid: u32, which: u32) {
    var acc = 0.0;
    for (var i = wg * RED + lid; i < p_.nodes; i = i + RED * p_.partials) {
        if (free[i] != 1u) {
            continue;
        }
        var a = vec3<f32>(0.0);
        var c = vec3<f32>(0.0);
        if (which == 0u) {
            a = p[i].xyz;
            c = q[i].xyz;
        } else if (which == 1u) {
            a = r[i].xyz;
            c = z[i].xyz;
        } else {
            a = r[i].xyz;
            c = r[i].xyz;
        }
        acc = acc + dot(a, c);
    }
    let total = reduce_into(lid, acc);
    if (lid == 0u) {
        partial[which * MAX_PARTIALS + wg] = total;
    }
}

@compute @workgroup_size(256)
fn dot_pq(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    dot_partial(wg.x, lid, 0u);
}

@compute @workgroup_size(256)
fn dot_rz(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    dot_partial(wg.x, lid, 1u);
}

@compute @workgroup_size(256)
fn dot_rr(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    dot_partial(wg.x, lid, 2u);
}

// Second pass: the partials of the three dot products into their slots (one
// workgroup; PQ for p·q, RZ_NEW for r·z, RR for r·r). A product whose first
// pass did not run this round is summed again from its last partials, which
// gives its last value; nothing reads it before it is refreshed.
@compute @workgroup_size(256)
fn dot_final(@builtin(local_invocation_index) lid: u32) {
    for (var which = 0u; which < 3u; which = which + 1u) {
        var acc = 0.0;
        for (var w = lid; w < p_.partials; w = w + RED) {
            acc = acc + partial[which * MAX_PARTIALS + w];
        }
        let total = reduce_into(lid, acc);
        if (lid == 0u) {
            if (which == 0u) {
                scalars[PQ] = total;
            } else if (which == 1u) {
                scalars[RZ_NEW] = total;
            } else {
                scalars[RR] = total;
            }
        }
        workgroupBarrier();
    }
}

// After `start`: the first r·z is the current one.
@compute @workgroup_size(1)
fn begin() {
    scalars[RZ] = scalars[RZ_NEW];
}
