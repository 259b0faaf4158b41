//! Gradient EM (ALGORITHMS.md 4) against exact answers on `lgss`: the gradient of Q^
//! against central differences, the BFGS M-step against the closed-form maximiser of
//! Q^ on fixed trajectories, and the EM fixed point against exact (Kalman) EM.

mod common;

use proptest::prelude::*;
use sysid::em::gradient::{GradientEm, GradientModel, Gradients, MStepOptions, m_step, q_hat};
use sysid::em::linear::{Covariance, LinearEm, LinearEmSpec};
use sysid::em::{EmAlgorithm, EmOptions, run_em};
use sysid::models::{LgssGradient, System};
use sysid::smc::{FfbsiReject, Series, Trajectories};

/// A gradient model with its shortcuts switched off: no closed-form dynamics step
/// (BFGS over every parameter), and with `finite_differences` the trait's default
/// central differences instead of the analytic gradients.
struct Plain<G> {
    inner: G,
    finite_differences: bool,
}

impl<G: GradientModel> GradientModel for Plain<G> {
    type Smc = G::Smc;
    type Params = G::Params;
    fn parameter_dim(&self) -> usize {
        self.inner.parameter_dim()
    }
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    fn parameter_names(&self) -> Vec<String> {
        self.inner.parameter_names()
    }
    fn constrained(&self, theta: &[f64]) -> Vec<f64> {
        self.inner.constrained(theta)
    }
    fn smc_model(&self, theta: &[f64]) -> Result<Self::Smc, sysid::em::gradient::GradientEmError> {
        self.inner.smc_model(theta)
    }
    fn unpack(&self, theta: &[f64]) -> Self::Params {
        self.inner.unpack(theta)
    }
    fn gradients(&self) -> Gradients {
        if self.finite_differences {
            Gradients::FiniteDifferences
        } else {
            self.inner.gradients()
        }
    }
    fn log_initial(&self, p: &Self::Params, x: &[f64]) -> f64 {
        self.inner.log_initial(p, x)
    }
    fn log_transition(
        &self,
        p: &Self::Params,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
    ) -> f64 {
        self.inner.log_transition(p, t, x, u, next)
    }
    fn log_observation(&self, p: &Self::Params, t: usize, x: &[f64], u: &[f64], y: &[f64]) -> f64 {
        self.inner.log_observation(p, t, x, u, y)
    }
    fn log_initial_gradient(&self, p: &Self::Params, x: &[f64], grad: &mut [f64]) -> f64 {
        self.inner.log_initial_gradient(p, x, grad)
    }
    fn log_transition_gradient(
        &self,
        p: &Self::Params,
        t: usize,
        x: &[f64],
        u: &[f64],
        next: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        self.inner.log_transition_gradient(p, t, x, u, next, grad)
    }
    fn log_observation_gradient(
        &self,
        p: &Self::Params,
        t: usize,
        x: &[f64],
        u: &[f64],
        y: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        self.inner.log_observation_gradient(p, t, x, u, y, grad)
    }
}

fn random_paths(steps: usize, paths: usize, seed: u64) -> (Trajectories, Vec<f64>) {
    use rand::RngExt;
    let mut rng = sysid::smc::stream(seed, 0);
    let mut states = vec![0.0; steps * paths];
    let mut y = vec![0.0; steps];
    for (t, yt) in y.iter_mut().enumerate() {
        *yt = rng.random::<f64>() * 4.0 - 2.0;
        for k in 0..paths {
            states[t * paths + k] = *yt + rng.random::<f64>() - 0.5;
        }
    }
    (
        Trajectories::from_states(steps, paths, 1, states).unwrap(),
        y,
    )
}

