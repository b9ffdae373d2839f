//! Simulating a case: the drawn truth (geometry and effects) of the arm, its positions file or socket recordings with noise.

use super::*;

/// The truth of one case: geometry and effect, evaluated on configurations.
pub(super) struct Truth<'a> {
    setup: &'a ArmSetup,
    chain: &'a Chain,
    x: Vec<f64>,
    injected: &'a Injected,
}

impl Truth<'_> {
    /// `Δq` at effective angles `q`, with `signs` the sign of each joint's last motion (same
    /// socket or file), rad.
    fn delta_q(&self, q: &[f64], signs: &[f64]) -> Vec<f64> {
        let mut sum = vec![0.0; q.len()];
        for part in self.injected.parts() {
            for (s, d) in sum.iter_mut().zip(self.delta_q_of(part, q, signs)) {
                *s += d;
            }
        }
        sum
    }

    /// `Δq` of one injected effect (not a pair).
    fn delta_q_of(&self, injected: &Injected, q: &[f64], signs: &[f64]) -> Vec<f64> {
        let n = q.len();
        let torques = |model: &GravityCompliance| model.lumped_torques(self.chain, q);
        match injected {
            Injected::GravityCompliance { k } => match &self.setup.gravity {
                Some(m) => (torques(m).iter().zip(k)).map(|(t, k)| k * t).collect(),
                None => vec![0.0; n],
            },
            Injected::LumpedCompliance { k } => (torques(&GravityCompliance::default()).iter())
                .zip(k)
                .map(|(t, k)| k * t)
                .collect(),
            Injected::Harmonic { h, a, b } => (0..n)
                .map(|j| {
                    let hq = f64::from(*h) * q[j];
                    a[j] * hq.sin() + b[j] * hq.cos()
                })
                .collect(),
            Injected::Backlash { b } => (0..n).map(|j| -b[j] * signs[j]).collect(),
            Injected::GearRatio { s } => (0..n).map(|j| s[j] * q[j]).collect(),
            Injected::Coupling { j, k, c } => {
                let mut d = vec![0.0; n];
                d[*j] = c * q[*k];
                d
            }
            _ => vec![0.0; n],
        }
    }

    /// The readings of one group's configurations (a file or a socket, in time order) at
    /// effective angles `q_eff`: `q_read = q_eff − Δq`. Backlash's sign is that of the
    /// readings' own last motion ([`hapcal_diagnose::arm::approach_signs`] on the readings, as the diagnosis sees
    /// them: the motor drives, the output trails by the half-play), so each joint's sign is
    /// chosen to agree with the reading it produces (with the output trailing, one always
    /// does; the previous sign is the fallback).
    fn readings(&self, q_eff: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let play: Vec<f64> = (0..q_eff.first().map_or(0, Vec::len))
            .map(|j| {
                (self.injected.parts().into_iter())
                    .map(|e| match e {
                        Injected::Backlash { b } => -b[j],
                        _ => 0.0,
                    })
                    .sum()
            })
            .collect();
        let mut out: Vec<Vec<f64>> = Vec::with_capacity(q_eff.len());
        let mut signs = vec![0.0; play.len()];
        for (c, q) in q_eff.iter().enumerate() {
            let other = self.delta_q(q, &vec![0.0; q.len()]);
            let read: Vec<f64> = (0..q.len())
                .map(|j| {
                    let base = q[j] - other[j];
                    if c == 0 {
                        return base;
                    }
                    let prev = out[c - 1][j];
                    let agrees = |s: f64| {
                        let d = base - play[j] * s - prev;
                        let seen = if d.abs() >= REPEAT_TOLERANCE {
                            d.signum()
                        } else {
                            signs[j]
                        };
                        seen == s
                    };
                    let s = [signs[j], 1.0, -1.0]
                        .into_iter()
                        .find(|&s| s != 0.0 && agrees(s))
                        .unwrap_or(signs[j]);
                    signs[j] = s;
                    base - play[j] * s
                })
                .collect();
            out.push(read);
        }
        out
    }

    /// True tip in the base frame at effective angles, m.
    fn tip(&self, q: &[f64]) -> Vector3<f64> {
        self.chain.end_point(&self.x, q).coords
    }
}

/// Random geometric deviations of every parameter of `chain`.
pub(super) fn draw_geometry(chain: &Chain, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let (m, r) = (
        Normal::new(0.0, SIGMA_GEOMETRY_M).unwrap_or_else(|_| unreachable!()),
        Normal::new(0.0, SIGMA_GEOMETRY_RAD).unwrap_or_else(|_| unreachable!()),
    );
    (chain.params().iter())
        .map(|p| match p.unit {
            ParamUnit::Meter => m.sample(rng),
            ParamUnit::Radian => r.sample(rng),
        })
        .collect()
}

