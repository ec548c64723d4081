//! One frame's inverse problem (Coevoet et al.; Rodríguez et al. ICRA
//! 2017, step 2): the changes of the actuators' efforts `Δλ` that bring
//! the effectors closest to their targets,
//!
//! `min ‖W Δλ + δ‖²` subject to the effort bounds, the measure bounds and
//! the measures scripted for this frame,
//!
//! with `W` the effectors' responses to each effort (`J_e K⁻¹ J_aᵀ`, from
//! one compliance solve per actuator) and `δ` the effectors' offset from
//! their targets. It is a small dense QP (one unknown per actuator), solved
//! with `clarabel` — a maintained interior-point solver that reports
//! infeasibility instead of returning a wrong point — with a vanishing
//! effort term (`½ε‖λ + Δλ‖²`, ε = [`EFFORT_WEIGHT`] of the largest
//! diagonal) so that redundant actuators (four cavities, one 3-D target)
//! have one answer: the least effort.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

/// The linearised problem of one frame, over the unknown efforts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InverseProblem {
    /// Per effector coordinate (x, y, z of each effector), its response
    /// to a unit change of each unknown effort (mm per effort unit).
    pub effector_response: Vec<Vec<f64>>,
    /// Per effector coordinate, the offset from its target now (mm).
    pub effector_offset: Vec<f64>,
    /// The unknown efforts now and their bounds.
    pub efforts: Vec<f64>,
    /// The bounds of each unknown effort.
    pub effort_bounds: Vec<[f64; 2]>,
    /// The largest change of each unknown effort this frame (the trust
    /// region; `∞` or missing: none).
    pub step_limits: Vec<f64>,
    /// Per actuator with a measure row: the measure's response to each
    /// unknown, its value now, its bounds, and the value its script asks
    /// for this frame (an equality), if any.
    pub measures: Vec<MeasureRow>,
}

/// One actuator's measure in the inverse problem.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeasureRow {
    /// Response to a unit change of each unknown effort.
    pub response: Vec<f64>,
    /// The measure now (predicted with `Δλ = 0`).
    pub now: f64,
    /// Its bounds.
    pub bounds: [f64; 2],
    /// The value scripted for this frame.
    pub target: Option<f64>,
}

/// What the solve found.
#[derive(Clone, Debug, PartialEq)]
pub struct InverseSolution {
    /// The change of each unknown effort.
    pub delta: Vec<f64>,
    /// The predicted effector offset norm after the change (mm).
    pub predicted_offset: f64,
    /// Interior-point iterations.
    pub iterations: u32,
}

impl InverseProblem {
    /// Number of unknowns.
    pub fn unknowns(&self) -> usize {
        self.efforts.len()
    }

    /// Solves the QP; an error names clarabel's status (infeasible: the
    /// scripted measures cannot be met within the bounds).
    pub fn solve(&self) -> Result<InverseSolution, String> {
        let n = self.unknowns();
        if n == 0 {
            return Ok(InverseSolution {
                delta: vec![],
                predicted_offset: norm(&self.effector_offset),
                iterations: 0,
            });
        }
        let (p, q) = self.objective();
        let (a, b, cones) = self.constraints();
        let a = if a.is_empty() {
            CscMatrix::zeros((0, n))
        } else {
            CscMatrix::from(&a)
        };
        let p = CscMatrix::from(&p).to_triu();
        let settings = DefaultSettings {
            verbose: false,
            ..DefaultSettings::default()
        };
        let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings)
            .map_err(|e| format!("the inverse QP could not be set up: {e:?}"))?;
        solver.solve();
        let status = solver.solution.status;
        if !matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved) {
            return Err(format!("the inverse QP ended {status:?}"));
        }
        let delta = solver.solution.x.clone();
        Ok(InverseSolution {
            predicted_offset: norm(&self.predicted_offset(&delta)),
            iterations: solver.solution.iterations,
            delta,
        })
    }

    /// The effector offsets after `delta` by the linearisation.
    pub fn predicted_offset(&self, delta: &[f64]) -> Vec<f64> {
        self.effector_response
            .iter()
            .zip(&self.effector_offset)
            .map(|(row, d)| d + dot(row, delta))
            .collect()
    }

    /// `½ Δλᵀ P Δλ + qᵀ Δλ` with `P = 2 WᵀW + εI`, `q = 2 Wᵀ δ + ε λ`:
    /// `‖W Δλ + δ‖² + ½ ε ‖λ + Δλ‖²` up to a constant.
    fn objective(&self) -> (Vec<Vec<f64>>, Vec<f64>) {
        let n = self.unknowns();
        let mut p = vec![vec![0.0; n]; n];
        let mut q = vec![0.0; n];
        for (row, d) in self.effector_response.iter().zip(&self.effector_offset) {
            for i in 0..n {
                q[i] += 2.0 * row[i] * d;
                for j in 0..n {
                    p[i][j] += 2.0 * row[i] * row[j];
                }
            }
        }
        let largest = (0..n)
            .map(|i| p[i][i])
            .chain(
                self.measures
                    .iter()
                    .flat_map(|m| m.response.iter().map(|r| 2.0 * r * r)),
            )
            .fold(0.0f64, f64::max);
        let eps = if largest > 0.0 {
            EFFORT_WEIGHT * largest
        } else {
            1.0
        };
        for (i, row) in p.iter_mut().enumerate() {
            row[i] += eps;
            // The term weighs the efforts themselves (λ + Δλ), not only
            // their change: antagonistic actuators do not creep up together.
            q[i] += eps * self.efforts[i];
        }
        (p, q)
    }

    /// Rows `A Δλ + s = b`: the scripted measures (zero cone) first, then
    /// every finite bound (non-negative cone).
    fn constraints(&self) -> (Vec<Vec<f64>>, Vec<f64>, Vec<SupportedConeT<f64>>) {
        let n = self.unknowns();
        let (mut a, mut b) = (vec![], vec![]);
        for m in &self.measures {
            if let Some(t) = m.target {
                a.push(m.response.clone());
                b.push(t - m.now);
            }
        }
        let equalities = a.len();
        let mut upper = |row: Vec<f64>, limit: f64| {
            if limit.is_finite() {
                a.push(row);
                b.push(limit);
            }
        };
        for (i, (&now, bounds)) in self.efforts.iter().zip(&self.effort_bounds).enumerate() {
            let mut e = vec![0.0; n];
            e[i] = 1.0;
            let limit = self.step_limits.get(i).copied().unwrap_or(f64::INFINITY);
            upper(e.clone(), (bounds[1] - now).min(limit));
            upper(e.iter().map(|v| -v).collect(), (now - bounds[0]).min(limit));
        }
        for m in &self.measures {
            upper(m.response.clone(), m.bounds[1] - m.now);
            upper(m.response.iter().map(|v| -v).collect(), m.now - m.bounds[0]);
        }
        let mut cones = vec![];
        if equalities > 0 {
            cones.push(SupportedConeT::ZeroConeT(equalities));
        }
        if a.len() > equalities {
            cones.push(SupportedConeT::NonnegativeConeT(a.len() - equalities));
        }
        (a, b, cones)
    }
}

