// Emission–absorption ray casting and MIP of the `raycast` plugin: the WGSL
// twin of plugins/raycast/src/cpu.rs. Same uniforms (`RayUniforms`), same
// f32 formulas in the same order, so both paths agree to rounding.
//
// One invocation per pixel, workgroups of 8 × 8 over the image.
// Buffers (all 32-bit):
//   vol    f32 per voxel, x fastest (voxel indices; centres at integers)
//   lut    LUT_SIZE × vec4: linear r, g, b and extinction κ (per mm)
//   accel  [0, LUT_SIZE]: count of entries with κ > 0 before each entry;
//          from counts.z: cell minima (f32 bits), cell maxima, leap
//          distances (u32, see leap.wgsl), scratch
//   maps   combined opacity map, u16 fixed point packed two per word
//          (even voxel in the low half)
//   out_px RGBA8 per pixel, R in the low byte (sRGB, straight alpha)
//   stats  [samples lo, samples hi, rays terminated early]
//   state  8 words per pixel: a ray's loop state between the passes of a
//          volume split into z-slabs (plugins/raycast/src/slabs.rs)
//
// A volume above one storage binding is bound as z-slabs: each pass binds
// the voxel planes slab.x − 1 … slab.y + 1 (every tap of a sample whose
// footprint plane lies in [slab.x, slab.y)) and handles the rays going up
// in z (PASS_UP, slabs ascending) or down (PASS_DOWN, descending). A ray
// runs its own loop until a sample's footprint leaves the slab, saves the
// loop state and resumes in its next slab's pass: the same samples in the
// same order, so the image of the unsplit volume bit for bit. One pass
// with every PASS_* flag but PASS_SPLIT renders an unsplit volume.

struct U {
    eye: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    forward: vec4<f32>,
    image: vec4<u32>,       // width, height, projection (0 ortho, 1 persp), mode (0 composite, 1 mip)
    dims: vec4<u32>,        // nx, ny, nz, macro-cell edge
    cells: vec4<u32>,       // cells per axis, flags
    origin: vec4<f32>,
    inv_spacing: vec4<f32>,
    grad_scale: vec4<f32>,
    step: vec4<f32>,        // dt (mm), termination threshold, opacity unit distance (mm), cell edge
    lut: vec4<f32>,         // value of entry 0, entries per value unit, entries
    shading: vec4<f32>,     // ambient, diffuse, specular, shininess
    background: vec4<f32>,  // linear premultiplied
    box_min: vec4<f32>,
    box_max: vec4<f32>,
    planes: array<vec4<f32>, 6>,
    counts: vec4<u32>,      // planes, has map, accel offset of cell minima, total cells
    map_origin: vec4<u32>,  // voxels; w = outside (u16 fixed point)
    map_dims: vec4<u32>,
    slab: vec4<u32>,        // footprint planes [x, y) of this pass; z = first element of the bound
                            // volume window; w = first word of the bound map window
    pass_flags: vec4<u32>,  // x = PASS_* flags
}

@group(0) @binding(0) var<storage, read> u: U;
@group(0) @binding(1) var<storage, read> vol: array<f32>;
@group(0) @binding(2) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> accel: array<u32>;
@group(0) @binding(4) var<storage, read> maps: array<u32>;
@group(0) @binding(5) var<storage, read_write> out_px: array<u32>;
@group(0) @binding(6) var<storage, read_write> stats: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> state: array<u32>;

const FLAG_ESS: u32 = 1u;
const FLAG_EARLY_TERMINATION: u32 = 2u;
const FLAG_SHADING: u32 = 4u;
const FLAG_MAP_NEAREST: u32 = 8u;
const FLAG_BACKGROUND: u32 = 16u;
const FLAG_SOBEL: u32 = 32u;
const FLAG_TRICUBIC: u32 = 64u;
const FLAG_JITTER: u32 = 128u;
const PASS_UP: u32 = 1u;
const PASS_DOWN: u32 = 2u;
const PASS_FIRST: u32 = 4u;
const PASS_LAST: u32 = 8u;
const PASS_SPLIT: u32 = 16u;
const T_FAR: f32 = 3.0e38;
const F32_MIN: f32 = -3.40282347e38;

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    return a + t * (b - a);
}

// Voxel `i` (linear index in the whole volume) from the bound window.
fn vx(i: u32) -> f32 {
    return vol[i - u.slab.z];
}

