//! Resampler accuracy through the real path: the `affine` plugin (loaded
//! from its shared library) maps the implicit sampling mesh; voxflex-core
//! resamples; every output voxel is checked against the analytic answer.
//!
//! - On a linear ramp, piecewise-linear interpolation is exact, so the
//!   resampled volume must equal the backward-mapped ramp to float precision
//!   (≤ 1e-4 of the data range).
//! - On the head phantom, the error against *direct* analytic resampling
//!   (trilinear sampling of the source at the inverse-mapped point) is
//!   reported and bounded.

use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_core::deformation::{
    DeformationModel, DisplacementTarget, ExecutionBackend, FrameInfo, RestPoints,
};
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::volume::Volume;
use voxflex_integration_tests::*;
use voxflex_resample::{DisplacementsRef, Interpolation, ResampleParams, Resampler};

/// Maps `volume` with the affine plugin's `params` and resamples it on the
/// CPU (default interpolation).
fn deform(volume: &Volume, params: &str) -> (voxflex_core::grid::Grid, Vec<f32>) {
    deform_with(volume, params, Interpolation::default())
}

/// As [`deform`], with the given interpolation.
fn deform_with(
    volume: &Volume,
    params: &str,
    interpolation: Interpolation,
) -> (voxflex_core::grid::Grid, Vec<f32>) {
    let p =
        voxflex_runtime::plugin_loader::load_by_name("affine", &[plugin_dir(&["affine"])]).unwrap();
    let services = HostServices::new(None, 2);
    // SAFETY: checked, never-unloaded library.
    let mut m =
        unsafe { DeformationProxy::create("affine", p.deformation.unwrap(), params, services) }
            .unwrap();
    m.init(volume.view(), ExecutionBackend::Cpu).unwrap();
    let b = m.bind(RestPoints::Lattice(volume.grid)).unwrap();
    m.step(FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 0.0,
    })
    .unwrap();
    let n = volume.grid.len();
    let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
    m.map(
        b,
        DisplacementTarget::Cpu {
            x: &mut x,
            y: &mut y,
            z: &mut z,
        },
    )
    .unwrap();
    let mut r = Resampler::new(ResampleParams {
        background: f32::NAN,
        interpolation,
        ..Default::default()
    });
    r.resample_cpu(
        volume.view(),
        DisplacementsRef {
            x: &x,
            y: &y,
            z: &z,
        },
        None,
        voxflex_core::deformation::DirtyRegion::All,
    )
    .unwrap();
    let out = r.cpu_output().unwrap();
    (out.grid, out.values)
}

/// Inverse maps of the fields used below, world mm → rest world mm.
fn inverse_twist(centre: DVec3, rate: f64) -> impl Fn(DVec3) -> DVec3 {
    move |p| {
        let q = p - centre;
        let (s, c) = (-rate * q.z).sin_cos();
        centre + DVec3::new(c * q.x - s * q.y, s * q.x + c * q.y, q.z)
    }
}

fn inverse_affine(centre: DVec3, m: DMat3, t: DVec3) -> impl Fn(DVec3) -> DVec3 {
    let inv = m.inverse();
    move |p| centre + inv * (p - centre - t)
}

/// Compares every output voxel whose inverse image lies at least one voxel
/// inside the source with `reference(inverse(p))`; returns (max, rms, count).
fn compare(
    volume: &Volume,
    out_grid: &voxflex_core::grid::Grid,
    out: &[f32],
    inverse: impl Fn(DVec3) -> DVec3,
    reference: impl Fn(DVec3) -> f64,
) -> (f64, f64, usize) {
    let g = &volume.grid;
    let (mut max, mut sum2, mut count) = (0f64, 0f64, 0usize);
    for (l, &value) in out.iter().enumerate() {
        let [i, j, k] = out_grid.unlinear(l);
        let p = out_grid.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        let rest = inverse(p);
        let idx = g.world_to_index(rest);
        let inside = (0..3).all(|a| idx[a] >= 1.0 && idx[a] <= (g.dims[a] - 2) as f64);
        if !inside {
            continue;
        }
        assert!(
            value.is_finite(),
            "voxel {l} inside the deformed mesh was not written"
        );
        let e = (value as f64 - reference(rest)).abs();
        max = max.max(e);
        sum2 += e * e;
        count += 1;
    }
    (max, (sum2 / count.max(1) as f64).sqrt(), count)
}

