//! The keys every mesh-based model shares in its `[model.params.<plugin>]`
//! table: the proxy, the materials, gravity and the `.vtu` export. The
//! other keys of the table belong to the solver ([`split`]).
//!
//! Units (mm-g-s, so stresses come out in pascals): Young's modulus in Pa,
//! density in kg/m³ as users write it (converted to g/mm³ inside), gravity
//! in mm/s², points in world millimetres.

use crate::error::ModelError;
use serde::Deserialize;
use std::path::PathBuf;

/// Where the tetrahedral proxy comes from.
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum ProxySpec {
    /// Hexahedral cells every `step` voxels, five tetrahedra each
    /// ([`crate::proxy::uniform_proxy`]); a cell takes the material of the
    /// voxel at its centre.
    Uniform {
        /// Cell size, voxels (≥ 1).
        #[schemars(extend("unit" = "voxels"), range(min = 1))]
        step: usize,
    },
    /// A label-aware, 2:1-balanced octree with leaves of at most
    /// `max_cell` voxels ([`crate::proxy::octree_proxy`]), hanging nodes
    /// tied to their masters.
    Octree {
        /// Largest leaf, voxels (rounded down to a power of two).
        #[schemars(extend("unit" = "voxels"), range(min = 1))]
        max_cell: usize,
    },
    /// A tetrahedral mesh file: Gmsh `.msh` 4.1 ASCII or TetGen `.node`
    /// (with its `.ele` beside it), in world millimetres; the file's
    /// element tags choose the materials by `label`.
    File {
        /// The mesh file.
        path: PathBuf,
    },
}

/// One material of the material transfer function.
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Name (for `fix` by material and for messages).
    #[serde(default)]
    pub name: Option<String>,
    /// Intensity range `[lo, hi)` of the voxels of this material (proxies
    /// built from the volume).
    #[serde(default)]
    pub range: Option<[f64; 2]>,
    /// Element tag of this material in a mesh file.
    #[serde(default)]
    pub label: Option<u16>,
    /// Young's modulus, Pa (> 0).
    #[schemars(extend("unit" = "Pa"), range(min = 0))]
    pub youngs_modulus: f64,
    /// Poisson ratio (0 ≤ ν < 0.5; default 0.45, near-incompressible soft
    /// tissue).
    #[serde(default = "default_poisson")]
    #[schemars(range(min = 0, max = 0.5))]
    pub poisson_ratio: f64,
    /// Density, kg/m³ (default 1000, water).
    #[serde(default = "default_density")]
    #[schemars(extend("unit" = "kg/m³"), range(min = 0))]
    pub density: f64,
}

fn default_poisson() -> f64 {
    0.45
}
fn default_density() -> f64 {
    1000.0
}

/// The shared keys of a mesh model's table.
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshModelParams {
    /// The proxy; `None` (no `proxy` key) takes the solver's default
    /// ([`crate::mesh_model::MeshSolver::default_proxy`]: uniform cells
    /// with nodes [`crate::mesh_model::MeshSolver::DEFAULT_NODE_SPACING`]
    /// voxels apart).
    #[serde(default)]
    pub proxy: Option<ProxySpec>,
    /// The material transfer function: intensity ranges (or mesh-file
    /// labels) → elastic parameters. The first match wins.
    pub materials: Vec<MaterialSpec>,
    /// Gravity, mm/s² in world axes (default none; Earth is
    /// `[0, 0, -9810]` with z up).
    #[serde(default)]
    #[schemars(extend("unit" = "mm/s²"))]
    pub gravity: [f64; 3],
    /// Writes the deformed proxy to this `.vtu` file after every frame that
    /// changed it (atomically), for ParaView.
    #[serde(default)]
    pub vtu: Option<PathBuf>,
}

/// The keys [`MeshModelParams`] owns.
const SHARED_KEYS: [&str; 4] = ["proxy", "materials", "gravity", "vtu"];

/// Splits a plugin's table (TOML text) into the shared parameters and the
/// solver's own keys (as a table the solver deserialises itself, unknown
/// keys refused there). `plugin` names the table in errors.
pub fn split(plugin: &str, text: &str) -> Result<(MeshModelParams, toml::Table), ModelError> {
    let mut table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| ModelError(format!("{plugin} params: {}", e.message())))?;
    let mut shared = toml::Table::new();
    for key in SHARED_KEYS {
        if let Some(v) = table.remove(key) {
            shared.insert(key.to_string(), v);
        }
    }
    let params: MeshModelParams = shared
        .try_into()
        .map_err(|e: toml::de::Error| ModelError(format!("{plugin} params: {}", e.message())))?;
    params.validate(plugin)?;
    Ok((params, table))
}

/// Deserialises a solver's keys, naming the plugin and the keys it knows in
/// errors.
pub fn solver_params<T: serde::de::DeserializeOwned>(
    plugin: &str,
    rest: toml::Table,
) -> Result<T, ModelError> {
    rest.try_into().map_err(|e: toml::de::Error| {
        ModelError(format!(
            "{plugin} params: {} (shared keys: {})",
            e.message(),
            SHARED_KEYS.join(", ")
        ))
    })
}

