//! Inverted tetrahedra: counted after every frame, reported in the
//! model's notes (`inverted_tetrahedra` now, `inverted_tetrahedra_max` over
//! the run) and warned about when some stay inverted while no grab holds
//! the mesh.
//!
//! A tetrahedron is inverted when its signed volume at the current
//! positions is ≤ 0 (the proxy stores every tetrahedron positively
//! oriented). The volume is computed from rest edge vectors plus
//! displacement differences, so a model far from the origin loses no
//! precision.

use crate::tet_mesh::TetMesh;
use glam::DVec3;
use rayon::prelude::*;

/// Frames without a grab after which tetrahedra still inverted are warned
/// about (one second at the default 30 frames per second: long enough for
/// a released grab's recoil to pass).
pub const SETTLE_FRAMES: u64 = 30;

/// Tetrahedra of `mesh` whose signed volume at displacements `u` (mm) is
/// ≤ 0.
pub fn inverted_tetrahedra(mesh: &TetMesh, u: &[DVec3]) -> usize {
    mesh.tets
        .par_iter()
        .with_min_len(4096)
        .filter(|t| {
            let [a, b, c, d] = t.map(|n| n as usize);
            let edge = |n: usize| (mesh.nodes[n] - mesh.nodes[a]) + (u[n] - u[a]);
            edge(b).dot(edge(c).cross(edge(d))) <= 0.0
        })
        .count()
}

/// The edge of `mesh` whose length at displacements `u` (mm) differs most
/// from its rest length, relative to it: `((i, j), |now − rest| / rest)`
/// (`None` for a mesh without tetrahedra). A mesh back at rest up to a
/// rigid motion has every edge at its rest length — what the inversion
/// tests check after recovery.
pub fn largest_edge_change(mesh: &TetMesh, u: &[DVec3]) -> Option<((usize, usize), f64)> {
    let mut worst: Option<((usize, usize), f64)> = None;
    for tet in &mesh.tets {
        for a in 0..4 {
            for b in a + 1..4 {
                let (i, j) = (tet[a] as usize, tet[b] as usize);
                let rest = (mesh.nodes[i] - mesh.nodes[j]).length();
                let now = (mesh.nodes[i] - mesh.nodes[j] + (u[i] - u[j])).length();
                let change = (now - rest).abs() / rest;
                if worst.is_none_or(|(_, w)| change > w) {
                    worst = Some(((i, j), change));
                }
            }
        }
    }
    worst
}

/// The run's inverted-tetrahedron counts and its warning state.
#[derive(Clone, Copy, Debug, Default)]
pub struct InversionWatch {
    /// Inverted after the last frame.
    pub current: usize,
    /// The most inverted after any frame.
    pub max: usize,
    /// Frames since a grab last held the mesh.
    free_frames: u64,
    /// A warning was given for the present tangle.
    warned: bool,
}

impl InversionWatch {
    /// Records a frame's count (`grabbed`: a grab held the mesh this
    /// frame); warns once, naming `model` and what to change (`hint`), when
    /// tetrahedra stay inverted [`SETTLE_FRAMES`] frames after the last
    /// grab let go. Returns whether it warned.
    pub fn record(&mut self, inverted: usize, grabbed: bool, model: &str, hint: &str) -> bool {
        self.current = inverted;
        self.max = self.max.max(inverted);
        self.free_frames = if grabbed { 0 } else { self.free_frames + 1 };
        if inverted == 0 || grabbed {
            self.warned = false;
            return false;
        }
        if self.free_frames < SETTLE_FRAMES || self.warned {
            return false;
        }
        self.warned = true;
        tracing::warn!(
            inverted_tetrahedra = inverted,
            "{model}: {inverted} tetrahedra are still inverted {} frames after the last grab \
             let go (the most over the run: {}); the proxy is tangled{hint}",
            self.free_frames,
            self.max
        );
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::proxy::uniform_proxy;

    #[test]
    fn inverted_tetrahedra_are_counted_and_a_lasting_tangle_is_warned_once() {
        let grid = Grid::new([3, 3, 3], DVec3::ONE, DVec3::splat(1000.0));
        let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
        let n = mesh.nodes.len();
        assert_eq!(inverted_tetrahedra(&mesh, &vec![DVec3::ZERO; n]), 0);
        // Mirrored through z = 1001 (the middle layer): every tetrahedron
        // turns inside out; a rigid translation turns none.
        let mirror: Vec<DVec3> = mesh
            .nodes
            .iter()
            .map(|p| DVec3::new(0.0, 0.0, 2.0 * (1001.0 - p.z)))
            .collect();
        assert_eq!(inverted_tetrahedra(&mesh, &mirror), mesh.tets.len());
        let shift = vec![DVec3::new(3.0, -2.0, 7.0); n];
        assert_eq!(inverted_tetrahedra(&mesh, &shift), 0);
        // One corner node pushed through its cell: only its tetrahedra.
        let corner = mesh
            .nodes
            .iter()
            .position(|p| *p == DVec3::splat(1000.0))
            .unwrap();
        let mut poke = vec![DVec3::ZERO; n];
        poke[corner] = DVec3::splat(1.5);
        let count = inverted_tetrahedra(&mesh, &poke);
        assert!(count >= 1 && count < mesh.tets.len(), "{count}");

        let mut w = InversionWatch::default();
        assert!(!w.record(5, true, "m", ""), "held by a grab: no warning");
        for _ in 1..SETTLE_FRAMES {
            assert!(!w.record(3, false, "m", ""), "still settling");
        }
        assert!(w.record(3, false, "m", ""), "a lasting tangle warns");
        assert!(!w.record(3, false, "m", ""), "once");
        assert_eq!((w.current, w.max), (3, 5));
        w.record(0, false, "m", "");
        assert_eq!((w.current, w.max), (0, 5));
    }
}