/// The effort term's weight relative to the largest diagonal of `2 WᵀW`:
/// small enough to leave a reachable target's offset at 1e-6 of the
/// effectors' reach, large enough that the interior-point solve lands on
/// the least-effort answer of redundant actuators.
const EFFORT_WEIGHT: f64 = 1e-6;

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(v: &[f64]) -> f64 {
    dot(v, v).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two actuators moving one effector coordinate: +1 mm and +2 mm per
    /// unit effort.
    fn line(offset: f64, bounds: [f64; 2]) -> InverseProblem {
        InverseProblem {
            effector_response: vec![vec![1.0, 2.0]],
            effector_offset: vec![offset],
            efforts: vec![0.0, 0.0],
            effort_bounds: vec![bounds; 2],
            step_limits: vec![],
            measures: vec![],
        }
    }

    #[test]
    fn a_reachable_target_is_reached_with_the_least_effort() {
        let s = line(-5.0, [0.0, f64::INFINITY]).solve().unwrap();
        // Within EFFORT_WEIGHT of the 5 mm asked for.
        assert!(s.predicted_offset < 1e-5 * 5.0, "{s:?}");
        // Least effort: Δλ ∝ (1, 2), so (1, 2).
        assert!(
            (s.delta[0] - 1.0).abs() < 1e-3 && (s.delta[1] - 2.0).abs() < 1e-3,
            "{s:?}"
        );
    }

    #[test]
    fn bounds_stop_the_efforts_and_the_closest_point_is_returned() {
        // Reaching needs negative efforts: the closest is zero effort.
        let s = line(5.0, [0.0, f64::INFINITY]).solve().unwrap();
        assert!(s.delta.iter().all(|d| d.abs() < 1e-6), "{s:?}");
        assert!((s.predicted_offset - 5.0).abs() < 1e-5);
        // Capped at 1 each: 1 + 2 = 3 of the 5 mm.
        let s = line(-5.0, [0.0, 1.0]).solve().unwrap();
        assert!((s.predicted_offset - 2.0).abs() < 1e-5, "{s:?}");
        // Mirrored: the same answer with the signs turned.
        let s = line(5.0, [-1.0, 0.0]).solve().unwrap();
        assert!((s.predicted_offset - 2.0).abs() < 1e-5, "{s:?}");
        assert!(s.delta.iter().all(|d| *d <= 1e-9));
    }

    #[test]
    fn scripted_measures_are_met_and_infeasible_ones_are_reported() {
        let mut p = line(0.0, [0.0, f64::INFINITY]);
        p.effector_response.clear();
        p.effector_offset.clear();
        p.measures.push(MeasureRow {
            response: vec![3.0, 0.0],
            now: 1.0,
            bounds: [f64::NEG_INFINITY, f64::INFINITY],
            target: Some(7.0),
        });
        let s = p.solve().unwrap();
        assert!((s.delta[0] - 2.0).abs() < 1e-6, "{s:?}");
        p.measures[0].target = Some(-5.0);
        let e = p.solve().unwrap_err();
        assert!(e.contains("Infeasible"), "{e}");
    }

    #[test]
    fn the_trust_region_limits_each_step_both_ways() {
        let mut p = line(-5.0, [f64::NEG_INFINITY, f64::INFINITY]);
        p.step_limits = vec![0.5, 0.5];
        let s = p.solve().unwrap();
        assert!(s.delta.iter().all(|d| (d - 0.5).abs() < 1e-6), "{s:?}");
        p.effector_offset = vec![5.0];
        let s = p.solve().unwrap();
        assert!(s.delta.iter().all(|d| (d + 0.5).abs() < 1e-6), "{s:?}");
    }

    #[test]
    fn a_measure_bound_limits_the_reach() {
        let mut p = line(-5.0, [0.0, f64::INFINITY]);
        p.measures.push(MeasureRow {
            response: vec![1.0, 1.0],
            now: 0.0,
            bounds: [f64::NEG_INFINITY, 1.0],
            target: None,
        });
        let s = p.solve().unwrap();
        // At most Δλ₀ + Δλ₁ = 1: best all on the stronger one, 2 mm.
        assert!((s.predicted_offset - 3.0).abs() < 1e-4, "{s:?}");
    }
}
