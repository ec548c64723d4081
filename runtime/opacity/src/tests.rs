//! Tests of the CPU path: the phantom (Dice, leakage), stepwise = run,
//! monotonicity, seeds, sparse = dense, several maps, bad input.

use super::parity::{Phantom, dice, noisy_ball_i16, three_spheres, three_spheres_with};
use super::state::Growth;
use super::*;
use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use voxflex_io::png::{SliceAxis, Window, render_slice};

/// The thesis's kernel: Jacobi sweeps of the update rule over every voxel
/// of the volume, propagating from reached voxels (above `o_min`) only;
/// with `pump`, the pump shortcut of [`Extinction::pumps`] too.
struct Dense {
    dims: [usize; 3],
    ext: Extinction,
    pump: bool,
    connectivity: u32,
    field: Vec<u16>,
    values: Vec<f32>,
    visits: u64,
    useful: u64,
    sweeps: u64,
}

impl Dense {
    fn new(volume: &Volume, seed: [usize; 3], params: GrowthParams, pump: bool) -> Self {
        let stats = seed_stats(volume.view(), seed, &params).unwrap();
        let ext = Extinction::new(&stats, &params).unwrap();
        let g = volume.grid;
        let mut field = vec![ext.q_min; g.len()];
        field[g.linear(seed[0], seed[1], seed[2])] = ext.q_max;
        Self {
            dims: g.dims,
            ext,
            pump,
            connectivity: params.connectivity,
            field,
            values: volume.data.as_slice().to_f32_vec(),
            visits: 0,
            useful: 0,
            sweeps: 0,
        }
    }

    /// Linear indices of the neighbours (26, or the 6 faces) of `(i, j, k)`.
    fn neighbours(&self, i: usize, j: usize, k: usize) -> Vec<usize> {
        let [nx, ny, nz] = self.dims.map(|d| d as i64);
        let mut out = Vec::with_capacity(26);
        for dk in -1i64..=1 {
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let (a, b, c) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
                    let inside = a >= 0 && b >= 0 && c >= 0 && a < nx && b < ny && c < nz;
                    let taxicab = di.abs() + dj.abs() + dk.abs();
                    let linked = taxicab == 1 || (taxicab > 1 && self.connectivity == 26);
                    if linked && inside {
                        out.push((a + nx * (b + ny * c)) as usize);
                    }
                }
            }
        }
        out
    }

    /// One sweep; returns the number of voxels that changed.
    fn sweep(&mut self) -> usize {
        let [nx, ny, nz] = self.dims;
        let old = self.field.clone();
        let mut changed = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let l = i + nx * (j + ny * k);
                    let nb = self.neighbours(i, j, k);
                    let Some(m) = nb
                        .iter()
                        .map(|&n| old[n])
                        .filter(|&q| q > self.ext.q_min)
                        .max()
                    else {
                        continue; // no reached neighbour: nothing propagates here
                    };
                    let e = self.ext.fixed(self.values[l]);
                    let new = self.ext.rise(m, e).max(old[l]);
                    if new != old[l] {
                        self.field[l] = new;
                        changed.push((l, [i, j, k], e));
                    }
                }
            }
        }
        if self.pump {
            // Pump shortcut, on the neighbours' values after the sweep.
            let lifted = self.field.clone();
            for &(l, [i, j, k], e) in &changed {
                let new = lifted[l];
                if self.ext.may_pump(new, e)
                    && self.neighbours(i, j, k).iter().any(|&n| {
                        self.ext
                            .pumps(new, e, self.ext.fixed(self.values[n]), lifted[n])
                    })
                {
                    self.field[l] = self.ext.q_max;
                }
            }
        }
        let changed = changed.len();
        self.sweeps += 1;
        self.visits += self.field.len() as u64;
        self.useful += changed as u64;
        changed
    }
}

