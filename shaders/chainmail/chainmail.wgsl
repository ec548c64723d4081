// ChainMail on the GPU: the WGSL twins of plugins/chainmail/src/propagate.rs
// (`sponsor`, one Jacobi iteration), relax.rs (`relax_one`, one colour of a
// red-black sweep) and mapping.rs (`copy_identity`), over the same data in
// the same red-black storage order (lattice.rs, `Order::linear`).
//
// Buffers (32-bit structure of arrays):
//   u      f32  [copy][axis][site]   displacement, mm
//   keys   u32  [copy][site]         arrival key (12-bit wave, 20-bit time)
//   sites  u32  [site]               material/flags byte | cut byte << 8
//   links  u32  [a * M + b] * 5      d.x, d.y, d.z (f32 bits), weight (f32
//                                    bits), tau; then M elastic fractions
//   list   u32  [1 + slot]           the block list: its length in word 0,
//                                    then the block indices (built on the
//                                    device by schedule.wgsl, or written
//                                    by the host)
//   stats  atomic<u32> [slot * 4]    per listed block: face mask, visits,
//                                    updates, largest move (f32 bits)
// Dispatched indirectly with one workgroup per listed block (the arguments
// written on the device with the list, folded into x, y; workgroups past
// the length return at once). A listed block's threads stride over it and reduce into workgroup atomics,
// and one thread writes the block's four result words (so nothing needs
// clearing between launches).

struct Params {
    dims: vec4<u32>,   // nx, ny, nz, hx
    blocks: vec4<u32>, // sx, sy, sz, cx
    counts: vec4<u32>, // cy, half, materials, largest workgroup count per dimension
    step: vec4<u32>,   // read (current) copy, colour, sites, tolerance (f32 bits)
    spacing: vec4<f32>, // element spacing, mm (x, y, z, unused)
}

@group(0) @binding(0) var<storage, read> p: Params;
@group(0) @binding(1) var<storage, read_write> u: array<f32>;
@group(0) @binding(2) var<storage, read_write> keys: array<u32>;
@group(0) @binding(3) var<storage, read> sites: array<u32>;
@group(0) @binding(4) var<storage, read> links: array<u32>;
@group(0) @binding(5) var<storage, read> list: array<u32>;
@group(0) @binding(6) var<storage, read_write> stats: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> out_x: array<f32>;
@group(0) @binding(8) var<storage, read_write> out_y: array<f32>;
@group(0) @binding(9) var<storage, read_write> out_z: array<f32>;

const WG: u32 = 64u;
const ABSENT: u32 = 0x3fu;
const HELD: u32 = 0x40u;
const FIXED: u32 = 0x80u;
const CHANGED: u32 = 64u;
const MAX_TIME: u32 = 0xfffffu;
const WAVE_SHIFT: u32 = 20u;
const LINK_WORDS: u32 = 5u;  // per material pair: d.x, d.y, d.z, weight, tau
const STAT_WORDS: u32 = 4u;  // per listed block: face mask, visits, updates, largest move

var<workgroup> wg_mask: atomic<u32>;
var<workgroup> wg_visits: atomic<u32>;
var<workgroup> wg_updates: atomic<u32>;
var<workgroup> wg_max: atomic<u32>;

fn clear_workgroup(lid: u32) {
    if (lid == 0u) {
        atomicStore(&wg_mask, 0u);
        atomicStore(&wg_visits, 0u);
        atomicStore(&wg_updates, 0u);
        atomicStore(&wg_max, 0u);
    }
    workgroupBarrier();
}

// Storage index of element c (lattice.rs, `Order::linear`).
fn linear(c: vec3<u32>) -> u32 {
    let colour = (c.x + c.y + c.z) & 1u;
    return colour * p.counts.y + (c.z * p.dims.y + c.y) * p.dims.w + c.x / 2u;
}

fn u_at(copy: u32, axis: u32, n: u32) -> f32 {
    return u[(copy * 3u + axis) * p.step.z + n];
}

