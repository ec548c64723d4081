//! Struct layouts read from WGSL, compared with `#[repr(C)]` Rust structs.

use std::fmt::Write as _;

/// One member of a WGSL struct: name, byte offset and byte size.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MemberLayout {
    /// Member name in the WGSL source.
    pub name: String,
    /// Byte offset from the start of the struct.
    pub offset: u32,
    /// Byte size of the member's type (without trailing padding).
    pub size: u32,
}

/// A WGSL struct's memory layout as naga computes it (WGSL alignment rules).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StructLayout {
    /// The shader it was read from.
    pub shader: String,
    /// The struct's name.
    pub name: String,
    /// Byte size of the struct (its span, trailing padding included).
    pub size: u32,
    /// Members in declaration order.
    pub members: Vec<MemberLayout>,
}

impl StructLayout {
    /// The member called `name`; panics naming the struct and shader when
    /// there is none.
    #[track_caller]
    pub fn member(&self, name: &str) -> &MemberLayout {
        self.members
            .iter()
            .find(|m| m.name == name)
            .unwrap_or_else(|| {
                panic!(
                    "`struct {}` of shader `{}` has no member `{name}`",
                    self.name, self.shader
                )
            })
    }

    /// Compares with a Rust struct given as its name, `size_of` and, per
    /// field in declaration order, `(Rust field name, WGSL member name,
    /// offset_of, size_of)`:
    /// `Err` lists every difference. The layouts agree when the sizes are
    /// equal and each field sits at its member's offset, under the same
    /// name, at least as large as the member (a Rust `[f32; 4]` may back a
    /// WGSL `vec3<f32>` and its padding).
    pub fn compare_with_rust(
        &self,
        rust_name: &str,
        rust_size: usize,
        rust_fields: &[(&str, &str, usize, usize)],
    ) -> Result<(), String> {
        let mut problems = String::new();
        if rust_size != self.size as usize {
            let _ = writeln!(
                problems,
                "  size: Rust {rust_size} bytes, WGSL {} bytes",
                self.size
            );
        }
        if rust_fields.len() != self.members.len() {
            let _ = writeln!(
                problems,
                "  fields: Rust {}, WGSL {} members",
                rust_fields.len(),
                self.members.len()
            );
        }
        for (i, (r, w)) in rust_fields.iter().zip(&self.members).enumerate() {
            let (field, name, offset, size) = *r;
            if name != w.name || offset != w.offset as usize || size < w.size as usize {
                let _ = writeln!(
                    problems,
                    "  field {i}: Rust `{field}` (for `{name}`) at {offset} ({size} bytes), WGSL `{}` at {} ({} bytes)",
                    w.name, w.offset, w.size
                );
            }
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(format!(
                "Rust `{rust_name}` does not match `struct {}` of shader `{}`:\n{problems}",
                self.name, self.shader
            ))
        }
    }
}

/// Byte size of a field, from an accessor closure (used by
/// [`assert_struct_layout!`]).
#[doc(hidden)]
pub fn field_size<T, F>(_field: fn(&T) -> &F) -> usize {
    size_of::<F>()
}

/// Asserts that a `#[repr(C)]` Rust struct has the memory layout of a WGSL
/// struct: same size, each field at its member's offset and under its name
/// (`field as "wgsl_name"` when the names differ).
///
/// ```ignore
/// let shader = voxflex_wgsl_check::validate("common.wgsl", SOURCE);
/// voxflex_wgsl_check::assert_struct_layout!(shader, "Params", Params { vdim, cdim, inv });
/// ```
#[macro_export]
macro_rules! assert_struct_layout {
    ($shader:expr, $wgsl:expr, $ty:ty { $($field:ident $(as $wname:literal)?),* $(,)? }) => {{
        let fields: &[(&str, &str, usize, usize)] = &[$((
            stringify!($field),
            { #[allow(unused_variables)] let n = stringify!($field); $(let n = $wname;)? n },
            ::core::mem::offset_of!($ty, $field),
            $crate::__field_size::<$ty, _>(|s| &s.$field),
        )),*];
        if let Err(e) = $shader
            .struct_layout($wgsl)
            .compare_with_rust(stringify!($ty), ::core::mem::size_of::<$ty>(), fields)
        {
            panic!("{e}");
        }
    }};
}

#[cfg(test)]
mod tests {
    #[repr(C)]
    struct Params {
        n: u32,
        scale: f32,
        pad: [u32; 2],
        origin: [f32; 4],
    }

    #[repr(C)]
    struct Shifted {
        n: u32,
        pad: [u32; 2],
        scale: f32,
        origin: [f32; 4],
    }

    const SRC: &str = "
struct Params { n: u32, scale: f32, pad: vec2<u32>, origin: vec3<f32>, }
@group(0) @binding(0) var<storage, read_write> p: Params;
@compute @workgroup_size(1) fn main() { p.n = 1u; }
";

    #[test]
    fn naga_places_members_by_wgsl_rules() {
        let l = crate::validate("layout", SRC).struct_layout("Params");
        let got: Vec<(&str, u32, u32)> = l
            .members
            .iter()
            .map(|m| (m.name.as_str(), m.offset, m.size))
            .collect();
        assert_eq!(
            got,
            [
                ("n", 0, 4),
                ("scale", 4, 4),
                ("pad", 8, 8),
                ("origin", 16, 12)
            ]
        );
        assert_eq!(l.size, 32, "vec3<f32> aligns the struct to 16");
    }

    #[test]
    fn a_matching_rust_struct_passes() {
        let s = crate::validate("layout", SRC);
        crate::assert_struct_layout!(
            s,
            "Params",
            Params {
                n,
                scale,
                pad,
                origin
            }
        );
    }

    #[test]
    #[should_panic(expected = "field 1: Rust `pad` (for `pad`) at 4 (8 bytes), WGSL `scale` at 4")]
    fn a_reordered_rust_struct_fails() {
        let s = crate::validate("layout", SRC);
        crate::assert_struct_layout!(
            s,
            "Params",
            Shifted {
                n,
                pad,
                scale,
                origin
            }
        );
    }

    #[test]
    #[should_panic(
        expected = "field 2: Rust `scale` (for `pad`) at 12 (4 bytes), WGSL `pad` at 8 (8 bytes)"
    )]
    fn renamed_fields_are_still_checked_by_offset() {
        let s = crate::validate("layout", SRC);
        crate::assert_struct_layout!(s, "Params", Shifted { n, pad as "scale", scale as "pad", origin });
    }

    #[test]
    #[should_panic(expected = "size: Rust 48 bytes, WGSL 32 bytes")]
    fn a_larger_rust_struct_fails() {
        #[repr(C)]
        struct Longer {
            n: u32,
            scale: f32,
            pad: [u32; 2],
            origin: [f32; 8],
        }
        let s = crate::validate("layout", SRC);
        crate::assert_struct_layout!(
            s,
            "Params",
            Longer {
                n,
                scale,
                pad,
                origin
            }
        );
    }
}