#[test]
fn twist_and_affine_on_a_linear_ramp_are_exact() {
    let volume = voxflex_phantom::ramp([40, 36, 32]);
    let (a, b, c) = voxflex_phantom::RAMP_COEFFS.into();
    let ramp = move |p: DVec3| a * p.x + b * p.y + c * p.z;
    let (lo, hi) = volume.value_range();
    let range = (hi - lo) as f64;
    let centre = volume.grid.centre();
    let extent_z = volume.grid.world_bounds().1.z - volume.grid.world_bounds().0.z;

    let (g, out) = deform(&volume, "field = \"twist\"\naxis = \"z\"\nangle_deg = 50");
    let rate = 50f64.to_radians() / extent_z;
    let (max, _, n) = compare(&volume, &g, &out, inverse_twist(centre, rate), ramp);
    assert!(n > volume.grid.len() / 3, "only {n} voxels compared");
    assert!(
        max <= 1e-4 * range,
        "twist: max error {max} > 1e-4 of range {range}"
    );

    let m =
        DMat3::from_cols_array(&[1.05, 0.1, 0.0, -0.08, 0.95, 0.02, 0.0, 0.05, 1.1]).transpose();
    let t = DVec3::new(3.0, -2.0, 1.5);
    let (g, out) = deform(
        &volume,
        "field = \"affine\"\nmatrix = [[1.05, 0.1, 0.0, 3.0], [-0.08, 0.95, 0.02, -2.0], [0.0, 0.05, 1.1, 1.5]]",
    );
    let (max, _, n) = compare(&volume, &g, &out, inverse_affine(centre, m, t), ramp);
    assert!(n > volume.grid.len() / 3, "only {n} voxels compared");
    assert!(
        max <= 1e-4 * range,
        "affine: max error {max} > 1e-4 of range {range}"
    );
}

/// Trilinear sample of `volume` at a world point (mm).
fn trilinear(volume: &Volume, p: DVec3) -> f64 {
    let g = &volume.grid;
    let idx = g.world_to_index(p);
    let i0 = idx.floor();
    let f = idx - i0;
    let mut v = 0.0;
    for corner in 0..8 {
        let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
        let mut w = 1.0;
        let mut c = [0usize; 3];
        for a in 0..3 {
            w *= if o[a] == 1 { f[a] } else { 1.0 - f[a] };
            c[a] = ((i0[a] as i64 + o[a] as i64).clamp(0, g.dims[a] as i64 - 1)) as usize;
        }
        v += w * volume.get_f32(c[0], c[1], c[2]) as f64;
    }
    v
}

#[test]
fn head_phantom_twist_error_against_direct_analytic_resampling() {
    let volume = voxflex_phantom::phantom("head", [64, 64, 64]).unwrap();
    let centre = volume.grid.centre();
    let extent_z = volume.grid.world_bounds().1.z - volume.grid.world_bounds().0.z;
    let rate = 40f64.to_radians() / extent_z;
    let (lo, hi) = volume.value_range();
    let range = (hi - lo) as f64;
    let mut rms_of = vec![];
    for mode in Interpolation::ALL {
        let (g, out) = deform_with(
            &volume,
            "field = \"twist\"\naxis = \"z\"\nangle_deg = 40",
            mode,
        );
        let (max, rms, n) = compare(&volume, &g, &out, inverse_twist(centre, rate), |p| {
            trilinear(&volume, p)
        });
        eprintln!(
            "head 64³, 40° twist, {mode}: {n} voxels, RMS error {rms:.3} HU ({:.4}% of range), max {max:.2} HU",
            100.0 * rms / range
        );
        assert!(n > volume.grid.len() / 4);
        // Tetrahedral and trilinear interpolation agree at voxel centres and
        // differ inside cells at sharp edges: the RMS stays a small fraction
        // of the range.
        assert!(
            rms < 0.02 * range,
            "{mode}: RMS error {rms} HU is too large for range {range}"
        );
        rms_of.push(rms);
    }
    // Trilinear mode samples like the reference: only the piecewise-linear
    // inverse map's error is left.
    assert!(
        rms_of[1] * 10.0 < rms_of[0],
        "RMS (tetrahedral, trilinear) {rms_of:?}"
    );
}

#[test]
fn identity_field_reproduces_the_volume_exactly() {
    for volume in [
        voxflex_phantom::phantom("head", [33, 40, 37]).unwrap(),
        voxflex_phantom::ramp([20, 17, 9]),
    ] {
        let (g, out) = deform(&volume, "field = \"affine\"");
        assert_eq!(g, volume.grid, "the identity must not grow the output grid");
        let src = volume.data.as_slice().to_f32_vec();
        assert!(
            src.iter()
                .zip(&out)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "identity resample is not bit-exact"
        );
    }
}
