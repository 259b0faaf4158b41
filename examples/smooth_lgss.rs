//! Build a model by hand, simulate it with a seed, knock out some outputs, and smooth.
//!
//! `cargo run --release --example smooth_lgss`

use nalgebra::{DMatrix, dmatrix};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use sysid::prelude::*;

fn main() -> Result<(), KalmanError> {
    // x' = 0.95 x + w, y = [1; 0.5] x + e: two sensors of one state
    let model = LinearGaussianModel::builder(
        dmatrix![0.95],
        dmatrix![1.0; 0.5],
        dmatrix![0.1],
        DMatrix::identity(2, 2) * 0.2,
    )
    .build()?;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(2026);
    let mut sim = model.simulate(&DMatrix::zeros(0, 50), &mut rng)?;
    // sensor 2 fails from t = 20 to t = 29; both fail at t = 40
    for t in 19..29 {
        sim.record.y[(1, t)] = f64::NAN;
    }
    sim.record.y.column_mut(39).fill(f64::NAN);
    let mut ws = KalmanWorkspace::new();
    let smoothed = ws.smooth(&model, &sim.record)?;
    println!("log-likelihood {:.4}", smoothed.loglik());
    println!("  t   true x   smoothed   sd");
    for k in [0, 19, 25, 39, 49] {
        println!(
            "{:3} {:8.3} {:10.3} {:6.3}",
            k + 1,
            sim.x[(0, k)],
            smoothed.mean(k)[0],
            smoothed.covariance(k)[(0, 0)].sqrt()
        );
    }
    Ok(())
}
