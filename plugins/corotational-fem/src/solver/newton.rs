//! The static solve: Newton iterations on the corotational forces with a
//! line search on the total potential, and load stepping (see
//! [`CorotationalFem::step_static`]).

use super::{CorotationalFem, Twist};

use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_mesh::mesh_model::pcg::CgSettings;
use voxflex_mesh::mesh_model::{Boundary, NodeState, SolveReport};

/// Load steps are halved down to this fraction of a frame's load change
/// before the static solve gives up.
pub const SMALLEST_LOAD_STEP: f64 = 1.0 / 1024.0;

/// Backtracking halves the Newton step down to this fraction before the
/// load step is declared failed.
const SMALLEST_LINE_STEP: f64 = 1.0 / 64.0;

/// The loosest relative PCG residual a Newton direction is solved to
/// ([`CorotationalFem::newton_settings`]): a direction worse than this is
/// not worth its line search.
const LOOSEST_NEWTON_CG: f64 = 1e-2;

/// The fraction of the static tolerance a Newton direction's linear
/// residual is held to ([`CorotationalFem::newton_settings`]). At 0.1 the
/// CPU and GPU static solves of one grab (block-Jacobi PCG in f32 on the
/// GPU) parted by 2.6e-3 mm in a soft sliding mode, both within the
/// static tolerance; at 0.01 the last Newton iteration carries the answer
/// as far past the tolerance as the exact solves did.
const NEWTON_FORCING: f64 = 0.01;

/// The share of a Newton step's own quadratic error its linear solve may
/// add ([`CorotationalFem::newton_settings`]): from relative residual `r`
/// a full step ends near `C r²` however exactly its direction is solved,
/// so the direction need only be solved to `QUADRATIC_SHARE · C · r`
/// relative. With `C` taken from the last step, whose end also holds that
/// share, the estimate settles at `C / (1 − QUADRATIC_SHARE)`: stable.
const QUADRATIC_SHARE: f64 = 0.1;

/// A Newton iterate's figures: relative force residual, residual force
/// per node (µN), total potential and the largest potential met (µN·mm),
/// the force-scale floor of its load step and the force scale its
/// residual was measured against (µN).
struct Point {
    residual: f64,
    g: Vec<DVec3>,
    potential: f64,
    scale: f64,
    floor: f64,
    force_scale: f64,
}

/// The mean force scale (µN) of the load steps converged so far — the
/// "time-averaged force" of nonlinear FE codes (Abaqus's q̃). A load step's
/// residual is measured against at least this, so a frame that asks for
/// nothing new (a held grab at rest: every force zero to rounding) is
/// converged as it starts, instead of its rounding noise being its own
/// scale, which no Newton iteration can shrink.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct ForceScale {
    sum: f64,
    count: u64,
}

impl ForceScale {
    /// The mean of the recorded scales, µN (0 before any).
    fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }

    /// Records a converged load step's force scale (µN); zero and
    /// non-finite scales are left out.
    fn record(&mut self, scale: f64) {
        if scale.is_finite() && scale > 0.0 {
            self.sum += scale;
            self.count += 1;
        }
    }
}

/// One Newton solve's end: converged or not, with its relative force
/// residual.
struct NewtonEnd {
    converged: bool,
    residual: f64,
    force_scale: f64,
}

/// Euclidean norm over the free nodes.
fn free_norm(v: &[DVec3], free: &[bool]) -> f64 {
    v.iter()
        .zip(free)
        .filter(|(_, f)| **f)
        .map(|(x, _)| x.length_squared())
        .sum::<f64>()
        .sqrt()
}

fn norm(v: &[DVec3]) -> f64 {
    v.iter().map(|x| x.length_squared()).sum::<f64>().sqrt()
}

