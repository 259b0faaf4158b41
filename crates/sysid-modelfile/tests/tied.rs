//! Model files with a parameter shared by two equations, bounded coefficients and a
//! noise block mixing fixed and free variances keep the closed-form particle EM (the
//! constrained M-step, whose exactness `sysid-models/tests/constrained_mstep.rs`
//! checks against least-squares and profile-likelihood references).

use sysid_em::FitRun;
use sysid_em::affine::{AffineFitOptions, AffineMethod, AffineModel, CoefficientSlot};
use sysid_em::linear::Covariance;
use sysid_modelfile::{FileFitMethod, ModelFile};
use sysid_smc::Series;

/// Two tanks; the outflow `a1` of the first is the inflow of the second; `h1`'s noise
/// fixed, `h2`'s free.
const TANKS: &str = r#"
format = 1
states = ["h1", "h2"]
inputs = ["u"]
outputs = ["y"]
[parameters]
k  = { value = 0.5,  min = 0 }
a1 = { value = 0.3,  min = 0, max = 2 }
a2 = { value = 0.25 }
q2 = { value = 0.004, min = 0 }
r  = { value = 0.01, min = 0 }
[transition]
h1 = "h1 + k*u - a1*sqrt(max(h1, 0))"
h2 = "h2 + a1*sqrt(max(h1, 0)) - a2*sqrt(max(h2, 0))"
[observation]
y = "h2"
[noise]
h1 = 1e-3
h2 = "q2"
y = "r"
[initial]
h1 = { mean = 2.8, variance = 0.1 }
h2 = { mean = 4.0, variance = 0.1 }
"#;

#[test]
fn a_shared_bounded_coefficient_and_a_mixed_noise_block_are_affine() {
    let file = ModelFile::parse(TANKS, "tanks.toml").unwrap();
    let affine = file.affine().expect("closed form");
    assert_eq!(file.why_not_affine(), None);
    let spec = affine.em_spec();
    assert_eq!(spec.pi_x, Covariance::Diagonal);
    assert_eq!(spec.pi_y, Covariance::Diagonal);
    let constraints = affine.constraints().expect("constraints");
    assert_eq!(constraints.held_process_variances, vec![0]);
    assert!(constraints.held_measurement_variances.is_empty());
    // k, a1 (in both transitions), a2
    assert_eq!(constraints.coefficients.len(), 3);
    let a1 = &constraints.coefficients[1];
    assert_eq!(a1.slots.len(), 2);
    assert!(matches!(a1.slots[0], CoefficientSlot::State { row: 0, .. }));
    assert!(matches!(a1.slots[1], CoefficientSlot::State { row: 1, .. }));
    // open bounds as closed ones just inside; a2 unbounded
    assert!(a1.lower > 0.0 && a1.lower < 1e-8 && a1.upper < 2.0 && a1.upper > 2.0 - 1e-8);
    assert_eq!(constraints.coefficients[2].lower, f64::NEG_INFINITY);
    // the values go both ways, the tie in both rows
    let params = affine.params(&[0.5, 0.3, 0.25, 0.004, 0.01]).unwrap();
    let values = constraints.values(&params);
    assert_eq!(values, vec![0.5, 0.3, 0.25]);
    assert_eq!(affine.theta(&params), vec![0.5, 0.3, 0.25, 0.004, 0.01]);
    constraints.check(&affine).unwrap();
}

#[test]
fn without_ties_bounds_or_mixed_blocks_there_are_no_constraints() {
    // each parameter in one equation, unbounded; both process variances free
    let text = TANKS
        .replace(
            "[parameters]",
            "[parameters]\nb1 = { value = 0.3 }\nq1 = { value = 0.001, min = 0 }",
        )
        .replace("h2 + a1*sqrt", "h2 + b1*sqrt")
        .replace("k  = { value = 0.5,  min = 0 }", "k  = { value = 0.5 }")
        .replace(
            "a1 = { value = 0.3,  min = 0, max = 2 }",
            "a1 = { value = 0.3 }",
        )
        .replace("h1 = 1e-3", "h1 = \"q1\"");
    let file = ModelFile::parse(&text, "plain.toml").unwrap();
    let affine = file.affine().expect("closed form");
    assert_eq!(affine.constraints(), None);
}

