//! Bad input gets a typed error naming the place, never a panic or a NaN.

use rand_distr::{Distribution, StandardNormal};
use sysid_smc::{
    Ffbsi, FfbsiReject, FilterOptions, InitialSampler, ObservationDensity, ParticleFilter,
    ScalarGaussianKernel, Series, SmcError, Smoother, StateSpace, Tanizaki, TransitionBound,
    TransitionDensity, TransitionSampler,
};

/// A random walk observed through a bounded sensor: `y_t` in [x - 1, x + 1] uniformly,
/// so an output far from every particle is impossible (log-density -inf).
/// `nan_at` makes the observation density NaN at one step, `nan_mean_at` the
/// transition mean of one particle (broken models); `hide_scalar_form` withholds the
/// scalar Gaussian form, so that the smoothers take their general routes.
#[derive(Default)]
struct BoundedSensor {
    nan_at: Option<usize>,
    nan_mean_at: Option<usize>,
    hide_scalar_form: bool,
}

impl StateSpace for BoundedSensor {
    fn state_dim(&self) -> usize {
        1
    }
}
impl InitialSampler for BoundedSensor {
    fn sample_initial<R: rand::Rng + ?Sized>(&self, x: &mut [f64], rng: &mut R) {
        x[0] = StandardNormal.sample(rng);
    }
}
impl TransitionSampler for BoundedSensor {
    fn sample_transition<R: rand::Rng + ?Sized>(
        &self,
        _: usize,
        x: &[f64],
        _: &[f64],
        next: &mut [f64],
        rng: &mut R,
    ) {
        let w: f64 = StandardNormal.sample(rng);
        next[0] = x[0] + 0.1 * w;
    }
}
impl ObservationDensity for BoundedSensor {
    fn log_observation(&self, t: usize, x: &[f64], _: &[f64], y: &[f64]) -> f64 {
        if Some(t) == self.nan_at {
            return f64::NAN;
        }
        if (y[0] - x[0]).abs() <= 1.0 {
            0.5f64.ln()
        } else {
            f64::NEG_INFINITY
        }
    }
}
/// The scalar Gaussian form `N(x, 0.01)`, which sends Tanizaki's smoother down its
/// nearest-mean route and rejection FFBSi to each row's own bound.
impl TransitionDensity for BoundedSensor {
    fn log_transition(&self, _: usize, x: &[f64], _: &[f64], next: &[f64]) -> f64 {
        ScalarGaussianKernel::with_variance(0.01).log_density(x[0], next[0])
    }

    fn scalar_gaussian_means(
        &self,
        t: usize,
        _: &[f64],
        from: &[f64],
        means: &mut Vec<f64>,
    ) -> Option<ScalarGaussianKernel> {
        if self.hide_scalar_form {
            return None;
        }
        means.clear();
        means.extend_from_slice(from);
        if Some(t) == self.nan_mean_at {
            means[from.len() / 2] = f64::NAN;
        }
        Some(ScalarGaussianKernel::with_variance(0.01))
    }
}

/// A wrong bound: the log-density reaches `-ln(2 pi 0.01) / 2 = 1.38` where `next = x`.
impl TransitionBound for BoundedSensor {
    fn log_transition_bound(&self, _: usize, _: &[f64]) -> f64 {
        -1.0
    }
}

fn filter(particles: usize, history: bool) -> ParticleFilter {
    ParticleFilter::new(FilterOptions {
        particles,
        store_history: history,
        ..Default::default()
    })
    .unwrap()
}

#[test]
fn impossible_observation_is_degenerate_weights_at_its_time() {
    let y = [0.0, 0.1, 50.0, 0.0];
    let data = Series::new(&y, 1).unwrap();
    let err = filter(100, false)
        .run(&BoundedSensor::default(), &data, 1)
        .unwrap_err();
    assert_eq!(err, SmcError::DegenerateWeights { t: 2 });
    assert!(err.to_string().contains("time 2"));
}

