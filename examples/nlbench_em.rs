//! One particle-EM run on the seed-000 benchmark (ALGORITHMS.md 3): T = 1000 data,
//! M = 50 particles, Tanizaki's smoother, from a perturbation of the truth; prints the
//! parameter trace every 50 iterations.
//!
//! `cargo run --release --example nlbench_em [iterations]`

use sysid::em::affine::AffineParams;
use sysid::em::affine::{AffineEm, AffineEmSpec};
use sysid::em::{EmObserver, EmOptions, IterationInfo, run_em};
use sysid::models::{Nlbench, NlbenchAffine, NlbenchParams};
use sysid::smc::{Series, Tanizaki};

struct Print;

impl EmObserver<AffineParams> for Print {
    fn iteration(&mut self, info: &IterationInfo<'_, AffineParams>) {
        if info.iteration.is_multiple_of(50) || info.iteration == 1 {
            let p = NlbenchAffine::nlbench_params(info.estimate);
            println!(
                "{:5}  loglik {:10.3}  a {:.4}  b {:7.3}  c {:.4}  d {:.5}  ({:.1} s)",
                info.iteration,
                info.loglik,
                p.a,
                p.b,
                p.c,
                p.d,
                info.elapsed.as_secs_f64()
            );
        }
    }
}

fn main() {
    let iterations: usize = std::env::args()
        .nth(1)
        .map_or(1000, |s| s.parse().expect("a number"));
    let sim = Nlbench::truth().simulate(1000, 1);
    let data = Series::new(&sim.outputs, 1).expect("simulated data");
    let start = NlbenchParams {
        a: 0.6,
        b: 20.0,
        c: 9.0,
        d: 0.04,
        ..NlbenchParams::TRUE
    };
    // q and r known (ALGORITHMS.md 3): only a, b, c, d are estimated.
    let spec = AffineEmSpec {
        pi_x: sysid::em::linear::Covariance::Fixed,
        pi_y: sysid::em::linear::Covariance::Fixed,
        ..AffineEmSpec::default()
    };
    let model = NlbenchAffine;
    let mut em =
        AffineEm::new(&model, data, 50, Tanizaki::default(), spec, 7).expect("valid settings");
    let options = EmOptions {
        max_iterations: iterations,
        tol: 0.0,
        ..EmOptions::default()
    }
    .check()
    .expect("valid options");
    let result = run_em(&mut em, NlbenchAffine::params(&start), &options, &mut Print);
    let p = NlbenchAffine::nlbench_params(&result.estimate);
    println!(
        "final: a {:.4} b {:.3} c {:.4} d {:.5} (truth 0.5, 25, 8, 0.05); {} iterations in {:.2} s; {:?}",
        p.a,
        p.b,
        p.c,
        p.d,
        result.iterations,
        result.elapsed.as_secs_f64(),
        result.termination
    );
}
