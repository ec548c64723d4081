// ChainMail's active-block schedule on the GPU: the WGSL twin of
// plugins/chainmail/src/blocks.rs (`Blocks::next_active`). After a
// propagation iteration or a relaxation sweep over a block list, `schedule`
// builds the next list from the launch's per-block results without a trip
// through the CPU: a block that changed stays active and activates its face
// neighbours across the borders where one of its elements changed. `retire`
// then clears the de-duplication bits, readies the spent list for reuse and
// writes the indirect dispatch arguments that size the next launches to the
// new list, so the host can queue many iterations and read back only a few
// words every few of them.
//
// Buffers (32-bit words):
//   grid   u32  [4]                  blocks along x, y, z; the device's
//                                    largest workgroup count per dimension
//   list   u32  [1 + slot]           the list just run: length, blocks
//   stats  u32  [slot * 4]           its results (chainmail.wgsl): face
//                                    mask, visits, updates, largest move
//   next   atomic<u32> [1 + slot]    the list being built: length, blocks
//                                    (in no particular order: a launch's
//                                    result does not depend on the order)
//   flags  atomic<u32> [block]       IN_NEXT (de-duplication), ACTIVATED,
//                                    DIRTY, LISTED since the host last read
//   sched  atomic<u32> [SCHED_WORDS] run totals (see the S_ constants)
//   spent  atomic<u32> [1 + slot]    `retire`: the list just run, emptied
//   args   u32  [6]                  `retire`: the indirect dispatch
//                                    arguments of `next`: workgroups of the
//                                    block kernels (one per listed block,
//                                    folded into x, y), then of `schedule`
// One invocation per slot of `list` (`schedule`, dispatched through the
// list's arguments) or per block of the lattice (`retire`), in workgroups
// of WG.

@group(0) @binding(0) var<storage, read> grid: vec4<u32>;
@group(0) @binding(1) var<storage, read> list: array<u32>;
@group(0) @binding(2) var<storage, read> stats: array<u32>;
@group(0) @binding(3) var<storage, read_write> next: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> flags: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> sched: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> spent: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> args: array<u32>;

const WG: u32 = 64u;
const CHANGED: u32 = 64u;
const STAT_WORDS: u32 = 4u;

// flags bits.
const IN_NEXT: u32 = 1u;    // already in the list being built
const ACTIVATED: u32 = 2u;  // entered a built list during the run
const DIRTY: u32 = 4u;      // changed during the run (a nonzero face mask)
const LISTED: u32 = 8u;     // was in a list that ran

// sched words: 64-bit sums as (low, high) pairs.
const S_VISITS: u32 = 0u;
const S_UPDATES: u32 = 2u;
const S_BLOCKS: u32 = 4u;      // sum of the run lists' lengths
const S_LAUNCHES: u32 = 6u;    // launches whose list was not empty
const S_MAX: u32 = 7u;         // largest move of the launch being retired
const S_LAST_MAX: u32 = 8u;    // largest move of the last nonempty launch
const S_ANY_MAX: u32 = 9u;     // largest move of the whole run
const S_PENDING: u32 = 10u;    // length of the last list built
const SCHED_WORDS: u32 = 12u;
const ARG_WORDS: u32 = 6u;     // per list: block kernels' x, y, z; schedule's

// The flat invocation index of a launch folded as `workgroups_1d` folds
// (x = min(groups, limit), then y, then z): a dimension past the first is
// used only when the ones before it are the device's limit wide, so
// `num_workgroups` is not needed (D3D12 does not report it for
// unvalidated indirect dispatches).
fn flat(gid: vec3<u32>) -> u32 {
    let limit = grid.w;
    return gid.x + WG * limit * (gid.y + limit * gid.z);
}

// Workgroups for n items in groups of `per`, folded into (x, y, z) as
// voxflex_core::gpu::workgroups_1d folds them, so no dimension exceeds the
// device's limit; zero workgroups for no items.
fn write_args(at: u32, n: u32, per: u32) {
    let groups = (n + per - 1u) / per;
    let x = min(groups, grid.w);
    let rest = (groups + x - 1u) / max(x, 1u);
    let y = min(max(rest, 1u), grid.w);
    args[at] = x;
    args[at + 1u] = y;
    args[at + 2u] = (rest + y - 1u) / y;
}

