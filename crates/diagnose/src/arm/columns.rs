//! The effect columns: the weighted residual per unit parameter of each candidate effect of the
//! library, from the problem's derivatives at the estimate (joint-angle effects through the
//! readings, transversal compliance through the rotation deviations, positional effects
//! directly), with their names and units.

use hapcal_calibrate::baseline::DataKind;
use hapcal_contract::Effect;
use hapcal_kinematics::Tree;
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, JointLoad, ModelTerms, Observations, Transversal,
    TransversalTerm, Weights,
};
use nalgebra::{DMatrix, Vector3};

use super::problem::{Context, Derivatives, Res, Rows, jacobian_sets, rotation_params};
use super::{NEGLIGIBLE_BASIS, REPEAT_TOLERANCE};
use crate::Error;

/// The joint-angle basis of `effect` at every configuration: per parameter, its name, unit,
/// joint and per-configuration value; `Err` with the reason when the data cannot test it.
#[allow(clippy::type_complexity)]
fn joint_terms(
    effect: Effect,
    ctx: &Context<'_>,
    rows: &Rows,
) -> Result<Vec<(String, &'static str, usize, Vec<f64>)>, String> {
    let names = &ctx.baseline.robot.joint_names;
    let prismatic = &ctx.baseline.robot.prismatic;
    let n = ctx.n_joints();
    // A joint whose basis is negligible beside the effect's largest (a torque that gravity
    // never loads, on a joint whose axis is vertical or carries the tip on its axis) is left
    // out: its column would be numerical noise.
    let per_joint = |unit: &'static str, f: &dyn Fn(usize, usize) -> f64, revolute_only: bool| {
        let all: Vec<(usize, Vec<f64>)> = (0..n)
            .filter(|&j| !(revolute_only && prismatic[j]))
            .map(|j| (j, (0..rows.n_configurations()).map(|c| f(c, j)).collect()))
            .collect();
        let size = |b: &Vec<f64>| b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let largest = all.iter().map(|(_, b)| size(b)).fold(0.0, f64::max);
        all.into_iter()
            .filter(|(_, b)| size(b) > NEGLIGIBLE_BASIS * largest)
            .map(|(j, b)| (format!("{}.{}", effect.name(), names[j]), unit, j, b))
            .collect::<Vec<_>>()
    };
    Ok(match effect {
        Effect::GravityCompliance | Effect::LumpedCompliance => {
            let model = ctx.torque_model(effect)?;
            // Every link's weight on every branch of the robot's tree (its loads).
            let tips = &ctx.baseline.torque_tips;
            let torques: Vec<Vec<f64>> = (rows.q.iter())
                .map(|q| {
                    (model.joint_loads(tips, q).iter())
                        .map(|l| l.torque)
                        .collect()
                })
                .collect();
            let unit = if effect == Effect::GravityCompliance {
                "rad/(N·m)"
            } else {
                "rad/m"
            };
            per_joint(unit, &|c, j| torques[c][j], false)
        }
        Effect::FirstHarmonic | Effect::SecondHarmonic => {
            let h = if effect == Effect::FirstHarmonic {
                1.0
            } else {
                2.0
            };
            let mut out = Vec::new();
            for (label, f) in [("sin", f64::sin as fn(f64) -> f64), ("cos", f64::cos)] {
                for mut t in per_joint("rad", &|c, j| f(h * rows.q[c][j]), true) {
                    t.0 = format!("{}_{label}", t.0);
                    out.push(t);
                }
            }
            out
        }
        Effect::Backlash => {
            let signs = approach_signs(&rows.q, &rows.group);
            per_joint("rad", &|c, j| signs[c][j], false)
        }
        Effect::GearRatio => per_joint("1", &|c, j| rows.q[c][j], false),
        _ => return Err("not a joint-angle effect".into()),
    })
}

/// The calibration's transversal compliance terms of `robot` (its tree without instrument
/// frames, whose tips carry the gravity loads), isotropic and per axis: the terms
/// [`CalibrationProblem`] builds for `--model transversal-compliance` and `transversal-axes`
/// (joint and, per axis, the axis normal to the joint axis), read from such a problem on no
/// rows, so that the joints and axes are the calibration's own. `Err` with the calibration's
/// reason when the robot has none (a D-H chain, no revolute joint).
pub(super) fn library_transversal(robot: &Tree) -> Result<[Vec<TransversalTerm>; 2], String> {
    let terms = |transversal| {
        let problem = CalibrationProblem::on_tree(
            robot.clone(),
            Observations::default(),
            Weights::default(),
            ModelTerms {
                compliance: Some(GravityCompliance::default()),
                transversal,
                ..ModelTerms::default()
            },
        )
        .map_err(|e| e.to_string())?;
        Ok::<_, String>(problem.model(problem.initial_guess().as_ref()).transversal)
    };
    Ok([terms(Transversal::Isotropic)?, terms(Transversal::PerAxis)?])
}

