// Analytic deformation fields of the `affine` plugin: the WGSL twin of
// plugins/affine/src/field.rs. Same uniforms, same f32 formulas.
//
// Writes one displacement (mm, world axes) per point into three
// structure-of-arrays buffers. Points are either every voxel centre of a
// lattice (mode 0) or an explicit list (mode 1). A dispatch covers the
// slab of points `slab.x .. slab.x + slab.y`; the point and displacement
// arrays are bound from point `slab.x` on (windows, so that a volume's
// arrays larger than one storage binding are written slab by slab).

struct Uniforms {
    header: vec4<u32>,      // kind (0 affine, 1 twist, 2 bend), axis, towards, mode
    centre_rate: vec4<f32>, // centre (mm), rate (rad/mm or 1/mm)
    row0: vec4<f32>,
    row1: vec4<f32>,
    row2: vec4<f32>,
    region: vec4<f32>,      // centre (mm), radius (mm; 0 = unconfined)
    origin: vec4<f32>,      // lattice origin (mm)
    spacing: vec4<f32>,     // lattice spacing (mm)
    counts: vec4<u32>,      // nx, ny, nz (lattice); w unused
    slab: vec4<u32>,        // first point, points of this dispatch
}

@group(0) @binding(0) var<storage, read> u: Uniforms;
@group(0) @binding(1) var<storage, read> px: array<f32>;
@group(0) @binding(2) var<storage, read> py: array<f32>;
@group(0) @binding(3) var<storage, read> pz: array<f32>;
@group(0) @binding(4) var<storage, read_write> ux: array<f32>;
@group(0) @binding(5) var<storage, read_write> uy: array<f32>;
@group(0) @binding(6) var<storage, read_write> uz: array<f32>;

const WG: u32 = 64u;

fn twist(q: vec3<f32>, a: u32, rate: f32) -> vec3<f32> {
    let ua = (a + 1u) % 3u;
    let va = (a + 2u) % 3u;
    let theta = rate * q[a];
    let s = sin(theta);
    let c = cos(theta);
    var o = q;
    o[ua] = c * q[ua] - s * q[va];
    o[va] = s * q[ua] + c * q[va];
    return o;
}

fn bend(q: vec3<f32>, a: u32, b: u32, k: f32) -> vec3<f32> {
    let theta = k * q[a];
    let s = sin(theta);
    let c = cos(theta);
    var sinc = 1.0;
    var versc = 0.0;
    if (theta != 0.0) {
        let h = sin(0.5 * theta);
        sinc = s / theta;
        versc = 2.0 * h * h / theta;
    }
    var o = q;
    o[a] = q[a] * sinc - q[b] * s;
    o[b] = q[b] * c + q[a] * versc;
    return o;
}

fn displacement(p: vec3<f32>) -> vec3<f32> {
    var w = 1.0;
    let radius = u.region.w;
    if (radius > 0.0) {
        let d = p - u.region.xyz;
        let r2 = dot(d, d) / (radius * radius);
        if (r2 >= 1.0) {
            return vec3<f32>(0.0);
        }
        let t = 1.0 - r2;
        w = t * t * t;
    }
    let q = p - u.centre_rate.xyz;
    var moved: vec3<f32>;
    switch u.header.x {
        case 0u: {
            moved = vec3<f32>(
                u.row0.x * q.x + u.row0.y * q.y + u.row0.z * q.z + u.row0.w,
                u.row1.x * q.x + u.row1.y * q.y + u.row1.z * q.z + u.row1.w,
                u.row2.x * q.x + u.row2.y * q.y + u.row2.z * q.z + u.row2.w);
        }
        case 1u: { moved = twist(q, u.header.y, u.centre_rate.w); }
        default: { moved = bend(q, u.header.y, u.header.z, u.centre_rate.w); }
    }
    return (moved - q) * w;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    // n: the point within the slab (and the bound windows); g: in all.
    let n = gid.x + gid.y * (nwg.x * WG) + gid.z * (nwg.x * WG * nwg.y);
    if (n >= u.slab.y) {
        return;
    }
    let g = u.slab.x + n;
    var p: vec3<f32>;
    if (u.header.w == 0u) {
        let nx = u.counts.x;
        let ny = u.counts.y;
        let i = g % nx;
        let j = (g / nx) % ny;
        let k = g / (nx * ny);
        p = u.origin.xyz + vec3<f32>(f32(i), f32(j), f32(k)) * u.spacing.xyz;
    } else {
        p = vec3<f32>(px[n], py[n], pz[n]);
    }
    let d = displacement(p);
    ux[n] = d.x;
    uy[n] = d.y;
    uz[n] = d.z;
}
