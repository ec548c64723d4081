//! The soft-robot phantoms' cavities as an actuator will see them: each
//! cavity label's surface (marching tetrahedra) is closed and outward, the
//! column grid weighs the fluid filling it at the volume the surface
//! encloses, and the pressure directions (area-weighted normals) balance.

use voxflex_core::glam::DVec3;
use voxflex_fluid::{FluidWeightParams, fluid_weights};
use voxflex_mesh::label_surface::label_surface;
use voxflex_phantom::PhantomKind;
use voxflex_phantom::soft_robot::FIRST_CAVITY;

#[test]
fn every_cavity_is_closed_weighed_and_balanced() {
    for (kind, cavities) in [
        (PhantomKind::Finger, 1),
        (PhantomKind::Cylinder, 1),
        (PhantomKind::Pendulum, 4),
    ] {
        let v = kind.generate([64, 64, 64]).unwrap();
        for n in 0..cavities {
            let label = (FIRST_CAVITY + n) as i64;
            let s = label_surface(&v, label).unwrap();
            let enclosed = s.signed_volume();
            assert!(enclosed > 0.0, "{kind} cavity {label}: normals point out");
            let w = fluid_weights(&s, &FluidWeightParams::default()).unwrap();
            assert_eq!(w.count.irregular_columns, 0, "{kind} cavity {label}");
            let rel = (w.volume_mm3 - enclosed).abs() / enclosed;
            assert!(
                rel < 2e-3,
                "{kind} cavity {label}: columns hold {} of {enclosed} mm³",
                w.volume_mm3
            );
            let net: DVec3 = s.area_weighted_normals().iter().sum();
            assert!(
                net.length() < 1e-9 * s.area(),
                "{kind} cavity {label}: pressure does not balance: {net}"
            );
        }
    }
}