/// Per label (0 background, 1 A, 2 B, 3 C): voxels, voxels ≥ 0.5, voxels
/// above `o_min`.
fn census(p: &Phantom, map: &OpacityMap) -> [[u64; 3]; 4] {
    let dims = p.volume.grid.dims;
    let mut count = [[0u64; 3]; 4];
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let l = p.label([i, j, k]) as usize;
                let q = map.values.first().map(|_| map.get(i, j, k)).unwrap_or(0.0);
                count[l][0] += 1;
                count[l][1] += (q >= 0.5) as u64;
                count[l][2] += (crate::opacity_map::to_fixed(q) > map.outside) as u64;
            }
        }
    }
    count
}

fn frac(c: &[[u64; 3]; 4], label: usize, what: usize) -> f64 {
    c[label][what] as f64 / c[label][0] as f64
}

#[test]
fn phantom_grows_sphere_a_and_never_enters_c() {
    // A 100, B 115 (5 σ), C 300, noise σ 3, 96³, default parameters.
    let p = three_spheres(96, 3.0, 7);
    let dims = p.volume.grid.dims;
    let mut g = CpuGrowth::new(
        p.volume.view(),
        &Seed::Voxel(p.a.centre_voxel()),
        GrowthParams::default(),
    )
    .unwrap();
    let rep = g.run(p.volume.view()).unwrap();
    assert!(rep.converged);
    let map = g.map();
    let d = dice(&map, dims, |v| p.label(v) == 1);
    let c = census(&p, &map);
    eprintln!(
        "σ_s {:.3}; dice(A) {d:.4}; ≥0.5: A {:.4} B {:.4}; >o_min: B {:.4} C {} bg {}; {rep:?}",
        g.stats().sigma,
        frac(&c, 1, 1),
        frac(&c, 2, 1),
        frac(&c, 2, 2),
        c[3][2],
        c[0][2]
    );
    assert!(d >= 0.95, "Dice of sphere A = {d}");
    assert!(
        frac(&c, 1, 1) >= 0.995,
        "sphere A is not filled: {}",
        frac(&c, 1, 1)
    );
    // Sphere C (contrast 200 ≫ (λ + 1) σ_s) is never entered, not even faintly.
    assert_eq!(c[3][2], 0, "opacity leaked into sphere C");
    // The background (contrast 100, E ≈ 100 / (30 σ_s) ≈ 1.05) is not
    // entered: no voxel of it reaches 0.5, and only a noise voxel (3 σ
    // towards A) right at A's surface rises faintly above o_min — one
    // voxel deep, since it passes on less than the next voxel's extinction.
    assert_eq!(c[0][1], 0, "opacity ≥ 0.5 in the background");
    assert!(
        c[0][2] as f64 <= 1e-4 * c[0][0] as f64,
        "opacity leaked into the background: {} voxels",
        c[0][2]
    );
    // Sphere B (contrast 15 ≈ 5 σ_s): entered through the contact disc and
    // fading — a cap near the contact above 0.5, most of B below it, and the
    // far side of B never reached.
    assert!(
        frac(&c, 2, 1) > 0.01 && frac(&c, 2, 1) < 0.2,
        "B above 0.5: {}",
        frac(&c, 2, 1)
    );
    assert!(frac(&c, 2, 2) < 0.6, "B reached: {}", frac(&c, 2, 2));
    // The enumeration's test is exact: every visit changes a value.
    assert_eq!(rep.visits, rep.useful);
    assert!(rep.useful_fraction() >= 0.5);
    assert_eq!(map.bytes(), map.values.len() * 2);
    assert_eq!(map.origin, g.region().lo);
}

#[test]
fn a_neighbour_within_a_few_sigma_is_absorbed() {
    // B at 110 (3.4 σ_s): about 1 % of B's voxels lie within σ_s of d_s and
    // regenerate opacity, and adjacent pairs of them pump to o_max, so at
    // λ = 30 (and 15, 10) with the paper's 26 neighbours the whole of B ends
    // above 0.5 — the method cannot separate it (with 6, 40 % of B). C
    // still stays untouched.
    let p = three_spheres_with(64, 110.0, 3.0, 7);
    let mut g = CpuGrowth::new(
        p.volume.view(),
        &Seed::Voxel(p.a.centre_voxel()),
        GrowthParams {
            connectivity: 26,
            ..GrowthParams::default()
        },
    )
    .unwrap();
    g.run(p.volume.view()).unwrap();
    let c = census(&p, &g.map());
    assert!(frac(&c, 1, 1) >= 0.995);
    assert!(frac(&c, 2, 1) >= 0.9, "B above 0.5: {}", frac(&c, 2, 1));
    assert_eq!(c[3][2], 0);
    assert_eq!(c[0][2], 0);
}

