// voxflex fluid weights: the column-grid pass of Rodríguez, Coevoet and
// Duriez (ICRA 2017) on the GPU. Twin of runtime/fluid/src/{hits,sections,
// weighing}.rs; the CPU prepares the projection (projection.rs) and uploads
// it, so both paths test the same candidates with the same triangle sides.
//
// Coordinates: (u, v, h) in the gravity frame, relative to the grid's lower
// corner and the lowest vertex (mm, f32).

struct Params {
    grid: vec4<u32>,   // n_u, n_v, k (workers per triangle), triangles
    more: vec4<u32>,   // cap (crossing slots per column), columns, vertices, 0
    geom: vec4<f32>,   // cell w, cell d, column area w·d (mm²), ρ·|g| in µN/mm³
}

const WG: u32 = 64u;
const MAX_CAP: u32 = 32u;           // gpu.rs: MAX_CROSSINGS_PER_COLUMN
const TOP: u32 = 0x80000000u;       // hits.rs: TOP
const STATUS_HEADER: u32 = 8u;      // gpu.rs: STATUS_HEADER

@group(0) @binding(0) var<storage, read> P: Params;
@group(0) @binding(1) var<storage, read> uvh: array<f32>;        // 3 per vertex
@group(0) @binding(2) var<storage, read> tris: array<u32>;       // 3 per triangle
@group(0) @binding(3) var<storage, read> info: array<u32>;       // 4 per triangle: i0, i1, j0, j1 | TOP
@group(0) @binding(4) var<storage, read_write> counts: array<atomic<u32>>;  // crossings per column
@group(0) @binding(5) var<storage, read_write> rec_tri: array<u32>;         // cap slots per column: triangle | TOP
@group(0) @binding(6) var<storage, read_write> rec_h: array<f32>;           // cap slots per column: height
@group(0) @binding(7) var<storage, read_write> weights: array<atomic<u32>>; // f32 bits per vertex, µN
// 0 most crossings in one column, 1 sections, 2 columns with fluid,
// 3 irregular columns, 4 crossings; from STATUS_HEADER: per workgroup of
// `sections`, its fluid volume (f32 bits, mm³).
@group(0) @binding(8) var<storage, read_write> status: array<atomic<u32>>;

// Flat invocation index of a folded 3-D dispatch (gpu.rs: workgroups_1d).
fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
}

fn corner_uv(v: u32) -> vec2<f32> {
    return vec2<f32>(uvh[3u * v], uvh[3u * v + 1u]);
}

fn column_centre(i: u32, j: u32) -> vec2<f32> {
    return (vec2<f32>(f32(i), f32(j)) + 0.5) * P.geom.xy;
}

fn perp(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
}

// hits.rs: TriangleTest — the edge function along the canonical direction
// (lower vertex index first); a tie is decided by the sign at p + (ε, ε²).
// Returns (1 if p is on the interior side else 0, the edge value with the
// interior positive).
fn edge_test(ia: u32, ib: u32, qa: vec2<f32>, qb: vec2<f32>, orient: f32, p: vec2<f32>) -> vec2<f32> {
    var a = qa;
    var b = qb;
    var side = orient;
    if (ia > ib) {
        a = qb;
        b = qa;
        side = -orient;
    }
    let d = b - a;
    let value = perp(d, p - a);
    var sgn = sign(value);
    if (value == 0.0) {
        if (d.y != 0.0) { sgn = -sign(d.y); } else { sgn = sign(d.x); }
    }
    return vec2<f32>(select(0.0, 1.0, sgn * side > 0.0), value * side);
}

// One worker of one triangle: its candidates lane, lane + k, … (schedule.rs),
// each crossing appended to its column's slots.
@compute @workgroup_size(64)
fn emit(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let w = flat_index(gid, nwg);
    let k = P.grid.z;
    if (w >= k * P.grid.w) {
        return;
    }
    let t = w / k;
    let i0 = info[4u * t];
    let i1 = info[4u * t + 1u];
    let j0 = info[4u * t + 2u];
    let top = (info[4u * t + 3u] & TOP) != 0u;
    let j1 = info[4u * t + 3u] & ~TOP;
    let width = i1 - i0;
    let count = width * (j1 - j0);
    let ids = vec3<u32>(tris[3u * t], tris[3u * t + 1u], tris[3u * t + 2u]);
    let q0 = corner_uv(ids.x);
    let q1 = corner_uv(ids.y);
    let q2 = corner_uv(ids.z);
    let hs = vec3<f32>(uvh[3u * ids.x + 2u], uvh[3u * ids.y + 2u], uvh[3u * ids.z + 2u]);
    let orient = select(-1.0, 1.0, top);
    let total = abs(perp(q1 - q0, q2 - q0));
    let tag = t | select(0u, TOP, top);
    for (var m = w % k; m < count; m += k) {
        let i = i0 + m % width;
        let j = j0 + m / width;
        let p = column_centre(i, j);
        // opposite corner 0 is edge 1→2, corner 1: 2→0, corner 2: 0→1
        let e0 = edge_test(ids.y, ids.z, q1, q2, orient, p);
        let e1 = edge_test(ids.z, ids.x, q2, q0, orient, p);
        let e2 = edge_test(ids.x, ids.y, q0, q1, orient, p);
        if (e0.x * e1.x * e2.x == 0.0) {
            continue;
        }
        let b0 = e0.y / total;
        let b1 = e1.y / total;
        let h = dot(vec3<f32>(b0, b1, 1.0 - b0 - b1), hs);
        let col = i + j * P.grid.x;
        let slot = atomicAdd(&counts[col], 1u);
        atomicMax(&status[0], slot + 1u);
        if (slot < P.more.x) {
            rec_tri[col * P.more.x + slot] = tag;
            rec_h[col * P.more.x + slot] = h;
        }
    }
}

