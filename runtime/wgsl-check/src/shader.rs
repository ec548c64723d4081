//! A validated WGSL module and what Rust-side tests read from it.

use naga::valid::ModuleInfo;
use naga::{AddressSpace, Expression, Literal, Module, ShaderStage, TypeInner};

use crate::layout::{MemberLayout, StructLayout};

/// A WGSL source that parsed and validated as wgpu would accept it (see
/// [`crate::validate`]), with naga's module and analysis.
pub struct Shader {
    name: String,
    source: String,
    module: Module,
    info: ModuleInfo,
    layouter: naga::proc::Layouter,
}

impl std::fmt::Debug for Shader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shader")
            .field("name", &self.name)
            .field("entry_points", &self.compute_entry_points())
            .finish_non_exhaustive()
    }
}

impl Shader {
    pub(crate) fn new(name: &str, source: &str, module: Module, info: ModuleInfo) -> Self {
        let mut layouter = naga::proc::Layouter::default();
        layouter
            .update(module.to_ctx())
            .expect("a validated module has a layout");
        Self {
            name: name.to_owned(),
            source: source.to_owned(),
            module,
            info,
            layouter,
        }
    }

    /// The name the test gave the shader.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The full WGSL source that was validated.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// naga's module.
    pub fn module(&self) -> &Module {
        &self.module
    }

    /// The names of the module's `@compute` entry points, in source order.
    pub fn compute_entry_points(&self) -> Vec<&str> {
        self.module
            .entry_points
            .iter()
            .filter(|e| e.stage == ShaderStage::Compute)
            .map(|e| e.name.as_str())
            .collect()
    }

    /// Asserts that the module declares exactly the `@compute` entry points
    /// `compiled` names (in any order): the ones `compiler` (the Rust type
    /// that builds the pipelines) compiles. A kernel added on one side
    /// only fails here.
    pub fn assert_compute_entry_points(&self, compiled: &[&str], compiler: &str) {
        let mut declared = self.compute_entry_points();
        let mut compiled = compiled.to_vec();
        declared.sort_unstable();
        compiled.sort_unstable();
        assert_eq!(
            declared, compiled,
            "{}: kernels declared vs compiled by {compiler}",
            self.name
        );
    }

    fn entry_index(&self, entry: &str) -> usize {
        self.module
            .entry_points
            .iter()
            .position(|e| e.name == entry && e.stage == ShaderStage::Compute)
            .unwrap_or_else(|| {
                panic!(
                    "shader `{}` has no @compute entry point `{entry}` (it has {:?}); \
                     the host compiles pipelines by entry-point name",
                    self.name,
                    self.compute_entry_points()
                )
            })
    }

    /// `@workgroup_size` of a compute entry point, `[x, y, z]` threads;
    /// panics naming the shader when the entry point does not exist.
    #[track_caller]
    pub fn workgroup_size(&self, entry: &str) -> [u32; 3] {
        self.module.entry_points[self.entry_index(entry)].workgroup_size
    }

    /// Threads per workgroup of a compute entry point (`x · y · z`).
    #[track_caller]
    pub fn workgroup_threads(&self, entry: &str) -> u32 {
        self.workgroup_size(entry).iter().product()
    }

    /// The storage buffers an entry point uses (what wgpu counts against
    /// `max_storage_buffers_per_shader_stage`).
    #[track_caller]
    pub fn storage_buffers(&self, entry: &str) -> usize {
        let info = self.info.get_entry_point(self.entry_index(entry));
        self.module
            .global_variables
            .iter()
            .filter(|(h, v)| {
                matches!(v.space, AddressSpace::Storage { .. }) && !info[*h].is_empty()
            })
            .count()
    }

    /// `@binding` number of a resource variable (all are in group 0: see
    /// [`crate::try_validate`]); panics naming the shader when absent.
    #[track_caller]
    pub fn binding(&self, var: &str) -> u32 {
        self.module
            .global_variables
            .iter()
            .find(|(_, v)| v.name.as_deref() == Some(var))
            .and_then(|(_, v)| v.binding.as_ref())
            .unwrap_or_else(|| panic!("shader `{}` has no resource variable `{var}`", self.name))
            .binding
    }

    fn literal_of(&self, name: &str) -> Literal {
        let (_, c) = self
            .module
            .constants
            .iter()
            .find(|(_, c)| c.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("shader `{}` declares no `const {name}`", self.name));
        match self.module.global_expressions[c.init] {
            Expression::Literal(l) => l,
            ref other => panic!(
                "`const {name}` of shader `{}` is not a scalar literal after evaluation: {other:?}",
                self.name
            ),
        }
    }

