//! Gmsh MSH 4.1 ASCII tetrahedral meshes, so users can bring their own
//! proxy (`gmsh -3 -format msh41 model.geo`).
//!
//! Read: `$MeshFormat` (4.x, ASCII only), `$Nodes` (entity blocks, sparse
//! tags, parametric coordinates skipped) and `$Elements`, of which the
//! 4-node tetrahedra (type 4) are kept and labelled with their volume
//! entity's tag; every other section and element type is skipped.
//! Coordinates are millimetres in the world frame. Counts are checked
//! against the file's size before anything is allocated, and every error
//! names the file, the line and what to do.

use crate::error::IoError;
use crate::tet_mesh::TetMesh;
use glam::DVec3;
use std::collections::HashMap;
use std::path::Path;

/// Gmsh's element type of the 4-node tetrahedron.
const TETRAHEDRON: u32 = 4;
/// Nodes of each Gmsh element type this reader can skip (types 1–15).
const NODES_PER_TYPE: [usize; 16] = [0, 2, 3, 4, 4, 8, 6, 5, 3, 6, 9, 10, 27, 18, 14, 1];

/// Reads a tetrahedral mesh from a Gmsh MSH 4.1 ASCII file.
pub fn read_msh(path: &Path) -> Result<TetMesh, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_msh(path, &text)
}

/// Line-by-line reader that names the line of every error.
struct Lines<'a> {
    path: &'a Path,
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    line: usize,
    /// Bytes in the file: no count may ask for more items than that.
    bytes: usize,
}

impl<'a> Lines<'a> {
    fn err(&self, message: impl Into<String>) -> IoError {
        IoError::Corrupt {
            path: self.path.to_path_buf(),
            message: format!("line {}: {}", self.line, message.into()),
        }
    }

    fn next(&mut self, expect: &str) -> Result<&'a str, IoError> {
        match self.lines.next() {
            Some((i, l)) => {
                self.line = i + 1;
                Ok(l.trim())
            }
            None => Err(self.err(format!(
                "the file ends where {expect} was expected (truncated?)"
            ))),
        }
    }

    /// The next line's whitespace-separated numbers.
    fn numbers<T: std::str::FromStr>(&mut self, expect: &str) -> Result<Vec<T>, IoError> {
        let l = self.next(expect)?;
        l.split_whitespace()
            .map(|v| {
                v.parse::<T>()
                    .map_err(|_| self.err(format!("`{v}` is not a valid number in {expect}")))
            })
            .collect()
    }

    fn count(&self, n: u64, what: &str) -> Result<usize, IoError> {
        if n as usize > self.bytes {
            return Err(self.err(format!(
                "{n} {what} cannot fit in a {}-byte file (corrupt header)",
                self.bytes
            )));
        }
        Ok(n as usize)
    }
}

fn parse_msh(path: &Path, text: &str) -> Result<TetMesh, IoError> {
    let mut r = Lines {
        path,
        lines: text.lines().enumerate(),
        line: 0,
        bytes: text.len(),
    };
    let mut nodes: Option<(Vec<DVec3>, HashMap<u64, u32>)> = None;
    let mut tets = Vec::new();
    let mut labels = Vec::new();
    let mut format_seen = false;
    while let Some((i, l)) = r.lines.next() {
        r.line = i + 1;
        match l.trim() {
            "$MeshFormat" => {
                let f: Vec<String> = r.numbers("the format line")?;
                let version = f.first().and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
                if !(4.0..5.0).contains(&version) {
                    return Err(IoError::Unsupported {
                        path: path.to_path_buf(),
                        message: format!(
                            "MSH version {} is not read; save as MSH 4.1 ASCII (gmsh -format msh41)",
                            f.first().map_or("?", |s| s.as_str())
                        ),
                    });
                }
                if f.get(1).map(|s| s.as_str()) != Some("0") {
                    return Err(IoError::Unsupported {
                        path: path.to_path_buf(),
                        message: "binary MSH is not read; save as ASCII (gmsh -format msh41, Mesh.Binary = 0)".into(),
                    });
                }
                format_seen = true;
            }
            "$Nodes" => nodes = Some(read_nodes(&mut r)?),
            "$Elements" => {
                let (_, index) = nodes
                    .as_ref()
                    .ok_or_else(|| r.err("$Elements comes before $Nodes"))?;
                read_elements(&mut r, index, &mut tets, &mut labels)?;
            }
            _ => {}
        }
    }
    if !format_seen {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: "no $MeshFormat section: not a Gmsh MSH file".into(),
        });
    }
    let (nodes, _) = nodes.ok_or_else(|| IoError::Corrupt {
        path: path.to_path_buf(),
        message: "no $Nodes section".into(),
    })?;
    Ok(TetMesh::new(
        &path.display().to_string(),
        nodes,
        tets,
        labels,
    )?)
}

