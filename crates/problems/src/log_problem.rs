//! A haptic device's distance-log model ([`DistanceLogModel`]) as a least-squares problem of
//! `hapcal-identify`: the one measurement model that `diagnose` tests effects with, fitted by
//! the engine that fits every other calibration.

use std::ops::Range;

use faer::{ColMut, ColRef, MatMut};
use hapcal_contract::ValueName;
use hapcal_identify::{EvalError, ParamLayout, Problem, RowBlocks, Unit};
use hapcal_kinematics::ParamUnit;

use crate::Error;
use crate::distance_log::{DistanceLogModel, DistanceLogState, EffectTerm, EffectTermKind};
use crate::transmission::{CAPSTAN_PARAMS, spec};

/// Unit of a compliance coefficient of a [`EffectTermKind::Compliance`] term, as reports and
/// device files spell it.
pub const HANDLE_COMPLIANCE_UNIT: &str = "rad/(N·m)";

impl EffectTerm {
    /// The gravity compliance of the handle on joint `joint` (0-based): the term
    /// [`EffectTermKind::Compliance`], named `joint_compliance.j{joint + 1}` (the simulator's
    /// and the diagnosis's effect name), coefficient in [`HANDLE_COMPLIANCE_UNIT`].
    pub fn handle_compliance(joint: usize) -> EffectTerm {
        EffectTerm {
            name: ValueName::HandleCompliance { joint: joint + 1 }.to_string(),
            unit: HANDLE_COMPLIANCE_UNIT,
            kind: EffectTermKind::Compliance { joint },
        }
    }
}

/// A [`DistanceLogModel`] as a [`Problem`]: `x` holds every parameter of a state
/// ([`DistanceLogState`]) in the model's column order (transmissions, chain deviations,
/// effect coefficients), as absolute values (a capstan's `c`, not its change), so that
/// `hapcal-identify`'s priors, pruning and covariance see the parameters themselves.
///
/// Residuals: [`DistanceLogModel::linearise`]'s, `(model − measured)/σ` per row (the `n`
/// cable distances, then the external-encoder rows of [`DistanceLogModel::ext_joints`]),
/// dimensionless; the Jacobian is its (Gauss–Newton, see [`DistanceLogModel`]) Jacobian.
///
/// Layout units: capstan parameters as [`crate::CapstanProblem`], Chebyshev coefficients
/// rad, chain parameters m or rad, effect coefficients [`Unit::Radian`] for a joint term or
/// a compliance (an angle per unit of its shape, so that the identification's angle prior
/// sizes them; the term's own unit, e.g. [`HANDLE_COMPLIANCE_UNIT`], is in
/// [`EffectTerm::unit`]), [`Unit::Meter`] for a distance term, dimensionless otherwise.
///
/// Source: the model is [`DistanceLogModel`]'s (docs/diagnosis.md §1–3); the fit is
/// `hapcal-identify`'s, as for [`crate::JointProblem`].
#[derive(Clone, Debug)]
pub struct DistanceLogProblem {
    model: DistanceLogModel,
    zero: DistanceLogState,
    layout: ParamLayout,
    n_residuals: usize,
}

impl DistanceLogProblem {
    /// The problem of `model` over the parameters of `structure` (its transmissions and
    /// effect terms; its values are not used, see [`Self::x_of`]).
    ///
    /// # Errors
    /// [`DistanceLogModel::linearise`]'s, for a structure that does not fit the model's
    /// chain or log.
    pub fn new(model: DistanceLogModel, structure: &DistanceLogState) -> Result<Self, Error> {
        // Every parameter at 0 (`v + (−v)` is exactly 0).
        let mut zero = structure.clone();
        zero.apply(&structure.values().iter().map(|v| -v).collect::<Vec<f64>>());
        // The structure's checks, on no sample.
        model.linearise_samples(&zero, 0..0, faer::Col::zeros(0).as_mut(), None)?;
        let all_names = model.names(&zero);
        let mut specs = Vec::with_capacity(all_names.len());
        let mut names = all_names.iter();
        for tr in &zero.transmissions {
            let units: Vec<Unit> = match tr {
                crate::LogTransmission::Capstan { .. } => {
                    CAPSTAN_PARAMS.iter().map(|(_, u)| *u).collect()
                }
                crate::LogTransmission::Polynomial { .. } => vec![Unit::Radian; tr.n_params()],
            };
            for unit in units {
                specs.extend(names.next().map(|n| spec(n.clone(), unit)));
            }
        }
        for p in model.chain().params() {
            let unit = match p.unit {
                ParamUnit::Meter => Unit::Meter,
                ParamUnit::Radian => Unit::Radian,
            };
            specs.extend(names.next().map(|n| spec(n.clone(), unit)));
        }
        for (term, _) in &zero.terms {
            let unit = match term.kind {
                EffectTermKind::Joint { .. } | EffectTermKind::Compliance { .. } => Unit::Radian,
                EffectTermKind::Distance { .. } | EffectTermKind::CableAngle { .. } => Unit::Meter,
                _ => Unit::Dimensionless,
            };
            specs.extend(names.next().map(|n| spec(n.clone(), unit)));
        }
        Ok(Self {
            n_residuals: model.n_rows(),
            model,
            zero,
            layout: ParamLayout::new(specs),
        })
    }

