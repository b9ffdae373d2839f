//! The problem trait that every identification problem implements, and its named parameter layout.

use faer::{Col, ColMut, ColRef, Mat, MatMut};

/// Physical unit of one parameter; used for reporting and for the rank tolerance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Unit {
    /// A length in m.
    Meter,
    /// An angle in rad.
    Radian,
    /// A pure number (ratio, scale factor, polynomial coefficient).
    Dimensionless,
    /// A compliance under a torque in N·m, rad/(N·m): the angle a joint turns per unit
    /// torque.
    RadianPerNewtonMeter,
    /// A compliance under a lever arm in m, rad/m: the angle per metre of lever arm of a unit
    /// weight, where the weight itself is unknown and absorbed into the parameter.
    RadianPerMeter,
}

impl Unit {
    /// Symbol used in reports: `m`, `rad`, `1`, `rad/(N·m)` or `rad/m`.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Meter => "m",
            Unit::Radian => "rad",
            Unit::Dimensionless => "1",
            Unit::RadianPerNewtonMeter => "rad/(N·m)",
            Unit::RadianPerMeter => "rad/m",
        }
    }
}

/// Role of a parameter in the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Role {
    /// A parameter the user wants (kinematic deviation, transmission parameter).
    Model,
    /// A nuisance parameter (unknown socket point, …): identified, reported apart, never pruned
    /// before model parameters.
    Nuisance,
}

/// One named parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSpec {
    /// Stable name, e.g. `dtheta3` or `joint_a2.rx` or `socket0.x`.
    pub name: String,
    /// Physical unit.
    pub unit: Unit,
    /// Model or nuisance.
    pub role: Role,
}

/// Names and order of the entries of a parameter vector `x` (length `len()`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamLayout {
    specs: Vec<ParamSpec>,
}

impl ParamLayout {
    /// Builds a layout from its specs, in the order of `x`.
    pub fn new(specs: Vec<ParamSpec>) -> Self {
        Self { specs }
    }
    /// A layout of `n` model parameters ([`Role::Model`]) of one `unit`, named `{prefix}0` to
    /// `{prefix}{n−1}`: the unknowns of a generic least-squares problem.
    pub fn numbered(prefix: &str, n: usize, unit: Unit) -> Self {
        Self::new(
            (0..n)
                .map(|j| ParamSpec {
                    name: format!("{prefix}{j}"),
                    unit,
                    role: Role::Model,
                })
                .collect(),
        )
    }
    /// Number of parameters `n`.
    pub fn len(&self) -> usize {
        self.specs.len()
    }
    /// True when there is no parameter.
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }
    /// All specs, in the order of `x`.
    pub fn specs(&self) -> &[ParamSpec] {
        &self.specs
    }
    /// Spec of entry `idx`.
    ///
    /// # Panics
    /// If `idx >= len()`.
    #[track_caller]
    pub fn spec(&self, idx: usize) -> &ParamSpec {
        &self.specs[idx]
    }
    /// Name of entry `idx`.
    ///
    /// # Panics
    /// If `idx >= len()`.
    #[track_caller]
    pub fn name(&self, idx: usize) -> &str {
        &self.specs[idx].name
    }
    /// Index of the parameter called `name`, if any.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.specs.iter().position(|s| s.name == name)
    }
}

/// A model evaluation that failed for data-dependent reasons (e.g. a singular configuration).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("evaluation failed: {reason}")]
pub struct EvalError {
    /// What went wrong, in plain words.
    pub reason: String,
}

