//! Property tests of identifiability over random serial chains: the rank the pruning finds
//! equals the number of independent parameters derived below, for every model convention and
//! measurement type; duplicates, a cable-drum scale factor, units and parameter order behave.
//!
//! # The theoretical counts
//!
//! A chain of `n` revolute joints is a function `q ↦ T(q)` (the tip frame in the rig frame). Its
//! set of possible functions has `4n + 6` dimensions (Everett, Driels & Mooring 1987; Hollerbach
//! & Wampler 1996, "complete and minimal" models: each joint axis is a line, 4 dof; the tool frame
//! relative to the last axis, 6 dof; the joint offsets and along-axis slides are absorbed in the
//! next element). A parametrisation may be *incomplete* (it cannot reach some of those
//! dimensions) and *redundant* (several parameters move along the same dimension, one of each
//! redundant group being pruned). A measurement type then hides some dimensions. The
//! identifiable count is the number of dimensions the parametrisation reaches **and** the
//! measurement sees; the rest of the parameters must be pruned.
//!
//! Generic random geometry: link twists away from 0 and π except where Hayati's `β` is used, link
//! lengths `|a| ≥ 0.05 m`, tool offsets non-zero, joint angles uniform in `[−π, π]`.
//!
//! **Standard D-H with a fixed rig row** (rows `0..=n`, `4(n+1)` parameters, Hayati `β` on
//! near-parallel rows `1..n−1`): row 0 places joint 1's axis (4 dof), each row `i` places the
//! next axis relative to the previous one (4 dof), the last row gives the tool 4 dof (`θ_n, d_n,
//! a_n, α_n`: no `y` offset, no rotation about `y`). A row with `β` has 5 parameters for the same
//! 4 dof (when `α_i = 0`, `d_i` and `d_{i+1}` are the same translation; `β_i` takes over, Hayati
//! 1983). So:
//! - full pose: `4n + 4` (all but the extra parameter of each `β` row);
//! - position: the tool point relative to the last axis has 3 dof, the tool frame 4: `α_n` is
//!   lost, `4n + 3`;
//! - distance from the rig origin: rotations of the whole chain about the rig origin (3 dof,
//!   all reachable, since row 0 and `θ_1, d_1` make a complete base) do not change a distance:
//!   `4n`. (The paper's device, `n = 7`: 28.)
//!
//! **Standard D-H without a rig row** (rows `1..=n`, `4n` parameters; joint 1's axis is the rig's
//! `z` axis): pose `4n`; position `4n − 1` (`α_n`); distance: joint 1 turns about an axis through
//! the rig origin, so the distance does not depend on `q_1` at all, and the rest of the chain,
//! seen from the frame after `Rz(q_1)`, has a complete base (`θ_1, d_1, a_1, α_1` place joint 2's
//! axis, `θ_2, d_2` the frame along it): all 3 rotations about the rig origin are parameter
//! changes (`θ_1` alone is the one about `z`), `4n − 1 − 3 = 4n − 4`. (A first derivation that
//! counted only the rotation about `z` was caught by this test; its shrunk case is in
//! `proptest-regressions/identifiability.txt`.)
//!
//! **Modified D-H** (Craig: rows `1..=n` with `Rx(α) [Ry(β)] Tx(a) Rz(θ + q) Tz(d)`, then a fixed
//! tool row, `4(n+1)` parameters, `β` on near-parallel rows `2..n`): joint 1's axis gets only
//! 2 dof (`α_1, a_1` about the rig `x` axis), the tool frame 6 dof (`θ_n, d_n` and the tool row).
//! Full pose: `2 + 4(n−1) + 6 = 4n + 4`, all parameters. Position: the tool point has 3 dof of the
//! tool frame's 6, `4n + 1`. Distance: of the rotations about the rig origin only the one about
//! the rig `x` axis is reachable (`α_1`): `4n`.
//!
//! **URDF placements** (each joint: origin, then `Tx Ty Tz Rx Ry Rz` deviations, then the joint
//! rotation; plus a tip placement with its own 6; `6(n+1)` parameters): complete, with the
//! slide along and the rotation about each joint axis redundant with the next element (2 per
//! joint): full pose `4n + 6`; position loses the tip's 3 rotations, `4n + 3`; distance loses the
//! 3 rotations about the rig origin, `4n`.
//!
//! The rank test uses a tiny noise (1e-6 of the prior scale), so only exact dependencies are
//! pruned: the counts are structural, not statistical.

