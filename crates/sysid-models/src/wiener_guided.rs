//! The fully adapted proposal of the blind Wiener model: `p(y_t | x_{t-1})` and
//! `p(x_t | x_{t-1}, y_t)` in closed form, for `sysid_smc::GuidedFilter`.
//!
//! # Model
//! With `L` the Cholesky factor of `Q` and `z_t = x_{t,1}`,
//! ```text
//! z_t         = (A x_{t-1})_1 + L11 e1,                 e1, e2 ~ N(0, 1)
//! x_{t,2}     = (A x_{t-1})_2 + L21 e1 + L22 e2
//! y_{t,i}     = h_i(z_t) + N(0, r_i)
//! ```
//! so `y_t` depends on `x_t` through the scalar `z_t ~ N(m, L11^2)` alone.
//!
//! # Algorithm
//! Between consecutive sorted breakpoints both `h1` and `h2` are affine in `z` (slope
//! 0 or 1), so on each of the (at most five) intervals `N(z; m, s) g(y | z)` is a
//! constant times a Gaussian in `z`: an output with slope 1 updates the Gaussian as a
//! scalar Kalman step and contributes its predictive density, one with slope 0 a
//! constant. Then
//! `p(y | x_{t-1}) = sum_k c_k P(lo_k <= N(m_k, s_k) <= hi_k)` (normal interval
//! probabilities in the log domain), `z_t` is drawn from the mixture of truncated
//! normals, and `e1 = (z_t - m) / L11`, `e2 ~ N(0, 1)` give the second state. The
//! initial step is the same with `x_0 ~ N(0, p1 I)`.
//!
//! Each piece's constant bounds its mass, so the interval probabilities (the costly
//! part: `erfc`) are computed largest bound first, and a piece whose bound lies more
//! than 40 log units below the largest mass so far is left out (a relative change
//! of the total below `e^-40`).
//!
//! # Complexity
//! O(1) per particle: at most five interval probabilities and, for a draw, one
//! truncated normal draw.

use crate::truncated_normal::{ln_interval_probability, sample_interval};
use crate::wiener::{LN_2PI, Unpacked, WienerSmc};
use rand::{Rng, RngExt};
use rand_distr::{Distribution, StandardNormal};
use sysid_smc::GuidedProposal;

/// How far (in log units) below the largest piece a piece's upper bound may lie
/// before it is left out of the mixture.
const NEGLIGIBLE: f64 = 40.0;

/// One interval of the posterior of `z`: the Gaussian `N(mean, sd^2)` restricted to
/// `[lo, hi]`, with log-weight `ln_mass`.
#[derive(Debug, Clone, Copy)]
struct Piece {
    lo: f64,
    hi: f64,
    mean: f64,
    sd: f64,
    ln_mass: f64,
}

/// `p(z | y)` (up to the prior's normalisation) as a mixture of truncated normals,
/// and `ln p(y)`.
#[derive(Debug, Clone, Copy)]
struct ZPosterior {
    pieces: [Piece; 5],
    ln_total: f64,
}

impl Unpacked {
    /// The slope (0 or 1) and offset of `h1` and `h2` on the open interval between
    /// consecutive breakpoints that contains `z`.
    fn affine_pieces(&self, z: f64) -> [(bool, f64); 2] {
        let b = self.beta;
        let saturation = if z < b[0] {
            (false, b[0])
        } else if z > b[1] {
            (false, b[1])
        } else {
            (true, 0.0)
        };
        let dead_zone = if z < b[2] {
            (true, -b[2])
        } else if z > b[3] {
            (true, -b[3])
        } else {
            (false, 0.0)
        };
        [saturation, dead_zone]
    }

    /// The per-piece constants of `p(z | y)` for the prior variance `var`, with the
    /// outputs marked observed (`observed[i]`) and the rest left out.
    pub(crate) fn guide_form(&self, var: f64, observed: [bool; 2]) -> GuideForm {
        let mut cuts = self.beta;
        cuts.sort_by(f64::total_cmp);
        let edges = [
            f64::NEG_INFINITY,
            cuts[0],
            cuts[1],
            cuts[2],
            cuts[3],
            f64::INFINITY,
        ];
        let pieces = std::array::from_fn(|k| {
            let (lo, hi) = (edges[k], edges[k + 1]);
            let inside = if lo == f64::NEG_INFINITY {
                hi - 1.0
            } else if hi == f64::INFINITY {
                lo + 1.0
            } else {
                0.5 * (lo + hi)
            };
            let mut v = var;
            let affine = self.affine_pieces(inside);
            let outputs = std::array::from_fn(|i| {
                let (slope, offset) = affine[i];
                if !observed[i] {
                    OutputForm::default()
                } else if slope {
                    // y_i = z + offset + noise: a scalar Kalman update of z
                    let s = v + self.r[i];
                    let gain = v / s;
                    v *= self.r[i] / s;
                    OutputForm {
                        slope: 1.0,
                        offset,
                        ln_norm: -0.5 * (LN_2PI + s.ln()),
                        half_inv_var: 0.5 / s,
                        gain,
                    }
                } else {
                    OutputForm {
                        slope: 0.0,
                        offset,
                        ln_norm: self.observation_norm[i],
                        half_inv_var: 0.5 * self.inv_r[i],
                        gain: 0.0,
                    }
                }
            });
            PieceForm {
                lo,
                hi,
                outputs,
                sd: v.sqrt(),
            }
        });
        GuideForm { pieces }
    }
}

