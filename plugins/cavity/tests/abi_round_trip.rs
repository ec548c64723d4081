//! The cavity through the C ABI in one process: the exported vtable
//! driven by the host's `ActuatorProxy` — parameters, the surface with its
//! triangles, the command, the linearisation with its loads, the notes.

use voxflex_abi::actuator::{ActuatorProxy, actuator_vtable};
use voxflex_abi::host_side::HostServices;
use voxflex_cavity::Cavity;
use voxflex_core::actuator::{ActuatorCommand, ActuatorGeometry, ActuatorModel};
use voxflex_core::deformation::FrameInfo;
use voxflex_core::glam::DVec3;
use voxflex_core::triangle_surface::TriangleSurface;

static VTABLE: voxflex_abi::ffi::ActuatorVTable = actuator_vtable::<Cavity>();

fn proxy(params: &str) -> Result<ActuatorProxy, String> {
    // SAFETY: a static vtable of this process.
    unsafe { ActuatorProxy::create("cavity", &VTABLE, params, HostServices::new(None, 1)) }
        .map_err(|e| e.0)
}

#[test]
fn a_hydraulic_cavity_crosses_the_boundary_intact() {
    let mut p =
        proxy("fluid = \"water\"\npressure_pa = [[0, 0], [10, 500]]\ncolumns_per_side = 20")
            .unwrap();
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::new(2.0, 3.0, 4.0), 2);
    p.init(ActuatorGeometry {
        points: &s.vertices,
        triangles: &s.triangles,
        gravity_m_s2: DVec3::new(0.0, 0.0, -9.81),
    })
    .unwrap();
    let frame = FrameInfo {
        frame: 4,
        frames: 10,
        dt_s: 0.1,
    };
    assert_eq!(p.command(frame).unwrap(), ActuatorCommand::Effort(200.0));
    let x: Vec<DVec3> = s.vertices.iter().map(|&v| v * 1.1).collect();
    let l = p.linearise(&x).unwrap();
    let mut direct = Cavity::new(
        voxflex_cavity::CavityParams::from_toml("fluid = \"water\"\ncolumns_per_side = 20")
            .unwrap(),
    );
    direct
        .init(ActuatorGeometry {
            points: &s.vertices,
            triangles: &s.triangles,
            gravity_m_s2: DVec3::new(0.0, 0.0, -9.81),
        })
        .unwrap();
    let d = direct.linearise(&x).unwrap();
    assert_eq!(l.directions, d.directions);
    assert_eq!(
        (l.measure, &l.loads, &l.load_growth),
        (d.measure, &d.loads, &d.load_growth)
    );
    // 24 mm³ × 1.331 of water: 9.81 µN per mm³.
    let w: DVec3 = l.loads.iter().sum();
    assert!((w.z + 24.0 * 1.331 * 9.81).abs() < 1e-9, "{w}");
    let notes = p.notes().unwrap();
    assert_eq!(notes["weighings"], 1.0);
    assert!((notes["volume_growth_mm3"] - 24.0 * 0.331).abs() < 1e-9);
}

#[test]
fn refusals_cross_the_boundary_naming_the_key_or_the_geometry() {
    let e = proxy("pressure_pa = [[0, 1]]\nvolume_mm3 = [[0, 1]]")
        .err()
        .unwrap();
    assert!(e.contains("pressure_pa and volume_mm3"), "{e}");
    let mut p = proxy("").unwrap();
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1);
    let e = p
        .init(ActuatorGeometry {
            points: &s.vertices,
            triangles: &s.triangles[2..],
            gravity_m_s2: DVec3::ZERO,
        })
        .unwrap_err()
        .0;
    assert!(e.contains("not closed"), "{e}");
}
