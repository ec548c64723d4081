// The mass-spring model's explicit sub-step on the GPU: the WGSL twins of
// plugins/mass-spring/src/kernel.rs (`spring_pass`, then `integrate` with
// the imposed nodes of solver.rs's explicit step), over the same data.
//
// Buffers (32-bit):
//   springs  vec4<f32> [s]   rest vector X_b − X_a (mm), rest length (mm)
//   ends     vec2<u32> [s]   end nodes a, b
//   kc       vec2<f32> [s]   stiffness (µN/mm), damping (µN·s/mm)
//   force    vec4<f32> [s + 4 t]  force on end a (µN), written by spring_forces;
//                            then per volume spring (tetrahedron) the force
//                            on each of its corners, written by tet_forces
//   start    u32 [n + 1]     node n's springs are incident[start[n] .. start[n + 1]]
//   incident u32 [2 s + 4 t] spring index, top bit set where the node is end b;
//                            or a volume-spring corner's row s + 4 t + c (added)
//   tets     vec4<u32> [t]   a volume spring's corners
//   tet_geom vec4<f32> [3 t] rest edge vectors X_c − X_0 (c = 1, 2, 3; mm),
//                            with κE/V₀ (µN/mm⁵), V₀ (mm³) and 0 in w
//   u, v     vec4<f32> [n]   displacement (mm) and velocity (mm/s)
//   node     vec4<f32> [n]   external force xyz (µN), mass (g)
//   drive    vec4<f32> [2 n] per node: kind (w of the first: 0 free, 1 fixed,
//                            2 driven, 3 hanging), start displacement (xyz of
//                            the first), target displacement (xyz of the
//                            second), mm
//   fnode    vec4<f32> [n]   total force per node (µN), when there are ties
//   tie_*, untie_*           a hanging node's masters, a master's hanging
//                            nodes: (node, weight bits) lists per node
// A sub-step starts with spring_forces and, when there are volume springs,
// tet_forces (kernel.rs `tet_forces`). Without hanging nodes it goes on with
// integrate. With them it
// is spring_forces, node_forces, integrate_tied (each free node adds the
// forces of the hanging nodes it carries, Pᵀ f), tie_state (P u, P v): the
// CPU's general path.
// A flat invocation index covers springs or nodes; dispatches are folded
// into 3-D (GpuServiceExt::workgroups_for) and unfolded with num_workgroups.

