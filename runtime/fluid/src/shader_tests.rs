//! The fluid-weight WGSL checked without a GPU: every kernel validates as
//! wgpu would accept it, and what the Rust side shares with it agrees
//! (workgroup size, `Params` layout, binding numbers, constants).

use super::*;
use voxflex_wgsl_check::{ShaderSet, assert_struct_layout};

#[test]
fn every_kernel_validates_and_shares_the_rust_constants() {
    let mut set = ShaderSet::new("fluid");
    for (entry, source) in kernel_sources() {
        let s = set.validate(&format!("fluid `{entry}`"), &source);
        assert!(s.compute_entry_points().contains(&entry));
        assert_eq!(s.workgroup_size(entry), [WORKGROUP, 1, 1], "{entry}");
        assert_eq!(s.const_u32("WG"), WORKGROUP);
        assert_eq!(s.const_u32("MAX_CAP"), MAX_CROSSINGS_PER_COLUMN);
        assert_eq!(s.const_u32("TOP"), TOP);
        assert_eq!(s.const_u32("STATUS_HEADER") as usize, STATUS_HEADER);
        assert_struct_layout!(s, "Params", Params { grid, more, geom });
        for (var, binding) in [
            ("P", bind::PARAMS),
            ("uvh", bind::UVH),
            ("tris", bind::TRIS),
            ("info", bind::INFO),
            ("counts", bind::COUNTS),
            ("rec_tri", bind::REC_TRI),
            ("rec_h", bind::REC_H),
            ("weights", bind::WEIGHTS),
            ("status", bind::STATUS),
        ] {
            assert_eq!(s.binding(var), binding, "{var}");
        }
        assert!(
            s.storage_buffers(entry) <= 8,
            "{entry}: wgpu's default limit is 8 storage buffers per stage"
        );
    }
    set.finish();
}
