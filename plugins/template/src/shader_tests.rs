//! STEP 5b: the kernel's WGSL checked without a GPU — it validates as
//! wgpu would accept it (naga, through `voxflex-wgsl-check`), and its
//! workgroup size and `Uniforms` layout agree with the Rust side
//! ([`FieldUniforms`]). Keep this test when you copy the template: the
//! shader coverage guard fails for a shader directory whose owner has no
//! such test.

use crate::field::FieldUniforms;
use crate::model::{FIELD_WGSL, WORKGROUP, bind};
use voxflex_wgsl_check::{ShaderSet, assert_struct_layout};

#[test]
fn the_bulge_kernel_validates_and_shares_the_rust_layout() {
    let mut set = ShaderSet::new("template");
    let s = set.validate("template/bulge.wgsl", FIELD_WGSL);
    assert_eq!(s.compute_entry_points(), ["main"]);
    assert_eq!(s.workgroup_size("main"), [WORKGROUP, 1, 1]);
    assert_eq!(s.const_u32("WG"), WORKGROUP, "the flat index folds with WG");
    assert_struct_layout!(
        s,
        "Uniforms",
        FieldUniforms {
            centre_radius,
            amplitude,
            origin,
            spacing,
            counts,
            mode,
        }
    );
    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("u", bind::U),
        ("px", bind::PX),
        ("py", bind::PY),
        ("pz", bind::PZ),
        ("ux", bind::UX),
        ("uy", bind::UY),
        ("uz", bind::UZ),
    ] {
        assert_eq!(s.binding(var), binding, "`{var}`");
    }
    set.finish();
}
