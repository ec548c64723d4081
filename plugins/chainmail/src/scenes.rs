//! The head-pull scene the rest test and the `rest` bench share: a cube
//! crop of `phantom:head` with the materials of
//! `configs/chainmail-head.toml` (fat, soft tissue, rigid bone), the skull
//! fixed, and the scalp on one side pulled out by a grab.
//!
//! Geometry: the phantom is generated at `200 / n` mm isotropic spacing
//! (its 200 mm width in `n` voxels) and cropped to `n³` voxels centred in
//! y and z, so the crop holds the whole width of the head and cuts its
//! front, back, top and bottom open. Positions are world mm (LPS).

use crate::model::ChainMail;
use crate::params::{ChainMailParams, InteractionSpec};
use voxflex_core::volume::Volume;
use voxflex_phantom::{HEAD_SIZE_MM, phantom};

/// The materials of `configs/chainmail-head.toml`.
pub const HEAD_MATERIALS: &str = "materials = [\n\
  { name = \"fat\", range = [-150, -50], constraint = 0.4, elastic = 0.6 },\n\
  { name = \"soft tissue\", range = [-50, 300], constraint = 0.3, elastic = 0.8 },\n\
  { name = \"bone\", range = [300, 4000], constraint = 0, rigid = true },\n]";

/// A head pull, as a scene: the volume, the `[model.params]` TOML and the
/// interactions' TOML, in order (see [`head_pull`]).
pub fn head_pull_scene(
    n: usize,
    pull_mm: f64,
    frames: u64,
    mirrored: bool,
    fix_skull: bool,
    extra: &str,
) -> (Volume, String, Vec<String>) {
    let h = HEAD_SIZE_MM.x / n as f64;
    let dims = [
        n,
        (HEAD_SIZE_MM.y / h).round() as usize,
        (HEAD_SIZE_MM.z / h).round() as usize,
    ];
    let v = phantom("head", dims).expect("head phantom");
    let lo = [0, (dims[1] - n) / 2, (dims[2] - n) / 2];
    let hi = lo.map(|l| l + n - 1);
    let params = format!("{extra}\ncrop = {{ min = {lo:?}, max = {hi:?} }}\n{HEAD_MATERIALS}");
    let mut interactions = Vec::new();
    if fix_skull {
        interactions.push("kind = \"fix\"\nmaterial = \"bone\"".to_owned());
    }
    let s = if mirrored { -1.0 } else { 1.0 };
    interactions.push(format!(
        "kind = \"grab\"\npoint = [{:?}, 0.0, 20.0]\nby = [{:?}, 0.0, 0.0]\nframes = {frames}",
        s * 90.0,
        s * pull_mm
    ));
    (v, params, interactions)
}

/// A head pull: an `n³` crop of `phantom:head`, the skull fixed when
/// `fix_skull` (`fix` with `material = "bone"`, as the head scene does;
/// otherwise the rigid skull moves with the tissue), and the scalp at
/// `x = ±90 mm, y = 0, z = 20 mm` grabbed and pulled out along ±x by
/// `pull_mm` over `frames` frames (`mirrored`: the −x side, pulled
/// towards −x). `extra` is added to `[model.params]` (e.g.
/// `over_relaxation = 1`).
pub fn head_pull(
    n: usize,
    pull_mm: f64,
    frames: u64,
    mirrored: bool,
    fix_skull: bool,
    extra: &str,
) -> ChainMail {
    let (v, params, interactions) = head_pull_scene(n, pull_mm, frames, mirrored, fix_skull, extra);
    let params = ChainMailParams::from_toml(&params).expect("head scene parameters");
    let mut m = ChainMail::new(v.view(), params).expect("head model");
    for i in interactions {
        let spec = InteractionSpec::from_toml(&i).expect("head scene interaction");
        m.interact(&spec).expect("head scene interaction");
    }
    m
}
