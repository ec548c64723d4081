//! ChainMail benchmarks (`cargo bench -p voxflex-chainmail`), after the
//! papers' test: a homogeneous 126³ model (2 M elements), one deformation
//! that reaches every element, run to rest without rendering in between.
//!
//! Prints, on this machine:
//! - sequential Gibson vs parallel (timestamps + active blocks): time to
//!   rest, propagation and relaxation iterations, speed-up;
//! - the parallel algorithm with several block sizes: time and element
//!   visits per useful update;
//! - a local grab (~5 % of the model) on two model sizes: time per frame;
//! - memory per element.
//!
//! Pass a size to run smaller (`cargo bench -p voxflex-chainmail -- 64`);
//! `-- parallel` runs only the parallel model to rest (and prints its
//! relaxation energy and a hash of its state), `-- energy` runs the papers'
//! test to the energy of the papers' 619 plain sweeps with the model's
//! default, the automatic over-relaxation (`-- energy mirror`: the opposite
//! corner pulled the opposite way; `reference` also compares both states
//! with the default relaxed 20 times as long), `-- propagation` only the propagation
//! (ten times, with a hash of the state: equal hashes, equal results),
//! `-- kernels` times
//! only the relaxation kernels (beside a bare sweep of the same positions
//! without bookkeeping, and a copy of them, for scale), `-- local` only the
//! local grabs (three times), `-- gpu` runs the papers' test on the WGSL
//! path (any adapter). `block=X,Y,Z` sets the block size of `parallel`
//! and `kernels`.

use std::time::Instant;
use voxflex_chainmail::model::ChainMail;
use voxflex_chainmail::params::{ChainMailParams, InteractionSpec};
use voxflex_phantom::phantom;

/// The papers' test parameters; plain relaxation (`over_relaxation = 1`),
/// as the papers relax, so the figures compare like for like.
fn params(algorithm: &str, block: [usize; 3]) -> ChainMailParams {
    params_with(algorithm, block, "over_relaxation = 1.0")
}

/// The papers' test parameters with `relaxation` (a TOML line: the
/// over-relaxation, or nothing for the model's automatic choice).
fn params_with(algorithm: &str, block: [usize; 3], relaxation: &str) -> ChainMailParams {
    // "frontier" selects the parallel algorithm with the element work-list.
    let (algorithm, schedule) = match algorithm {
        "frontier" => ("parallel", "frontier"),
        a => (a, "blocks"),
    };
    ChainMailParams::from_toml(&format!(
        "algorithm = \"{algorithm}\"\nschedule = \"{schedule}\"\nblock = {block:?}\n\
         {relaxation}\n\
         materials = [{{ range = [-1e9, 1e9], constraint = 0.1, elastic = 1.0 }}]"
    ))
    .expect("bench parameters")
}

/// A cube model of `n³` elements with one corner grabbed and pulled far
/// enough to move every element.
fn setup(n: usize, algorithm: &str, block: [usize; 3]) -> ChainMail {
    setup_with(n, params(algorithm, block), false)
}

/// [`setup`] with `params`; `mirrored` grabs the opposite corner and pulls
/// it the opposite way.
fn setup_with(n: usize, params: ChainMailParams, mirrored: bool) -> ChainMail {
    let v = phantom("cube", [n, n, n]).expect("cube phantom");
    let mut m = ChainMail::new(v.view(), params).expect("model");
    let lat = m.lattice();
    let (corner, sign) = if mirrored {
        (lat.world([n - 1; 3]), 1.0)
    } else {
        (lat.world([0; 3]), -1.0)
    };
    let pull = sign * lat.spacing[0] * 0.1 * (3 * n) as f64 * 1.5;
    m.interact(&InteractionSpec::Grab {
        point: corner.to_array(),
        by: Some([pull, pull, pull]),
        to: None,
        path: None,
        frames: 1,
    })
    .expect("grab");
    m
}

/// Relaxation sweeps the papers report for this test; both algorithms run
/// at most this many (both stop earlier if they come to rest).
const RELAX_SWEEPS: u64 = 619;