/// Simulated positions data: the measurement table (all rows; the plan holds out the last
/// [`TEST_FRACTION`]).
pub(super) fn simulate_positions(
    case: &ArmCase,
    setup: &ArmSetup,
    n_rows: usize,
    rng: &mut ChaCha8Rng,
) -> MeasurementTable {
    let chain = &setup.robot.tree.tips()[0];
    let truth = Truth {
        setup,
        chain,
        x: draw_geometry(chain, rng),
        injected: &case.injected,
    };
    let limits = &setup.robot.limits;
    // A random walk within the limits (5 % margins), reflected at them.
    let mut q_eff: Vec<Vec<f64>> = Vec::with_capacity(n_rows);
    let mut q: Vec<f64> = (limits.iter())
        .map(|(lo, hi)| rng.random_range(lo + 0.05 * (hi - lo)..=hi - 0.05 * (hi - lo)))
        .collect();
    for _ in 0..n_rows {
        for (j, (lo, hi)) in limits.iter().enumerate() {
            let (a, b) = (lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo));
            let step: f64 = StandardNormal.sample(rng);
            let mut v = q[j] + 0.25 * (b - a) * step;
            for _ in 0..4 {
                if v < a {
                    v = 2.0 * a - v;
                }
                if v > b {
                    v = 2.0 * b - v;
                }
            }
            q[j] = v.clamp(a, b);
        }
        q_eff.push(q.clone());
    }
    // The instrument: uniformly random rotation, 1–2 m away.
    let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from_vector(
        nalgebra::Vector4::from_fn(|_, _| StandardNormal.sample(rng)),
    ))
    .to_rotation_matrix();
    let dir = Vector3::from(vector(rng, 1.0, 2.0));
    let base_tips: Vec<Vector3<f64>> = q_eff.iter().map(|q| truth.tip(q)).collect();
    let reach = |p: &Vector3<f64>| (p.x * p.x + p.y * p.y).sqrt();
    let reach_max = base_tips.iter().map(reach).fold(1e-3, f64::max);
    let sag_c: f64 = (case.injected.parts().into_iter())
        .map(|e| match e {
            Injected::LinkDeflection { c } => *c,
            _ => 0.0,
        })
        .sum();
    let mut meas: Vec<Vector3<f64>> = (base_tips.iter())
        .map(|p| {
            let sag = -Vector3::z() * (sag_c * (reach(p) / reach_max).powi(3));
            rot * (p + sag) + dir
        })
        .collect();
    let t_span = (n_rows.max(2) - 1) as f64;
    let t_mean = t_span / 2.0;
    apply_point_effects(&case.injected, &mut meas, t_mean, t_span, true);
    let noise = Normal::new(0.0, SIGMA_POSITION_M).unwrap_or_else(|_| unreachable!());
    let readings = truth.readings(&q_eff);
    let rows = (0..n_rows)
        .map(|i| {
            let q_read = readings[i].clone();
            let p = meas[i] + Vector3::from_fn(|_, _| noise.sample(rng));
            MeasuredRow {
                line: i as u64 + 2,
                q: q_read.into(),
                t_s: Some(i as f64),
                markers: vec![MarkerSample {
                    marker: 0,
                    position_m: [p.x, p.y, p.z],
                    rotation: None,
                }],
                distance_m: None,
            }
        })
        .collect();
    MeasurementTable::positions(
        format!("sim-{}", case.seed),
        format!("sim-{}.csv", case.seed),
        1,
        rows,
    )
}

/// Adds the displacements of the measurement-frame effects to `points` (time = index).
pub(crate) fn apply_point_effects(
    injected: &Injected,
    points: &mut [Vector3<f64>],
    t_mean: f64,
    t_span: f64,
    instrument: bool,
) {
    let n = points.len();
    match injected {
        Injected::Pair(a, b) => {
            apply_point_effects(a, points, t_mean, t_span, instrument);
            apply_point_effects(b, points, t_mean, t_span, instrument);
        }
        Injected::ThermalDrift { v } => {
            for (i, p) in points.iter_mut().enumerate() {
                *p += Vector3::from(*v) * ((i as f64 - t_mean) / t_span);
            }
        }
        Injected::QuadraticDrift { v } => {
            for (i, p) in points.iter_mut().enumerate() {
                let u = (i as f64 - t_mean) / t_span;
                *p += Vector3::from(*v) * (4.0 * u * u - 1.0 / 3.0);
            }
        }
        Injected::InstrumentScale { s } if instrument => {
            for p in points.iter_mut() {
                *p *= 1.0 + s;
            }
        }
        Injected::QuadraticInstrument { axis, d } if instrument && n > 0 => {
            let mean = points.iter().map(|p| p[*axis]).sum::<f64>() / n as f64;
            let h = (points.iter())
                .map(|p| (p[*axis] - mean).abs())
                .fold(1e-9, f64::max);
            for p in points.iter_mut() {
                let u = (p[*axis] - mean) / h;
                p[*axis] += d * u * u;
            }
        }
        _ => {}
    }
}