fn add64(at: u32, v: u32) {
    let old = atomicAdd(&sched[at], v);
    if (old + v < old) {
        atomicAdd(&sched[at + 1u], 1u);
    }
}

// This invocation's blocks for the list being built (a changed block and
// its face neighbours: at most 7), each claimed once by its IN_NEXT flag.
var<private> mine: array<u32, 7>;
var<private> mine_n: u32;

// Claims block b for the list being built unless it is in already.
fn push(b: u32) {
    let old = atomicOr(&flags[b], IN_NEXT | ACTIVATED);
    if ((old & IN_NEXT) == 0u) {
        mine[mine_n] = b;
        mine_n = mine_n + 1u;
    }
}

// The workgroup's sums, added to the run totals by one invocation (one
// global atomic per workgroup and total, not one per listed block).
var<workgroup> wg_visits: atomic<u32>;
var<workgroup> wg_updates: atomic<u32>;
var<workgroup> wg_max: atomic<u32>;
var<workgroup> wg_pushed: atomic<u32>;
var<workgroup> wg_base: u32;

@compute @workgroup_size(64)
fn schedule(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if (lid == 0u) {
        atomicStore(&wg_visits, 0u);
        atomicStore(&wg_updates, 0u);
        atomicStore(&wg_max, 0u);
        atomicStore(&wg_pushed, 0u);
    }
    workgroupBarrier();
    let slot = flat(gid);
    let len = list[0];
    if (slot == 0u && len > 0u) {
        atomicAdd(&sched[S_LAUNCHES], 1u);
        add64(S_BLOCKS, len);
    }
    mine_n = 0u;
    if (slot < len) {
        let b = list[1u + slot];
        let m = stats[STAT_WORDS * slot];
        // A block's visits and updates are at most its elements: the
        // workgroup's sums fit 32 bits.
        atomicAdd(&wg_visits, stats[STAT_WORDS * slot + 1u]);
        atomicAdd(&wg_updates, stats[STAT_WORDS * slot + 2u]);
        // Moves are non-negative f32: their bits order as the values do.
        atomicMax(&wg_max, stats[STAT_WORDS * slot + 3u]);
        atomicOr(&flags[b], select(LISTED, LISTED | DIRTY, m != 0u));
        if ((m & CHANGED) != 0u) {
            push(b);
            let c = vec3<u32>(b % grid.x, (b / grid.x) % grid.y, b / (grid.x * grid.y));
            let stride = vec3<u32>(1u, grid.x, grid.x * grid.y);
            for (var a = 0u; a < 3u; a = a + 1u) {
                if ((m & (1u << (2u * a))) != 0u && c[a] > 0u) {
                    push(b - stride[a]);
                }
                if ((m & (1u << (2u * a + 1u))) != 0u && c[a] + 1u < grid[a]) {
                    push(b + stride[a]);
                }
            }
        }
    }
    let local = atomicAdd(&wg_pushed, mine_n);
    workgroupBarrier();
    if (lid == 0u) {
        add64(S_VISITS, atomicLoad(&wg_visits));
        add64(S_UPDATES, atomicLoad(&wg_updates));
        atomicMax(&sched[S_MAX], atomicLoad(&wg_max));
        wg_base = atomicAdd(&next[0], atomicLoad(&wg_pushed));
    }
    workgroupBarrier();
    let base = wg_base + local;
    for (var k = 0u; k < mine_n; k = k + 1u) {
        atomicStore(&next[1u + base + k], mine[k]);
    }
}

@compute @workgroup_size(64)
fn retire(
    @builtin(global_invocation_id) gid: vec3<u32>,
) {
    let slot = flat(gid);
    let len = atomicLoad(&next[0]);
    if (slot == 0u) {
        if (atomicLoad(&spent[0]) > 0u) {
            let mv = atomicLoad(&sched[S_MAX]);
            atomicStore(&sched[S_LAST_MAX], mv);
            atomicMax(&sched[S_ANY_MAX], mv);
        }
        atomicStore(&sched[S_MAX], 0u);
        atomicStore(&sched[S_PENDING], len);
        atomicStore(&spent[0], 0u);
        write_args(0u, len, 1u);
        write_args(3u, len, WG);
    }
    if (slot < len) {
        atomicAnd(&flags[atomicLoad(&next[1u + slot])], ~IN_NEXT);
    }
}