struct Fp {
    i: vec3<u32>,
    f: vec3<f32>,
    base: u32,
}

fn upper() -> vec3<f32> {
    return vec3<f32>(max(u.dims.xyz, vec3<u32>(1u))) - vec3<f32>(1.0);
}

fn offsets() -> vec3<u32> {
    let strides = vec3<u32>(1u, u.dims.x, u.dims.x * u.dims.y);
    return select(vec3<u32>(0u), strides, u.dims.xyz > vec3<u32>(1u));
}

fn footprint(p_in: vec3<f32>) -> Fp {
    let p = clamp(p_in, vec3<f32>(0.0), upper());
    let max0 = max(u.dims.xyz, vec3<u32>(2u)) - vec3<u32>(2u);
    let i = min(vec3<u32>(p), max0);
    var fp: Fp;
    fp.i = i;
    fp.f = p - vec3<f32>(i);
    fp.base = i.x + u.dims.x * (i.y + u.dims.y * i.z);
    return fp;
}

fn value(fp: Fp) -> f32 {
    let o = offsets();
    let b = fp.base;
    let x00 = lerp(vx(b), vx(b + o.x), fp.f.x);
    let x10 = lerp(vx(b + o.y), vx(b + o.x + o.y), fp.f.x);
    let x01 = lerp(vx(b + o.z), vx(b + o.x + o.z), fp.f.x);
    let x11 = lerp(vx(b + o.y + o.z), vx(b + o.x + o.y + o.z), fp.f.x);
    return lerp(lerp(x00, x10, fp.f.y), lerp(x01, x11, fp.f.y), fp.f.z);
}

// Central difference f(p + e) − f(p − e) along `axis` (voxel units).
fn diff(fp: Fp, axis: u32) -> f32 {
    let ab = (axis + 1u) % 3u;
    let ac = (axis + 2u) % 3u;
    let strides = vec3<u32>(1u, u.dims.x, u.dims.x * u.dims.y);
    let o = offsets();
    let n = u.dims[axis];
    let i0 = fp.i[axis];
    let sa = strides[axis];
    let im = select(0u, i0 - 1u, i0 > 0u);
    let i1 = min(i0 + 1u, n - 1u);
    let i2 = min(i0 + 2u, n - 1u);
    let fa = fp.f[axis];
    let fb = fp.f[ab];
    let fc = fp.f[ac];
    let row0 = fp.base - i0 * sa;
    var acc: array<f32, 4>;
    for (var q = 0u; q < 4u; q++) {
        let r = row0 + select(0u, o[ab], (q & 1u) != 0u) + select(0u, o[ac], (q & 2u) != 0u);
        acc[q] = (1.0 - fa) * (vx(r + i1 * sa) - vx(r + im * sa)) + fa * (vx(r + i2 * sa) - vx(r + i0 * sa));
    }
    return lerp(lerp(acc[0], acc[1], fb), lerp(acc[2], acc[3], fb), fc);
}

// ---- Filters: the twins of plugins/raycast/src/filters.rs. ----

