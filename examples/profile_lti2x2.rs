//! Runs filter + smoother + EM statistics on lti2x2 (T = 2000) a few times: a fixed
//! workload for instruction-count profiling, e.g.
//! `valgrind --tool=callgrind target/release/examples/profile_lti2x2`.

use sysid::prelude::*;

fn main() -> Result<(), KalmanError> {
    let model = System::Lti2x2.model();
    let sim = System::Lti2x2.simulate(2000, 1)?;
    let mut ws = KalmanWorkspace::new();
    let mut stats = SufficientStatistics::new(model.n(), model.m(), model.p());
    for _ in 0..5 {
        ws.accumulate_statistics(&model, &sim.record, 0, &mut stats)?;
    }
    println!("steps accumulated: {}", stats.steps());
    Ok(())
}
