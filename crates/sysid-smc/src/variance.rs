//! The Monte Carlo variance of the log-likelihood estimate from a single filter run,
//! by the genealogy (Lee and Whiteley 2018; Chan and Lai 2013), in blocks so that it
//! survives the genealogy's collapse (after the idea of Olsson and Douc 2019).
//!
//! # Why
//! The variance of `log p^(y)` otherwise needs independent repeats of the filter (ten
//! filters for one figure). Lee and Whiteley's estimator needs the run's own genealogy
//! only: with `E^j` the index at time `s` of the ancestor of particle `j` at time `t`
//! and `S_k` the normalised weight at `t` of the descendants of particle `k` at `s`,
//!
//! ```text
//! v_{s,t} = 1 - (M / (M - 1))^{r + 1} (1 - sum_k S_k^2)
//! ```
//!
//! (`r` resampling steps between `s` and `t`) estimates the relative variance of the
//! likelihood of `y_{s..t}` without bias for multinomial resampling. Over a whole
//! record the genealogy collapses to one ancestor and the estimate to 0, so it is
//! used over short spans only; and the factor is `M / (M - 1)` alone (the origin's
//! sampling), because under systematic resampling, the default, the `r` further
//! factors over-correct.
//!
//! # Accuracy (measured, not proven)
//! Spans of 2 steps, 200 runs each, systematic resampling: lgss (T = 1000), sd over
//! the runs 4.80 at M = 100 and 1.63 at M = 1000, single-run estimates 4.13 and 1.47
//! (median; 10-90 % of runs within +-2 %); nlbench (T = 1000, M = 10 000, 1000 runs)
//! 0.701 against 0.644 (200 runs had given 0.78). So it is 8-14 % low (with multinomial
//! resampling, spans of 1 step: lgss at
//! M = 100 within 1 %, so the shortfall is systematic resampling's, which no published
//! estimator covers), and blind to rare losses of the state: nlbench at
//! M = 1000 has an sd of 520 over 200 runs (a few runs lose the state) where a single
//! run estimates 1.7. Longer spans are worse on lgss (spans of 10: 1.43; of 40: 1.30)
//! and not better on nlbench. It is also blind to a step whose weights collapse onto a
//! few particles (the measured cascaded tanks, a fitted model, M = 100 000, one step at
//! an ESS of 1.5: 1.48 where 5 runs scatter by 26; longer spans give less, not more):
//! `FilterDiagnostics` flags such a run. Independent repeats stay the reference.
//! `cargo run --release -p sysid-bench -- loglik-variance` measures the cases above.
//!
//! # Algorithm
//! Origins every `block` steps (`s_k = k block`), each followed for `2 block` steps by
//! its map `E`. Only the newest origin's map follows the ancestors (one gather per
//! step); the older one is frozen when the newer begins and composed with it when
//! measured (`E_old(t) = E_old(s_k + block)[E_new(t)]`). At `t = s_k + 2 block` the
//! log-variance of generations `s_k..s_k + block` is
//! `ln(1 + v_{s_k,t}) - ln(1 + v_{s_k + block,t})`: both spans end at `t`, so their
//! difference is the resampling noise of the first block, seen through a horizon of
//! `block` to `2 block` steps. At the last step the origin not yet accounted adds
//! `ln(1 + v_{s,T})`. The sum of the parts estimates `Var(log p^(y))`
//! (`log p^` is close to normal, so `Var(log) = ln(1 + relative variance)`).
//!
//! # Complexity
//! One gather of `M` indices per step, and one more with two passes over the weights
//! every `block` steps.

/// The span (steps) of the single-run estimate that `sysid pf`, `psmooth` and the
/// Python package use: the best measured (module docs; 1 step is 30 % low on nlbench,
/// 3 to 10 steps are no better there and lower on lgss).
pub const VARIANCE_SPAN: usize = 2;

/// The origin of one span: its time and each current particle's ancestor there.
#[derive(Debug, Clone, Default)]
struct Span {
    origin: usize,
    eve: Vec<u32>,
}

/// The block estimator's state during a run (see the module docs).
#[derive(Debug, Clone, Default)]
pub(crate) struct GenealogyVariance {
    block: usize,
    old: Option<Span>,
    new: Option<Span>,
    scratch: Vec<u32>,
    /// The old span's eves composed through the new span's.
    composed: Vec<u32>,
    sums: Vec<f64>,
    /// The log-variance accounted so far.
    total: f64,
}

impl GenealogyVariance {
    /// Starts a run of `particles` particles with spans of `block` steps.
    pub(crate) fn start(&mut self, block: usize, particles: usize) {
        self.block = block.max(1);
        self.old = None;
        self.new = None;
        self.total = 0.0;
        self.sums.resize(particles, 0.0);
        self.scratch.resize(particles, 0);
    }

