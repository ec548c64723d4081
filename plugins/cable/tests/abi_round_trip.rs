//! The cable through the C ABI in one process: the exported vtable driven
//! by the host's `ActuatorProxy` — parameters, points, command,
//! linearisation, notes.

use voxflex_abi::actuator::{ActuatorProxy, actuator_vtable};
use voxflex_abi::host_side::HostServices;
use voxflex_cable::Cable;
use voxflex_core::actuator::{ActuatorCommand, ActuatorGeometry, ActuatorModel};
use voxflex_core::deformation::FrameInfo;
use voxflex_core::glam::DVec3;

static VTABLE: voxflex_abi::ffi::ActuatorVTable = actuator_vtable::<Cable>();

fn proxy(params: &str) -> Result<ActuatorProxy, String> {
    // SAFETY: a static vtable of this process.
    unsafe { ActuatorProxy::create("cable", &VTABLE, params, HostServices::new(None, 1)) }
        .map_err(|e| e.0)
}

#[test]
fn a_cable_crosses_the_boundary_intact() {
    let mut p = proxy("pull_point_mm = [0, 0, 0]\nshortening_mm = [[0, 0], [4, 2]]").unwrap();
    let rest = [DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, 0.0, 3.0)];
    p.init(ActuatorGeometry {
        points: &rest,
        triangles: &[],
        gravity_m_s2: DVec3::new(0.0, 0.0, -9.81),
    })
    .unwrap();
    let frame = FrameInfo {
        frame: 1,
        frames: 10,
        dt_s: 0.1,
    };
    assert_eq!(p.command(frame).unwrap(), ActuatorCommand::Measure(0.5));
    let l = p.linearise(&[rest[0], DVec3::new(0.0, 0.0, 2.5)]).unwrap();
    assert_eq!(l.directions, vec![DVec3::ZERO, DVec3::new(0.0, 0.0, -1.0)]);
    assert!((l.measure - 0.5).abs() < 1e-12);
    assert!(l.loads.is_empty() && l.load_growth.is_empty());
    assert_eq!(l.effort_bounds, [0.0, f64::INFINITY]);
    let notes = p.notes().unwrap();
    assert_eq!((notes["rest_length_mm"], notes["length_mm"]), (3.0, 2.5));
}

#[test]
fn refusals_cross_the_boundary_naming_the_key_or_the_points() {
    let e = proxy("pull_point_mm = [0, 0, 0]\nmax_tension_uN = -1")
        .err()
        .unwrap();
    assert!(e.contains("max_tension_uN"), "{e}");
    let mut p = proxy("pull_point_mm = [0, 0, 0]").unwrap();
    let e = p
        .init(ActuatorGeometry {
            points: &[DVec3::ZERO],
            triangles: &[],
            gravity_m_s2: DVec3::ZERO,
        })
        .unwrap_err()
        .0;
    assert!(e.contains("pull point"), "{e}");
}
