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
}

@group(0) @binding(0) var<storage, read> u: U;
@group(0) @binding(1) var<storage, read> vol: array<f32>;
@group(0) @binding(2) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> accel: array<u32>;
@group(0) @binding(4) var<storage, read> maps: array<u32>;
@group(0) @binding(5) var<storage, read_write> out_px: array<u32>;
@group(0) @binding(6) var<storage, read_write> stats: array<atomic<u32>>;

const FLAG_ESS: u32 = 1u;
const FLAG_EARLY_TERMINATION: u32 = 2u;
const FLAG_SHADING: u32 = 4u;
const FLAG_MAP_NEAREST: u32 = 8u;
const FLAG_BACKGROUND: u32 = 16u;
const T_FAR: f32 = 3.0e38;
const F32_MIN: f32 = -3.40282347e38;

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    return a + t * (b - a);
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
    let x00 = lerp(vol[b], vol[b + o.x], fp.f.x);
    let x10 = lerp(vol[b + o.y], vol[b + o.x + o.y], fp.f.x);
    let x01 = lerp(vol[b + o.z], vol[b + o.x + o.z], fp.f.x);
    let x11 = lerp(vol[b + o.y + o.z], vol[b + o.x + o.y + o.z], fp.f.x);
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
        acc[q] = (1.0 - fa) * (vol[r + i1 * sa] - vol[r + im * sa]) + fa * (vol[r + i2 * sa] - vol[r + i0 * sa]);
    }
    return lerp(lerp(acc[0], acc[1], fb), lerp(acc[2], acc[3], fb), fc);
}

fn gradient(fp: Fp) -> vec3<f32> {
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
        q = (maps[l >> 1u] >> ((l & 1u) * 16u)) & 0xffffu;
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

struct Result {
    rgba: vec4<f32>,
    samples: u32,
    terminated: u32,
}

struct Schedule {
    n_full: u32,
    rem: f32,
    n_total: u32,
}

fn schedule(t0: f32, t1: f32) -> Schedule {
    let dt = u.step.x;
    let span = t1 - t0;
    var s: Schedule;
    s.n_full = u32(span * (1.0 / dt));
    s.rem = span - f32(s.n_full) * dt;
    s.n_total = s.n_full + select(0u, 1u, s.rem > 1e-4 * dt);
    return s;
}

fn next_sample(k: u32, t0: f32, t_exit: f32, n_total: u32) -> u32 {
    let next = u32(ceil(clamp((t_exit - t0) * (1.0 / u.step.x) - 0.5, 0.0, f32(n_total))));
    return max(next, k + 1u);
}

fn composite(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> Result {
    let oi = (o - u.origin.xyz) * u.inv_spacing.xyz;
    let di = d * u.inv_spacing.xyz;
    let s = schedule(t0, t1);
    let dt = u.step.x;
    let flags = u.cells.w;
    let ess = (flags & FLAG_ESS) != 0u;
    let et = (flags & FLAG_EARLY_TERMINATION) != 0u;
    let shade = (flags & FLAG_SHADING) != 0u;
    let has_map = u.counts.y != 0u;
    var c_acc = vec3<f32>(0.0);
    var a_acc = 0.0;
    var samples = 0u;
    var terminated = 0u;
    var exit_t = -1.0;
    var k = 0u;
    loop {
        if (k >= s.n_total) {
            break;
        }
        var t = t0 + f32(s.n_full) * dt + 0.5 * s.rem;
        var len = s.rem;
        if (k < s.n_full) {
            t = t0 + (f32(k) + 0.5) * dt;
            len = dt;
        }
        let p = oi + di * t;
        if (ess && t >= exit_t) {
            let c = cell_of(p);
            let d = cell_leap(c.l);
            if (d > 0u) {
                k = next_sample(k, t0, cell_exit(c.c, d, oi, di), s.n_total);
                exit_t = -1.0;
                continue;
            }
            exit_t = cell_exit(c.c, 1u, oi, di);
        }
        k += 1u;
        let fp = footprint(p);
        let v = value(fp);
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
            terminated = 1u;
            break;
        }
    }
    var r: Result;
    r.rgba = vec4<f32>(c_acc, a_acc);
    r.samples = samples;
    r.terminated = terminated;
    return r;
}

fn mip(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> Result {
    let oi = (o - u.origin.xyz) * u.inv_spacing.xyz;
    let di = d * u.inv_spacing.xyz;
    let s = schedule(t0, t1);
    let dt = u.step.x;
    let ess = (u.cells.w & FLAG_ESS) != 0u;
    var vmax = F32_MIN;
    var pmax = vec3<f32>(0.0);
    var samples = 0u;
    var exit_t = -1.0;
    var k = 0u;
    loop {
        if (k >= s.n_total) {
            break;
        }
        var t = t0 + f32(s.n_full) * dt + 0.5 * s.rem;
        if (k < s.n_full) {
            t = t0 + (f32(k) + 0.5) * dt;
        }
        let p = oi + di * t;
        if (ess && t >= exit_t) {
            let c = cell_of(p);
            let e = cell_exit(c.c, 1u, oi, di);
            if (samples > 0u && cell_max(c.l) <= vmax) {
                k = next_sample(k, t0, e, s.n_total);
                exit_t = -1.0;
                continue;
            }
            exit_t = e;
        }
        k += 1u;
        let v = value(footprint(p));
        samples += 1u;
        if (v > vmax) {
            vmax = v;
            pmax = p;
        }
    }
    var r: Result;
    r.rgba = vec4<f32>(0.0);
    r.samples = samples;
    r.terminated = 0u;
    if (samples == 0u) {
        return r;
    }
    let tf = lut_lookup(vmax);
    var alpha = 1.0 - exp(-tf.w * u.step.z);
    if (u.counts.y != 0u) {
        alpha *= map_factor(footprint(pmax), pmax);
    }
    r.rgba = vec4<f32>(tf.xyz * alpha, alpha);
    return r;
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
    let ray = primary_ray(gid.x, gid.y);
    let iv = interval(ray.o, ray.d);
    var res: Result;
    res.rgba = vec4<f32>(0.0);
    res.samples = 0u;
    res.terminated = 0u;
    if (iv.x < iv.y) {
        if (u.image.w == 0u) {
            res = composite(ray.o, ray.d, iv.x, iv.y);
        } else {
            res = mip(ray.o, ray.d, iv.x, iv.y);
        }
    }
    var px = res.rgba;
    if ((u.cells.w & FLAG_BACKGROUND) != 0u) {
        px += (1.0 - px.w) * u.background;
    }
    out_px[gid.x + gid.y * u.image.x] = encode(px);
    if (res.samples > 0u) {
        let old = atomicAdd(&stats[0], res.samples);
        if (old + res.samples < old) {
            atomicAdd(&stats[1], 1u);
        }
    }
    if (res.terminated != 0u) {
        atomicAdd(&stats[2], 1u);
    }
}
