//! The canonical systems of the source papers, each with its true parameters and a
//! seeded simulator. Tests, examples, benchmarks and the CLI demo all use these.
//!
//! | name | what | source |
//! | --- | --- | --- |
//! | [`lgss`] | scalar `x' = 0.9 x + w`, `y = x + e`, `Var w = 1`, `Var e = 0.5` | the usual particle-filter test model |
//! | [`lti2x2`] | 2-input 2-output system of McMillan degree 8 | Gibson and Ninness (2005), ALGORITHMS.md 1.5 |
//! | [`BlindWiener`] | 2-state linear part, saturation and dead zone, unobserved input | seed 001, ALGORITHMS.md 4 |
//! | [`Nlbench`] | `x' = a x + b x/(1+x^2) + c cos(1.2 t) + w`, `y = d x^2 + e` | Schön, Wills and Ninness (2006), ALGORITHMS.md 3 |
//! | [`Pendulum`] | damped pendulum driven by a torque, angle measured: two states, affine in five coefficients | Särkkä (2013), Euler-discretised; sysid's settings |
//!
//! [`LinearGaussianSmc`] lets any linear Gaussian model run through the particle
//! methods of `sysid-smc`, which is how they are checked against the Kalman answer;
//! [`GaussianAffineSmc`] does the same for any affine model from its regressors.

mod affine;
mod families;
mod gaussian_affine;
mod gradient_lgss;
mod linear_smc;
mod nlbench;
mod pendulum;
mod truncated_normal;
mod wiener;
mod wiener_fit;
mod wiener_guided;
mod wiener_observations;
mod wiener_start;

pub use affine::{LinearAffine, NlbenchAffine};
pub use families::{LgssConjugate, LgssFamily, NlbenchConjugate, NlbenchFamily};
pub use gaussian_affine::{GaussianAffineSmc, MAX_REGRESSORS};
pub use gradient_lgss::LgssGradient;
pub use linear_smc::{AdapterError, LinearGaussianSmc, MAX_DIM};
pub use nlbench::{Nlbench, NlbenchParams, NlbenchSimulation};
pub use pendulum::{PENDULUM_COEFFICIENTS, Pendulum, PendulumSimulation};
pub use wiener::{
    BlindWiener, WienerEstimate, WienerModel, WienerSimulation, WienerSmc, dead_zone,
    normalised_magnitude_error, saturation, spectral_magnitude, wiener_frequency_grid,
};
pub use wiener_fit::{
    CheckedWienerFitOptions, WienerFit, WienerFitError, WienerFitOptions, fit_wiener,
};
pub use wiener_start::wiener_start;

use nalgebra::{DMatrix, dmatrix};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use sysid_kalman::{KalmanError, LinearGaussianModel, Simulation};

/// The scalar linear Gaussian system.
///
/// # Model
/// ```text
/// x_{t+1} = 0.9 x_t + w_t,  w_t ~ N(0, 1)
/// y_t     = x_t + e_t,      e_t ~ N(0, 0.5),   x_1 ~ N(0, 1)
/// ```
pub fn lgss() -> LinearGaussianModel {
    LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
        .p1(dmatrix![1.0])
        .build()
        .expect("lgss parameters are valid")
}

/// A second-order block `(b1 q + b0) / ((q - p1)(q - p2))` in controllable canonical
/// form: `A = [[p1 + p2, -p1 p2], [1, 0]]`, `B = [1; 0]`, `C = [b1, b0]`.
fn second_order_block(b1: f64, b0: f64, p1: f64, p2: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    (dmatrix![p1 + p2, -p1 * p2; 1.0, 0.0], dmatrix![b1, b0])
}

/// First-order block `b0 / (q - p1)`.
fn first_order_block(b0: f64, p1: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    (dmatrix![p1], dmatrix![b0])
}

