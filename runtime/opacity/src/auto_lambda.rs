//! The automatic λ (`lambda = "auto"`): λ where the grown region's size
//! is flattest in λ — the plateau rule.
//!
//! The converged map grows monotonically with λ (a larger λ lowers every
//! positive extinction). Let `V(λ)` be the voxels at opacity ≥ 0.5. At
//! small λ the region is held back inside the organ by noise (σ_s, from the
//! seed's neighbourhood, can underestimate correlated noise), so `V` rises
//! quickly as λ grows and the organ fills; at large λ opacity flows further into every
//! touching structure (a depth ∝ λ) or jumps across a contact into a
//! neighbour, so `V` rises again. Between the two `V(λ)` is flattest. The
//! rule:
//!
//! 1. measure `V` at λ = [`CANDIDATES`] (√2 apart, 1 … 32), in increasing
//!    order, stopping early at a **jump**: `V(λ_{k+1}) > (1 + JUMP) V(λ_k)`
//!    ([`JUMP`]), or at a **break**: a step whose growth `r − 1` exceeds
//!    [`BREAK`] times the mean growth of the steps before it (at least two
//!    of them) — the region has started to run into a neighbour. A trial
//!    is cut short as soon as it passes the jump or break bound, so a
//!    leaking λ costs little, and no λ past it is tried;
//! 2. for each step taken before a break, the growth ratio
//!    `r_k = V(λ_{k+1}) / V(λ_k)` (steps from regions under
//!    [`MIN_VOXELS`] are skipped);
//! 3. λ is the **largest** `λ_k` whose step is nearly the flattest:
//!    `r_k − 1 ≤ (1 + FLAT_TOL) (min r − 1)` ([`FLAT_TOL`] = 0.25; the
//!    largest, so a region that no λ changes — an isolated organ — takes
//!    the most complete map, and a near-tie is not decided by noise in
//!    favour of a half-grown map). Without any ratio (the first step
//!    already jumps) it is the last candidate before the jump.
//!
//! The sizes `V(λ_k)` come from one [`PathCostScan`] that continues from
//! each λ to the next (the converged map at λ is a λ-independent path cost
//! compared with thresholds ∝ λ; see that module), not from one growth per
//! λ. The map is then written from the scan's costs at the λ chosen
//! ([`PathCostScan::into_map`]), with no growth: its region is the chosen
//! trial's, voxel for voxel, and its values the real-valued rule rounded
//! once. A fixed-λ growth at the same λ rounds every step instead, so the
//! two maps can differ by half a fixed-point unit per step of a path, and
//! their regions in the voxels whose opacity lies that close to ½ (a
//! handful per hundred thousand). Only a map capped at a number of steps
//! is grown, on the runner's backend.
//! Figures (Dice per organ for this rule and for fixed λ on
//! `phantom:abdomen`) are in docs/BENCHMARKS.md and in
//! `docs/roi_dice_vs_lambda.md`.

use super::OpacityError;
use super::params::GrowthParams;
use super::path_cost::{PathCostScan, ScanInput};
use super::runner::{GrowRunner, Grown};

/// λ tried, in order: `2^(k/2)`, k = 0 … 10.
pub const CANDIDATES: [f32; 11] = [
    1.0,
    std::f32::consts::SQRT_2,
    2.0,
    2.828_427,
    4.0,
    5.656_854,
    8.0,
    11.313_708,
    16.0,
    22.627_417,
    32.0,
];

/// Relative growth between two candidates that counts as a jump (a leak):
/// `V(λ_{k+1}) > (1 + JUMP) · V(λ_k)`, i.e. the region more than doubles
/// within a √2 step of λ.
pub const JUMP: f64 = 1.0;