// lowbias32 integer hash.
fn hash32(x_in: u32) -> u32 {
    var x = x_in;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

// Ray-start offset of a pixel, a fraction of a step in [0, 1).
fn jitter(px: u32, py: u32) -> f32 {
    return f32(hash32(px ^ hash32(py)) >> 8u) * (1.0 / 16777216.0);
}

// Sigg–Hadwiger fetch positions h0, h1 and weight g1 along one axis.
fn bspline_axis(x: f32) -> vec3<f32> {
    let i = f32(u32(x));
    let f = x - i;
    let f2 = f * f;
    let f3 = f2 * f;
    let w0 = (1.0 - 3.0 * f + 3.0 * f2 - f3) * (1.0 / 6.0);
    let w1 = (4.0 - 6.0 * f2 + 3.0 * f3) * (1.0 / 6.0);
    let w2 = (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) * (1.0 / 6.0);
    let w3 = f3 * (1.0 / 6.0);
    let g0 = w0 + w1;
    let g1 = w2 + w3;
    return vec3<f32>(i - 1.0 + w1 / g0, i + 1.0 + w3 / g1, g1);
}

fn trilinear_at(q: vec3<f32>) -> f32 {
    return value(footprint(q));
}

fn tricubic_plane(bx: vec3<f32>, by: vec3<f32>, z: f32) -> f32 {
    let a = lerp(trilinear_at(vec3<f32>(bx.x, by.x, z)), trilinear_at(vec3<f32>(bx.y, by.x, z)), bx.z);
    let b = lerp(trilinear_at(vec3<f32>(bx.x, by.y, z)), trilinear_at(vec3<f32>(bx.y, by.y, z)), bx.z);
    return lerp(a, b, by.z);
}

// Tricubic B-spline sample at voxel position p: 8 trilinear fetches.
fn tricubic(p_in: vec3<f32>) -> f32 {
    let p = clamp(p_in, vec3<f32>(0.0), upper());
    let bx = bspline_axis(p.x);
    let by = bspline_axis(p.y);
    let bz = bspline_axis(p.z);
    let lo = tricubic_plane(bx, by, bz.x);
    let hi = tricubic_plane(bx, by, bz.y);
    return lerp(lo, hi, bz.z);
}

// Value at p: trilinear, or tricubic when FLAG_TRICUBIC.
fn sample_value(p: vec3<f32>, fp: Fp) -> f32 {
    if ((u.cells.w & FLAG_TRICUBIC) != 0u) {
        return tricubic(p);
    }
    return value(fp);
}

// The 4×4×4 voxels around the footprint, indices clamped.
fn gather(fp: Fp) -> array<f32, 64> {
    var b: array<f32, 64>;
    let last = max(u.dims.xyz, vec3<u32>(1u)) - vec3<u32>(1u);
    for (var z = 0u; z < 4u; z++) {
        let iz = min(select(0u, fp.i.z + z - 1u, fp.i.z + z >= 1u), last.z);
        for (var y = 0u; y < 4u; y++) {
            let iy = min(select(0u, fp.i.y + y - 1u, fp.i.y + y >= 1u), last.y);
            let row = u.dims.x * (iy + u.dims.y * iz);
            for (var x = 0u; x < 4u; x++) {
                let ix = min(select(0u, fp.i.x + x - 1u, fp.i.x + x >= 1u), last.x);
                b[x + 4u * (y + 4u * z)] = vx(row + ix);
            }
        }
    }
    return b;
}

// Derivative (d) or [1, 2, 1]/4 smoothing at the inner positions of 4 taps.
fn tap(b0: f32, b1: f32, b2: f32, b3: f32, d: bool) -> vec2<f32> {
    if (d) {
        return vec2<f32>(b2 - b0, b3 - b1);
    }
    return vec2<f32>((b0 + 2.0 * b1 + b2) * 0.25, (b1 + 2.0 * b2 + b3) * 0.25);
}

fn sobel_component(block: array<f32, 64>, axis: u32, f: vec3<f32>) -> f32 {
    var blk = block;
    var sx: array<f32, 32>;
    for (var l = 0u; l < 16u; l++) {
        let r = tap(blk[4u * l], blk[4u * l + 1u], blk[4u * l + 2u], blk[4u * l + 3u], axis == 0u);
        sx[2u * l] = r.x;
        sx[2u * l + 1u] = r.y;
    }
    var sy: array<f32, 16>;
    for (var z = 0u; z < 4u; z++) {
        for (var x = 0u; x < 2u; x++) {
            let r = tap(sx[x + 2u * (4u * z)], sx[x + 2u * (1u + 4u * z)], sx[x + 2u * (2u + 4u * z)], sx[x + 2u * (3u + 4u * z)], axis == 1u);
            sy[x + 2u * (2u * z)] = r.x;
            sy[x + 2u * (1u + 2u * z)] = r.y;
        }
    }
    var c: array<f32, 8>;
    for (var y = 0u; y < 2u; y++) {
        for (var x = 0u; x < 2u; x++) {
            let r = tap(sy[x + 2u * y], sy[x + 2u * (y + 2u)], sy[x + 2u * (y + 4u)], sy[x + 2u * (y + 6u)], axis == 2u);
            c[x + 2u * y] = r.x;
            c[x + 2u * y + 4u] = r.y;
        }
    }
    let x00 = lerp(c[0], c[1], f.x);
    let x10 = lerp(c[2], c[3], f.x);
    let x01 = lerp(c[4], c[5], f.x);
    let x11 = lerp(c[6], c[7], f.x);
    return lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z);
}

