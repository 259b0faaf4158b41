//! Tier 4: a seeded run's output is pinned, so an accidental change of the random
//! stream (generator, draw order, distribution code) or of the numbers is caught.
//! If a change is intended, update the pinned values in the same commit and say why.

use sysid::prelude::*;

#[test]
fn seeded_lgss_simulation_is_pinned() {
    let sim = System::Lgss.simulate(4, 42).unwrap();
    let y: Vec<u64> = sim.record.y.iter().map(|v| v.to_bits()).collect();
    let x: Vec<u64> = sim.x.iter().map(|v| v.to_bits()).collect();
    assert_eq!(y, PINNED_LGSS_Y, "y = {:?}", sim.record.y.as_slice());
    assert_eq!(x, PINNED_LGSS_X, "x = {:?}", sim.x.as_slice());
}

#[test]
fn seeded_lti2x2_loglik_is_pinned() {
    let sim = System::Lti2x2.simulate(200, 7).unwrap();
    let mut ws = KalmanWorkspace::new();
    let ll = ws.loglik(&System::Lti2x2.model(), &sim.record).unwrap();
    // the data are pinned bit for bit through the first inputs; the log-likelihood to
    // round-off (an algorithmic change may move the last bits, not more)
    assert_eq!(
        sim.record.u[(0, 0)].to_bits(),
        PINNED_LTI2X2_U11,
        "u11 = {}",
        sim.record.u[(0, 0)]
    );
    assert!(
        (ll - PINNED_LTI2X2_LOGLIK).abs() <= 1e-11 * ll.abs(),
        "loglik = {ll:?}"
    );
}

const PINNED_LGSS_Y: [u64; 4] = [
    0x3ffd46e82bef3946,
    0x3fed217f9f134932,
    0xbfd30308815577b4,
    0x3fdcf12f2cb4069e,
];
const PINNED_LGSS_X: [u64; 4] = [
    0x3feab3627bf1d0be,
    0x3fce3514677a5f20,
    0x3fe5a8c1d502e9ba,
    0x3fec43d6093db9ad,
];
const PINNED_LTI2X2_U11: u64 = 0xbffd3a0fe3599983; // -1.8266753083094904
const PINNED_LTI2X2_LOGLIK: f64 = 341.7250239112496;

/// The particle filter and smoothers on `nlbench`: the simulated data, the
/// log-likelihood estimate and smoothed means, each pinned to the last bit (the SMC
/// code is reproducible bit for bit on any x86-64, whatever the vector unit).
#[test]
fn seeded_nlbench_particle_methods_are_pinned() {
    use sysid::smc::{FfbsiReject, Tanizaki};
    let model = Nlbench::truth();
    let sim = model.simulate(100, 42);
    let data = Series::new(&sim.outputs, 1).unwrap();
    let mut pf = ParticleFilter::new(FilterOptions {
        particles: 200,
        store_history: true,
        ..Default::default()
    })
    .unwrap();
    let loglik = pf.run(&model, &data, 7).unwrap().loglik;
    let history = pf.history().unwrap();
    let (tanizaki, _) = Tanizaki::default()
        .trajectories(&model, history, &data, 8)
        .unwrap();
    let (reject, _) = FfbsiReject {
        paths: 50,
        max_trials: None,
        parallel: false,
    }
    .trajectories(&model, history, &data, 9)
    .unwrap();
    let got = [
        sim.outputs[99].to_bits(),
        loglik.to_bits(),
        tanizaki.means()[0].to_bits(),
        reject.means()[50].to_bits(),
    ];
    assert_eq!(
        got,
        PINNED_NLBENCH,
        "y99 = {}, loglik = {loglik}, tanizaki mean0 = {}, reject mean50 = {}",
        sim.outputs[99],
        tanizaki.means()[0],
        reject.means()[50]
    );
}

const PINNED_NLBENCH: [u64; 4] = [
    0xbfbf12536f02eb04,
    // re-pinned 2026-11-23 on purpose, twice: (1) rejection draws in rounds (Tanizaki,
    // FFBSi-reject), Tanizaki's trial cap M/4 and FFBSi-reject's alias-table proposal
    // take the random numbers in another order; (2) the transition draws come from the
    // bulk normal generator (`sysid_smc::normals`: eight xoshiro lanes, Box-Muller)
    // instead of one ziggurat draw per particle; the smoothers re-pinned 2026-11-23 on
    // purpose a third time: the rejection trials take their uniforms and exponentials
    // in bulk, a run per round (`trial_numbers`), and FFBSi-reject's alias table is
    // built by the sweep (another table for the same weights); FFBSi-reject re-pinned
    // 2026-11-23 on purpose: for scalar Gaussian transitions each path's envelope is
    // its own maximum (the nearest transition mean), not the model's global bound;
    // Tanizaki re-pinned 2026-11-24 on purpose: where the means spread wider than a
    // window, each path proposes from its window of sorted means (`smoother::window`);
    // FFBSi-reject re-pinned 2026-11-24 on purpose: the same windows, each candidate
    // weighted by its filter weight (`nearest::draw_weighted_block`); both smoothers
    // re-pinned 2026-11-24 on purpose: a block holds 64 paths, not 32, so the paths
    // take other random streams
    0xc04a3f96f4c3d947,
    0x3fe99904347fab03, // 0.7999287629475876
    0x3feeb6354eb5495b, // 0.9597422158497396
];
