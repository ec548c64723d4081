//! The shared test surfaces as the paper uses them, for tests, parity
//! checks and benchmarks (feature `test-support`): the icosphere of radius
//! 10 mm and the Stanford bunny scaled to 2 cm height. Both come from
//! `shared/data` (see `voxflex_core::test_data`); `Ok(None)` when that
//! folder is missing outside CI.

use glam::DVec3;
use voxflex_core::triangle_surface::TriangleSurface;

/// The bunny's up axis in `bunny_75k.off` (the Stanford scan is y-up).
pub const BUNNY_UP: DVec3 = DVec3::Y;

/// Gravity for the bunny standing upright, m/s².
pub const BUNNY_GRAVITY: DVec3 = DVec3::new(0.0, -9.81, 0.0);

fn read(name: &str) -> Result<Option<TriangleSurface>, String> {
    let Some(dir) = voxflex_core::test_data::dir() else {
        return Ok(None);
    };
    let s = voxflex_io::off::read_off(&dir.join(name)).map_err(|e| e.to_string())?;
    s.check_closed(name).map_err(|e| e.to_string())?;
    Ok(Some(s))
}

/// `sphere_ico4_5120.off`: 4 subdivisions of an icosahedron, radius 10 mm,
/// 5,120 triangles; exact signed volume 4179.74 mm³.
pub fn icosphere() -> Result<Option<TriangleSurface>, String> {
    read("sphere_ico4_5120.off")
}

/// `bunny_75k.off` (75,408 triangles) scaled about its lowest point to a
/// height of 20 mm along [`BUNNY_UP`], the paper's non-convex test.
pub fn bunny_2cm() -> Result<Option<TriangleSurface>, String> {
    let Some(s) = read("bunny_75k.off")? else {
        return Ok(None);
    };
    let (lo, hi) = s.bounds();
    let scale = 20.0 / (hi - lo).dot(BUNNY_UP);
    Ok(Some(s.mapped(|p| (p - lo) * scale)))
}