use faer::{Col, ColMut, ColRef, Mat, MatMut};
use hapcal_identify::{
    EvalError, Identifiability, IdentifyConfig, ParamLayout, ParamSpec, Problem, PruneReason,
    RankConfig, RankConfigBase, Role, Unit, identifiability, identify,
};
use hapcal_kinematics::{
    Chain, DhConvention, DhRow, Factor, ParamInfo, ParamUnit, Placement, Vector3,
};
use hapcal_problems::{CalibrationProblem, Observations, Row, RowKind, Weights};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Model convention of a random chain.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Convention {
    /// Standard D-H; `rig_row`: with a fixed row 0 (rig → base).
    Dh { rig_row: bool },
    /// Modified D-H with a fixed tool row.
    Mdh,
    /// URDF joint placements with a tip placement.
    Urdf,
}

/// What the rig measures.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Measurement {
    Pose,
    Position,
    Distance,
}

/// A random chain: convention, joints, and the seed of its geometry.
#[derive(Clone, Copy, Debug)]
struct Case {
    convention: Convention,
    n_joints: usize,
    seed: u64,
}

fn case() -> impl Strategy<Value = Case> {
    (0..4u8, 3..=7usize, any::<u64>()).prop_map(|(c, n_joints, seed)| Case {
        convention: match c {
            0 => Convention::Dh { rig_row: true },
            1 => Convention::Dh { rig_row: false },
            2 => Convention::Mdh,
            _ => Convention::Urdf,
        },
        n_joints,
        seed,
    })
}

fn measurement() -> impl Strategy<Value = Measurement> {
    prop_oneof![
        Just(Measurement::Pose),
        Just(Measurement::Position),
        Just(Measurement::Distance)
    ]
}

/// The derivation in the module docs.
fn theoretical_rank(case: &Case, m: Measurement) -> usize {
    let n = case.n_joints;
    match (case.convention, m) {
        (Convention::Dh { rig_row: true }, Measurement::Pose) => 4 * n + 4,
        (Convention::Dh { rig_row: true }, Measurement::Position) => 4 * n + 3,
        (Convention::Dh { rig_row: true }, Measurement::Distance) => 4 * n,
        (Convention::Dh { rig_row: false }, Measurement::Pose) => 4 * n,
        (Convention::Dh { rig_row: false }, Measurement::Position) => 4 * n - 1,
        (Convention::Dh { rig_row: false }, Measurement::Distance) => 4 * n - 4,
        (Convention::Mdh, Measurement::Pose) => 4 * n + 4,
        (Convention::Mdh, Measurement::Position) => 4 * n + 1,
        (Convention::Mdh, Measurement::Distance) => 4 * n,
        (Convention::Urdf, Measurement::Pose) => 4 * n + 6,
        (Convention::Urdf, Measurement::Position) => 4 * n + 3,
        (Convention::Urdf, Measurement::Distance) => 4 * n,
    }
}

/// `±U[lo, hi]`.
fn signed(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    let v = rng.random_range(lo..hi);
    if rng.random::<bool>() { v } else { -v }
}