    /// The model.
    pub fn model(&self) -> &DistanceLogModel {
        &self.model
    }

    /// The `x` of state `s` (of this problem's structure): its values in column order.
    pub fn x_of(&self, s: &DistanceLogState) -> faer::Col<f64> {
        let v = s.values();
        faer::Col::from_fn(v.len(), |i| v[i])
    }

    /// The state at `x` (length `layout().len()`).
    pub fn state(&self, x: ColRef<'_, f64>) -> DistanceLogState {
        let mut s = self.zero.clone();
        s.apply(&x.iter().copied().collect::<Vec<f64>>());
        s
    }

    fn eval(
        &self,
        x: ColRef<'_, f64>,
        out: Option<ColMut<'_, f64>>,
        jac: Option<MatMut<'_, f64>>,
    ) -> Result<(), EvalError> {
        let lin = self
            .model
            .linearise(&self.state(x))
            .map_err(|e| EvalError {
                reason: e.to_string(),
            })?;
        if let Some(mut out) = out {
            for (i, r) in lin.residuals.iter().enumerate() {
                out[i] = *r;
            }
        }
        if let Some(mut jac) = jac {
            for c in 0..lin.jacobian.ncols() {
                for i in 0..lin.jacobian.nrows() {
                    jac[(i, c)] = lin.jacobian[(i, c)];
                }
            }
        }
        Ok(())
    }
}

impl Problem for DistanceLogProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.n_residuals
    }
    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.eval(x, Some(out), None)
    }
    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.eval(x, None, Some(jac))
    }
    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.eval(x, Some(out), Some(jac))
    }

    /// Row blocks of [`SAMPLES_PER_BLOCK`] samples when no effect term carries values per
    /// sample (a state is then built per block in time independent of the log's length).
    fn row_blocks(&self) -> Option<&dyn RowBlocks> {
        let per_sample = (self.zero.terms.iter()).any(|(t, _)| {
            matches!(
                t.kind,
                EffectTermKind::Joint { .. } | EffectTermKind::Distance { .. }
            )
        });
        (!per_sample).then_some(self as &dyn RowBlocks)
    }
}

/// Samples of a row block of [`DistanceLogProblem`]: a block's rows are its samples'
/// distance and external-encoder rows.
pub const SAMPLES_PER_BLOCK: usize = 256;

impl DistanceLogProblem {
    /// The samples of row block `block`.
    fn block_samples(&self, block: usize) -> Range<usize> {
        let n = self.model.log().n_rows();
        (block * SAMPLES_PER_BLOCK).min(n)..((block + 1) * SAMPLES_PER_BLOCK).min(n)
    }

    fn eval_block(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        out: ColMut<'_, f64>,
        jac: Option<MatMut<'_, f64>>,
    ) -> Result<(), EvalError> {
        let rows = self.block_rows(block);
        if out.nrows() != rows.len() || x.nrows() != self.layout.len() {
            return Err(EvalError {
                reason: format!(
                    "block {block}: x of {} values and {} residuals, expected {} and {}",
                    x.nrows(),
                    out.nrows(),
                    self.layout.len(),
                    rows.len()
                ),
            });
        }
        (self.model)
            .linearise_samples(&self.state(x), self.block_samples(block), out, jac)
            .map_err(|e| EvalError {
                reason: e.to_string(),
            })
    }
}

/// The rows of [`DistanceLogProblem`] in blocks of samples, each sample's distance row then
/// its external-encoder rows ([`DistanceLogModel::linearise_samples`]): a permutation of
/// [`Problem::residuals`]'s rows, which has the same Gram matrix and norm, all the streaming
/// back end reads.
impl RowBlocks for DistanceLogProblem {
    fn n_blocks(&self) -> usize {
        self.model.log().n_rows().div_ceil(SAMPLES_PER_BLOCK)
    }

    fn block_rows(&self, block: usize) -> Range<usize> {
        let per = 1 + self.model.ext_joints().len();
        let samples = self.block_samples(block);
        samples.start * per..samples.end * per
    }

    fn block_residuals(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        out: ColMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.eval_block(x, block, out, None)
    }

    fn block_jacobian(
        &self,
        x: ColRef<'_, f64>,
        block: usize,
        r_out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.eval_block(x, block, r_out, Some(jac))
    }
}