fn gradient(fp: Fp) -> vec3<f32> {
    if ((u.cells.w & FLAG_SOBEL) != 0u) {
        let b = gather(fp);
        let d = vec3<f32>(sobel_component(b, 0u, fp.f), sobel_component(b, 1u, fp.f), sobel_component(b, 2u, fp.f));
        return d * u.grad_scale.xyz;
    }
    return vec3<f32>(diff(fp, 0u), diff(fp, 1u), diff(fp, 2u)) * u.grad_scale.xyz;
}

fn lut_lookup(v: f32) -> vec4<f32> {
    let top = u.lut.z - 1.0;
    let x = clamp((v - u.lut.x) * u.lut.y, 0.0, top);
    let e0 = min(u32(x), u32(top) - 1u);
    let f = x - f32(e0);
    let a = lut[e0];
    let b = lut[e0 + 1u];
    return vec4<f32>(lerp(a.x, b.x, f), lerp(a.y, b.y, f), lerp(a.z, b.z, f), lerp(a.w, b.w, f));
}

fn cell_max(l: u32) -> f32 {
    return bitcast<f32>(accel[u.counts.z + u.counts.w + l]);
}

// 0: the cell may hold a visible sample; d > 0: every cell within d − 1
// cells is empty (MacroCells::leap_distances).
fn cell_leap(l: u32) -> u32 {
    return accel[u.counts.z + 2u * u.counts.w + l];
}

fn map_at(i: u32, j: u32, k: u32) -> f32 {
    let x = i - u.map_origin.x;
    let y = j - u.map_origin.y;
    let z = k - u.map_origin.z;
    var q = u.map_origin.w;
    if (x < u.map_dims.x && y < u.map_dims.y && z < u.map_dims.z) {
        let l = x + u.map_dims.x * (y + u.map_dims.y * z);
        q = (maps[(l >> 1u) - u.slab.w] >> ((l & 1u) * 16u)) & 0xffffu;
    }
    return f32(q) / 65535.0;
}

fn map_factor(fp: Fp, p: vec3<f32>) -> f32 {
    if ((u.cells.w & FLAG_MAP_NEAREST) != 0u) {
        let q = clamp(floor(p + vec3<f32>(0.5)), vec3<f32>(0.0), upper());
        return map_at(u32(q.x), u32(q.y), u32(q.z));
    }
    let i0 = fp.i;
    let i1 = min(i0 + vec3<u32>(1u), max(u.dims.xyz, vec3<u32>(1u)) - vec3<u32>(1u));
    let f = fp.f;
    let x00 = lerp(map_at(i0.x, i0.y, i0.z), map_at(i1.x, i0.y, i0.z), f.x);
    let x10 = lerp(map_at(i0.x, i1.y, i0.z), map_at(i1.x, i1.y, i0.z), f.x);
    let x01 = lerp(map_at(i0.x, i0.y, i1.z), map_at(i1.x, i0.y, i1.z), f.x);
    let x11 = lerp(map_at(i0.x, i1.y, i1.z), map_at(i1.x, i1.y, i1.z), f.x);
    return lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z);
}

struct Cell {
    c: vec3<u32>,
    l: u32,
}

fn cell_of(p_in: vec3<f32>) -> Cell {
    let p = clamp(p_in, vec3<f32>(0.0), upper());
    let c = min(vec3<u32>(p * (1.0 / u.step.w)), u.cells.xyz - vec3<u32>(1u));
    var out: Cell;
    out.c = c;
    out.l = c.x + u.cells.x * (c.y + u.cells.y * c.z);
    return out;
}

// Where the ray leaves the block of cells within d − 1 of cell c (d = 1: the cell).
fn cell_exit(c: vec3<u32>, d: u32, oi: vec3<f32>, di: vec3<f32>) -> f32 {
    var t = T_FAR;
    for (var a = 0u; a < 3u; a++) {
        if (di[a] > 0.0) {
            t = min(t, (f32(c[a] + d) * u.step.w - oi[a]) * (1.0 / di[a]));
        } else if (di[a] < 0.0) {
            t = min(t, ((f32(c[a]) + 1.0 - f32(d)) * u.step.w - oi[a]) * (1.0 / di[a]));
        }
    }
    return t;
}

struct Ray {
    o: vec3<f32>,
    d: vec3<f32>,
}