fn u3(copy: u32, n: u32) -> vec3<f32> {
    return vec3<f32>(u_at(copy, 0u, n), u_at(copy, 1u, n), u_at(copy, 2u, n));
}

fn set_u3(copy: u32, n: u32, v: vec3<f32>) {
    u[(copy * 3u) * p.step.z + n] = v.x;
    u[(copy * 3u + 1u) * p.step.z + n] = v.y;
    u[(copy * 3u + 2u) * p.step.z + n] = v.z;
}

fn material(n: u32) -> u32 {
    return sites[n] & ABSENT;
}

// Link table entry of materials a, b: (d, weight, tau).
fn link_d(a: u32, b: u32) -> vec3<f32> {
    let at = (a * p.counts.z + b) * LINK_WORDS;
    return vec3<f32>(bitcast<f32>(links[at]), bitcast<f32>(links[at + 1u]), bitcast<f32>(links[at + 2u]));
}

fn link_weight(a: u32, b: u32) -> f32 {
    return bitcast<f32>(links[(a * p.counts.z + b) * LINK_WORDS + 3u]);
}

fn link_tau(a: u32, b: u32) -> u32 {
    return links[(a * p.counts.z + b) * LINK_WORDS + 4u];
}

fn elastic(m: u32) -> f32 {
    return bitcast<f32>(links[p.counts.z * p.counts.z * LINK_WORDS + m]);
}

// The neighbour of element c along link l (+x, −x, +y, −y, +z, −z), or
// 0xffffffff when it leaves the lattice or the link is cut.
fn neighbour(n: u32, c: vec3<u32>, l: u32) -> u32 {
    if (((sites[n] >> 8u) & (1u << l)) != 0u) {
        return 0xffffffffu;
    }
    let axis = l / 2u;
    var e = vec3<i32>(c);
    if ((l & 1u) == 0u) {
        e[axis] = e[axis] + 1;
    } else {
        e[axis] = e[axis] - 1;
    }
    let d = vec3<i32>(p.dims.xyz);
    if (any(e < vec3<i32>(0)) || any(e >= d)) {
        return 0xffffffffu;
    }
    return linear(vec3<u32>(e));
}

// `earlier` of state.rs: a newer wave, or the same wave earlier.
fn earlier(a: u32, b: u32) -> bool {
    let wa = a >> WAVE_SHIFT;
    let wb = b >> WAVE_SHIFT;
    return wa > wb || (wa == wb && a < b);
}

fn violated(un: vec3<f32>, ue: vec3<f32>, d: vec3<f32>) -> bool {
    return any(un < ue - d) || any(un > ue + d);
}

// Face bits of element c in the block [lo, hi) (blocks.rs, `border`).
fn border(c: vec3<u32>, lo: vec3<u32>, hi: vec3<u32>) -> u32 {
    var m = 0u;
    for (var a = 0u; a < 3u; a = a + 1u) {
        if (c[a] == lo[a]) {
            m = m | (1u << (2u * a));
        }
        if (c[a] + 1u == hi[a]) {
            m = m | (1u << (2u * a + 1u));
        }
    }
    return m;
}

struct Block {
    lo: vec3<u32>,
    hi: vec3<u32>,
    size: vec3<u32>,
}

// Length of the block list.
fn listed() -> u32 {
    return list[0];
}

fn block_of(slot: u32) -> Block {
    let b = list[1u + slot];
    let cx = p.blocks.w;
    let cy = p.counts.x;
    let bc = vec3<u32>(b % cx, (b / cx) % cy, b / (cx * cy));
    var k: Block;
    k.lo = bc * p.blocks.xyz;
    k.hi = min(k.lo + p.blocks.xyz, p.dims.xyz);
    k.size = p.blocks.xyz;
    return k;
}