#[test]
fn stepwise_then_continue_equals_run() {
    let p = three_spheres(48, 3.0, 11);
    let seed = Seed::Voxel(p.a.centre_voxel());
    let params = GrowthParams::default();
    let mut a = CpuGrowth::new(p.volume.view(), &seed, params).unwrap();
    let r1 = a.step(p.volume.view(), 7).unwrap();
    assert_eq!(r1.steps, 7);
    assert!(!r1.converged);
    a.step(p.volume.view(), 5).unwrap();
    a.run(p.volume.view()).unwrap();
    let mut b = CpuGrowth::new(p.volume.view(), &seed, params).unwrap();
    b.run(p.volume.view()).unwrap();
    assert_eq!(a.map(), b.map());
    assert_eq!(a.report(), b.report());
    // Stepping a converged growth does nothing.
    let r = a.step(p.volume.view(), 3).unwrap();
    assert_eq!((r.steps, r.visits, r.converged), (0, 0, true));
}

#[test]
fn opacity_never_decreases_and_stays_in_range() {
    let p = three_spheres(48, 3.0, 12);
    let params = GrowthParams {
        o_min: 0.1,
        o_max: 0.9,
        lambda: 10.0,
        ..Default::default()
    };
    let dims = p.volume.grid.dims;
    let mut g = CpuGrowth::new(p.volume.view(), &Seed::Voxel(p.a.centre_voxel()), params).unwrap();
    let (qmin, qmax) = (g.extinction().q_min, g.extinction().q_max);
    let mut prev = g.map().dense(dims);
    let mut steps = 0;
    while !g.is_converged() {
        g.step(p.volume.view(), 1).unwrap();
        let now = g.map().dense(dims);
        assert!(
            now.iter().zip(&prev).all(|(n, o)| n >= o),
            "opacity decreased at step {steps}"
        );
        assert!(now.iter().all(|&q| q >= qmin && q <= qmax));
        prev = now;
        steps += 1;
    }
    assert!(steps > 5);
    assert!(prev.contains(&qmax));
}

#[test]
fn sparse_equals_dense_at_convergence() {
    // B at 110 so that pumping pairs occur (the shortcut must not change the
    // converged map), and at 115 (none).
    for (b, connectivity) in [(110.0, 26), (115.0, 26), (110.0, 6), (115.0, 6)] {
        let p = three_spheres_with(40, b, 3.0, 5);
        let seed = p.a.centre_voxel();
        let params = GrowthParams {
            connectivity,
            ..GrowthParams::default()
        };
        let dims = p.volume.grid.dims;
        let mut dense = Dense::new(&p.volume, seed, params, false);
        while dense.sweep() > 0 {}
        let mut sparse = CpuGrowth::new(p.volume.view(), &Seed::Voxel(seed), params).unwrap();
        let r = sparse.run(p.volume.view()).unwrap();
        let s = sparse.map().dense(dims);
        let differ = s.iter().zip(&dense.field).filter(|(a, b)| a != b).count();
        assert_eq!(
            differ, 0,
            "B {b}, connectivity {connectivity}: {differ} voxels differ from the dense reference"
        );
        eprintln!(
            "B {b}, connectivity {connectivity}: dense {} sweeps, {} visits, useful {:.5}; sparse {r:?}",
            dense.sweeps,
            dense.visits,
            dense.useful as f64 / dense.visits as f64,
        );
        assert_eq!(r.visits, r.useful);
        assert!(r.useful_fraction() >= 0.5);
        assert!(r.visits * 20 < dense.visits);
        assert!(r.steps <= dense.sweeps);
    }
}

