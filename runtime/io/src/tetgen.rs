//! TetGen `.node` / `.ele` tetrahedral meshes (`tetgen -pq model.poly`
//! writes `model.1.node` and `model.1.ele`).
//!
//! `.node`: `count 3 attributes markers`, then `index x y z [attributes]
//! [marker]` per point (mm, world frame). `.ele`: `count 4|10 regions`,
//! then `index n0 n1 n2 n3 [6 more for quadratic] [region]`; the first four
//! nodes make the (linear) tetrahedron and the region attribute, when
//! present, its label. Indices start at 0 or 1, as the first point says.
//! `#` starts a comment. Counts are checked against the files' sizes
//! before anything is allocated, and every error names the file and line.

use crate::error::IoError;
use crate::tet_mesh::TetMesh;
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Reads `<base>.node` and `<base>.ele`; `path` may name either file.
pub fn read_tetgen(path: &Path) -> Result<TetMesh, IoError> {
    // `model.1.ele` → `model.1` (only the last extension goes).
    let base = path.with_extension("").into_os_string();
    let with = |ext: &str| {
        let mut p = base.clone();
        p.push(ext);
        PathBuf::from(p)
    };
    let (node_path, ele_path) = (with(".node"), with(".ele"));
    let read = |p: &PathBuf| {
        std::fs::read_to_string(p).map_err(|source| IoError::Io {
            path: p.clone(),
            source,
        })
    };
    parse_tetgen(&node_path, &read(&node_path)?, &ele_path, &read(&ele_path)?)
}

/// The non-empty, comment-free lines of a file with their line numbers.
fn records(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let l = l.split('#').next().unwrap_or("");
        let f: Vec<&str> = l.split_whitespace().collect();
        (!f.is_empty()).then_some((i + 1, f))
    })
}

fn corrupt(path: &Path, line: usize, message: impl std::fmt::Display) -> IoError {
    IoError::Corrupt {
        path: path.to_path_buf(),
        message: format!("line {line}: {message}"),
    }
}

fn number<T: std::str::FromStr>(path: &Path, line: usize, v: &str) -> Result<T, IoError> {
    v.parse()
        .map_err(|_| corrupt(path, line, format!("`{v}` is not a valid number")))
}