    fn fresh(&mut self, origin: usize, particles: usize) -> Span {
        let mut eve = match self.new.take() {
            // reuse a buffer when one is free
            Some(span) => span.eve,
            None => Vec::with_capacity(particles),
        };
        eve.clear();
        eve.extend(0..particles as u32);
        Span { origin, eve }
    }

    /// Puts in `composed` the old span's eve of every current particle: its frozen
    /// map composed with the new span's while there is a new span, else its own.
    fn compose_old(&mut self) {
        self.composed.clear();
        match (&self.old, &self.new) {
            (Some(old), Some(new)) => self
                .composed
                .extend(new.eve.iter().map(|&e| old.eve[e as usize])),
            (Some(old), None) => self.composed.extend_from_slice(&old.eve),
            (None, _) => {}
        }
    }

    /// After step `t`'s weights are normalised: measures a span that is due and opens
    /// the next.
    pub(crate) fn observe(&mut self, t: usize, weights: &[f64]) {
        let m = weights.len();
        if m < 2 {
            return;
        }
        match (&self.old, &self.new) {
            (None, _) => {
                let span = self.fresh(t, m);
                self.old = Some(span);
            }
            (Some(old), None) if t >= old.origin + self.block => {
                let span = self.fresh(t, m);
                self.new = Some(span);
            }
            (Some(old), Some(_)) if t >= old.origin + 2 * self.block => {
                self.compose_old();
                let whole = log_variance(&mut self.sums, &self.composed, weights);
                let new = self.new.take().expect("matched");
                let tail = log_variance(&mut self.sums, &new.eve, weights);
                self.total += (whole - tail).max(0.0);
                // the new span becomes the old one, frozen from here; the old span's
                // buffer is free for the fresh one
                let old = self.old.replace(new).expect("matched");
                self.new = Some(old);
                let fresh = self.fresh(t, m);
                self.new = Some(fresh);
            }
            _ => {}
        }
    }

    /// After the resampling decision of step `t`: the newest span follows the
    /// ancestors of the next step's particles.
    pub(crate) fn advance(&mut self, ancestors: &[usize]) {
        // the newest span only (the older one is frozen while a newer exists)
        if let Some(span) = self.new.as_mut().or(self.old.as_mut()) {
            self.scratch.clear();
            self.scratch.extend(ancestors.iter().map(|&a| span.eve[a]));
            std::mem::swap(&mut span.eve, &mut self.scratch);
        }
    }

    /// After the last step: the total log-variance, with the span not yet accounted.
    pub(crate) fn finish(&mut self, weights: &[f64]) -> f64 {
        if weights.len() < 2 || self.old.is_none() {
            return self.total;
        }
        self.compose_old();
        self.total + log_variance(&mut self.sums, &self.composed, weights)
    }
}

/// `ln(1 + v)` of the span whose eves are `eve`, at the current weights (normalised);
/// `sums` is scratch for unsorted eves.
fn log_variance(sums: &mut Vec<f64>, eve: &[u32], weights: &[f64]) -> f64 {
    let m = weights.len();
    let squares = match sorted_squares(eve, weights) {
        Some(squares) => squares,
        None => {
            sums.clear();
            sums.resize(m, 0.0);
            for (&e, &w) in eve.iter().zip(weights) {
                sums[e as usize] += w;
            }
            sums.iter().map(|s| s * s).sum()
        }
    };
    // Lee and Whiteley's factor is (M / (M - 1))^(r + 1) for multinomial resampling;
    // under systematic resampling (the default) it over-corrects (lgss, M = 1000, spans
    // of 10: sd 1.09 against 1.43 with the origin's factor alone and 1.63 over 200
    // runs), so only the origin's sampling is corrected for
    let correction = m as f64 / (m as f64 - 1.0);
    let v = 1.0 - correction * (1.0 - squares);
    // a negative relative variance is an estimate below 0: nothing to add
    v.max(0.0).ln_1p()
}

