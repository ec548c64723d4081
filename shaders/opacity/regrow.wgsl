// Moving the growth into a larger working box (gpu.rs: GpuGrowth::regrow).

// One invocation per u32 word (two voxels) of the new field: the old value
// where the old box had the voxel, q_min elsewhere.
@compute @workgroup_size(64)
fn regrow(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let w = flat_index(gid, nwg);
    let n = R.nlo.w;
    if (w >= (n + 1u) / 2u) {
        return;
    }
    var word = 0u;
    for (var h = 0u; h < 2u; h++) {
        let l = 2u * w + h;
        var q = R.odim.w;
        if (l < n) {
            let x = l % R.ndim.x;
            let r = l / R.ndim.x;
            let p = R.nlo.xyz + vec3<u32>(x, r % R.ndim.y, r / R.ndim.y);
            if (all(p >= R.olo.xyz) && all(p < R.olo.xyz + R.odim.xyz)) {
                let o = p - R.olo.xyz;
                let ol = o.x + R.odim.x * (o.y + R.odim.y * o.z);
                q = (old_field[ol >> 1u] >> ((ol & 1u) * 16u)) & 0xffffu;
            }
        }
        word = word | (q << (h * 16u));
    }
    atomicStore(&field[w], word);
}

// One invocation per frontier entry: old box index -> new box index.
@compute @workgroup_size(64)
fn remap(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = flat_index(gid, nwg);
    if (i >= R.olo.w) {
        return;
    }
    let l = front[i];
    let x = l % R.odim.x;
    let r = l / R.odim.x;
    let o = R.olo.xyz + vec3<u32>(x, r % R.odim.y, r / R.odim.y) - R.nlo.xyz;
    next[i] = o.x + R.ndim.x * (o.y + R.ndim.y * o.z);
}

// One invocation per u32 word of the new marks: done where the new field
// holds q_max, no candidate (frontier.rs: marks_for).
@compute @workgroup_size(64)
fn mark(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let w = flat_index(gid, nwg);
    let n = R.nlo.w;
    if (w >= (n + 15u) / 16u) {
        return;
    }
    var word = 0u;
    for (var i = 0u; i < 16u; i++) {
        let v = 16u * w + i;
        if (v < n && field_get(v) == R.ndim.w) {
            word = word | (MARK_DONE << (2u * i));
        }
    }
    atomicStore(&marks[w], word);
}