fn main() {
    let n: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(126);
    println!(
        "voxflex-chainmail bench: {n}³ elements, threads: {}",
        rayon::current_num_threads()
    );

    let run = |algorithm: &str, block: [usize; 3], sweeps: u64| {
        let mut m = setup(n, algorithm, block);
        let t = Instant::now();
        m.start_deformation();
        let prop_iters = m.propagate(u64::MAX);
        let t_prop = t.elapsed();
        let t = Instant::now();
        let relax_iters = m.relax(sweeps);
        let t_relax = t.elapsed();
        let c = m.counts();
        (t_prop, prop_iters, t_relax, relax_iters, c, m)
    };
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;

    if std::env::args().any(|a| a == "rest") {
        rest(n);
        return;
    }
    // `block=X,Y,Z` picks the block size of `parallel` and `kernels`
    let block = std::env::args()
        .find_map(|a| {
            let b: Vec<usize> = a
                .strip_prefix("block=")?
                .split(',')
                .filter_map(|v| v.parse().ok())
                .collect();
            (b.len() == 3).then(|| [b[0], b[1], b[2]])
        })
        .unwrap_or([8, 4, 4]);
    if std::env::args().any(|a| a == "kernels") {
        // Only the relaxation kernels (for profiling).
        let (.., pm) = run("parallel", [8, 4, 4], 20);
        relaxation_kernels(&pm, block, ms);
        return;
    }
    if std::env::args().any(|a| a == "gpu") {
        // The papers' test on the WGSL path (any adapter; lavapipe is slow).
        use voxflex_core::gpu::GpuService;
        let service = voxflex_runtime::gpu_context::WgpuService::new(
            voxflex_runtime::gpu_context::AdapterPolicy::AnyAdapter,
        )
        .expect("a GPU adapter");
        println!("adapter: {}", service.adapter_description());
        let service: std::sync::Arc<dyn GpuService> = std::sync::Arc::new(service);
        for _ in 0..3 {
            let mut m = setup(n, "parallel", [8, 4, 4]);
            m.use_gpu(service.clone()).expect("model on the GPU");
            let t = Instant::now();
            m.start_deformation();
            let prop = m.propagate(u64::MAX);
            m.pull().expect("GPU state");
            let tp = t.elapsed();
            let t = Instant::now();
            let sweeps = m.relax(RELAX_SWEEPS);
            m.pull().expect("GPU state");
            let tr = t.elapsed();
            println!(
                "GPU 8×4×4: propagation {:.1} ms ({prop} iterations), relaxation {:.1} ms ({sweeps} sweeps), total {:.1} ms (state read back after each stage)",
                ms(tp),
                ms(tr),
                ms(tp + tr)
            );
        }
        return;
    }
    if std::env::args().any(|a| a == "local") {
        for _ in 0..3 {
            local_grabs(n, ms);
        }
        return;
    }
    if std::env::args().any(|a| a == "propagation") {
        // Only the parallel propagation, ten times (for profiling).
        for _ in 0..10 {
            let (pp, ppi, _, _, c, m) = run("parallel", block, 0);
            println!(
                "propagation {:.1} ms ({ppi} iterations, {} visits, {} updates, state {:016x})",
                ms(pp),
                c.visits,
                c.updates,
                state_hash(&m)
            );
        }
        return;
    }
    if std::env::args().any(|a| a == "energy") {
        equal_energy(n, block, std::env::args().any(|a| a == "mirror"), ms);
        return;
    }
    if std::env::args().any(|a| a == "parallel") {
        // Only the parallel run to rest (for profiling).
        let (pp, ppi, pr, pri, _, m) = run("parallel", block, RELAX_SWEEPS);
        println!(
            "energy {:.6e}, state {:016x}",
            voxflex_chainmail::relax::energy(m.lattice(), m.state()),
            state_hash(&m)
        );
        println!(
            "parallel {block:?}: propagation {:.1} ms ({ppi} iterations), relaxation {:.1} ms ({pri} sweeps), total {:.1} ms",
            ms(pp),
            ms(pr),
            ms(pp + pr)
        );
        return;
    }
    let (sp, _, sr, sri, sc, sm) = run("sequential", [8, 4, 4], RELAX_SWEEPS);
    println!(
        "sequential Gibson: propagation {:9.1} ms (one pass, {} elements moved)   relaxation {:9.1} ms ({} dense sweeps)",
        ms(sp),
        sc.updates,
        ms(sr),
        sri
    );
    let (pp, ppi, pr, pri, pc, pm) = run("parallel", [8, 4, 4], RELAX_SWEEPS);
    println!(
        "parallel 8×4×4:    propagation {:9.1} ms ({ppi} iterations)          relaxation {:9.1} ms ({pri} sweeps over active blocks)",
        ms(pp),
        ms(pr),
    );
    println!(
        "speed-up over the sequential baseline: propagation {:.2}×, relaxation {:.2}×, total {:.2}× ({:.1} ms vs {:.1} ms)",
        ms(sp) / ms(pp),
        ms(sr) / ms(pr),
        ms(sp + sr) / ms(pp + pr),
        ms(pp + pr),
        ms(sp + sr)
    );
    println!(
        "elements: {}; memory: {:.1} bytes per element (both Jacobi copies, keys, material, cut-link and interior bytes); propagation visits per useful update: {:.2}",
        pm.lattice().element_count(),
        pm.bytes_per_element(),
        pc.visits as f64 / pc.updates.max(1) as f64
    );
    drop(sm);

    relaxation_kernels(&pm, [8, 4, 4], ms);
    drop(pm);

    println!("schedule            propagation (ms)   visits per useful update");
    let mut rows: Vec<(String, &str, [usize; 3])> =
        [[32, 32, 32], [16, 16, 16], [8, 8, 8], [16, 4, 4], [8, 4, 4]]
            .into_iter()
            .map(|b| (format!("blocks {}×{}×{}", b[0], b[1], b[2]), "parallel", b))
            .collect();
    rows.push(("frontier list".into(), "frontier", [16, 4, 4]));
    for (name, algorithm, block) in rows {
        let (t, _, _, _, c, _) = run(algorithm, block, 0);
        println!(
            "{name:>18}   {:16.1}   {:.2}",
            ms(t),
            c.visits as f64 / c.updates.max(1) as f64
        );
    }

    local_grabs(n, ms);
}