/// A step whose growth `r − 1` is more than `BREAK` times the mean growth
/// of the steps before it (at least two) ends the scan: the region has run
/// into a neighbour. 2 measured on `phantom:abdomen` at 3, 2 and 1.5 mm
/// (three organs each): mean automatic-λ Dice 0.933 → 0.949, worst case
/// 0.855 → 0.895, none worse (docs/BENCHMARKS.md, "ROI maps").
pub const BREAK: f64 = 2.0;

/// Steps whose growth `r − 1` is within `(1 + FLAT_TOL)` times the
/// flattest step's count as equally flat (0.25: measured on
/// `phantom:abdomen` at 3 and 2 mm, see docs/BENCHMARKS.md).
pub const FLAT_TOL: f64 = 0.25;

/// Regions smaller than this (voxels at opacity ≥ 0.5) do not start a
/// ratio: a seed that has not spread yet.
pub const MIN_VOXELS: usize = 27;

/// One candidate λ tried by the search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trial {
    /// λ.
    pub lambda: f32,
    /// Voxels at opacity ≥ 0.5 (a lower bound when `aborted`), by the
    /// real-valued rule ([`PathCostScan`]).
    pub voxels: usize,
    /// Voxels the scan relaxed for this λ (continuing the λ before).
    pub visits: u64,
    /// Cut short at the jump or break bound.
    pub aborted: bool,
}

/// What the search found: the λ and the trials behind it, without the
/// map ([`crate::roi::RoiOutcome`] keeps it beside the map it returns).
#[derive(Clone, Debug)]
pub struct AutoSearch {
    /// The λ chosen.
    pub lambda: f32,
    /// Every candidate tried, in order.
    pub trials: Vec<Trial>,
    /// True when the map was written from the scan, not grown.
    pub from_scan: bool,
}

/// What the search found, and the map at the λ it chose.
#[derive(Clone, Debug)]
pub struct AutoLambda {
    /// The λ, the trials and how the map was made.
    pub search: AutoSearch,
    /// The map at the chosen λ: the scan's ([`auto_map`]), or a growth
    /// capped at a number of steps.
    pub grown: Grown,
}

/// The λ the rule picks from the trials (in increasing λ; the last may
/// have jumped). See the module docs.
pub fn pick(trials: &[Trial]) -> f32 {
    let ok = |t: &&Trial| !t.aborted;
    let mut ratios = step_ratios(trials);
    if let Some(b) = first_break(&ratios) {
        ratios.truncate(b);
    }
    let Some(min) = ratios.iter().map(|r| r.1).reduce(f64::min) else {
        return trials
            .iter()
            .rev()
            .find(ok)
            .map_or(CANDIDATES[0], |t| t.lambda);
    };
    ratios
        .iter()
        .filter(|r| r.1 - 1.0 <= (1.0 + FLAT_TOL) * (min - 1.0))
        .map(|r| r.0)
        .reduce(f32::max)
        .unwrap_or(CANDIDATES[0])
}

/// The steps `(λ_k, r_k)` of `trials` that start from a region of at least
/// [`MIN_VOXELS`] (and not from a trial cut short), jumps left out.
fn step_ratios(trials: &[Trial]) -> Vec<(f32, f64)> {
    let mut ratios = vec![];
    for w in trials.windows(2) {
        if w[0].voxels >= MIN_VOXELS && !w[0].aborted {
            let r = w[1].voxels as f64 / w[0].voxels as f64;
            if r <= 1.0 + JUMP {
                ratios.push((w[0].lambda, r));
            }
        }
    }
    ratios
}

/// The largest growth `r − 1` the step after `before` may have without
/// being a break (`None` before two steps).
fn break_bound(before: &[(f32, f64)]) -> Option<f64> {
    (before.len() >= 2)
        .then(|| BREAK * before.iter().map(|r| r.1 - 1.0).sum::<f64>() / before.len() as f64)
}

/// Index of the first step that is a break ([`BREAK`]).
fn first_break(ratios: &[(f32, f64)]) -> Option<usize> {
    (0..ratios.len()).find(|&k| break_bound(&ratios[..k]).is_some_and(|b| ratios[k].1 - 1.0 > b))
}

