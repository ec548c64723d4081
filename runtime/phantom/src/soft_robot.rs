//! Soft-robot phantoms (u8 labels): silicone bodies with fluid cavities, as
//! label volumes — so a soft robot is deformed, cut and rendered like every
//! other volume, and its cavities are label regions
//! (`voxflex_mesh::label_surface`) that actuator plugins inflate.
//!
//! Labels: [`AIR`] 0, [`SILICONE`] 1, cavities from [`FIRST_CAVITY`] (2)
//! up. A cavity is fluid, not material: the deformation model meshes the
//! silicone around it and the actuator pressurises its walls.
//!
//! Shapes (world millimetres, grid centred on the origin):
//!
//! - [`finger`] — a bar 80 × 16 × 16 mm along x, with one cavity
//!   (68 × 8 × 6 mm, z from −1 to 5) off-centre toward +z, under a 3 mm
//!   wall: inflating it lengthens the +z side and the finger bends toward
//!   −z. Clamp the face x = −40. The cavity is 3 cells tall and its wall
//!   1.5 cells thick on a 2 mm proxy (a proxy keeps every cell holding a
//!   silicone voxel, so a cavity thinner than two cells is meshed over).
//! - [`cylinder`] — the paper's fabricated specimen: a silicone cylinder
//!   (radius 20 mm, height 60 mm, axis z) around one cylindrical cavity
//!   (radius 12 mm, height 40 mm), inflated by 15 ml of air or water.
//! - [`pendulum`] — Fig. 6 of the paper: a column (radius 15 mm, height
//!   80 mm, axis z, hung from its top face) with four cavities (radius
//!   4 mm, height 60 mm) at 8 mm from the axis on ±x and ±y; inflating them
//!   together extends it, one or two bend it any way in the horizontal
//!   plane.

use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::{DVec2, DVec3};

/// Label of the background.
pub const AIR: u8 = 0;
/// Label of the silicone body.
pub const SILICONE: u8 = 1;
/// Label of the first cavity (the others follow: 3, 4, …).
pub const FIRST_CAVITY: u8 = 2;

/// Field of view of [`finger`], mm.
pub const FINGER_SIZE_MM: DVec3 = DVec3::new(96.0, 24.0, 24.0);
/// Field of view of [`cylinder`], mm.
pub const CYLINDER_SIZE_MM: DVec3 = DVec3::new(48.0, 48.0, 68.0);
/// Field of view of [`pendulum`], mm.
pub const PENDULUM_SIZE_MM: DVec3 = DVec3::new(36.0, 36.0, 88.0);

fn in_box(p: DVec3, lo: DVec3, hi: DVec3) -> bool {
    p.cmpge(lo).all() && p.cmple(hi).all()
}

/// A z-aligned cylinder: axis through `centre` (x, y), radius, z range.
fn in_cylinder(p: DVec3, centre: DVec2, radius: f64, z: [f64; 2]) -> bool {
    (p.truncate() - centre).length() <= radius && (z[0]..=z[1]).contains(&p.z)
}

/// The soft finger (see the module docs) on `grid`.
pub fn finger(grid: Grid) -> Volume {
    label_volume(grid, |p| {
        if !in_box(p, DVec3::new(-40.0, -8.0, -8.0), DVec3::new(40.0, 8.0, 8.0)) {
            AIR
        } else if in_box(p, DVec3::new(-32.0, -4.0, -1.0), DVec3::new(36.0, 4.0, 5.0)) {
            FIRST_CAVITY
        } else {
            SILICONE
        }
    })
}

/// The paper's cylinder specimen (see the module docs) on `grid`.
pub fn cylinder(grid: Grid) -> Volume {
    label_volume(grid, |p| {
        if !in_cylinder(p, DVec2::ZERO, 20.0, [-30.0, 30.0]) {
            AIR
        } else if in_cylinder(p, DVec2::ZERO, 12.0, [-20.0, 20.0]) {
            FIRST_CAVITY
        } else {
            SILICONE
        }
    })
}

