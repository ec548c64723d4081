//! Closed triangle surfaces from the mesh files CAD tools and slicers
//! write — Wavefront OBJ (`tobj`) and STL, ASCII or binary (`stl_io`,
//! which welds the vertices STL repeats per facet) — beside OFF
//! ([`crate::off`]), chosen by extension. Units: the file's numbers as
//! world millimetres. Polygons are triangulated (a fan), every object of
//! an OBJ file goes into the one surface, and every error names the file.

use crate::error::IoError;
use crate::off::read_off;
use glam::DVec3;
use std::path::Path;
use voxflex_core::triangle_surface::TriangleSurface;

/// Reads a triangle surface from an `.off`, `.obj` or `.stl` file.
/// Closedness is not checked here (see [`TriangleSurface::check_closed`]).
pub fn read_surface(path: &Path) -> Result<TriangleSurface, IoError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "off" => read_off(path),
        "obj" => read_obj(path),
        "stl" => read_stl(path),
        _ => Err(IoError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "`.{ext}` is not a surface mesh format voxflex reads; give an .off, .obj or .stl file"
            ),
        }),
    }
}

fn corrupt(path: &Path, message: String) -> IoError {
    IoError::Corrupt {
        path: path.to_path_buf(),
        message,
    }
}

/// The surface of every object in an OBJ file.
fn read_obj(path: &Path) -> Result<TriangleSurface, IoError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(path, &options)
        .map_err(|e| corrupt(path, format!("not a readable OBJ file: {e}")))?;
    let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
    for m in &models {
        let base = vertices.len() as u32;
        vertices.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| DVec3::new(p[0], p[1], p[2])),
        );
        triangles.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|t| [base + t[0], base + t[1], base + t[2]]),
        );
    }
    surface(path, vertices, triangles)
}

/// The surface of an STL file, its repeated vertices welded.
fn read_stl(path: &Path) -> Result<TriangleSurface, IoError> {
    let mut file = std::fs::File::open(path).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mesh = stl_io::read_stl(&mut file)
        .map_err(|e| corrupt(path, format!("not a readable STL file: {e}")))?;
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let triangles = mesh
        .faces
        .iter()
        .map(|f| f.vertices.map(|i| i as u32))
        .collect();
    surface(path, vertices, triangles)
}

fn surface(
    path: &Path,
    vertices: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
) -> Result<TriangleSurface, IoError> {
    TriangleSurface::new(&path.display().to_string(), vertices, triangles)
        .map_err(|e| corrupt(path, e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's six faces as quads (OBJ) or twelve facets (STL),
    /// outward.
    const CUBE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

    fn cube_stl() -> String {
        let c = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let quads = [
            [0, 3, 2, 1],
            [4, 5, 6, 7],
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [3, 0, 4, 7],
        ];
        let mut s = String::from("solid cube\n");
        for q in quads {
            for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                s += "facet normal 0 0 0\nouter loop\n";
                for v in t {
                    let p: [f64; 3] = c[v];
                    s += &format!("vertex {} {} {}\n", p[0], p[1], p[2]);
                }
                s += "endloop\nendfacet\n";
            }
        }
        s + "endsolid cube\n"
    }

    #[test]
    fn obj_and_stl_cubes_read_closed_and_outward() {
        let dir = tempfile::tempdir().unwrap();
        for (name, text) in [("cube.obj", CUBE_OBJ.to_string()), ("cube.STL", cube_stl())] {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            let s = read_surface(&path).unwrap();
            s.check_closed(name).unwrap();
            assert_eq!(s.triangles.len(), 12, "{name}");
            assert_eq!(s.vertices.len(), 8, "{name}: vertices welded");
            assert!(
                (s.signed_volume() - 1.0).abs() < 1e-12,
                "{name}: {}",
                s.signed_volume()
            );
        }
    }

    #[test]
    fn other_extensions_and_garbage_are_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("cavity.ply");
        std::fs::write(&ply, "ply").unwrap();
        let e = read_surface(&ply).unwrap_err().to_string();
        assert!(
            e.contains("cavity.ply") && e.contains(".off, .obj or .stl"),
            "{e}"
        );
        let stl = dir.path().join("bad.stl");
        std::fs::write(&stl, "solid x\nfacet normal nonsense\n").unwrap();
        let e = read_surface(&stl).unwrap_err().to_string();
        assert!(e.contains("bad.stl"), "{e}");
    }
}