/// Stacks SISO blocks `(A_k, C_k)` (each with `B_k = e_1`) driven by input `inputs[k]`
/// into output `outputs[k]` as one block-diagonal state-space model, with output noise
/// `R = r I`, no process noise and the system at rest (`mu = 0`, `P1 = 0`).
fn block_diagonal(
    blocks: &[(DMatrix<f64>, DMatrix<f64>)],
    inputs: &[usize],
    outputs: &[usize],
    r: f64,
) -> LinearGaussianModel {
    let n: usize = blocks.iter().map(|(a, _)| a.nrows()).sum();
    let (mut a, mut b, mut c) = (
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, 2),
        DMatrix::zeros(2, n),
    );
    let mut offset = 0;
    for (k, (ak, ck)) in blocks.iter().enumerate() {
        let nk = ak.nrows();
        a.view_mut((offset, offset), (nk, nk)).copy_from(ak);
        b[(offset, inputs[k])] = 1.0;
        c.view_mut((outputs[k], offset), (1, nk)).copy_from(ck);
        offset += nk;
    }
    LinearGaussianModel::builder(a, c, DMatrix::zeros(n, n), DMatrix::identity(2, 2) * r)
        .b(b)
        .p1(DMatrix::zeros(n, n))
        .build()
        .expect("block-diagonal realisation is valid")
}

/// The 2x2 system of Gibson and Ninness as an 8-state block-diagonal realisation.
///
/// # Model
/// `y_t = G(q) u_t + e_t`, `e_t ~ N(0, 0.01 I)`, no process noise, starting at rest:
/// ```text
/// G11 = (0.0355 q + 0.02465) / ((q - 0.3679)(q - 0.9084))
/// G12 = (0.2364 q + 0.1038)  / ((q - 0.1353)(q - 0.6065))
/// G21 = (0.07601 q + 0.05447)/ ((q - 0.4966)(q - 0.7408))
/// G22 = (0.1087 q + 0.07286) / ((q - 0.4493)(q - 0.6703))
/// ```
/// States 1-2 realise G11, 3-4 G12, 5-6 G21, 7-8 G22 (controllable canonical form).
pub fn lti2x2() -> LinearGaussianModel {
    block_diagonal(
        &[
            second_order_block(0.0355, 0.02465, 0.3679, 0.9084),
            second_order_block(0.2364, 0.1038, 0.1353, 0.6065),
            second_order_block(0.07601, 0.05447, 0.4966, 0.7408),
            second_order_block(0.1087, 0.07286, 0.4493, 0.6703),
        ],
        &[0, 1, 0, 1],
        &[0, 0, 1, 1],
        0.01,
    )
}

/// The initial model of the paper for [`lti2x2`] (6 states):
/// `G11 = 0.1/(q - 0.5)^2`, `G12 = 0.1/(q - 0.7)`, `G21 = 0.1/(q - 0.6)^2`,
/// `G22 = 0.1/(q - 0.4)`, with the same noise level.
pub fn lti2x2_initial_guess() -> LinearGaussianModel {
    block_diagonal(
        &[
            second_order_block(0.0, 0.1, 0.5, 0.5),
            first_order_block(0.1, 0.7),
            second_order_block(0.0, 0.1, 0.6, 0.6),
            first_order_block(0.1, 0.4),
        ],
        &[0, 1, 0, 1],
        &[0, 0, 1, 1],
        0.01,
    )
}

/// Process-noise variance given to the paper's initial model as an EM start (ours:
/// the paper's model has `Q = 0`, from which EM cannot move `A`).
pub const LTI2X2_PAPER_START_Q: f64 = 0.01;

/// The paper's initial model as an EM start: [`lti2x2_initial_guess`] with
/// `Q = LTI2X2_PAPER_START_Q I`.
pub fn lti2x2_paper_start() -> LinearGaussianModel {
    lti2x2_initial_guess()
        .to_builder()
        .q(DMatrix::identity(6, 6) * LTI2X2_PAPER_START_Q)
        .build()
        .expect("a positive process noise keeps the model valid")
}

/// What linear EM estimates in the seed-004 experiment: `A, B, C, D, Q, R`, with the
/// offset `h` and the initial state (`mu`, `P1`) held at their known values.
pub fn lti2x2_em_spec() -> sysid_em::linear::LinearEmSpec {
    sysid_em::linear::LinearEmSpec {
        h: false,
        mu: false,
        p1: false,
        ..sysid_em::linear::LinearEmSpec::default()
    }
}

