//! The resampler's WGSL checked without a GPU: every kernel source
//! [`kernel_sources`] assembles validates as wgpu would accept it, and what
//! the Rust side shares with it agrees (workgroup size, `Params` layout,
//! binding numbers, block constants, owner encoding).

use super::*;
use crate::blocks::BLOCK_EDGE;
use crate::sampling_mesh::{OWNER_ID, WEAK_OWNER};
use voxflex_wgsl_check::{ShaderSet, assert_struct_layout};

#[test]
fn every_kernel_validates_and_shares_the_rust_constants() {
    let mut set = ShaderSet::new("resample");
    let sources = kernel_sources();
    for (entry, source) in &sources {
        let s = set.validate(&format!("resample `{entry}`"), source);
        assert_eq!(s.compute_entry_points(), [*entry], "one kernel per source");
        // Dispatches size their groups with WORKGROUP (`workgroups_for`);
        // block_bounds runs one workgroup per block, its threads striding.
        assert_eq!(s.workgroup_size(entry), [WORKGROUP, 1, 1], "{entry}");
        assert_eq!(s.const_u32("WG"), WORKGROUP, "flat_index folds with WG");
        assert_struct_layout!(
            s,
            "Params",
            Params {
                vdim,
                cdim,
                bdim,
                inv,
                oorg,
                odim,
                clo,
                chi,
                misc,
                slab,
                cells
            }
        );
        assert_eq!(s.binding("P"), bind::PARAMS);
        if *entry != "clear" {
            // displacement.wgsl, in every kernel that reads vertex positions.
            assert_eq!(s.binding("DX"), bind::DX);
            assert_eq!(s.binding("DY"), bind::DY);
            assert_eq!(s.binding("DZ"), bind::DZ);
        }
        assert_eq!(s.const_u32("BLOCK_EDGE") as usize, BLOCK_EDGE);
        assert_eq!(s.const_u32("CELLS_PER_BLOCK") as usize, CELLS_PER_BLOCK);
        assert_eq!(
            s.const_u32("NO_OWNER"),
            u32::MAX,
            "cpu.rs clears to u32::MAX"
        );
    }
    let by_entry = |e: &str| {
        let (_, src) = sources.iter().find(|(n, _)| *n == e).unwrap();
        voxflex_wgsl_check::validate(e, src)
    };
    let bounds = by_entry("block_bounds");
    assert_eq!(bounds.binding("BLOCKS"), bind::BLOCKS);
    assert_eq!(bounds.binding("BOUNDS"), bind::BOUNDS);
    let raster = by_entry("raster");
    assert_eq!(raster.binding("OUT"), bind::OUT);
    assert_eq!(raster.binding("MASK"), bind::MASK);
    assert_eq!(raster.const_u32("WEAK_OWNER"), WEAK_OWNER);
    let fill = by_entry("fill");
    assert_eq!(fill.binding("OUT"), bind::OUT);
    assert_eq!(fill.binding("VALUES"), bind::VALUES);
    assert_eq!(fill.binding("FILLED"), bind::FILLED);
    assert_eq!(fill.binding("MISSED"), bind::MISSED);
    assert!(
        fill.source()
            .contains(&format!("owner & 0x{OWNER_ID:08x}u"))
    );
    assert_eq!(by_entry("clear").binding("OUT"), bind::OUT);
    assert_eq!(by_entry("clear").binding("FILLED"), bind::FILLED);
    set.finish();
}