impl MeshModelParams {
    fn validate(&self, plugin: &str) -> Result<(), ModelError> {
        let fail = |msg: String| Err(ModelError(format!("{plugin} params: {msg}")));
        // Finite as the f32 the GPU paths narrow them to, not only as f64.
        let f32_finite = |v: f64| v.is_finite() && (v as f32).is_finite();
        if self.materials.is_empty() {
            return fail("`materials` needs at least one material".into());
        }
        for (i, m) in self.materials.iter().enumerate() {
            let at = format!("materials[{i}]");
            if !(f32_finite(m.youngs_modulus) && m.youngs_modulus > 0.0) {
                return fail(format!(
                    "{at}: youngs_modulus {} must be a positive number of pascals (within f32)",
                    m.youngs_modulus
                ));
            }
            if !(0.0..0.5).contains(&m.poisson_ratio) {
                return fail(format!(
                    "{at}: poisson_ratio {} must lie in [0, 0.5)",
                    m.poisson_ratio
                ));
            }
            if !(f32_finite(m.density) && m.density > 0.0) {
                return fail(format!(
                    "{at}: density {} must be positive (kg/m³, within f32)",
                    m.density
                ));
            }
            if let Some(r) = m.range
                && r[0].partial_cmp(&r[1]) != Some(std::cmp::Ordering::Less)
            {
                return fail(format!("{at}: range {r:?} must have lo < hi"));
            }
            if m.range.is_none() && m.label.is_none() {
                return fail(format!(
                    "{at}: give an intensity `range = [lo, hi]` or a mesh-file `label`"
                ));
            }
        }
        if self.gravity.iter().any(|&g| !f32_finite(g)) {
            return fail(format!(
                "gravity {:?} must be finite (mm/s², within f32)",
                self.gravity
            ));
        }
        match self.proxy {
            Some(ProxySpec::Uniform { step: 0 }) => {
                fail("proxy.step must be at least 1 voxel".into())
            }
            Some(ProxySpec::Octree { max_cell: 0 }) => {
                fail("proxy.max_cell must be at least 1 voxel".into())
            }
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_beyond_f32_are_refused_naming_the_key() {
        for (text, key) in [
            (
                "materials = [{ range = [0, 1], youngs_modulus = 1e39 }]",
                "youngs_modulus",
            ),
            (
                "materials = [{ range = [0, 1], youngs_modulus = 1, density = 1e300 }]",
                "density",
            ),
            (
                "materials = [{ range = [0, 1], youngs_modulus = 1 }]\ngravity = [0, 0, -1e39]",
                "gravity",
            ),
        ] {
            let e = split("fem", text).unwrap_err().0;
            assert!(e.contains(key) && e.contains("f32"), "{text}: {e}");
        }
    }

    #[test]
    fn shared_and_solver_keys_are_split_and_named_in_errors() {
        let (p, rest) = split(
            "fem",
            "materials = [{ range = [0, 100], youngs_modulus = 3000 }]\n\
             proxy = { kind = \"octree\", max_cell = 8 }\ncg_tolerance = 1e-6",
        )
        .unwrap();
        assert_eq!(p.proxy, Some(ProxySpec::Octree { max_cell: 8 }));
        assert_eq!(p.materials[0].poisson_ratio, 0.45);
        assert!(rest.contains_key("cg_tolerance") && rest.len() == 1);
        let e = split("fem", "materials = []").unwrap_err().0;
        assert!(e.contains("fem params") && e.contains("`materials`"), "{e}");
        let e = split(
            "fem",
            "materials = [{ range = [0, 1], youngs_modulus = 1, poisson_ratio = 0.5 }]",
        )
        .unwrap_err()
        .0;
        assert!(
            e.contains("materials[0]") && e.contains("poisson_ratio"),
            "{e}"
        );
        let e = split(
            "fem",
            "materials = [{ range = [0, 1], youngs_modulus = -1 }]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("youngs_modulus"), "{e}");
        let e = split(
            "fem",
            "materials = [{ range = [0, 1], youngs_modulus = 1 }]\nproxy = { kind = \"uniform\", step = 0 }",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("proxy.step"), "{e}");
        let e = split(
            "fem",
            "materials = [{ range = [0, 1], youngs_modulus = 1, colour = 2 }]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("colour"), "{e}");
        #[derive(Debug, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct Solver {
            cg_tolerance: f64,
        }
        let e = solver_params::<Solver>(
            "fem",
            toml::Table::from_iter([("cg_tolerence".to_string(), toml::Value::Float(1.0))]),
        )
        .unwrap_err()
        .0;
        assert!(
            e.contains("cg_tolerence") && e.contains("shared keys"),
            "{e}"
        );
    }
}
