//! What the *Rendering* panel needs to know about the renderer and the
//! volume, gathered on the worker once a volume is open: the renderer's
//! parameters as opened, its transfer-function presets (read from the
//! plugin's parameter schema), the source volume's histogram, its bounds
//! and value range; and [`sync_shown`], which hands the renderer only the
//! ROI maps the panel shows.

use crate::histogram::BINS;
use voxflex_core::glam::DVec3;
use voxflex_runtime::param_schema::{ParamKind, ParamSchema};
use voxflex_runtime::session::{Histogram, RenderParams, RoiId, Session};

/// The renderer and volume facts the *Rendering* panel starts from.
#[derive(Clone, Debug)]
pub struct RenderInfo {
    /// The renderer's parameters as opened (a `[render.params]` table).
    pub params_toml: String,
    /// The renderer's transfer-function presets (empty when its schema
    /// names none).
    pub presets: Vec<String>,
    /// The source volume's values ([`BINS`] bins).
    pub histogram: Histogram,
    /// The source volume's voxel-centre box, world mm (lower, upper).
    pub bounds: (DVec3, DVec3),
    /// The source volume's value range (volume units).
    pub range: (f64, f64),
}

/// Gathers [`RenderInfo`] for `session` rendered with `render`.
pub fn render_info(session: &Session, render: &RenderParams) -> anyhow::Result<RenderInfo> {
    let source = session.source();
    let (lo, hi) = source.value_range();
    let schema = session
        .plugins()
        .plugins
        .into_iter()
        .find(|p| p.loads && p.plugin.name == render.plugin)
        .map(|p| p.plugin.params);
    Ok(RenderInfo {
        params_toml: render.params_toml.clone(),
        presets: schema.as_ref().map(preset_names).unwrap_or_default(),
        histogram: session.histogram(BINS)?,
        bounds: source.grid.world_bounds(),
        range: (f64::from(lo), f64::from(hi)),
    })
}

/// The preset names a renderer's schema documents for
/// `transfer_function.preset`: the `code` spans of its doc line (the
/// raycast plugin's "A built-in preset name (`ct-bone`, …)").
pub fn preset_names(schema: &ParamSchema) -> Vec<String> {
    let Some(ParamKind::Table(fields)) = schema.get("transfer_function").map(|s| &s.kind) else {
        return vec![];
    };
    let Some(doc) = fields.iter().find(|f| f.name == "preset").map(|f| &f.doc) else {
        return vec![];
    };
    doc.split('`')
        .skip(1)
        .step_by(2)
        .filter(|s| !s.is_empty() && !s.contains(char::is_whitespace))
        .map(str::to_owned)
        .collect()
}

/// Shows in the session's renders every ROI map but those in `hidden`;
/// true when that changed what is shown.
pub fn sync_shown(session: &mut Session, hidden: &[RoiId]) -> bool {
    let mut changed = false;
    for info in session.rois() {
        let shown = !hidden.contains(&info.id);
        if session.roi_shown(info.id) != shown {
            changed |= session.set_roi_shown(info.id, shown).is_ok();
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preset_names_are_the_code_spans_of_the_preset_doc() {
        let schema = ParamSchema::from_json(
            r#"{"type": "object", "properties": {"transfer_function": {"type": "object",
                "properties": {"preset": {"type": ["string", "null"],
                "description": "A built-in preset name (`ct-bone`, `mri-t1`)."}}}}}"#,
        )
        .unwrap();
        assert_eq!(preset_names(&schema), ["ct-bone", "mri-t1"]);
        let none = ParamSchema::from_json(r#"{"type": "object", "properties": {}}"#).unwrap();
        assert!(preset_names(&none).is_empty());
    }
}