/// A link twist: near-parallel (`|α| ≤ 0.02`, sometimes exactly 0) with Hayati's `β` when
/// `hayati_allowed` and a coin says so, else well away from 0 and π.
fn twist(rng: &mut ChaCha8Rng, hayati_allowed: bool) -> (f64, Option<f64>) {
    if hayati_allowed && rng.random_bool(0.3) {
        let alpha = if rng.random_bool(0.3) {
            0.0
        } else {
            rng.random_range(-0.02..0.02)
        };
        (alpha, Some(rng.random_range(-0.02..0.02)))
    } else {
        (signed(rng, 0.3, 2.8), None)
    }
}

fn build_chain(case: &Case) -> Chain {
    let mut rng = ChaCha8Rng::seed_from_u64(case.seed);
    let n = case.n_joints;
    let rng = &mut rng;
    match case.convention {
        Convention::Dh { rig_row } => {
            let mut rows = Vec::new();
            if rig_row {
                rows.push(DhRow {
                    convention: DhConvention::Standard,
                    a_m: signed(rng, 0.05, 0.4),
                    alpha_rad: signed(rng, 0.3, 2.8),
                    d_m: rng.random_range(-0.3..0.3),
                    theta_rad: rng.random_range(-PI..PI),
                    beta_rad: None,
                    joint: None,
                });
            }
            for j in 0..n {
                // Row j+1's twist is between joints j+1 and j+2: none after the last joint.
                let (alpha_rad, beta_rad) = twist(rng, j + 1 < n);
                rows.push(DhRow {
                    convention: DhConvention::Standard,
                    a_m: signed(rng, 0.05, 0.4),
                    alpha_rad,
                    d_m: rng.random_range(-0.3..0.3),
                    theta_rad: rng.random_range(-PI..PI),
                    beta_rad,
                    joint: Some(j),
                });
            }
            Chain::from_dh(&rows).expect("valid D-H table")
        }
        Convention::Mdh => {
            let mut rows = Vec::new();
            for j in 0..=n {
                // Row j+1's twist is between joints j and j+1 (row 1: rig z and joint 1; the
                // tool row: joint n and the tool's z).
                let (alpha_rad, beta_rad) = twist(rng, j > 0 && j < n);
                rows.push(DhRow {
                    convention: DhConvention::Modified,
                    a_m: signed(rng, 0.05, 0.4),
                    alpha_rad,
                    d_m: signed(rng, 0.05, 0.3),
                    theta_rad: rng.random_range(-PI..PI),
                    beta_rad,
                    joint: (j < n).then_some(j),
                });
            }
            Chain::from_dh(&rows).expect("valid MDH table")
        }
        Convention::Urdf => {
            let mut placements: Vec<Placement> = (0..n)
                .map(|j| {
                    let axis = loop {
                        let v = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
                        if v.norm() > 0.3 {
                            break v.normalize();
                        }
                    };
                    Placement {
                        name: format!("j{j}"),
                        xyz_m: [0; 3].map(|_| rng.random_range(-0.3..0.3)),
                        rpy_rad: [0; 3].map(|_| rng.random_range(-PI..PI)),
                        axis: Some([axis.x, axis.y, axis.z]),
                        prismatic: false,
                    }
                })
                .collect();
            placements.push(Placement {
                name: "tip".into(),
                xyz_m: [0; 3].map(|_| signed(rng, 0.05, 0.2)),
                rpy_rad: [0; 3].map(|_| rng.random_range(-PI..PI)),
                axis: None,
                prismatic: false,
            });
            Chain::from_placements(&placements).expect("valid placements")
        }
    }
}

/// `n_poses` joint configurations, uniform in `[−π, π]`, from `seed`.
fn configurations(n_joints: usize, n_poses: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
    (0..n_poses)
        .map(|_| (0..n_joints).map(|_| rng.random_range(-PI..PI)).collect())
        .collect()
}

fn unit_of(p: &ParamInfo) -> Unit {
    match p.unit {
        ParamUnit::Meter => Unit::Meter,
        ParamUnit::Radian => Unit::Radian,
    }
}

/// Residual σ of every measurement (m, rad): tiny for structural rank decisions.
const SIGMA_STRUCTURAL: f64 = 1e-8;