/// `T` steps of the tanks at the file's values (a hand-written simulation), the pump
/// input held for `hold` steps at a time.
fn simulate(steps: usize, hold: usize) -> Vec<f64> {
    use rand::RngExt;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = sysid_smc::stream(3, 0);
    let (k, a1, a2) = (0.5, 0.3, 0.25);
    let mut h = [2.8, 4.0];
    let mut data = Vec::new();
    let mut u = 0.7;
    for t in 0..steps {
        if t % hold == 0 {
            u = rng.random_range(0.4..1.0);
        }
        let n: [f64; 3] = [
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
        ];
        data.extend_from_slice(&[u, h[1] + 0.1 * n[2]]);
        let (s1, s2) = (h[0].max(0.0).sqrt(), h[1].max(0.0).sqrt());
        h = [
            h[0] + k * u - a1 * s1 + 1e-3f64.sqrt() * n[0],
            h[1] + a1 * s1 - a2 * s2 + 0.004f64.sqrt() * n[1],
        ];
    }
    data
}

#[test]
fn the_closed_form_fit_runs_and_keeps_the_constraints() {
    let file = ModelFile::parse(TANKS, "tanks.toml").unwrap();
    // a start off the truth, a1 at its upper bound's side
    let start = file.with_values(&[0.6, 0.25, 0.2, 0.01, 0.02]);
    let data = simulate(300, 1);
    let (u, y): (Vec<f64>, Vec<f64>) = data.chunks_exact(2).map(|c| (c[0], c[1])).unzip();
    let series = Series::new(&y, 1).unwrap().with_inputs(&u, 1).unwrap();
    let mut options = AffineFitOptions::default();
    options.method = AffineMethod::Em;
    options.particles = 50;
    options.iterations = 40;
    let fit = start
        .fit(
            series,
            &FileFitMethod::ParticleEm(options.check().unwrap()),
            &FitRun::new(1),
            &mut (),
        )
        .unwrap();
    assert_eq!(fit.method(), "em");
    let [k, a1, a2, q2, r] = fit.estimate[..] else {
        panic!("{:?}", fit.estimate)
    };
    assert!(
        k > 0.0 && a1 > 0.0 && a1 < 2.0 && q2 > 0.0 && r > 0.0,
        "{:?}",
        fit.estimate
    );
    // EM from a start 20 % off moves towards the truth in the well-determined k/a2
    // direction: the steady-state level k u = a2 sqrt(h2) is what the data fix first
    let ratio = |k: f64, a2: f64| k / a2;
    assert!(
        (ratio(k, a2) - 2.0).abs() < (ratio(0.6, 0.2) - 2.0).abs() + 1e-9,
        "{:?}",
        fit.estimate
    );
    assert!(fit.warnings.iter().all(|w| !w.to_string().contains("NaN")));
}

/// The two-tank file of `../shared/data/nonlinear/twotank` (`tank_true.toml`): both
/// process variances held at 1e-3, `a1` shared, every coefficient positive.
const TWO_TANKS: &str = r#"
format = 1
states = ["h1", "h2"]
inputs = ["u"]
outputs = ["y"]
[parameters]
k  = { value = 0.5,  min = 0 }
a1 = { value = 0.3,  min = 0 }
a2 = { value = 0.25, min = 0 }
r  = { value = 0.01, min = 0 }
[transition]
h1 = "h1 + k*u - a1*sqrt(max(h1, 0))"
h2 = "h2 + a1*sqrt(max(h1, 0)) - a2*sqrt(max(h2, 0))"
[observation]
y = "h2"
[noise]
h1 = 1e-3
h2 = 1e-3
y = "r"
[initial]
h1 = { mean = 2.8, variance = 0.1 }
h2 = { mean = 4.0, variance = 0.1 }
"#;