/// A working box given up front ([`CpuGrowth::with_room`]) changes the
/// work, never the map: a room that holds the region (no regrow at all),
/// one too small, one elsewhere in the volume and one past its edge.
#[test]
fn a_room_given_up_front_changes_the_work_not_the_map() {
    let p = three_spheres_with(40, 110.0, 3.0, 5);
    let seed = Seed::Voxel(p.a.centre_voxel());
    let dims = p.volume.grid.dims;
    for connectivity in [6, 26] {
        let params = GrowthParams {
            connectivity,
            ..GrowthParams::default()
        };
        let mut plain = CpuGrowth::new(p.volume.view(), &seed, params).unwrap();
        let r = plain.run(p.volume.view()).unwrap();
        assert!(r.regrows > 0, "the plain growth starts small and moves");
        let want = plain.map();
        let region = plain.region();
        let rooms = [
            region,
            VoxelBounds::point(p.a.centre_voxel()),
            VoxelBounds {
                lo: [0; 3],
                hi: [3; 3],
            },
            VoxelBounds {
                lo: [30, 30, 30],
                hi: [400, 400, 400],
            },
        ];
        for (i, room) in rooms.into_iter().enumerate() {
            let mut g = CpuGrowth::with_room(p.volume.view(), &seed, params, Some(room)).unwrap();
            let r = g.run(p.volume.view()).unwrap();
            assert_eq!(g.map(), want, "room {room:?}, connectivity {connectivity}");
            assert!(g.working_box().hi.iter().zip(dims).all(|(&h, d)| h < d));
            if i == 0 {
                assert_eq!(r.regrows, 0, "a room holding the region is never left");
            }
        }
    }
}

#[test]
fn sparse_equals_dense_step_by_step() {
    // The same rule (with the pump shortcut) swept densely: identical after
    // every step, and the sparse visits are exactly the dense sweep's
    // changes; for both connectivities, with the sparse step's passes on
    // one thread and on the pool (a frontier this small runs on one thread
    // by default).
    for connectivity in [26, 6] {
        for parallel_from in [usize::MAX, 0] {
            sparse_equals_dense_step_by_step_with(connectivity, parallel_from);
        }
    }
}

fn sparse_equals_dense_step_by_step_with(connectivity: u32, parallel_from: usize) {
    let p = three_spheres_with(32, 110.0, 3.0, 5);
    let seed = p.a.centre_voxel();
    let params = GrowthParams {
        connectivity,
        ..GrowthParams::default()
    };
    let dims = p.volume.grid.dims;
    let mut dense = Dense::new(&p.volume, seed, params, true);
    let mut sparse = CpuGrowth::new(p.volume.view(), &Seed::Voxel(seed), params).unwrap();
    sparse.set_parallel_from(parallel_from);
    loop {
        let before = dense.field.clone();
        let changed = dense.sweep();
        let r = sparse.step(p.volume.view(), 1).unwrap();
        let sm = sparse.map().dense(dims);
        if let Some(l) = (0..sm.len()).find(|&l| sm[l] != dense.field[l]) {
            let g = p.volume.grid;
            let [i, j, k] = g.unlinear(l);
            let nb = dense.neighbours(i, j, k);
            panic!(
                "connectivity {connectivity}: differ after sweep {} at {:?}: sparse {} dense {} before {} e {} nb {:?}",
                dense.sweeps,
                [i, j, k],
                sm[l],
                dense.field[l],
                before[l],
                dense.ext.fixed(dense.values[l]),
                nb.iter()
                    .map(|&n| (before[n], dense.field[n], dense.ext.fixed(dense.values[n])))
                    .collect::<Vec<_>>()
            );
        }
        assert_eq!(r.useful, changed as u64);
        if changed == 0 {
            break;
        }
    }
    assert!(sparse.is_converged());
    assert_eq!(sparse.report().useful, dense.useful);
}

#[test]
fn homogeneous_cube_is_filled_exactly() {
    // σ_s = 0 in the cube: the floor (1e-3 of the range) applies.
    let v = voxflex_phantom::cube([32, 32, 32]);
    let mut g = CpuGrowth::new(
        v.view(),
        &Seed::Voxel([16, 16, 16]),
        GrowthParams::default(),
    )
    .unwrap();
    assert_eq!(g.stats().std, 0.0);
    assert!((g.stats().sigma - 0.1).abs() < 1e-6);
    g.run(v.view()).unwrap();
    let m = g.map();
    assert_eq!((m.origin, m.dims), ([8; 3], [16; 3]));
    assert!(m.values.iter().all(|&q| q == u16::MAX));
    assert!(g.report().useful_fraction() > 0.9, "{:?}", g.report());
}