/// Axis positions (x, y; mm) of the [`pendulum`]'s cavities, labels 2…5.
pub const PENDULUM_CAVITIES: [DVec2; 4] = [
    DVec2::new(8.0, 0.0),
    DVec2::new(0.0, 8.0),
    DVec2::new(-8.0, 0.0),
    DVec2::new(0.0, -8.0),
];

/// The four-cavity pendulum (see the module docs) on `grid`.
pub fn pendulum(grid: Grid) -> Volume {
    label_volume(grid, |p| {
        if !in_cylinder(p, DVec2::ZERO, 15.0, [-40.0, 40.0]) {
            return AIR;
        }
        PENDULUM_CAVITIES
            .iter()
            .position(|&c| in_cylinder(p, c, 4.0, [-30.0, 30.0]))
            .map_or(SILICONE, |n| FIRST_CAVITY + n as u8)
    })
}

fn label_volume(grid: Grid, label: impl Fn(DVec3) -> u8 + Sync) -> Volume {
    Volume {
        data: VoxelData::U8(crate::fill(&grid, label)),
        grid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PhantomKind;

    fn count(v: &Volume, label: u8) -> usize {
        match &v.data {
            VoxelData::U8(d) => d.iter().filter(|&&x| x == label).count(),
            _ => unreachable!("soft-robot phantoms are u8"),
        }
    }

    fn voxel_mm3(v: &Volume) -> f64 {
        v.grid.spacing.x * v.grid.spacing.y * v.grid.spacing.z
    }

    #[test]
    fn each_robot_has_its_body_and_cavities_at_their_volumes() {
        let pi = std::f64::consts::PI;
        let cases = [
            (
                PhantomKind::Finger,
                80.0 * 16.0 * 16.0,
                vec![68.0 * 8.0 * 6.0],
            ),
            (
                PhantomKind::Cylinder,
                pi * 400.0 * 60.0,
                vec![pi * 144.0 * 40.0],
            ),
            (
                PhantomKind::Pendulum,
                pi * 225.0 * 80.0,
                vec![pi * 16.0 * 60.0; 4],
            ),
        ];
        for (kind, body, cavities) in cases {
            let v = kind.generate([96, 96, 96]).unwrap();
            let dv = voxel_mm3(&v);
            let total: f64 = cavities.iter().sum();
            let silicone = count(&v, SILICONE) as f64 * dv;
            assert!(
                ((silicone - (body - total)) / body).abs() < 0.05,
                "{kind}: silicone {silicone} mm³"
            );
            for (n, want) in cavities.iter().enumerate() {
                let got = count(&v, FIRST_CAVITY + n as u8) as f64 * dv;
                assert!(
                    ((got - want) / want).abs() < 0.1,
                    "{kind} cavity {n}: {got} vs {want} mm³"
                );
            }
            assert_eq!(
                count(&v, FIRST_CAVITY + cavities.len() as u8),
                0,
                "{kind}: no extra cavity"
            );
        }
    }

    #[test]
    fn the_fingers_cavity_is_off_centre_toward_plus_z() {
        let v = PhantomKind::Finger.generate([48, 12, 12]).unwrap();
        let g = v.grid;
        let (mut sum, mut n) = (0.0, 0);
        for l in 0..g.len() {
            let [i, j, k] = g.unlinear(l);
            if v.get_f32(i, j, k) as u8 == FIRST_CAVITY {
                sum += g.index_to_world(DVec3::new(i as f64, j as f64, k as f64)).z;
                n += 1;
            }
        }
        // z from −1 to 5 mm: its centroid 2 mm above the axis (±1 voxel).
        let centroid = sum / n as f64;
        assert!(
            (centroid - 2.0).abs() <= 1.0,
            "cavity centroid at z = {centroid}"
        );
    }
}