fn parse_tetgen(
    node_path: &Path,
    nodes_text: &str,
    ele_path: &Path,
    ele_text: &str,
) -> Result<TetMesh, IoError> {
    // Nodes.
    let mut lines = records(nodes_text);
    let (line, head) = lines.next().ok_or_else(|| {
        corrupt(
            node_path,
            1,
            "the file is empty; expected `count 3 attributes markers`",
        )
    })?;
    let count: usize = number(node_path, line, head[0])?;
    if head.get(1).is_some_and(|d| *d != "3") {
        return Err(corrupt(
            node_path,
            line,
            "only 3-D meshes are read (dimension must be 3)",
        ));
    }
    if count > nodes_text.len() {
        return Err(corrupt(
            node_path,
            line,
            format!(
                "{count} points cannot fit in a {}-byte file",
                nodes_text.len()
            ),
        ));
    }
    let mut nodes = Vec::with_capacity(count);
    let mut first_index = None;
    for _ in 0..count {
        let (line, f) = lines.next().ok_or_else(|| {
            corrupt(
                node_path,
                nodes_text.lines().count(),
                format!(
                    "the file ends before point {} of {count} (truncated?)",
                    nodes.len()
                ),
            )
        })?;
        if f.len() < 4 {
            return Err(corrupt(node_path, line, "a point needs `index x y z`"));
        }
        let index: usize = number(node_path, line, f[0])?;
        let base = *first_index.get_or_insert(index);
        if index != base + nodes.len() {
            return Err(corrupt(
                node_path,
                line,
                format!(
                    "point {index} is out of order (expected {})",
                    base + nodes.len()
                ),
            ));
        }
        let c: [f64; 3] = [
            number(node_path, line, f[1])?,
            number(node_path, line, f[2])?,
            number(node_path, line, f[3])?,
        ];
        if c.iter().any(|v| !v.is_finite()) {
            return Err(corrupt(
                node_path,
                line,
                format!("point {index} has a non-finite coordinate {c:?} (mm); fix or remove it"),
            ));
        }
        nodes.push(DVec3::from_array(c));
    }
    let base = first_index.unwrap_or(0);
    // Tetrahedra.
    let mut lines = records(ele_text);
    let (line, head) = lines
        .next()
        .ok_or_else(|| corrupt(ele_path, 1, "the file is empty; expected `count 4 regions`"))?;
    let count: usize = number(ele_path, line, head[0])?;
    let per: usize = head.get(1).map_or(Ok(4), |v| number(ele_path, line, v))?;
    if per != 4 && per != 10 {
        return Err(corrupt(
            ele_path,
            line,
            format!("{per} nodes per tetrahedron: only 4 or 10 are read"),
        ));
    }
    let regions = head.get(2).is_some_and(|v| *v != "0");
    if count > ele_text.len() {
        return Err(corrupt(
            ele_path,
            line,
            format!(
                "{count} tetrahedra cannot fit in a {}-byte file",
                ele_text.len()
            ),
        ));
    }
    let mut tets = Vec::with_capacity(count);
    let mut labels = Vec::with_capacity(count);
    for _ in 0..count {
        let (line, f) = lines.next().ok_or_else(|| {
            corrupt(
                ele_path,
                ele_text.lines().count(),
                format!(
                    "the file ends before tetrahedron {} of {count} (truncated?)",
                    tets.len()
                ),
            )
        })?;
        if f.len() < 1 + per + usize::from(regions) {
            return Err(corrupt(
                ele_path,
                line,
                format!("a tetrahedron needs an index and {per} nodes"),
            ));
        }
        let mut tet = [0u32; 4];
        for k in 0..4 {
            let n: usize = number(ele_path, line, f[1 + k])?;
            tet[k] = n
                .checked_sub(base)
                .filter(|&n| n < nodes.len())
                .ok_or_else(|| {
                    corrupt(
                        ele_path,
                        line,
                        format!("node {n} is not in {}", node_path.display()),
                    )
                })? as u32;
        }
        let label = if regions {
            let r: f64 = number(ele_path, line, f[1 + per])?;
            if !(0.0..=65535.0).contains(&r) || r.fract() != 0.0 {
                return Err(corrupt(
                    ele_path,
                    line,
                    format!("region {r} is not a label in 0..=65535"),
                ));
            }
            r as u16
        } else {
            0
        };
        tets.push(tet);
        labels.push(label);
    }
    Ok(TetMesh::new(
        &ele_path.display().to_string(),
        nodes,
        tets,
        labels,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NODE: &str =
        "# a cube corner and its neighbour\n5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n";
    const ELE: &str = "2 4 1\n1 1 2 3 4 7\n2 2 3 4 5 9\n";

    fn parse(node: &str, ele: &str) -> Result<TetMesh, IoError> {
        parse_tetgen(Path::new("m.1.node"), node, Path::new("m.1.ele"), ele)
    }

    #[test]
    fn reads_one_based_meshes_with_region_labels() {
        let m = parse(NODE, ELE).unwrap();
        assert_eq!(m.nodes.len(), 5);
        assert_eq!(m.labels, vec![7, 9]);
        assert!((0..2).all(|t| m.volume(t) > 0.0));
        // Zero-based, no regions.
        let m = parse(
            &NODE
                .replace("\n1 0 0 0\n2 1", "\n0 0 0 0\n1 1")
                .replace("\n3 0 1 0\n4 0 0 1\n5 1", "\n2 0 1 0\n3 0 0 1\n4 1"),
            "1 4 0\n0 0 1 2 3\n",
        )
        .unwrap();
        assert_eq!(m.labels, vec![0]);
    }

    #[test]
    fn hostile_files_get_one_clear_error() {
        let cases: Vec<(String, String, &str)> = vec![
            (
                NODE.to_string(),
                ELE.replace("1 1 2 3 4 7", "1 1 2 3 8 7"),
                "node 8 is not in m.1.node",
            ),
            (
                NODE.replace("5 3 0 0", "5 2 0 0"),
                ELE.to_string(),
                "only 3-D",
            ),
            (
                NODE.replace("\n5 1 1 1\n", "\n"),
                ELE.to_string(),
                "truncated",
            ),
            (
                NODE.replace("4 0 0 1", "4 0 0 z"),
                ELE.to_string(),
                "`z` is not a valid number",
            ),
            (
                NODE.replace("4 0 0 1", "4 0 0 nan"),
                ELE.to_string(),
                "non-finite",
            ),
            (
                NODE.to_string(),
                ELE.replace("2 4 1", "999999 4 1"),
                "cannot fit",
            ),
            (
                NODE.to_string(),
                ELE.replace("2 4 1", "2 8 1"),
                "only 4 or 10",
            ),
            (
                NODE.to_string(),
                ELE.replace(" 9\n", " 70000\n"),
                "not a label",
            ),
            (
                NODE.to_string(),
                ELE.replace("2 2 3 4 5 9", "2 2 3 4 2 9"),
                "degenerate",
            ),
        ];
        for (node, ele, want) in cases {
            let e = parse(&node, &ele).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("m.1."), "{want}: {e}");
        }
        let e = read_tetgen(Path::new("/nonexistent/m.1.ele"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/m.1.node"), "{e}");
    }
}
