//! Checks and layouts a calibration problem is built from: the rows' residual counts, the weights, the compliance and transversal parameters, the row blocks, the distance lanes.

use super::*;

/// The torque tips must exist and have the tree's `n_joints` joints.
///
/// # Errors
/// [`Error::NoSuchParam`] with the first joint count that differs (0 without any tip).
pub(super) fn check_torque_tips(torque_tips: &[Chain], n_joints: usize) -> Result<(), Error> {
    let wrong = match torque_tips.iter().find(|t| t.n_joints() != n_joints) {
        Some(t) => Some(t.n_joints()),
        None => torque_tips.is_empty().then_some(0),
    };
    match wrong {
        Some(index) => Err(Error::NoSuchParam {
            index,
            n_params: n_joints,
        }),
        None => Ok(()),
    }
}

/// The model terms whose bases a configuration's gravity loads and joint angles give.
pub(super) struct BasisTerms<'a> {
    /// The compliance model and the tips of its loads.
    pub(super) compliance: Option<(&'a GravityCompliance, &'a [Chain])>,
    /// The joint harmonics.
    pub(super) harmonics: Option<&'a JointHarmonics>,
    /// The transversal terms.
    pub(super) transversal: &'a [TransversalTerm],
}

impl BasisTerms<'_> {
    /// Appends one configuration's bases: to `angle` its angle terms' (its joint torques under
    /// the compliance model, N·m or m·kg without masses, one per joint; then its harmonics'
    /// basis at the readings `q`, `sin`/`cos`), to `tilts` its transversal terms' tilts
    /// ([`TransversalTerm::tilt`]); the loads at `at` (a torque equilibrium's angles, rad)
    /// or at `q`.
    pub(super) fn bases(
        &self,
        q: &[f64],
        at: Option<&[f64]>,
        angle: &mut Vec<f64>,
        tilts: &mut Vec<[f64; 3]>,
    ) {
        if let Some((model, torque_tips)) = self.compliance {
            let loads = model.joint_loads(torque_tips, at.unwrap_or(q));
            angle.extend(loads.iter().map(|l| l.torque));
            tilts.extend(
                (self.transversal.iter()).map(|t| <[f64; 3]>::from(t.tilt(&loads[t.joint]))),
            );
        }
        if let Some(h) = self.harmonics {
            angle.extend(h.basis(q));
        }
    }
}

/// The rows' bases ([`row_bases`]).
pub(super) struct RowBases {
    /// Angle terms' basis per configuration (`n_configurations × n_terms`); empty unless
    /// `stored`.
    pub(super) angle: Vec<f64>,
    /// Transversal tilts per configuration (`n_configurations × transversal.len()`); empty
    /// unless `stored`.
    pub(super) tilts: Vec<[f64; 3]>,
    /// Each row's configuration; empty without terms.
    pub(super) row_config: Vec<usize>,
    /// Whether the bases are kept (at most [`STORED_BASES_MAX`] values) rather than
    /// evaluated row by row.
    pub(super) stored: bool,
}

/// The rows' configurations ([`Observations::configurations`]: rows of one configuration, a
/// file row's markers and distance, share their bases) and, up to [`STORED_BASES_MAX`]
/// values, every configuration's bases ([`BasisTerms::bases`]; `load_angles`, the joint
/// angles of each configuration's loads, `n_joints` a configuration, or the readings). Past
/// that, the problem evaluates them row by row: a million two-marker rows of a 20-joint robot
/// would keep half a gigabyte of bases.
pub(super) fn row_bases(
    obs: &Observations,
    terms: &BasisTerms<'_>,
    load_angles: Option<&[f64]>,
    n_terms: usize,
) -> RowBases {
    let mut bases = RowBases {
        angle: Vec::new(),
        tilts: Vec::new(),
        row_config: Vec::new(),
        stored: true,
    };
    if n_terms == 0 && terms.transversal.is_empty() {
        return bases;
    }
    bases.row_config.reserve_exact(obs.rows.len());
    for (c, rows) in obs.configurations().enumerate() {
        bases.row_config.extend(std::iter::repeat_n(c, rows.len()));
    }
    let n_configurations = bases.row_config.last().map_or(0, |c| c + 1);
    let per_configuration = n_terms + 3 * terms.transversal.len();
    bases.stored = n_configurations * per_configuration <= STORED_BASES_MAX;
    if !bases.stored {
        return bases;
    }
    for (c, rows) in obs.configurations().enumerate() {
        let q = &obs.rows[rows.start].q;
        let at = load_angles.map(|a| &a[c * q.len()..(c + 1) * q.len()]);
        terms.bases(q, at, &mut bases.angle, &mut bases.tilts);
    }
    bases
}