// Element t of a block (x fastest); may lie past the lattice (test `hi`).
fn element_of(blk: Block, t: u32) -> vec3<u32> {
    let s = blk.size;
    return blk.lo + vec3<u32>(t % s.x, (t / s.x) % s.y, t / (s.x * s.y));
}

// The list slot of a workgroup. Launches over a list are indirect, folded
// as `workgroups_1d` folds (x = min(slots, limit), then y, then z): a
// dimension past the first is used only when the ones before it are the
// device's limit wide, so `num_workgroups` (which D3D12 does not report
// for unvalidated indirect dispatches) is not needed.
fn slot_of(wid: vec3<u32>) -> u32 {
    let limit = p.counts.w;
    return wid.x + limit * (wid.y + limit * wid.z);
}

// One Jacobi propagation iteration over the active blocks: reads copy
// p.step.x, writes the other.
@compute @workgroup_size(64)
fn propagate(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let slot = slot_of(wid);
    if (slot >= listed()) {
        return;
    }
    clear_workgroup(lid);
    let blk = block_of(slot);
    let rd = p.step.x;
    let wr = 1u - rd;
    let total = blk.size.x * blk.size.y * blk.size.z;
    var visits = 0u;
    var updates = 0u;
    var mask = 0u;
    for (var t = lid; t < total; t = t + WG) {
        let c = element_of(blk, t);
        if (any(c >= blk.hi)) {
            continue;
        }
        let n = linear(c);
        let cell = sites[n] & 0xffu;
        if ((cell & ABSENT) == ABSENT) {
            continue;
        }
        visits = visits + 1u;
        let un = u3(rd, n);
        let kn = keys[rd * p.step.z + n];
        var best = 0xffffffffu;
        var best_key = 0u;
        if ((cell & (HELD | FIXED)) == 0u) {
            let mn = cell & ABSENT;
            for (var l = 0u; l < 6u; l = l + 1u) {
                let e = neighbour(n, c, l);
                if (e == 0xffffffffu) {
                    continue;
                }
                let me = material(e);
                if (me == ABSENT) {
                    continue;
                }
                let ke = keys[rd * p.step.z + e];
                if (ke == 0u) {
                    continue;
                }
                let tau = link_tau(mn, me);
                let time = (ke & MAX_TIME) + tau;
                if (time > MAX_TIME) {
                    continue;
                }
                let a = ke + tau;
                if (!earlier(a, kn) || (best != 0xffffffffu && !earlier(a, best_key))) {
                    continue;
                }
                if (violated(un, u3(rd, e), link_d(mn, me))) {
                    best = e;
                    best_key = a;
                }
            }
        }
        if (best != 0xffffffffu) {
            let d = link_d(cell & ABSENT, material(best));
            let ue = u3(rd, best);
            set_u3(wr, n, min(max(un, ue - d), ue + d));
            keys[wr * p.step.z + n] = best_key;
            updates = updates + 1u;
            mask = mask | CHANGED | border(c, blk.lo, blk.hi);
        } else {
            set_u3(wr, n, un);
            keys[wr * p.step.z + n] = kn;
        }
    }
    atomicAdd(&wg_visits, visits);
    atomicAdd(&wg_updates, updates);
    atomicOr(&wg_mask, mask);
    workgroupBarrier();
    if (lid == 0u) {
        atomicStore(&stats[STAT_WORDS * slot], atomicLoad(&wg_mask));
        atomicStore(&stats[STAT_WORDS * slot + 1u], atomicLoad(&wg_visits));
        atomicStore(&stats[STAT_WORDS * slot + 2u], atomicLoad(&wg_updates));
        atomicStore(&stats[STAT_WORDS * slot + 3u], 0u);
    }
}