/// What `p(z | y)` needs that does not depend on the prior mean or on `y`: per piece
/// the interval, the Kalman gains and normalisations of its affine outputs, and the
/// posterior standard deviation. Made once per parameter value (and prior variance).
#[derive(Debug, Clone, Copy)]
pub(crate) struct GuideForm {
    pieces: [PieceForm; 5],
}

#[derive(Debug, Clone, Copy)]
struct PieceForm {
    lo: f64,
    hi: f64,
    outputs: [OutputForm; 2],
    sd: f64,
}

/// One output on one piece: `y_i = slope z + offset + N(0, r_i)`. Its factor is
/// `exp(ln_norm - half_inv_var e^2)` with `e = y_i - offset - slope m`, and the mean
/// moves by `gain e`; an unobserved output has every constant 0.
#[derive(Debug, Clone, Copy, Default)]
struct OutputForm {
    slope: f64,
    offset: f64,
    ln_norm: f64,
    half_inv_var: f64,
    gain: f64,
}

impl GuideForm {
    /// `p(z | y)` for the prior `z ~ N(mean, var)` (the variance of the form); the
    /// outputs the form leaves out are ignored.
    fn posterior(&self, mean: f64, y: &[f64]) -> ZPosterior {
        let mut pieces: [Piece; 5] = std::array::from_fn(|k| {
            let form = &self.pieces[k];
            let (mut m, mut ln_c) = (mean, 0.0);
            for (o, &y) in form.outputs.iter().zip(y) {
                if o.half_inv_var > 0.0 {
                    let e = y - o.offset - o.slope * m;
                    ln_c += o.ln_norm - o.half_inv_var * e * e;
                    m += o.gain * e;
                }
            }
            Piece {
                lo: form.lo,
                hi: form.hi,
                mean: m,
                sd: form.sd,
                // for now the bound ln c >= ln(c P(lo <= z <= hi))
                ln_mass: ln_c,
            }
        });
        // the interval probabilities, largest bound first; a piece whose bound is
        // NEGLIGIBLE below the largest mass so far is left out (a relative change
        // below e^-40 of the total)
        let first = (0..5)
            .max_by(|&i, &j| pieces[i].ln_mass.total_cmp(&pieces[j].ln_mass))
            .unwrap_or(0);
        let mut best = f64::NEG_INFINITY;
        for k in std::iter::once(first).chain((0..5).filter(|&k| k != first)) {
            let p = &mut pieces[k];
            if p.ln_mass < best - NEGLIGIBLE {
                p.ln_mass = f64::NEG_INFINITY;
                continue;
            }
            p.ln_mass += if p.sd > 0.0 {
                ln_interval_probability((p.lo - p.mean) / p.sd, (p.hi - p.mean) / p.sd)
            } else if p.lo <= p.mean && p.mean <= p.hi {
                // a point prediction (L11 underflowed): all mass at the mean
                0.0
            } else {
                f64::NEG_INFINITY
            };
            best = best.max(p.ln_mass);
        }
        let ln_total = if best == f64::NEG_INFINITY {
            best
        } else {
            best + pieces
                .iter()
                .map(|p| (p.ln_mass - best).exp())
                .sum::<f64>()
                .ln()
        };
        ZPosterior { pieces, ln_total }
    }
}

impl ZPosterior {
    /// A draw of `z`; from the prior `N(mean, var)` when no piece has positive mass
    /// (the filter gives such a parent zero weight, so it is never drawn).
    fn sample<R: Rng + ?Sized>(&self, mean: f64, var: f64, rng: &mut R) -> f64 {
        if !self.ln_total.is_finite() {
            let e: f64 = StandardNormal.sample(rng);
            return mean + var.sqrt() * e;
        }
        let u: f64 = rng.random();
        let mut cumulative = 0.0;
        let mut chosen = None;
        for p in &self.pieces {
            let w = (p.ln_mass - self.ln_total).exp();
            if w > 0.0 {
                chosen = Some(p);
                cumulative += w;
                if u < cumulative {
                    break;
                }
            }
        }
        let p = chosen.expect("a finite total has a piece of positive mass");
        if p.sd == 0.0 {
            return p.mean;
        }
        let alpha = (p.lo - p.mean) / p.sd;
        let beta = (p.hi - p.mean) / p.sd;
        p.mean + p.sd * sample_interval(alpha, beta, rng)
    }
}