/// A local grab (~5 % of the model, the same 16-link reach) on an
/// `n/2`³ and an `n`³ cube: time per frame of 10 + 10 iterations, up to
/// 60 frames or rest (`-- local` runs only this).
fn local_grabs(n: usize, ms: impl Fn(std::time::Duration) -> f64) {
    println!("local grab (same 16-link reach on two model sizes; up to 60 frames or rest):");
    for size in [n / 2, n] {
        let v = phantom("cube", [size, size, size]).expect("cube phantom");
        let mut m = ChainMail::new(v.view(), params("parallel", [8, 4, 4])).expect("model");
        let lat = m.lattice();
        let centre = lat.world([size / 2, size / 2, size / 2]);
        let reach = 16.0 * 0.1 * lat.spacing[2];
        m.interact(&InteractionSpec::Grab {
            point: centre.to_array(),
            by: Some([0.0, 0.0, reach]),
            to: None,
            path: None,
            frames: 1,
        })
        .expect("grab");
        let t = Instant::now();
        let mut frames = 0;
        while frames < 60 {
            frames += 1;
            m.step();
            if m.at_rest() {
                break;
            }
        }
        let dt = t.elapsed();
        let c = m.counts();
        println!(
            "  {size}³ model: {frames} frames (10 + 10 iterations each), {:7.2} ms per frame, {:.0} element visits per frame",
            ms(dt) / frames as f64,
            c.visits as f64 / frames as f64
        );
    }
}

