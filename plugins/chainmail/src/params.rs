//! The plugin's parameters (the scene's `[model.params]` table) and its
//! interactions (`[[interaction]]` tables).
//!
//! Units: intensities are the source volume's values; constraints are
//! fractions of the element spacing (dimensionless); points and offsets are
//! world millimetres.

use serde::Deserialize;
use voxflex_core::error::ModelError;

/// Which propagation algorithm runs.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, schemars::JsonSchema, serde::Serialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Algorithm {
    /// Timestamp propagation with wavefront counters, Jacobi iterations over
    /// active blocks (rayon), then weighted relaxation.
    #[default]
    Parallel,
    /// The sequential Gibson 3D ChainMail (breadth-first, each element moved
    /// at most once per deformation), then the same relaxation run serially:
    /// the correctness and speed baseline.
    Sequential,
}

/// How the parallel propagation finds its work.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, schemars::JsonSchema, serde::Serialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Schedule {
    /// Active blocks (`block` elements each) in one launch per iteration.
    #[default]
    Blocks,
    /// An element work-list: the elements that moved and their neighbours.
    Frontier,
}

/// A link constraint: the half-size of the box a neighbour may occupy around
/// its rest offset, as a fraction of the element spacing, on all axes or per
/// axis.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Constraint {
    /// The same fraction on x, y and z.
    Isotropic(f64),
    /// `[x, y, z]` fractions.
    PerAxis([f64; 3]),
}

impl Constraint {
    /// The per-axis fractions.
    pub fn per_axis(self) -> [f64; 3] {
        match self {
            Constraint::Isotropic(c) => [c; 3],
            Constraint::PerAxis(c) => c,
        }
    }
}

/// One entry of the material transfer function: voxels whose intensity is in
/// `range` (`lo ≤ v < hi`) become elements of this material.
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// A name for logs and metrics.
    #[serde(default)]
    pub name: Option<String>,
    /// Intensity range `[lo, hi)`.
    pub range: [f64; 2],
    /// Constraint (fraction of the element spacing; 0 ≤ c ≤ 8).
    pub constraint: Constraint,
    /// Fraction of the relaxation move applied per iteration (1 elastic,
    /// 0 plastic: keeps its deformation).
    #[serde(default = "one")]
    #[schemars(range(min = 0, max = 1))]
    pub elastic: f64,
    /// Rigid: constraint 0, so links inside the material never stretch,
    /// shear or compress (the material translates with its neighbours).
    #[serde(default)]
    pub rigid: bool,
}

fn one() -> f64 {
    1.0
}

/// Voxel-index box (inclusive) the model is cropped to.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Crop {
    /// Lower corner, voxel indices of the source volume.
    pub min: [usize; 3],
    /// Upper corner (inclusive), voxel indices.
    pub max: [usize; 3],
}

/// Parameters of the `chainmail` plugin (`[model.params]`).
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChainMailParams {
    /// `"parallel"` (default) or `"sequential"`.
    #[serde(default)]
    pub algorithm: Algorithm,
    /// The material transfer function; voxels matching no entry are not
    /// elements (air, background, unlabelled).
    pub materials: Vec<Material>,
    /// One element per `downsample` voxels along each axis (default 1).
    #[serde(default = "default_downsample")]
    #[schemars(extend("unit" = "voxels"), range(min = 1, max = 64))]
    pub downsample: usize,
    /// Optional crop of the source volume (voxel indices, inclusive).
    #[serde(default)]
    pub crop: Option<Crop>,
    /// Propagation iterations per frame (parallel algorithm; default 10).
    #[serde(default = "default_iterations")]
    pub propagation_iterations: usize,
    /// Relaxation iterations per frame (default 10).
    #[serde(default = "default_iterations")]
    pub relaxation_iterations: usize,
    /// `"blocks"` (default) or `"frontier"` (see [`Schedule`]).
    #[serde(default)]
    pub schedule: Schedule,
    /// Elements per scheduling block `[x, y, z]` (default `[8, 4, 4]`, the
    /// fastest in `benches/chainmail.rs` on 2 cores).
    #[serde(default = "default_block")]
    pub block: [usize; 3],
    /// Relaxation stops when no element moves more than this fraction of
    /// the element spacing in an iteration (default 1e-4).
    #[serde(default = "default_rest_tolerance")]
    #[schemars(range(min = 0, max = 1))]
    pub rest_tolerance: f64,
    /// Over-relaxation factor ω of the relaxation sweeps, in (0, 2): each
    /// element moves `ω · elastic` of the way to its neighbours' weighted
    /// mean. 1 is plain (Gauss-Seidel) relaxation, which needs on the order
    /// of `L²` sweeps to settle a region `L` elements across; absent (the
    /// default) picks `2 / (1 + sin(π / L))` for the lattice's largest side
    /// `L` (successive over-relaxation: on the order of `L` sweeps),
    /// divided by the largest `elastic` (see [`ChainMailParams::omega`]).
    /// Explicit values must keep `ω · elastic < 2` for every material.
    #[serde(default)]
    pub over_relaxation: Option<f64>,
}

fn default_downsample() -> usize {
    1
}
fn default_iterations() -> usize {
    10
}
fn default_block() -> [usize; 3] {
    [8, 4, 4]
}
fn default_rest_tolerance() -> f64 {
    1e-4
}