/// The sum over eves of their descendants' squared weight, in one pass when `eve` is
/// sorted (it is under systematic, stratified and multinomial resampling, whose
/// ancestor indices never decrease, so their composition keeps the identity's
/// order); `None` when it is not, for the general pass.
///
/// An eve's descendants end at unpredictable places: a branch there was mispredicted
/// so often that the pass cost as much as the filter's own step (nlbench, M = 10 000),
/// and one arithmetic chain is bound by its latency. So the particles are cut into
/// [`LANES`] contiguous lanes run side by side without branches, and the groups that
/// cross a lane's end are stitched afterwards (`(a + b)^2 = a^2 + b^2 + 2ab`).
fn sorted_squares(eve: &[u32], weights: &[f64]) -> Option<f64> {
    let m = eve.len().min(weights.len());
    let width = m / LANES;
    if width < 16 {
        let lane = Lane::over(&eve[..m], &weights[..m]);
        return (!lane.unsorted).then_some(lane.squares + lane.run * lane.run);
    }
    let starts: [usize; LANES] = std::array::from_fn(|l| l * width);
    let mut lanes = starts.map(|start| Lane::start(eve[start]));
    // equal slices, so that the loop has no bounds checks
    let e: [&[u32]; LANES] = std::array::from_fn(|l| &eve[starts[l]..starts[l] + width]);
    let w: [&[f64]; LANES] = std::array::from_fn(|l| &weights[starts[l]..starts[l] + width]);
    for i in 0..width {
        lanes[0].push(e[0][i], w[0][i]);
        lanes[1].push(e[1][i], w[1][i]);
        lanes[2].push(e[2][i], w[2][i]);
        lanes[3].push(e[3][i], w[3][i]);
    }
    // the last lane takes the remainder
    for i in LANES * width..m {
        lanes[LANES - 1].push(eve[i], weights[i]);
    }
    let ends: [usize; LANES] =
        std::array::from_fn(|l| if l + 1 < LANES { starts[l + 1] } else { m });
    let mut total = 0.0;
    let mut carry = 0.0;
    for l in 0..LANES {
        let lane = &lanes[l];
        if lane.unsorted {
            return None;
        }
        total += lane.squares + lane.run * lane.run;
        let first = eve[starts[l]];
        // the lane's first group (all of the lane when it holds one eve only)
        let head: f64 = eve[starts[l]..ends[l]]
            .iter()
            .zip(&weights[starts[l]..ends[l]])
            .take_while(|&(&e, _)| e == first)
            .map(|(_, &w)| w)
            .sum();
        let single = eve[ends[l] - 1] == first;
        if l > 0 {
            let last = eve[starts[l] - 1];
            if last > first {
                return None;
            }
            if last == first {
                total += 2.0 * carry * head;
                carry = if single { carry + head } else { lane.run };
                continue;
            }
        }
        carry = lane.run;
    }
    Some(total)
}

/// Lanes of [`sorted_squares`].
const LANES: usize = 4;

/// One lane of [`sorted_squares`]: the squares of the groups it completed, the sum of
/// the group it is in, and whether its eves ever decreased.
#[derive(Clone, Copy)]
struct Lane {
    squares: f64,
    run: f64,
    current: u32,
    unsorted: bool,
}

impl Lane {
    fn start(first: u32) -> Lane {
        Lane {
            squares: 0.0,
            run: 0.0,
            current: first,
            unsorted: false,
        }
    }

    /// One lane over all of `eve` (the short case).
    fn over(eve: &[u32], weights: &[f64]) -> Lane {
        let mut lane = Lane::start(eve.first().copied().unwrap_or(0));
        for (&e, &w) in eve.iter().zip(weights) {
            lane.push(e, w);
        }
        lane
    }

    #[inline(always)]
    fn push(&mut self, e: u32, w: f64) {
        // 1.0 where a new eve's descendants begin, by masking the bits of 1.0 (a
        // conversion from bool became a mispredicted branch again)
        let mask = 0u64.wrapping_sub(u64::from(e != self.current));
        let new = f64::from_bits(1f64.to_bits() & mask);
        self.unsorted |= e < self.current;
        self.squares += new * self.run * self.run;
        self.run = self.run * (1.0 - new) + w;
        self.current = e;
    }
}

#[cfg(test)]
mod tests {
    use super::sorted_squares;
    use rand::RngExt;

    /// The sum of squared group weights, by scattering into one sum per eve.
    fn scattered(eve: &[u32], weights: &[f64]) -> f64 {
        let mut sums = vec![0.0; eve.iter().max().map_or(0, |&e| e as usize + 1)];
        for (&e, &w) in eve.iter().zip(weights) {
            sums[e as usize] += w;
        }
        sums.iter().map(|s| s * s).sum()
    }

    #[test]
    fn the_lanes_give_the_scattered_sum_of_squares() {
        let mut rng = crate::stream(3, 0);
        for case in 0..400 {
            let m = 1 + case % 137 + if case % 5 == 0 { 1000 } else { 0 };
            // few eves (groups crossing lanes) to many
            let eves = 1 + rng.random_range(0..m as u32);
            let mut eve: Vec<u32> = (0..m).map(|_| rng.random_range(0..eves)).collect();
            eve.sort_unstable();
            let weights: Vec<f64> = (0..m).map(|_| rng.random::<f64>()).collect();
            let lanes = sorted_squares(&eve, &weights).expect("sorted");
            let reference = scattered(&eve, &weights);
            assert!(
                (lanes - reference).abs() <= 1e-12 * reference.max(1.0),
                "m {m}, eves {eves}: {lanes} against {reference}"
            );
            if eve.first() != eve.last() {
                eve.reverse();
                assert_eq!(sorted_squares(&eve, &weights), None, "m {m}");
            }
        }
    }
}