/// Central difference of Q^ itself in coordinate `i`.
fn fd_of_q<G: GradientModel>(
    model: &G,
    theta: &[f64],
    paths: &Trajectories,
    data: &Series,
    i: usize,
) -> f64 {
    let h = 1e-5 * theta[i].abs().max(1.0);
    let (mut up, mut down) = (theta.to_vec(), theta.to_vec());
    up[i] += h;
    down[i] -= h;
    (q_hat(model, &up, paths, data, None).unwrap()
        - q_hat(model, &down, paths, data, None).unwrap())
        / (2.0 * h)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn gradient_of_q_matches_central_differences(
        phi in -0.95f64..0.95, ln_q in -2.0f64..1.0, ln_r in -2.0f64..1.0, seed in 0u64..1000,
    ) {
        let (paths, y) = random_paths(40, 5, seed);
        let data = Series::new(&y, 1).unwrap();
        let theta = [phi, ln_q, ln_r];
        let analytic = LgssGradient { p1: 1.0, fixed_r: None };
        let numeric = Plain {
            inner: analytic,
            finite_differences: true,
        };
        let mut grad = vec![0.0; 3];
        let mut grad_default = vec![0.0; 3];
        let q = q_hat(&analytic, &theta, &paths, &data, Some(&mut grad)).unwrap();
        let q_default = q_hat(&numeric, &theta, &paths, &data, Some(&mut grad_default)).unwrap();
        prop_assert!((q - q_default).abs() <= 1e-12 * q.abs());
        let scale = grad.iter().fold(1.0f64, |m, g| m.max(g.abs()));
        for i in 0..3 {
            let fd = fd_of_q(&analytic, &theta, &paths, &data, i);
            prop_assert!((grad[i] - fd).abs() <= 1e-6 * scale, "analytic {} vs fd {} ({i})", grad[i], fd);
            prop_assert!((grad_default[i] - fd).abs() <= 1e-6 * scale, "default {} vs fd {} ({i})", grad_default[i], fd);
        }
    }
}

#[test]
fn bfgs_m_step_reaches_the_closed_form_maximiser_and_never_lowers_q() {
    let (paths, y) = random_paths(200, 20, 3);
    let data = Series::new(&y, 1).unwrap();
    let model = LgssGradient {
        p1: 1.0,
        fixed_r: None,
    };
    // closed form: phi = sum x x' / sum x^2, q = mean (x' - phi x)^2, r = mean (y - x)^2
    let (mut sxx, mut sxn, mut count) = (0.0, 0.0, 0.0);
    let mut sr = 0.0;
    for k in 0..20 {
        for (t, &yt) in y.iter().enumerate() {
            let x = paths.state(t, k)[0];
            sr += (yt - x).powi(2);
            if t + 1 < 200 {
                let next = paths.state(t + 1, k)[0];
                sxx += x * x;
                sxn += x * next;
                count += 1.0;
            }
        }
    }
    let phi = sxn / sxx;
    let mut sq = 0.0;
    for k in 0..20 {
        for t in 0..199 {
            sq += (paths.state(t + 1, k)[0] - phi * paths.state(t, k)[0]).powi(2);
        }
    }
    let exact = [phi, sq / count, sr / (20.0 * 200.0)];
    for start in [[0.0, 0.0, 0.0], [0.9, -1.0, 1.0], [-0.5, 2.0, -2.0]] {
        let out = m_step(
            &model,
            &paths,
            &data,
            &start,
            &MStepOptions::default(),
            None,
        )
        .unwrap();
        let fit = model.constrained(&out.theta);
        assert!(out.q_after >= out.q_before, "{out:?}");
        assert!(
            out.q_after > out.q_before + 1.0,
            "no progress from {start:?}: {out:?}"
        );
        for (f, e) in fit.iter().zip(exact) {
            assert!(
                (f - e).abs() < 1e-6 * e.abs().max(1.0),
                "{fit:?} vs {exact:?} ({})",
                out.status
            );
        }
    }
    // at the maximiser itself the step keeps (or very slightly improves) the value
    let at = [exact[0], exact[1].ln(), exact[2].ln()];
    let out = m_step(&model, &paths, &data, &at, &MStepOptions::default(), None).unwrap();
    assert!(out.q_after >= out.q_before);
}