/// The columns of the transversal compliance terms `terms` on `rows`, under the gravity loads
/// `loads[c]` of each configuration `c`: for term `t` of joint `j` and residual `i` of
/// configuration `c`, `Σ_a ∂r_i/∂ρ_{j,a} · tilt_t(c)_a`, with `ρ_j = (rx, ry, rz)` joint
/// `j`'s placement rotation deviations (its frame before its motion; `rotation`, three columns
/// per joint) and `tilt_t(c)` [`TransversalTerm::tilt`]. The calibration adds `c_t·tilt_t(c)`
/// to `ρ_j` in every row ([`hapcal_problems::Transversal`]), so each column is the exact first
/// derivative of its residuals in `c_t` at zero compliance: the tilt carried through the
/// chain to every marker or tip below the joint and into the instrument frame.
fn transversal_block(
    terms: &[TransversalTerm],
    rotation: &DMatrix<f64>,
    rows: &Rows,
    loads: &[Vec<JointLoad>],
) -> DMatrix<f64> {
    let tilts: Vec<Vec<Vector3<f64>>> = (loads.iter())
        .map(|l| terms.iter().map(|t| t.tilt(&l[t.joint])).collect())
        .collect();
    let mut m = DMatrix::zeros(rows.res.len(), terms.len());
    for (i, (_, c)) in rows.res.iter().enumerate() {
        if *c == usize::MAX {
            continue;
        }
        for (p, (t, tilt)) in terms.iter().zip(&tilts[*c]).enumerate() {
            m[(i, p)] = (0..3)
                .map(|a| rotation[(i, 3 * t.joint + a)] * tilt[a])
                .sum();
        }
    }
    m
}

/// The torque model a transversal compliance is tested on beside the effects `with`, and the
/// joint compliance whose loads it is: the named joint compliance's among them; alone, the
/// link masses' gravity loads ([`Effect::GravityCompliance`]: what bends a link sideways is
/// the weight below it, and a tilt normal to the joint axis needs a moment normal to it), or
/// unit weights at the tips ([`Effect::LumpedCompliance`]) when the robot's masses are
/// unknown. `Err` with the reason when neither can be built.
pub(super) fn transversal_loads(
    ctx: &Context<'_>,
    with: &[Effect],
) -> Result<(Effect, GravityCompliance), String> {
    if let Some(&compliance) = with.iter().find(|e| e.is_joint_compliance()) {
        return Ok((compliance, ctx.torque_model(compliance)?));
    }
    (ctx.torque_model(Effect::GravityCompliance)
        .map(|m| (Effect::GravityCompliance, m)))
    .or_else(|_| {
        let m = ctx.torque_model(Effect::LumpedCompliance)?;
        Ok((Effect::LumpedCompliance, m))
    })
}

/// The parameter names of transversal compliance terms (`effect.joint`, and `.u` / `.v` per
/// axis, the calibration's `transversal.{joint}[.u|.v]`), and their unit under `compliance`'s
/// loads.
fn transversal_names(
    effect: Effect,
    terms: &[TransversalTerm],
    joint_names: &[String],
    compliance: Effect,
) -> Vec<(String, &'static str)> {
    let unit = if compliance == Effect::GravityCompliance {
        "rad/(N·m)"
    } else {
        "rad/m"
    };
    (terms.iter().enumerate())
        .map(|(k, t)| {
            let axis = match (t.direction, k % 2) {
                (None, _) => "",
                (Some(_), 0) => ".u",
                (Some(_), _) => ".v",
            };
            (
                format!("{}.{}{axis}", effect.name(), joint_names[t.joint]),
                unit,
            )
        })
        .collect()
}