/// The papers' test to the papers' relaxation: the plain run (619 sweeps)
/// sets the energy `Σ w |u_n − u_e|²` its relaxation reaches; the model's
/// default, the automatic over-relaxation, then relaxes after the same
/// propagation until its energy is at most that (the sweeps counted in a
/// first run, the energy measured after each; a second run of that many
/// sweeps is timed).
fn equal_energy(
    n: usize,
    block: [usize; 3],
    mirrored: bool,
    ms: impl Fn(std::time::Duration) -> f64,
) {
    use voxflex_chainmail::relax::energy;
    let stages = |m: &mut ChainMail| {
        let t = Instant::now();
        m.start_deformation();
        let iterations = m.propagate(u64::MAX);
        (t.elapsed(), iterations)
    };
    let mut plain = setup_with(n, params("parallel", block), mirrored);
    let (plain_prop, _) = stages(&mut plain);
    let t = Instant::now();
    let plain_sweeps = plain.relax(RELAX_SWEEPS);
    let plain_relax = t.elapsed();
    let target = energy(plain.lattice(), plain.state());
    let displacements = |m: &ChainMail| -> Vec<[f32; 3]> {
        (0..m.lattice().len()).map(|e| m.displacement(e)).collect()
    };
    let plain_u = displacements(&plain);
    drop(plain);
    // The sweeps the default needs, found one sweep at a time with the
    // energy measured between them; then a clean run of that many, timed.
    let auto = || params_with("parallel", block, "");
    let omega = auto().omega(n);
    let mut m = setup_with(n, auto(), mirrored);
    stages(&mut m);
    let mut sweeps = 0;
    while energy(m.lattice(), m.state()) > target && sweeps < RELAX_SWEEPS {
        let done = m.relax(1);
        if done == 0 {
            break; // at rest
        }
        sweeps += done;
    }
    drop(m);
    let mut m = setup_with(n, auto(), mirrored);
    let (prop, iterations) = stages(&mut m);
    let t = Instant::now();
    let done = m.relax(sweeps);
    let relax = t.elapsed();
    let e = energy(m.lattice(), m.state());
    assert_eq!(done, sweeps, "the timed run relaxed differently");
    println!(
        "plain relaxation ({}): propagation {:.1} ms, relaxation {:.1} ms ({plain_sweeps} sweeps), energy {target:.4e}",
        if mirrored { "mirrored pull" } else { "pull" },
        ms(plain_prop),
        ms(plain_relax)
    );
    println!(
        "equal energy, automatic over-relaxation ω = {omega:.4}: propagation {:.1} ms ({iterations} iterations), relaxation {:.1} ms ({sweeps} sweeps), total {:.1} ms, energy {e:.4e}{}",
        ms(prop),
        ms(relax),
        ms(prop + relax),
        if e > target { " — NOT reached" } else { "" }
    );
    if std::env::args().any(|a| a == "reference") {
        // Both states against the default relaxed 20 times as long.
        let auto_u = displacements(&m);
        let more = m.relax(20 * RELAX_SWEEPS);
        let reference = displacements(&m);
        let rms = |u: &[[f32; 3]]| {
            let lat = m.lattice();
            let present = (0..lat.len()).filter(|&e| lat.present(e));
            let sum: f64 = present
                .clone()
                .map(|e| {
                    (0..3)
                        .map(|a| ((u[e][a] - reference[e][a]) as f64).powi(2))
                        .sum::<f64>()
                })
                .sum();
            (sum / present.count() as f64).sqrt()
        };
        println!(
            "against the default after {} more sweeps (energy {:.4e}): RMS displacement difference, plain 619 sweeps {:.4} mm, automatic ω {sweeps} sweeps {:.4} mm",
            more,
            energy(m.lattice(), m.state()),
            rms(&plain_u),
            rms(&auto_u)
        );
    }
}

/// FNV-1a of every element's displacement bits and key, in storage order:
/// equal hashes show that a faster build computed the same state.
fn state_hash(m: &ChainMail) -> u64 {
    use std::sync::atomic::Ordering::Relaxed;
    let st = m.state();
    let words = (0..3)
        .flat_map(|a| st.u[st.cur][a].iter())
        .chain(st.key[st.cur].iter());
    words.fold(0xcbf2_9ce4_8422_2325u64, |h, w| {
        (h ^ w.load(Relaxed) as u64).wrapping_mul(0x100_0000_01b3)
    })
}