fn primary_ray(px: u32, py: u32) -> Ray {
    let nx = 2.0 * (f32(px) + 0.5) / f32(u.image.x) - 1.0;
    let ny = 1.0 - 2.0 * (f32(py) + 0.5) / f32(u.image.y);
    var r: Ray;
    if (u.image.z == 0u) {
        r.o = u.eye.xyz + u.right.xyz * nx + u.up.xyz * ny;
        r.d = u.forward.xyz;
    } else {
        r.o = u.eye.xyz;
        r.d = normalize(u.forward.xyz + u.right.xyz * nx + u.up.xyz * ny);
    }
    return r;
}

// [t0, t1] inside the box and every clip plane (t0 >= t1 when none).
fn interval(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t0 = 0.0;
    var t1 = T_FAR;
    for (var a = 0u; a < 3u; a++) {
        let lo = u.box_min[a];
        let hi = u.box_max[a];
        if (abs(d[a]) < 1e-12) {
            if (o[a] < lo || o[a] > hi) {
                return vec2<f32>(1.0, 0.0);
            }
        } else {
            let inv = 1.0 / d[a];
            let ta = (lo - o[a]) * inv;
            let tb = (hi - o[a]) * inv;
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    for (var q = 0u; q < u.counts.x; q++) {
        let pl = u.planes[q];
        let s = dot(pl.xyz, o) + pl.w;
        let nd = dot(pl.xyz, d);
        if (abs(nd) < 1e-12) {
            if (s < 0.0) {
                return vec2<f32>(1.0, 0.0);
            }
        } else {
            let th = -s / nd;
            if (nd > 0.0) {
                t0 = max(t0, th);
            } else {
                t1 = min(t1, th);
            }
        }
    }
    return vec2<f32>(t0, t1);
}

// A ray's loop state (saved between the passes of a split volume): for
// composite the accumulated colour and opacity, for MIP the running maximum
// (a) and the opacity-map factor at it (c.x); the next sample k, the samples
// taken, the empty-space exit parameter, and DONE / TERMINATED bits.
struct State {
    c: vec3<f32>,
    a: f32,
    k: u32,
    samples: u32,
    exit_t: f32,
    bits: u32,
}

const DONE: u32 = 1u;
const TERMINATED: u32 = 2u;
const MAXED: u32 = 4u;  // MIP: a maximum was recorded (c.x holds its map factor)

fn fresh_state() -> State {
    var st: State;
    st.c = vec3<f32>(0.0);
    st.a = select(0.0, F32_MIN, u.image.w == 1u);
    st.k = 0u;
    st.samples = 0u;
    st.exit_t = -1.0;
    st.bits = 0u;
    return st;
}

fn load_state(px: u32) -> State {
    let b = 8u * px;
    var st: State;
    st.c = vec3<f32>(bitcast<f32>(state[b]), bitcast<f32>(state[b + 1u]), bitcast<f32>(state[b + 2u]));
    st.a = bitcast<f32>(state[b + 3u]);
    st.k = state[b + 4u];
    st.samples = state[b + 5u];
    st.exit_t = bitcast<f32>(state[b + 6u]);
    st.bits = state[b + 7u];
    return st;
}

fn store_state(px: u32, st: State) {
    let b = 8u * px;
    state[b] = bitcast<u32>(st.c.x);
    state[b + 1u] = bitcast<u32>(st.c.y);
    state[b + 2u] = bitcast<u32>(st.c.z);
    state[b + 3u] = bitcast<u32>(st.a);
    state[b + 4u] = st.k;
    state[b + 5u] = st.samples;
    state[b + 6u] = bitcast<u32>(st.exit_t);
    state[b + 7u] = st.bits;
}

// True when sample point p (voxel units) belongs to a later pass: its
// footprint plane is outside this pass's [slab.x, slab.y).
fn elsewhere(p: vec3<f32>) -> bool {
    if ((u.pass_flags.x & PASS_SPLIT) == 0u) {
        return false;
    }
    let iz = footprint(p).i.z;
    return iz < u.slab.x || iz >= u.slab.y;
}

// Samples of [t0, t1]: `lead` (0/1) in the jitter step [t0, ts], n_full
// steps of dt from ts, then a last step of rem if not negligible.
struct Schedule {
    t0: f32,
    lead: u32,
    ts: f32,
    n_full: u32,
    rem: f32,
    n_total: u32,
}

fn schedule(t0: f32, t1: f32, px: u32, py: u32) -> Schedule {
    let dt = u.step.x;
    var xi = 0.0;
    if ((u.cells.w & FLAG_JITTER) != 0u) {
        xi = jitter(px, py);
    }
    let a = min(xi * dt, t1 - t0);
    var s: Schedule;
    s.t0 = t0;
    s.lead = select(0u, 1u, a > 1e-4 * dt);
    s.ts = t0 + a;
    let span = t1 - s.ts;
    s.n_full = u32(max(span, 0.0) * (1.0 / dt));
    s.rem = span - f32(s.n_full) * dt;
    s.n_total = s.lead + s.n_full + select(0u, 1u, s.rem > 1e-4 * dt);
    return s;
}

// Ray parameter (x) and step length (y) of sample k.
fn sample_at(s: Schedule, k: u32) -> vec2<f32> {
    let dt = u.step.x;
    if (k < s.lead) {
        let a = s.ts - s.t0;
        return vec2<f32>(s.t0 + 0.5 * a, a);
    }
    if (k - s.lead < s.n_full) {
        return vec2<f32>(s.ts + (f32(k - s.lead) + 0.5) * dt, dt);
    }
    return vec2<f32>(s.ts + f32(s.n_full) * dt + 0.5 * s.rem, s.rem);
}

fn next_sample(k: u32, s: Schedule, t_exit: f32) -> u32 {
    let next = u32(ceil(clamp((t_exit - s.ts) * (1.0 / u.step.x) - 0.5 + f32(s.lead), 0.0, f32(s.n_total))));
    return max(next, k + 1u);
}

fn composite(o: vec3<f32>, d: vec3<f32>, s: Schedule, st_in: State) -> State {
    let oi = (o - u.origin.xyz) * u.inv_spacing.xyz;
    let di = d * u.inv_spacing.xyz;
    let flags = u.cells.w;
    let ess = (flags & FLAG_ESS) != 0u;
    let et = (flags & FLAG_EARLY_TERMINATION) != 0u;
    let shade = (flags & FLAG_SHADING) != 0u;
    let has_map = u.counts.y != 0u;
    var c_acc = st_in.c;
    var a_acc = st_in.a;
    var samples = st_in.samples;
    var bits = st_in.bits;
    var exit_t = st_in.exit_t;
    var k = st_in.k;
    loop {
        if (k >= s.n_total) {
            bits |= DONE;
            break;
        }
        let tl = sample_at(s, k);
        let t = tl.x;
        let len = tl.y;
        let p = oi + di * t;
        if (elsewhere(p)) {
            break;
        }
        if (ess && t >= exit_t) {
            let c = cell_of(p);
            let d = cell_leap(c.l);
            if (d > 0u) {
                k = next_sample(k, s, cell_exit(c.c, d, oi, di));
                exit_t = -1.0;
                continue;
            }
            exit_t = cell_exit(c.c, 1u, oi, di);
        }
        k += 1u;
        let fp = footprint(p);
        let v = sample_value(p, fp);
        samples += 1u;
        let tf = lut_lookup(v);
        if (tf.w <= 0.0) {
            continue;
        }
        var alpha = 1.0 - exp(-tf.w * len);
        if (has_map) {
            alpha *= map_factor(fp, p);
        }
        if (alpha <= 0.0) {
            continue;
        }
        var col = tf.xyz;
        if (shade) {
            let g = gradient(fp);
            let len2 = dot(g, g);
            var ndl = 1.0;
            if (len2 > 1e-20) {
                ndl = abs(dot(g, d) / sqrt(len2));
            }
            var spec = 0.0;
            if (ndl > 0.0) {
                spec = pow(ndl, u.shading.w);
            }
            col = col * (u.shading.x + u.shading.y * ndl) + vec3<f32>(u.shading.z * spec);
        }
        let w = (1.0 - a_acc) * alpha;
        c_acc += col * w;
        a_acc += w;
        if (et && a_acc >= u.step.y) {
            bits |= DONE | TERMINATED;
            break;
        }
    }
    var r: State;
    r.c = c_acc;
    r.a = a_acc;
    r.k = k;
    r.samples = samples;
    r.exit_t = exit_t;
    r.bits = bits;
    return r;
}

fn mip(o: vec3<f32>, d: vec3<f32>, s: Schedule, st_in: State) -> State {
    let oi = (o - u.origin.xyz) * u.inv_spacing.xyz;
    let di = d * u.inv_spacing.xyz;
    let ess = (u.cells.w & FLAG_ESS) != 0u;
    var vmax = st_in.a;
    var factor = st_in.c.x;
    var samples = st_in.samples;
    var bits = st_in.bits;
    var exit_t = st_in.exit_t;
    var k = st_in.k;
    loop {
        if (k >= s.n_total) {
            bits |= DONE;
            break;
        }
        let t = sample_at(s, k).x;
        let p = oi + di * t;
        if (elsewhere(p)) {
            break;
        }
        if (ess && t >= exit_t) {
            let c = cell_of(p);
            let e = cell_exit(c.c, 1u, oi, di);
            if (samples > 0u && cell_max(c.l) <= vmax) {
                k = next_sample(k, s, e);
                exit_t = -1.0;
                continue;
            }
            exit_t = e;
        }
        k += 1u;
        let fp = footprint(p);
        let v = sample_value(p, fp);
        samples += 1u;
        if (v > vmax) {
            vmax = v;
            bits |= MAXED;
            // The opacity-map factor at the maximum, taken while its voxels
            // are bound (the same value the end of the ray would compute).
            if (u.counts.y != 0u) {
                factor = map_factor(fp, p);
            }
        }
    }
    var r: State;
    r.c = vec3<f32>(factor, 0.0, 0.0);
    r.a = vmax;
    r.k = k;
    r.samples = samples;
    r.exit_t = exit_t;
    r.bits = bits;
    return r;
}

// The pixel of a finished ray (premultiplied linear RGBA).
fn finish(st: State) -> vec4<f32> {
    if (u.image.w == 0u) {
        return vec4<f32>(st.c, st.a);
    }
    if (st.samples == 0u) {
        return vec4<f32>(0.0);
    }
    let tf = lut_lookup(st.a);
    var alpha = 1.0 - exp(-tf.w * u.step.z);
    if (u.counts.y != 0u) {
        if ((st.bits & MAXED) != 0u) {
            alpha *= st.c.x;
        } else {
            // No sample beat F32_MIN (all NaN): the map at voxel 0, as cpu.rs
            // (bound: the last pass is slab 0's).
            let p0 = vec3<f32>(0.0);
            alpha *= map_factor(footprint(p0), p0);
        }
    }
    return vec4<f32>(tf.xyz * alpha, alpha);
}

fn linear_to_srgb(c_in: f32) -> f32 {
    let c = clamp(c_in, 0.0, 1.0);
    if (c <= 0.0031308) {
        return c * 12.92;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

fn encode(p: vec4<f32>) -> u32 {
    let a = p.w;
    if (!(a > 0.0)) {
        return 0u;
    }
    let inv = 1.0 / a;
    let r = u32(round(linear_to_srgb(p.x * inv) * 255.0));
    let g = u32(round(linear_to_srgb(p.y * inv) * 255.0));
    let b = u32(round(linear_to_srgb(p.z * inv) * 255.0));
    let al = u32(round(clamp(a, 0.0, 1.0) * 255.0));
    return r | (g << 8u) | (b << 16u) | (al << 24u);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= u.image.x || gid.y >= u.image.y) {
        return;
    }
    let pixel = gid.x + gid.y * u.image.x;
    let flags = u.pass_flags.x;
    let split = (flags & PASS_SPLIT) != 0u;
    let ray = primary_ray(gid.x, gid.y);
    var st = fresh_state();
    if (split && (flags & PASS_FIRST) == 0u) {
        st = load_state(pixel);
    }
    let mine = select(PASS_DOWN, PASS_UP, ray.d.z >= 0.0);
    if ((flags & mine) != 0u && (st.bits & DONE) == 0u) {
        let iv = interval(ray.o, ray.d);
        if (iv.x < iv.y) {
            let sch = schedule(iv.x, iv.y, gid.x, gid.y);
            if (u.image.w == 0u) {
                st = composite(ray.o, ray.d, sch, st);
            } else {
                st = mip(ray.o, ray.d, sch, st);
            }
        } else {
            st.bits |= DONE;
        }
    }
    if ((flags & PASS_LAST) == 0u) {
        store_state(pixel, st);
        return;
    }
    var px = finish(st);
    if ((u.cells.w & FLAG_BACKGROUND) != 0u) {
        px += (1.0 - px.w) * u.background;
    }
    out_px[pixel] = encode(px);
    if (st.samples > 0u) {
        let old = atomicAdd(&stats[0], st.samples);
        if (old + st.samples < old) {
            atomicAdd(&stats[1], 1u);
        }
    }
    if ((st.bits & TERMINATED) != 0u) {
        atomicAdd(&stats[2], 1u);
    }
}
