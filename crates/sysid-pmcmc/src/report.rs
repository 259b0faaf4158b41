//! What a user needs to judge a set of chains: the summaries (Vehtari et al. 2021),
//! the acceptance rates, particle Gibbs's state update rate, and warnings when the
//! summaries should not be trusted.

use crate::{Chain, ParameterSummary, summarise};

/// R-hat above this says the chains have not mixed (Vehtari et al. 2021).
pub const RHAT_LIMIT: f64 = 1.01;

/// Fewer effective draws than this make the posterior summaries unreliable.
pub const ESS_LIMIT: f64 = 400.0;

/// PMMH acceptance below this: the chain barely moves.
pub const ACCEPTANCE_LIMIT: f64 = 0.05;

/// Why a set of chains' summaries should not be trusted.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum ChainWarning {
    /// Rank-normalised R-hat above [`RHAT_LIMIT`] (several chains): each parameter
    /// concerned with its R-hat.
    NotMixed(Vec<(String, f64)>),
    /// Parameters whose draws never changed.
    Stuck(Vec<String>),
    /// Bulk or tail ESS below [`ESS_LIMIT`]: each parameter with its bulk and tail ESS.
    FewDraws(Vec<(String, f64, f64)>),
    /// PMMH acceptance below [`ACCEPTANCE_LIMIT`] (the lowest over the chains).
    LowAcceptance(f64),
    /// The chains stopped (a user's Ctrl-C) before the end of their burn-in: no draw
    /// to summarise.
    NoDraws {
        /// Iterations the shortest chain made.
        iterations: usize,
        /// The burn-in.
        burn_in: usize,
    },
}

impl std::fmt::Display for ChainWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ChainWarning::NotMixed(rhat) => {
                let list: Vec<String> = rhat.iter().map(|(n, r)| format!("{n} {r:.3}")).collect();
                write!(
                    f,
                    "the chains have not mixed: R-hat above {RHAT_LIMIT} ({}); run longer or \
                     tune the proposal before using the summaries",
                    list.join(", ")
                )
            }
            ChainWarning::Stuck(names) => write!(
                f,
                "the draws of {} never changed: the sampler did not move them (a summary of \
                 one value)",
                names.join(", ")
            ),
            ChainWarning::FewDraws(ess) => {
                let list: Vec<String> = ess
                    .iter()
                    .map(|(n, bulk, tail)| format!("{n} bulk {bulk:.0}, tail {tail:.0}"))
                    .collect();
                write!(
                    f,
                    "few effective draws: ESS below {ESS_LIMIT} ({}); the means and quantiles \
                     carry large Monte Carlo error",
                    list.join(", ")
                )
            }
            ChainWarning::NoDraws {
                iterations,
                burn_in,
            } => write!(
                f,
                "the chains stopped after {iterations} iterations, inside their burn-in of \
                 {burn_in}: no draws to summarise"
            ),
            ChainWarning::LowAcceptance(lowest) => write!(
                f,
                "acceptance {lowest:.3} below {ACCEPTANCE_LIMIT}: the chain barely moves \
                 (smaller proposal steps, or more particles for a less noisy likelihood \
                 estimate)"
            ),
        }
    }
}

/// The summaries of a set of chains and the warnings they call for.
///
/// # Example
/// ```
/// use sysid_pmcmc::{Chain, ChainReport, ChainWarning};
/// // two chains that never moved
/// let chain = Chain {
///     names: vec!["a".into()],
///     burn_in: 10,
///     samples: vec![0.5; 100],
///     log_likelihood: vec![-1.0; 100],
///     log_prior: vec![0.0; 100],
///     accepted: vec![false; 100],
///     state_update_rate: None,
///     state_mean: None,
///     interrupted: false,
/// };
/// let report = ChainReport::of(&[chain.clone(), chain]);
/// assert_eq!(report.acceptance, vec![0.0, 0.0]);
/// assert!(report.warnings.contains(&ChainWarning::Stuck(vec!["a".into()])));
/// assert!(report.warnings.contains(&ChainWarning::LowAcceptance(0.0)));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ChainReport {
    /// Each parameter's summary over the chains' post-burn-in draws.
    pub summary: Vec<ParameterSummary>,
    /// Each chain's acceptance rate after burn-in.
    pub acceptance: Vec<f64>,
    /// Particle Gibbs: the lowest per-step state update rate over the chains.
    pub min_state_update_rate: Option<f64>,
    /// Why the summaries should not be trusted.
    pub warnings: Vec<ChainWarning>,
    /// Iterations made by the shortest chain (fewer than asked when interrupted).
    pub iterations: usize,
}

