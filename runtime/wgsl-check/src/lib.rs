//! Test-only checks of voxflex's WGSL shaders that need no GPU adapter.
//!
//! wgpu compiles every shader with naga: it parses the WGSL, validates the
//! module with naga's [`naga::valid::Validator`] under the capabilities the
//! device grants, and checks the entry point against the device limits when
//! the pipeline is created. [`validate`] runs the same parser and validator
//! (naga 30.0.1, the version wgpu 30.0.1 uses) with the capabilities wgpu
//! derives from the host's device request (see [`capabilities`]), plus the
//! pipeline-creation checks that need no adapter, so a typo in a shader —
//! or in the Rust code that assembles one with `format!` — fails a plain
//! `cargo test` on any machine.
//!
//! The validated [`Shader`] then answers what Rust-side tests compare with
//! their own constants: a `const`'s value ([`Shader::const_u32`]), an entry
//! point's `@workgroup_size` ([`Shader::workgroup_size`]) and a struct's
//! size and member offsets as the WGSL layout rules place them
//! ([`Shader::struct_layout`], [`assert_struct_layout!`]).
//!
//! [`ShaderSet`] collects what one crate's test validated and
//! [`ShaderSet::finish`] checks it against [`SHADER_OWNERS`], the one table
//! naming which crate ships each file under `shaders/`; the guard test of
//! this crate fails when a `.wgsl` file is missing from that table.

mod coverage;
mod layout;
mod shader;
mod validate;

pub use coverage::{SHADER_OWNERS, ShaderSet, shader_files, shaders_dir, uncovered_files};
#[doc(hidden)]
pub use layout::field_size as __field_size;
pub use layout::{MemberLayout, StructLayout};
pub use shader::Shader;
pub use validate::{ShaderError, capabilities, try_validate, validate};