#[test]
fn gradient_em_on_lgss_reaches_the_exact_em_estimate() {
    let truth = System::Lgss.model();
    let sim = System::Lgss.simulate(300, 8).unwrap();
    let y = sim.record.y.as_slice().to_vec();
    let r = truth.r()[(0, 0)];
    // exact reference: linear EM with C and R fixed, run to convergence (its fixed point
    // is the maximum-likelihood estimate of (A, Q))
    let spec = LinearEmSpec {
        c: false,
        r: Covariance::Fixed,
        h: false,
        mu: false,
        p1: false,
        ..LinearEmSpec::default()
    };
    let model = LgssGradient {
        p1: truth.p1()[(0, 0)],
        fixed_r: Some(r),
    };
    let start = vec![0.5, (0.5f64).ln()];
    let records = [sim.record.clone()];
    let mut linear = LinearEm::new(&records, spec);
    let exact_options = EmOptions {
        max_iterations: 5000,
        tol: 1e-13,
        ..EmOptions::default()
    }
    .check()
    .unwrap();
    let exact = run_em(
        &mut linear,
        model.linear_model(&start).unwrap(),
        &exact_options,
        &mut (),
    )
    .estimate;
    let exact = [exact.a()[(0, 0)], exact.q()[(0, 0)]];

    let data = Series::new(&y, 1).unwrap();
    // the E-step's filter: bootstrap, and fully adapted (the linear model's guided
    // proposal is exact)
    for guided in [false, true] {
        let smoother = FfbsiReject {
            paths: 100,
            max_trials: None,
            parallel: false,
        };
        let mut em =
            GradientEm::new(&model, data, 500, smoother, MStepOptions::default(), 3).unwrap();
        if guided {
            em = em.with_guided_filter();
        }
        let mut current = start.clone();
        let mut tail: Vec<Vec<f64>> = Vec::new();
        for k in 0..100 {
            current = em.step(&current).unwrap().0;
            let m = em.last_m_step().unwrap();
            assert!(m.q_after >= m.q_before, "iteration {k}: Q^ decreased");
            if k >= 50 {
                tail.push(model.constrained(&current));
            }
        }
        let label = if guided {
            "gradient EM, guided"
        } else {
            "gradient EM"
        };
        for (i, name) in ["phi", "q"].iter().enumerate() {
            let values: Vec<f64> = tail.iter().map(|v| v[i]).collect();
            common::assert_iterates_match(label, name, &values, exact[i]);
        }
    }
}

#[test]
fn wiener_gradient_matches_central_differences() {
    use sysid::models::{BlindWiener, WienerEstimate, WienerModel};
    let sim = BlindWiener::simulate(60, 4);
    let data = Series::new(&sim.outputs, 2).unwrap();
    let model = WienerModel::default();
    // trajectories: z near the truth's, second state arbitrary; offsets keep every z
    // away from the breakpoints (where Q^ has kinks and differences are meaningless)
    let paths = 3;
    let mut states = Vec::new();
    for t in 0..60 {
        for k in 0..paths {
            states.push(sim.z[t] + 0.1 * k as f64 + 0.0123);
            states.push(0.3 * sim.z[t.saturating_sub(1)] - 0.05 * k as f64);
        }
    }
    let paths = Trajectories::from_states(60, paths, 2, states).unwrap();
    for estimate in [
        WienerEstimate {
            a: [[1.0, -0.9], [1.0, 0.0]],
            q: [[1.0, 0.2], [0.2, 0.5]],
            beta: [-2.0, 3.0, -1.5, 1.0],
            r: [0.01, 0.02],
        },
        WienerEstimate {
            a: [[0.5, 0.1], [-0.3, 0.2]],
            q: [[2.0, -0.5], [-0.5, 1.0]],
            beta: [-0.2, 0.3, -0.15, 0.1],
            r: [0.1, 0.1],
        },
    ] {
        let theta = estimate.theta().unwrap();
        let back = WienerEstimate::from_theta(&theta);
        assert!(
            (back.q[1][0] - estimate.q[1][0]).abs() < 1e-12
                && (back.beta[1] - estimate.beta[1]).abs() < 1e-12
        );
        let mut grad = vec![0.0; 13];
        q_hat(&model, &theta, &paths, &data, Some(&mut grad)).unwrap();
        assert!(q_hat(&model, &theta[..12], &paths, &data, None).is_err());
        let scale = grad.iter().fold(1.0f64, |m, g| m.max(g.abs()));
        for (i, g) in grad.iter().enumerate() {
            let fd = fd_of_q(&model, &theta, &paths, &data, i);
            assert!(
                (g - fd).abs() <= 1e-6 * scale,
                "parameter {i}: analytic {g} vs fd {fd}"
            );
        }
    }
}