/// The Jacobian (`rows × n_params`, residuals in m or rad, not divided by σ) and layout of
/// `measurement` at the nominal chain, with enough poses for ≥ 4 residuals per parameter.
fn jacobian(chain: &Chain, measurement: Measurement, seed: u64) -> (Mat<f64>, ParamLayout) {
    let n_params = chain.n_params();
    let per_pose = match measurement {
        Measurement::Pose => 6,
        Measurement::Position => 3,
        Measurement::Distance => 1,
    };
    let n_poses = (4 * n_params).div_ceil(per_pose).max(12);
    let qs = configurations(chain.n_joints(), n_poses, seed);
    match measurement {
        Measurement::Pose => {
            let layout = ParamLayout::new(
                chain
                    .params()
                    .iter()
                    .map(|p| ParamSpec {
                        name: p.name.clone(),
                        unit: unit_of(p),
                        role: Role::Model,
                    })
                    .collect(),
            );
            let x0 = vec![0.0; n_params];
            let mut jac = Mat::<f64>::zeros(6 * n_poses, n_params);
            for (k, q) in qs.iter().enumerate() {
                // Rows 0–2: m per unit parameter; rows 3–5: rad per unit parameter (1 rad ~ 1 m).
                let j6 = chain.pose_jacobian_wrt_params(&x0, q);
                for r in 0..6 {
                    for c in 0..n_params {
                        jac[(6 * k + r, c)] = j6[(r, c)];
                    }
                }
            }
            (jac, layout)
        }
        Measurement::Position | Measurement::Distance => {
            let rows = qs
                .into_iter()
                .map(|q| Row {
                    q: q.into(),
                    kind: if measurement == Measurement::Distance {
                        RowKind::Distance { distance_m: 0.5 }
                    } else {
                        RowKind::Position {
                            position_m: [0.0; 3],
                        }
                    },
                })
                .collect();
            let obs = Observations {
                rows,
                ..Observations::default()
            };
            let problem = CalibrationProblem::new(chain.clone(), obs, Weights::default(), None)
                .expect("valid problem");
            let mut jac = Mat::<f64>::zeros(problem.n_residuals(), problem.layout().len());
            problem
                .jacobian(problem.initial_guess().as_ref(), jac.as_mut())
                .expect("jacobian");
            (jac, problem.layout().clone())
        }
    }
}

fn decide(jac: &Mat<f64>, layout: &ParamLayout, cfg: &RankConfig) -> Identifiability {
    let all: Vec<usize> = (0..layout.len()).collect();
    identifiability(jac.as_ref(), layout, &all, cfg)
}

fn structural() -> RankConfig {
    RankConfigBase::default().with_sigma(SIGMA_STRUCTURAL)
}

