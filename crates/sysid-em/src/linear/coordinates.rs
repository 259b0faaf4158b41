//! The free parameters of a linear Gaussian model as a vector of unconstrained
//! coordinates: the map the direct maximisations of the exact likelihood search over
//! (the quasi-Newton polish and the scoring finish).

use super::{Covariance, LinearEmSpec};
use nalgebra::{DMatrix, DVector};
use sysid_kalman::LinearGaussianModel;

/// One free block of the model in unconstrained coordinates.
#[derive(Debug, Clone)]
pub(crate) enum Block {
    /// Free entries (column-major indices) of A, B, C, D (0..4) or h (4) or mu (5).
    Entries { matrix: usize, indices: Vec<usize> },
    /// A covariance `F^{1/2} (floor_one I + L L') F^{1/2}` with `L` lower triangular,
    /// its diagonal stored as logarithms (full) or only its diagonal (diagonal; the
    /// entries listed in `zeros` are structural zeros, held at 0).
    Covariance {
        which: usize,
        full: bool,
        scale: DVector<f64>,
        floor_one: bool,
        zeros: Vec<usize>,
    },
}

/// The map between a model and a vector of unconstrained coordinates.
#[derive(Debug, Clone)]
pub(crate) struct Coordinates {
    blocks: Vec<Block>,
    start: LinearGaussianModel,
}

pub(crate) const Q_BLOCK: usize = 0;
pub(crate) const R_BLOCK: usize = 1;
pub(crate) const P1_BLOCK: usize = 2;

fn matrix_of(model: &LinearGaussianModel, which: usize) -> DMatrix<f64> {
    let column = |v: &DVector<f64>| DMatrix::from_column_slice(v.len(), 1, v.as_slice());
    match which {
        0 => model.a().clone(),
        1 => model.b().clone(),
        2 => model.c().clone(),
        3 => model.d().clone(),
        4 => column(model.h()),
        _ => column(model.mu()),
    }
}

fn covariance_of(model: &LinearGaussianModel, which: usize) -> DMatrix<f64> {
    match which {
        Q_BLOCK => model.q().clone(),
        R_BLOCK => model.r().clone(),
        _ => model.p1().clone(),
    }
}

impl Coordinates {
    /// The coordinates of `spec`'s free parameters at `start`, or why there are none.
    pub(crate) fn new(
        start: &LinearGaussianModel,
        spec: &LinearEmSpec,
    ) -> Result<Coordinates, String> {
        if spec.s {
            return Err("not available with a free S".into());
        }
        let mut blocks = Vec::new();
        let masks = [
            (spec.a, &spec.fixed_entries.a),
            (spec.b, &spec.fixed_entries.b),
            (spec.c, &spec.fixed_entries.c),
            (spec.d, &spec.fixed_entries.d),
        ];
        for (matrix, (free, mask)) in masks.into_iter().enumerate() {
            if free {
                let size = matrix_of(start, matrix).len();
                let indices: Vec<usize> = (0..size)
                    .filter(|&k| mask.as_ref().is_none_or(|m| !m[k]))
                    .collect();
                blocks.push(Block::Entries { matrix, indices });
            }
        }
        for (matrix, free) in [(4, spec.h), (5, spec.mu)] {
            if free {
                let indices = (0..matrix_of(start, matrix).len()).collect();
                blocks.push(Block::Entries { matrix, indices });
            }
        }
        let (n, p) = (start.n(), start.p());
        let covariances = [
            (Q_BLOCK, spec.q, DVector::from_element(n, spec.min_variance)),
            (
                R_BLOCK,
                spec.r,
                match &spec.output_noise_floor {
                    Some(f) => f.map(|v| v.max(spec.min_variance)),
                    None => DVector::from_element(p, spec.min_variance),
                },
            ),
            (
                P1_BLOCK,
                if spec.p1 {
                    Covariance::Full
                } else {
                    Covariance::Fixed
                },
                DVector::zeros(n),
            ),
        ];
        for (which, structure, floor) in covariances {
            let full = match structure {
                Covariance::Fixed => continue,
                Covariance::Full => true,
                Covariance::Diagonal => false,
            };
            let floor_one = floor.iter().all(|&v| v > 0.0);
            let scale = if floor_one {
                floor
            } else {
                DVector::from_element(floor.len(), 1.0)
            };
            let cov = covariance_of(start, which);
            // variances at most 1e-12 of the largest are structural zeros (EM leaves
            // rounding-level values where the start had exact zeros)
            let largest = cov.diagonal().amax();
            let zeros = if full || floor_one {
                Vec::new()
            } else {
                (0..cov.nrows())
                    .filter(|&i| cov[(i, i)] <= 1e-12 * largest)
                    .collect()
            };
            blocks.push(Block::Covariance {
                which,
                full,
                scale,
                floor_one,
                zeros,
            });
        }
        Ok(Coordinates {
            blocks,
            start: start.clone(),
        })
    }

