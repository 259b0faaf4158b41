//! Shared test helpers: random stable systems and a dense joint-Gaussian reference.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use sysid_kalman::{LinearGaussianModel, Record};

pub fn gaussian_matrix(rng: &mut Xoshiro256PlusPlus, r: usize, c: usize) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |_, _| StandardNormal.sample(rng))
}

fn spd(rng: &mut Xoshiro256PlusPlus, n: usize, floor: f64) -> DMatrix<f64> {
    let g = gaussian_matrix(rng, n, n);
    (&g * g.transpose()) / (n as f64) + DMatrix::identity(n, n) * floor
}

/// A random stable system: n <= 6, p <= 3, m <= 2; half with S != 0, half with an offset.
pub fn random_system(seed: u64) -> (LinearGaussianModel, Record) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let n = rng.random_range(1..=6);
    let p = rng.random_range(1..=3);
    let m = rng.random_range(0..=2);
    let g = gaussian_matrix(&mut rng, n, n);
    let rho: f64 = rng.random_range(0.3..0.97);
    let a = &g * (rho / g.norm().max(1e-9)); // Frobenius >= spectral norm: stable
    let c = gaussian_matrix(&mut rng, p, n);
    let b = gaussian_matrix(&mut rng, n, m);
    let d = gaussian_matrix(&mut rng, p, m);
    let joint = spd(&mut rng, n + p, 0.05);
    let q = joint.view((0, 0), (n, n)).clone_owned();
    let r = joint.view((n, n), (p, p)).clone_owned();
    let with_s = seed.is_multiple_of(2);
    let mut builder = LinearGaussianModel::builder(a, c, q, r)
        .b(b)
        .d(d)
        .mu(DVector::from_fn(n, |_, _| rng.random_range(-1.0..1.0)))
        .p1(spd(&mut rng, n, 0.1));
    if with_s {
        builder = builder.s(joint.view((0, n), (n, p)).clone_owned());
    }
    if !seed.is_multiple_of(3) {
        builder = builder.h(DVector::from_fn(p, |_, _| rng.random_range(-2.0..2.0)));
    }
    let model = builder.build().unwrap();
    let t_len = rng.random_range(4..=14);
    let u = gaussian_matrix(&mut rng, m, t_len);
    let mut sim = model.simulate(&u, &mut rng).unwrap();
    for t in 0..t_len {
        if rng.random_bool(0.12) {
            sim.record.y.column_mut(t).fill(f64::NAN);
            continue;
        }
        for i in 0..p {
            if rng.random_bool(0.15) {
                sim.record.y[(i, t)] = f64::NAN;
            }
        }
    }
    (model, sim.record)
}

/// Dense joint Gaussian of Z = [x_1..x_{T+1}; y_1..y_T] conditioned on the observed
/// outputs: the exact answer every recursion is compared with.
pub struct DenseReference {
    pub n: usize,
    pub p: usize,
    pub t_len: usize,
    pub loglik: f64,
    /// conditional mean of Z
    pub mean: DVector<f64>,
    /// conditional covariance of Z
    pub cov: DMatrix<f64>,
}

