//! The field kernel's WGSL checked without a GPU: it validates as wgpu
//! would accept it, and its workgroup size and `Uniforms` layout agree with
//! the Rust side ([`FieldUniforms`]).

use crate::field::{FieldUniforms, UNIFORM_BYTES};
use crate::{FIELD_WGSL, WORKGROUP, bind};
use std::mem::offset_of;
use voxflex_wgsl_check::ShaderSet;

#[test]
fn the_field_kernel_validates_and_shares_the_rust_layout() {
    let mut set = ShaderSet::new("affine");
    let s = set.validate("affine/field.wgsl", FIELD_WGSL);
    // `AffineField` compiles this entry point.
    assert_eq!(s.compute_entry_points(), ["main"]);
    assert_eq!(s.workgroup_size("main"), [WORKGROUP, 1, 1]);
    assert_eq!(s.const_u32("WG"), WORKGROUP, "the flat index folds with WG");
    let l = s.struct_layout("Uniforms");
    assert_eq!(l.size as usize, UNIFORM_BYTES);
    // Rust keeps the three affine rows in one array, WGSL in three members.
    let rust = [
        ("header", offset_of!(FieldUniforms, header)),
        ("centre_rate", offset_of!(FieldUniforms, centre_rate)),
        ("row0", offset_of!(FieldUniforms, rows)),
        (
            "row1",
            offset_of!(FieldUniforms, rows) + size_of::<[f32; 4]>(),
        ),
        (
            "row2",
            offset_of!(FieldUniforms, rows) + 2 * size_of::<[f32; 4]>(),
        ),
        ("region", offset_of!(FieldUniforms, region)),
        ("origin", offset_of!(FieldUniforms, origin)),
        ("spacing", offset_of!(FieldUniforms, spacing)),
        ("counts", offset_of!(FieldUniforms, counts)),
        ("slab", offset_of!(FieldUniforms, slab)),
    ];
    let wgsl: Vec<(&str, usize)> = l
        .members
        .iter()
        .map(|m| (m.name.as_str(), m.offset as usize))
        .collect();
    assert_eq!(wgsl, rust, "`Uniforms` of field.wgsl vs FieldUniforms");
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