/// The columns the diagnosis tests for the transversal compliance `effect`
/// ([`Effect::TransversalCompliance`] or [`Effect::TransversalAxes`]) on `problem` at `x`,
/// with the gravity loads of `weights` on the tips of `robot` (the robot's tree without
/// instrument frames, as [`GeometricBaseline::torque_tips`]): per parameter, its name (as in
/// [`ArmCandidate::parameters`]) and the derivative of each of `problem`'s residuals (its
/// order and weighting) per unit compliance, rad/(N·m) with link masses, rad/m with unit
/// weights. They are the exact first derivatives of the calibration's transversal model
/// (`--model transversal-compliance` and `transversal-axes`: the tilt `c·m⊥(q)` added to each
/// revolute joint's rotation deviations) at zero compliance; `problem` is a geometric
/// calibration problem, or one whose compliances are zero at `x`.
///
/// # Errors
/// [`Error::Config`] for an effect that is not a transversal compliance; [`Error::Data`] when
/// the robot has none (no revolute joint with rotation deviations); [`Error::Baseline`] if
/// the problem cannot be evaluated.
///
/// # Panics
/// If `x.nrows()` differs from `problem`'s parameter count, or `robot`'s joints from
/// `problem`'s.
///
/// [`GeometricBaseline::torque_tips`]: hapcal_calibrate::baseline::GeometricBaseline::torque_tips
/// [`ArmCandidate::parameters`]: super::ArmCandidate::parameters
#[track_caller]
pub fn transversal_columns(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
    robot: &Tree,
    weights: &GravityCompliance,
    effect: Effect,
) -> Result<Vec<(String, Vec<f64>)>, Error> {
    if !effect.is_transversal() {
        return Err(Error::Config {
            message: format!("{} is not a transversal compliance", effect.name()),
        });
    }
    let terms = library_transversal(robot).map_err(|message| Error::Data { message })?;
    let terms = &terms[usize::from(effect == Effect::TransversalAxes)];
    let obs = problem.observations();
    let q: Vec<Vec<f64>> = obs.rows.iter().map(|r| r.q.to_vec()).collect();
    let n_rows = q.len();
    let rows = Rows::new(
        problem,
        &(0..n_rows).collect::<Vec<_>>(),
        q,
        vec![0; n_rows],
        vec![0.0; n_rows],
    );
    let names = robot.joint_names();
    let [rotation] = jacobian_sets(problem, x, [&rotation_params(problem, names)])?;
    let loads: Vec<Vec<JointLoad>> = (rows.q.iter())
        .map(|q| weights.joint_loads(robot.tips(), q))
        .collect();
    let m = transversal_block(terms, &rotation, &rows, &loads);
    let compliance = if weights.masses.is_empty() {
        Effect::LumpedCompliance
    } else {
        Effect::GravityCompliance
    };
    Ok(transversal_names(effect, terms, names, compliance)
        .into_iter()
        .enumerate()
        .map(|(k, (name, _))| (name, m.column(k).iter().copied().collect()))
        .collect())
}

/// The sign of each joint's last motion at every configuration (`q[c]`, rad or m), from the
/// configurations before it in the same group (`group[c]`), in order: `+1` or `−1` when the
/// joint moved by at least [`REPEAT_TOLERANCE`] since the previous configuration, the previous
/// sign when it did not (the gear stays on the flank it was driven against), 0 before the
/// group's first motion. The basis of [`Effect::Backlash`]; shape `q.len() × n_joints`.
pub fn approach_signs(q: &[Vec<f64>], group: &[usize]) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::with_capacity(q.len());
    for c in 0..q.len() {
        let same_group = c > 0 && group.get(c) == group.get(c - 1);
        let signs = (0..q[c].len())
            .map(|j| {
                if !same_group {
                    return 0.0;
                }
                let d = q[c][j] - q[c - 1].get(j).copied().unwrap_or(q[c][j]);
                if d.abs() >= REPEAT_TOLERANCE {
                    d.signum()
                } else {
                    out[c - 1][j]
                }
            })
            .collect();
        out.push(signs);
    }
    out
}