struct Params {
    springs: u32,
    nodes: u32,
    h: f32,        // sub-step, s
    alpha: f32,    // mass damping, 1/s
    frac: f32,     // how far along their path driven nodes are after this sub-step
    tets: u32,     // volume springs
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> p: Params;
@group(0) @binding(1) var<storage, read> springs: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> ends: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read> kc: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> force: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<u32>;
@group(0) @binding(7) var<storage, read_write> u: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read> node: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> drive: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> fnode: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read> tie_start: array<u32>;
@group(0) @binding(13) var<storage, read> tie_list: array<vec2<u32>>;
@group(0) @binding(14) var<storage, read> untie_start: array<u32>;
@group(0) @binding(15) var<storage, read> untie_list: array<vec2<u32>>;
@group(0) @binding(16) var<storage, read> tets: array<vec4<u32>>;
@group(0) @binding(17) var<storage, read> tet_geom: array<vec4<f32>>;

const WG: u32 = 64u;
const END_B: u32 = 0x80000000u;

fn flat(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    let row = nwg.x * WG;
    return gid.x + gid.y * row + gid.z * row * nwg.y;
}

// kernel.rs `spring_pass`: stretch from the ends' displacement difference,
// (|d|² − L²) / (|d| + L), never from subtracted positions.
@compute @workgroup_size(64)
fn spring_forces(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let s = flat(gid, nwg);
    if (s >= p.springs) {
        return;
    }
    let e = springs[s];
    let ab = ends[s];
    let du = u[ab.y].xyz - u[ab.x].xyz;
    let dv = v[ab.y].xyz - v[ab.x].xyz;
    let d = e.xyz + du;
    let len = sqrt(dot(d, d));
    let grow = 2.0 * dot(e.xyz, du) + dot(du, du);
    let sum = len + e.w;
    var stretch = 0.0;
    if (sum > 0.0) {
        stretch = grow / sum;
    }
    var dir = vec3<f32>(0.0);
    if (len > 0.0) {
        dir = d * (1.0 / len);
    }
    let k = kc[s];
    let mag = k.x * stretch + k.y * dot(dv, dir);
    force[s] = vec4<f32>(mag * dir, 0.0);
}

// kernel.rs `tet_forces`: a volume spring smaller than at rest pushes its
// corners along −k_v (V − V₀) ∂V/∂x; edges from displacement differences.
@compute @workgroup_size(64)
fn tet_forces(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let t = flat(gid, nwg);
    if (t >= p.tets) {
        return;
    }
    let c = tets[t];
    let g1 = tet_geom[3u * t];
    let g2 = tet_geom[3u * t + 1u];
    let g3 = tet_geom[3u * t + 2u];
    let u0 = u[c.x].xyz;
    let d1 = g1.xyz + (u[c.y].xyz - u0);
    let d2 = g2.xyz + (u[c.z].xyz - u0);
    let d3 = g3.xyz + (u[c.w].xyz - u0);
    let a1 = cross(d2, d3);
    let vol = dot(d1, a1) / 6.0;
    let row = p.springs + 4u * t;
    if (vol >= g2.w) {
        for (var k = 0u; k < 4u; k = k + 1u) {
            force[row + k] = vec4<f32>(0.0);
        }
        return;
    }
    let s = -g1.w * (vol - g2.w) / 6.0;
    let f1 = s * a1;
    let f2 = s * cross(d3, d1);
    let f3 = s * cross(d1, d2);
    force[row] = vec4<f32>(-(f1 + f2 + f3), 0.0);
    force[row + 1u] = vec4<f32>(f1, 0.0);
    force[row + 2u] = vec4<f32>(f2, 0.0);
    force[row + 3u] = vec4<f32>(f3, 0.0);
}

// The springs' (and volume springs') force on node n (µN).
fn spring_sum(n: u32) -> vec3<f32> {
    var f = vec3<f32>(0.0);
    for (var i = start[n]; i < start[n + 1u]; i = i + 1u) {
        let tagged = incident[i];
        let fs = force[tagged & ~END_B].xyz;
        if ((tagged & END_B) == 0u) {
            f = f + fs;
        } else {
            f = f - fs;
        }
    }
    return f;
}

// Imposed nodes (fixed, driven) as solver.rs's explicit step sets them;
// returns true when node n was one.
fn impose(n: u32) -> bool {
    let kind = drive[2u * n].w;
    if (kind == 1.0) {
        u[n] = vec4<f32>(0.0);
        v[n] = vec4<f32>(0.0);
        return true;
    }
    if (kind == 2.0) {
        let goal = mix(drive[2u * n].xyz, drive[2u * n + 1u].xyz, p.frac);
        v[n] = vec4<f32>((goal - u[n].xyz) / p.h, 0.0);
        u[n] = vec4<f32>(goal, 0.0);
        return true;
    }
    return kind == 3.0;
}

// With ties: every node's total force (springs, external, mass damping).
@compute @workgroup_size(64)
fn node_forces(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let n = flat(gid, nwg);
    if (n >= p.nodes) {
        return;
    }
    fnode[n] = vec4<f32>(spring_sum(n) + node[n].xyz - p.alpha * node[n].w * v[n].xyz, 0.0);
}

// With ties: free nodes take their own force plus that of the hanging
// nodes they carry (solver.rs's general path: untie, then apply).
@compute @workgroup_size(64)
fn integrate_tied(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let n = flat(gid, nwg);
    if (n >= p.nodes || impose(n)) {
        return;
    }
    var f = fnode[n].xyz;
    for (var k = untie_start[n]; k < untie_start[n + 1u]; k = k + 1u) {
        let e = untie_list[k];
        f = f + bitcast<f32>(e.y) * fnode[e.x].xyz;
    }
    let vn = v[n].xyz + f * (p.h / node[n].w);
    v[n] = vec4<f32>(vn, 0.0);
    u[n] = vec4<f32>(u[n].xyz + p.h * vn, 0.0);
}

// With ties: hanging nodes follow their masters.
@compute @workgroup_size(64)
fn tie_state(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let n = flat(gid, nwg);
    if (n >= p.nodes || drive[2u * n].w != 3.0) {
        return;
    }
    var un = vec3<f32>(0.0);
    var vn = vec3<f32>(0.0);
    for (var k = tie_start[n]; k < tie_start[n + 1u]; k = k + 1u) {
        let e = tie_list[k];
        let w = bitcast<f32>(e.y);
        un = un + w * u[e.x].xyz;
        vn = vn + w * v[e.x].xyz;
    }
    u[n] = vec4<f32>(un, 0.0);
    v[n] = vec4<f32>(vn, 0.0);
}

// kernel.rs `integrate` for free nodes (symplectic Euler,
// v += h ((f + ext) / m − α v), u += h v), then the
// imposed nodes as solver.rs's explicit step sets them.
@compute @workgroup_size(64)
fn integrate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let n = flat(gid, nwg);
    if (n >= p.nodes || impose(n)) {
        return;
    }
    let f = spring_sum(n);
    let m = node[n].w;
    var vn = v[n].xyz;
    let a = (f + node[n].xyz) * (1.0 / m) - p.alpha * vn;
    vn = vn + p.h * a;
    v[n] = vec4<f32>(vn, 0.0);
    u[n] = vec4<f32>(u[n].xyz + p.h * vn, 0.0);
}
