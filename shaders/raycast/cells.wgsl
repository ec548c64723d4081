// Min/max macro-cells of the `raycast` plugin over a box of cells: the WGSL
// twin of MacroCells::rebuild (plugins/raycast/src/macrocell.rs).
//
// Cell c (per axis) covers voxels [c·s − 1, (c+1)·s + 1]: the shared border
// voxel and a one-voxel halo (tricubic samples read 4³ voxels), clamped to
// the volume. One invocation per cell of the box, 64 per
// workgroup, folded into 3-D (flat index as in voxflex_core::gpu::workgroups_1d).
// Writes f32 bits into `accel`: minima from `counts.w`, maxima `total` later.

struct C {
    dims: vec4<u32>,    // nx, ny, nz, cell edge s
    counts: vec4<u32>,  // cells per axis, accel offset of the minima
    lo: vec4<u32>,      // first cell of the box, w = total cells
    size: vec4<u32>,    // cells of the box per axis, w = cells in the box
    base: vec4<u32>,    // x = first element of the bound volume window (a z-slab, raycast.wgsl)
}

@group(0) @binding(0) var<storage, read> c: C;
@group(0) @binding(1) var<storage, read> vol: array<f32>;
@group(0) @binding(2) var<storage, read_write> accel: array<u32>;

const WG: u32 = 64u;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
    if (idx >= c.size.w) {
        return;
    }
    let b = vec3<u32>(idx % c.size.x, (idx / c.size.x) % c.size.y, idx / (c.size.x * c.size.y));
    let cell = c.lo.xyz + b;
    let last = c.dims.xyz - vec3<u32>(1u);
    let v0 = min(max(cell * c.dims.w, vec3<u32>(1u)) - vec3<u32>(1u), last);
    let v1 = min((cell + vec3<u32>(1u)) * c.dims.w + vec3<u32>(1u), last);
    var lo = 3.40282347e38;
    var hi = -3.40282347e38;
    for (var k = v0.z; k <= v1.z; k++) {
        for (var j = v0.y; j <= v1.y; j++) {
            let row = (k * c.dims.y + j) * c.dims.x;
            for (var i = v0.x; i <= v1.x; i++) {
                let v = vol[row + i - c.base.x];
                lo = min(lo, v);
                hi = max(hi, v);
            }
        }
    }
    let l = cell.x + c.counts.x * (cell.y + c.counts.y * cell.z);
    accel[c.counts.w + l] = bitcast<u32>(lo);
    accel[c.counts.w + c.lo.w + l] = bitcast<u32>(hi);
}
