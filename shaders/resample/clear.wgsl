// voxflex resampler: mark the clip box of the bound output slab "no owner"
// (and, when the source is split, not filled: fill.wgsl).

@group(0) @binding(6) var<storage, read_write> OUT: array<u32>;
@group(0) @binding(9) var<storage, read_write> FILLED: array<atomic<u32>>;

@compute @workgroup_size(64)
fn clear(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = flat_index(gid, nwg);
    let d = vec3<u32>(P.chi.xyz - P.clo.xyz + vec3<i32>(1));
    if n >= d.x * d.y * d.z {
        return;
    }
    let x = P.clo.x + i32(n % d.x);
    let y = P.clo.y + i32((n / d.x) % d.y);
    let z = P.clo.z + i32(n / (d.x * d.y));
    let o = out_index(x, y, z);
    OUT[o] = NO_OWNER;
    if P.cells.w == 1u {
        let e = o + P.odim.w;
        atomicAnd(&FILLED[e / 32u - P.cells.z], ~(1u << (e % 32u)));
    }
}