impl CorotationalFem {
    /// The static equilibrium `f_int(u) = f_ext` on the free nodes, by
    /// Newton iterations with load stepping.
    ///
    /// From the state `u0` it is given, the solve follows the path
    /// `f_ext(λ) = λ f + (1 − λ) f_int(u0)` with the imposed displacements
    /// moving linearly from their values in `u0` to their targets, so that
    /// `u0` solves `λ = 0` exactly and `λ = 1` is the frame's problem. It
    /// first tries the whole step; a load step whose Newton iterations do
    /// not converge is halved (down to [`SMALLEST_LOAD_STEP`]), and a
    /// converged one doubles the next. Giving up is a [`ModelError`] that
    /// leaves the last converged state.
    pub(super) fn step_static(
        &mut self,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let mut report = SolveReport {
            substeps: 1,
            ..SolveReport::default()
        };
        if self.params.static_lag {
            return self.step_static_lagged(bc, &free, state, report);
        }
        let u0 = state.u.clone();
        let f_int0 = self.elastic_forces(&u0);
        let mut target = u0.clone();
        bc.impose(&mut target);
        let (mut done, mut step) = (0.0f64, 1.0f64);
        let mut newton = 0u64;
        let mut last = NewtonEnd {
            converged: false,
            residual: f64::NAN,
            force_scale: 0.0,
        };
        while done < 1.0 {
            let lambda = (done + step).min(1.0);
            let f_ext: Vec<DVec3> = bc
                .force
                .iter()
                .zip(&f_int0)
                .map(|(f, g)| lambda * *f + (1.0 - lambda) * *g)
                .collect();
            let mut trial = state.u.clone();
            for (n, c) in free.iter().enumerate() {
                if !c {
                    trial[n] = u0[n].lerp(target[n], lambda);
                }
            }
            bc.tie(&mut trial);
            let (end, iterations) = self.newton(bc, &free, &f_ext, &mut trial, &mut report)?;
            newton += u64::from(iterations);
            last = end;
            self.stats.load_steps += 1;
            if last.converged {
                self.force_scale.record(last.force_scale);
                state.u = trial;
                done = lambda;
                step = (2.0 * step).min(1.0);
            } else {
                step *= 0.5;
                if step < SMALLEST_LOAD_STEP {
                    break;
                }
            }
        }
        self.stats.newton_iterations += newton;
        self.stats.force_residual = last.residual;
        state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        if done < 1.0 {
            return Err(ModelError(format!(
                "corotational-fem: the static solve did not converge: relative force residual \
                 {:.2e} above static_tolerance {:.1e} after {newton} Newton iterations, with \
                 this frame's loads and imposed displacements applied only to {:.4} (load steps \
                 down to 1/{}); the step is too large for a quasi-static solve from this state: \
                 ramp the load in over more frames (`frames` of the load or grab interaction), \
                 raise static_iterations ({}), or use solver = \"dynamic\" (a piece that \
                 nothing fixes or grabs has no static equilibrium at all)",
                last.residual,
                self.params.static_tolerance,
                done,
                (1.0 / SMALLEST_LOAD_STEP) as u32,
                self.params.static_iterations,
            )));
        }
        Ok(report)
    }

    /// The interactive static frame (`static_lag`): the imposed
    /// displacements at their targets, then at most `static_iterations`
    /// Newton iterations on the frame's whole load from the state the last
    /// frame left, whose iterate is kept whether or not it reached
    /// `static_tolerance` (counted in `lagged_frames`; the first such frame
    /// of a run is warned about). Never an error for stopping above the
    /// tolerance; a failed linear solve still is.
    fn step_static_lagged(
        &mut self,
        bc: &Boundary,
        free: &[bool],
        state: &mut NodeState,
        mut report: SolveReport,
    ) -> Result<SolveReport, ModelError> {
        let mut u = state.u.clone();
        let mut target = u.clone();
        bc.impose(&mut target);
        for (n, f) in free.iter().enumerate() {
            if !f {
                u[n] = target[n];
            }
        }
        bc.tie(&mut u);
        let (end, iterations) = self.newton(bc, free, &bc.force, &mut u, &mut report)?;
        self.stats.newton_iterations += u64::from(iterations);
        self.stats.load_steps += 1;
        self.stats.force_residual = end.residual;
        if end.converged {
            self.force_scale.record(end.force_scale);
        } else {
            if self.stats.lagged_frames == 0 {
                tracing::warn!(
                    "corotational-fem: static_lag: a frame ended at relative force residual {:.2e}, above \
                     static_tolerance {:.1e}, after {iterations} Newton iteration(s): the body lags its \
                     loads and catches up over the next frames (every such frame is counted in \
                     lagged_frames; newton_force_residual is the last frame's)",
                    end.residual,
                    self.params.static_tolerance,
                );
            }
            self.stats.lagged_frames += 1;
        }
        state.u = u;
        state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        Ok(report)
    }

    /// The elastic force on every node (µN) and the total potential
    /// `Σ_e E_e(u) − f_ext · u` (µN·mm) at `u`, from one rotation per
    /// element.
    fn force_and_potential(&self, u: &[DVec3], f_ext: &[DVec3]) -> (Vec<DVec3>, f64) {
        let (per_corner, strain) = self.elements.forces_and_energy(u);
        let mut f_int = vec![DVec3::ZERO; u.len()];
        self.matrix.sum_corners(&per_corner, &mut f_int);
        let work: f64 = f_ext.iter().zip(u).map(|(f, x)| f.dot(*x)).sum();
        (f_int, strain - work)
    }