impl DenseReference {
    pub fn new(model: &LinearGaussianModel, rec: &Record) -> Self {
        let (n, p) = (model.n(), model.p());
        let t_len = rec.len();
        let np = n + p;
        let nv = n + t_len * np;
        let mut cov_v = DMatrix::zeros(nv, nv);
        cov_v.view_mut((0, 0), (n, n)).copy_from(model.p1());
        let mut pi = DMatrix::zeros(np, np);
        pi.view_mut((0, 0), (n, n)).copy_from(model.q());
        pi.view_mut((0, n), (n, p)).copy_from(model.s());
        pi.view_mut((n, 0), (p, n))
            .copy_from(&model.s().transpose());
        pi.view_mut((n, n), (p, p)).copy_from(model.r());
        for t in 0..t_len {
            cov_v
                .view_mut((n + t * np, n + t * np), (np, np))
                .copy_from(&pi);
        }
        let nz = n * (t_len + 1) + p * t_len;
        let mut g = DMatrix::zeros(nz, nv);
        let mut mean = DVector::zeros(nz);
        // x_1 = mu + v_0
        let mut gx = DMatrix::zeros(n, nv);
        gx.view_mut((0, 0), (n, n)).fill_with_identity();
        let mut mx = model.mu().clone();
        for t in 0..t_len {
            g.view_mut((t * n, 0), (n, nv)).copy_from(&gx);
            mean.rows_mut(t * n, n).copy_from(&mx);
            let u = rec.u.column(t).clone_owned();
            let mut gy = model.c() * &gx;
            for i in 0..p {
                gy[(i, n + t * np + n + i)] += 1.0;
            }
            let my = model.c() * &mx + model.d() * &u + model.h();
            let oy = n * (t_len + 1) + t * p;
            g.view_mut((oy, 0), (p, nv)).copy_from(&gy);
            mean.rows_mut(oy, p).copy_from(&my);
            let mut gx_next = model.a() * &gx;
            for i in 0..n {
                gx_next[(i, n + t * np + i)] += 1.0;
            }
            mx = model.a() * &mx + model.b() * &u;
            gx = gx_next;
        }
        g.view_mut((t_len * n, 0), (n, nv)).copy_from(&gx);
        mean.rows_mut(t_len * n, n).copy_from(&mx);
        let cov = &g * cov_v * g.transpose();
        let obs: Vec<usize> = (0..t_len)
            .flat_map(|t| (0..p).map(move |i| (t, i)))
            .filter(|&(t, i)| !rec.y[(i, t)].is_nan())
            .map(|(t, i)| n * (t_len + 1) + t * p + i)
            .collect();
        let k = obs.len();
        let y_obs = DVector::from_fn(k, |a, _| {
            let idx = obs[a] - n * (t_len + 1);
            rec.y[(idx % p, idx / p)]
        });
        let mu_obs = DVector::from_fn(k, |a, _| mean[obs[a]]);
        let s_oo = DMatrix::from_fn(k, k, |a, b| cov[(obs[a], obs[b])]);
        let s_zo = DMatrix::from_fn(nz, k, |i, b| cov[(i, obs[b])]);
        let chol = s_oo.clone().cholesky().expect("observed covariance PD");
        let resid = &y_obs - &mu_obs;
        let alpha = chol.solve(&resid);
        let logdet = 2.0 * chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
        let loglik = -0.5 * (k as f64) * (2.0 * std::f64::consts::PI).ln()
            - 0.5 * logdet
            - 0.5 * resid.dot(&alpha);
        let mut cond_mean = &mean + &s_zo * alpha;
        let mut cond_cov = &cov - &s_zo * chol.solve(&s_zo.transpose());
        let mut loglik = loglik;
        if model.is_diffuse() {
            // x_1 = mu + A_d delta + v_0 with a flat delta: Z moves by H delta. Given
            // delta the moments are affine in it; its posterior is N(S^-1 s, S^-1).
            let h = g.columns(0, n) * model.diffuse();
            let h_o = DMatrix::from_fn(k, h.ncols(), |a, c| h[(obs[a], c)]);
            let sinv_h = chol.solve(&h_o);
            let info = h_o.transpose() * &sinv_h;
            let score = sinv_h.transpose() * &resid;
            let info_chol = info.clone().cholesky().expect("diffuse part identified");
            let delta = info_chol.solve(&score);
            let logdet_info = 2.0 * info_chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
            loglik += -0.5 * logdet_info + 0.5 * score.dot(&delta);
            let gain = &h - &s_zo * &sinv_h;
            cond_mean += &gain * delta;
            cond_cov += &gain * info_chol.inverse() * gain.transpose();
        }
        DenseReference {
            n,
            p,
            t_len,
            loglik,
            mean: cond_mean,
            cov: cond_cov,
        }
    }

    pub fn x_mean(&self, k: usize) -> DVector<f64> {
        self.mean.rows(k * self.n, self.n).clone_owned()
    }
    pub fn x_cov(&self, k: usize, l: usize) -> DMatrix<f64> {
        self.cov
            .view((k * self.n, l * self.n), (self.n, self.n))
            .clone_owned()
    }

    /// Sum over t of E[c c'] for c = [x_t; u_t; 1; x_{t+1}; y_t].
    pub fn second_moment(&self, rec: &Record) -> DMatrix<f64> {
        let (n, p) = (self.n, self.p);
        let m = rec.u.nrows();
        let dim = 2 * n + m + 1 + p;
        let mut h = DMatrix::zeros(dim, dim);
        for t in 0..self.t_len {
            // c = sel * Z + const
            let nz = self.mean.len();
            let mut sel = DMatrix::zeros(dim, nz);
            let mut cst = DVector::zeros(dim);
            for i in 0..n {
                sel[(i, t * n + i)] = 1.0;
                sel[(n + m + 1 + i, (t + 1) * n + i)] = 1.0;
            }
            for i in 0..m {
                cst[n + i] = rec.u[(i, t)];
            }
            cst[n + m] = 1.0;
            for i in 0..p {
                sel[(2 * n + m + 1 + i, n * (self.t_len + 1) + t * p + i)] = 1.0;
            }
            let mean = &sel * &self.mean + cst;
            let cov = &sel * &self.cov * sel.transpose();
            h += cov + &mean * mean.transpose();
        }
        h
    }
}

/// max |a - b| / max(1, max |b|)
pub fn rel_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax().max(1.0)
}
