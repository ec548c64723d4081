// voxflex resampler, pass 1: one invocation per cell of the listed blocks.
// Every output voxel centre in the cell's clipped bounding box goes to the
// tetrahedron of the cell that passes the inclusion test of raster.rs
// (CellRaster) with the smallest owner key — its id, with WEAK_OWNER set
// when none of its corners moved, it is inverted, or the voxel centre is
// the rest position of one of its still corners (sampling_mesh.rs) —
// atomicMin(key) into the output slab. The listed blocks lie in the bound
// source slab (gpu_slabs.rs), so every vertex read is inside its window.

@group(0) @binding(4) var<storage, read> BLOCKS: array<u32>;
@group(0) @binding(6) var<storage, read_write> OUT: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read> MASK: array<u32>;

// FACE_TABLES.faces (sampling_mesh.rs): [parity][face][3 ascending corners].
var<private> FACES: array<u32, 96> = array<u32, 96>(
    1u, 2u, 4u, 0u, 2u, 4u, 0u, 1u, 4u, 0u, 1u, 2u, 2u, 3u, 7u, 1u, 3u, 7u, 1u, 2u, 7u, 1u, 2u, 3u,
    4u, 5u, 7u, 1u, 5u, 7u, 1u, 4u, 7u, 1u, 4u, 5u, 4u, 6u, 7u, 2u, 6u, 7u, 2u, 4u, 7u, 2u, 4u, 6u,
    1u, 3u, 5u, 0u, 3u, 5u, 0u, 1u, 5u, 0u, 1u, 3u, 2u, 3u, 6u, 0u, 3u, 6u, 0u, 2u, 6u, 0u, 2u, 3u,
    4u, 5u, 6u, 0u, 5u, 6u, 0u, 4u, 6u, 0u, 4u, 5u, 5u, 6u, 7u, 3u, 6u, 7u, 3u, 5u, 7u, 3u, 5u, 6u,
);

// FACE_TABLES.tet_faces: [parity][tet][a] = face opposite corner slot a.
var<private> TET_FACES: array<u32, 40> = array<u32, 40>(
    0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 10u, 11u, 12u, 13u, 14u, 15u, 14u, 10u, 6u, 0u,
    0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 10u, 11u, 12u, 13u, 14u, 15u, 15u, 9u, 5u, 1u,
);

const WEAK_OWNER: u32 = 0x80000000u;

var<private> PX: array<f32, 8>;
var<private> PY: array<f32, 8>;
var<private> PZ: array<f32, 8>;
var<private> PN: array<vec3<f32>, 16>;
var<private> PB: array<vec3<f32>, 16>;
var<private> SG: array<f32, 20>;
var<private> TH: array<f32, 20>;

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
    var moved = 0u;
    for (var c = 0u; c < 8u; c++) {
        let v = vec3<u32>(ci + (c & 1u), cj + ((c >> 1u) & 1u), ck + (c >> 2u));
        let p = vertex_position(v.x, v.y, v.z);
        if any(p != vec3<f32>(v)) {
            moved |= 1u << c;
        }
        PX[c] = p.x;
        PY[c] = p.y;
        PZ[c] = p.z;
        cmin = min(cmin, p);
        cmax = max(cmax, p);
    }
    let lo = max(vec3<i32>(ceil(cmin)), P.clo.xyz);
    let hi = min(vec3<i32>(floor(cmax)), P.chi.xyz);
    if any(lo > hi) {
        return;
    }
    let cell = ci + P.cdim.x * (cj + P.cdim.y * ck);
    var live = 31u;
    if P.oorg.w != 0 {
        live &= ~((MASK[cell / 4u - P.cdim.w] >> ((cell % 4u) * 8u)) & 0xffu);
    }
    let parity = (ci + cj + ck) & 1u;
    for (var f = 0u; f < 16u; f++) {
        let k = parity * 48u + f * 3u;
        let pl = make_plane(corner(FACES[k]), corner(FACES[k + 1u]), corner(FACES[k + 2u]));
        PN[f] = pl.n;
        PB[f] = pl.b;
    }
    // One D per tetrahedron, at its ORIENT slot o; face a's is ±D
    // (sampling_mesh.rs: D_SIGN, (−1)^(a−o)).
    let eps = P.inv.w;
    for (var t = 0u; t < 5u; t++) {
        let o = ORIENT[parity * 5u + t] & 3u;
        let so = t * 4u + o;
        let f = TET_FACES[parity * 20u + so];
        let d = plane_eval(Plane(PN[f], PB[f]), corner(TETS[parity * 20u + so]));
        if d == 0.0 || !(abs(d) <= 3.4028235e38) {
            live &= ~(1u << t);
        }
        for (var a = 0u; a < 4u; a++) {
            let da = d_of_slot(d, a, o);
            SG[t * 4u + a] = select(-1.0, 1.0, da > 0.0);
            TH[t * 4u + a] = -eps * abs(da);
        }
    }
    if live == 0u {
        return;
    }
    // Weak owners (bit t): no corner moved, or inverted.
    var weak = 0u;
    for (var t = 0u; t < 5u; t++) {
        var any_moved = 0u;
        for (var a = 0u; a < 4u; a++) {
            any_moved |= moved & (1u << TETS[parity * 20u + t * 4u + a]);
        }
        let o = ORIENT[parity * 5u + t];
        let positive = SG[t * 4u + (o & 3u)] > 0.0;
        if any_moved == 0u || positive != ((o >> 2u) == 1u) {
            weak |= 1u << t;
        }
    }
    let base = cell * 5u;
    for (var z = lo.z; z <= hi.z; z++) {
        for (var y = lo.y; y <= hi.y; y++) {
            for (var x = lo.x; x <= hi.x; x++) {
                let q = vec3<f32>(f32(x), f32(y), f32(z));
                var tv: array<f32, 16>;
                for (var f = 0u; f < 16u; f++) {
                    tv[f] = plane_eval(Plane(PN[f], PB[f]), q);
                }
                // Still corners whose rest position is this voxel centre: a
                // tetrahedron touching it only there claims it weakly.
                var still_here = 0u;
                let r = vec3<i32>(x, y, z) - vec3<i32>(vec3<u32>(ci, cj, ck));
                if all(r >= vec3<i32>(0)) && all(r <= vec3<i32>(1)) {
                    still_here = (1u << u32(r.x + 2 * r.y + 4 * r.z)) & ~moved;
                }
                var key = NO_OWNER;
                for (var t = 0u; t < 5u; t++) {
                    if (live & (1u << t)) == 0u {
                        continue;
                    }
                    var ok = true;
                    var touch = false;
                    for (var a = 0u; a < 4u; a++) {
                        let s = t * 4u + a;
                        ok = ok && SG[s] * tv[TET_FACES[parity * 20u + s]] >= TH[s];
                        let c = TETS[parity * 20u + s];
                        touch = touch || ((still_here & (1u << c)) != 0u);
                    }
                    if ok {
                        let w = (weak & (1u << t)) != 0u || touch;
                        key = min(key, (base + t) | select(0u, WEAK_OWNER, w));
                    }
                }
                if key != NO_OWNER {
                    let o = out_index(x, y, z);
                    if atomicLoad(&OUT[o]) > key {
                        atomicMin(&OUT[o], key);
                    }
                }
            }
        }
    }
}
