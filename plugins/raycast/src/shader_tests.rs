//! The renderer's WGSL checked without a GPU: the three kernels validate as
//! wgpu would accept them, and their workgroup sizes, uniform layouts,
//! render flags and leap cap agree with the Rust side.

use super::*;
use crate::macrocell::LEAP_CAP;
use crate::uniforms::{
    FLAG_BACKGROUND, FLAG_EARLY_TERMINATION, FLAG_ESS, FLAG_JITTER, FLAG_MAP_NEAREST, FLAG_SHADING,
    FLAG_SOBEL, FLAG_TRICUBIC, PASS_DOWN, PASS_FIRST, PASS_LAST, PASS_SPLIT, PASS_UP, RayUniforms,
};
use voxflex_wgsl_check::{ShaderSet, assert_struct_layout};

#[test]
fn the_render_kernels_validate_and_share_the_rust_constants() {
    let mut set = ShaderSet::new("raycast");

    let ray = set.validate("raycast/raycast.wgsl", RAYCAST_WGSL);
    // `GpuRenderer` compiles `main` of each kernel.
    assert_eq!(ray.compute_entry_points(), ["main"]);
    let tile = PIXEL_TILE as u32;
    assert_eq!(ray.workgroup_size("main"), [tile, tile, 1]);
    assert_struct_layout!(
        ray,
        "U",
        RayUniforms {
            eye,
            right,
            up,
            forward,
            image,
            dims,
            cells,
            origin,
            inv_spacing,
            grad_scale,
            step,
            lut,
            shading,
            background,
            box_min,
            box_max,
            planes,
            counts,
            map_origin,
            map_dims,
            slab,
            pass_flags,
        }
    );
    for (name, rust) in [
        ("FLAG_ESS", FLAG_ESS),
        ("FLAG_EARLY_TERMINATION", FLAG_EARLY_TERMINATION),
        ("FLAG_SHADING", FLAG_SHADING),
        ("FLAG_MAP_NEAREST", FLAG_MAP_NEAREST),
        ("FLAG_BACKGROUND", FLAG_BACKGROUND),
        ("FLAG_SOBEL", FLAG_SOBEL),
        ("FLAG_TRICUBIC", FLAG_TRICUBIC),
        ("FLAG_JITTER", FLAG_JITTER),
        ("PASS_UP", PASS_UP),
        ("PASS_DOWN", PASS_DOWN),
        ("PASS_FIRST", PASS_FIRST),
        ("PASS_LAST", PASS_LAST),
        ("PASS_SPLIT", PASS_SPLIT),
    ] {
        assert_eq!(ray.const_u32(name), rust, "{name}");
    }

    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("u", bind::ray::U),
        ("vol", bind::ray::VOL),
        ("lut", bind::ray::LUT),
        ("accel", bind::ray::ACCEL),
        ("maps", bind::ray::MAPS),
        ("out_px", bind::ray::OUT_PX),
        ("stats", bind::ray::STATS),
        ("state", bind::ray::STATE),
    ] {
        assert_eq!(ray.binding(var), binding, "ray: `{var}`");
    }

    let cells = set.validate("raycast/cells.wgsl", CELLS_WGSL);
    assert_eq!(cells.compute_entry_points(), ["main"]);
    assert_eq!(cells.workgroup_size("main"), [CELL_WORKGROUP, 1, 1]);
    assert_eq!(
        cells.const_u32("WG"),
        CELL_WORKGROUP,
        "flat index folds with WG"
    );
    assert_struct_layout!(
        cells,
        "C",
        CellUniforms {
            dims,
            counts,
            lo,
            size,
            base
        }
    );

    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [
        ("c", bind::cells::C),
        ("vol", bind::cells::VOL),
        ("accel", bind::cells::ACCEL),
    ] {
        assert_eq!(cells.binding(var), binding, "cells: `{var}`");
    }

    let leap = set.validate("raycast/leap.wgsl", LEAP_WGSL);
    assert_eq!(leap.compute_entry_points(), ["main"]);
    assert_eq!(leap.workgroup_size("main"), [CELL_WORKGROUP, 1, 1]);
    assert_eq!(
        leap.const_u32("WG"),
        CELL_WORKGROUP,
        "flat index folds with WG"
    );
    assert_struct_layout!(leap, "P", LeapUniforms { counts, offs, lut });
    assert_eq!(leap.const_u32("CAP"), u32::from(LEAP_CAP));

    // Every variable's `@binding` is the number the dispatches bind it at.
    for (var, binding) in [("p", bind::leap::P), ("accel", bind::leap::ACCEL)] {
        assert_eq!(leap.binding(var), binding, "leap: `{var}`");
    }
    set.finish();
}
