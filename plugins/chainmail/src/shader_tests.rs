//! The ChainMail kernels' WGSL checked without a GPU: the module validates
//! as wgpu would accept it, declares exactly the kernels [`GpuChainMail`]
//! compiles, and agrees with the Rust side on the key layout (wave/time
//! split), the site flag bits, the block-changed bit, the buffer layouts
//! (`Params` words, link records, result words) and the workgroup sizes;
//! the scheduling kernels (`schedule.wgsl`) agree with
//! [`crate::gpu_schedule`] on the same and on their flag bits and totals.

use super::*;
use crate::blocks::CHANGED;
use crate::gpu_schedule::{SCHED_WORDS, SCHEDULE_WGSL, SCHEDULE_WORKGROUP};
use crate::lattice::{ABSENT, FIXED, HELD};
use crate::state::{MAX_TIME, MAX_WAVE, TIME_BITS, key};
use voxflex_wgsl_check::ShaderSet;

/// The entry points `GpuChainMail::new` compiles.
const KERNELS: [&str; 4] = ["propagate", "relax", "sync_copies", "map_identity"];

#[test]
fn the_kernels_validate_and_share_chainmails_constants() {
    let mut set = ShaderSet::new("chainmail");
    let s = set.validate("chainmail/chainmail.wgsl", CHAINMAIL_WGSL);
    s.assert_compute_entry_points(&KERNELS, "GpuChainMail");

    // Block kernels run one workgroup per listed block (`workgroups_for(len,
    // 1)`) and stride their threads by WG; map_identity is one invocation per
    // voxel in workgroups of MAP_WORKGROUP.
    let wg = s.const_u32("WG");
    for k in KERNELS {
        assert_eq!(s.workgroup_size(k), [wg, 1, 1], "{k} strides by WG");
    }
    assert_eq!(s.workgroup_size("map_identity"), [MAP_WORKGROUP, 1, 1]);

    // Arrival keys: wave in the high bits, time in the low TIME_BITS.
    assert_eq!(
        s.const_u32("WAVE_SHIFT"),
        TIME_BITS,
        "WAVE_SHIFT vs state::TIME_BITS"
    );
    assert_eq!(
        s.const_u32("MAX_TIME"),
        MAX_TIME,
        "MAX_TIME vs state::MAX_TIME"
    );
    let (shift, max_time) = (s.const_u32("WAVE_SHIFT"), s.const_u32("MAX_TIME"));
    let k = key(MAX_WAVE, MAX_TIME);
    assert_eq!((k >> shift, k & max_time), (MAX_WAVE, MAX_TIME));

    // Site byte: material (ABSENT = no element) and the held/fixed flags.
    assert_eq!(
        s.const_u32("ABSENT"),
        u32::from(ABSENT),
        "ABSENT vs lattice::ABSENT"
    );
    assert_eq!(
        s.const_u32("HELD"),
        u32::from(HELD),
        "HELD vs lattice::HELD"
    );
    assert_eq!(
        s.const_u32("FIXED"),
        u32::from(FIXED),
        "FIXED vs lattice::FIXED"
    );
    assert_eq!(
        s.const_u32("CHANGED"),
        u32::from(CHANGED),
        "CHANGED vs blocks::CHANGED"
    );

    // Buffer layouts.
    assert_eq!(
        s.struct_layout("Params").size as usize,
        4 * PARAM_WORDS,
        "Params vs PARAM_WORDS"
    );
    assert_eq!(s.const_u32("LINK_WORDS") as usize, LINK_WORDS, "LINK_WORDS");
    assert_eq!(s.const_u32("STAT_WORDS") as usize, STAT_WORDS, "STAT_WORDS");
    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("p", bind::PARAMS),
        ("u", bind::U),
        ("keys", bind::KEYS),
        ("sites", bind::SITES),
        ("links", bind::LINKS),
        ("list", bind::LIST),
        ("stats", bind::STATS),
        ("out_x", bind::OUT_X),
        ("out_y", bind::OUT_Y),
        ("out_z", bind::OUT_Z),
    ] {
        assert_eq!(s.binding(var), binding, "`{var}`");
    }
    // The block kernels bind the list the device builds.
    for k in ["propagate", "relax", "sync_copies"] {
        assert!(s.storage_buffers(k) <= 8, "{k}: at most 8 storage buffers");
    }
    the_schedule_kernels_share_the_hosts_layout(&mut set);
    set.finish();
}

fn the_schedule_kernels_share_the_hosts_layout(set: &mut ShaderSet) {
    use crate::gpu_schedule::{bind, flag};
    let s = set.validate("chainmail/schedule.wgsl", SCHEDULE_WGSL);
    s.assert_compute_entry_points(&["schedule", "retire"], "DeviceSchedule");
    for k in ["schedule", "retire"] {
        assert_eq!(s.workgroup_size(k), [SCHEDULE_WORKGROUP, 1, 1], "{k}");
        assert!(s.storage_buffers(k) <= 8, "{k}: at most 8 storage buffers");
    }
    assert_eq!(s.const_u32("WG"), SCHEDULE_WORKGROUP);
    assert_eq!(s.const_u32("CHANGED"), u32::from(CHANGED), "CHANGED");
    assert_eq!(s.const_u32("STAT_WORDS") as usize, STAT_WORDS);
    assert_eq!(s.const_u32("SCHED_WORDS") as usize, SCHED_WORDS);
    for (name, bit) in [
        ("IN_NEXT", flag::IN_NEXT),
        ("ACTIVATED", flag::ACTIVATED),
        ("DIRTY", flag::DIRTY),
        ("LISTED", flag::LISTED),
    ] {
        assert_eq!(s.const_u32(name), bit, "flag {name}");
    }
    use crate::gpu_schedule::{ARG_WORDS, word};
    assert_eq!(s.const_u32("ARG_WORDS") as usize, ARG_WORDS, "ARG_WORDS");
    for (name, at) in [
        ("S_VISITS", word::VISITS),
        ("S_UPDATES", word::UPDATES),
        ("S_BLOCKS", word::BLOCKS),
        ("S_LAUNCHES", word::LAUNCHES),
        ("S_LAST_MAX", word::LAST_MAX),
        ("S_ANY_MAX", word::ANY_MAX),
        ("S_PENDING", word::PENDING),
    ] {
        assert_eq!(s.const_u32(name) as usize, at, "{name}");
    }
    for (var, binding) in [
        ("grid", bind::GRID),
        ("list", bind::LIST),
        ("stats", bind::STATS),
        ("next", bind::NEXT),
        ("flags", bind::FLAGS),
        ("sched", bind::SCHED),
        ("spent", bind::SPENT),
        ("args", bind::ARGS),
    ] {
        assert_eq!(s.binding(var), binding, "`{var}`");
    }
}
