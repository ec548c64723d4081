//! The GPU PCG's WGSL checked without a GPU: the module validates as wgpu
//! would accept it, declares exactly the kernels [`GpuPcg::new`] compiles,
//! and agrees with the Rust side on workgroup sizes, the reduction width,
//! the partial-sum stride, the scalar slots and the `Params` size.

use super::*;
use voxflex_wgsl_check::ShaderSet;

/// The entry points `GpuPcg::new` compiles, with the threads per workgroup
/// its dispatch math assumes.
fn kernels() -> [(&'static str, u32); 14] {
    let (node, red) = (WORKGROUP, RED as u32);
    [
        ("start", node),
        ("begin_search", node),
        ("untie_r", node),
        ("untie_q", node),
        ("tie_p", node),
        ("spmv", node),
        ("update_xr", node),
        ("update_p", node),
        ("advance", 1),
        ("begin", 1),
        ("dot_pq", red),
        ("dot_rz", red),
        ("dot_rr", red),
        ("dot_final", red),
    ]
}

#[test]
fn the_pcg_kernels_validate_and_share_the_rust_constants() {
    let mut set = ShaderSet::new("mesh-model");
    let s = set.validate("mesh-model/pcg.wgsl", PCG_WGSL);
    let compiled: Vec<&str> = kernels().iter().map(|k| k.0).collect();
    s.assert_compute_entry_points(&compiled, "GpuPcg::new");
    for (entry, threads) in kernels() {
        assert_eq!(s.workgroup_size(entry), [threads, 1, 1], "{entry}");
    }
    assert_eq!(s.const_u32("WG"), WORKGROUP, "`flat` folds with WG");
    assert_eq!(s.const_u32("RED") as u64, RED);
    assert_eq!(s.const_u32("MAX_PARTIALS") as u64, MAX_PARTIALS);
    for (k, slot) in ["RZ", "PQ", "RZ_NEW", "RR"].into_iter().enumerate() {
        assert_eq!(s.const_u32(slot) as usize, k * SLOT, "scalar slot {slot}");
    }
    assert_eq!(s.struct_layout("Params").size as u64, PARAMS_BYTES);
    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("p_", bind::PARAMS),
        ("row_start", bind::ROW_START),
        ("col", bind::COL),
        ("blocks", bind::BLOCKS),
        ("inv", bind::INV),
        ("free", bind::FREE),
        ("x", bind::X),
        ("r", bind::R),
        ("z", bind::Z),
        ("p", bind::P),
        ("q", bind::Q),
        ("scalars", bind::SCALARS),
        ("partial", bind::PARTIAL),
        ("b", bind::B),
        ("tie_start", bind::TIE_START),
        ("tie_list", bind::TIE_LIST),
        ("untie_start", bind::UNTIE_START),
        ("untie_list", bind::UNTIE_LIST),
    ] {
        assert_eq!(s.binding(var), binding, "`{var}`");
    }
    set.finish();
}
