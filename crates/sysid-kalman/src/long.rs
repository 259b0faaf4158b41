//! Long records in bounded memory: the filter over a stream of blocks, and the
//! smoother by checkpoints.
//!
//! [`KalmanWorkspace::filter`] and [`KalmanWorkspace::smooth`] keep `O(T n^2)` numbers
//! (about 1.7 kB per step for eight states): 17 GB at `T = 10^7`. Here the record is cut
//! into blocks of [`BLOCK_STEPS`] steps. The filter carries the predicted state
//! `x_{s|s-1}` (mean and factor) from one block to the next, so its memory does not
//! depend on `T`. The smoother keeps only that state at the start of every block (a
//! checkpoint, `n + n^2` numbers), then walks the blocks backwards: it filters one
//! block again from its checkpoint and runs the RTS recursion over it from the smoothed
//! state at the start of the following block. Time stays linear (the filter runs twice);
//! memory is `O(T/B n^2 + B n^2)`.
//!
//! The results equal the whole-record passes to round-off (the steady-state reuse of
//! [`KalmanWorkspace::set_steady_state_reuse`] restarts at every block; tested to 1e-9
//! relative), and are reproducible bit for bit.

use crate::{KalmanError, KalmanWorkspace, LinearGaussianModel, Record, Result};
use nalgebra::DMatrix;

/// The steps in one block: large enough that the per-block restart costs nothing
/// measurable, small enough that a block of a 20-state model needs a few tens of MB.
pub const BLOCK_STEPS: usize = 4096;

/// The predicted state at the start of a block: `x_{s|s-1}` and a factor `U` with
/// `U'U = P_{s|s-1}`.
#[derive(Debug, Clone)]
struct Checkpoint {
    mean: Vec<f64>,
    factor: Vec<f64>,
}

/// The square-root filter run over consecutive blocks of one long record, carrying the
/// predicted state from block to block; memory independent of the record's length.
///
/// A model with a diffuse initial state is filtered exactly when the first block
/// determines the diffuse part (a few steps for an observable model); otherwise the
/// first block fails with [`KalmanError::DiffuseNotIdentified`].
///
/// # Example
/// ```
/// use nalgebra::{dmatrix, DMatrix};
/// use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
/// use sysid_kalman::{BlockFilter, KalmanWorkspace, LinearGaussianModel};
///
/// let model = LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
///     .build()
///     .unwrap();
/// let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
/// let sim = model.simulate(&DMatrix::zeros(0, 1000), &mut rng).unwrap();
/// let mut filter = BlockFilter::new(&model);
/// for start in (0..1000).step_by(300) {
///     let len = 300.min(1000 - start);
///     let block = sim.record.y.columns(start, len).clone_owned();
///     let out = filter.push(&sysid_kalman::Record::outputs_only(block)).unwrap();
///     let _first = out.filtered_mean(0); // x_{start+1 | start+1}
/// }
/// let whole = KalmanWorkspace::new().loglik(&model, &sim.record).unwrap();
/// assert!((filter.loglik() - whole).abs() < 1e-9 * whole.abs());
/// ```
#[derive(Debug, Clone)]
pub struct BlockFilter<'m> {
    model: &'m LinearGaussianModel,
    workspace: KalmanWorkspace,
    /// the state the next block starts from (`None` before the first block)
    next: Option<Checkpoint>,
    loglik: f64,
    steps: usize,
}

impl<'m> BlockFilter<'m> {
    /// A filter at the start of a record.
    pub fn new(model: &'m LinearGaussianModel) -> Self {
        BlockFilter {
            model,
            workspace: KalmanWorkspace::new(),
            next: None,
            loglik: 0.0,
            steps: 0,
        }
    }

    /// Filters the next block of the record; the output's index 0 is the block's first
    /// step. Errors name the time within the whole record.
    ///
    /// # Errors
    /// As [`KalmanWorkspace::filter`]; a diffuse part that the first block does not
    /// determine.
    pub fn push(&mut self, block: &Record) -> Result<&crate::FilterOutput> {
        let offset = self.steps;
        let model = match &self.next {
            None => self.model.clone(),
            Some(c) => self.model.with_initial_factor(&c.mean, &c.factor),
        };
        let out = self
            .workspace
            .filter(&model, block)
            .map_err(|e| e.at_offset(offset))?;
        self.next = Some(carried_state(out).map_err(|e| e.at_offset(offset))?);
        self.loglik += out.loglik();
        self.steps += block.len();
        Ok(&self.workspace.filter)
    }

    /// The log-likelihood of the blocks filtered so far, `log p(y_1..y_s)`.
    pub fn loglik(&self) -> f64 {
        self.loglik
    }

    /// The steps filtered so far.
    pub fn steps(&self) -> usize {
        self.steps
    }
}

