//! The problem as the effects see it: what each residual measures ([`Rows`]), the residuals
//! and Jacobian columns at the estimate, the derivatives with respect to the readings and the
//! rotation deviations ([`Derivatives`]), and what the effects need to know about the robot
//! ([`Context`]).

use hapcal_calibrate::baseline::GeometricBaseline;
use hapcal_contract::Effect;
use hapcal_identify::Problem;
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, Observations, RowKind, TransversalTerm,
};
use nalgebra::{DMatrix, DVector, Vector3};

use super::READING_STEP;
use crate::Error;

/// What one residual measures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Res {
    /// Axis `axis` of a position (marker, position or socket), σ of its weight, m.
    Position { axis: usize, sigma: f64 },
    /// An orientation component, σ rad.
    Orientation,
    /// A distance, σ m.
    Distance { sigma: f64 },
    /// A constraint between unknown points (never held out, never scored).
    Constraint,
}

impl Res {
    /// σ (m) of a residual that is a length error — a position axis or a distance — whose
    /// squares the held-out RMS, the floor and the residual map add up; `None` for an
    /// orientation or a constraint. (On a distance log every scored residual is a distance.)
    pub(super) fn length_sigma(&self) -> Option<f64> {
        match self {
            Res::Position { sigma, .. } | Res::Distance { sigma } => Some(*sigma),
            Res::Orientation | Res::Constraint => None,
        }
    }
}

/// The rows of one problem, described for the effects.
pub(super) struct Rows {
    /// Per residual: its kind and configuration (`usize::MAX` for constraints).
    pub(super) res: Vec<(Res, usize)>,
    /// Per residual: the measured position of its row in the measurement frame (m), if any.
    pub(super) measured: Vec<Option<[f64; 3]>>,
    /// Per configuration: readings.
    pub(super) q: Vec<Vec<f64>>,
    /// Per configuration: group.
    pub(super) group: Vec<usize>,
    /// Per configuration: time.
    pub(super) time: Vec<f64>,
}

impl Rows {
    pub(super) fn new(
        problem: &CalibrationProblem,
        configuration: &[usize],
        q: Vec<Vec<f64>>,
        group: Vec<usize>,
        time: Vec<f64>,
    ) -> Rows {
        let w = problem.weights();
        let obs = problem.observations();
        let mut res = Vec::new();
        let mut measured = Vec::new();
        for (row, &c) in obs.rows.iter().zip(configuration) {
            // Three position residuals (measured where the row gives the position), then the
            // orientation's three.
            let (position, sigma, n_orientation) = match &row.kind {
                RowKind::Distance { distance_m } => {
                    res.push((
                        Res::Distance {
                            sigma: w.sigma_distance_m,
                        },
                        c,
                    ));
                    measured.push(Some([*distance_m, 0.0, 0.0]));
                    continue;
                }
                RowKind::Position { position_m } | RowKind::Marker { position_m, .. } => {
                    (Some(*position_m), w.sigma_position_m, 0)
                }
                RowKind::Pose { position_m, .. } => (Some(*position_m), w.sigma_position_m, 3),
                RowKind::Point { .. } => (None, w.sigma_point_m, 0),
            };
            for axis in 0..3 {
                res.push((Res::Position { axis, sigma }, c));
                measured.push(position);
            }
            for _ in 0..n_orientation {
                res.push((Res::Orientation, c));
                measured.push(None);
            }
        }
        for _ in 0..obs.point_distances.len() {
            res.push((Res::Constraint, usize::MAX));
            measured.push(None);
        }
        Rows {
            res,
            measured,
            q,
            group,
            time,
        }
    }

    pub(super) fn n_configurations(&self) -> usize {
        self.q.len()
    }
}

/// Residuals of `problem` at `x`, as a vector.
pub(super) fn residuals(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
) -> Result<DVector<f64>, Error> {
    let mut r = faer::Col::<f64>::zeros(problem.n_residuals());
    problem
        .residuals(x.as_ref(), r.as_mut())
        .map_err(|e| Error::Baseline {
            message: format!("evaluating the residuals: {e}"),
        })?;
    Ok(DVector::from_iterator(r.nrows(), r.iter().copied()))
}

/// Jacobian columns of `problem` at `x`, one matrix per set of `sets` (a `None` entry is a
/// zero column), from one evaluation of the Jacobian.
pub(super) fn jacobian_sets<const N: usize>(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
    sets: [&[Option<usize>]; N],
) -> Result<[DMatrix<f64>; N], Error> {
    let mut j = faer::Mat::<f64>::zeros(problem.n_residuals(), problem.layout().len());
    problem
        .jacobian(x.as_ref(), j.as_mut())
        .map_err(|e| Error::Baseline {
            message: format!("evaluating the Jacobian: {e}"),
        })?;
    Ok(sets.map(|cols| {
        DMatrix::from_fn(j.nrows(), cols.len(), |i, k| {
            cols[k].map_or(0.0, |c| j[(i, c)])
        })
    }))
}