#[test]
fn extrapolation_carries_a_crawling_refinement_up_the_likelihood() {
    use rand::RngExt;
    use sysid_em::affine::{RobustOptions, fit_robust};
    // the data as that folder's: a pump level held 20 steps at a time, 600 steps
    let file = ModelFile::parse(TWO_TANKS, "tank_true.toml").unwrap();
    let mut rng = sysid_smc::stream(5, 1);
    let mut u = Vec::new();
    while u.len() < 600 {
        let level: f64 = rng.random_range(0.3..1.5);
        u.extend(std::iter::repeat_n(level, 20));
    }
    let (_, y) = file
        .at(&file.free_values())
        .unwrap()
        .simulate(600, &u, 5)
        .unwrap();
    let series = Series::new(&y, 1).unwrap().with_inputs(&u, 1).unwrap();
    // from tank.toml's rough start, EM crawls along the ridge of equal steady levels
    // (k u = a2 sqrt(h2)) for thousands of iterations
    let affine = file.affine().unwrap();
    let start = affine.params(&[0.8, 0.15, 0.4, 0.05]).unwrap();
    let fit = |extrapolate: bool| {
        let options = RobustOptions {
            starts: 2,
            explore_iterations: 25,
            refine_iterations: 300,
            polish_particles: 0,
            extrapolate,
            ..RobustOptions::default()
        };
        fit_robust(
            &affine,
            series,
            &start,
            &affine.em_spec(),
            &sysid_smc::Tanizaki::default(),
            &options,
            4,
        )
        .unwrap()
    };
    let (on, off) = (fit(true), fit(false));
    let k = |f: &sysid_em::affine::RobustFit| affine.theta(&f.estimate)[0];
    eprintln!(
        "with jumps {:.1} (k {:.3}, {:?}), without {:.1} (k {:.3})",
        on.loglik,
        k(&on),
        on.extrapolation,
        off.loglik,
        k(&off)
    );
    assert_eq!(off.extrapolation.tried, 0);
    assert!(on.extrapolation.taken > 0, "{:?}", on.extrapolation);
    // both scored by the same 1000-particle filter on common random numbers; the
    // crawl is hundreds of nats long, a filter's noise a few
    assert!(
        on.loglik > off.loglik + 20.0,
        "with jumps {:.1}, without {:.1}",
        on.loglik,
        off.loglik
    );
    assert!(
        (k(&on) - 0.5).abs() < (k(&off) - 0.5).abs(),
        "k {} against {}",
        k(&on),
        k(&off)
    );
}

#[test]
fn a_coefficient_held_at_its_bound_by_the_data_is_flagged() {
    use rand_distr::{Distribution, StandardNormal};
    // x' = a x + w, y = x + e at a = 0.9; the file caps a at 0.5
    let ar = |bounds: &str| {
        format!(
            r#"
format = 1
states = ["x"]
outputs = ["y"]
[parameters]
a = {{ value = 0.3{bounds} }}
[transition]
x = "a*x"
[observation]
y = "x"
[noise]
x = 1.0
y = 0.1
[initial]
x = {{ mean = 0, variance = 1 }}
"#
        )
    };
    let mut rng = sysid_smc::stream(8, 0);
    let (mut x, mut y) = (0.0, Vec::new());
    for _ in 0..300 {
        let (w, e): (f64, f64) = (
            StandardNormal.sample(&mut rng),
            StandardNormal.sample(&mut rng),
        );
        y.push(x + 0.1f64.sqrt() * e);
        x = 0.9 * x + w;
    }
    let series = Series::new(&y, 1).unwrap();
    let mut options = AffineFitOptions::default();
    options.method = AffineMethod::Em;
    options.particles = 50;
    options.iterations = 30;
    let options = FileFitMethod::ParticleEm(options.check().unwrap());
    let fit = |bounds: &str| {
        ModelFile::parse(&ar(bounds), "ar.toml")
            .unwrap()
            .fit(series, &options, &FitRun::new(1), &mut ())
            .unwrap()
    };
    let capped = fit(", min = -1, max = 0.5");
    let a = capped.estimate[0];
    assert!(a < 0.5 && a > 0.5 - 1e-8, "{a}");
    let flagged: Vec<String> = capped.warnings.iter().map(ToString::to_string).collect();
    assert!(
        flagged
            .iter()
            .any(|w| w.starts_with("a = ") && w.contains("its bound 0.5")),
        "{flagged:?}"
    );
    // bounds the data do not reach are not flagged
    let free = fit(", min = -1, max = 1");
    assert!((free.estimate[0] - 0.9).abs() < 0.1, "{:?}", free.estimate);
    assert!(
        free.warnings
            .iter()
            .all(|w| !w.to_string().contains("its bound"))
    );
}
