//! The CPU raster's work counters (cargo feature `counters`) count what
//! the kernel does: run with
//! `cargo test -p voxflex-resample --features counters --test raster_counters`
//! (`scripts/test.sh` does). Without the feature this file is empty.
#![cfg(feature = "counters")]

use glam::DVec3;
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::grid::Grid;
use voxflex_resample::parity::{Field, head_i16, twist_z};
use voxflex_resample::{ResampleParams, Resampler, last_raster_counts};

/// Output voxels with a value other than the background (an owner).
fn covered(values: &[f32], background: f32) -> u64 {
    values.iter().filter(|&&v| v != background).count() as u64
}

#[test]
fn counts_bound_each_other_and_the_output() {
    let grid = Grid::new([40, 36, 33], DVec3::new(1.0, 1.1, 1.3), DVec3::ZERO);
    let vol = head_i16(&grid);
    let centre = grid.index_to_world(DVec3::new(20.0, 18.0, 16.0));
    for (name, rad_per_mm) in [("twist", 0.02), ("mirrored twist", -0.02)] {
        let field = Field::from_map(&grid, twist_z(centre, rad_per_mm).0);
        let params = ResampleParams::default();
        let background = params.background;
        let mut r = Resampler::new(params);
        r.resample_cpu(vol.view(), field.as_ref(), None, DirtyRegion::All)
            .unwrap();
        let c = last_raster_counts().expect("the feature is on");
        let out = r.cpu_values().unwrap();
        let mesh_cells = (39 * 35 * 32) as u64;
        assert_eq!(c.mesh_cells, mesh_cells, "{name}");
        assert_eq!(c.output_voxels, out.len() as u64, "{name}");
        // Every cell goes through the lanes at least once (a full resample
        // of a moved mesh: no still blocks), cells of straddling blocks more.
        assert!(c.cells >= mesh_cells, "{name}: {c:?}");
        assert!(c.busy_cells <= c.cells, "{name}: {c:?}");
        assert!(c.busy_groups * 8 >= c.busy_cells, "{name}: {c:?}");
        assert!(c.tested <= 8 * c.iterations, "{name}: {c:?}");
        assert!(c.found <= c.tested && c.claims <= c.found, "{name}: {c:?}");
        // Every voxel with an owner was claimed at least once (the head's
        // air is −1000, never the background 0).
        assert!(c.claims >= covered(out, background), "{name}: {c:?}");
        assert!(covered(out, background) > mesh_cells / 2, "{name}: {c:?}");
    }
}
