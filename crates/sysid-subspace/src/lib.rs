//! Subspace identification (N4SID) of linear Gaussian state-space models: the
//! initialisation of EM.
//!
//! ```
//! use sysid_subspace::{n4sid, N4sidOptions, Order};
//! # use nalgebra::{dmatrix, DMatrix};
//! # use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
//! # use rand_distr::{Distribution, StandardNormal};
//! # let truth = sysid_kalman::LinearGaussianModel::builder(dmatrix![0.8], dmatrix![1.0], dmatrix![0.1], dmatrix![0.1])
//! #     .b(dmatrix![1.0]).build().unwrap();
//! # let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
//! # let u = DMatrix::from_fn(1, 2000, |_, _| StandardNormal.sample(&mut rng));
//! # let record = truth.simulate(&u, &mut rng).unwrap().record;
//! let fit = n4sid(&record, &N4sidOptions { order: Order::Fixed(1), ..Default::default() }).unwrap();
//! assert!((fit.model.a()[(0, 0)] - 0.8).abs() < 0.05);
//! assert!(fit.singular_values[0] > 10.0 * fit.singular_values[1]);
//! ```

mod auto_weighting;
mod error;
mod input_fit;
mod n4sid;
mod stabilised;
mod warning;
mod weighting;

pub use auto_weighting::{WeightedN4sid, WeightingChoice, WeightingScore, n4sid_weighted};
pub use error::SubspaceError;
pub use n4sid::{
    AUTO_MAX_ORDER, Criterion, Focus, InputMethod, N4sidOptions, N4sidResult, Order, OrderScore,
    auto_order, n4sid, spectral_radius,
};
pub use stabilised::{DESTROYED_FIT, StabilisedFit, stabilised_fit};
pub use warning::SubspaceWarning;
pub use weighting::Weighting;
