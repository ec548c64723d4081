//! The template plugin (`plugins/template`) through the real path: the
//! built `libvoxflex_template.so` is listed by `voxflex plugins`, a scene
//! that names it runs and deforms the volume where (and only where) its
//! ball is, and its WGSL field matches its rayon field through the C ABI.
//! `scripts/new-plugin.sh` copies this file along with the plugin, so a new
//! plugin starts with these checks.

use std::sync::Arc;
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::{GpuService, LimitedDevice};
use voxflex_core::grid::Grid;
use voxflex_integration_tests::*;
use voxflex_runtime::gpu_context::testing::test_gpu;

/// The plugin's name, as a scene writes it.
const PLUGIN: &str = "template";

#[test]
fn template_plugin_is_listed_by_voxflex_plugins() {
    let dir = plugin_dir(&[PLUGIN]);
    let o = voxflex(&["plugins"], &repo_root());
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out
        .lines()
        .find(|l| l.starts_with(&format!("{PLUGIN} ")))
        .unwrap_or_else(|| panic!("`{PLUGIN}` is not listed:\n{out}"));
    assert!(
        line.contains("deformation")
            && line.contains("cpu, gpu")
            && line.contains(&dir.display().to_string()),
        "{line}"
    );
}

/// Runs the plugin on `phantom:cube` (`n`³ voxels) with its ball inside the
/// cube, 3 voxels below the +x face, and returns the source and the output.
fn bulge_the_cube(
    backend: &str,
    amplitude_voxels: f64,
) -> (
    voxflex_core::volume::Volume,
    voxflex_core::volume::Volume,
    DVec3,
    f64,
) {
    plugin_dir(&[PLUGIN]);
    let n = 32;
    let source = voxflex_phantom::phantom("cube", [n, n, n]).unwrap();
    let s = source.grid.spacing.x;
    // The cube fills voxels n/4 … n − n/4 − 1; its +x face lies half a voxel
    // past the last one.
    let face = source
        .grid
        .index_to_world(DVec3::new((n - n / 4) as f64 - 0.5, 0.0, 0.0))
        .x;
    let centre = DVec3::new(face - 3.0 * s, 0.0, 0.0);
    let radius = 6.0 * s;
    let params = format!(
        "centre = [{}, 0, 0]\nradius_mm = {radius}\namplitude_mm = {}\nramp_frames = 2",
        centre.x,
        amplitude_voxels * s
    );
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let text_of_scene = scene(backend, "cube", n, 3, PLUGIN, &params, &out);
    std::fs::write(tmp.path().join("s.toml"), text_of_scene).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&out);
    assert_eq!(m["plugin"]["name"], PLUGIN, "{m}");
    let output =
        voxflex_io::read_volume(&out.join("deformed.nii.gz"), &Default::default()).unwrap();
    (source, output, centre, radius)
}

#[test]
fn a_template_plugin_scene_bulges_the_cube_only_inside_its_ball() {
    let (source, output, centre, radius) = bulge_the_cube("cpu", 8.0);
    assert_eq!(
        output.grid.dims, source.grid.dims,
        "the output grid changed"
    );
    assert!((output.grid.origin - source.grid.origin).length() < 1e-6);
    let (src, out) = (
        source.data.as_slice().to_f32_vec(),
        output.data.as_slice().to_f32_vec(),
    );
    let s = source.grid.spacing.max_element();
    let (mut unchanged_far, mut changed_near) = (0, 0);
    for (l, (a, b)) in src.iter().zip(&out).enumerate() {
        let [i, j, k] = source.grid.unlinear(l);
        let p = source
            .grid
            .index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        let r = p.distance(centre);
        if r > radius + 2.0 * s {
            // Outside the ball (and the cells touching it) the resampler
            // keeps every source value bit for bit.
            assert_eq!(
                a, b,
                "voxel [{i}, {j}, {k}] at {r:.2} mm from the centre changed"
            );
            unchanged_far += 1;
        } else if a != b {
            changed_near += 1;
        }
    }
    assert!(unchanged_far > src.len() / 2, "{unchanged_far}");
    assert!(changed_near > 0, "nothing changed inside the ball");
    // The bulge pushes the cube's +x face outwards: more cube voxels, and
    // the background voxel 1.5 voxels past the face now holds cube tissue.
    let cube = |v: &[f32]| v.iter().filter(|&&x| x >= 50.0).count();
    assert!(cube(&out) > cube(&src), "{} vs {}", cube(&out), cube(&src));
    let past_face = source.grid.linear(25, 16, 16);
    assert_eq!(src[past_face], 0.0);
    assert!(out[past_face] > 50.0, "{}", out[past_face]);
}

#[test]
fn a_negative_amplitude_dents_the_cube() {
    let (source, output, _, _) = bulge_the_cube("cpu", -8.0);
    let cube = |v: &[f32]| v.iter().filter(|&&x| x >= 50.0).count();
    let (src, out) = (
        source.data.as_slice().to_f32_vec(),
        output.data.as_slice().to_f32_vec(),
    );
    assert!(cube(&out) < cube(&src), "{} vs {}", cube(&out), cube(&src));
}

#[test]
fn bad_template_params_are_refused_by_validate_naming_the_key() {
    plugin_dir(&[PLUGIN]);
    let tmp = tempfile::tempdir().unwrap();
    let s = scene(
        "cpu",
        "cube",
        12,
        1,
        PLUGIN,
        "radius_mm = -1\namplitude_mm = 2",
        &tmp.path().join("o"),
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["validate", "s.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("radius_mm"),
        "{}",
        text(&o)
    );
}

/// On the device as it is, and on one that binds at most 4 KiB per
/// storage array, where the 11,220-point lattice and its 3,740-point list
/// are written in slabs (the wrapper refuses any larger or misaligned
/// binding).
#[test]
fn template_plugin_wgsl_field_matches_its_rayon_field() {
    let Some(gpu) = test_gpu() else { return };
    let gpu: Arc<dyn GpuService> = gpu;
    let small: Arc<dyn GpuService> = Arc::new(LimitedDevice::binding(gpu.clone(), 4096));
    let grid = Grid::centred([33, 20, 17], DVec3::new(0.9, 1.1, 2.5));
    let params = [
        "radius_mm = 12\namplitude_mm = 6",
        "centre = [4, -3, 2]\nradius_mm = 9\namplitude_mm = -5\nramp_frames = 4",
    ];
    assert_field_parity(&[gpu, small], PLUGIN, &params, grid, 3, 1e-5);
}
