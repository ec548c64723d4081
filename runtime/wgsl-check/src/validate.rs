//! Parsing and validating one WGSL source as wgpu does when the host
//! compiles it (`GpuService::compile` → `create_shader_module` +
//! `create_compute_pipeline`), without a device.

use naga::valid::{Capabilities, ValidationFlags, Validator};

use crate::shader::Shader;

/// A shader that wgpu would refuse: which shader, which stage of the check
/// and naga's rendered diagnostic (with the offending source line).
#[derive(Debug, thiserror::Error)]
#[error("WGSL shader `{name}` fails {stage}:\n{diagnostic}")]
pub struct ShaderError {
    /// The name the test gave the shader (file name or kernel).
    pub name: String,
    /// "parsing", "validation" or "wgpu's pipeline limits".
    pub stage: &'static str,
    /// naga's diagnostic as text (`emit_to_string`), or the limit broken.
    pub diagnostic: String,
}

/// The naga capabilities wgpu grants the host's device.
///
/// wgpu maps device features and downlevel flags to naga capabilities with
/// `wgpu_naga_bridge::features_to_naga_capabilities`, called here with:
///
/// - `Features::empty()`: the host opens its device with no optional
///   features (`runtime/host/src/gpu_context.rs`, `required_features`), so no
///   f16, f64, i64, subgroup, binding-array or immediate capability;
/// - `DownlevelFlags::empty()`: the three capabilities that depend on
///   downlevel flags (f16 in f32 packing, multisampled shading, cube-array
///   textures) vary by adapter and no compute kernel needs them; granting
///   none is the strictest choice, so a shader that passes here passes on
///   every adapter.
///
/// The result is the empty set: every voxflex shader must stay within core
/// WGSL.
pub fn capabilities() -> Capabilities {
    wgpu_naga_bridge::features_to_naga_capabilities(
        wgpu_types::Features::empty(),
        wgpu_types::DownlevelFlags::empty(),
    )
}

/// Parses and validates `source` as wgpu does; `name` labels the errors.
///
/// Parsing uses the same capabilities as validation (wgpu passes them to the
/// WGSL front end too) and validation runs with every
/// [`ValidationFlags`], as wgpu does. On top of naga, the checks wgpu makes
/// when it creates a compute pipeline that need no adapter, against
/// `wgpu_types::Limits::downlevel_defaults()` (the limits every adapter
/// wgpu opens reaches): each entry point's `@workgroup_size` per dimension
/// and in total, and its workgroup memory; and, for the host's single bind
/// group, every resource in group 0 with no binding number used twice by
/// one entry point.
pub fn try_validate(name: &str, source: &str) -> Result<Shader, ShaderError> {
    let caps = capabilities();
    let mut options = naga::front::wgsl::Options::new();
    options.capabilities = caps;
    let module = naga::front::wgsl::Frontend::new_with_options(options)
        .parse(source)
        .map_err(|e| ShaderError {
            name: name.to_owned(),
            stage: "parsing",
            diagnostic: e.emit_to_string_with_path(source, name),
        })?;
    let info = Validator::new(ValidationFlags::all(), caps)
        .validate(&module)
        .map_err(|e| ShaderError {
            name: name.to_owned(),
            stage: "validation",
            diagnostic: e.emit_to_string_with_path(source, name),
        })?;
    let shader = Shader::new(name, source, module, info);
    if let Err(problem) = shader.check_pipeline_limits(&wgpu_types::Limits::downlevel_defaults()) {
        return Err(ShaderError {
            name: name.to_owned(),
            stage: "wgpu's pipeline limits",
            diagnostic: problem,
        });
    }
    Ok(shader)
}

/// [`try_validate`], panicking with the shader's name and naga's diagnostic
/// when wgpu would refuse the shader (for tests).
#[track_caller]
pub fn validate(name: &str, source: &str) -> Shader {
    try_validate(name, source).unwrap_or_else(|e| panic!("{e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "
struct Params { n: u32, scale: f32, pad: vec2<u32>, origin: vec3<f32>, }
@group(0) @binding(0) var<storage, read> p: Params;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
const WG: u32 = 64u;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x < p.n) { out[gid.x] = p.scale; }
}
";

    #[test]
    fn core_wgsl_validates_and_no_capability_is_granted() {
        assert!(capabilities().is_empty());
        let s = validate("good", GOOD);
        assert_eq!(s.workgroup_size("main"), [64, 1, 1]);
        assert_eq!(s.const_u32("WG"), 64);
    }

    #[test]
    fn a_typo_fails_with_the_shader_name_and_the_offending_line() {
        let bad = GOOD.replace("out[gid.x] = p.scale;", "out[gid.x] = p.scael;");
        let e = try_validate("typo.wgsl", &bad).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("typo.wgsl"), "{text}");
        assert!(text.contains("p.scael"), "{text}");
        let syntax = GOOD.replace("fn main(", "fn main((");
        let e = try_validate("syntax.wgsl", &syntax).unwrap_err();
        assert_eq!(e.stage, "parsing", "{e}");
        assert!(e.to_string().contains("fn main(("), "{e}");
    }

    #[test]
    fn a_type_error_fails() {
        let bad = GOOD.replace("out[gid.x] = p.scale;", "out[gid.x] = p.n;");
        assert!(try_validate("types", &bad).is_err());
    }

    #[test]
    fn what_only_the_validator_sees_fails_validation() {
        // Parses, but stores through a `read` binding: the validator's catch.
        let bad = GOOD.replace("out[gid.x] = p.scale;", "p.n = gid.x;");
        let e = try_validate("read-only.wgsl", &bad).unwrap_err();
        assert_eq!(e.stage, "validation", "{e}");
        let text = e.to_string();
        assert!(text.contains("read-only.wgsl"), "{text}");
        assert!(text.contains("p.n = gid.x;"), "{text}");
        assert!(text.contains("not permitted"), "{text}");
    }

    #[test]
    fn capabilities_wgpu_does_not_grant_are_refused() {
        let f16 = "enable f16;\n@compute @workgroup_size(1) fn main() { let h = 1.0h; }";
        assert!(try_validate("f16", f16).is_err());
        let f64_ = "@group(0) @binding(0) var<storage, read_write> o: array<f64>;\n\
                    @compute @workgroup_size(1) fn main() { o[0] = o[1]; }";
        assert!(try_validate("f64", f64_).is_err());
    }

    #[test]
    fn pipeline_limits_and_the_single_bind_group_are_enforced() {
        let big = GOOD.replace("@workgroup_size(64)", "@workgroup_size(512)");
        let e = try_validate("big", &big).unwrap_err();
        assert_eq!(e.stage, "wgpu's pipeline limits", "{e}");
        let wide = GOOD.replace("@workgroup_size(64)", "@workgroup_size(16, 16, 2)");
        assert!(try_validate("wide", &wide).is_err());
        let group1 = GOOD.replace("@group(0) @binding(1)", "@group(1) @binding(1)");
        let e = try_validate("group1", &group1).unwrap_err();
        assert!(e.diagnostic.contains("group 1"), "{e}");
        let twice = GOOD.replace("@binding(1)", "@binding(0)");
        assert!(try_validate("twice", &twice).is_err());
        let shared = "var<workgroup> big: array<f32, 8192>;\n\
                      @compute @workgroup_size(1) fn main() { big[0] = 1.0; }";
        assert!(try_validate("shared", shared).is_err());
    }

    #[test]
    #[should_panic(expected = "WGSL shader `typo` fails")]
    fn validate_panics_with_the_diagnostic() {
        validate("typo", "fn f() -> u32 { return 1.0; }");
    }
}
