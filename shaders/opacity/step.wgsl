// The kernels of one Jacobi step (frontier.rs: enumerate, evaluate, apply;
// then pump), each one invocation per list entry, 3-D-folded dispatch —
// evaluate, apply and pump indirect, sized by size_candidates.

// Phase 1: one invocation per frontier voxel u; lists each neighbour v (26, or 6)
// that u's new value lifts (rise(q_u, e_v) > q_v), once (candidate mark),
// skipping done voxels, appending per workgroup.
@compute @workgroup_size(64)
fn enumerate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_index(gid, nwg);
    var mine: array<u32, 26>;
    var n = 0u;
    if (i < atomicLoad(&counters[0])) {
        let u = front[i];
        let qu = field_get(u);
        let c = vec3<i32>(box_coords(u));
        for (var dz = -1; dz <= 1; dz++) {
            for (var dy = -1; dy <= 1; dy++) {
                for (var dx = -1; dx <= 1; dx++) {
                    let p = c + vec3<i32>(dx, dy, dz);
                    if (not_a_neighbour(vec3<i32>(dx, dy, dz)) || !inside_box(p)) {
                        continue;
                    }
                    let pc = vec3<u32>(p);
                    let v = box_linear(pc);
                    let sh = (v & 15u) * 2u;
                    if (((atomicLoad(&marks[v >> 4u]) >> sh) & (MARK_CANDIDATE | MARK_DONE)) != 0u) {
                        continue;
                    }
                    let q = field_get(v);
                    let e = extinction(value_at(pc));
                    if (rise(qu, e) <= q) {
                        continue;
                    }
                    let bit = MARK_CANDIDATE << sh;
                    if ((atomicOr(&marks[v >> 4u], bit) & bit) != 0u) {
                        continue;
                    }
                    mine[n] = v;
                    n += 1u;
                }
            }
        }
    }
    let local = atomicAdd(&w_count, n);
    workgroupBarrier();
    if (lid == 0u) {
        w_base = atomicAdd(&counters[1], atomicLoad(&w_count));
    }
    workgroupBarrier();
    let base = w_base + local;
    for (var k = 0u; k < n; k++) {
        cand[base + k] = mine[k];
    }
}

// Between phases 1 and 2, one invocation: the workgroups of phases 2–4 (one
// invocation per candidate) as indirect arguments, folded as
// workgroups_1d folds them, so the host reads nothing back to size them.
@compute @workgroup_size(64)
fn size_candidates(@builtin(local_invocation_index) lid: u32) {
    if (lid != 0u) {
        return;
    }
    let groups = (atomicLoad(&counters[1]) + WG - 1u) / WG;
    let limit = P.vdim.w;
    let x = min(groups, limit);
    let rest = (groups + x - 1u) / max(x, 1u);
    let y = min(max(rest, 1u), limit);
    args[0] = x;
    args[1] = y;
    args[2] = (rest + y - 1u) / y;
}

// Phase 2: one invocation per candidate; the update rule, field read-only.
@compute @workgroup_size(64)
fn evaluate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = folded_index(gid);
    if (i >= atomicLoad(&counters[1])) {
        return;
    }
    let v = cand[i];
    let cu = box_coords(v);
    let c = vec3<i32>(cu);
    var m = 0u;
    for (var dz = -1; dz <= 1; dz++) {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let p = c + vec3<i32>(dx, dy, dz);
                if (not_a_neighbour(vec3<i32>(dx, dy, dz)) || !inside_box(p)) {
                    continue;
                }
                m = max(m, field_get(box_linear(vec3<u32>(p))));
            }
        }
    }
    let old = field_get(v);
    let e = extinction(value_at(cu));
    let new_q = max(rise(m, e), old);
    newval[i] = new_q;
    // Clear the candidate mark; set the done mark at the ceiling.
    var done = 0u;
    if (new_q == rise(P.q.y, e)) {
        done = MARK_DONE;
    }
    atomicXor(&marks[v >> 4u], (MARK_CANDIDATE | done) << ((v & 15u) * 2u));
}

var<workgroup> w_min: array<atomic<u32>, 3>;
var<workgroup> w_max: array<atomic<u32>, 3>;

// Phase 3: one invocation per candidate; stores risen values, appends them
// to the next frontier and grows the region box (per workgroup).
@compute @workgroup_size(64)
fn apply(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if (lid == 0u) {
        atomicStore(&w_min[0], NONE);
        atomicStore(&w_min[1], NONE);
        atomicStore(&w_min[2], NONE);
    }
    workgroupBarrier();
    let i = folded_index(gid);
    var changed = false;
    var v = 0u;
    if (i < atomicLoad(&counters[1])) {
        v = cand[i];
        let old = field_get(v);
        let new_q = newval[i];
        if (new_q > old) {
            // Only this invocation writes this half-word, and new_q <= 0xffff: no carry.
            atomicAdd(&field[v >> 1u], (new_q - old) << ((v & 1u) * 16u));
            changed = true;
            let p = P.blo.xyz + box_coords(v);
            atomicMin(&w_min[0], p.x);
            atomicMin(&w_min[1], p.y);
            atomicMin(&w_min[2], p.z);
            atomicMax(&w_max[0], p.x);
            atomicMax(&w_max[1], p.y);
            atomicMax(&w_max[2], p.z);
        }
    }
    var local = 0u;
    if (changed) {
        local = atomicAdd(&w_count, 1u);
    }
    workgroupBarrier();
    if (lid == 0u) {
        let total = atomicLoad(&w_count);
        if (total > 0u) {
            w_base = atomicAdd(&counters[2], total);
            for (var a = 0u; a < 3u; a++) {
                atomicMin(&counters[4u + a], atomicLoad(&w_min[a]));
                atomicMax(&counters[8u + a], atomicLoad(&w_max[a]));
            }
        }
    }
    workgroupBarrier();
    if (changed) {
        next[w_base + local] = v;
    }
}

// Phase 4: one invocation per voxel of the next frontier (dispatched for
// every candidate, at least as many): the pump shortcut on the values after
// the step (extinction.rs: Extinction::may_pump, pumps). A jump of another
// voxel to q_max does not change whether it is reached (above q_min), so
// the order of jumps does not matter.
@compute @workgroup_size(64)
fn pump(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = folded_index(gid);
    if (i >= atomicLoad(&counters[2])) {
        return;
    }
    let v = next[i];
    let q = field_get(v);
    let cu = box_coords(v);
    let e = extinction(value_at(cu));
    if (!(e < 0 && q < P.q.y)) {
        return;
    }
    let c = vec3<i32>(cu);
    var pumps = false;
    for (var dz = -1; dz <= 1; dz++) {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let p = c + vec3<i32>(dx, dy, dz);
                if (not_a_neighbour(vec3<i32>(dx, dy, dz)) || !inside_box(p)) {
                    continue;
                }
                let pc = vec3<u32>(p);
                let en = extinction(value_at(pc));
                let qn = field_get(box_linear(pc));
                if (e + en < 0 && (qn > P.q.x || rise(q, en) > P.q.x)) {
                    pumps = true;
                }
            }
        }
    }
    if (pumps) {
        // Only this invocation writes this half-word; q_max <= 0xffff: no carry.
        atomicAdd(&field[v >> 1u], (P.q.y - q) << ((v & 1u) * 16u));
        atomicOr(&marks[v >> 4u], MARK_DONE << ((v & 15u) * 2u));
    }
}
