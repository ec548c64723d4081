//! The opacity growth's WGSL checked without a GPU: every kernel source
//! [`kernel_sources`] assembles validates as wgpu would accept it, and what
//! the Rust side shares with it agrees (workgroup size, `Params` and
//! `Regrow` layouts, binding numbers, the extinction bound).

use super::*;
use voxflex_wgsl_check::{ShaderSet, assert_struct_layout};

#[test]
fn every_kernel_validates_and_shares_the_rust_constants() {
    let mut set = ShaderSet::new("opacity");
    for (entry, source) in kernel_sources() {
        let s = set.validate(&format!("opacity `{entry}`"), &source);
        assert!(s.compute_entry_points().contains(&entry));
        assert_eq!(s.workgroup_size(entry), [WORKGROUP, 1, 1], "{entry}");
        assert_eq!(s.const_u32("WG"), WORKGROUP, "flat_index folds with WG");
        assert_struct_layout!(
            s,
            "Params",
            Params {
                vdim,
                blo,
                bdim,
                ext,
                q
            }
        );
        assert_struct_layout!(
            s,
            "Regrow",
            Regrow {
                olo,
                odim,
                nlo,
                ndim
            }
        );
        assert_eq!(s.const_f32("E_BOUND"), super::super::extinction::E_BOUND);
        for (var, binding) in [
            ("P", bind::PARAMS),
            ("values", bind::VALUES),
            ("field", bind::FIELD),
            ("marks", bind::MARKS),
            ("front", bind::FRONT),
            ("cand", bind::CAND),
            ("newval", bind::NEWVAL),
            ("next", bind::NEXT),
            ("counters", bind::COUNTERS),
            ("old_field", bind::OLD_FIELD),
            ("R", bind::REGROW),
        ] {
            assert_eq!(s.binding(var), binding, "`{var}` of {entry}");
        }
    }
    set.finish();
}

#[test]
fn every_entry_point_of_a_source_is_a_listed_kernel() {
    let sources = kernel_sources();
    for (entry, source) in &sources {
        for e in voxflex_wgsl_check::validate(entry, source).compute_entry_points() {
            assert!(
                sources.iter().any(|(k, s)| *k == e && s == source),
                "`{e}` is declared but kernel_sources() compiles no pipeline for it"
            );
        }
    }
}
