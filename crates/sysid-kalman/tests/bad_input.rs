//! Bad input gives typed errors naming the place; never a panic or a silent NaN.

use nalgebra::{DMatrix, dmatrix};
use sysid_kalman::{KalmanError, KalmanWorkspace, LinearGaussianModel, ModelSpec, Record};
use sysid_linalg::LinalgError;

fn scalar() -> sysid_kalman::ModelBuilder {
    LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
}

#[test]
fn wrong_dimension_names_the_matrix() {
    let err = scalar().b(dmatrix![1.0; 2.0]).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Dimension { name, expected_rows: 1, rows: 2, .. } if name == "B"),
        "{err:?}"
    );
    let err = scalar().c(dmatrix![1.0, 2.0]).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Dimension { name, .. } if name == "C"),
        "{err:?}"
    );
    assert!(err.to_string().contains("C must be 1x1, got 1x2"));
}

#[test]
fn a_model_without_states_or_outputs_is_refused() {
    // (an empty A used to build, and the particle adapter then panicked in an
    // eigen-decomposition of the empty matrix)
    let empty = |n: usize, p: usize| {
        LinearGaussianModel::builder(
            DMatrix::zeros(n, n),
            DMatrix::zeros(p, n),
            DMatrix::zeros(n, n),
            DMatrix::identity(p, p),
        )
        .build()
    };
    let err = empty(0, 1).unwrap_err();
    assert!(
        matches!(
            err,
            KalmanError::EmptyModel {
                what: "state",
                matrix: "A",
                rows: 0,
                cols: 0
            }
        ),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        "a model needs at least one state: A is 0x0"
    );
    let err = empty(2, 0).unwrap_err();
    assert!(
        matches!(
            err,
            KalmanError::EmptyModel {
                what: "output",
                matrix: "C",
                rows: 0,
                cols: 2
            }
        ),
        "{err:?}"
    );
    assert!(empty(1, 1).is_ok());
}

#[test]
fn non_symmetric_and_indefinite_covariances() {
    let two = || {
        LinearGaussianModel::builder(
            DMatrix::identity(2, 2) * 0.5,
            DMatrix::identity(2, 2),
            DMatrix::identity(2, 2),
            DMatrix::identity(2, 2),
        )
    };
    let err = two().q(dmatrix![1.0, 0.5; 0.1, 1.0]).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Matrix(LinalgError::NotSymmetric { name, .. }) if name == "Q"),
        "{err:?}"
    );
    let err = two().r(dmatrix![1.0, 2.0; 2.0, 1.0]).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Matrix(LinalgError::NotPositiveSemiDefinite { name, .. }) if name == "R"),
        "{err:?}"
    );
    let err = two().p1(dmatrix![-1.0, 0.0; 0.0, 1.0]).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Matrix(LinalgError::NotPositiveSemiDefinite { name, .. }) if name == "P1")
    );
    // Q and R fine separately, but the joint covariance with S is indefinite
    let err = two().s(DMatrix::identity(2, 2) * 2.0).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Matrix(LinalgError::NotPositiveSemiDefinite { name, .. }) if name.contains('S')),
        "{err:?}"
    );
}

#[test]
fn nan_in_a_model_matrix() {
    let err = scalar().a(dmatrix![f64::NAN]).build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Matrix(LinalgError::NonFinite { name, row: 0, col: 0, .. }) if name == "A"),
        "{err:?}"
    );
    let err = scalar()
        .h(nalgebra::dvector![f64::INFINITY])
        .build()
        .unwrap_err();
    assert!(
        matches!(&err, KalmanError::Matrix(LinalgError::NonFinite { name, .. }) if name == "h")
    );
}

#[test]
fn inf_in_the_data_names_record_time_and_output() {
    let model = scalar().build().unwrap();
    let mut y = DMatrix::from_element(1, 10, 0.3);
    y[(0, 6)] = f64::INFINITY;
    let err = KalmanWorkspace::new()
        .loglik(&model, &Record::outputs_only(y))
        .unwrap_err();
    assert_eq!(
        err,
        KalmanError::NonFiniteData {
            record: 0,
            time: 7,
            what: "output",
            index: 1,
            value: f64::INFINITY
        }
    );
    // NaN outputs are missing data, not errors; NaN inputs are errors
    let model_u = scalar().b(dmatrix![1.0]).build().unwrap();
    let mut u = DMatrix::zeros(1, 4);
    u[(0, 2)] = f64::NAN;
    let err = KalmanWorkspace::new()
        .smooth(
            &model_u,
            &Record::new(u, DMatrix::from_element(1, 4, f64::NAN)),
        )
        .unwrap_err();
    assert!(matches!(
        err,
        KalmanError::NonFiniteData {
            time: 3,
            what: "input",
            ..
        }
    ));
}

#[test]
fn records_of_the_wrong_shape() {
    let model = scalar().build().unwrap();
    let mut ws = KalmanWorkspace::new();
    let err = ws
        .loglik(&model, &Record::outputs_only(DMatrix::zeros(2, 5)))
        .unwrap_err();
    assert!(matches!(
        err,
        KalmanError::Dimension {
            expected_rows: 1,
            rows: 2,
            ..
        }
    ));
    let err = ws
        .loglik(&model, &Record::outputs_only(DMatrix::zeros(1, 0)))
        .unwrap_err();
    assert_eq!(err, KalmanError::EmptyRecord { record: 0 });
    let err = ws
        .loglik(
            &model,
            &Record::new(DMatrix::zeros(0, 3), DMatrix::zeros(1, 5)),
        )
        .unwrap_err();
    assert!(matches!(
        err,
        KalmanError::LengthMismatch {
            input_steps: 3,
            output_steps: 5,
            ..
        }
    ));
}

#[test]
fn exactly_predictable_output_is_a_typed_error() {
    // R = 0 and a perfectly known state: y_1 has no density
    let model = scalar().r(dmatrix![0.0]).p1(dmatrix![0.0]).build().unwrap();
    let err = KalmanWorkspace::new()
        .loglik(&model, &Record::outputs_only(dmatrix![0.0, 1.0]))
        .unwrap_err();
    assert_eq!(
        err,
        KalmanError::SingularInnovation {
            record: 0,
            time: 1,
            output: 1
        }
    );
}

#[test]
fn spec_round_trip_and_ragged_rows() {
    let model = scalar()
        .b(dmatrix![0.5])
        .h(nalgebra::dvector![1.5])
        .build()
        .unwrap();
    let json = serde_json::to_string(&ModelSpec::from_model(&model)).unwrap();
    let back: ModelSpec = serde_json::from_str(&json).unwrap();
    assert_eq!(back.build().unwrap(), model);
    let ragged = ModelSpec {
        a: vec![vec![0.5, 0.1], vec![0.2]],
        ..ModelSpec::from_model(&model)
    };
    let err = ragged.build().unwrap_err();
    assert!(
        matches!(&err, KalmanError::Dimension { name, .. } if name == "A (row 2)"),
        "{err:?}"
    );
}
