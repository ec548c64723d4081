//! Test fixtures of the opacity maps (phantoms, a seeded RNG) and the
//! GPU-versus-CPU checks, written against [`GpuService`] so any crate that
//! owns a real device (the integration tests, through the host's GPU
//! context) can run them.
//!
//! Every `check_*` returns `Err(description)` on the first disagreement.
//! CPU and GPU maps must be identical (the arithmetic is exact; see
//! [`super::extinction`]), and so must the work counts.

use super::cpu::CpuGrowth;
use super::gpu::{GpuGrowth, GpuOpacityVolume};
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::Seed;
use super::state::Growth;
use super::{OpacityError, OpacityMap};
use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::gpu::LimitedDevice;

/// xorshift64* — a tiny deterministic RNG for reproducible noise.
#[derive(Clone, Debug)]
pub struct XorShift(u64);

impl XorShift {
    /// A generator from a seed (0 is replaced by a fixed non-zero state).
    pub fn new(seed: u64) -> Self {
        Self(if seed == 0 {
            0x9E37_79B9_7F4A_7C15
        } else {
            seed
        })
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in (0, 1].
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// A ball of voxels, in **voxel index** units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre, voxel index units.
    pub centre: [f64; 3],
    /// Radius, voxels.
    pub radius: f64,
    /// Value inside (before noise).
    pub value: f32,
}

impl Sphere {
    /// True when the centre of voxel `v` lies inside.
    pub fn contains(&self, v: [usize; 3]) -> bool {
        let d2: f64 = (0..3).map(|a| (v[a] as f64 - self.centre[a]).powi(2)).sum();
        d2 <= self.radius * self.radius
    }

    /// The voxel nearest the centre.
    pub fn centre_voxel(&self) -> [usize; 3] {
        self.centre.map(|c| c.round() as usize)
    }
}

/// Three spheres in a noisy background: `a` (100) and `b` (close
/// intensity, 115 by default) overlapping by half a voxel along +x (a
/// contact disc), `c` (300) overlapping `a` by half a voxel along +y;
/// background 0; Gaussian noise of standard deviation `noise` everywhere.
/// Where spheres overlap, `a` wins.
#[derive(Clone, Debug)]
pub struct Phantom {
    /// The f32 volume, an `n³` grid of spacing (0.8, 1.0, 1.25) mm.
    pub volume: Volume,
    /// The seed region (100).
    pub a: Sphere,
    /// The close-intensity neighbour.
    pub b: Sphere,
    /// The different neighbour (300).
    pub c: Sphere,
}

impl Phantom {
    /// Which sphere holds voxel `v` (`a` wins overlaps): 0 none, 1 a, 2 b, 3 c.
    pub fn label(&self, v: [usize; 3]) -> u8 {
        if self.a.contains(v) {
            1
        } else if self.b.contains(v) {
            2
        } else if self.c.contains(v) {
            3
        } else {
            0
        }
    }
}

/// The three-sphere phantom on an `n³` grid (designed at n = 96: radii 18,
/// 14, 14 voxels; scaled with n), `b` at 115, noise σ = `noise`, RNG seed
/// `seed`.
pub fn three_spheres(n: usize, noise: f32, seed: u64) -> Phantom {
    three_spheres_with(n, 115.0, noise, seed)
}

/// [`three_spheres`] with sphere `b` at `b_value`.
pub fn three_spheres_with(n: usize, b_value: f32, noise: f32, seed: u64) -> Phantom {
    let s = n as f64 / 96.0;
    let a = Sphere {
        centre: [40.0 * s, 48.0 * s, 48.0 * s],
        radius: 18.0 * s,
        value: 100.0,
    };
    let b = Sphere {
        centre: [a.centre[0] + 31.5 * s, a.centre[1], a.centre[2]],
        radius: 14.0 * s,
        value: b_value,
    };
    let c = Sphere {
        centre: [a.centre[0], a.centre[1] + 31.5 * s, a.centre[2]],
        radius: 14.0 * s,
        value: 300.0,
    };
    let grid = Grid::new(
        [n; 3],
        DVec3::new(0.8, 1.0, 1.25),
        DVec3::new(-30.0, -40.0, 10.0),
    );
    let mut rng = XorShift::new(seed);
    let mut p = Phantom {
        volume: Volume {
            grid,
            data: VoxelData::F32(Vec::new()),
        },
        a,
        b,
        c,
    };
    let values = (0..grid.len())
        .map(|l| {
            let v = grid.unlinear(l);
            let base = match p.label(v) {
                1 => a.value,
                2 => b.value,
                3 => c.value,
                _ => 0.0,
            };
            base + noise * rng.normal() as f32
        })
        .collect();
    p.volume.data = VoxelData::F32(values);
    p
}

/// An i16 volume of `n³` unit voxels: a ball of radius `radius` voxels at
/// the centre, value 100, in 0, plus Gaussian noise of σ `noise` (rounded).
pub fn noisy_ball_i16(n: usize, radius: f64, noise: f64, seed: u64) -> Volume {
    let grid = Grid::centred([n; 3], DVec3::ONE);
    let c = (n as f64 - 1.0) / 2.0;
    let ball = Sphere {
        centre: [c; 3],
        radius,
        value: 100.0,
    };
    let mut rng = XorShift::new(seed);
    let values = (0..grid.len())
        .map(|l| {
            let base = if ball.contains(grid.unlinear(l)) {
                100.0
            } else {
                0.0
            };
            (base + noise * rng.normal()).round() as i16
        })
        .collect();
    Volume {
        grid,
        data: VoxelData::I16(values),
    }
}

/// Dice coefficient of `{v : map(v) ≥ 0.5}` against `truth` over a volume of
/// `dims`.
pub fn dice(map: &OpacityMap, dims: [usize; 3], truth: impl Fn([usize; 3]) -> bool) -> f64 {
    let (mut both, mut m, mut t) = (0u64, 0u64, 0u64);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let a = map.get(i, j, k) >= 0.5;
                let b = truth([i, j, k]);
                both += (a && b) as u64;
                m += a as u64;
                t += b as u64;
            }
        }
    }
    if m + t == 0 {
        1.0
    } else {
        2.0 * both as f64 / (m + t) as f64
    }
}

