// voxflex resampler: definitions shared by every kernel.
// Mirrors runtime/core/src/resample/{sampling_mesh,raster,gpu}.rs; keep the
// arithmetic identical (same expressions, same order) or CPU/GPU parity and
// the identity bit-exactness break.
//
// Units: positions and voxel centres are source voxel index units.

struct Params {
    vdim: vec4<u32>,  // source vertices (= voxels) x, y, z
    cdim: vec4<u32>,  // cells x, y, z; w = word index of the bound mask range's start
    bdim: vec4<u32>,  // cell blocks x, y, z; w = listed blocks
    inv: vec4<f32>,   // 1 / spacing x, y, z (voxels per mm); w = inclusion epsilon
    oorg: vec4<i32>,  // source index of output voxel (0,0,0); w = 1 when a mask is bound
    odim: vec4<u32>,  // output dims x, y, z; w = output element index of the bound slab's start
    clo: vec4<i32>,   // clip box (voxels that may be written), lower corner, source index units
    chi: vec4<i32>,   // clip box upper corner (inclusive); w = interpolation (0 tetrahedral, 1 trilinear)
    misc: vec4<f32>,  // x = background value
    slab: vec4<u32>,  // source slab: x = source element index of the bound source/displacement
                      // window's start; y, z = its first and last vertex z-planes (inclusive)
    cells: vec4<u32>, // x, y = cell z-planes [x, y) this pass rasterises and fills; z = word index
                      // of the bound filled-bit range's start; w = 1 when the source is split
}

@group(0) @binding(0) var<storage, read> P: Params;

const NO_OWNER: u32 = 0xffffffffu;
const BLOCK_EDGE: u32 = 4u;       // blocks.rs: BLOCK_EDGE
const CELLS_PER_BLOCK: u32 = 64u;  // BLOCK_EDGE³
const WG: u32 = 64u;

// CELL_TETS (sampling_mesh.rs): [parity][tet][corner], corners ascending,
// corner c = cx + 2 cy + 4 cz.
var<private> TETS: array<u32, 40> = array<u32, 40>(
    0u, 1u, 2u, 4u,  1u, 2u, 3u, 7u,  1u, 4u, 5u, 7u,  2u, 4u, 6u, 7u,  1u, 2u, 4u, 7u,
    0u, 1u, 3u, 5u,  0u, 2u, 3u, 6u,  0u, 4u, 5u, 6u,  3u, 5u, 6u, 7u,  0u, 3u, 5u, 6u,
);

// The corners of the face opposite corner slot a: the other three slots, ascending.
var<private> OTHERS: array<u32, 12> = array<u32, 12>(1u, 2u, 3u, 0u, 2u, 3u, 0u, 1u, 3u, 0u, 1u, 2u);

// ORIENTATION (sampling_mesh.rs): [parity][tet] = slot | (rest D > 0) << 2:
// the face whose D (at that slot's corner) is the tetrahedron's one D.
var<private> ORIENT: array<u32, 10> = array<u32, 10>(
    0u, 6u, 2u, 6u, 7u, 5u, 1u, 5u, 3u, 3u,
);

// D_SIGN (sampling_mesh.rs): the D of the face opposite slot a from the
// tetrahedron's one D at slot o, (−1)^(a−o) D.
fn d_of_slot(d: f32, a: u32, o: u32) -> f32 {
    return select(-d, d, ((a + o) & 1u) == 0u);
}

// Flat invocation index of a folded 3-D dispatch (gpu.rs: workgroups_1d).
fn flat_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
}

// Face plane t(q) = n . (q - b) through pu, pv, pw (ascending vertex order).
struct Plane {
    n: vec3<f32>,
    b: vec3<f32>,
}

fn make_plane(pu: vec3<f32>, pv: vec3<f32>, pw: vec3<f32>) -> Plane {
    let a = pv - pu;
    let c = pw - pu;
    return Plane(vec3<f32>(a.y * c.z - a.z * c.y, a.z * c.x - a.x * c.z, a.x * c.y - a.y * c.x), pu);
}

fn plane_row(p: Plane, y: f32, z: f32) -> f32 {
    return p.n.y * (y - p.b.y) + p.n.z * (z - p.b.z);
}

fn plane_at(p: Plane, x: f32, row: f32) -> f32 {
    return p.n.x * (x - p.b.x) + row;
}

fn plane_eval(p: Plane, q: vec3<f32>) -> f32 {
    return plane_at(p, q.x, plane_row(p, q.y, q.z));
}

// Index of source vertex (i, j, k) in the bound source/displacement window.
fn source_index(i: u32, j: u32, k: u32) -> u32 {
    return i + P.vdim.x * (j + P.vdim.y * k) - P.slab.x;
}

// Linear output index of a voxel (source index units), relative to the bound slab.
fn out_index(x: i32, y: i32, z: i32) -> u32 {
    let ox = u32(x - P.oorg.x);
    let oy = u32(y - P.oorg.y);
    let oz = u32(z - P.oorg.z);
    return ox + P.odim.x * (oy + P.odim.y * oz) - P.odim.w;
}