// One colour (p.step.y) of a red-black relaxation sweep over the active
// blocks, in place in copy p.step.x.
@compute @workgroup_size(64)
fn relax(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let slot = slot_of(wid);
    if (slot >= listed()) {
        return;
    }
    clear_workgroup(lid);
    let blk = block_of(slot);
    let cur = p.step.x;
    let colour = p.step.y;
    let tol = bitcast<f32>(p.step.w);
    let inv = vec3<f32>(1.0) / p.spacing.xyz;
    let total = blk.size.x * blk.size.y * blk.size.z;
    var mask = 0u;
    var max_move = 0.0;
    for (var t = lid; t < total; t = t + WG) {
        let c = element_of(blk, t);
        if (any(c >= blk.hi) || ((c.x + c.y + c.z) & 1u) != colour) {
            continue;
        }
        let n = linear(c);
        let cell = sites[n] & 0xffu;
        if ((cell & ABSENT) == ABSENT || (cell & (HELD | FIXED)) != 0u) {
            continue;
        }
        let mn = cell & ABSENT;
        var sum = vec3<f32>(0.0);
        var wsum = 0.0;
        var lo = vec3<f32>(-3.0e38);
        var hi = vec3<f32>(3.0e38);
        for (var l = 0u; l < 6u; l = l + 1u) {
            let e = neighbour(n, c, l);
            if (e == 0xffffffffu) {
                continue;
            }
            let me = material(e);
            if (me == ABSENT) {
                continue;
            }
            let w = link_weight(mn, me);
            let d = link_d(mn, me);
            let ue = u3(cur, e);
            sum = sum + w * ue;
            lo = max(lo, ue - d);
            hi = min(hi, ue + d);
            wsum = wsum + w;
        }
        if (wsum == 0.0) {
            continue;
        }
        let un = u3(cur, n);
        let mean = sum / wsum;
        let cand = un + elastic(mn) * (mean - un);
        let v = select(un, min(max(cand, lo), hi), lo <= hi);
        set_u3(cur, n, v);
        let mv = max(max(abs(v.x - un.x) * inv.x, abs(v.y - un.y) * inv.y), abs(v.z - un.z) * inv.z);
        max_move = max(max_move, mv);
        if (mv >= tol) {
            mask = mask | CHANGED | border(c, blk.lo, blk.hi);
        }
    }
    atomicMax(&wg_max, bitcast<u32>(max_move));
    atomicOr(&wg_mask, mask);
    workgroupBarrier();
    if (lid == 0u) {
        // The first colour's launch starts the block's results.
        let m = atomicLoad(&wg_mask);
        let mv = atomicLoad(&wg_max);
        if (colour == 0u) {
            atomicStore(&stats[STAT_WORDS * slot], m);
            atomicStore(&stats[STAT_WORDS * slot + 3u], mv);
        } else {
            atomicOr(&stats[STAT_WORDS * slot], m);
            atomicMax(&stats[STAT_WORDS * slot + 3u], mv);
        }
    }
}

// Copies the displacements of the listed blocks from copy p.step.x to the
// other (after relaxation, before propagation).
@compute @workgroup_size(64)
fn sync_copies(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let slot = slot_of(wid);
    if (slot >= listed()) {
        return;
    }
    let blk = block_of(slot);
    let src = p.step.x;
    let total = blk.size.x * blk.size.y * blk.size.z;
    for (var t = lid; t < total; t = t + WG) {
        let c = element_of(blk, t);
        if (any(c >= blk.hi)) {
            continue;
        }
        let n = linear(c);
        set_u3(1u - src, n, u3(src, n));
    }
}

// Identity map: the current displacements in voxel order (x fastest) into
// out_x, out_y, out_z.
@compute @workgroup_size(64)
fn map_identity(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let v = gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
    let nx = p.dims.x;
    let ny = p.dims.y;
    let voxels = nx * ny * p.dims.z;
    if (v >= voxels) {
        return;
    }
    let c = vec3<u32>(v % nx, (v / nx) % ny, v / (nx * ny));
    let n = linear(c);
    let cur = p.step.x;
    out_x[v] = u_at(cur, 0u, n);
    out_y[v] = u_at(cur, 1u, n);
    out_z[v] = u_at(cur, 2u, n);
}