// weighing.rs: barycentric — of p in the triangle's projection.
fn barycentric(ids: vec3<u32>, p: vec2<f32>) -> vec3<f32> {
    let q0 = corner_uv(ids.x);
    let q1 = corner_uv(ids.y);
    let q2 = corner_uv(ids.z);
    let area2 = perp(q1 - q0, q2 - q0);
    let b0 = perp(q1 - p, q2 - p) / area2;
    let b1 = perp(p - q0, q2 - q0) / area2;
    return vec3<f32>(b0, b1, 1.0 - b0 - b1);
}

// Adds w to a vertex's weight (f32 in a u32 atomic: compare-and-swap).
fn add_weight(v: u32, w: f32) {
    var old = atomicLoad(&weights[v]);
    loop {
        let r = atomicCompareExchangeWeak(&weights[v], old, bitcast<u32>(bitcast<f32>(old) + w));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}

var<workgroup> wg_volume: array<f32, 64>;
var<workgroup> wg_counts: array<atomic<u32>, 4>;

// sections.rs: match_column, then weighing.rs: distribute — one column per
// invocation: its crossings sorted by height (a bottom first at a tie),
// matched bottom → top, each section's weight A·h·ρ|g| onto its bottom
// triangle's corners.
@compute @workgroup_size(64)
fn sections(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
) {
    let c = flat_index(gid, nwg);
    var n = 0u;
    if (c < P.more.y) {
        n = min(atomicLoad(&counts[c]), min(P.more.x, MAX_CAP));
    }
    var th: array<f32, MAX_CAP>;
    var tt: array<u32, MAX_CAP>;
    for (var s = 0u; s < n; s++) {
        // insertion sort by (height, top after bottom)
        let h = rec_h[c * P.more.x + s];
        let tag = rec_tri[c * P.more.x + s];
        var at = s;
        while (at > 0u && (th[at - 1u] > h || (th[at - 1u] == h && tag < TOP && tt[at - 1u] >= TOP))) {
            th[at] = th[at - 1u];
            tt[at] = tt[at - 1u];
            at--;
        }
        th[at] = h;
        tt[at] = tag;
    }
    var alternates = n % 2u == 0u;
    for (var s = 0u; s + 1u < n; s += 2u) {
        alternates = alternates && tt[s] < TOP && tt[s + 1u] >= TOP;
    }
    var volume = 0.0;
    var pairs = 0u;
    if (alternates && n > 0u) {
        let centre = column_centre(c % P.grid.x, c / P.grid.x);
        for (var s = 0u; s + 1u < n; s += 2u) {
            let fluid = th[s + 1u] - th[s];
            pairs++;
            if (fluid <= 0.0) {
                continue;
            }
            let v = P.geom.z * fluid;
            volume += v;
            let t = tt[s];
            let ids = vec3<u32>(tris[3u * t], tris[3u * t + 1u], tris[3u * t + 2u]);
            let b = barycentric(ids, centre) * (P.geom.w * v);
            add_weight(ids.x, b.x);
            add_weight(ids.y, b.y);
            add_weight(ids.z, b.z);
        }
    }
    wg_volume[lid] = volume;
    if (pairs > 0u) {
        atomicAdd(&wg_counts[0], pairs);
        atomicAdd(&wg_counts[1], 1u);
    }
    if (!alternates) {
        atomicAdd(&wg_counts[2], 1u);
    }
    atomicAdd(&wg_counts[3], n);
    workgroupBarrier();
    for (var stride = 32u; stride > 0u; stride /= 2u) {
        if (lid < stride) {
            wg_volume[lid] += wg_volume[lid + stride];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        let g = wid.x + wid.y * nwg.x + wid.z * nwg.x * nwg.y;
        atomicStore(&status[STATUS_HEADER + g], bitcast<u32>(wg_volume[0]));
        atomicAdd(&status[1], atomicLoad(&wg_counts[0]));
        atomicAdd(&status[2], atomicLoad(&wg_counts[1]));
        atomicAdd(&status[3], atomicLoad(&wg_counts[2]));
        atomicAdd(&status[4], atomicLoad(&wg_counts[3]));
    }
}
