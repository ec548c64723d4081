//! The parameter schema every plugin declares: the JSON Schema (draft
//! 2020-12, as `schemars` writes it) of the TOML table its `create` reads —
//! `[model.params]` for a deformation model, `[render.params]` for a
//! renderer. The host reads it once at load (`voxflex plugins --params
//! NAME` prints it, `voxflex validate` checks a scene's table against it,
//! the viewer builds its parameter form from it).
//!
//! A plugin derives the schema from the very `serde` types its `create`
//! deserialises (`#[derive(schemars::JsonSchema)]`), so keys, types and
//! defaults cannot drift from what it accepts; units ride on each property
//! as `"unit"` and ranges as `minimum` / `maximum`.

use crate::ffi::ErrorBuf;
use crate::guard::guard;
use crate::host_side::checked_call;
use voxflex_core::error::ModelError;

/// The most bytes of schema text the host reads from a plugin.
pub const HOST_CAPACITY: usize = 256 * 1024;

/// What every plugin kind declares besides its vtable.
pub trait DeclaresParams {
    /// The JSON Schema text of the plugin's parameter table (see the
    /// module docs); typically `json(&schemars::schema_for!(MyParams))`.
    fn params_schema() -> Result<String, String>;
}

/// The JSON text of a schema (a `schemars::Schema`, or any serialisable
/// value).
pub fn json(schema: &impl serde::Serialize) -> Result<String, String> {
    serde_json::to_string(schema).map_err(|e| format!("the parameter schema: {e}"))
}

/// The declaration's `params_schema` entry for plugin type `P` (used by
/// the export macros).
///
/// # Safety
/// `out` and `err` are null or valid buffers for the call.
pub unsafe extern "C" fn entry<P: DeclaresParams>(out: *mut ErrorBuf, err: *mut ErrorBuf) -> i32 {
    guard(err, || {
        let text = P::params_schema()?;
        // SAFETY: host contract: `out` is null or the host's buffer of `cap` bytes.
        unsafe { ErrorBuf::write_whole(out, &text, "the parameter schema") }
    })
}

/// The host side: calls a declaration's `params_schema` entry and returns
/// its text; errors name the plugin.
///
/// # Safety
/// `f` is the entry of a loaded, checked plugin that is never unloaded.
pub unsafe fn read(
    name: &str,
    f: unsafe extern "C" fn(*mut ErrorBuf, *mut ErrorBuf) -> i32,
) -> Result<String, ModelError> {
    let mut storage = vec![0u8; HOST_CAPACITY];
    let mut out = ErrorBuf {
        ptr: storage.as_mut_ptr(),
        cap: storage.len(),
        len: 0,
    };
    // SAFETY: `out` points at `storage`, alive during the call.
    checked_call(name, |err| unsafe { f(&mut out, err) })?;
    storage.truncate(out.len.min(storage.len()));
    String::from_utf8(storage).map_err(|_| {
        ModelError(format!(
            "plugin '{name}': its parameter schema is not UTF-8"
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Small;
    impl DeclaresParams for Small {
        fn params_schema() -> Result<String, String> {
            json(&serde_json::json!({"type": "object"}))
        }
    }

    struct Huge;
    impl DeclaresParams for Huge {
        fn params_schema() -> Result<String, String> {
            Ok("x".repeat(HOST_CAPACITY + 1))
        }
    }

    struct Panics;
    impl DeclaresParams for Panics {
        fn params_schema() -> Result<String, String> {
            panic!("no schema")
        }
    }

    #[test]
    fn the_host_reads_the_text_and_refuses_what_does_not_fit_or_panics() {
        // SAFETY: the entries are this crate's own functions.
        unsafe {
            assert_eq!(
                read("small", entry::<Small>).unwrap(),
                r#"{"type":"object"}"#
            );
            let e = read("huge", entry::<Huge>).unwrap_err().to_string();
            assert!(
                e.contains("huge") && e.contains("more than the host's"),
                "{e}"
            );
            let e = read("panics", entry::<Panics>).unwrap_err().to_string();
            assert!(e.contains("no schema"), "{e}");
        }
    }
}