/// Times the relaxation kernels on a deformed model: 40 sweeps over every
/// block of size `block`; and, for scale, a copy of as many bytes as the
/// state's positions hold, split over the threads.
fn relaxation_kernels(pm: &ChainMail, block: [usize; 3], ms: impl Fn(std::time::Duration) -> f64) {
    use rayon::prelude::*;
    use voxflex_chainmail::blocks::Blocks;
    use voxflex_chainmail::relax_passes::{SweepScratch, sweep_runs};
    let (lat, st) = (pm.lattice(), pm.state());
    let blocks = Blocks::new(lat.dims, block);
    let all: Vec<u32> = (0..blocks.len() as u32).collect();
    let mut scratch = SweepScratch::default();
    let t = Instant::now();
    for _ in 0..40 {
        sweep_runs(lat, st, &blocks, &all, 1e-4, &mut scratch);
    }
    println!(
        "relaxation over every block {block:?}: {:.2} ms per sweep",
        ms(t.elapsed()) / 40.0
    );
    bare_sweeps(lat, st, &ms);
    let words = 3 * lat.len();
    let (src, mut dst) = (vec![1u32; words], vec![0u32; words]);
    let t = Instant::now();
    for _ in 0..40 {
        dst.par_chunks_mut(1 << 16)
            .zip(src.par_chunks(1 << 16))
            .for_each(|(d, s)| d.copy_from_slice(s));
    }
    let per = t.elapsed().as_secs_f64() / 40.0;
    println!(
        "copy of the positions' {:.1} MB: {:.2} ms ({:.1} GB/s read + write)",
        words as f64 * 4e-6,
        per * 1e3,
        2.0 * words as f64 * 4.0 / per / 1e9
    );
    std::hint::black_box(&dst);
}

/// The question issue 17 asked — why does a sweep cost several copies of
/// the positions? — answered by a bare red-black sweep over a plain copy
/// of the same positions, in the same storage order: every inner 8-slot
/// window of every inner row, the uniform kernel's arithmetic (mean of
/// the six neighbours, clamped to their box ± the link's rest offset), no
/// classification of the window, no moves recorded, no block lists. What
/// the real sweep costs beyond it is its bookkeeping, not memory.
fn bare_sweeps(
    lat: &voxflex_chainmail::lattice::ElementLattice,
    st: &voxflex_chainmail::state::State,
    ms: &impl Fn(std::time::Duration) -> f64,
) {
    use rayon::prelude::*;
    use std::sync::atomic::Ordering::Relaxed;
    use wide::f32x8;
    let order = lat.order();
    let [_, ny, nz] = order.dims;
    let hx = order.hx;
    let mut u: [Vec<f32>; 3] = [0, 1, 2].map(|a| {
        st.u[st.cur][a]
            .iter()
            .map(|x| f32::from_bits(x.load(Relaxed)))
            .collect()
    });
    let d = lat.material_link(0, 0).d;
    let alpha = f32x8::splat(0.5);
    let sixth = f32x8::splat(1.0 / 6.0);
    let sweep = |u: &mut [Vec<f32>; 3]| {
        for colour in 0..2 {
            // rows of one k-plane per task: a colour row has one writer,
            // the other colour is only read
            let ptr: [usize; 3] = [0, 1, 2].map(|a| u[a].as_mut_ptr() as usize);
            (1..nz - 1).into_par_iter().for_each(|k| {
                for j in 1..ny - 1 {
                    let (own, p) = order.row(colour, j, k);
                    let other = |j: usize, k: usize| order.row(1 - colour, j, k).0;
                    let same = other(j, k) + p;
                    let nb = [
                        same,
                        same - 1,
                        other(j + 1, k),
                        other(j - 1, k),
                        other(j, k + 1),
                        other(j, k - 1),
                    ];
                    let mut w = 1;
                    while w + 9 <= hx {
                        for (a, &base) in ptr.iter().enumerate() {
                            let at = |i: usize| {
                                // SAFETY: `i + 8 ≤ len` (inner rows and
                                // windows); this task alone writes colour
                                // `colour`'s row (j, k), the other colour
                                // is only read during this colour's pass.
                                f32x8::from(unsafe {
                                    std::ptr::read_unaligned(
                                        (base as *const f32).add(i) as *const [f32; 8]
                                    )
                                })
                            };
                            let x = at(own + w);
                            let n: [f32x8; 6] = [0, 1, 2, 3, 4, 5].map(|l| at(nb[l] + w));
                            let sum = n[0] + n[1] + n[2] + n[3] + n[4] + n[5];
                            let lo = n
                                .iter()
                                .fold(f32x8::splat(f32::NEG_INFINITY), |m, &v| m.fast_max(v))
                                - f32x8::splat(d[a]);
                            let hi = n
                                .iter()
                                .fold(f32x8::splat(f32::INFINITY), |m, &v| m.fast_min(v))
                                + f32x8::splat(d[a]);
                            let cand = x + alpha * (sum * sixth - x);
                            let v = lo.simd_le(hi).select(cand.fast_max(lo).fast_min(hi), x);
                            // SAFETY: as above.
                            unsafe {
                                std::ptr::write_unaligned(
                                    (base as *mut f32).add(own + w) as *mut [f32; 8],
                                    v.to_array(),
                                )
                            };
                        }
                        w += 8;
                    }
                }
            });
        }
    };
    sweep(&mut u);
    let t = Instant::now();
    for _ in 0..40 {
        sweep(&mut u);
    }
    println!(
        "bare sweep, same positions and order (inner windows, no bookkeeping): {:.2} ms per sweep",
        ms(t.elapsed()) / 40.0
    );
    std::hint::black_box(&u);
}