/// The columns (weighted residual per unit parameter) of `effect` on `rows` (derivatives
/// `d`), named with the effects `with` (a transversal compliance takes the gravity loads of
/// the joint compliance among them), and their names and units; `Err` with the reason when
/// these data cannot test it.
#[allow(clippy::type_complexity)]
pub(super) fn effect_columns(
    effect: Effect,
    ctx: &Context<'_>,
    rows: &Rows,
    d: &Derivatives,
    with: &[Effect],
) -> Result<(DMatrix<f64>, Vec<(String, &'static str)>), String> {
    let n_res = rows.res.len();
    let positional = |basis: &dyn Fn(usize, usize, Option<[f64; 3]>) -> Vec<[f64; 3]>,
                      names: Vec<(String, &'static str)>|
     -> DMatrix<f64> {
        let k = names.len();
        let mut m = DMatrix::zeros(n_res, k);
        for (i, ((kind, c), meas)) in rows.res.iter().zip(&rows.measured).enumerate() {
            let (axis, sigma) = match kind {
                Res::Position { axis, sigma } => (*axis, *sigma),
                Res::Distance { sigma } => (usize::MAX, *sigma),
                _ => continue,
            };
            let v = basis(*c, axis, *meas);
            for (p, v) in v.iter().enumerate().take(k) {
                m[(i, p)] = (if axis == usize::MAX { v[0] } else { v[axis] }) / sigma;
            }
        }
        m
    };
    let has_distance = rows.res.iter().any(|r| matches!(r.0, Res::Distance { .. }));
    let has_position = rows.res.iter().any(|r| matches!(r.0, Res::Position { .. }));
    match effect {
        Effect::ThermalDrift => {
            if ctx.time_span <= 0.0 {
                return Err("all configurations at one time".into());
            }
            let s = |c: usize| (rows.time[c] - ctx.time_origin) / ctx.time_span;
            let mut names = Vec::new();
            if has_position {
                names.extend(["x", "y", "z"].map(|a| (format!("thermal_drift.{a}"), "m")));
            }
            if has_distance {
                names.push(("thermal_drift.d".into(), "m"));
            }
            let n_pos = if has_position { 3 } else { 0 };
            let m = positional(
                &|c, axis, _| {
                    let t = s(c);
                    if axis == usize::MAX {
                        let mut v = vec![[0.0; 3]; n_pos + 1];
                        v[n_pos] = [t, 0.0, 0.0];
                        v
                    } else {
                        vec![[t, 0.0, 0.0], [0.0, t, 0.0], [0.0, 0.0, t]]
                    }
                },
                names.clone(),
            );
            Ok((m, names))
        }
        Effect::LinkDeflection => {
            if !has_position {
                return Err("no position measured".into());
            }
            let g = ctx.gravity;
            let m = positional(
                &|c, axis, _| {
                    if axis == usize::MAX {
                        return vec![[0.0; 3]];
                    }
                    let s = (ctx.reach(&rows.q[c]) / ctx.reach_max).powi(3);
                    vec![(g * s).into()]
                },
                vec![("link_deflection.sag".into(), "m")],
            );
            Ok((m, vec![("link_deflection.sag".into(), "m")]))
        }
        Effect::InstrumentScale => {
            if ctx.baseline.kind == DataKind::Sockets {
                return Err("socket data have no instrument".into());
            }
            let m = positional(
                &|_, _, meas| vec![meas.unwrap_or([0.0; 3])],
                vec![("instrument_scale.s".into(), "1")],
            );
            Ok((m, vec![("instrument_scale.s".into(), "1")]))
        }
        Effect::TransversalCompliance | Effect::TransversalAxes => {
            let (compliance, model) = transversal_loads(ctx, with)?;
            let terms = &ctx.transversal.as_ref().map_err(Clone::clone)?
                [usize::from(effect == Effect::TransversalAxes)];
            let loads: Vec<Vec<JointLoad>> = (rows.q.iter())
                .map(|q| model.joint_loads(&ctx.baseline.torque_tips, q))
                .collect();
            let m = transversal_block(terms, &d.rotation, rows, &loads);
            if (0..m.ncols()).all(|k| m.column(k).norm() == 0.0) {
                return Err("no variation in these data".into());
            }
            let names =
                transversal_names(effect, terms, &ctx.baseline.robot.joint_names, compliance);
            Ok((m, names))
        }
        _ => {
            let terms = joint_terms(effect, ctx, rows)?;
            let mut m = DMatrix::zeros(n_res, terms.len());
            for (i, (_, c)) in rows.res.iter().enumerate() {
                if *c == usize::MAX {
                    continue;
                }
                for (p, (_, _, j, basis)) in terms.iter().enumerate() {
                    m[(i, p)] = d.dq[(i, *j)] * basis[*c];
                }
            }
            let norms_zero = (0..m.ncols()).all(|k| m.column(k).norm() == 0.0);
            if norms_zero {
                return Err("no variation in these data".into());
            }
            Ok((m, terms.into_iter().map(|t| (t.0, t.1)).collect()))
        }
    }
}
