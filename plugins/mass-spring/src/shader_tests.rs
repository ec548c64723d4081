//! The mass-spring kernels' WGSL checked without a GPU: the module
//! validates as wgpu would accept it, declares exactly the kernels
//! [`GpuSprings`] compiles, and agrees with the Rust side on the workgroup
//! size, the `Params` words and the end-b flag of the incidence lists.

use super::*;
use voxflex_wgsl_check::ShaderSet;

/// The entry points `GpuSprings` compiles.
const KERNELS: [&str; 6] = [
    "spring_forces",
    "tet_forces",
    "node_forces",
    "integrate_tied",
    "tie_state",
    "integrate",
];

#[test]
fn the_kernels_validate_and_share_the_rust_constants() {
    let mut set = ShaderSet::new("mass-spring");
    let s = set.validate("mass-spring/springs.wgsl", SPRINGS_WGSL);
    s.assert_compute_entry_points(&KERNELS, "GpuSprings");
    for k in KERNELS {
        assert_eq!(s.workgroup_size(k), [WORKGROUP, 1, 1], "{k}");
    }
    assert_eq!(s.const_u32("WG"), WORKGROUP, "`flat` folds with WG");
    // `GpuSprings::frame` writes the words in this order, one 32-bit word each.
    let params = s.struct_layout("Params");
    assert_eq!(params.size as usize, 4 * PARAM_WORDS);
    let words: Vec<(&str, u32)> = params
        .members
        .iter()
        .map(|m| (m.name.as_str(), m.offset))
        .collect();
    let order = [
        "springs", "nodes", "h", "alpha", "frac", "tets", "pad1", "pad2",
    ];
    let expected: Vec<(&str, u32)> = order.into_iter().zip((0..).step_by(4)).collect();
    assert_eq!(words, expected);
    assert_eq!(s.const_u32("END_B"), crate::kernel::END_B);
    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("p", bind::PARAMS),
        ("springs", bind::SPRINGS),
        ("ends", bind::ENDS),
        ("kc", bind::KC),
        ("force", bind::FORCE),
        ("start", bind::START),
        ("incident", bind::INCIDENT),
        ("u", bind::U),
        ("v", bind::V),
        ("node", bind::NODE),
        ("drive", bind::DRIVE),
        ("fnode", bind::FNODE),
        ("tie_start", bind::TIE_START),
        ("tie_list", bind::TIE_LIST),
        ("untie_start", bind::UNTIE_START),
        ("untie_list", bind::UNTIE_LIST),
        ("tets", bind::TETS),
        ("tet_geom", bind::TET_GEOM),
    ] {
        assert_eq!(s.binding(var), binding, "`{var}`");
    }
    set.finish();
}