/// Configuration near `q0` whose true tip is `target` (base frame): Newton steps of the
/// minimum-norm inverse kinematics, `Δq = Jᵀ(JJᵀ)⁻¹·e` with a central-difference Jacobian.
pub(super) fn inverse_kinematics(truth: &Truth<'_>, q0: &[f64], target: &Vector3<f64>) -> Vec<f64> {
    let mut q = q0.to_vec();
    let n = q.len();
    for _ in 0..20 {
        let e = target - truth.tip(&q);
        if e.norm() < 1e-13 {
            break;
        }
        let mut jac = DMatrix::zeros(3, n);
        for j in 0..n {
            let h = 1e-7;
            let mut qp = q.clone();
            qp[j] += h;
            let mut qm = q.clone();
            qm[j] -= h;
            let d = (truth.tip(&qp) - truth.tip(&qm)) / (2.0 * h);
            jac.set_column(j, &DVector::from_column_slice(d.as_slice()));
        }
        let jjt: Matrix3<f64> = Matrix3::from_iterator((&jac * jac.transpose()).iter().copied());
        let Some(inv) = jjt.try_inverse() else { break };
        let y = inv * e;
        let dq = jac.transpose() * DVector::from_column_slice(y.as_slice());
        for j in 0..n {
            q[j] += dq[j];
        }
    }
    q
}

/// Simulated sockets data: the training placement and the held-out one.
pub(super) fn simulate_sockets(
    case: &ArmCase,
    setup: &ArmSetup,
    rng: &mut ChaCha8Rng,
) -> (SocketPlacement, SocketPlacement) {
    let chain = &setup.chain;
    let truth = Truth {
        setup,
        chain,
        x: draw_geometry(chain, rng),
        injected: &case.injected,
    };
    let k = setup.placements.len();
    let first = rng.random_range(0..k);
    let second = (first + 1 + rng.random_range(0..k - 1)) % k;
    let noise = Normal::new(0.0, SIGMA_SEATING_M).unwrap_or_else(|_| unreachable!());
    let nominal = vec![0.0; chain.n_params()];
    // Time: row index over both placements; the drift's mean and span are the training's.
    let n_train: usize = (setup.placements[first].sockets.iter())
        .map(|s| s.q.len())
        .sum();
    let t_span = (n_train.max(2) - 1) as f64;
    let t_mean = t_span / 2.0;
    let mut t = 0usize;
    let mut out = Vec::new();
    for &pi in &[first, second] {
        let placement = &setup.placements[pi];
        // Socket points: the mean nominal tip of each socket's recorded configurations, the
        // second moved to lie exactly SOCKET_DISTANCE_M from the first.
        let mut points: Vec<Vector3<f64>> = (placement.sockets.iter())
            .map(|s| {
                s.q.iter()
                    .map(|q| chain.end_point(&nominal, q).coords)
                    .sum::<Vector3<f64>>()
                    / s.q.len().max(1) as f64
            })
            .collect();
        if points.len() >= 2 {
            let d = points[1] - points[0];
            points[1] = points[0] + d.normalize() * SOCKET_DISTANCE_M;
        }
        let mut sockets = Vec::new();
        for (s, point) in placement.sockets.iter().zip(&points) {
            let mut q_eff: Vec<Vec<f64>> = Vec::new();
            for q0 in &s.q {
                let mut shift = [Vector3::zeros()];
                apply_point_effects(&case.injected, &mut shift, t_mean - t as f64, t_span, false);
                // The true tip plus the drift reaches the socket (plus seating noise).
                let target = point - shift[0] + Vector3::from_fn(|_, _| noise.sample(rng));
                q_eff.push(inverse_kinematics(&truth, q0, &target));
                t += 1;
            }
            let q_read = truth.readings(&q_eff);
            sockets.push(SocketSamples {
                file: s.file.clone(),
                q: q_read,
                line_numbers: s.line_numbers.clone(),
            });
        }
        out.push(SocketPlacement {
            name: placement.name.clone(),
            sockets,
            warnings: Vec::new(),
        });
    }
    let test = out.pop().unwrap_or_else(|| unreachable!());
    let train = out.pop().unwrap_or_else(|| unreachable!());
    (train, test)
}