/// The rank property: the pruning keeps exactly the theoretical number of parameters.
fn check_rank(case: &Case, m: Measurement, cfg: &RankConfig) -> Result<(), TestCaseError> {
    let chain = build_chain(case);
    let (jac, layout) = jacobian(&chain, m, case.seed);
    let id = decide(&jac, &layout, cfg);
    let expected = theoretical_rank(case, m);
    prop_assert_eq!(
        id.kept.len(),
        expected,
        "{:?}, {:?}: kept {} of {}, pruned {:?}",
        case,
        m,
        id.kept.len(),
        layout.len(),
        id.pruned
            .iter()
            .map(|p| format!("{} ({})", p.name, p.reason))
            .collect::<Vec<_>>()
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Full pose, position and distance data: the rank equals the derived count.
    #[test]
    fn pruning_rank_equals_the_theoretical_count(case in case(), m in measurement()) {
        check_rank(&case, m, &structural())?;
    }

    /// A parameter duplicated under another name: one twin is pruned, as dependent on the other
    /// with coefficient 1, and the rank does not change.
    #[test]
    fn a_duplicated_parameter_is_always_pruned(
        case in case(), m in measurement(), pick in any::<prop::sample::Index>(),
    ) {
        let chain = build_chain(&case);
        let (jac, layout) = jacobian(&chain, m, case.seed);
        let base = decide(&jac, &layout, &structural());
        // Duplicate a parameter that is kept (a pruned one's twin would be pruned too, trivially).
        let original = base.kept[pick.index(base.kept.len())];
        let dup = duplicate(&chain, original);
        let (jac_dup, layout_dup) = jacobian(&dup, m, case.seed);
        let id = decide(&jac_dup, &layout_dup, &structural());
        prop_assert_eq!(id.kept.len(), base.kept.len(), "rank changed");
        let twin = layout.name(original).to_owned();
        let copy = format!("{twin}_copy");
        let kept_names: Vec<&str> = id.kept.iter().map(|&j| layout_dup.name(j)).collect();
        prop_assert!(
            !(kept_names.contains(&twin.as_str()) && kept_names.contains(&copy.as_str())),
            "both {twin} and {copy} are kept"
        );
        // When one twin is kept, the other is reproduced by it exactly (coefficient 1). Both
        // may be pruned when the parameter belongs to a redundant group (e.g. a URDF joint's
        // slide along its axis and the next joint's offsets): then each is a combination of
        // the kept members of the group.
        let kept_twin = [&twin, &copy].into_iter().find(|n| kept_names.contains(&n.as_str()));
        for name in [&twin, &copy] {
            let Some(pruned) = id.find_pruned(name) else { continue };
            match (&pruned.reason, kept_twin) {
                (PruneReason::Dependent { on }, Some(kept)) => {
                    prop_assert_eq!(&on[0].0, kept, "{:?}", on);
                    prop_assert!((on[0].1 - 1.0).abs() < 1e-6, "{:?}", on);
                }
                (PruneReason::Dependent { .. }, None) => {}
                (other, _) => prop_assert!(false, "{name}: expected a dependence, got {other:?}"),
            }
        }
    }

    /// A cable-drum scale factor `k` (measured distance `(1 + k)·|P|`) is reproduced exactly by
    /// scaling every length (Euler: `|P| = Σ L_j ∂|P|/∂L_j`), so with all lengths free it adds no
    /// rank, and it is pruned or named in a pruned length's dependence.
    #[test]
    fn a_drum_scale_factor_is_pruned_or_flagged_when_all_lengths_are_free(case in case()) {
        let chain = build_chain(&case);
        let (jac, layout) = jacobian(&chain, Measurement::Distance, case.seed);
        let base = decide(&jac, &layout, &structural());
        // ∂r/∂k = |P| per row (residual (1 + k)|P| − δ at k = 0).
        let qs = configurations(chain.n_joints(), jac.nrows(), case.seed);
        let x0 = vec![0.0; chain.n_params()];
        let n = layout.len();
        let with_k = Mat::from_fn(jac.nrows(), n + 1, |i, j| {
            if j < n { jac[(i, j)] } else { chain.end_point(&x0, &qs[i]).coords.norm() }
        });
        let mut specs = layout.specs().to_vec();
        specs.push(ParamSpec { name: "drum_scale".into(), unit: Unit::Dimensionless, role: Role::Model });
        let layout_k = ParamLayout::new(specs);
        let id = decide(&with_k, &layout_k, &structural());
        prop_assert_eq!(id.kept.len(), base.kept.len(), "the scale factor added rank");
        let flagged = id.find_pruned("drum_scale").is_some()
            || id.pruned.iter().any(|p| matches!(&p.reason,
                PruneReason::Dependent { on } if on.iter().any(|(name, _)| name == "drum_scale")));
        prop_assert!(flagged, "drum_scale neither pruned nor named: {:?}", id.pruned);
    }

    /// Residuals and lengths in mm instead of m (σ and the length prior scaled by 1000) keep the
    /// same parameters, with a realistic noise of 10 µm / 10 µrad.
    #[test]
    fn rescaling_m_to_mm_keeps_the_same_parameters(case in case(), m in measurement()) {
        let chain = build_chain(&case);
        let (jac, layout) = jacobian(&chain, m, case.seed);
        let sigma_m = 1e-5;
        let in_m = decide(&jac, &layout, &RankConfigBase::default().with_sigma(sigma_m));
        // r_mm = 1000·r_m; ∂r_mm/∂L_mm = ∂r_m/∂L_m; ∂r_mm/∂θ = 1000·∂r_m/∂θ.
        let jac_mm = Mat::from_fn(jac.nrows(), jac.ncols(), |i, j| match layout.spec(j).unit {
            Unit::Meter => jac[(i, j)],
            _ => 1000.0 * jac[(i, j)],
        });
        let base_mm = RankConfigBase { prior_m: 1000.0 * RankConfigBase::default().prior_m, ..RankConfigBase::default() };
        let in_mm = decide(&jac_mm, &layout, &base_mm.with_sigma(1000.0 * sigma_m));
        prop_assert_eq!(&in_m.kept, &in_mm.kept, "pruned in m: {:?}, in mm: {:?}",
            in_m.pruned_names(), in_mm.pruned_names());
    }
}

/// The chain with a second screw right after the one of parameter `original`, with its own
/// parameter `{name}_copy` on the same axis: an exact duplicate under another name.
fn duplicate(chain: &Chain, original: usize) -> Chain {
    let mut factors = chain.factors().to_vec();
    let at = factors
        .iter()
        .position(|f| matches!(f, Factor::Screw { param: Some(p), .. } if *p == original))
        .expect("a factor carries the parameter");
    let Factor::Screw { motion, axis, .. } = factors[at].clone() else {
        unreachable!("matched a screw above")
    };
    let mut params = chain.params().to_vec();
    let info = params[original].clone();
    params.push(ParamInfo {
        name: format!("{}_copy", info.name),
        ..info
    });
    factors.insert(
        at + 1,
        Factor::Screw {
            motion,
            axis,
            nominal: 0.0,
            param: Some(params.len() - 1),
            joint: None,
        },
    );
    Chain::from_factors(
        factors,
        params,
        chain.joint_names().to_vec(),
        chain.element_names().to_vec(),
    )
    .expect("valid chain")
}

/// A problem whose parameters are those of `inner`, in the order `order` (`order[k]` = inner
/// index of entry `k`).
struct Permuted<'a, P> {
    inner: &'a P,
    order: Vec<usize>,
    layout: ParamLayout,
}

