//! The points an actuator acts on, at rest: a cavity's closed surface
//! (from a mesh file or a label of the source volume) or a cable's points.

use super::settings::ActuatorSettings;
use std::path::Path;
use voxflex_core::glam::DVec3;
use voxflex_core::triangle_surface::TriangleSurface;
use voxflex_core::volume::Volume;

/// An actuator's rest geometry (world mm).
#[derive(Clone, Debug, PartialEq)]
pub struct RestGeometry {
    /// The points, world mm.
    pub points: Vec<DVec3>,
    /// A cavity's triangles (empty for a cable).
    pub triangles: Vec<[u32; 3]>,
}

/// Loads `settings`' geometry: `cavity.file` relative to `base_dir`,
/// `cavity.label` from `source`. Errors say what to fix.
pub fn rest_geometry(
    settings: &ActuatorSettings,
    base_dir: &Path,
    source: &Volume,
) -> Result<RestGeometry, String> {
    let Some(cavity) = &settings.cavity else {
        return Ok(RestGeometry {
            points: settings
                .points
                .iter()
                .map(|p| DVec3::from_array(*p))
                .collect(),
            triangles: vec![],
        });
    };
    let surface: TriangleSurface = match (&cavity.file, cavity.label) {
        (Some(file), _) => {
            let path = base_dir.join(file);
            voxflex_io::surface_mesh::read_surface(&path).map_err(|e| e.to_string())?
        }
        (None, Some(label)) => voxflex_mesh::label_surface::label_surface(source, label)
            .map_err(|e| format!("cavity = {{ label = {label} }}: {e}"))?,
        (None, None) => return Err("cavity: give `file` or `label`".into()),
    };
    Ok(RestGeometry {
        points: surface.vertices,
        triangles: surface.triangles,
    })
}
