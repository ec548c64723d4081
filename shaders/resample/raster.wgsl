// voxflex resampler, pass 1: one invocation per cell of the listed blocks.
// Each non-removed tetrahedron atomic-mins its id into every output voxel
// centre (inside the clip box) that passes the inclusion test of raster.rs.

@group(0) @binding(4) var<storage, read> BLOCKS: array<u32>;
@group(0) @binding(6) var<storage, read_write> OUT: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read> MASK: array<u32>;

var<private> PX: array<f32, 8>;
var<private> PY: array<f32, 8>;
var<private> PZ: array<f32, 8>;

fn corner(c: u32) -> vec3<f32> {
    return vec3<f32>(PX[c], PY[c], PZ[c]);
}

@compute @workgroup_size(64)
fn raster(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let flat = flat_index(gid, nwg);
    let slot = flat / CELLS_PER_BLOCK;
    if slot >= P.bdim.w {
        return;
    }
    let b = BLOCKS[slot];
    let l = flat % CELLS_PER_BLOCK;
    let ci = (b % P.bdim.x) * BLOCK_EDGE + l % BLOCK_EDGE;
    let cj = ((b / P.bdim.x) % P.bdim.y) * BLOCK_EDGE + (l / BLOCK_EDGE) % BLOCK_EDGE;
    let ck = (b / (P.bdim.x * P.bdim.y)) * BLOCK_EDGE + l / (BLOCK_EDGE * BLOCK_EDGE);
    if ci >= P.cdim.x || cj >= P.cdim.y || ck >= P.cdim.z {
        return;
    }
    var cmin = vec3<f32>(3.0e38);
    var cmax = vec3<f32>(-3.0e38);
    for (var c = 0u; c < 8u; c++) {
        let p = vertex_position(ci + (c & 1u), cj + ((c >> 1u) & 1u), ck + (c >> 2u));
        PX[c] = p.x;
        PY[c] = p.y;
        PZ[c] = p.z;
        cmin = min(cmin, p);
        cmax = max(cmax, p);
    }
    let clo = max(vec3<i32>(ceil(cmin)), P.clo.xyz);
    let chi = min(vec3<i32>(floor(cmax)), P.chi.xyz);
    if any(clo > chi) {
        return;
    }
    let cell = ci + P.cdim.x * (cj + P.cdim.y * ck);
    var removed = 0u;
    if P.oorg.w != 0 {
        removed = (MASK[cell / 4u] >> ((cell % 4u) * 8u)) & 0xffu;
    }
    let parity = (ci + cj + ck) & 1u;
    let eps = P.inv.w;
    for (var t = 0u; t < 5u; t++) {
        if (removed & (1u << t)) != 0u {
            continue;
        }
        var cs: array<u32, 4>;
        for (var a = 0u; a < 4u; a++) {
            cs[a] = TETS[parity * 20u + t * 4u + a];
        }
        let p0 = corner(cs[0]);
        let p1 = corner(cs[1]);
        let p2 = corner(cs[2]);
        let p3 = corner(cs[3]);
        let tmin = min(min(p0, p1), min(p2, p3));
        let tmax = max(max(p0, p1), max(p2, p3));
        let lo = max(vec3<i32>(ceil(tmin)), P.clo.xyz);
        let hi = min(vec3<i32>(floor(tmax)), P.chi.xyz);
        if any(lo > hi) {
            continue;
        }
        // Faces as lanes: plane normals n, base points b, sign and threshold.
        var nx: vec4<f32>;
        var ny: vec4<f32>;
        var nz: vec4<f32>;
        var bx: vec4<f32>;
        var by: vec4<f32>;
        var bz: vec4<f32>;
        var sg: vec4<f32>;
        var th: vec4<f32>;
        var ok = true;
        for (var a = 0u; a < 4u; a++) {
            let f = make_plane(corner(cs[OTHERS[a * 3u]]), corner(cs[OTHERS[a * 3u + 1u]]), corner(cs[OTHERS[a * 3u + 2u]]));
            let d = plane_eval(f, corner(cs[a]));
            if d == 0.0 {
                ok = false;
            }
            nx[a] = f.n.x;
            ny[a] = f.n.y;
            nz[a] = f.n.z;
            bx[a] = f.b.x;
            by[a] = f.b.y;
            bz[a] = f.b.z;
            sg[a] = select(-1.0, 1.0, d > 0.0);
            th[a] = -eps * abs(d);
        }
        if !ok {
            continue;
        }
        let id = cell * 5u + t;
        for (var z = lo.z; z <= hi.z; z++) {
            for (var y = lo.y; y <= hi.y; y++) {
                let row = ny * (vec4<f32>(f32(y)) - by) + nz * (vec4<f32>(f32(z)) - bz);
                for (var x = lo.x; x <= hi.x; x++) {
                    let tv = nx * (vec4<f32>(f32(x)) - bx) + row;
                    if all(sg * tv >= th) {
                        let o = out_index(x, y, z);
                        if atomicLoad(&OUT[o]) > id {
                            atomicMin(&OUT[o], id);
                        }
                    }
                }
            }
        }
    }
}