fn e(err: OpacityError) -> String {
    err.to_string()
}

/// Compares two maps and two reports; `what` names the case.
fn same(
    what: &str,
    gpu: &OpacityMap,
    cpu: &OpacityMap,
    rg: &GrowthReport,
    rc: &GrowthReport,
) -> Result<(), String> {
    if (gpu.origin, gpu.dims, gpu.outside) != (cpu.origin, cpu.dims, cpu.outside) {
        return Err(format!(
            "{what}: GPU map box {:?}+{:?} (outside {}) differs from CPU {:?}+{:?} (outside {})",
            gpu.origin, gpu.dims, gpu.outside, cpu.origin, cpu.dims, cpu.outside
        ));
    }
    if let Some(i) = (0..cpu.values.len()).find(|&i| gpu.values[i] != cpu.values[i]) {
        let n = cpu
            .values
            .iter()
            .zip(&gpu.values)
            .filter(|(a, b)| a != b)
            .count();
        let v = cpu.voxel(i);
        return Err(format!(
            "{what}: {n} voxels differ; first at voxel {v:?}: GPU {} CPU {}",
            gpu.values[i], cpu.values[i]
        ));
    }
    let key = |r: &GrowthReport| (r.steps, r.visits, r.useful, r.converged);
    if key(rg) != key(rc) {
        return Err(format!("{what}: GPU report {rg:?} differs from CPU {rc:?}"));
    }
    Ok(())
}