    /// The Newton iterate at `u`: the relative force residual
    /// `|f_ext − f_int(u)|` (free nodes, hanging nodes' forces moved onto
    /// their masters) over the force scale — the largest of `|f_ext|`
    /// there, `|f_int(u)|` over all nodes (reactions included) and the
    /// floor (µN; `None`: the residual itself, as a load step starts, so
    /// that a step whose answer is stress-free, such as a grabbed piece
    /// moving rigidly, still has a scale, and at least the mean scale of
    /// the converged load steps before, [`ForceScale`]) —, the residual
    /// force per node, the potential and the force scale (µN).
    fn measure(
        &self,
        bc: &Boundary,
        free: &[bool],
        f_ext: &[DVec3],
        u: &[DVec3],
        floor: Option<f64>,
    ) -> Point {
        let (f_int, potential) = self.force_and_potential(u, f_ext);
        let mut g: Vec<DVec3> = f_ext.iter().zip(&f_int).map(|(a, b)| *a - *b).collect();
        let mut ext = f_ext.to_vec();
        bc.untie(&mut g);
        bc.untie(&mut ext);
        let r = free_norm(&g, free);
        let floor = floor.unwrap_or_else(|| r.max(self.force_scale.mean()));
        let scale = free_norm(&ext, free).max(norm(&f_int)).max(floor);
        let relative = if scale > 0.0 { r / scale } else { r };
        Point {
            residual: if relative.is_finite() {
                relative
            } else {
                f64::INFINITY
            },
            g,
            potential,
            scale: potential.abs(),
            floor,
            force_scale: scale,
        }
    }

    /// The PCG settings of a Newton direction from an iterate at relative
    /// force residual `residual` (inexact Newton, Eisenstat and Walker
    /// 1996): the linear residual need only fall to the larger of
    ///
    /// - [`NEWTON_FORCING`] of what the static tolerance allows of the
    ///   force, `NEWTON_FORCING static_tolerance / residual` of its start,
    ///   so a solve near convergence stops early, and
    /// - with `static_lag` (one Newton iteration a frame), [`QUADRATIC_SHARE`]
    ///   of the error the step leaves anyway, `C r²` with `C` from the last
    ///   full step, so a frame's step under new loads (on the pendulum `r` ≈
    ///   0.01–0.5 and `C` ≈ 0.01) stops once the step's own nonlinearity
    ///   dominates instead of solving to `cg_tolerance`;
    ///
    /// never tighter than `cg_tolerance`, never looser than
    /// [`LOOSEST_NEWTON_CG`].
    fn newton_settings(&self, free: &[bool], residual: f64) -> CgSettings {
        let mut settings = self.settings(free);
        // Only where a frame takes one Newton iteration: a converged solve
        // that loosened its first directions took more Newton iterations
        // (the finger under inverse control: 111 → 131 in 15 frames, each
        // a linearisation, for 7 % fewer PCG iterations).
        let quadratic = if self.params.static_lag {
            self.newton_quadratic
        } else {
            0.0
        };
        let wanted = forcing(self.params.static_tolerance, quadratic, residual);
        settings.tolerance = wanted.clamp(
            settings.tolerance,
            LOOSEST_NEWTON_CG.max(settings.tolerance),
        );
        settings
    }

    /// Newton iterations on `f_int(u) = f_ext` from `u` (imposed values in
    /// place). The tangent is the potential's exact Hessian (`R K Rᵀ` plus
    /// the rotations' own stiffness); where that solve fails (an
    /// indefinite Hessian: compressed elements, or far from equilibrium)
    /// or gives no descent, the iteration is redone with its positive part
    /// only. The step is backtracked until it lowers the total potential
    /// enough (Armijo; the force is the potential's gradient, and along a
    /// descent direction it must fall) — or, once the potential's change
    /// is below its rounding, the force residual. Returns how it ended and
    /// the iterations taken.
    fn newton(
        &mut self,
        bc: &Boundary,
        free: &[bool],
        f_ext: &[DVec3],
        u: &mut Vec<DVec3>,
        report: &mut SolveReport,
    ) -> Result<(NewtonEnd, u32), ModelError> {
        let tolerance = self.params.static_tolerance;
        let mut at = self.measure(bc, free, f_ext, u, None);
        let mut iterations = 0;
        while at.residual > tolerance && iterations < self.params.static_iterations {
            iterations += 1;
            let mut moved = false;
            let settings = self.newton_settings(free, at.residual);
            for twist in [Twist::Full, Twist::Clamped] {
                self.linearise(u, 1.0, None, twist);
                let mut du = vec![DVec3::ZERO; u.len()];
                if twist == Twist::Full {
                    let out = self.solve_quietly(bc, free, &at.g, &mut du, settings)?;
                    if !out.converged(settings) {
                        report.iterations += out.iterations;
                        continue;
                    }
                    report.add_solve(out, true);
                } else {
                    self.solve(bc, free, &at.g, &mut du, settings, report)?;
                }
                if let Some((next, step)) = self.line_search(bc, free, f_ext, u, &du, &at) {
                    self.newton_quadratic = quadratic_constant(&at, &next, step, twist);
                    at = next;
                    moved = true;
                    break;
                }
            }
            if !moved {
                break;
            }
        }
        Ok((
            NewtonEnd {
                converged: at.residual <= tolerance,
                residual: at.residual,
                force_scale: at.force_scale,
            },
            iterations,
        ))
    }

