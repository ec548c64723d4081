// Leap distances of the `raycast` plugin's empty-space skipping: the WGSL
// twin of MacroCells::leap_distances (plugins/raycast/src/macrocell.rs).
//
// One separable pass of the Chebyshev distance (in cells, capped at CAP)
// from every cell to the nearest cell that is not empty under the transfer
// function. Pass 0 (axis x) reads emptiness from the cell min/max and the
// TF's non-zero prefix counts; passes 1 (y) and 2 (z) read the previous
// pass: d(c) = min over o of max(|o|, src(c + o·e_axis)). One invocation
// per cell, 64 per workgroup, folded into 3-D.
//
// `accel` layout: [0, LUT_SIZE] prefix counts; from `offs.x` the cell
// minima, then maxima (f32 bits); `offs.y` source, `offs.z` destination.

struct P {
    counts: vec4<u32>,  // cells per axis, total
    offs: vec4<u32>,    // minima offset, source offset, destination offset, axis
    lut: vec4<f32>,     // value of entry 0, entries per value unit, entries
}

@group(0) @binding(0) var<storage, read> p: P;
@group(0) @binding(1) var<storage, read_write> accel: array<u32>;

const WG: u32 = 64u;
const CAP: u32 = 16u;

// Same as Lut::range_is_empty.
fn is_empty(l: u32) -> bool {
    let top = p.lut.z - 1.0;
    let mn = bitcast<f32>(accel[p.offs.x + l]);
    let mx = bitcast<f32>(accel[p.offs.x + p.counts.w + l]);
    let a = u32(clamp(floor((mn - p.lut.x) * p.lut.y), 0.0, top));
    let b = u32(clamp(floor((mx - p.lut.x) * p.lut.y), 0.0, top));
    let lo = select(0u, a - 1u, a > 0u);
    let hi = min(b + 2u, u32(top));
    return accel[hi + 1u] == accel[lo];
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let l = gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
    if (l >= p.counts.w) {
        return;
    }
    let cx = p.counts.x;
    let cy = p.counts.y;
    let c = vec3<u32>(l % cx, (l / cx) % cy, l / (cx * cy));
    let axis = p.offs.w;
    let strides = vec3<u32>(1u, cx, cx * cy);
    let n = p.counts[axis];
    let st = strides[axis];
    let pos = c[axis];
    let line = l - pos * st;
    var best = CAP;
    for (var o = 0u; o < min(CAP, n); o++) {
        if (o >= best) {
            break;
        }
        for (var side = 0u; side < 2u; side++) {
            var q = pos + o;
            if (side == 0u) {
                q = pos - o; // wraps past 0 to a huge value: skipped below
            }
            if (q < n) {
                var v: u32;
                if (axis == 0u) {
                    v = select(0u, CAP, is_empty(line + q * st));
                } else {
                    v = accel[p.offs.y + line + q * st];
                }
                best = min(best, max(o, v));
            }
        }
    }
    accel[p.offs.z + l] = best;
}
