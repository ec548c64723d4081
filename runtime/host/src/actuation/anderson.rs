//! Anderson acceleration (Walker & Ni, SIAM J. Numer. Anal. 49, 2011) of
//! the follower-force fixed point: the forces applied, `f`, give a shape,
//! whose forces are `g(f)`; the settled forces solve `g(f) = f`. Plain
//! iteration `f ← g(f)` contracts slowly where the forces turn with the
//! walls they bend (measured on the finger at 10 kPa: 22 repeated steps
//! to 0.1 %); Anderson mixes the last `depth` iterates to cancel the slow
//! direction.

use voxflex_core::glam::DVec3;

/// The mixing history.
#[derive(Clone, Debug)]
pub(crate) struct Anderson {
    depth: usize,
    /// Past `g(f)` and residuals `g(f) − f`, flattened.
    outputs: Vec<Vec<f64>>,
    residuals: Vec<Vec<f64>>,
}

impl Anderson {
    /// An empty history mixing at most `depth` past iterates.
    pub(crate) fn new(depth: usize) -> Self {
        Self {
            depth,
            outputs: Vec::new(),
            residuals: Vec::new(),
        }
    }

    /// The next forces to apply, from the forces applied `input` and the
    /// forces they led to `output`.
    pub(crate) fn next(&mut self, input: &[DVec3], output: &[DVec3]) -> Vec<DVec3> {
        let g: Vec<f64> = output.iter().flat_map(|v| v.to_array()).collect();
        let r: Vec<f64> = g
            .iter()
            .zip(input.iter().flat_map(|v| v.to_array()))
            .map(|(a, b)| a - b)
            .collect();
        self.outputs.push(g.clone());
        self.residuals.push(r.clone());
        if self.outputs.len() > self.depth + 1 {
            self.outputs.remove(0);
            self.residuals.remove(0);
        }
        let m = self.residuals.len() - 1;
        let mixed = if m == 0 {
            g
        } else {
            let dr: Vec<Vec<f64>> = (0..m)
                .map(|j| diff(&self.residuals[j + 1], &self.residuals[j]))
                .collect();
            let gamma = least_squares(&dr, &r);
            let mut x = g.clone();
            for (j, c) in gamma.iter().enumerate() {
                let dg = diff(&self.outputs[j + 1], &self.outputs[j]);
                for (xi, d) in x.iter_mut().zip(dg) {
                    *xi -= c * d;
                }
            }
            // Safeguard: a mix farther from the plain iterate than the
            // residual itself is an extrapolation the history cannot
            // support (nearly dependent columns); take the plain iterate
            // and start the history again.
            let jump = norm(&diff(&x, &g));
            if jump.is_finite() && jump <= SAFE_JUMP * norm(&r) {
                x
            } else {
                self.outputs.clear();
                self.residuals.clear();
                self.outputs.push(g.clone());
                self.residuals.push(r);
                g
            }
        };
        mixed
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect()
    }
}

/// The largest distance from the plain iterate a mix may take, in
/// residual norms: a fixed point contracting by ρ lies ρ/(1 − ρ)
/// residuals away, so 20 allows ρ up to 0.95.
const SAFE_JUMP: f64 = 20.0;

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn diff(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

/// `argmin ‖Σ γ_j columns_j − target‖` by the normal equations with a
/// tiny ridge (columns may be nearly dependent), Gaussian elimination.
fn least_squares(columns: &[Vec<f64>], target: &[f64]) -> Vec<f64> {
    let m = columns.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut a: Vec<Vec<f64>> = (0..m)
        .map(|i| (0..m).map(|j| dot(&columns[i], &columns[j])).collect())
        .collect();
    let mut b: Vec<f64> = (0..m).map(|i| dot(&columns[i], target)).collect();
    let ridge = 1e-10 * (0..m).map(|i| a[i][i]).fold(0.0, f64::max);
    for (i, row) in a.iter_mut().enumerate() {
        row[i] += ridge.max(f64::MIN_POSITIVE);
    }
    for k in 0..m {
        let pivot = (k..m)
            .max_by(|&x, &y| a[x][k].abs().total_cmp(&a[y][k].abs()))
            .unwrap_or(k);
        a.swap(k, pivot);
        b.swap(k, pivot);
        if a[k][k].abs() < f64::MIN_POSITIVE {
            return vec![0.0; m];
        }
        let (upper, lower) = a.split_at_mut(k + 1);
        let pivot_row = &upper[k];
        for (i, row) in lower.iter_mut().enumerate() {
            let f = row[k] / pivot_row[k];
            for (x, p) in row[k..].iter_mut().zip(&pivot_row[k..]) {
                *x -= f * p;
            }
            b[k + 1 + i] -= f * b[k];
        }
    }
    let mut x = vec![0.0; m];
    for k in (0..m).rev() {
        let s: f64 = (k + 1..m).map(|j| a[k][j] * x[j]).sum();
        x[k] = (b[k] - s) / a[k][k];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slowly contracting linear map (factor 0.95 along one direction,
    /// 0.3 along another): plain iteration needs ~300 steps for 1e-7,
    /// Anderson a handful.
    #[test]
    fn a_slow_linear_fixed_point_converges_in_a_few_mixed_steps() {
        let fixed = [DVec3::new(2.0, -1.0, 0.5)];
        let g = |f: &[DVec3]| {
            let d = f[0] - fixed[0];
            vec![fixed[0] + DVec3::new(0.95 * d.x + 0.1 * d.y, 0.3 * d.y, 0.5 * d.z)]
        };
        let mut acc = Anderson::new(3);
        let mut f = vec![DVec3::ZERO];
        let mut steps = 0;
        while (f[0] - fixed[0]).length() > 1e-7 && steps < 50 {
            let out = g(&f);
            f = acc.next(&f, &out);
            steps += 1;
        }
        assert!(steps <= 8, "{steps} steps, at {}", f[0]);
    }

    #[test]
    fn the_first_step_is_the_plain_iterate() {
        let mut acc = Anderson::new(3);
        let out = acc.next(&[DVec3::ZERO], &[DVec3::ONE]);
        assert_eq!(out, vec![DVec3::ONE]);
    }
}