/// The head pull to rest: an `n³` crop of the head phantom (the head
/// scene's materials, skull fixed), the scalp pulled out by 20 mm over 6
/// frames, 150 frames of 10 + 10 iterations; every frame's wall time,
/// blocks visited and largest relaxation move, the rest frame, and the
/// mean cost per frame early and late. `mirror` pulls the other side.
fn rest(n: usize) {
    let mirrored = std::env::args().any(|a| a == "mirror");
    let verbose = std::env::args().any(|a| a == "verbose");
    let extra: String = std::env::args()
        .filter_map(|a| a.strip_prefix("param:").map(str::to_owned))
        .collect::<Vec<_>>()
        .join("\n");
    let fix = std::env::args().any(|a| a == "fix");
    let mut m = voxflex_chainmail::scenes::head_pull(n, 20.0, 6, mirrored, fix, &extra);
    println!(
        "head pull: {n}³ crop, {} elements, 20 mm over 6 frames{}{}, {extra}",
        m.lattice().element_count(),
        if mirrored { " (mirrored)" } else { "" },
        if fix {
            ", skull fixed"
        } else {
            ", skull free (rigid)"
        }
    );
    let mut rest_frame = None;
    let mut ms = Vec::new();
    for f in 1..=150u64 {
        let s = m.step_stats();
        ms.push(s.ms);
        if verbose || f % 10 == 0 || f <= 10 {
            println!(
                "frame {f:3}: {:7.2} ms, blocks propagated {:6}, relaxed {:7}, sweeps {:2}, max move {:.2e}, changed {}",
                s.ms, s.propagation_blocks, s.relaxation_blocks, s.sweeps, s.max_move, s.changed
            );
        }
        if !s.changed && rest_frame.is_none() {
            rest_frame = Some(f);
        }
    }
    let mean = |r: std::ops::Range<usize>| {
        let r = r.start.min(ms.len())..r.end.min(ms.len());
        ms[r.clone()].iter().sum::<f64>() / r.len().max(1) as f64
    };
    println!(
        "rest frame: {}; ms per frame: frames 1–10 {:.2}, 11–40 {:.2}, 41–80 {:.2}, 81–150 {:.2}",
        rest_frame.map_or("none within 150".into(), |f| f.to_string()),
        mean(0..10),
        mean(10..40),
        mean(40..80),
        mean(80..150)
    );
    println!("notes: {:?}", m.notes());
}