/// Runs the search (see the module docs) on `input` — the values
/// `runner` grows on — and makes the map at the λ chosen. Run to
/// convergence (`steps = None`), the map is the scan's own at that λ
/// ([`auto_map`]: no growth runs, and `runner` is not used); with a step
/// cap it is grown on `runner`'s backend for at most `steps` steps, its
/// working box where the scan found the region. `params.lambda` is
/// ignored, the other fields are used as given.
pub fn auto_lambda(
    input: ScanInput<'_>,
    runner: &mut dyn GrowRunner,
    params: GrowthParams,
    steps: Option<usize>,
) -> Result<AutoLambda, OpacityError> {
    let Some(steps) = steps else {
        return auto_map(input, params);
    };
    let (scan, lambda, trials) = search(input, params)?;
    let room = scan.reached_box(lambda);
    let grown = runner.grow_within(GrowthParams { lambda, ..params }, Some(steps), room)?;
    Ok(AutoLambda {
        search: AutoSearch {
            lambda,
            trials,
            from_scan: false,
        },
        grown,
    })
}

/// The search on `input` and the converged map at the λ chosen, written
/// from the scan's path costs ([`PathCostScan::into_map`]: real arithmetic
/// rounded once, on the CPU) instead of grown. `params.lambda` is ignored.
pub fn auto_map(input: ScanInput<'_>, params: GrowthParams) -> Result<AutoLambda, OpacityError> {
    let (scan, lambda, trials) = search(input, params)?;
    Ok(AutoLambda {
        search: AutoSearch {
            lambda,
            trials,
            from_scan: true,
        },
        grown: scan.into_map(lambda)?,
    })
}

/// The converged map at `lambda`, one of [`CANDIDATES`], from a scan of
/// `input` run to that λ's phase — what [`auto_map`] returns for the same
/// λ, without choosing it again (an automatic-λ map on a new volume).
/// `params.lambda` is ignored.
pub fn map_at(
    input: ScanInput<'_>,
    params: GrowthParams,
    lambda: f32,
) -> Result<Grown, OpacityError> {
    let mut scan = PathCostScan::new(input, params)?;
    if CANDIDATES.contains(&lambda) {
        while scan.next_phase(None).is_some_and(|(l, _)| l < lambda) {}
    }
    scan.into_map(lambda)
}

/// The λ the rule picks on `input` and the trials it measured, from one
/// [`PathCostScan`] (no map is made). `params.lambda` is ignored.
pub fn choose_lambda(
    input: ScanInput<'_>,
    params: GrowthParams,
) -> Result<(f32, Vec<Trial>), OpacityError> {
    search(input, params).map(|(_, lambda, trials)| (lambda, trials))
}

/// The scan as the rule left it, the λ it picks and the trials.
fn search<'a>(
    input: ScanInput<'a>,
    params: GrowthParams,
) -> Result<(PathCostScan<'a>, f32, Vec<Trial>), OpacityError> {
    let mut scan = PathCostScan::new(input, params)?;
    let mut trials: Vec<Trial> = Vec::new();
    loop {
        // Cut short past the jump, or past the break when two steps are in.
        let growth = break_bound(&step_ratios(&trials)).map_or(JUMP, |b| b.min(JUMP));
        let bound = trials
            .last()
            .filter(|t| !t.aborted)
            .map(|t| t.voxels)
            .filter(|&v| v >= MIN_VOXELS)
            .map(|v| ((1.0 + growth) * v as f64).floor() as usize);
        let Some((lambda, found)) = scan.next_phase(bound) else {
            break;
        };
        trials.push(Trial {
            lambda,
            voxels: found.voxels,
            visits: found.visits,
            aborted: found.cut,
        });
        if found.cut {
            break;
        }
    }
    let lambda = pick(&trials);
    Ok((scan, lambda, trials))
}
