//! A Broyden (secant) correction of the effectors' response to the
//! actuators' efforts.
//!
//! The compliance gives `J_e K⁻¹ J_aᵀ` with the model's tangent stiffness
//! `K`, which leaves out the stiffness of the loads themselves: a pressure
//! follows the walls it pushes (a thin wall bulges more the more it
//! bulges), a cable follows its points. Under large strain the true
//! response then differs in size and direction, and the inverse solve's
//! fixed point — where the *predicted* response is orthogonal to the
//! remaining offset — is not the closest reachable point (measured on the
//! finger: 21.4 mm instead of the 17.9 mm a pressure sweep reaches).
//! After every frame the effectors' actual motion is compared with the
//! prediction and the difference is folded into a correction `B` by
//! Broyden's update, in efforts scaled by their size (a pressure in Pa and
//! a tension in µN are not commensurate):
//! `B ← B + (Δy − (W + B) Δλ) Δλ̃ᵀ / ‖Δλ̃‖²`, `Δλ̃ = Δλ / s`.
//! For one actuator this is the exact secant.

/// Relative effort change below which a frame teaches nothing (its
/// motion is solver noise).
const SMALLEST_RELATIVE_STEP: f64 = 1e-3;

/// A frame teaches only when the motion its effort change was predicted
/// to cause is at least this fraction of the motion seen: otherwise the
/// motion is mostly not the efforts' doing (a fluid's weight settling, a
/// body still creeping under old efforts) and would be blamed on them.
const SMALLEST_PREDICTED_SHARE: f64 = 0.2;

/// The correction and the step it waits to judge.
#[derive(Clone, Debug, Default)]
pub(crate) struct Secant {
    /// Rows: effector coordinates; columns: actuators (mm per effort unit).
    b: Vec<Vec<f64>>,
    pending: Option<Pending>,
    /// Per actuator, the largest effort or effort change seen: the scale
    /// its changes are measured in (a change of 1e-5 Pa from 1e-5 Pa is
    /// not a step).
    scale: Vec<f64>,
    /// Updates made (for metrics).
    pub(crate) updates: u64,
}

#[derive(Clone, Debug)]
struct Pending {
    /// Effort change per actuator, and each effort's scale.
    delta: Vec<f64>,
    scale: Vec<f64>,
    /// Effector coordinates before the step, and the predicted change.
    before: Vec<f64>,
    predicted: Vec<f64>,
}

impl Secant {
    /// No correction, for `rows` effector coordinates and `cols` actuators.
    pub(crate) fn new(rows: usize, cols: usize) -> Self {
        Self {
            b: vec![vec![0.0; cols]; rows],
            pending: None,
            scale: vec![0.0; cols],
            updates: 0,
        }
    }

    /// The correction of row `row`, column `col` (0 outside the matrix).
    pub(crate) fn correction(&self, row: usize, col: usize) -> f64 {
        self.b
            .get(row)
            .and_then(|r| r.get(col))
            .copied()
            .unwrap_or(0.0)
    }

    /// Remembers a step: each actuator's effort before it and its change
    /// (changes are measured against the largest effort each actuator has
    /// had),
    /// the effector coordinates before it and the change predicted with
    /// the corrected response.
    pub(crate) fn record(
        &mut self,
        efforts: &[f64],
        delta: Vec<f64>,
        before: Vec<f64>,
        predicted: Vec<f64>,
    ) {
        if self.scale.len() < delta.len() {
            self.scale.resize(delta.len(), 0.0);
        }
        for ((s, l), d) in self.scale.iter_mut().zip(efforts).zip(&delta) {
            *s = s.max(l.abs()).max((l + d).abs()).max(d.abs());
        }
        let scale = self
            .scale
            .iter()
            .map(|s| s.max(f64::MIN_POSITIVE))
            .collect();
        self.pending = Some(Pending {
            delta,
            scale,
            before,
            predicted,
        });
    }

    /// Judges the recorded step by the effector coordinates `after` it.
    pub(crate) fn observe(&mut self, after: &[f64]) {
        let Some(p) = self.pending.take() else {
            return;
        };
        let scaled: Vec<f64> = p.delta.iter().zip(&p.scale).map(|(d, s)| d / s).collect();
        let norm2: f64 = scaled.iter().map(|v| v * v).sum();
        if norm2.sqrt() < SMALLEST_RELATIVE_STEP || after.len() != p.before.len() {
            return;
        }
        let seen: f64 = after
            .iter()
            .zip(&p.before)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let predicted: f64 = p.predicted.iter().map(|v| v * v).sum::<f64>().sqrt();
        if predicted < SMALLEST_PREDICTED_SHARE * seen {
            return;
        }
        for (row, b) in self.b.iter_mut().enumerate() {
            let miss = (after[row] - p.before[row]) - p.predicted[row];
            for (col, v) in b.iter_mut().enumerate() {
                *v += miss * scaled[col] / norm2 / p.scale[col];
            }
        }
        self.updates += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_actuator_learns_the_exact_secant() {
        // Predicted 1 mm per unit, the model moved 3 mm for 2 units.
        let mut s = Secant::new(1, 1);
        s.record(&[0.0], vec![2.0], vec![10.0], vec![2.0]);
        s.observe(&[13.0]);
        assert!((1.0 + s.correction(0, 0) - 1.5).abs() < 1e-12);
        assert_eq!(s.updates, 1);
    }

    #[test]
    fn tiny_steps_teach_nothing_and_mirrored_steps_learn_the_same() {
        let mut s = Secant::new(1, 1);
        s.record(&[100.0], vec![1e-6], vec![0.0], vec![0.0]);
        s.observe(&[1.0]);
        assert_eq!(s.correction(0, 0), 0.0);
        for sign in [1.0, -1.0] {
            let mut s = Secant::new(1, 1);
            s.record(&[5.0], vec![sign * 2.0], vec![0.0], vec![sign * 2.0]);
            s.observe(&[sign * 3.0]);
            assert!((s.correction(0, 0) - 0.5).abs() < 1e-12, "{sign}");
        }
    }

    #[test]
    fn motion_the_efforts_did_not_cause_teaches_nothing() {
        // 0.1 mm predicted, 3 mm seen: a weight settling, not the effort.
        let mut s = Secant::new(1, 1);
        s.record(&[0.0], vec![1.0], vec![0.0], vec![0.1]);
        s.observe(&[3.0]);
        assert_eq!((s.correction(0, 0), s.updates), (0.0, 0));
    }

    #[test]
    fn the_update_reproduces_the_observed_step_with_two_actuators() {
        let mut s = Secant::new(2, 2);
        let (delta, efforts) = (vec![3.0, -1.0], vec![10.0, 1000.0]);
        s.record(&efforts, delta.clone(), vec![0.0, 0.0], vec![1.0, 1.0]);
        s.observe(&[4.0, -2.0]);
        // The corrected response maps the step onto what was observed.
        for (row, seen) in [(0, 4.0), (1, -2.0)] {
            let b: f64 = (0..2).map(|c| s.correction(row, c) * delta[c]).sum();
            assert!((1.0 + b - seen).abs() < 1e-12, "row {row}");
        }
    }
}