    /// The value of a scalar integer `const` (u32, i32 or abstract int,
    /// non-negative and within u32); panics naming the shader otherwise.
    #[track_caller]
    pub fn const_u32(&self, name: &str) -> u32 {
        let v: i64 = match self.literal_of(name) {
            Literal::U32(v) => v.into(),
            Literal::I32(v) => v.into(),
            Literal::AbstractInt(v) => v,
            other => panic!(
                "`const {name}` of shader `{}` is {other:?}, not an integer",
                self.name
            ),
        };
        u32::try_from(v).unwrap_or_else(|_| {
            panic!(
                "`const {name}` of shader `{}` is {v}, outside u32",
                self.name
            )
        })
    }

    /// The value of a scalar float `const` (f32 or abstract float).
    #[track_caller]
    pub fn const_f32(&self, name: &str) -> f32 {
        match self.literal_of(name) {
            Literal::F32(v) => v,
            Literal::AbstractFloat(v) => v as f32,
            other => panic!(
                "`const {name}` of shader `{}` is {other:?}, not a float",
                self.name
            ),
        }
    }

    /// A struct as WGSL lays it out in memory (host-shareable layout rules:
    /// the same rules wgpu's backends use for storage and uniform buffers).
    #[track_caller]
    pub fn struct_layout(&self, name: &str) -> StructLayout {
        let ty = self
            .module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("shader `{}` declares no `struct {name}`", self.name));
        let TypeInner::Struct { members, span } = &ty.1.inner else {
            panic!("`{name}` of shader `{}` is not a struct", self.name);
        };
        StructLayout {
            shader: self.name.clone(),
            name: name.to_owned(),
            size: *span,
            members: members
                .iter()
                .map(|m| MemberLayout {
                    name: m.name.clone().unwrap_or_default(),
                    offset: m.offset,
                    size: self.layouter[m.ty].size,
                })
                .collect(),
        }
    }

    /// wgpu's pipeline-creation checks that need no adapter (see
    /// [`crate::try_validate`]); `Err` names the entry point and the limit.
    pub(crate) fn check_pipeline_limits(&self, limits: &wgpu_types::Limits) -> Result<(), String> {
        for (i, ep) in self.module.entry_points.iter().enumerate() {
            if ep.stage != ShaderStage::Compute {
                continue;
            }
            let [x, y, z] = ep.workgroup_size;
            let max = [
                limits.max_compute_workgroup_size_x,
                limits.max_compute_workgroup_size_y,
                limits.max_compute_workgroup_size_z,
            ];
            if x > max[0] || y > max[1] || z > max[2] {
                return Err(format!(
                    "entry point `{}`: @workgroup_size({x}, {y}, {z}) exceeds the per-dimension \
                     limit {max:?}",
                    ep.name
                ));
            }
            let threads = x * y * z;
            if threads > limits.max_compute_invocations_per_workgroup {
                return Err(format!(
                    "entry point `{}`: {threads} threads per workgroup exceed \
                     max_compute_invocations_per_workgroup = {}",
                    ep.name, limits.max_compute_invocations_per_workgroup
                ));
            }
            let info = self.info.get_entry_point(i);
            let mut shared = 0u32;
            let mut bindings: Vec<(u32, &str)> = Vec::new();
            for (h, var) in self.module.global_variables.iter() {
                if info[h].is_empty() {
                    continue;
                }
                let var_name = var.name.as_deref().unwrap_or("?");
                if var.space == AddressSpace::WorkGroup {
                    shared += self.layouter[var.ty].size;
                }
                let Some(rb) = &var.binding else { continue };
                if rb.group != 0 {
                    return Err(format!(
                        "entry point `{}` uses `{var_name}` in group {}; the host binds \
                         everything in one bind group, group 0",
                        ep.name, rb.group
                    ));
                }
                if let Some((_, other)) = bindings.iter().find(|(b, _)| *b == rb.binding) {
                    return Err(format!(
                        "entry point `{}` uses `{other}` and `{var_name}`, both at binding {}",
                        ep.name, rb.binding
                    ));
                }
                bindings.push((rb.binding, var_name));
            }
            if shared > limits.max_compute_workgroup_storage_size {
                return Err(format!(
                    "entry point `{}` uses {shared} bytes of workgroup memory, above \
                     max_compute_workgroup_storage_size = {}",
                    ep.name, limits.max_compute_workgroup_storage_size
                ));
            }
        }
        Ok(())
    }
}