/// Grows both paths from `seed` to convergence and compares maps and counts.
fn converged_case(
    gpu: &dyn GpuService,
    volume: &Volume,
    seed: Seed,
    params: GrowthParams,
    what: &str,
) -> Result<(), String> {
    let gv = GpuOpacityVolume::upload(gpu, volume.view()).map_err(e)?;
    let out = (|| {
        let mut g = GpuGrowth::new(gpu, &gv, volume.view(), &seed, params).map_err(e)?;
        let res = (|| {
            let rg = g.run(gpu, &gv).map_err(e)?;
            let mut c = CpuGrowth::new(volume.view(), &seed, params).map_err(e)?;
            let rc = c.run(volume.view()).map_err(e)?;
            same(what, &g.map(gpu).map_err(e)?, &c.map(), &rg, &rc)?;
            if !rg.converged || rg.steps < 3 {
                return Err(format!("{what}: suspicious run {rg:?}"));
            }
            Ok(())
        })();
        g.release(gpu);
        res
    })();
    gv.release(gpu);
    out
}

/// The three-sphere phantom (64³, f32, noise σ 3) seeded in spheres A and
/// B, the phantom with B at 110 (absorbed through pumping pairs), and a
/// noisy i16 ball with non-default parameters, and the pumping phantom
/// with face neighbours only (`connectivity = 6`): identical converged
/// maps, identical step / visit / useful counts.
pub fn check_converged_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    let p = three_spheres(64, 3.0, 21);
    converged_case(
        gpu,
        &p.volume,
        Seed::Voxel(p.a.centre_voxel()),
        GrowthParams::default(),
        "phantom, seed in A",
    )?;
    converged_case(
        gpu,
        &p.volume,
        Seed::Voxel(p.b.centre_voxel()),
        GrowthParams::default(),
        "phantom, seed in B",
    )?;
    let q = three_spheres_with(48, 110.0, 3.0, 25);
    converged_case(
        gpu,
        &q.volume,
        Seed::Voxel(q.a.centre_voxel()),
        GrowthParams::default(),
        "B at 110 (pumps)",
    )?;
    converged_case(
        gpu,
        &q.volume,
        Seed::Voxel(q.a.centre_voxel()),
        GrowthParams {
            connectivity: 6,
            ..GrowthParams::default()
        },
        "B at 110 (pumps), connectivity 6",
    )?;
    let ball = noisy_ball_i16(40, 14.0, 4.0, 5);
    let params = GrowthParams {
        o_min: 0.1,
        o_max: 0.8,
        lambda: 8.0,
        ..Default::default()
    };
    converged_case(
        gpu,
        &ball,
        Seed::Voxel([20, 20, 20]),
        params,
        "i16 ball, λ = 8",
    )
}

/// A volume four times larger than one storage binding, grown from a seed
/// whose working box spans a quarter of its planes: the GPU binds only
/// those planes of the values (an aligned window, rebound as the box
/// grows) and its converged map and counts equal the CPU's.
pub fn check_values_window_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    // A noisy ball of radius 4 in the middle of a tall volume.
    let dims = [24, 24, 96];
    let grid = Grid::new(dims, DVec3::ONE, DVec3::ZERO);
    let ball = Sphere {
        centre: [12.0, 12.0, 48.0],
        radius: 4.0,
        value: 100.0,
    };
    let mut rng = XorShift::new(9);
    let values = (0..grid.len())
        .map(|l| {
            let base = if ball.contains(grid.unlinear(l)) {
                ball.value
            } else {
                0.0
            };
            (base as f64 + 4.0 * rng.normal()).round() as i16
        })
        .collect();
    let volume = Volume {
        grid,
        data: VoxelData::I16(values),
    };
    let plane = (dims[0] * dims[1] * 4) as u64;
    let limit = 26 * plane;
    if (volume.grid.len() as u64) * 4 <= 3 * limit {
        return Err("the volume must exceed the binding several times".into());
    }
    let small = LimitedDevice::binding(gpu, limit);
    converged_case(
        &small,
        &volume,
        Seed::Voxel([12, 12, 48]),
        GrowthParams::default(),
        "values bound as a window of planes",
    )
}

/// Step by step (1, 1, …, then 5, then to convergence) on the phantom with
/// B at 110 (the pump shortcut fires), with 26 and with 6 neighbours: the
/// GPU map equals the CPU map after every call.
pub fn check_stepwise_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    for connectivity in [26, 6] {
        stepwise_case(gpu, connectivity)
            .map_err(|m| format!("connectivity {connectivity}: {m}"))?;
    }
    Ok(())
}