    /// Backtracks along `du` from `u` (halving down to
    /// [`SMALLEST_LINE_STEP`]); moves `u` and returns the new point and the
    /// step length taken (1 for the full step), or `None` when `du` is no
    /// descent direction or no step is accepted.
    fn line_search(
        &self,
        bc: &Boundary,
        free: &[bool],
        f_ext: &[DVec3],
        u: &mut Vec<DVec3>,
        du: &[DVec3],
        at: &Point,
    ) -> Option<(Point, f64)> {
        // The potential's slope along du is −g · du.
        let descent: f64 = at.g.iter().zip(du).map(|(a, b)| a.dot(*b)).sum();
        if descent.is_nan() || descent <= 0.0 {
            return None;
        }
        let mut s = 1.0;
        while s >= SMALLEST_LINE_STEP {
            let mut trial: Vec<DVec3> = u.iter().zip(du).map(|(a, d)| *a + s * *d).collect();
            bc.tie(&mut trial);
            let next = self.measure(bc, free, f_ext, &trial, Some(at.floor));
            let p = next.potential;
            let flat = (p - at.potential).abs() <= 1e-11 * at.scale;
            if p <= at.potential - 1e-4 * s * descent || flat && next.residual < at.residual {
                *u = trial;
                let next = Point {
                    scale: at.scale.max(p.abs()),
                    ..next
                };
                return Some((next, s));
            }
            s *= 0.5;
        }
        None
    }
}

/// The relative linear residual a Newton direction from relative force
/// residual `residual` needs (before the clamp to `cg_tolerance` …
/// [`LOOSEST_NEWTON_CG`]; see [`CorotationalFem::newton_settings`]), with
/// `quadratic` the last full step's `C` (0: unknown).
fn forcing(static_tolerance: f64, quadratic: f64, residual: f64) -> f64 {
    let final_step = NEWTON_FORCING * static_tolerance / residual.max(f64::MIN_POSITIVE);
    final_step.max(QUADRATIC_SHARE * quadratic * residual)
}

/// The quadratic constant `C` of the Newton step from `at` to `next`
/// (`r_next / r_at²`), for the next step's forcing: only a full step along
/// the exact tangent shows it; after a backtracked or clamped step (far
/// from where Newton converges quadratically) it is 0, and the next solve
/// goes back to the tight rule.
fn quadratic_constant(at: &Point, next: &Point, step: f64, twist: Twist) -> f64 {
    let c = next.residual / (at.residual * at.residual);
    if step == 1.0 && twist == Twist::Full && c.is_finite() {
        c
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(residual: f64) -> Point {
        Point {
            residual,
            g: Vec::new(),
            potential: 0.0,
            scale: 1.0,
            floor: 0.0,
            force_scale: 1.0,
        }
    }

    #[test]
    fn a_direction_far_from_convergence_is_solved_to_a_tenth_of_the_steps_quadratic_error() {
        // r = 0.2, C = 0.02: the step ends near C r² = 8e-4 (relative to
        // the force scale, 4e-3 of r); a tenth of that is 4e-4 of r.
        assert!((forcing(1e-6, 0.02, 0.2) - 4e-4).abs() < 1e-15);
        // Unknown C: the tight rule (0.01 · 1e-6 / 0.2), which the
        // caller's clamp then raises to cg_tolerance.
        assert!((forcing(1e-6, 0.0, 0.2) - 5e-8).abs() < 1e-20);
        // Near convergence the final-step rule is the looser and wins.
        assert!((forcing(1e-6, 0.02, 1e-5) - 1e-3).abs() < 1e-15);
    }

    #[test]
    fn only_a_full_step_along_the_exact_tangent_measures_the_quadratic_constant() {
        let (at, next) = (point(0.1), point(1e-4));
        let c = quadratic_constant(&at, &next, 1.0, Twist::Full);
        assert!((c - 0.01).abs() < 1e-15, "{c}");
        assert_eq!(quadratic_constant(&at, &next, 0.5, Twist::Full), 0.0);
        assert_eq!(quadratic_constant(&at, &next, 1.0, Twist::Clamped), 0.0);
        assert_eq!(
            quadratic_constant(&point(0.0), &next, 1.0, Twist::Full),
            0.0,
            "a start already at zero residual has no constant"
        );
        assert_eq!(
            quadratic_constant(&at, &point(f64::NAN), 1.0, Twist::Full),
            0.0
        );
    }
}