impl WienerSmc {
    /// The mean of `x_{t+1}` given `x_t`.
    fn predicted(&self, x: &[f64]) -> [f64; 2] {
        let a = &self.p.a;
        [
            a[0][0] * x[0] + a[0][1] * x[1],
            a[1][0] * x[0] + a[1][1] * x[1],
        ]
    }

    /// `p(z_{t+1} | x_t, y_{t+1})` given the predicted mean of `z_{t+1}`.
    fn step_posterior(&self, mean: f64, y: &[f64]) -> ZPosterior {
        let observed = [!y[0].is_nan(), !y[1].is_nan()];
        if observed == [true, true] {
            self.guide.posterior(mean, y)
        } else {
            let var = self.p.l11 * self.p.l11;
            self.p.guide_form(var, observed).posterior(mean, y)
        }
    }

    /// `p(z_0 | y_0)`.
    fn initial_posterior(&self, y: &[f64]) -> ZPosterior {
        let observed = [!y[0].is_nan(), !y[1].is_nan()];
        let var = self.sd_p1 * self.sd_p1;
        self.p.guide_form(var, observed).posterior(0.0, y)
    }
}

impl GuidedProposal for WienerSmc {
    fn sample_initial_guided<R: Rng + ?Sized>(
        &self,
        _u: &[f64],
        y: &[f64],
        x: &mut [f64],
        rng: &mut R,
    ) {
        let var = self.sd_p1 * self.sd_p1;
        x[0] = self.initial_posterior(y).sample(0.0, var, rng);
        let e: f64 = StandardNormal.sample(rng);
        x[1] = self.sd_p1 * e;
    }

    fn log_initial_predictive(&self, _u: &[f64], y: &[f64]) -> f64 {
        self.initial_posterior(y).ln_total
    }

    fn log_predictive(
        &self,
        _t: usize,
        x: &[f64],
        _u: &[f64],
        _u_next: &[f64],
        y_next: &[f64],
    ) -> f64 {
        self.step_posterior(self.predicted(x)[0], y_next).ln_total
    }

    fn sample_guided<R: Rng + ?Sized>(
        &self,
        _t: usize,
        x: &[f64],
        _u: &[f64],
        _u_next: &[f64],
        y_next: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let mean = self.predicted(x);
        let var = self.p.l11 * self.p.l11;
        let z = self
            .step_posterior(mean[0], y_next)
            .sample(mean[0], var, rng);
        let e1 = (z - mean[0]) / self.p.l11;
        let e2: f64 = StandardNormal.sample(rng);
        next[0] = z;
        next[1] = mean[1] + self.p.l21 * e1 + self.p.l22 * e2;
    }
}

#[cfg(test)]
mod tests {
    use crate::wiener::{WienerEstimate, WienerModel, dead_zone, saturation};
    use sysid_em::gradient::GradientModel;
    use sysid_smc::GuidedProposal;

    /// `ln int N(z; m, s) g(y | z) dz` and the posterior mean and variance of `z`, by
    /// the midpoint rule on 400 000 cells over `[-40, 40]`.
    fn quadrature(beta: [f64; 4], r: [f64; 2], m: f64, s: f64, y: [f64; 2]) -> (f64, f64, f64) {
        let ln_density = |z: f64| {
            let mut l = -0.5 * ((2.0 * std::f64::consts::PI * s).ln() + (z - m).powi(2) / s);
            let h = [
                saturation(z, beta[0], beta[1]),
                dead_zone(z, beta[2], beta[3]),
            ];
            for i in 0..2 {
                if !y[i].is_nan() {
                    l -= 0.5
                        * ((2.0 * std::f64::consts::PI * r[i]).ln() + (y[i] - h[i]).powi(2) / r[i]);
                }
            }
            l
        };
        let (lo, hi, cells) = (-40.0, 40.0, 400_000);
        let h = (hi - lo) / cells as f64;
        let grid: Vec<f64> = (0..cells).map(|k| lo + (k as f64 + 0.5) * h).collect();
        let top = grid
            .iter()
            .map(|&z| ln_density(z))
            .fold(f64::NEG_INFINITY, f64::max);
        let (mut m0, mut m1, mut m2) = (0.0, 0.0, 0.0);
        for &z in &grid {
            let w = (ln_density(z) - top).exp();
            m0 += w;
            m1 += w * z;
            m2 += w * z * z;
        }
        let mean = m1 / m0;
        (top + (m0 * h).ln(), mean, m2 / m0 - mean * mean)
    }