fn stepwise_case(gpu: &dyn GpuService, connectivity: u32) -> Result<(), String> {
    // B at 110: absorbed through pumping pairs, so the pump shortcut fires.
    let p = three_spheres_with(48, 110.0, 3.0, 22);
    let seed = Seed::Voxel(p.a.centre_voxel());
    let params = GrowthParams {
        connectivity,
        ..GrowthParams::default()
    };
    let v = p.volume.view();
    let gv = GpuOpacityVolume::upload(gpu, v).map_err(e)?;
    let out = (|| {
        let mut g = GpuGrowth::new(gpu, &gv, v, &seed, params).map_err(e)?;
        let res = (|| {
            let mut c = CpuGrowth::new(v, &seed, params).map_err(e)?;
            same(
                "after seeding",
                &g.map(gpu).map_err(e)?,
                &c.map(),
                &g.report(),
                &c.report(),
            )?;
            for (i, n) in [1, 1, 1, 1, 1, 1, 1, 1, 5, usize::MAX]
                .into_iter()
                .enumerate()
            {
                let rg = g.step(gpu, &gv, n).map_err(e)?;
                let rc = c.step(v, n).map_err(e)?;
                same(
                    &format!("call {i} ({n} steps)"),
                    &g.map(gpu).map_err(e)?,
                    &c.map(),
                    &rg,
                    &rc,
                )?;
            }
            if !g.is_converged() {
                return Err("GPU growth did not converge".into());
            }
            Ok(())
        })();
        g.release(gpu);
        res
    })();
    gv.release(gpu);
    out
}

/// Two growths (seeds in A and C) on one uploaded volume, stepped in turn:
/// each equals its CPU twin.
pub fn check_several_maps(gpu: &dyn GpuService) -> Result<(), String> {
    let p = three_spheres(48, 3.0, 23);
    let v = p.volume.view();
    let params = GrowthParams::default();
    let gv = GpuOpacityVolume::upload(gpu, v).map_err(e)?;
    let seeds = [
        Seed::Voxel(p.a.centre_voxel()),
        Seed::Voxel(p.c.centre_voxel()),
    ];
    let mut growths = Vec::new();
    let res = (|| {
        for s in &seeds {
            growths.push(GpuGrowth::new(gpu, &gv, v, s, params).map_err(e)?);
        }
        while !growths.iter().all(GpuGrowth::is_converged) {
            for g in growths.iter_mut() {
                g.step(gpu, &gv, 3).map_err(e)?;
            }
        }
        for (g, s) in growths.iter().zip(&seeds) {
            let mut c = CpuGrowth::new(v, s, params).map_err(e)?;
            c.run(v).map_err(e)?;
            same(
                &format!("map seeded at {s}"),
                &g.map(gpu).map_err(e)?,
                &c.map(),
                &g.report(),
                &c.report(),
            )?;
        }
        Ok(())
    })();
    for g in growths {
        g.release(gpu);
    }
    gv.release(gpu);
    res
}