impl<P: Problem> Permuted<'_, P> {
    fn inner_x(&self, x: ColRef<'_, f64>) -> Col<f64> {
        let mut y = Col::zeros(x.nrows());
        for (k, &i) in self.order.iter().enumerate() {
            y[i] = x[k];
        }
        y
    }
}

impl<P: Problem> Problem for Permuted<'_, P> {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }
    fn n_residuals(&self) -> usize {
        self.inner.n_residuals()
    }
    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.inner.residuals(self.inner_x(x).as_ref(), out)
    }
    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        let mut inner = Mat::zeros(jac.nrows(), jac.ncols());
        self.inner
            .jacobian(self.inner_x(x).as_ref(), inner.as_mut())?;
        for (k, &i) in self.order.iter().enumerate() {
            jac.as_mut().col_mut(k).copy_from(inner.col(i));
        }
        Ok(())
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]

    /// Identifying from the parameters in a shuffled order gives the same kept set and the same
    /// values, within 1 % of each standard deviation (the statistical uncertainty; the solver's
    /// own tolerance is far smaller). Position data on standard D-H chains without `β`, so that
    /// no two parameters are exactly collinear (a tie would be broken by layout order).
    #[test]
    fn identified_values_do_not_depend_on_parameter_order(
        n_joints in 3..=6usize, seed in any::<u64>(), shuffle in any::<u64>(),
    ) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let rows: Vec<DhRow> = (0..=n_joints).map(|i| DhRow {
            convention: DhConvention::Standard,
            a_m: signed(&mut rng, 0.05, 0.4),
            alpha_rad: signed(&mut rng, 0.3, 2.8),
            d_m: rng.random_range(-0.3..0.3),
            theta_rad: rng.random_range(-PI..PI),
            beta_rad: None,
            joint: (i > 0).then(|| i - 1),
        }).collect();
        let chain = Chain::from_dh(&rows).expect("valid");
        let truth: Vec<f64> = (0..chain.n_params()).map(|_| rng.random_range(-1e-3..1e-3)).collect();
        let sigma = 1e-5;
        let qs = configurations(n_joints, 3 * chain.n_params(), seed);
        let obs = Observations {
            rows: qs.into_iter().map(|q| {
                let p = chain.end_point(&truth, &q);
                let noise = [0; 3].map(|_| sigma * rng.sample::<f64, _>(rand_distr::StandardNormal));
                Row { kind: RowKind::Position { position_m: [p.x + noise[0], p.y + noise[1], p.z + noise[2]] }, q: q.into() }
            }).collect(),
            ..Observations::default()
        };
        let weights = Weights { sigma_position_m: sigma, ..Weights::default() };
        let problem = CalibrationProblem::new(chain, obs, weights, None).expect("valid");
        let n = problem.layout().len();
        let mut order: Vec<usize> = (0..n).collect();
        let mut shuffle_rng = ChaCha8Rng::seed_from_u64(shuffle);
        for k in (1..n).rev() {
            order.swap(k, shuffle_rng.random_range(0..=k));
        }
        let permuted = Permuted {
            inner: &problem,
            layout: ParamLayout::new(order.iter().map(|&i| problem.layout().spec(i).clone()).collect()),
            order,
        };
        let cfg = IdentifyConfig::default();
        let a = identify(&problem, problem.initial_guess(), &cfg).expect("identifies");
        let b = identify(&permuted, Col::zeros(n), &cfg).expect("identifies");
        let mut kept_a: Vec<&str> = a.identifiability.kept.iter().map(|&j| a.layout.name(j)).collect();
        let mut kept_b: Vec<&str> = b.identifiability.kept.iter().map(|&j| b.layout.name(j)).collect();
        kept_a.sort_unstable();
        kept_b.sort_unstable();
        prop_assert_eq!(&kept_a, &kept_b);
        for name in kept_a {
            let (va, vb) = (a.value(name).expect("kept"), b.value(name).expect("kept"));
            let std = a.std(name).expect("kept");
            prop_assert!((va - vb).abs() <= 0.01 * std, "{name}: {va} vs {vb}, std {std}");
        }
    }
}

/// The rank property must be able to fail: with a deliberately wrong tolerance (`rel_tol = 0.5`:
/// any column farther than 30° from the others' span counts as dependent) the same property,
/// run by proptest's own runner on the same strategies, finds a counterexample.
#[test]
fn the_rank_property_fails_with_a_wrong_tolerance() {
    let wrong = RankConfig {
        rel_tol: 0.5,
        ..structural()
    };
    let mut runner = TestRunner::new(Config {
        cases: 16,
        failure_persistence: None,
        ..Config::default()
    });
    let result = runner.run(&(case(), measurement()), |(case, m)| {
        check_rank(&case, m, &wrong)
    });
    let err = result.expect_err("a wrong tolerance must break the rank property");
    assert!(
        err.to_string().contains("kept"),
        "the failure names the kept count: {err}"
    );
    // The same runner and strategies pass with the right tolerance.
    let mut runner = TestRunner::new(Config {
        cases: 16,
        failure_persistence: None,
        ..Config::default()
    });
    runner
        .run(&(case(), measurement()), |(case, m)| {
            check_rank(&case, m, &structural())
        })
        .expect("the right tolerance passes");
}