#[test]
fn slice_clicks_follow_the_png_orientation() {
    // Distinct values: the pixel a slice image shows at a click is the
    // value of the voxel the click resolves to.
    let grid = Grid::new([5, 6, 7], DVec3::new(1.0, 2.0, 0.5), DVec3::ZERO);
    let vol = Volume::new(grid, VoxelData::U8((0..210).map(|x| x as u8).collect())).unwrap();
    let window = Window {
        level: 127.5,
        width: 255.0,
    };
    for axis in [SliceAxis::Axial, SliceAxis::Coronal, SliceAxis::Sagittal] {
        for index in 0..grid.dims[axis.fixed_axis()] {
            let img = render_slice(vol.view(), axis, index, window).unwrap();
            for row in 0..img.height {
                for col in 0..img.width {
                    let v = Seed::Slice {
                        axis,
                        index,
                        pixel: [col, row],
                    }
                    .resolve(&grid)
                    .unwrap();
                    let value = vol.get_f32(v[0], v[1], v[2]);
                    let shown = img.pixels[row * img.width + col] as f32;
                    assert!((value - shown).abs() <= 1.0, "{axis} {index} ({col},{row})");
                    assert_eq!(
                        Seed::slice_click(&grid, v, axis),
                        Seed::Slice {
                            axis,
                            index,
                            pixel: [col, row]
                        }
                    );
                }
            }
        }
    }
    // The documented table, on one voxel.
    let v = [1, 2, 3];
    let click = |axis, index, pixel| Seed::Slice { axis, index, pixel }.resolve(&grid).unwrap();
    assert_eq!(click(SliceAxis::Axial, 3, [1, 2]), v);
    assert_eq!(click(SliceAxis::Coronal, 2, [1, 7 - 1 - 3]), v);
    assert_eq!(click(SliceAxis::Sagittal, 1, [2, 7 - 1 - 3]), v);
}

#[test]
fn slice_seed_equals_world_seed() {
    let p = three_spheres(40, 3.0, 3);
    let grid = p.volume.grid;
    let voxel = [14, 22, 19];
    // A world point a little off the voxel centre (less than half a voxel).
    let world = grid.index_to_world(DVec3::new(14.3, 21.8, 19.4));
    let mut from_world = CpuGrowth::new(
        p.volume.view(),
        &Seed::World(world),
        GrowthParams::default(),
    )
    .unwrap();
    assert_eq!(from_world.stats().voxel, voxel);
    from_world.run(p.volume.view()).unwrap();
    for axis in [SliceAxis::Axial, SliceAxis::Coronal, SliceAxis::Sagittal] {
        let click = Seed::slice_click(&grid, voxel, axis);
        let mut g = CpuGrowth::new(p.volume.view(), &click, GrowthParams::default()).unwrap();
        g.run(p.volume.view()).unwrap();
        assert_eq!(g.map(), from_world.map(), "{axis}");
        assert_eq!(g.stats(), from_world.stats());
    }
}

#[test]
fn several_maps_combine_by_max() {
    let p = three_spheres(40, 3.0, 9);
    let v = p.volume.view();
    let params = GrowthParams::default();
    let mut set = OpacityMapSet::new();
    set.add(v, &Seed::Voxel(p.a.centre_voxel()), params)
        .unwrap();
    set.add(v, &Seed::Voxel(p.c.centre_voxel()), params)
        .unwrap();
    let rep = set.run_all(v).unwrap();
    assert!(rep.converged);
    let maps = set.maps();
    for (m, s) in maps.iter().zip([p.a, p.c]) {
        let mut single = CpuGrowth::new(v, &Seed::Voxel(s.centre_voxel()), params).unwrap();
        single.run(v).unwrap();
        assert_eq!(*m, single.map());
    }
    let all = set.combined().unwrap();
    let dims = p.volume.grid.dims;
    let (fa, fc, fall) = (maps[0].dense(dims), maps[1].dense(dims), all.dense(dims));
    assert!(
        fall.iter()
            .zip(fa.iter().zip(&fc))
            .all(|(x, (a, c))| *x == (*a).max(*c))
    );
    assert!(dice(&all, dims, |x| matches!(p.label(x), 1 | 3)) > 0.9);
    assert!(set.remove(5).is_none());
    assert!(set.remove(0).is_some());
    assert_eq!(set.len(), 1);
    assert!(combine_max(&[]).is_none());
}