/// The predicted state after a block, as a proper Gaussian: with a diffuse part (first
/// block), the mean and covariance given the block's data, which must determine it.
fn carried_state(out: &crate::FilterOutput) -> Result<Checkpoint> {
    let (n, len) = (out.n, out.t_len);
    let nn = n * n;
    let mean = out.predicted_mean(len).as_slice().to_vec();
    let stored = out.pred_factor[len * nn..(len + 1) * nn].to_vec();
    let Some((x, undetermined)) = out.predicted_undetermined(len) else {
        return Ok(Checkpoint {
            mean,
            factor: stored,
        });
    };
    if undetermined.ncols() > 0 {
        let q = x.ncols();
        return Err(KalmanError::DiffuseNotIdentified {
            record: 0,
            directions: q,
            rank: q - undetermined.ncols(),
        });
    }
    // P = U'U + X V X' = [U; W]'[U; W] with W = S^{1/2} E' X' (V = E S E'), triangularised
    let v = out
        .partial_delta_covariance(len)
        .expect("a diffuse filter output has a partial posterior");
    let eigen = v.symmetric_eigen();
    let scale = DMatrix::from_diagonal(&eigen.eigenvalues.map(|s| s.max(0.0).sqrt()));
    let w = scale * eigen.eigenvectors.transpose() * x.transpose();
    let u = DMatrix::from_column_slice(n, n, &stored);
    let mut stacked = DMatrix::zeros(n + w.nrows(), n);
    stacked.view_mut((0, 0), (n, n)).copy_from(&u);
    stacked.view_mut((n, 0), (w.nrows(), n)).copy_from(&w);
    // (n + q) x n with n + q >= n rows: R is n x n
    let factor = stacked.qr().r();
    Ok(Checkpoint {
        mean,
        factor: factor.as_slice().to_vec(),
    })
}

impl KalmanWorkspace {
    /// RTS smoothing of a long record in bounded memory: the smoothed mean `x_{k+1|T}`
    /// and covariance `P_{k+1|T}` (column-major `n x n`) of every step `k` in `0..T` go
    /// to `sink(k, mean, covariance)`, block by block from the last block of
    /// [`BLOCK_STEPS`] steps to the first (in increasing `k` within a block). Returns
    /// the log-likelihood.
    ///
    /// # Algorithm
    /// A filter pass keeps the predicted state at the start of every block (a
    /// checkpoint); the backward pass filters each block again from its checkpoint and
    /// runs the recursion of [`smooth`](Self::smooth) over it, started from the smoothed
    /// state at the start of the next block. `O(T (n + p)^3)` time (the filter runs
    /// twice), `O((T / B + B) n^2)` memory.
    ///
    /// # Errors
    /// As [`smooth`](Self::smooth); a model with a diffuse initial state is refused
    /// ([`KalmanError::DiffuseInBlocks`]): smooth it whole.
    ///
    /// # Example
    /// ```
    /// use nalgebra::{dmatrix, DMatrix};
    /// use rand::{SeedableRng, rngs::Xoshiro256PlusPlus};
    /// use sysid_kalman::{KalmanWorkspace, LinearGaussianModel};
    ///
    /// let model = LinearGaussianModel::builder(dmatrix![0.9], dmatrix![1.0], dmatrix![1.0], dmatrix![0.5])
    ///     .build()
    ///     .unwrap();
    /// let sim = model
    ///     .simulate(&DMatrix::zeros(0, 10_000), &mut Xoshiro256PlusPlus::seed_from_u64(7))
    ///     .unwrap();
    /// let mut means = vec![0.0; 10_000];
    /// let mut ws = KalmanWorkspace::new();
    /// ws.smooth_in_blocks(&model, &sim.record, |k, mean, _cov| means[k] = mean[0])
    ///     .unwrap();
    /// let whole = KalmanWorkspace::new().smooth(&model, &sim.record).unwrap().mean(0)[0];
    /// assert!((means[0] - whole).abs() < 1e-9);
    /// ```
    pub fn smooth_in_blocks(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        sink: impl FnMut(usize, &[f64], &[f64]),
    ) -> Result<f64> {
        self.smooth_in_blocks_of(model, record, BLOCK_STEPS, sink)
    }

    /// [`smooth_in_blocks`](Self::smooth_in_blocks) with blocks of `block` steps (at
    /// least 1): fewer steps save memory and cost a restart per block.
    pub fn smooth_in_blocks_of(
        &mut self,
        model: &LinearGaussianModel,
        record: &Record,
        block: usize,
        mut sink: impl FnMut(usize, &[f64], &[f64]),
    ) -> Result<f64> {
        if model.is_diffuse() {
            return Err(KalmanError::DiffuseInBlocks);
        }
        record.validate(model, 0)?;
        let block = block.max(1);
        let t_len = record.len();
        let starts: Vec<usize> = (0..t_len).step_by(block).collect();
        let slice = |start: usize| {
            let len = block.min(t_len - start);
            Record::new(
                record.u.columns(start, len).clone_owned(),
                record.y.columns(start, len).clone_owned(),
            )
        };
        // forward: the checkpoint of every block
        let mut checkpoints = Vec::with_capacity(starts.len());
        let mut filter = BlockFilter::new(model);
        for &start in &starts {
            checkpoints.push(filter.next.clone());
            filter.push(&slice(start))?;
        }
        let loglik = filter.loglik();
        // backward: each block from its checkpoint, ending at the next block's start
        let (n, nn) = (model.n(), model.n() * model.n());
        let mut terminal: Option<(Vec<f64>, Vec<f64>)> = None;
        for (&start, checkpoint) in starts.iter().zip(&checkpoints).rev() {
            let block_model = match checkpoint {
                None => model.clone(),
                Some(c) => model.with_initial_factor(&c.mean, &c.factor),
            };
            let part = slice(start);
            let ends_at = terminal.as_ref().map(|(m, p)| (m.as_slice(), p.as_slice()));
            self.smooth_record_from(&block_model, &part, ends_at)
                .map_err(|e| e.at_offset(start))?;
            let s = &self.smoother;
            for k in 0..part.len() {
                sink(
                    start + k,
                    &s.mean[k * n..(k + 1) * n],
                    &s.cov[k * nn..(k + 1) * nn],
                );
            }
            terminal = Some((s.mean[..n].to_vec(), s.cov[..nn].to_vec()));
        }
        Ok(loglik)
    }
}
