//! Levenberg–Marquardt on a dense synthetic problem (the calibration bench lives with the
//! problems that define it).

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use faer::{Col, ColMut, ColRef, Mat, MatMut};
use hapcal_identify::{EvalError, LmConfig, ParamLayout, Problem, Unit, levenberg_marquardt};

/// `r_i = Σ_j A_ij·sin(x_j) − y_i`, `y = A·sin(x*)`: dense, mildly nonlinear, zero residual.
struct DenseSine {
    layout: ParamLayout,
    a: Mat<f64>,
    y: Col<f64>,
}

impl Problem for DenseSine {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.a.nrows()
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        let s = Col::from_fn(x.nrows(), |j| x[j].sin());
        out.copy_from(&self.a * &s - &self.y);
        Ok(())
    }
    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        for j in 0..self.a.ncols() {
            let c = x[j].cos();
            for i in 0..self.a.nrows() {
                jac[(i, j)] = self.a[(i, j)] * c;
            }
        }
        Ok(())
    }
}

/// Deterministic entries in [−1, 1) from a 64-bit LCG (Knuth's MMIX constants).
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

fn dense_sine(m: usize, n: usize) -> DenseSine {
    let mut state = 42;
    let a = Mat::from_fn(m, n, |_, _| lcg(&mut state));
    let truth = Col::from_fn(n, |_| 0.5 * lcg(&mut state));
    let y = &a * Col::from_fn(n, |j| truth[j].sin());
    let layout = ParamLayout::numbered("x", n, Unit::Radian);
    DenseSine { layout, a, y }
}

fn bench_lm(c: &mut Criterion) {
    let mut group = c.benchmark_group("levenberg_marquardt");
    let (m, n) = (200, 30);
    let problem = dense_sine(m, n);
    let free: Vec<usize> = (0..n).collect();
    let cfg = LmConfig::default();
    // Measure a converging run, not an early exit.
    let fit = levenberg_marquardt(&problem, Col::zeros(n), &free, &cfg);
    assert!(fit.is_ok_and(|f| f.termination.is_success() && f.cost < 1e-20));
    group.bench_with_input(
        BenchmarkId::from_parameter(format!("{m}x{n}")),
        &problem,
        |b, p| b.iter(|| levenberg_marquardt(black_box(p), Col::zeros(n), &free, &cfg)),
    );
    group.finish();
}

criterion_group!(benches, bench_lm);
criterion_main!(benches);