impl ChainMailParams {
    /// The over-relaxation factor for a lattice whose largest side is `l`
    /// elements (see [`ChainMailParams::over_relaxation`]). The automatic
    /// choice is divided by the largest `elastic` fraction of a non-rigid
    /// material, so the most elastic steps by exactly `2 / (1 + sin(π / l))`
    /// and every product `ω · elastic` of those stays below 2 (a rigid
    /// element cannot move in relaxation: its links allow one position).
    pub fn omega(&self, l: usize) -> f64 {
        self.over_relaxation.unwrap_or_else(|| {
            let best = 2.0 / (1.0 + (std::f64::consts::PI / l.max(2) as f64).sin());
            // Rigid materials are held by their own links (a box of size
            // 0), whatever their elastic fraction.
            let most = self
                .materials
                .iter()
                .filter(|m| !m.rigid)
                .map(|m| m.elastic)
                .fold(0.0, f64::max);
            if most > 0.0 { best / most } else { 1.0 }
        })
    }
}

/// Largest constraint fraction: keeps arrival times inside their 20 bits
/// for volumes up to 512 elements a side (see `state`).
pub const MAX_CONSTRAINT: f64 = 8.0;

/// Materials one model may hold (one byte per element holds the index).
pub const MAX_MATERIALS: usize = 120;

impl ChainMailParams {
    /// Parses and validates `[model.params]`; errors name the key.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let p: ChainMailParams = toml::from_str(text)
            .map_err(|e| ModelError(format!("chainmail [model.params]: {}", e.message())))?;
        p.validate()?;
        Ok(p)
    }

    fn validate(&self) -> Result<(), ModelError> {
        let bad = |key: &str, msg: String| Err(ModelError(format!("chainmail `{key}`: {msg}")));
        if self.materials.is_empty() {
            return bad(
                "materials",
                "needs at least one material, e.g. materials = [{ range = [0, 1e9], constraint = 0.2 }]".into(),
            );
        }
        if self.materials.len() > MAX_MATERIALS {
            return bad(
                "materials",
                format!(
                    "{} materials; at most {MAX_MATERIALS}",
                    self.materials.len()
                ),
            );
        }
        for (i, m) in self.materials.iter().enumerate() {
            let key = format!("materials[{i}]");
            let [lo, hi] = m.range;
            if !(lo.is_finite() || lo == f64::NEG_INFINITY) || hi.is_nan() || lo >= hi {
                return bad(&key, format!("range [{lo}, {hi}] must have lo < hi"));
            }
            for c in m.constraint.per_axis() {
                if !(0.0..=MAX_CONSTRAINT).contains(&c) {
                    return bad(
                        &key,
                        format!(
                            "constraint {c} must be in [0, {MAX_CONSTRAINT}] (a fraction of the element spacing)"
                        ),
                    );
                }
            }
            if !(0.0..=1.0).contains(&m.elastic) {
                return bad(&key, format!("elastic {} must be in [0, 1]", m.elastic));
            }
        }
        if self.downsample == 0 || self.downsample > 64 {
            return bad(
                "downsample",
                format!("{} must be in 1..=64", self.downsample),
            );
        }
        if self.block.iter().any(|&b| b == 0 || b > 256) {
            return bad(
                "block",
                format!("{:?}: each entry must be in 1..=256", self.block),
            );
        }
        if !(self.rest_tolerance > 0.0 && self.rest_tolerance < 1.0) {
            return bad(
                "rest_tolerance",
                format!("{} must be in (0, 1)", self.rest_tolerance),
            );
        }
        let most = self.materials.iter().map(|m| m.elastic).fold(0.0, f64::max);
        if let Some(w) = self.over_relaxation
            && !(w > 0.0 && w * most < 2.0)
        {
            return bad(
                "over_relaxation",
                format!(
                    "{w} must be positive with {w} × the largest elastic ({most}) below 2 \
                     (1 = plain relaxation; leave it out for the automatic choice)"
                ),
            );
        }
        if let Some(c) = self.crop
            && (0..3).any(|a| c.min[a] > c.max[a])
        {
            return bad("crop", format!("min {:?} exceeds max {:?}", c.min, c.max));
        }
        Ok(())
    }
}

pub use voxflex_core::interaction::InteractionSpec;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_materials_parse() {
        let p = ChainMailParams::from_toml(
            r#"materials = [
                { name = "soft", range = [0, 150], constraint = 0.2 },
                { range = [150, 300], constraint = [0.1, 0.2, 0.3], elastic = 0.5 },
                { range = [300, 1e9], constraint = 0, rigid = true },
            ]"#,
        )
        .unwrap();
        assert_eq!(p.algorithm, Algorithm::Parallel);
        assert_eq!(p.block, [8, 4, 4]);
        assert_eq!(p.materials[1].constraint.per_axis(), [0.1, 0.2, 0.3]);
        assert!(p.materials[2].rigid);
    }

    #[test]
    fn errors_name_the_key() {
        let e = ChainMailParams::from_toml("materials = []").unwrap_err().0;
        assert!(e.contains("`materials`"), "{e}");
        let e = ChainMailParams::from_toml("materials = [{ range = [0, 1], constraint = 20 }]")
            .unwrap_err()
            .0;
        assert!(
            e.contains("materials[0]") && e.contains("constraint 20"),
            "{e}"
        );
        let e = ChainMailParams::from_toml(
            "materials = [{ range = [0, 1], constraint = 0.1 }]\nblok = [1, 1, 1]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("blok"), "{e}");
    }
}