#[test]
fn wiener_closed_form_dynamics_step_is_the_maximiser_bfgs_finds() {
    use rand::RngExt;
    use sysid::models::{BlindWiener, WienerEstimate, WienerModel};
    let steps = 200;
    let sim = BlindWiener::simulate(steps, 5);
    let data = Series::new(&sim.outputs, 2).unwrap();
    let model = WienerModel::default();
    // four paths near the linear part's output and its lag, with uniform noise
    let mut rng = sysid::smc::stream(11, 0);
    let mut states = Vec::new();
    for t in 0..steps {
        for k in 0..4 {
            states.push(sim.z[t] + 0.3 * (rng.random::<f64>() - 0.5));
            let lag = if t == 0 { 0.0 } else { sim.z[t - 1] };
            states.push(lag + 0.2 * (rng.random::<f64>() - 0.5) + 0.1 * k as f64);
        }
    }
    let paths = Trajectories::from_states(steps, 4, 2, states).unwrap();
    let start = WienerEstimate {
        a: [[0.5, 0.1], [-0.3, 0.2]],
        q: [[2.0, -0.5], [-0.5, 1.0]],
        beta: [-2.5, 2.5, -1.0, 1.5],
        r: [0.1, 0.1],
    }
    .theta()
    .unwrap();

    let mut closed = start.clone();
    let held = model
        .maximise_dynamics(&paths, &mut closed)
        .expect("a closed form");
    assert_eq!(held, (0..7).collect::<Vec<_>>());
    assert_eq!(closed[7..], start[7..]);
    // first-order optimality in the dynamics' entries, and a higher Q^ than at the start
    let (mut grad_start, mut grad_closed) = (vec![0.0; 13], vec![0.0; 13]);
    let q_start = q_hat(&model, &start, &paths, &data, Some(&mut grad_start)).unwrap();
    let q_closed = q_hat(&model, &closed, &paths, &data, Some(&mut grad_closed)).unwrap();
    assert!(q_closed > q_start + 1.0, "{q_closed} vs {q_start}");
    let scale = grad_start[..7].iter().fold(1.0f64, |m, g| m.max(g.abs()));
    for (i, g) in grad_closed[..7].iter().enumerate() {
        assert!(
            g.abs() < 1e-9 * scale,
            "entry {i}: gradient {g} at the closed form"
        );
    }

    // direct optimisation: BFGS over all 13 entries reaches the same dynamics
    let options = MStepOptions {
        max_iterations: 1000,
        tol_grad: 1e-10,
        ..MStepOptions::default()
    };
    let all_by_bfgs = Plain {
        inner: model,
        finite_differences: false,
    };
    let bfgs = m_step(&all_by_bfgs, &paths, &data, &start, &options, None).unwrap();
    for (i, (b, c)) in bfgs.theta[..7].iter().zip(&closed[..7]).enumerate() {
        assert!(
            (b - c).abs() < 1e-5 * c.abs().max(1.0),
            "entry {i}: BFGS {b} vs closed form {c} ({})",
            bfgs.status
        );
    }

    // the M-step with the closed form: the same dynamics, BFGS on the rest, Q^ up
    let out = m_step(&model, &paths, &data, &start, &options, None).unwrap();
    assert_eq!(out.theta[..7], closed[..7]);
    assert!(out.q_after >= q_closed, "{} vs {q_closed}", out.q_after);
    assert!(
        (out.q_after - bfgs.q_after).abs() < 1e-6 * bfgs.q_after.abs(),
        "closed form + BFGS {} vs BFGS {}",
        out.q_after,
        bfgs.q_after
    );
}

