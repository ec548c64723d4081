//! The benchmarks' inputs: the built-in ChainMail head scene at another
//! phantom size, and a CT-like volume file.

use crate::open::BUILT_IN_SCENE;
use anyhow::Context;
use std::path::{Path, PathBuf};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::VoxelData;
use voxflex_phantom::PhantomKind;

/// Writes the built-in scene (head phantom, ChainMail with its
/// materials, CPU or whatever the viewer is asked for) with the phantom at
/// `n`³ voxels as `dir/bench-head-<n>.toml` and returns its path.
pub fn head_scene(dir: &Path, n: usize) -> anyhow::Result<PathBuf> {
    let mut scene: toml::Table = BUILT_IN_SCENE
        .parse()
        .context("parsing the built-in scene")?;
    let volume = scene
        .get_mut("volume")
        .and_then(|v| v.as_table_mut())
        .context("the built-in scene has no [volume] table")?;
    let side = toml::Value::Integer(i64::try_from(n)?);
    volume.insert("dims".into(), toml::Value::Array(vec![side; 3]));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("bench-head-{n}.toml"));
    std::fs::write(&path, toml::to_string(&scene)?)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// The dims of the CT-like volume `n` voxels across: `n × n × n·133/512`
/// (the 512 × 512 × 133 class of head CT at `n` = 512).
pub fn ct_dims(n: usize) -> [usize; 3] {
    [n, n, (n * 133 / 512).max(1)]
}

/// Noise added to every voxel, HU: uniform in ±this (a CT's quantum
/// noise; it also keeps gzip from compressing the file far better than
/// a scan's).
const NOISE_HU: i32 = 15;

/// Writes a CT-like head, `dims` voxels of 0.5 × 0.5 × 1.25 mm at
/// `dims` = 512 × 512 × 133 (the spacing scaled with the size otherwise,
/// so the field of view stays 256 × 256 × 166 mm), int16 HU with
/// ±[`NOISE_HU`] of noise, as gzipped NIfTI `dir/ct-<x>x<y>x<z>.nii.gz`
/// — unless that file is there already (it is deterministic). Returns
/// its path.
pub fn ct_volume(dir: &Path, dims: [usize; 3]) -> anyhow::Result<PathBuf> {
    let path = dir.join(format!("ct-{}x{}x{}.nii.gz", dims[0], dims[1], dims[2]));
    if path.exists() {
        return Ok(path);
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut volume = PhantomKind::Head.generate(dims)?;
    let fov = DVec3::new(256.0, 256.0, 166.25);
    let d = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
    volume.grid = Grid::centred(dims, fov / d);
    if let VoxelData::I16(v) = &mut volume.data {
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        for x in v.iter_mut() {
            // xorshift64: a fixed, cheap stream.
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let noise = (state % (2 * NOISE_HU as u64 + 1)) as i32 - NOISE_HU;
            *x = (*x as i32 + noise).clamp(i16::MIN as i32, i16::MAX as i32) as i16;
        }
    }
    // Written aside and renamed: an interrupted run leaves no half file.
    let tmp = dir.join(format!(
        "partial-{}x{}x{}.nii.gz",
        dims[0], dims[1], dims[2]
    ));
    voxflex_io::write_volume(&tmp, volume.view())
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, &path).with_context(|| format!("naming {}", path.display()))?;
    Ok(path)
}