/// Checks that every σ of `weights` is finite and positive.
///
/// # Errors
/// [`Error::BadSigma`] naming the first that is not.
pub(super) fn check_weights(weights: &Weights) -> Result<(), Error> {
    for (name, value) in [
        ("sigma_distance_m", weights.sigma_distance_m),
        ("sigma_position_m", weights.sigma_position_m),
        ("sigma_point_m", weights.sigma_point_m),
        ("sigma_point_distance_m", weights.sigma_point_distance_m),
        ("sigma_orientation_rad", weights.sigma_orientation_rad),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(Error::BadSigma { name, value });
        }
    }
    Ok(())
}

/// The unit of `model`'s compliances: rad/(N·m) under link masses (the loads are torques),
/// rad/m under the lumped unit weights (the loads are lever arms). The rank decision holds
/// each to its unit's prior ([`hapcal_identify::RankConfig::prior_scale`]).
pub(super) fn compliance_unit(model: &GravityCompliance) -> Unit {
    if model.masses.is_empty() {
        Unit::RadianPerMeter
    } else {
        Unit::RadianPerNewtonMeter
    }
}

/// The compliance parameters of `model` on `chain`: one per group of joints,
/// `compliance.<joint>+<joint>…`, in the unit of [`compliance_unit`].
pub(super) fn compliance_specs(chain: &Chain, model: &GravityCompliance) -> Vec<ParamSpec> {
    let unit = compliance_unit(model);
    let n_joints = chain.n_joints();
    let names = chain.joint_names();
    (0..model.n_params(n_joints))
        .map(|g| {
            let joints = (0..n_joints)
                .filter(|&j| model.group(j) == g)
                .map(|j| names[j].clone())
                .collect();
            ParamSpec {
                name: ValueName::Compliance { joints }.to_string(),
                unit,
                role: Role::Model,
            }
        })
        .collect()
}

/// Each joint's angle parameter (the screw's `param`) over every tip, `None` for a joint
/// without one.
pub(super) fn joint_params(tips: &[Chain], n_joints: usize) -> Vec<Option<usize>> {
    let mut joint_param = vec![None; n_joints];
    for tip in tips {
        for factor in tip.factors() {
            if let hapcal_kinematics::Factor::Screw {
                param: Some(p),
                joint: Some(j),
                ..
            } = factor
            {
                joint_param[*j] = Some(*p);
            }
        }
    }
    joint_param
}

/// The angle terms of each angle parameter: `angle_terms` holds (joint, parameter) per term.
pub(super) fn terms_of_param(angle_terms: &[(usize, usize)]) -> Vec<Vec<usize>> {
    let n_params = angle_terms.iter().map(|&(_, p)| p + 1).max().unwrap_or(0);
    let mut of = vec![Vec::new(); n_params];
    for (t, &(_, p)) in angle_terms.iter().enumerate() {
        of[p].push(t);
    }
    of
}