fn read_nodes(r: &mut Lines<'_>) -> Result<(Vec<DVec3>, HashMap<u64, u32>), IoError> {
    let head: Vec<u64> = r.numbers("the $Nodes header")?;
    let [blocks, total, ..] = head[..] else {
        return Err(r.err("the $Nodes header needs numEntityBlocks numNodes minTag maxTag"));
    };
    let (blocks, total) = (r.count(blocks, "node blocks")?, r.count(total, "nodes")?);
    let mut nodes = Vec::with_capacity(total);
    let mut index = HashMap::with_capacity(total);
    for _ in 0..blocks {
        let b: Vec<u64> = r.numbers("a node block header")?;
        let [_dim, _entity, _parametric, n] = b[..] else {
            return Err(r.err("a node block header needs entityDim entityTag parametric numNodes"));
        };
        let n = r.count(n, "nodes")?;
        let mut tags = Vec::with_capacity(n);
        for _ in 0..n {
            let t: Vec<u64> = r.numbers("a node tag")?;
            tags.push(*t.first().ok_or_else(|| r.err("a node tag line is empty"))?);
        }
        for tag in tags {
            // Parametric coordinates, if any, follow x y z on the line.
            let c: Vec<f64> = r.numbers("node coordinates")?;
            if c.len() < 3 {
                return Err(r.err(format!("node {tag} has {} coordinates, 3 needed", c.len())));
            }
            if index.insert(tag, nodes.len() as u32).is_some() {
                return Err(r.err(format!("node tag {tag} appears twice")));
            }
            nodes.push(DVec3::new(c[0], c[1], c[2]));
        }
    }
    if nodes.len() != total {
        return Err(r.err(format!(
            "$Nodes announced {total} nodes but holds {}",
            nodes.len()
        )));
    }
    if r.next("$EndNodes")? != "$EndNodes" {
        return Err(r.err("expected $EndNodes"));
    }
    Ok((nodes, index))
}

fn read_elements(
    r: &mut Lines<'_>,
    index: &HashMap<u64, u32>,
    tets: &mut Vec<[u32; 4]>,
    labels: &mut Vec<u16>,
) -> Result<(), IoError> {
    let head: Vec<u64> = r.numbers("the $Elements header")?;
    let [blocks, ..] = head[..] else {
        return Err(r.err("the $Elements header needs numEntityBlocks numElements minTag maxTag"));
    };
    for _ in 0..r.count(blocks, "element blocks")? {
        let b: Vec<u64> = r.numbers("an element block header")?;
        let [_dim, entity, kind, n] = b[..] else {
            return Err(
                r.err("an element block header needs entityDim entityTag elementType numElements")
            );
        };
        let n = r.count(n, "elements")?;
        let per = *NODES_PER_TYPE
            .get(kind as usize)
            .filter(|&&p| p > 0)
            .ok_or_else(|| r.err(format!("element type {kind} is not known to this reader")))?;
        for _ in 0..n {
            let e: Vec<u64> = r.numbers("an element")?;
            if e.len() != per + 1 {
                return Err(r.err(format!(
                    "an element of type {kind} needs a tag and {per} nodes, the line has {} values",
                    e.len()
                )));
            }
            if kind as u32 != TETRAHEDRON {
                continue;
            }
            let mut tet = [0u32; 4];
            for (k, tag) in e[1..].iter().enumerate() {
                tet[k] = *index.get(tag).ok_or_else(|| {
                    r.err(format!(
                        "element {} names node {tag}, which $Nodes lacks",
                        e[0]
                    ))
                })?;
            }
            let label = u16::try_from(entity)
                .map_err(|_| r.err(format!("volume entity tag {entity} is above 65535")))?;
            tets.push(tet);
            labels.push(label);
        }
    }
    if r.next("$EndElements")? != "$EndElements" {
        return Err(r.err("expected $EndElements"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's corner tetrahedron and its neighbour, in two volume
    /// entities, with a triangle element and sparse node tags.
    const GOOD: &str = "$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
1
3 1 \"tissue\"
$EndPhysicalNames
$Nodes
2 5 1 50
0 1 0 1
10
0 0 0
3 2 0 4
20
30
40
50
1 0 0
0 1 0
0 0 1
1 1 1
$EndNodes
$Elements
3 4 1 4
2 5 2 1
1 20 30 40
3 7 4 2
2 10 20 30 40
3 20 30 40 50
3 9 4 1
4 10 20 30 50
$EndElements
";

    fn parse(text: &str) -> Result<TetMesh, IoError> {
        parse_msh(Path::new("model.msh"), text)
    }

    #[test]
    fn reads_tetrahedra_with_their_entity_labels() {
        let m = parse(GOOD).unwrap();
        assert_eq!(m.nodes.len(), 5);
        assert_eq!(m.tets.len(), 3);
        assert_eq!(m.labels, vec![7, 7, 9]);
        assert!((0..3).all(|t| m.volume(t) > 0.0));
        assert_eq!(m.nodes[4], DVec3::ONE);
    }

    #[test]
    fn hostile_files_get_one_clear_error() {
        let cases: Vec<(String, &str)> = vec![
            (GOOD.replace("4.1 0 8", "2.2 0 8"), "save as MSH 4.1 ASCII"),
            (GOOD.replace("4.1 0 8", "4.1 1 8"), "binary MSH is not read"),
            (
                GOOD[..GOOD.find("3 9 4 1").unwrap()].to_string(),
                "truncated",
            ),
            (
                GOOD.replace("2 10 20 30 40", "2 10 20 30 41"),
                "names node 41, which $Nodes lacks",
            ),
            (GOOD.replace("0 0 1\n", "0 nan 1\n"), "non-finite"),
            (GOOD.replace("2 5 1 50", "2 99999999999 1 50"), "cannot fit"),
            (
                GOOD.replace("1 1 1\n", "1 1 x\n"),
                "`x` is not a valid number",
            ),
            (
                GOOD.replace("4 10 20 30 50", "4 10 20 30"),
                "needs a tag and 4 nodes",
            ),
            ("hello\n".to_string(), "not a Gmsh MSH file"),
            (GOOD.replace("4 10 20 30 50", "4 10 20 30 10"), "degenerate"),
        ];
        for (text, want) in cases {
            let e = parse(&text).unwrap_err().to_string();
            assert!(e.contains("model.msh") && e.contains(want), "{want}: {e}");
        }
    }
}