/// A model moved to the known facts of the seed-004 experiment, as an EM start: no
/// output offset, the system at rest (`mu = 0`, `P1 = 0`), and `S = 0` (linear EM holds
/// `S`).
pub fn lti2x2_experiment_start(model: &LinearGaussianModel) -> LinearGaussianModel {
    let (n, p) = (model.n(), model.p());
    model
        .without_cross_covariance()
        .to_builder()
        .h(nalgebra::DVector::zeros(p))
        .mu(nalgebra::DVector::zeros(n))
        .p1(DMatrix::zeros(n, n))
        .build()
        .expect("zero offset and a known initial state keep a model valid")
}

/// The named canonical systems, for command lines and runners.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum System {
    /// [`lgss`]
    Lgss,
    /// [`lti2x2`]
    Lti2x2,
}

impl System {
    /// Every system, in a stable order.
    pub const ALL: [System; 2] = [System::Lgss, System::Lti2x2];

    /// The system's name as used on command lines.
    pub fn name(self) -> &'static str {
        match self {
            System::Lgss => "lgss",
            System::Lti2x2 => "lti2x2",
        }
    }

    /// Looks a system up by name.
    pub fn from_name(name: &str) -> Option<System> {
        System::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The true model.
    pub fn model(self) -> LinearGaussianModel {
        match self {
            System::Lgss => lgss(),
            System::Lti2x2 => lti2x2(),
        }
    }

    /// Simulates `steps` steps from the seed: white `N(0, I)` inputs (for systems with
    /// inputs) are drawn first, then the noises, all from one `Xoshiro256PlusPlus`.
    pub fn simulate(self, steps: usize, seed: u64) -> Result<Simulation, KalmanError> {
        let model = self.model();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let u = DMatrix::from_fn(model.m(), steps, |_, _| StandardNormal.sample(&mut rng));
        model.simulate(&u, &mut rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Complex;

    fn response(model: &LinearGaussianModel, z: Complex<f64>) -> nalgebra::DMatrix<Complex<f64>> {
        model.frequency_response(z.arg()).unwrap()
    }

    #[test]
    fn lti2x2_realises_the_transfer_functions() {
        let model = lti2x2();
        assert_eq!((model.n(), model.m(), model.p()), (8, 2, 2));
        let tf = |b1: f64, b0: f64, p1: f64, p2: f64, z: Complex<f64>| {
            (z * b1 + b0) / ((z - p1) * (z - p2))
        };
        for w in [0.05, 0.7, 2.5] {
            let z = Complex::from_polar(1.0, w);
            let g = response(&model, z);
            let expected = [
                [
                    tf(0.0355, 0.02465, 0.3679, 0.9084, z),
                    tf(0.2364, 0.1038, 0.1353, 0.6065, z),
                ],
                [
                    tf(0.07601, 0.05447, 0.4966, 0.7408, z),
                    tf(0.1087, 0.07286, 0.4493, 0.6703, z),
                ],
            ];
            for i in 0..2 {
                for j in 0..2 {
                    assert!(
                        (g[(i, j)] - expected[i][j]).norm() < 1e-12,
                        "w {w} G{}{}",
                        i + 1,
                        j + 1
                    );
                }
            }
        }
    }

    #[test]
    fn initial_guess_realises_the_paper_start() {
        let model = lti2x2_initial_guess();
        assert_eq!(model.n(), 6);
        let z = Complex::from_polar(1.0, 0.3);
        let g = response(&model, z);
        assert!((g[(0, 0)] - Complex::new(0.1, 0.0) / ((z - 0.5) * (z - 0.5))).norm() < 1e-12);
        assert!((g[(0, 1)] - Complex::new(0.1, 0.0) / (z - 0.7)).norm() < 1e-12);
        assert!((g[(1, 0)] - Complex::new(0.1, 0.0) / ((z - 0.6) * (z - 0.6))).norm() < 1e-12);
        assert!((g[(1, 1)] - Complex::new(0.1, 0.0) / (z - 0.4)).norm() < 1e-12);
    }

    #[test]
    fn seeded_simulation_is_reproducible() {
        let a = System::Lti2x2.simulate(50, 3).unwrap();
        let b = System::Lti2x2.simulate(50, 3).unwrap();
        let c = System::Lti2x2.simulate(50, 4).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.record.y, c.record.y);
        assert_eq!(System::from_name("lgss"), Some(System::Lgss));
        assert_eq!(System::from_name("nope"), None);
    }
}