#[test]
fn growth_reaches_the_volume_border() {
    // A seed in a corner region touching three faces: the working box is
    // clipped to the volume and the neighbour loops stay inside.
    let v = noisy_ball_i16(24, 30.0, 0.0, 1);
    let mut g =
        CpuGrowth::new(v.view(), &Seed::Voxel([0, 0, 23]), GrowthParams::default()).unwrap();
    g.run(v.view()).unwrap();
    let m = g.map();
    let inside = super::parity::Sphere {
        centre: [11.5; 3],
        radius: 30.0,
        value: 100.0,
    };
    assert!(dice(&m, [24; 3], |x| inside.contains(x)) > 0.999);
    assert!(g.report().regrows >= 1);
    assert!(g.working_box().contains(&g.region()));
}

#[test]
fn bad_input_is_refused_with_the_value() {
    let p = three_spheres(16, 3.0, 1);
    let v = p.volume.view();
    let ok = GrowthParams::default();
    let err = |seed: Seed, params: GrowthParams| {
        CpuGrowth::new(v, &seed, params).unwrap_err().to_string()
    };

    let e = err(Seed::Voxel([3, 16, 2]), ok);
    assert!(e.contains("outside") && e.contains("16"), "{e}");
    let e = err(Seed::World(DVec3::new(1e6, 0.0, 20.0)), ok);
    assert!(e.contains("outside") && e.contains("1000000"), "{e}");
    let e = err(Seed::World(DVec3::new(f64::NAN, 0.0, 20.0)), ok);
    assert!(e.contains("not finite") && e.contains("NaN"), "{e}");
    let e = err(
        Seed::Slice {
            axis: SliceAxis::Coronal,
            index: 40,
            pixel: [0, 0],
        },
        ok,
    );
    assert!(e.contains("slice index 40"), "{e}");
    let e = err(
        Seed::Slice {
            axis: SliceAxis::Sagittal,
            index: 1,
            pixel: [3, 99],
        },
        ok,
    );
    assert!(e.contains("row 99"), "{e}");

    let seed = Seed::Voxel([8, 8, 8]);
    for lambda in [0.0, -3.0, f32::NAN, f32::INFINITY] {
        let e = err(seed, GrowthParams { lambda, ..ok });
        assert!(e.contains(&format!("lambda = {lambda}")), "{e}");
    }
    for (o_min, o_max) in [
        (0.5, 0.5),
        (0.6, 0.4),
        (-0.1, 1.0),
        (0.0, 1.5),
        (f32::NAN, 1.0),
    ] {
        let e = err(seed, GrowthParams { o_min, o_max, ..ok });
        assert!(
            e.contains(&format!("o_min = {o_min}")) && e.contains(&format!("o_max = {o_max}")),
            "{e}"
        );
    }
    let e = err(
        seed,
        GrowthParams {
            sigma_floor: 0.0,
            ..ok
        },
    );
    assert!(e.contains("sigma_floor = 0"), "{e}");
    for connectivity in [0, 8, 18, 27] {
        let e = err(seed, GrowthParams { connectivity, ..ok });
        assert!(e.contains(&format!("connectivity = {connectivity}")), "{e}");
    }
    for seed_radius in [0, crate::MAX_SEED_RADIUS + 1] {
        let e = err(seed, GrowthParams { seed_radius, ..ok });
        assert!(e.contains(&format!("seed_radius = {seed_radius}")), "{e}");
    }

    // A volume of another size, a view whose values do not fit its grid.
    let mut g = CpuGrowth::new(v, &seed, ok).unwrap();
    let other = three_spheres(12, 3.0, 1);
    let e = g.step(other.volume.view(), 1).unwrap_err().to_string();
    assert!(
        e.contains("[16, 16, 16]") && e.contains("[12, 12, 12]"),
        "{e}"
    );
    let short = crate::volume::VolumeView {
        grid: v.grid,
        data: crate::volume::VoxelSlice::F32(&[1.0; 10]),
    };
    let e = CpuGrowth::new(short, &seed, ok).unwrap_err().to_string();
    assert!(e.contains("10 values"), "{e}");
    // Non-finite values around the seed.
    let mut nan = p.volume.clone();
    if let VoxelData::F32(x) = &mut nan.data {
        x[nan.grid.linear(8, 8, 8)] = f32::NAN;
    }
    let e = CpuGrowth::new(nan.view(), &seed, ok)
        .unwrap_err()
        .to_string();
    assert!(e.contains("non-finite"), "{e}");
    // …but NaN elsewhere is a wall, not a panic.
    let mut g = CpuGrowth::new(nan.view(), &Seed::Voxel([3, 3, 3]), ok).unwrap();
    g.run(nan.view()).unwrap();
    assert!(g.map().get(8, 8, 8) <= 0.0301);
}