/// A nonlinear least-squares problem `min_x ½‖r(x)‖²` with an analytic Jacobian.
///
/// Residuals are expected to be already weighted (divided by their standard deviation, or in a
/// common unit such as m): the solver treats them as having equal variance.
pub trait Problem {
    /// Names and order of the entries of `x` (length `n`).
    fn layout(&self) -> &ParamLayout;
    /// Number of residuals `m`.
    fn n_residuals(&self) -> usize;
    /// Writes `r(x)` into `out` (length `m`).
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError>;
    /// Writes `∂r/∂x` into `jac` (`m × n`; row i = residual i, column j = `layout()` entry j),
    /// every entry, zeros included: `jac` may hold anything before (Levenberg–Marquardt hands
    /// back the buffer it factorised in place).
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError>;
    /// Writes `r(x)` into `out` (length `m`) and `∂r/∂x` into `jac` (`m × n`) in one call.
    ///
    /// Levenberg–Marquardt evaluates both at a trial point when it expects the step to be
    /// accepted (MINPACK `lmder` needs the Jacobian at every accepted point), so a problem
    /// whose Jacobian pass computes the residuals on the way should override this and return
    /// both for the price of the Jacobian. The default calls [`Problem::residuals`], then
    /// [`Problem::jacobian`].
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.residuals(x, out)?;
        self.jacobian(x, jac)
    }
    /// Writes `r(x)` into `out` (length `m`) when given, and the columns `cols` of `∂r/∂x` into
    /// `jac` (`m × cols.len()`; column `k` = `layout()` entry `cols[k]`): what a
    /// [`Subset`](crate::Subset) of the problem evaluates. `scratch` is a buffer the call
    /// may use and keep (resized to `m × n` when it is not).
    ///
    /// The default evaluates the whole Jacobian into `scratch` and copies the columns; a
    /// [`Subset`](crate::Subset) passes the columns on to its own problem, so a subset of a
    /// subset fills one whole Jacobian, not one per level.
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    ///
    /// # Panics
    /// If a column index is out of `layout()` or `jac` is not `m × cols.len()` (misuse).
    #[track_caller]
    fn residuals_and_jacobian_columns(
        &self,
        x: ColRef<'_, f64>,
        out: Option<ColMut<'_, f64>>,
        cols: &[usize],
        mut jac: MatMut<'_, f64>,
        scratch: &mut Mat<f64>,
    ) -> Result<(), EvalError> {
        let (m, n) = (self.n_residuals(), self.layout().len());
        assert!(
            jac.nrows() == m && jac.ncols() == cols.len(),
            "jacobian columns are {} × {}, expected {m} × {}",
            jac.nrows(),
            jac.ncols(),
            cols.len()
        );
        // Not zeroed again when kept: the Jacobian writes every entry.
        if scratch.nrows() != m || scratch.ncols() != n {
            *scratch = Mat::zeros(m, n);
        }
        match out {
            Some(out) => self.residuals_and_jacobian(x, out, scratch.as_mut())?,
            None => self.jacobian(x, scratch.as_mut())?,
        }
        for (k, &i) in cols.iter().enumerate() {
            jac.as_mut().col_mut(k).copy_from(scratch.col(i));
        }
        Ok(())
    }
    /// The same residuals and Jacobian as independent row blocks, when the problem can
    /// evaluate them so; enables the streaming back end ([`Backend::Streaming`](crate::Backend)),
    /// whose memory does not grow with `m`. `None` (the default) means dense only.
    fn row_blocks(&self) -> Option<&dyn crate::RowBlocks> {
        None
    }
    /// The Jacobian in sparse form, when the problem knows its pattern; enables the sparse
    /// back end ([`Backend::Sparse`](crate::Backend)) for block-structured problems whose dense
    /// Jacobian would not fit in memory. `None` (the default) means dense only.
    fn sparse_jacobian(&self) -> Option<&dyn crate::SparseJacobian> {
        None
    }
}

/// The linear least-squares problem `r(x) = A·x − y`: `A` is `n_residuals × n_params` (each
/// column in its parameter's unit of `layout` per residual unit), `y` has `n_residuals`
/// entries; its Jacobian is `A` at every `x`. A linear solve by the same machinery as every
/// nonlinear fit (`hapcal-diagnose`'s least squares), and the problem whose exact answer
/// tests of that machinery know.
#[derive(Clone, Debug)]
pub struct LinearProblem {
    /// The parameters, one per column of `a`.
    pub layout: ParamLayout,
    /// The design matrix `A`.
    pub a: Mat<f64>,
    /// The observations `y`.
    pub y: Col<f64>,
}

impl Problem for LinearProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.a.nrows()
    }
    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        out.copy_from(&self.a * x - &self.y);
        Ok(())
    }
    fn jacobian(&self, _x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        jac.copy_from(&self.a);
        Ok(())
    }
}
