//! The runner's termination paths, on toy algorithms with known behaviour.

use sysid_em::{
    CheckedEmOptions, EmAlgorithm, EmObserver, EmOptions, IterationInfo, Termination, run_em,
};

/// Estimates are integers k; the log-likelihood of k is `lik[k]`; a step goes k -> k+1.
/// `fail_at` makes the step from that estimate fail.
struct Scripted {
    lik: Vec<f64>,
    fail_at: Option<usize>,
    exact: bool,
}

impl EmAlgorithm for Scripted {
    type Estimate = usize;
    type Error = String;
    fn step(&mut self, k: &usize) -> Result<(usize, f64), String> {
        if self.fail_at == Some(*k) {
            return Err(format!("failed at {k}"));
        }
        Ok((k + 1, self.lik[*k]))
    }
    fn loglik(&mut self, k: &usize) -> Result<f64, String> {
        if self.fail_at == Some(*k) {
            return Err(format!("failed at {k}"));
        }
        Ok(self.lik[*k])
    }
    fn is_exact(&self) -> bool {
        self.exact
    }
}

fn options(max_iterations: usize, tol: f64) -> CheckedEmOptions {
    EmOptions {
        max_iterations,
        tol,
        ..EmOptions::default()
    }
    .check()
    .unwrap()
}

#[test]
fn converges_by_the_relative_rule() {
    // -100, -50, -49, -48.99999 : relative change 2e-7 < 1e-6 at the last one
    let mut alg = Scripted {
        lik: vec![-100.0, -50.0, -49.0, -48.99999, -48.0],
        fail_at: None,
        exact: true,
    };
    let r = run_em(&mut alg, 0, &options(50, 1e-6), &mut ());
    assert_eq!(r.termination, Termination::Converged);
    assert_eq!(r.estimate, 3);
    assert_eq!(r.loglik, Some(-48.99999));
    assert_eq!(r.iterations, 3);
    assert_eq!(r.trace, vec![-100.0, -50.0, -49.0, -48.99999]);
}

#[test]
fn stops_at_the_iteration_limit_and_evaluates_the_last_estimate() {
    let mut alg = Scripted {
        lik: (0..10).map(|k| -100.0 + k as f64).collect(),
        fail_at: None,
        exact: true,
    };
    let r = run_em(&mut alg, 0, &options(4, 1e-12), &mut ());
    assert_eq!(r.termination, Termination::MaxIterations);
    assert_eq!((r.estimate, r.iterations, r.loglik), (4, 4, Some(-96.0)));
    assert_eq!(r.trace.len(), 5);
}

#[test]
fn exact_em_decrease_stops_and_returns_the_better_estimate() {
    let mut alg = Scripted {
        lik: vec![-10.0, -9.0, -8.0, -8.5, -7.0],
        fail_at: None,
        exact: true,
    };
    let r = run_em(&mut alg, 0, &options(50, 0.0), &mut ());
    assert_eq!(
        r.termination,
        Termination::LikelihoodDecreased {
            iteration: 3,
            previous: -8.0,
            current: -8.5
        }
    );
    assert_eq!(
        (r.estimate, r.loglik, r.iterations, r.decreases),
        (2, Some(-8.0), 2, 1)
    );
}

#[test]
fn decrease_within_tolerance_is_accepted() {
    let l = -1e6;
    let mut alg = Scripted {
        lik: vec![l, l - 1e-5, l + 1.0, l + 1.0],
        fail_at: None,
        exact: true,
    };
    let r = run_em(&mut alg, 0, &options(3, 0.0), &mut ());
    assert_eq!(r.termination, Termination::MaxIterations);
    assert_eq!(r.decreases, 0);
}

#[test]
fn noisy_em_counts_decreases_and_continues() {
    let mut alg = Scripted {
        lik: vec![-10.0, -9.0, -9.5, -8.0, -8.2, -7.0],
        fail_at: None,
        exact: false,
    };
    let r = run_em(&mut alg, 0, &options(5, 0.0), &mut ());
    assert_eq!(r.termination, Termination::MaxIterations);
    assert_eq!((r.decreases, r.estimate), (2, 5));
}