    fn smc(beta: [f64; 4], r: [f64; 2], q11: f64) -> crate::wiener::WienerSmc {
        let estimate = WienerEstimate {
            a: [[1.2, -0.5], [0.7, 0.1]],
            q: [[q11, 0.3 * q11], [0.3 * q11, 0.5 + 0.09 * q11]],
            beta,
            r,
        };
        WienerModel::default()
            .smc_model(&estimate.theta().unwrap())
            .unwrap()
    }

    /// The predictive density equals quadrature, and 20 000 draws of `x_t` have the
    /// posterior moments of `z` and the implied moments of the second state within 4
    /// Monte Carlo standard errors: in the linear pieces, in a flat piece, in a far
    /// tail, with a missing output, and at the lecture's start (breakpoints a tenth
    /// of the truth, r = 0.1).
    #[test]
    fn the_proposal_is_the_exact_posterior() {
        let truth = ([-2.0, 3.0, -1.5, 1.0], [0.01, 0.01]);
        let start = ([-0.2, 0.3, -0.15, 0.1], [0.1, 0.1]);
        let cases = [
            (truth, 1.0, [0.4, 0.2], [0.5, 0.0]),
            (truth, 2.0, [1.0, -0.3], [3.0, 1.5]),
            (truth, 0.5, [-4.0, 2.0], [-2.0, -3.5]),
            (truth, 0.3, [-9.0, 1.0], [3.02, 2.1]),
            (truth, 1.5, [0.0, 0.0], [2.5, f64::NAN]),
            (start, 9.0, [2.0, 0.0], [0.3, -2.6]),
        ];
        let mut rng = sysid_smc::stream(5, 0);
        for ((beta, r), q11, x, y) in cases {
            let model = smc(beta, r, q11);
            let m = [1.2 * x[0] - 0.5 * x[1], 0.7 * x[0] + 0.1 * x[1]];
            let (ln_p, z_mean, z_var) = quadrature(beta, r, m[0], q11, y);
            let ln_guided = model.log_predictive(0, &x, &[], &[], &y);
            assert!(
                (ln_guided - ln_p).abs() < 1e-6,
                "{y:?}: {ln_guided} vs {ln_p}"
            );
            let n = 20_000;
            let mut next = [0.0; 2];
            let (mut s0, mut s00, mut s1, mut s11) = (0.0, 0.0, 0.0, 0.0);
            for _ in 0..n {
                model.sample_guided(0, &x, &[], &[], &y, &mut next, &mut rng);
                s0 += next[0];
                s00 += next[0] * next[0];
                s1 += next[1];
                s11 += next[1] * next[1];
            }
            let nf = n as f64;
            let (mean0, mean1) = (s0 / nf, s1 / nf);
            let (var0, var1) = (s00 / nf - mean0 * mean0, s11 / nf - mean1 * mean1);
            // x_2 = m_2 + L21 (z - m_1) / L11 + L22 e2 with L21 / L11 = 0.3, L22^2 = 0.5
            let l22_sq = 0.5;
            let x2_mean = m[1] + 0.3 * (z_mean - m[0]);
            let x2_var = 0.09 * z_var + l22_sq;
            // 4 standard errors; a sample variance's variance is below 3 var^2 / n for
            // these mixtures
            let checks = [
                ("z mean", mean0, z_mean, (z_var / nf).sqrt()),
                ("x2 mean", mean1, x2_mean, (x2_var / nf).sqrt()),
                ("z var", var0, z_var, z_var * (3.0 / nf).sqrt()),
                ("x2 var", var1, x2_var, x2_var * (3.0 / nf).sqrt()),
            ];
            for (what, sample, exact, se) in checks {
                assert!(
                    (sample - exact).abs() < 4.0 * se,
                    "{y:?}: {what} {sample} vs {exact}"
                );
            }
        }
    }

    /// The initial step: `z_0 ~ N(0, p1)` conditioned on `y_0`.
    #[test]
    fn the_initial_predictive_is_exact() {
        let (beta, r) = ([-2.0, 3.0, -1.5, 1.0], [0.01, 0.01]);
        let model = smc(beta, r, 1.0);
        let p1 = WienerModel::default().p1;
        for y in [[0.7, 0.0], [3.1, 4.0], [-2.0, -6.5]] {
            let (ln_p, _, _) = quadrature(beta, r, 0.0, p1, y);
            let ln_guided = model.log_initial_predictive(&[], &y);
            assert!(
                (ln_guided - ln_p).abs() < 1e-6,
                "{y:?}: {ln_guided} vs {ln_p}"
            );
        }
    }
}