/// A volume larger than the storage-binding limit uploads (a growth binds
/// only the planes its working box spans), but a growth whose box spans
/// more planes than one binding holds is refused with
/// [`OpacityError::BindingTooLarge`]; a GPU volume of other dims with
/// [`OpacityError::GpuVolumeMismatch`]; nothing panics.
pub fn check_refusals(gpu: &dyn GpuService) -> Result<(), String> {
    let p = three_spheres(24, 3.0, 24);
    let small = LimitedDevice::binding(gpu, 4096);
    // 24 × 24 voxels of 4 bytes per plane: one plane fits 4 KiB, two do not.
    let gv = GpuOpacityVolume::upload(&small, p.volume.view()).map_err(e)?;
    let refused = (|| {
        let seed = Seed::Voxel(p.a.centre_voxel());
        let mut g = GpuGrowth::new(&small, &gv, p.volume.view(), &seed, GrowthParams::default())
            .map_err(e)?;
        let r = g.run(&small, &gv);
        g.release(gpu);
        match r {
            Err(OpacityError::BindingTooLarge { bytes, limit, .. })
                if bytes > limit && limit == 4096 =>
            {
                Ok(())
            }
            other => Err(format!("expected BindingTooLarge, got {other:?}")),
        }
    })();
    gv.release(gpu);
    refused?;
    let q = three_spheres(16, 3.0, 24);
    let gv = GpuOpacityVolume::upload(gpu, q.volume.view()).map_err(e)?;
    let r = GpuGrowth::new(
        gpu,
        &gv,
        p.volume.view(),
        &Seed::Voxel([8, 8, 8]),
        GrowthParams::default(),
    );
    let out = match r {
        Err(OpacityError::GpuVolumeMismatch { expected, actual })
            if expected == [24; 3] && actual == [16; 3] =>
        {
            Ok(())
        }
        Err(other) => Err(format!("expected GpuVolumeMismatch, got {other}")),
        Ok(g) => {
            g.release(gpu);
            Err("a mismatched GPU volume was accepted".into())
        }
    };
    gv.release(gpu);
    out
}

/// Bounded maps and the automatic λ on both paths, through
/// [`super::grow_roi`]: `phantom:abdomen` (64 × 50 × 43, 5.6 mm) seeded in
/// the liver with an intensity window, a distance bound, both, and
/// `lambda = "auto"` (written from the scan, and grown when capped at a
/// number of steps) — identical maps, counts, λ and bound hits.
pub fn check_limits_match_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    use super::limits::GrowthLimits;
    use super::roi::{LambdaChoice, RoiRequest, grow_roi};
    let ph = voxflex_phantom::abdomen_labelled([64, 50, 43]);
    let v = ph.volume.view();
    let seed = Seed::World(voxflex_phantom::abdomen::SEEDS[0].2);
    // The automatic λ's map is written from its scan on the CPU whatever
    // the backend; capped at a number of steps it is grown on the GPU.
    let cases = [
        (Some([80.0, 150.0]), None, LambdaChoice::Fixed(30.0), None),
        (None, Some(40.0), LambdaChoice::Fixed(30.0), None),
        (
            Some([60.0, 170.0]),
            Some(60.0),
            LambdaChoice::Fixed(8.0),
            None,
        ),
        (None, None, LambdaChoice::Auto, None),
        (None, Some(40.0), LambdaChoice::Auto, Some(12)),
    ];
    let gv = GpuOpacityVolume::upload(gpu, v).map_err(e)?;
    let res = (|| {
        for (intensity, max_distance_mm, lambda, steps) in cases {
            let what = format!(
                "intensity {intensity:?}, max_distance_mm {max_distance_mm:?}, lambda {lambda}, \
                 steps {steps:?}"
            );
            let req = RoiRequest {
                seed,
                params: GrowthParams::default(),
                lambda,
                limits: GrowthLimits {
                    intensity,
                    max_distance_mm,
                },
                steps,
            };
            let g = grow_roi(v, &req, Some((gpu, &gv))).map_err(e)?;
            let c = grow_roi(v, &req, None).map_err(e)?;
            same(
                &what,
                &g.grown.map,
                &c.grown.map,
                &g.grown.report,
                &c.grown.report,
            )?;
            if g.lambda != c.lambda || g.hits != c.hits {
                return Err(format!(
                    "{what}: GPU λ {} hits {:?}, CPU λ {} hits {:?}",
                    g.lambda, g.hits, c.lambda, c.hits
                ));
            }
            if intensity.is_some() && c.hits.intensity == 0 {
                return Err(format!("{what}: the window never held the growth back"));
            }
            if steps.is_some_and(|n| c.grown.report.steps != n as u64) {
                return Err(format!(
                    "{what}: not grown to the cap: {:?}",
                    c.grown.report
                ));
            }
            if max_distance_mm.is_some() && steps.is_none() && c.hits.distance == 0 {
                return Err(format!("{what}: the distance bound was never reached"));
            }
        }
        Ok(())
    })();
    gv.release(gpu);
    res
}