#[test]
fn an_error_returns_the_last_estimate_with_a_known_likelihood() {
    let mut alg = Scripted {
        lik: vec![-10.0, -9.0, -8.0, -7.0],
        fail_at: Some(2),
        exact: true,
    };
    let r = run_em(&mut alg, 0, &options(50, 0.0), &mut ());
    assert_eq!(
        r.termination,
        Termination::Error {
            iteration: 3,
            error: "failed at 2".into()
        }
    );
    assert_eq!((r.estimate, r.loglik, r.iterations), (1, Some(-9.0), 1));
    let mut first = Scripted {
        lik: vec![-10.0],
        fail_at: Some(0),
        exact: true,
    };
    let r = run_em(&mut first, 0, &options(5, 0.0), &mut ());
    assert_eq!((r.estimate, r.loglik), (0, None));
}

#[test]
fn observers_see_every_iteration_and_options_are_validated() {
    struct Count(Vec<(usize, f64)>);
    impl EmObserver<usize> for Count {
        fn iteration(&mut self, info: &IterationInfo<'_, usize>) {
            self.0.push((info.iteration, info.loglik));
        }
    }
    let mut alg = Scripted {
        lik: vec![-4.0, -3.0, -2.0, -1.0],
        fail_at: None,
        exact: true,
    };
    let mut seen = Count(vec![]);
    run_em(&mut alg, 0, &options(3, 0.0), &mut seen);
    assert_eq!(seen.0, vec![(1, -4.0), (2, -3.0), (3, -2.0)]);
    assert!(
        EmOptions {
            max_iterations: 0,
            ..EmOptions::default()
        }
        .check()
        .is_err()
    );
    assert!(
        EmOptions {
            tol: f64::NAN,
            ..EmOptions::default()
        }
        .check()
        .is_err()
    );
    assert!(
        EmOptions {
            monotonicity_tol: -1.0,
            ..EmOptions::default()
        }
        .check()
        .is_err()
    );
}

/// The observer hears the start once, every iteration, and the end once with the
/// returned estimate.
#[test]
fn observers_hear_the_start_and_the_finish() {
    #[derive(Default)]
    struct Events(Vec<String>);
    impl EmObserver<usize> for Events {
        fn start(&mut self, initial: &usize) {
            self.0.push(format!("start {initial}"));
        }
        fn iteration(&mut self, info: &IterationInfo<'_, usize>) {
            self.0.push(format!("iteration {}", info.iteration));
        }
        fn finish(&mut self, estimate: &usize, loglik: Option<f64>, iterations: usize) {
            self.0
                .push(format!("finish {estimate} {loglik:?} {iterations}"));
        }
    }
    let mut alg = Scripted {
        lik: vec![-4.0, -3.0, -2.0, -1.0],
        fail_at: None,
        exact: true,
    };
    let mut events = Events::default();
    let r = run_em(&mut alg, 0, &options(2, 0.0), &mut events);
    assert_eq!(
        events.0,
        [
            "start 0",
            "iteration 1",
            "iteration 2",
            "finish 2 Some(-2.0) 2"
        ]
    );
    assert_eq!((r.estimate, r.iterations), (2, 2));
}

/// An observer that asks to stop ends the run with `Interrupted` and the last estimate
/// whose log-likelihood is known.
#[test]
fn an_observer_can_stop_the_run() {
    struct StopAfter(usize, usize);
    impl EmObserver<usize> for StopAfter {
        fn iteration(&mut self, _info: &IterationInfo<'_, usize>) {
            self.1 += 1;
        }
        fn should_stop(&self) -> bool {
            self.1 >= self.0
        }
    }
    let mut alg = Scripted {
        lik: vec![-5.0, -4.0, -3.0, -2.0, -1.0],
        fail_at: None,
        exact: true,
    };
    let r = run_em(&mut alg, 0, &options(50, 0.0), &mut StopAfter(3, 0));
    assert_eq!(r.termination, Termination::Interrupted { iteration: 2 });
    // theta_2 with l(theta_2) = -3
    assert_eq!((r.estimate, r.loglik, r.iterations), (2, Some(-3.0), 2));
}