#[test]
fn nan_observation_density_is_reported_with_time_and_particle() {
    let y = [0.0, 0.1, 0.2];
    let data = Series::new(&y, 1).unwrap();
    let err = filter(10, false)
        .run(
            &BoundedSensor {
                nan_at: Some(1),
                ..Default::default()
            },
            &data,
            1,
        )
        .unwrap_err();
    assert!(
        matches!(
            err,
            SmcError::InvalidDensity {
                t: 1,
                particle: 0,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn missing_outputs_skip_the_update_and_keep_the_likelihood_finite() {
    let y = [0.0, f64::NAN, 0.2];
    let data = Series::new(&y, 1).unwrap();
    let mut pf = filter(100, true);
    let run = pf.run(&BoundedSensor::default(), &data, 1).unwrap();
    assert!(run.loglik.is_finite());
    assert!(pf.means().iter().all(|m| m.is_finite()));
}

#[test]
fn malformed_series_and_options_are_rejected() {
    assert!(matches!(
        Series::new(&[], 1),
        Err(SmcError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        Series::new(&[1.0, 2.0, 3.0], 2),
        Err(SmcError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        Series::new(&[1.0], 0),
        Err(SmcError::DimensionMismatch { .. })
    ));
    assert_eq!(
        Series::new(&[1.0, f64::INFINITY], 1).unwrap_err(),
        SmcError::NonFiniteData {
            what: "output",
            t: 1,
            index: 0,
            value: f64::INFINITY
        }
    );
    let y = [1.0, 2.0];
    let data = Series::new(&y, 1).unwrap();
    assert!(matches!(
        data.with_inputs(&[0.0], 1),
        Err(SmcError::DimensionMismatch { .. })
    ));
    let err = data.with_inputs(&[0.0, f64::NAN], 1).unwrap_err();
    assert!(matches!(
        err,
        SmcError::NonFiniteData {
            what: "input",
            t: 1,
            ..
        }
    ));
    for bad in [
        FilterOptions {
            particles: 0,
            ..Default::default()
        },
        FilterOptions {
            ess_threshold: 0.0,
            ..Default::default()
        },
        FilterOptions {
            ess_threshold: 1.5,
            ..Default::default()
        },
        FilterOptions {
            ess_threshold: f64::NAN,
            ..Default::default()
        },
    ] {
        assert!(matches!(
            ParticleFilter::new(bad),
            Err(SmcError::InvalidOption { .. })
        ));
    }
}

#[test]
fn smoothers_check_paths_and_history_length() {
    let y = [0.0, 0.1, 0.2];
    let data = Series::new(&y, 1).unwrap();
    let model = BoundedSensor::default();
    let mut pf = filter(20, true);
    pf.run(&model, &data, 1).unwrap();
    let history = pf.history().unwrap();
    let err = Ffbsi {
        paths: 0,
        parallel: false,
    }
    .trajectories(&model, history, &data, 1)
    .unwrap_err();
    assert!(matches!(err, SmcError::InvalidOption { name: "paths", .. }));
    let shorter = Series::new(&y[..2], 1).unwrap();
    let err = Tanizaki::default()
        .trajectories(&model, history, &shorter, 1)
        .unwrap_err();
    assert_eq!(
        err,
        SmcError::HistoryMismatch {
            history: 3,
            data: 2
        }
    );
    let mut no_history = filter(20, false);
    no_history.run(&model, &data, 1).unwrap();
    assert!(no_history.history().is_none());
}

#[test]
fn a_transition_bound_below_the_density_is_a_typed_error() {
    let y = [0.0, 0.1, 0.2, 0.1];
    let data = Series::new(&y, 1).unwrap();
    // the model's bound is used only without the scalar Gaussian form
    let model = BoundedSensor {
        hide_scalar_form: true,
        ..Default::default()
    };
    let mut pf = filter(50, true);
    pf.run(&model, &data, 1).unwrap();
    let smoother = FfbsiReject {
        paths: 40,
        max_trials: None,
        parallel: false,
    };
    let err = smoother
        .trajectories(&model, pf.history().unwrap(), &data, 1)
        .unwrap_err();
    // the first step walked back is t = 2; every trial's log-density there is above -1
    // for the nearby particles, so some trial of the block sees it (the density's
    // largest value is -ln(2 pi 0.01) / 2)
    match err {
        SmcError::BoundViolated {
            t,
            log_density,
            log_bound,
        } => {
            assert_eq!((t, log_bound), (2, -1.0));
            let peak = -0.5 * (2.0 * std::f64::consts::PI * 0.01).ln();
            assert!(log_density > -1.0 && log_density <= peak, "{log_density}");
        }
        other => panic!("{other:?}"),
    }
    // with the scalar form each row is bounded by its own exact maximum, and the same
    // history smooths
    let scalar = BoundedSensor::default();
    assert!(
        smoother
            .trajectories(&scalar, pf.history().unwrap(), &data, 1)
            .is_ok()
    );
}

#[test]
fn a_nan_transition_mean_is_a_typed_error_at_its_step_in_tanizaki() {
    let y = [0.0, 0.1, 0.2, 0.1, 0.0];
    let data = Series::new(&y, 1).unwrap();
    let model = BoundedSensor {
        nan_mean_at: Some(2),
        ..Default::default()
    };
    let mut pf = filter(40, true);
    pf.run(&model, &data, 1).unwrap();
    let history = pf.history().unwrap();
    // enough trials that no draw needs the exact fallback (which would meet the NaN
    // anyway): only the check of the means can find it
    let patient = Tanizaki {
        max_trials: Some(100_000),
        ..Tanizaki::default()
    };
    let err = patient.trajectories(&model, history, &data, 1).unwrap_err();
    assert!(
        matches!(err, SmcError::InvalidDensity { t: 2, .. }),
        "{err:?}"
    );
    // the same model without the NaN smooths
    let fine = BoundedSensor::default();
    pf.run(&fine, &data, 1).unwrap();
    assert!(
        patient
            .trajectories(&fine, pf.history().unwrap(), &data, 1)
            .is_ok()
    );
}