/// Checks every row of `obs` (its joint count `n_joints`, finite values, the tip among
/// `n_tips` and the point it names) and counts the residuals: 1 per distance, 3 per position,
/// marker or point, 6 per pose, 1 per point distance.
///
/// # Errors
/// [`Error::JointCount`], [`Error::NotFinite`], [`Error::NoSuchParam`] for a tip the tree does
/// not have, [`Error::NoSuchPoint`].
pub(super) fn checked_residuals(
    obs: &Observations,
    n_joints: usize,
    n_tips: usize,
) -> Result<usize, Error> {
    let mut n_residuals = obs.point_distances.len();
    for (row_idx, row) in obs.rows.iter().enumerate() {
        if row.q.len() != n_joints {
            return Err(Error::JointCount {
                row: row_idx,
                expected: n_joints,
                found: row.q.len(),
            });
        }
        let finite = row.q.iter().all(|v| v.is_finite())
            && match &row.kind {
                RowKind::Distance { distance_m } => distance_m.is_finite(),
                RowKind::Position { position_m } => position_m.iter().all(|v| v.is_finite()),
                RowKind::Point { .. } => true,
                RowKind::Marker { position_m, .. } => position_m.iter().all(|v| v.is_finite()),
                RowKind::Pose {
                    position_m,
                    rotation,
                    ..
                } => {
                    position_m.iter().chain(rotation).all(|v| v.is_finite())
                        && rotation.iter().map(|v| v * v).sum::<f64>() > 0.0
                }
            };
        if !finite {
            return Err(Error::NotFinite { row: row_idx });
        }
        n_residuals += match row.kind {
            RowKind::Distance { .. } => 1,
            RowKind::Position { .. } => 3,
            RowKind::Marker { tip, .. } | RowKind::Pose { tip, .. } if tip >= n_tips => {
                return Err(Error::NoSuchParam {
                    index: tip,
                    n_params: n_tips,
                });
            }
            RowKind::Marker { .. } => 3,
            RowKind::Pose { .. } => 6,
            RowKind::Point { point } => {
                if point >= obs.n_points {
                    return Err(Error::NoSuchPoint {
                        row: row_idx,
                        point,
                        n_points: obs.n_points,
                    });
                }
                3
            }
        };
    }
    for (idx, pd) in obs.point_distances.iter().enumerate() {
        for point in [pd.a, pd.b] {
            if point >= obs.n_points {
                return Err(Error::NoSuchPoint {
                    row: idx,
                    point,
                    n_points: obs.n_points,
                });
            }
        }
    }
    Ok(n_residuals)
}

/// The transversal compliance terms of the revolute joints of `torque_tips` with rotation
/// deviations (`rx`, `ry`, `rz` of `chain`): one per joint, or two per joint about the axes
/// normal to its axis (`Transversal::PerAxis`).
///
/// # Errors
/// [`Error::NoTransversal`] when no revolute joint has rotation deviations.
pub(super) fn transversal_terms_of(
    chain: &Chain,
    torque_tips: &[Chain],
    transversal: Transversal,
) -> Result<Vec<TransversalTerm>, Error> {
    let n_joints = chain.n_joints();
    let mut transversal_terms = Vec::new();
    let revolute: Vec<bool> = (hapcal_kinematics::joint_motions(torque_tips).iter())
        .map(|m| *m == Some(hapcal_kinematics::Motion::Rotation))
        .collect();
    // Each joint's axis in its own frame, for the per-axis directions.
    let mut joint_axis = vec![Vector3::z(); n_joints];
    for tip in torque_tips {
        for factor in tip.factors() {
            if let hapcal_kinematics::Factor::Screw {
                axis,
                joint: Some(j),
                ..
            } = factor
            {
                joint_axis[*j] = axis.into_inner();
            }
        }
    }
    let names = chain.joint_names();
    for (j, name) in names.iter().enumerate() {
        let index = |axis: &str| chain.param_index(&format!("{name}.{axis}"));
        if let (true, Some(rx), Some(ry), Some(rz)) =
            (revolute[j], index("rx"), index("ry"), index("rz"))
        {
            let term = |direction| TransversalTerm {
                joint: j,
                direction,
                rotation_params: [rx, ry, rz],
                compliance: 0.0,
            };
            if transversal == Transversal::PerAxis {
                let [u, v] = normal_axes(&joint_axis[j]);
                transversal_terms.extend([term(Some(u)), term(Some(v))]);
            } else {
                transversal_terms.push(term(None));
            }
        }
    }
    if transversal_terms.is_empty() {
        return Err(Error::NoTransversal {
            reason: "no revolute joint has rotation deviations (a URDF robot has them; a D-H chain does not)",
        });
    }
    Ok(transversal_terms)
}

/// The parameters of the transversal `terms` under `model`'s loads: `transversal.<joint>`, or
/// `.u` and `.v` per joint (`Transversal::PerAxis`), in the unit of the axial compliances
/// ([`compliance_unit`]): a moment about an axis normal to the joint's deflects it as a torque
/// about the joint's axis does.
pub(super) fn transversal_specs(
    chain: &Chain,
    model: &GravityCompliance,
    terms: &[TransversalTerm],
    transversal: Transversal,
) -> Vec<ParamSpec> {
    let unit = compliance_unit(model);
    let names = chain.joint_names();
    let n_per_joint = if transversal == Transversal::PerAxis {
        2
    } else {
        1
    };
    (terms.iter().enumerate())
        .map(|(k, t)| ParamSpec {
            name: ValueName::Transversal {
                joint: names[t.joint].clone(),
                axis: match (n_per_joint, k % 2) {
                    (1, _) => None,
                    (_, 0) => Some('u'),
                    _ => Some('v'),
                },
            }
            .to_string(),
            unit,
            role: Role::Model,
        })
        .collect()
}

