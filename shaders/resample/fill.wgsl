// voxflex resampler, pass 2: one invocation per output voxel of the clip box.
// Replaces the owner key by the value interpolated in the owner tetrahedron
// (raster.rs: barycentric, interpolate), or the background.

@group(0) @binding(6) var<storage, read_write> OUT: array<u32>;
@group(0) @binding(8) var<storage, read> VALUES: array<f32>;

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
    let owner = OUT[o];
    if owner == NO_OWNER {
        OUT[o] = bitcast<u32>(P.misc.x);
        return;
    }
    let id = owner & 0x7fffffffu;  // the owner key without WEAK_OWNER
    let cell = id / 5u;
    let t = id % 5u;
    let ci = cell % P.cdim.x;
    let cj = (cell / P.cdim.x) % P.cdim.y;
    let ck = cell / (P.cdim.x * P.cdim.y);
    let parity = (ci + cj + ck) & 1u;
    var p: array<vec3<f32>, 4>;
    var v: vec4<f32>;
    for (var a = 0u; a < 4u; a++) {
        let c = TETS[parity * 20u + t * 4u + a];
        let i = ci + (c & 1u);
        let j = cj + ((c >> 1u) & 1u);
        let k = ck + (c >> 2u);
        p[a] = vertex_position(i, j, k);
        v[a] = VALUES[i + P.vdim.x * (j + P.vdim.y * k)];
    }
    let q = vec3<f32>(f32(x), f32(y), f32(z));
    var w: vec4<f32>;
    for (var a = 0u; a < 4u; a++) {
        let f = make_plane(p[OTHERS[a * 3u]], p[OTHERS[a * 3u + 1u]], p[OTHERS[a * 3u + 2u]]);
        let dd = plane_eval(f, p[a]);
        w[a] = select(0.0, plane_eval(f, q) / dd, dd != 0.0);
    }
    var val = ((w.x * v.x + w.y * v.y) + w.z * v.z) + w.w * v.w;
    if w.w == 1.0 { val = v.w; }
    if w.z == 1.0 { val = v.z; }
    if w.y == 1.0 { val = v.y; }
    if w.x == 1.0 { val = v.x; }
    OUT[o] = bitcast<u32>(val);
}
