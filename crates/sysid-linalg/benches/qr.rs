//! Criterion group `linalg`: the triangularisation kernel on pre-array shapes of the
//! Kalman filter (rows x cols), throughput in flops (2 r c^2 - 2/3 c^3).
//!
//! `cargo bench -p sysid-linalg --bench qr`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use sysid_linalg::{QrScratch, triangularize};

fn qr(c: &mut Criterion) {
    let mut group = c.benchmark_group("linalg");
    for (rows, cols) in [(3, 2), (10, 18), (18, 10), (18, 18)] {
        let ld = rows.max(cols);
        // a fixed, well-conditioned pseudo-random matrix
        let x: Vec<f64> = (0..ld * cols)
            .map(|i| ((i * 7919 % 1009) as f64 / 1009.0) - 0.5)
            .collect();
        let mut a = x.clone();
        let mut scratch = QrScratch::default();
        let (r, k) = (rows as f64, cols.min(rows) as f64);
        let flops = (2.0 * r * k * cols as f64 - 2.0 / 3.0 * k * k * k).max(1.0);
        group.throughput(Throughput::Elements(flops as u64));
        group.bench_function(format!("triangularize/{rows}x{cols}"), |b| {
            b.iter(|| {
                a.copy_from_slice(&x);
                triangularize(black_box(&mut a), ld, rows, cols, &mut scratch);
            })
        });
    }
    group.finish();
}

criterion_group!(benches, qr);
criterion_main!(benches);
