// voxflex resampler: deformed bounds of listed cell blocks (blocks.rs).
// One workgroup per listed block; min/max reduced with workgroup atomics on
// order-preserving u32 encodings of the f32 coordinates (NaN propagates to
// the result, which the CPU rejects). Output: 6 encoded words per slot
// (min xyz, max xyz).

@group(0) @binding(4) var<storage, read> BLOCKS: array<u32>;
@group(0) @binding(5) var<storage, read_write> BOUNDS: array<u32>;

var<workgroup> WMIN: array<atomic<u32>, 3>;
var<workgroup> WMAX: array<atomic<u32>, 3>;

fn encode_ordered(v: f32) -> u32 {
    let b = bitcast<u32>(v);
    if (b & 0x80000000u) != 0u {
        return ~b;
    }
    return b | 0x80000000u;
}

@compute @workgroup_size(64)
fn block_bounds(
    @builtin(local_invocation_index) li: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let slot = wid.x + wid.y * nwg.x + wid.z * nwg.x * nwg.y;
    if li < 3u {
        atomicStore(&WMIN[li], 0xffffffffu);
        atomicStore(&WMAX[li], 0u);
    }
    workgroupBarrier();
    if slot < P.bdim.w {
        let b = BLOCKS[slot];
        let bx = b % P.bdim.x;
        let by = (b / P.bdim.x) % P.bdim.y;
        let bz = b / (P.bdim.x * P.bdim.y);
        let lo = vec3<u32>(bx, by, bz) * BLOCK_EDGE;
        let hi = min(lo + vec3<u32>(BLOCK_EDGE), P.cdim.xyz);
        let e = hi - lo + vec3<u32>(1u);
        let count = e.x * e.y * e.z;
        var mn = vec3<u32>(0xffffffffu);
        var mx = vec3<u32>(0u);
        for (var v = li; v < count; v += 64u) {
            let i = lo.x + v % e.x;
            let j = lo.y + (v / e.x) % e.y;
            let k = lo.z + v / (e.x * e.y);
            let p = vertex_position(i, j, k);
            let q = vec3<u32>(encode_ordered(p.x), encode_ordered(p.y), encode_ordered(p.z));
            mn = min(mn, q);
            mx = max(mx, q);
        }
        for (var a = 0u; a < 3u; a++) {
            atomicMin(&WMIN[a], mn[a]);
            atomicMax(&WMAX[a], mx[a]);
        }
    }
    workgroupBarrier();
    if slot < P.bdim.w && li < 3u {
        BOUNDS[slot * 6u + li] = atomicLoad(&WMIN[li]);
        BOUNDS[slot * 6u + 3u + li] = atomicLoad(&WMAX[li]);
    }
}