#[test]
fn extinction_matches_the_paper_formula() {
    let stats = SeedStats {
        voxel: [0; 3],
        ring_voxels: 27,
        mean: 100.0,
        std: 3.0,
        sigma: 3.0,
    };
    let ext = Extinction::new(&stats, &GrowthParams::default()).unwrap();
    for d in [
        100.0f32,
        101.0,
        103.0,
        110.0,
        130.0,
        190.0,
        1e20,
        -1e20,
        f32::NAN,
        f32::INFINITY,
    ] {
        let real = ((100.0 - d as f64).abs() - 3.0) / 90.0;
        let q = ext.fixed(d) as f64 / 65535.0;
        if real <= 31.0 / 30.0 {
            assert!((q - real).abs() <= 0.6 / 65535.0, "{d}: {q} vs {real}");
        } else {
            assert!(q >= 1.0, "{d}: {q}");
        }
    }
    assert_eq!(ext.rise(u16::MAX, ext.fixed(100.0)), u16::MAX);
    assert_eq!(ext.ceiling(ext.fixed(400.0)), ext.q_min);
}

#[test]
fn fast_rounding_is_ties_to_even() {
    use super::extinction::round_ties_even_small;
    let mut rng = super::parity::XorShift::new(3);
    let ties = (-300..300).map(|i| i as f32 + 0.5);
    let random = (0..100_000).map(|_| ((rng.uniform() - 0.5) * 2.0 * 131_072.0) as f32);
    let edges = [
        0.0,
        -0.0,
        0.49999997,
        -0.49999997,
        131_072.0,
        -131_072.0,
        131_071.5,
        -131_071.5,
    ];
    for x in ties.chain(random).chain(edges) {
        assert_eq!(round_ties_even_small(x), x.round_ties_even(), "{x}");
    }
}

#[test]
fn gaussian_transfer_function() {
    let tf = GaussianTf::new(100.0, 5.0);
    assert!((tf.opacity(100.0, 0.8) - 0.8).abs() < 1e-6);
    assert!((tf.opacity(105.0, 1.0) - (0.01 + 0.99 * (-0.5f32).exp())).abs() < 1e-6);
    assert!((tf.opacity(1e4, 0.5) - 0.005).abs() < 1e-6);
    let f = gaussian_tf(100.0, 5.0, 0.2, 0.8);
    assert!((f(100.0, 1.0) - 1.0).abs() < 1e-6);
    assert!((f(-1e9, 1.0) - 0.2).abs() < 1e-6);
    let delta = GaussianTf::new(3.0, 0.0);
    assert_eq!((delta.gaussian(3.0), delta.gaussian(3.1)), (1.0, 0.0));
    let stats = SeedStats {
        voxel: [0; 3],
        ring_voxels: 27,
        mean: 7.0,
        std: 0.0,
        sigma: 0.5,
    };
    assert_eq!(GaussianTf::from_stats(&stats), GaussianTf::new(7.0, 0.5));
}
