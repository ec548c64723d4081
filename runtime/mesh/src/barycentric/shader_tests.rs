//! The barycentric map's WGSL checked without a GPU: the kernel validates as
//! wgpu would accept it, and its workgroup size, `Params` size and weight
//! unit agree with the Rust side.

use super::*;
use voxflex_wgsl_check::ShaderSet;

#[test]
fn the_map_kernel_validates_and_shares_the_rust_constants() {
    let mut set = ShaderSet::new("barycentric");
    let s = set.validate("barycentric/map.wgsl", MAP_WGSL);
    // `GpuBinding::map` compiles this entry point.
    assert_eq!(s.compute_entry_points(), ["main"]);
    assert_eq!(s.workgroup_size("main"), [WORKGROUP, 1, 1]);
    assert_eq!(s.const_u32("WG"), WORKGROUP, "the flat index folds with WG");
    assert_eq!(s.struct_layout("Params").size as u64, PARAMS_BYTES);
    // One 16-bit weight unit, as the CPU's `unpack` decodes it.
    assert_eq!(s.const_f32("UNIT"), super::super::unpack([1, 0, 0])[1]);
    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("p", bind::PARAMS),
        ("tet_of", bind::TET_OF),
        ("w12", bind::W12),
        ("w3", bind::W3),
        ("tets", bind::TETS),
        ("nodes", bind::NODES),
        ("out_x", bind::OUT_X),
        ("out_y", bind::OUT_Y),
        ("out_z", bind::OUT_Z),
    ] {
        assert_eq!(s.binding(var), binding, "`{var}`");
    }
    set.finish();
}
