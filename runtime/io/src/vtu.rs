//! VTK XML unstructured grids (`.vtu`, ASCII), so a deformed proxy opens
//! in ParaView: points at their current positions (rest + displacement,
//! mm), the tetrahedra, the displacement as point data and the material
//! label as cell data. Written atomically (temporary file, then rename).

use crate::error::IoError;
use crate::tet_mesh::TetMesh;
use crate::write_atomically;
use std::io::Write;
use std::path::Path;

/// VTK's cell type of the linear tetrahedron.
const VTK_TETRA: u8 = 10;

/// Writes `mesh` moved by `displacement` (mm per node, x/y/z arrays; `None`
/// for the rest configuration) to `path`.
pub fn write_vtu(
    path: &Path,
    mesh: &TetMesh,
    displacement: Option<[&[f32]; 3]>,
) -> Result<(), IoError> {
    write_vtu_with(path, mesh, displacement, &[])
}

/// [`write_vtu`] with more per-node vectors (`(name, one per node)`, e.g.
/// the nodal forces in µN), written as point data beside the
/// displacement.
pub fn write_vtu_with(
    path: &Path,
    mesh: &TetMesh,
    displacement: Option<[&[f32]; 3]>,
    point_vectors: &[(&str, &[glam::DVec3])],
) -> Result<(), IoError> {
    let n = mesh.nodes.len();
    if let Some((name, v)) = point_vectors.iter().find(|(_, v)| v.len() != n) {
        return Err(IoError::InvalidRequest {
            path: path.to_path_buf(),
            message: format!(
                "{name} holds {} vectors but the mesh has {n} nodes",
                v.len()
            ),
        });
    }
    if let Some(u) = displacement
        && u.iter().any(|a| a.len() != n)
    {
        return Err(IoError::InvalidRequest {
            path: path.to_path_buf(),
            message: format!(
                "displacements hold {:?} values per axis but the mesh has {n} nodes",
                u.map(|a| a.len())
            ),
        });
    }
    let u = |node: usize, a: usize| displacement.map_or(0.0, |d| d[a][node] as f64);
    write_atomically(path, |w: &mut dyn Write| {
        writeln!(w, r#"<?xml version="1.0"?>"#)?;
        writeln!(
            w,
            r#"<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian">"#
        )?;
        writeln!(w, "<UnstructuredGrid>")?;
        writeln!(
            w,
            r#"<Piece NumberOfPoints="{n}" NumberOfCells="{}">"#,
            mesh.tets.len()
        )?;
        writeln!(w, "<Points>")?;
        writeln!(
            w,
            r#"<DataArray type="Float64" NumberOfComponents="3" format="ascii">"#
        )?;
        for (i, p) in mesh.nodes.iter().enumerate() {
            writeln!(w, "{} {} {}", p.x + u(i, 0), p.y + u(i, 1), p.z + u(i, 2))?;
        }
        writeln!(w, "</DataArray>\n</Points>")?;
        writeln!(w, "<Cells>")?;
        writeln!(
            w,
            r#"<DataArray type="Int64" Name="connectivity" format="ascii">"#
        )?;
        for t in &mesh.tets {
            writeln!(w, "{} {} {} {}", t[0], t[1], t[2], t[3])?;
        }
        writeln!(w, "</DataArray>")?;
        writeln!(
            w,
            r#"<DataArray type="Int64" Name="offsets" format="ascii">"#
        )?;
        for c in 1..=mesh.tets.len() {
            writeln!(w, "{}", 4 * c)?;
        }
        writeln!(w, "</DataArray>")?;
        writeln!(w, r#"<DataArray type="UInt8" Name="types" format="ascii">"#)?;
        for _ in &mesh.tets {
            writeln!(w, "{VTK_TETRA}")?;
        }
        writeln!(w, "</DataArray>\n</Cells>")?;
        writeln!(w, r#"<PointData Vectors="displacement_mm">"#)?;
        writeln!(
            w,
            r#"<DataArray type="Float32" Name="displacement_mm" NumberOfComponents="3" format="ascii">"#
        )?;
        for i in 0..n {
            writeln!(w, "{} {} {}", u(i, 0), u(i, 1), u(i, 2))?;
        }
        writeln!(w, "</DataArray>")?;
        for (name, values) in point_vectors {
            writeln!(
                w,
                r#"<DataArray type="Float64" Name="{name}" NumberOfComponents="3" format="ascii">"#
            )?;
            for v in values.iter() {
                writeln!(w, "{} {} {}", v.x, v.y, v.z)?;
            }
            writeln!(w, "</DataArray>")?;
        }
        writeln!(w, "</PointData>")?;
        writeln!(w, r#"<CellData Scalars="label">"#)?;
        writeln!(
            w,
            r#"<DataArray type="UInt16" Name="label" format="ascii">"#
        )?;
        for l in &mesh.labels {
            writeln!(w, "{l}")?;
        }
        writeln!(w, "</DataArray>\n</CellData>")?;
        writeln!(w, "</Piece>\n</UnstructuredGrid>\n</VTKFile>")
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn extra_point_vectors_are_written_and_wrong_lengths_refused() {
        let nodes = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        let m = TetMesh::new("one", nodes, vec![[0, 1, 2, 3]], vec![1]).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.vtu");
        let f = vec![DVec3::new(0.0, 0.0, -2.5); 4];
        write_vtu_with(&path, &m, None, &[("actuator_force_uN", &f)]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let field = text.split(r#"Name="actuator_force_uN""#).nth(1).unwrap();
        let field = &field[..field.find("</DataArray>").unwrap()];
        assert_eq!(field.matches("0 0 -2.5").count(), 4, "{field}");
        let e = write_vtu_with(&path, &m, None, &[("short", &f[1..])]).unwrap_err();
        assert!(e.to_string().contains("short holds 3 vectors"), "{e}");
    }

    #[test]
    fn writes_the_moved_proxy_for_paraview() {
        // Two tetrahedra sharing a face (what a proxy writes, without
        // the mesh crate that builds proxies).
        let nodes = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE];
        let m = TetMesh::new(
            "two tetrahedra",
            nodes,
            vec![[0, 1, 2, 3], [1, 2, 3, 4]],
            vec![2, 2],
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("proxy.vtu");
        let ux = vec![0.5f32; m.nodes.len()];
        let zeros = vec![0f32; m.nodes.len()];
        write_vtu(&path, &m, Some([&ux, &zeros, &zeros])).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains(&format!(
            r#"NumberOfPoints="{}" NumberOfCells="{}""#,
            m.nodes.len(),
            m.tets.len()
        )));
        // Every point moved by +0.5 mm along x.
        let first = m.nodes[0];
        assert!(text.contains(&format!("{} {} {}", first.x + 0.5, first.y, first.z)));
        let types = text
            .split(r#"Name="types" format="ascii">"#)
            .nth(1)
            .unwrap();
        let types = &types[..types.find("</DataArray>").unwrap()];
        assert_eq!(
            types.split_whitespace().filter(|t| *t == "10").count(),
            m.tets.len()
        );
        assert!(text.trim_end().ends_with("</VTKFile>"));
        // A wrong-length field is refused and the old file kept.
        let e = write_vtu(&path, &m, Some([&ux[1..], &zeros, &zeros])).unwrap_err();
        assert!(
            e.to_string().contains("proxy.vtu") && e.to_string().contains("nodes"),
            "{e}"
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), text);
    }
}