#[test]
fn wiener_sorted_observation_sum_equals_the_term_by_term_sum() {
    use rand::RngExt;
    use sysid::models::{BlindWiener, WienerEstimate, WienerModel};
    let (steps, k) = (150, 5);
    let sim = BlindWiener::simulate(steps, 8);
    let mut outputs = sim.outputs.clone();
    // some missing outputs, one of each kind and one whole step
    outputs[2 * 10] = f64::NAN;
    outputs[2 * 20 + 1] = f64::NAN;
    outputs[2 * 30] = f64::NAN;
    outputs[2 * 30 + 1] = f64::NAN;
    let data = Series::new(&outputs, 2).unwrap();
    let mut rng = sysid::smc::stream(12, 0);
    let mut states = Vec::new();
    for t in 0..steps {
        for _ in 0..k {
            states.push(sim.z[t] + rng.random::<f64>() - 0.5);
            states.push(rng.random::<f64>());
        }
    }
    let tie = states[2 * 7]; // a state's z exactly at a breakpoint
    let paths = Trajectories::from_states(steps, k, 2, states).unwrap();
    let model = WienerModel::default();
    let direct = |theta: &[f64]| {
        let p = model.unpack(theta);
        let mut total = 0.0;
        for t in 0..steps {
            for x in paths.states(t).chunks_exact(2) {
                total += model.log_observation(&p, t, x, &[], data.output(t));
            }
        }
        total / k as f64
    };
    let prepared = model.prepare_observations(&paths, &data).expect("prepared");
    for beta in [
        [-2.0, 3.0, -1.5, 1.0],
        [-0.2, 0.3, -0.15, 0.1],
        [tie, tie + 1.0, tie - 1.0, tie],
        [-40.0, 50.0, 30.0, 60.0],
    ] {
        let theta = WienerEstimate {
            a: [[0.5, 0.1], [-0.3, 0.2]],
            q: [[2.0, -0.5], [-0.5, 1.0]],
            beta,
            r: [0.05, 0.2],
        }
        .theta()
        .unwrap();
        let mut grad = vec![0.0; 13];
        let value = prepared.value_and_gradient(&theta, &mut grad);
        let expected = direct(&theta);
        assert!(
            (value - expected).abs() < 1e-10 * expected.abs(),
            "beta {beta:?}: {value} vs {expected}"
        );
        let mut full = vec![0.0; 13];
        q_hat(&model, &theta, &paths, &data, Some(&mut full)).unwrap();
        assert!(grad[..7].iter().all(|&g| g == 0.0));
        for i in 7..13 {
            assert!(
                (grad[i] - full[i]).abs() < 1e-9 * full[i].abs().max(1.0),
                "beta {beta:?}, entry {i}: {} vs {}",
                grad[i],
                full[i]
            );
        }
    }
}

