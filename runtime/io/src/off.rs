//! Object File Format (OFF, ASCII) triangle surfaces: the cavities of
//! actuators and the test meshes of `shared/data`.
//!
//! Read: the `OFF` keyword (alone on its line, or followed by the counts on
//! the same line), `nv nf ne`, `nv` vertex lines `x y z` (mm, world frame),
//! then `nf` face lines `n i0 … i(n−1)`. Faces with more than three
//! vertices are split into a fan from their first vertex; per-face colours
//! after the indices are ignored; `#` starts a comment. Counts are checked
//! against the file's size before anything is allocated, and every error
//! names the file, the line and what to do.

use crate::error::IoError;
use glam::DVec3;
use std::path::Path;
use voxflex_core::triangle_surface::TriangleSurface;

/// Reads a triangle surface from an ASCII OFF file. Closedness is not
/// checked here (callers that need a closed surface call
/// [`TriangleSurface::check_closed`]).
pub fn read_off(path: &Path) -> Result<TriangleSurface, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_off(path, &text)
}

/// The file's non-empty lines with comments stripped, numbered from 1.
struct Tokens<'a> {
    path: &'a Path,
    lines: Vec<(usize, Vec<&'a str>)>,
    at: usize,
}

impl<'a> Tokens<'a> {
    fn new(path: &'a Path, text: &'a str) -> Self {
        let lines = text
            .lines()
            .enumerate()
            .filter_map(|(i, l)| {
                let words: Vec<&str> = l.split('#').next()?.split_whitespace().collect();
                (!words.is_empty()).then_some((i + 1, words))
            })
            .collect();
        Self { path, lines, at: 0 }
    }

    fn err(&self, line: usize, message: impl Into<String>) -> IoError {
        IoError::Corrupt {
            path: self.path.to_path_buf(),
            message: format!("line {line}: {}", message.into()),
        }
    }

    fn next_line(&mut self, expect: &str) -> Result<(usize, Vec<&'a str>), IoError> {
        let l = self.lines.get(self.at).cloned().ok_or_else(|| {
            let last = self.lines.last().map_or(0, |l| l.0);
            self.err(
                last,
                format!("the file ends where {expect} was expected (truncated?)"),
            )
        })?;
        self.at += 1;
        Ok(l)
    }
}

fn parse<T: std::str::FromStr>(
    t: &Tokens<'_>,
    line: usize,
    v: &str,
    what: &str,
) -> Result<T, IoError> {
    v.parse::<T>()
        .map_err(|_| t.err(line, format!("`{v}` is not a valid {what}")))
}

fn parse_off(path: &Path, text: &str) -> Result<TriangleSurface, IoError> {
    let mut t = Tokens::new(path, text);
    let (line, mut words) = t.next_line("the OFF keyword")?;
    if words.first() != Some(&"OFF") {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "line {line}: starts with `{}`, not `OFF`: not an ASCII OFF file (COFF, NOFF and binary OFF are not read)",
                words.first().unwrap_or(&"")
            ),
        });
    }
    words.remove(0);
    let (line, counts) = if words.is_empty() {
        t.next_line("the counts `nv nf ne`")?
    } else {
        (line, words)
    };
    if counts.len() < 2 {
        return Err(t.err(
            line,
            "the counts line needs `nv nf ne` (vertices, faces, edges)",
        ));
    }
    let bytes = text.len();
    let nv: usize = parse(&t, line, counts[0], "vertex count")?;
    let nf: usize = parse(&t, line, counts[1], "face count")?;
    // A vertex line takes at least 6 bytes, a face line at least 8.
    if nv.saturating_mul(6).saturating_add(nf.saturating_mul(8)) > bytes {
        return Err(t.err(
            line,
            format!(
                "{nv} vertices and {nf} faces cannot fit in a {bytes}-byte file (corrupt header)"
            ),
        ));
    }
    let vertices = (0..nv)
        .map(|_| read_vertex(&mut t))
        .collect::<Result<Vec<_>, _>>()?;
    let mut triangles = Vec::with_capacity(nf);
    for _ in 0..nf {
        read_face(&mut t, nv, &mut triangles)?;
    }
    Ok(TriangleSurface::new(
        &path.display().to_string(),
        vertices,
        triangles,
    )?)
}

fn read_vertex(t: &mut Tokens<'_>) -> Result<DVec3, IoError> {
    let (line, w) = t.next_line("a vertex line `x y z`")?;
    if w.len() < 3 {
        return Err(t.err(line, "a vertex line needs three coordinates `x y z` (mm)"));
    }
    let c: [f64; 3] = [
        parse(t, line, w[0], "coordinate")?,
        parse(t, line, w[1], "coordinate")?,
        parse(t, line, w[2], "coordinate")?,
    ];
    Ok(DVec3::from_array(c))
}

fn read_face(t: &mut Tokens<'_>, nv: usize, out: &mut Vec<[u32; 3]>) -> Result<(), IoError> {
    let (line, w) = t.next_line("a face line `n i0 i1 …`")?;
    let n: usize = parse(t, line, w[0], "face vertex count")?;
    if n < 3 || w.len() < n + 1 {
        return Err(t.err(
            line,
            format!(
                "a face needs at least 3 vertex indices after its count (count {n}, {} given)",
                w.len() - 1
            ),
        ));
    }
    let idx = w[1..=n]
        .iter()
        .map(|v| {
            let i: usize = parse(t, line, v, "vertex index")?;
            if i >= nv {
                return Err(t.err(
                    line,
                    format!("vertex index {i}, but the file has {nv} vertices"),
                ));
            }
            Ok(i as u32)
        })
        .collect::<Result<Vec<u32>, IoError>>()?;
    out.extend((1..n - 1).map(|k| [idx[0], idx[k], idx[k + 1]]));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<TriangleSurface, IoError> {
        parse_off(Path::new("t.off"), text)
    }

    const TETRA: &str = "OFF\n# a tetrahedron\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";

    #[test]
    fn a_closed_tetrahedron_reads_with_its_volume() {
        let s = parse_str(TETRA).unwrap();
        assert_eq!((s.vertices.len(), s.triangles.len()), (4, 4));
        s.check_closed("t").unwrap();
        assert!((s.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn counts_on_the_keyword_line_and_quads_are_read() {
        let s = parse_str("OFF 4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 255 0 0\n").unwrap();
        assert_eq!(s.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn damaged_files_name_the_line_and_the_fix() {
        let cases = [
            ("PLY\n", "not `OFF`"),
            (
                "OFF\n2 1\n0 0 0\n# a comment long enough to pass the size check\n",
                "truncated",
            ),
            ("OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "line 4"),
            (
                "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
                "vertex index 7",
            ),
            ("OFF\n99999999 99999999 0\n", "cannot fit"),
            ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "at least 3"),
        ];
        for (text, want) in cases {
            let e = parse_str(text).unwrap_err().to_string();
            assert!(e.contains("t.off") && e.contains(want), "{text:?}: {e}");
        }
    }

    #[test]
    fn the_shared_icosphere_encloses_its_documented_volume() {
        let Some(dir) = voxflex_core::test_data::dir() else {
            return;
        };
        let s = read_off(&dir.join("sphere_ico4_5120.off")).unwrap();
        assert_eq!((s.vertices.len(), s.triangles.len()), (2562, 5120));
        s.check_closed("ico4").unwrap();
        assert!(
            (s.signed_volume() - 4179.74).abs() < 0.01,
            "{}",
            s.signed_volume()
        );
    }
}
