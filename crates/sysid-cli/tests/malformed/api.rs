//! The same kinds of bad input through the library API: typed errors whose messages
//! name the matrix, the time index or the option.

use nalgebra::{DMatrix, dmatrix};
use sysid::em::EmOptions;
use sysid::kalman::{KalmanWorkspace, LinearGaussianModel, Record};
use sysid::models::Nlbench;
use sysid::smc::{FilterOptions, ParticleFilter, Series};
use sysid::subspace::{N4sidOptions, Order, n4sid};
use sysid_cli::fuzzing;

fn lgss(a: DMatrix<f64>, c: DMatrix<f64>, q: DMatrix<f64>, r: DMatrix<f64>) -> String {
    match LinearGaussianModel::builder(a, c, q, r).build() {
        Ok(_) => "accepted".into(),
        Err(e) => e.to_string(),
    }
}

fn assert_contains(message: &str, needles: &[&str]) {
    for n in needles {
        assert!(message.contains(n), "{message:?} should contain {n:?}");
    }
}

#[test]
fn invalid_matrices_are_named() {
    let i = || dmatrix![1.0];
    assert_contains(
        &lgss(dmatrix![f64::NAN], i(), i(), i()),
        &["A", "non-finite", "(0, 0)"],
    );
    assert_contains(
        &lgss(i(), dmatrix![1.0, 2.0], i(), i()),
        &["C", "1x1", "1x2"],
    );
    let asymmetric = dmatrix![1.0, 0.5; 0.1, 1.0];
    assert_contains(
        &lgss(DMatrix::identity(2, 2), dmatrix![1.0, 0.0], asymmetric, i()),
        &["Q", "not symmetric", "(0, 1)"],
    );
    assert_contains(
        &lgss(i(), dmatrix![1.0; 1.0], i(), dmatrix![1.0, 2.0; 2.0, 1.0]),
        &["R", "not positive semi-definite"],
    );
    assert_contains(&lgss(i(), i(), dmatrix![f64::INFINITY], i()), &["Q", "inf"]);
}

#[test]
fn bad_data_names_the_time() {
    let model = sysid::models::lgss();
    let mut ws = KalmanWorkspace::new();
    let mut y = DMatrix::from_element(1, 5, 0.5);
    y[(0, 3)] = f64::INFINITY;
    let e = ws
        .loglik(&model, &Record::new(DMatrix::zeros(0, 5), y))
        .unwrap_err()
        .to_string();
    // time steps and components are 1-based, as in the equations and the CSV's t
    assert_contains(&e, &["time 4", "output 1", "inf"]);
    let with_input = model
        .to_builder()
        .b(dmatrix![1.0])
        .d(dmatrix![0.0])
        .build()
        .unwrap();
    let mut u = DMatrix::zeros(1, 5);
    u[(0, 2)] = f64::NAN;
    let e = ws
        .loglik(&with_input, &Record::new(u, DMatrix::zeros(1, 5)))
        .unwrap_err()
        .to_string();
    assert_contains(&e, &["time 3", "input 1", "NaN"]);
    let e = ws
        .loglik(
            &model,
            &Record::new(DMatrix::zeros(0, 0), DMatrix::zeros(1, 0)),
        )
        .unwrap_err()
        .to_string();
    assert_contains(&e, &["no time steps"]);
    let outputs = [0.1, f64::NEG_INFINITY, 0.3];
    assert_contains(&Series::new(&outputs, 1).unwrap_err().to_string(), &["1"]);
    assert_contains(
        &Series::new(&[0.1, 0.2, 0.3], 2).unwrap_err().to_string(),
        &["3", "2"],
    );
}

#[test]
fn bad_options_are_named() {
    let e = FilterOptions {
        particles: 0,
        ..FilterOptions::default()
    }
    .check()
    .unwrap_err()
    .to_string();
    assert_contains(&e, &["particles"]);
    let e = FilterOptions {
        ess_threshold: 1.5,
        ..FilterOptions::default()
    }
    .check()
    .unwrap_err()
    .to_string();
    assert_contains(&e, &["ess"]);
    let e = EmOptions {
        max_iterations: 0,
        ..EmOptions::default()
    }
    .check()
    .unwrap_err()
    .to_string();
    assert_contains(&e, &["max_iterations"]);
    let e = EmOptions {
        tol: f64::NAN,
        ..EmOptions::default()
    }
    .check()
    .unwrap_err()
    .to_string();
    assert_contains(&e, &["tol", "NaN"]);
    let sim = sysid::models::System::Lti2x2.simulate(40, 1).unwrap();
    let e = n4sid(
        &sim.record,
        &N4sidOptions {
            order: Order::Fixed(0),
            block_rows: None,
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert_contains(&e, &["order"]);
    let e = n4sid(
        &sim.record,
        &N4sidOptions {
            order: Order::Fixed(2),
            block_rows: Some(30),
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert_contains(&e, &["30 block rows", "40"]);
}

#[test]
fn degenerate_particle_weights_name_the_time() {
    // y = 1e300 at t = 4 has zero density under every particle: a typed error, not NaN
    let mut outputs = vec![1.0; 10];
    outputs[4] = 1e300;
    let series = Series::new(&outputs, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions::default()).unwrap();
    let e = pf
        .run(&Nlbench::truth(), &series, 1)
        .unwrap_err()
        .to_string();
    assert_contains(&e, &["degenerate", "time 4"]);
}

#[test]
fn the_fuzzed_parsers_report_lines() {
    assert_contains(
        &fuzzing::parse_data_file(b"t,y1\n1,2\n3\n").unwrap_err(),
        &["line 3"],
    );
    assert_contains(&fuzzing::parse_table(b"a,b\n1").unwrap_err(), &["line 2"]);
    assert_contains(
        &fuzzing::parse_model_file("{\"a\": [[1]],\n \"c\": }").unwrap_err(),
        &["line 2"],
    );
    assert_contains(
        &fuzzing::parse_command_line(&["pf".into(), "--particles".into(), "x".into()]).unwrap_err(),
        &["--particles"],
    );
    assert!(
        fuzzing::parse_command_line(&[
            "loglik".into(),
            "--model".into(),
            "m.json".into(),
            "--data".into(),
            "d.csv".into()
        ])
        .is_ok()
    );
}