#[test]
fn wiener_exact_breakpoints_beat_a_grid_local_moves_and_bfgs() {
    use rand::RngExt;
    use sysid::models::{BlindWiener, WienerEstimate, WienerModel, dead_zone, saturation};
    let (steps, k) = (300, 4);
    let sim = BlindWiener::simulate(steps, 9);
    let data = Series::new(&sim.outputs, 2).unwrap();
    let mut rng = sysid::smc::stream(13, 0);
    let mut states = Vec::new();
    for t in 0..steps {
        for _ in 0..k {
            states.push(sim.z[t] + 0.4 * (rng.random::<f64>() - 0.5));
            states.push(rng.random::<f64>());
        }
    }
    let paths = Trajectories::from_states(steps, k, 2, states).unwrap();
    let model = WienerModel::default();
    // the residual sums of squares of both outputs, term by term
    let rss = |beta: [f64; 4]| {
        let mut total = [0.0; 2];
        for t in 0..steps {
            let y = data.output(t);
            for x in paths.states(t).chunks_exact(2) {
                total[0] += (y[0] - saturation(x[0], beta[0], beta[1])).powi(2);
                total[1] += (y[1] - dead_zone(x[0], beta[2], beta[3])).powi(2);
            }
        }
        total
    };
    let start = WienerEstimate {
        a: [[1.0, -0.9], [1.0, 0.0]],
        q: [[1.0, 0.0], [0.0, 0.01]],
        beta: [-0.2, 0.3, -0.15, 0.1],
        r: [0.1, 0.1],
    }
    .theta()
    .unwrap();
    let prepared = model.prepare_observations(&paths, &data).unwrap();
    let mut exact = start.clone();
    assert!(prepared.maximise(&mut exact));
    assert_eq!(exact[..7], start[..7]);
    let found = WienerEstimate::from_theta(&exact);
    let best = rss(found.beta);
    let n = (steps * k) as f64;
    for (r, rss) in found.r.iter().zip(best) {
        assert!((r - rss / n).abs() < 1e-9 * r, "r {r} vs RSS/n {}", rss / n);
    }
    // no grid point and no small move of a breakpoint does better, output by output
    let grid = |lo: f64, hi: f64| (0..=40).map(move |j| lo + (hi - lo) * j as f64 / 40.0);
    for b1 in grid(-4.0, 1.0) {
        for b2 in grid(-1.0, 5.0).filter(|&b2| b2 > b1) {
            let other = rss([b1, b2, found.beta[2], found.beta[3]]);
            assert!(best[0] <= other[0] * (1.0 + 1e-12), "saturation {b1}, {b2}");
        }
    }
    for b3 in grid(-4.0, 1.0) {
        for b4 in grid(-1.0, 4.0).filter(|&b4| b4 > b3) {
            let other = rss([found.beta[0], found.beta[1], b3, b4]);
            assert!(best[1] <= other[1] * (1.0 + 1e-12), "dead zone {b3}, {b4}");
        }
    }
    for i in 0..4 {
        for step in [-1e-2, -1e-4, 1e-4, 1e-2] {
            let mut moved = found.beta;
            moved[i] += step;
            let other = rss(moved);
            assert!(
                best[i / 2] <= other[i / 2] * (1.0 + 1e-12),
                "breakpoint {i} moved by {step}"
            );
        }
    }
    // and BFGS on I3 from the same start ends no higher
    let by_bfgs = MStepOptions {
        exact_observations: false,
        ..MStepOptions::default()
    };
    let bfgs = m_step(&model, &paths, &data, &start, &by_bfgs, None).unwrap();
    let exact_step = m_step(
        &model,
        &paths,
        &data,
        &start,
        &MStepOptions::default(),
        None,
    )
    .unwrap();
    assert_eq!(exact_step.evaluations, 0, "{}", exact_step.status);
    assert_eq!(exact_step.theta[7..], exact[7..]);
    assert!(
        exact_step.q_after >= bfgs.q_after - 1e-9 * bfgs.q_after.abs(),
        "exact {} vs BFGS {} ({})",
        exact_step.q_after,
        bfgs.q_after,
        bfgs.status
    );
}

/// The whole blind Wiener pipeline on one realisation at the lecture's settings
/// (T = 1000, M = 100, the lecture's start), 60 iterations: the breakpoints within
/// 5 %, the noise variances within 50 % of 0.01 and the normalised magnitude error
/// below 0.1. With the bootstrap filter in the E-step this realisation ends with
/// `r2 = 0.030` and `beta3` 5 % off; without the canonical noise form the guided
/// filter loses the state at iteration 18.
#[test]
fn blind_wiener_em_recovers_one_realisation() {
    use sysid::models::{
        BlindWiener, WienerEstimate, WienerModel, normalised_magnitude_error, wiener_start,
    };
    let sim = BlindWiener::simulate(1000, 1);
    let data = Series::new(&sim.outputs, 2).unwrap();
    let start = wiener_start(&sim.outputs).unwrap();
    let model = WienerModel::default();
    let smoother = FfbsiReject {
        paths: 100,
        max_trials: None,
        parallel: false,
    };
    let mut em = GradientEm::new(&model, data, 100, smoother, MStepOptions::default(), 1)
        .unwrap()
        .with_guided_filter();
    let options = EmOptions {
        max_iterations: 60,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .unwrap();
    let fit = run_em(&mut em, start.theta().unwrap(), &options, &mut ());
    assert!(
        matches!(fit.termination, sysid::em::Termination::MaxIterations),
        "{:?}",
        fit.termination
    );
    let estimate = WienerEstimate::from_theta(&fit.estimate);
    for (b, truth) in estimate.beta.iter().zip(BlindWiener::BETA) {
        assert!(
            (b - truth).abs() < 0.05 * truth.abs(),
            "{:?}",
            estimate.beta
        );
    }
    for r in estimate.r {
        assert!((r - 0.01).abs() < 0.005, "{:?}", estimate.r);
    }
    let magnitude = normalised_magnitude_error(&estimate);
    assert!(magnitude < 0.1, "magnitude error {magnitude}");
    // the canonical form: A is a companion matrix
    assert_eq!(estimate.a[0], [0.0, 1.0]);
}