/// Per joint of `names`, the indices of its placement's rotation deviations `{joint}.rx`,
/// `.ry`, `.rz` in `problem`'s layout, three entries per joint (`None` for a joint without
/// them: a D-H row, or no rotation deviations).
pub(super) fn rotation_params(
    problem: &CalibrationProblem,
    names: &[String],
) -> Vec<Option<usize>> {
    let chain = problem.chain();
    (names.iter())
        .flat_map(|name| ["rx", "ry", "rz"].map(|a| chain.param_index(&format!("{name}.{a}"))))
        .collect()
}

/// What the effects are built from: the problem's derivatives at the estimate.
pub(super) struct Derivatives {
    /// `∂r/∂q_j` for every joint (`n_residuals × n_joints`).
    pub(super) dq: DMatrix<f64>,
    /// `∂r/∂ρ_{j,a}` for the rotation deviations `rx`, `ry`, `rz` of every joint's placement
    /// (`n_residuals × 3·n_joints`, columns `3j..3j + 3`; zero for a joint without them).
    pub(super) rotation: DMatrix<f64>,
}

/// `∂r/∂q_j` for every joint (n_residuals × n_joints), by central differences of the problem
/// with every row's reading of joint `j` moved by ±[`READING_STEP`].
pub(super) fn reading_derivatives(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
    n_joints: usize,
) -> Result<DMatrix<f64>, Error> {
    let obs = problem.observations();
    let mut d = DMatrix::zeros(problem.n_residuals(), n_joints);
    for j in 0..n_joints {
        let moved = |h: f64| -> Result<DVector<f64>, Error> {
            let mut o: Observations = obs.clone();
            for row in &mut o.rows {
                let mut q = row.q.to_vec();
                q[j] += h;
                row.q = q.into();
            }
            let p = problem.with_observations(o).map_err(|e| Error::Baseline {
                message: e.to_string(),
            })?;
            residuals(&p, x)
        };
        let plus = moved(READING_STEP)?;
        let minus = moved(-READING_STEP)?;
        d.set_column(j, &((plus - minus) / (2.0 * READING_STEP)));
    }
    Ok(d)
}

/// What the effects need to know about the robot.
pub(super) struct Context<'a> {
    pub(super) baseline: &'a GeometricBaseline,
    /// Gravity-torque model of the link masses, if any are known.
    pub(super) masses: Option<GravityCompliance>,
    /// Gravity direction in the measurement frame.
    pub(super) gravity: Vector3<f64>,
    /// Largest horizontal reach over the training configurations, m.
    pub(super) reach_max: f64,
    /// The drift's time origin (the first training time), the training's span and its
    /// median time step, s.
    pub(super) time_origin: f64,
    pub(super) time_span: f64,
    pub(super) time_step: f64,
    /// The calibration's transversal compliance terms of the robot, isotropic and per axis
    /// ([`library_transversal`]), or why it has none.
    pub(super) transversal: Result<[Vec<TransversalTerm>; 2], String>,
}

impl Context<'_> {
    pub(super) fn n_joints(&self) -> usize {
        self.baseline.robot.joint_names.len()
    }

    /// The gravity loads of a joint compliance `effect`: the link masses for
    /// [`Effect::GravityCompliance`], unit weights for [`Effect::LumpedCompliance`]; `Err`
    /// with the reason when the robot's masses are unknown.
    pub(super) fn torque_model(&self, effect: Effect) -> Result<GravityCompliance, String> {
        match effect {
            Effect::GravityCompliance => self.masses.clone().ok_or_else(|| {
                "no link masses: the URDF has no <inertial> and the robot's published masses \
                 are unknown"
                    .to_owned()
            }),
            _ => Ok(GravityCompliance::default()),
        }
    }

    /// Tip position on the nominal robot, base frame, m.
    pub(super) fn tip(&self, q: &[f64]) -> Vector3<f64> {
        let chain = &self.baseline.torque_chain;
        chain.end_point(&vec![0.0; chain.n_params()], q).coords
    }

    pub(super) fn reach(&self, q: &[f64]) -> f64 {
        let p = self.tip(q);
        (p.x * p.x + p.y * p.y).sqrt()
    }
}

impl Context<'_> {
    /// Times of the `n` configurations of a held-out set on the training's clock: a held-out
    /// set carries no time of its own, so it is taken to follow the training rows (the last
    /// rows of a file, or a file recorded after it), at the training's median time step.
    pub(super) fn held_out_times(&self, n: usize) -> Vec<f64> {
        let end = self.time_origin + self.time_span;
        (1..=n).map(|k| end + k as f64 * self.time_step).collect()
    }
}

/// Median of the positive steps between consecutive times (1 without any).
pub(super) fn median_step(time: &[f64]) -> f64 {
    let mut d: Vec<f64> = (time.windows(2))
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(1.0)
}
