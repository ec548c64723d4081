// voxflex resampler, pass 2: one invocation per output voxel of the clip box.
// Replaces the owner key by the value interpolated in the owner tetrahedron
// (raster.rs: barycentric, interpolate), or in trilinear mode (P.chi.w == 1)
// by the trilinear sample of the source at the owner's barycentric rest
// position (raster.rs: rest_offset, trilinear_axis, trilinear), or the
// background.
//
// Split source (P.cells.w == 1, gpu_slabs.rs): one pass per source slab,
// each filling only the voxels whose owner cell lies in its cell planes
// [P.cells.x, P.cells.y) (and the unowned ones); FILLED marks the voxels
// already holding a value, so no later pass reads a value as a key. A
// trilinear sample outside the bound window leaves its voxel unfilled and
// counts it in MISSED[0] (the host then fails the call).

@group(0) @binding(6) var<storage, read_write> OUT: array<u32>;
@group(0) @binding(8) var<storage, read> VALUES: array<f32>;
@group(0) @binding(9) var<storage, read_write> FILLED: array<atomic<u32>>;
@group(0) @binding(10) var<storage, read_write> MISSED: array<atomic<u32>>;

// Bit of output element `o` (bound-slab relative) in the bound FILLED range.
fn filled_word(o: u32) -> u32 {
    return (o + P.odim.w) / 32u - P.cells.z;
}

fn filled_bit(o: u32) -> u32 {
    return 1u << ((o + P.odim.w) % 32u);
}

fn set_value(o: u32, v: f32) {
    OUT[o] = bitcast<u32>(v);
    if P.cells.w == 1u {
        atomicOr(&FILLED[filled_word(o)], filled_bit(o));
    }
}

@compute @workgroup_size(64)
fn fill(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = flat_index(gid, nwg);
    let d = vec3<u32>(P.chi.xyz - P.clo.xyz + vec3<i32>(1));
    if n >= d.x * d.y * d.z {
        return;
    }
    let x = P.clo.x + i32(n % d.x);
    let y = P.clo.y + i32((n / d.x) % d.y);
    let z = P.clo.z + i32(n / (d.x * d.y));
    let o = out_index(x, y, z);
    if P.cells.w == 1u && (atomicLoad(&FILLED[filled_word(o)]) & filled_bit(o)) != 0u {
        return;
    }
    let owner = OUT[o];
    if owner == NO_OWNER {
        set_value(o, P.misc.x);
        return;
    }
    let id = owner & 0x7fffffffu;  // the owner key without WEAK_OWNER
    let cell = id / 5u;
    let t = id % 5u;
    let ci = cell % P.cdim.x;
    let cj = (cell / P.cdim.x) % P.cdim.y;
    let ck = cell / (P.cdim.x * P.cdim.y);
    if ck < P.cells.x || ck >= P.cells.y {
        return;
    }
    let parity = (ci + cj + ck) & 1u;
    var p: array<vec3<f32>, 4>;
    var v: vec4<f32>;
    var off: array<vec3<f32>, 4>;
    for (var a = 0u; a < 4u; a++) {
        let c = TETS[parity * 20u + t * 4u + a];
        let oc = vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u);
        let i = ci + oc.x;
        let j = cj + oc.y;
        let k = ck + oc.z;
        p[a] = vertex_position(i, j, k);
        v[a] = VALUES[source_index(i, j, k)];
        off[a] = vec3<f32>(oc);
    }
    let q = vec3<f32>(f32(x), f32(y), f32(z));
    // raster.rs: barycentric — λ_a = t_a(q) / D_a, D_a = ±D (d_of_slot).
    let so = ORIENT[parity * 5u + t] & 3u;
    let fo = make_plane(p[OTHERS[so * 3u]], p[OTHERS[so * 3u + 1u]], p[OTHERS[so * 3u + 2u]]);
    let dt = plane_eval(fo, p[so]);
    var w: vec4<f32>;
    for (var a = 0u; a < 4u; a++) {
        let f = make_plane(p[OTHERS[a * 3u]], p[OTHERS[a * 3u + 1u]], p[OTHERS[a * 3u + 2u]]);
        let dd = d_of_slot(dt, a, so);
        w[a] = select(0.0, plane_eval(f, q) / dd, dd != 0.0);
    }
    if P.chi.w == 1 {
        let t = trilinear_at(vec3<i32>(vec3<u32>(ci, cj, ck)), w, off);
        if t.inside {
            set_value(o, t.value);
        } else {
            atomicAdd(&MISSED[0], 1u);
        }
        return;
    }
    var val = ((w.x * v.x + w.y * v.y) + w.z * v.z) + w.w * v.w;
    if w.w == 1.0 { val = v.w; }
    if w.z == 1.0 { val = v.z; }
    if w.y == 1.0 { val = v.y; }
    if w.x == 1.0 { val = v.x; }
    set_value(o, val);
}

// raster.rs: lerp — exactly `a` when `f == 0` (a NaN neighbour never leaks in).
fn lerp0(a: f32, b: f32, f: f32) -> f32 {
    if f == 0.0 {
        return a;
    }
    return a + f * (b - a);
}

fn source_at(x: i32, y: i32, z: i32) -> f32 {
    return VALUES[source_index(u32(x), u32(y), u32(z))];
}

// A trilinear sample, or `inside == false` (and no read) when its z-planes
// are not all in the bound window [P.slab.y, P.slab.z].
struct Sample {
    value: f32,
    inside: bool,
}

// Trilinear sample of the source at the rest position `cell + Σ w_a off_a`
// (or exactly `off_a` where `w_a == 1`), clamped to the grid
// (raster.rs: rest_offset, trilinear_axis, trilinear).
fn trilinear_at(cell: vec3<i32>, w: vec4<f32>, off: array<vec3<f32>, 4>) -> Sample {
    var r = ((w.x * off[0] + w.y * off[1]) + w.z * off[2]) + w.w * off[3];
    if w.w == 1.0 { r = off[3]; }
    if w.z == 1.0 { r = off[2]; }
    if w.y == 1.0 { r = off[1]; }
    if w.x == 1.0 { r = off[0]; }
    let n = vec3<i32>(P.vdim.xyz);
    let fl = floor(r);
    let g = cell + vec3<i32>(fl);
    let last = n - vec3<i32>(1);
    let i0 = clamp(g, vec3<i32>(0), last);
    let i1 = min(i0 + vec3<i32>(1), last);
    let clamped = (g < vec3<i32>(0)) | (g > n - vec3<i32>(2));
    let f = select(r - fl, vec3<f32>(0.0), clamped);
    if i0.z < i32(P.slab.y) || i1.z > i32(P.slab.z) {
        return Sample(0.0, false);
    }
    let x00 = lerp0(source_at(i0.x, i0.y, i0.z), source_at(i1.x, i0.y, i0.z), f.x);
    let x10 = lerp0(source_at(i0.x, i1.y, i0.z), source_at(i1.x, i1.y, i0.z), f.x);
    let x01 = lerp0(source_at(i0.x, i0.y, i1.z), source_at(i1.x, i0.y, i1.z), f.x);
    let x11 = lerp0(source_at(i0.x, i1.y, i1.z), source_at(i1.x, i1.y, i1.z), f.x);
    let y0 = lerp0(x00, x10, f.y);
    let y1 = lerp0(x01, x11, f.y);
    return Sample(lerp0(y0, y1, f.z), true);
}