    /// The coordinates of `model` (a full covariance on its floor, or singular, is
    /// moved inside by a relative 1e-10 so that its Cholesky factor exists).
    pub(crate) fn point(&self, model: &LinearGaussianModel) -> Vec<f64> {
        let mut out = Vec::new();
        for block in &self.blocks {
            match block {
                Block::Entries { matrix, indices } => {
                    let m = matrix_of(model, *matrix);
                    out.extend(indices.iter().map(|&k| m[k]));
                }
                Block::Covariance {
                    which,
                    full,
                    scale,
                    floor_one,
                    zeros,
                } => {
                    let cov = covariance_of(model, *which);
                    let d = cov.nrows();
                    let mut inner =
                        DMatrix::from_fn(d, d, |i, j| cov[(i, j)] / (scale[i] * scale[j]).sqrt());
                    if *floor_one {
                        inner -= DMatrix::identity(d, d);
                    }
                    let jitter = 1e-10 * inner.diagonal().amax().max(1e-300);
                    if *full {
                        inner += DMatrix::identity(d, d) * jitter;
                        let l = nalgebra::Cholesky::new(inner.clone())
                            .map(|c| c.l())
                            .unwrap_or_else(|| {
                                DMatrix::from_diagonal(
                                    &inner.diagonal().map(|v| v.max(jitter).sqrt()),
                                )
                            });
                        for j in 0..d {
                            for i in j..d {
                                out.push(if i == j { l[(i, i)].ln() } else { l[(i, j)] });
                            }
                        }
                    } else {
                        for i in (0..d).filter(|i| !zeros.contains(i)) {
                            out.push(inner[(i, i)].max(jitter).ln());
                        }
                    }
                }
            }
        }
        out
    }

    /// The model at `point`, or `None` if it is not a valid model.
    pub(crate) fn model(&self, point: &[f64]) -> Option<LinearGaussianModel> {
        let mut at = 0;
        let mut builder = self.start.to_builder();
        for block in &self.blocks {
            match block {
                Block::Entries { matrix, indices } => {
                    let mut m = matrix_of(&self.start, *matrix);
                    for &k in indices {
                        m[k] = point[at];
                        at += 1;
                    }
                    builder = match matrix {
                        0 => builder.a(m),
                        1 => builder.b(m),
                        2 => builder.c(m),
                        3 => builder.d(m),
                        4 => builder.h(m.column(0).clone_owned()),
                        _ => builder.mu(m.column(0).clone_owned()),
                    };
                }
                Block::Covariance {
                    which,
                    full,
                    scale,
                    floor_one,
                    zeros,
                } => {
                    let d = scale.len();
                    let mut inner = if *full {
                        let mut l = DMatrix::zeros(d, d);
                        for j in 0..d {
                            for i in j..d {
                                l[(i, j)] = if i == j { point[at].exp() } else { point[at] };
                                at += 1;
                            }
                        }
                        &l * l.transpose()
                    } else {
                        let mut diag = DVector::zeros(d);
                        for i in (0..d).filter(|i| !zeros.contains(i)) {
                            diag[i] = point[at].exp();
                            at += 1;
                        }
                        DMatrix::from_diagonal(&diag)
                    };
                    if *floor_one {
                        inner += DMatrix::identity(d, d);
                    }
                    let mut cov =
                        DMatrix::from_fn(d, d, |i, j| inner[(i, j)] * (scale[i] * scale[j]).sqrt());
                    sysid_linalg::symmetrize(&mut cov);
                    builder = match *which {
                        Q_BLOCK => builder.q(cov),
                        R_BLOCK => builder.r(cov),
                        _ => builder.p1(cov),
                    };
                }
            }
        }
        builder.build().ok()
    }
}