impl ChainReport {
    /// The report of `chains` (PMMH's or particle Gibbs's): draws that never changed,
    /// rank-normalised R-hat above 1.01 (several chains), bulk or tail effective sample
    /// size below 400 (Vehtari et al. 2021), PMMH acceptance below 0.05.
    pub fn of(chains: &[Chain]) -> ChainReport {
        let iterations = chains.iter().map(Chain::iterations).min().unwrap_or(0);
        let burn_in = chains.iter().map(|c| c.burn_in).max().unwrap_or(0);
        if iterations <= burn_in {
            return ChainReport {
                summary: Vec::new(),
                acceptance: Vec::new(),
                min_state_update_rate: None,
                warnings: vec![ChainWarning::NoDraws {
                    iterations,
                    burn_in,
                }],
                iterations,
            };
        }
        let summary = summarise(chains);
        let acceptance: Vec<f64> = chains.iter().map(Chain::acceptance_rate).collect();
        let mut min_state_update_rate = None;
        for c in chains {
            if let Some(rates) = &c.state_update_rate {
                let low = rates.iter().copied().fold(f64::INFINITY, f64::min);
                min_state_update_rate =
                    Some(min_state_update_rate.map_or(low, |m: f64| m.min(low)));
            }
        }
        let mut warnings = Vec::new();
        let high_rhat: Vec<(String, f64)> = summary
            .iter()
            .filter(|s| s.rhat > RHAT_LIMIT)
            .map(|s| (s.name.clone(), s.rhat))
            .collect();
        if chains.len() >= 2 && !high_rhat.is_empty() {
            warnings.push(ChainWarning::NotMixed(high_rhat));
        }
        // no ESS for draws that exist: they never changed
        let stuck: Vec<String> = summary
            .iter()
            .filter(|s| s.ess_bulk.is_nan() && !s.mean.is_nan())
            .map(|s| s.name.clone())
            .collect();
        if !stuck.is_empty() {
            warnings.push(ChainWarning::Stuck(stuck));
        }
        let low_ess: Vec<(String, f64, f64)> = summary
            .iter()
            .filter(|s| s.ess_bulk.min(s.ess_tail) < ESS_LIMIT)
            .map(|s| (s.name.clone(), s.ess_bulk, s.ess_tail))
            .collect();
        if !low_ess.is_empty() {
            warnings.push(ChainWarning::FewDraws(low_ess));
        }
        // PMMH only: particle Gibbs reports its state update rate instead
        let lowest = acceptance.iter().copied().fold(f64::INFINITY, f64::min);
        if min_state_update_rate.is_none() && lowest < ACCEPTANCE_LIMIT {
            warnings.push(ChainWarning::LowAcceptance(lowest));
        }
        ChainReport {
            summary,
            acceptance,
            min_state_update_rate,
            warnings,
            iterations,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{ChainReport, ChainWarning};
    use crate::Chain;

    /// A chain of one parameter with `made` iterations and the burn-in given.
    fn chain(made: usize, burn_in: usize) -> Chain {
        Chain {
            names: vec!["phi".into()],
            burn_in,
            samples: (0..made).map(|k| (k as f64 * 0.7).sin()).collect(),
            log_likelihood: vec![-1.0; made],
            log_prior: vec![0.0; made],
            accepted: (0..made).map(|k| k % 3 == 0).collect(),
            state_update_rate: None,
            state_mean: None,
            interrupted: true,
        }
    }

    #[test]
    fn chains_stopped_inside_their_burn_in_have_no_summary_and_say_so() {
        let report = ChainReport::of(&[chain(40, 100), chain(37, 100)]);
        assert!(report.summary.is_empty() && report.acceptance.is_empty());
        assert_eq!(report.iterations, 37);
        assert_eq!(
            report.warnings,
            vec![ChainWarning::NoDraws {
                iterations: 37,
                burn_in: 100
            }]
        );
        assert!(
            report.warnings[0]
                .to_string()
                .contains("no draws to summarise")
        );
        // past the burn-in, the draws made are summarised and counted
        let report = ChainReport::of(&[chain(150, 100), chain(160, 100)]);
        assert_eq!(report.iterations, 150);
        assert_eq!(report.summary.len(), 1);
        assert!(report.summary[0].mean.is_finite() && report.summary[0].sd >= 0.0);
    }
}
