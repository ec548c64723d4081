//! A closed triangle surface: vertices in world millimetres, triangles as
//! three vertex indices. The boundary of an actuator's cavity (read from an
//! OFF file or extracted from a label region), and what the fluid-weight
//! and pressure computations integrate over.
//!
//! Orientation: a triangle `[a, b, c]` has the normal `(b − a) × (c − a)`;
//! on a surface that [`TriangleSurface::check_closed`] accepts with a
//! positive [`TriangleSurface::signed_volume`], every normal points out of
//! the enclosed region.

use crate::error::MeshError;
use glam::DVec3;
use std::collections::HashMap;

/// A triangle surface (rest or current configuration).
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleSurface {
    /// Vertex positions, mm (world frame).
    pub vertices: Vec<DVec3>,
    /// Vertex indices of each triangle; the order sets the normal (above).
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleSurface {
    /// Checks indices and coordinates; `source_name` (a file name or the
    /// generator) goes into every error. Does not require closedness (see
    /// [`Self::check_closed`]).
    pub fn new(
        source_name: &str,
        vertices: Vec<DVec3>,
        triangles: Vec<[u32; 3]>,
    ) -> Result<Self, MeshError> {
        if triangles.is_empty() {
            return Err(MeshError::Shape {
                source_name: source_name.to_string(),
                message: "the surface has no triangle".into(),
            });
        }
        if let Some((node, p)) = vertices.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(MeshError::NonFinite {
                source_name: source_name.to_string(),
                node,
                value: p.to_array(),
            });
        }
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&node) = tri.iter().find(|&&v| v as usize >= vertices.len()) {
                return Err(MeshError::Shape {
                    source_name: source_name.to_string(),
                    message: format!(
                        "triangle {t} names vertex {node}, but the surface has {} vertices",
                        vertices.len()
                    ),
                });
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(MeshError::Shape {
                    source_name: source_name.to_string(),
                    message: format!("triangle {t} repeats a vertex ({tri:?}); remove it"),
                });
            }
        }
        Ok(Self {
            vertices,
            triangles,
        })
    }

    /// The corner positions (mm) of triangle `t`.
    #[inline]
    pub fn corners(&self, t: usize) -> [DVec3; 3] {
        self.triangles[t].map(|v| self.vertices[v as usize])
    }

    /// Twice the area times the unit normal of triangle `t`: `(b − a) × (c − a)`, mm².
    #[inline]
    pub fn doubled_area_normal(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.corners(t);
        (b - a).cross(c - a)
    }

    /// Volume enclosed (mm³) by the divergence theorem: positive when the
    /// normals point out, negative when they point in. Meaningful only for
    /// a closed surface.
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                a.dot(b.cross(c))
            })
            .sum::<f64>()
            / 6.0
    }

    /// Total area, mm².
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| self.doubled_area_normal(t).length() / 2.0)
            .sum()
    }

    /// Per vertex, `Σ_t S_t n_t / 3` over the triangles `t` that hold it
    /// (`S_t` the area, `n_t` the unit normal): the pressure Jacobian's row
    /// of each vertex (mm²). A unit pressure pushes vertex `i` with this
    /// force (pressure × mm² = force); the sum over vertices is zero on a
    /// closed surface.
    pub fn area_weighted_normals(&self) -> Vec<DVec3> {
        let mut out = vec![DVec3::ZERO; self.vertices.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let share = self.doubled_area_normal(t) / 6.0;
            for &v in tri {
                out[v as usize] += share;
            }
        }
        out
    }

    /// The axis-aligned bounding box (mm): `(min, max)`.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.vertices.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    }

    /// Refuses a surface that does not enclose a region consistently:
    /// every edge must be shared by exactly two triangles that run along it
    /// in opposite directions (a closed, consistently oriented 2-manifold).
    /// The error names the first bad edge and how often each direction
    /// occurs.
    pub fn check_closed(&self, source_name: &str) -> Result<(), MeshError> {
        let mut uses: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
        for tri in &self.triangles {
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                let key = (a.min(b), a.max(b));
                let entry = uses.entry(key).or_default();
                if a < b {
                    entry.0 += 1;
                } else {
                    entry.1 += 1;
                }
            }
        }
        let mut bad: Vec<_> = uses.into_iter().filter(|(_, n)| *n != (1, 1)).collect();
        bad.sort_unstable();
        match bad.first() {
            None => Ok(()),
            Some(((a, b), (up, down))) => Err(MeshError::Shape {
                source_name: source_name.to_string(),
                message: format!(
                    "the surface is not closed and consistently oriented: edge {a}–{b} is run \
                     {up}× from {a} to {b} and {down}× back (each must be once; {} such edges). \
                     Close holes, remove duplicate triangles and orient every face the same way",
                    bad.len()
                ),
            }),
        }
    }

    /// The surface of the box `[lo, hi]` (mm), normals out, each face split
    /// into `m × m` equal quads of two triangles (`m ≥ 1`), vertices shared:
    /// a closed test and primitive cavity whose inner edges and vertices
    /// sit on known coordinates.
    pub fn tiled_box(lo: DVec3, hi: DVec3, m: usize) -> Self {
        let m = m.max(1);
        let mut index = HashMap::new();
        let mut vertices = Vec::new();
        let mut id = |p: [usize; 3]| -> u32 {
            *index.entry(p).or_insert_with(|| {
                let t = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) / m as f64;
                vertices.push(lo + t * (hi - lo));
                (vertices.len() - 1) as u32
            })
        };
        let mut triangles = Vec::with_capacity(12 * m * m);
        // Face at `at` across axis a, spanned by (b, c) with e_b × e_c = e_a.
        for a in 0..3 {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            for (at, outward) in [(0, false), (m, true)] {
                for i in 0..m {
                    for j in 0..m {
                        let corner = |di: usize, dj: usize| {
                            let mut p = [at; 3];
                            p[b] = i + di;
                            p[c] = j + dj;
                            p
                        };
                        let q =
                            [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)].map(&mut id);
                        let (t0, t1) = ([q[0], q[1], q[2]], [q[0], q[2], q[3]]);
                        if outward {
                            triangles.extend([t0, t1]);
                        } else {
                            triangles.extend([[t0[0], t0[2], t0[1]], [t1[0], t1[2], t1[1]]]);
                        }
                    }
                }
            }
        }
        Self {
            vertices,
            triangles,
        }
    }

    /// Copy with every vertex moved by `f` (e.g. a rigid motion, or the
    /// deformation model's map), same triangles.
    pub fn mapped(&self, f: impl Fn(DVec3) -> DVec3) -> Self {
        Self {
            vertices: self.vertices.iter().map(|&p| f(p)).collect(),
            triangles: self.triangles.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit cube's surface, normals out.
    fn cube() -> TriangleSurface {
        TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1)
    }

    #[test]
    fn tiled_boxes_are_closed_and_enclose_their_volume() {
        for m in [1, 2, 5] {
            let s = TriangleSurface::tiled_box(
                DVec3::new(-1.0, 2.0, 0.0),
                DVec3::new(3.0, 4.0, 5.0),
                m,
            );
            s.check_closed("tiled box").unwrap();
            assert_eq!(s.triangles.len(), 12 * m * m);
            assert_eq!(s.vertices.len(), 6 * m * m + 2);
            assert!(
                (s.signed_volume() - 40.0).abs() < 1e-9,
                "{m}: {}",
                s.signed_volume()
            );
        }
    }

    #[test]
    fn the_cube_encloses_one_cubic_mm_and_is_closed() {
        let c = cube();
        assert!((c.signed_volume() - 1.0).abs() < 1e-12);
        assert!((c.area() - 6.0).abs() < 1e-12);
        c.check_closed("cube").unwrap();
        let sum: DVec3 = c.area_weighted_normals().iter().sum();
        assert!(sum.length() < 1e-12, "{sum}");
    }

    #[test]
    fn flipped_orientation_gives_negative_volume() {
        let mut c = cube();
        for t in &mut c.triangles {
            t.swap(1, 2);
        }
        assert!((c.signed_volume() + 1.0).abs() < 1e-12);
        c.check_closed("flipped").unwrap();
    }

    #[test]
    fn a_hole_or_a_flipped_face_is_refused_by_name() {
        let mut holed = cube();
        holed.triangles.pop();
        let e = holed.check_closed("holed.off").unwrap_err().to_string();
        assert!(e.contains("holed.off") && e.contains("not closed"), "{e}");
        let mut flipped = cube();
        flipped.triangles[0].swap(1, 2);
        assert!(flipped.check_closed("one flipped").is_err());
    }

    #[test]
    fn bad_indices_and_non_finite_vertices_are_refused() {
        let v = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
        assert!(TriangleSurface::new("s", v.clone(), vec![[0, 1, 3]]).is_err());
        assert!(TriangleSurface::new("s", v.clone(), vec![[0, 1, 1]]).is_err());
        assert!(TriangleSurface::new("s", v.clone(), vec![]).is_err());
        let mut nan = v;
        nan[1].x = f64::NAN;
        let e = TriangleSurface::new("s", nan, vec![[0, 1, 2]]).unwrap_err();
        assert!(e.to_string().contains("node 1"), "{e}");
    }

    #[test]
    fn volume_does_not_depend_on_where_the_surface_is() {
        let c = cube().mapped(|p| p + DVec3::new(100.0, -40.0, 7.0));
        assert!((c.signed_volume() - 1.0).abs() < 1e-9);
    }
}