/// The row blocks of a problem: runs of [`ROWS_PER_BLOCK`] rows with their residual range
/// (the point distances' residuals at the end of the last block).
pub(super) fn row_blocks(obs: &Observations) -> Vec<(Range<usize>, Range<usize>)> {
    let mut blocks = Vec::new();
    let mut residual = 0;
    let n_rows = obs.rows.len();
    for start in (0..n_rows.max(1)).step_by(ROWS_PER_BLOCK) {
        let end = (start + ROWS_PER_BLOCK).min(n_rows);
        let len: usize = obs.rows[start..end]
            .iter()
            .map(|row| row.kind.n_residuals())
            .sum();
        let extra = if end == n_rows {
            obs.point_distances.len()
        } else {
            0
        };
        blocks.push((start..end, residual..residual + len + extra));
        residual += len + extra;
    }
    blocks
}

/// The distance rows of a problem without angle or transversal terms (`plain`), laid out for
/// the lane kernel: runs of [`LANES`] distance rows within a block, their joints' sines and
/// cosines and distances, and the other rows' sines and cosines.
pub(super) struct DistanceLanes {
    /// First row of each run of [`LANES`] distance rows.
    pub(super) groups: Vec<usize>,
    /// Per run and joint, the sines and cosines of the run's rows.
    pub(super) trig_lanes: Vec<[[f64; LANES]; 2]>,
    /// Per run, the rows' distances, m.
    pub(super) distance_m: Vec<[f64; LANES]>,
    /// The sines and cosines of the rows outside the runs, in row order.
    pub(super) trig: Vec<[f64; 2]>,
}

impl DistanceLanes {
    /// The lanes of `obs` within `blocks`, for `chain` (empty unless `plain` and some row is
    /// a distance).
    pub(super) fn of(
        chain: &Chain,
        obs: &Observations,
        blocks: &[(Range<usize>, Range<usize>)],
        plain: bool,
    ) -> Self {
        let n_joints = chain.n_joints();
        let any_distance = (obs.rows.iter()).any(|r| matches!(r.kind, RowKind::Distance { .. }));
        let lanes =
            plain && any_distance && chain.freeze(&vec![0.0; chain.n_params()]).supports_lanes();
        let mut lane_groups = Vec::new();
        let distance = |row: &Row| match row.kind {
            RowKind::Distance { distance_m } => Some(distance_m),
            _ => None,
        };
        if lanes {
            for (rows, _) in blocks {
                let mut row_idx = rows.start;
                while row_idx + LANES <= rows.end {
                    if obs.rows[row_idx..row_idx + LANES]
                        .iter()
                        .all(|row| distance(row).is_some())
                    {
                        lane_groups.push(row_idx);
                        row_idx += LANES;
                    } else {
                        row_idx += 1;
                    }
                }
            }
        }
        let mut lane_trig = Vec::with_capacity(lane_groups.len() * n_joints);
        let mut lane_distance_m = Vec::with_capacity(lane_groups.len());
        for &first in &lane_groups {
            let group = &obs.rows[first..first + LANES];
            lane_trig.extend(joint_trig_lanes(std::array::from_fn(|l| &group[l].q[..])));
            lane_distance_m.push(std::array::from_fn(|l| distance(&group[l]).unwrap_or(0.0)));
        }
        let mut trig = Vec::new();
        if plain && any_distance {
            let mut groups = lane_groups.iter().peekable();
            let mut row_idx = 0;
            while row_idx < obs.rows.len() {
                if groups.next_if_eq(&&row_idx).is_some() {
                    row_idx += LANES;
                    continue;
                }
                trig.extend(joint_trig(&obs.rows[row_idx].q));
                row_idx += 1;
            }
        }
        Self {
            groups: lane_groups,
            trig_lanes: lane_trig,
            distance_m: lane_distance_m,
            trig,
        }
    }
}
