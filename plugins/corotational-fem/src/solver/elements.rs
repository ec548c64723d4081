//! The solver's elements, linear or quadratic, behind one interface: per
//! element its warped stiffness and force offsets, its energy and its
//! elastic force, gathered from and scattered to the (full) node arrays.

use super::Twist;
use crate::element::Element;
use crate::quadratic::{NODES, Quadratic};
use rayon::prelude::*;
use voxflex_core::glam::{DMat3, DVec3};

/// What the solver needs of one element of `N` nodes.
pub(super) trait Tet<const N: usize>: Sync {
    /// Node indices.
    fn nodes(&self) -> [u32; N];
    /// `k[N a + b]` = warped stiffness, `f0[a]` = force offset, with the
    /// rotations' own stiffness as `twist` says.
    fn linearise(&self, u: [DVec3; N], k: &mut [DMat3], f0: &mut [DVec3], twist: Twist);
    /// Elastic force per node, µN.
    fn force(&self, u: [DVec3; N]) -> [DVec3; N];
    /// Both, from one rotation (per Gauss point): µN per node, µN·mm.
    fn force_and_energy(&self, u: [DVec3; N]) -> ([DVec3; N], f64);
}

/// The SVD's twist option of a [`Twist`]: `Some(clamp)` when the
/// rotations' own stiffness is added.
fn twist_clamp(twist: Twist) -> Option<bool> {
    match twist {
        Twist::None => None,
        Twist::Full => Some(false),
        Twist::Clamped => Some(true),
    }
}

impl Tet<4> for Element {
    fn nodes(&self) -> [u32; 4] {
        self.nodes
    }
    fn linearise(&self, u: [DVec3; 4], k: &mut [DMat3], f0: &mut [DVec3], twist: Twist) {
        Element::linearise(self, u, k, f0, twist_clamp(twist));
    }
    fn force(&self, u: [DVec3; 4]) -> [DVec3; 4] {
        self.elastic_force(u)
    }
    fn force_and_energy(&self, u: [DVec3; 4]) -> ([DVec3; 4], f64) {
        Element::force_and_energy(self, u)
    }
}

impl Tet<NODES> for Quadratic {
    fn nodes(&self) -> [u32; NODES] {
        self.nodes
    }
    fn linearise(&self, u: [DVec3; NODES], k: &mut [DMat3], f0: &mut [DVec3], twist: Twist) {
        Quadratic::linearise(self, &u, k, f0, twist_clamp(twist));
    }
    fn force(&self, u: [DVec3; NODES]) -> [DVec3; NODES] {
        self.elastic_force(&u)
    }
    fn force_and_energy(&self, u: [DVec3; NODES]) -> ([DVec3; NODES], f64) {
        Quadratic::force_and_energy(self, &u)
    }
}

/// The solver's elements.
pub(super) enum Elements {
    /// 4-node tetrahedra (`element = "p1"`).
    Linear(Vec<Element>),
    /// 10-node tetrahedra (`element = "p2"`).
    Quadratic(Vec<Quadratic>),
}

/// Per element: warped blocks and force offsets into the scratch arrays.
fn linearise_all<const N: usize, E: Tet<N>>(
    elements: &[E],
    u: &[DVec3],
    k_scale: f64,
    twist: Twist,
    blocks: &mut [DMat3],
    f0: &mut [DVec3],
) {
    blocks
        .par_chunks_mut(N * N)
        .zip(f0.par_chunks_mut(N))
        .zip(elements.par_iter())
        .with_min_len(if N == 4 { 256 } else { 32 })
        .for_each(|((k, f0), e)| {
            e.linearise(e.nodes().map(|n| u[n as usize]), k, f0, twist);
            if k_scale != 1.0 {
                for b in k.iter_mut() {
                    *b *= k_scale;
                }
            }
        });
}

fn forces_all<const N: usize, E: Tet<N>>(elements: &[E], u: &[DVec3]) -> Vec<DVec3> {
    elements
        .par_iter()
        .with_min_len(256)
        .flat_map_iter(|e| e.force(e.nodes().map(|n| u[n as usize])))
        .collect()
}

fn forces_and_energy_all<const N: usize, E: Tet<N>>(
    elements: &[E],
    u: &[DVec3],
) -> (Vec<DVec3>, f64) {
    let per: Vec<([DVec3; N], f64)> = elements
        .par_iter()
        .with_min_len(256)
        .map(|e| e.force_and_energy(e.nodes().map(|n| u[n as usize])))
        .collect();
    let energy = per.iter().map(|(_, w)| w).sum();
    (per.into_iter().flat_map(|(f, _)| f).collect(), energy)
}

impl Elements {
    /// Nodes per element.
    pub(super) fn nodes_per_element(&self) -> usize {
        match self {
            Self::Linear(_) => 4,
            Self::Quadratic(_) => NODES,
        }
    }

    /// Elements.
    pub(super) fn len(&self) -> usize {
        match self {
            Self::Linear(e) => e.len(),
            Self::Quadratic(e) => e.len(),
        }
    }

    /// Every element's warped blocks (`N²` each, scaled by `k_scale`) and
    /// force offsets (`N` each) at displacements `u`.
    pub(super) fn linearise(
        &self,
        u: &[DVec3],
        k_scale: f64,
        twist: Twist,
        blocks: &mut [DMat3],
        f0: &mut [DVec3],
    ) {
        match self {
            Self::Linear(e) => linearise_all(e, u, k_scale, twist, blocks, f0),
            Self::Quadratic(e) => linearise_all(e, u, k_scale, twist, blocks, f0),
        }
    }

    /// [`Elements::forces`] and the total strain energy (µN·mm) at `u`,
    /// from one rotation per element (per Gauss point).
    pub(super) fn forces_and_energy(&self, u: &[DVec3]) -> (Vec<DVec3>, f64) {
        match self {
            Self::Linear(e) => forces_and_energy_all(e, u),
            Self::Quadratic(e) => forces_and_energy_all(e, u),
        }
    }

    /// The elastic force of each element's nodes in turn (`N` per element).
    pub(super) fn forces(&self, u: &[DVec3]) -> Vec<DVec3> {
        match self {
            Self::Linear(e) => forces_all(e, u),
            Self::Quadratic(e) => forces_all(e, u),
        }
    }
}
