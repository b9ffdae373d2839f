//! Accuracy metrics: RMS, the paper's improvement percentages (eqs. 8 and 9), pose errors between
//! two models, and the MUKCa figures of merit.
//!
//! Architecture invariant: *`metrics` compares numbers; it never fits or reads files.*
//!
//! ```
//! use hapcal_metrics::{rms, accuracy_improvement_pct};
//! let before = rms(&[3.0e-3, -4.0e-3]);            // m
//! let after = rms(&[3.0e-5, -4.0e-5]);
//! assert!((accuracy_improvement_pct(after, before).unwrap() - 99.0).abs() < 1e-9);
//! ```

use nalgebra::{Isometry3, Point3};

/// Errors of the metrics: only degenerate inputs, where a percentage is undefined.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Eq. 8 divides by `|l_a − l_n|`: undefined when the assigned deviation is zero.
    #[error("parameter improvement is undefined: assigned value equals nominal ({nominal})")]
    ZeroAssignedDeviation {
        /// The nominal (= assigned) value.
        nominal: f64,
    },
    /// Eq. 9 divides by the uncalibrated RMS.
    #[error("accuracy improvement is undefined: the uncalibrated RMS is zero")]
    ZeroBaseline,
    /// A socket with no sample has no mean.
    #[error("socket {socket} has no sample")]
    EmptySocket {
        /// Index of the empty socket.
        socket: usize,
    },
}

/// Root mean square of `values` (same unit as the values); 0 for an empty slice.
pub fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// Parameter improvement in % (paper eq. 8): `(1 − |l_a − l_o| / |l_a − l_n|)·100`.
///
/// `assigned` (l_a) is the true value given to the simulated device, `identified` (l_o) the
/// calibrated value and `nominal` (l_n) the design value, all in the parameter's unit (m or rad).
/// 100 % means the identification recovered the assigned value exactly; 0 % means no better than
/// the nominal; negative means worse.
///
/// # Errors
/// [`Error::ZeroAssignedDeviation`] when `assigned == nominal`.
pub fn parameter_improvement_pct(
    assigned: f64,
    identified: f64,
    nominal: f64,
) -> Result<f64, Error> {
    let denom = (assigned - nominal).abs();
    if denom == 0.0 {
        return Err(Error::ZeroAssignedDeviation { nominal });
    }
    Ok((1.0 - (assigned - identified).abs() / denom) * 100.0)
}

/// Accuracy improvement in % (paper eq. 9): `|RMS(e_c) − RMS(e_nc)| / |RMS(e_nc)|·100`.
///
/// `rms_calibrated` and `rms_uncalibrated` in the same unit (m or rad). Note that eq. 9 takes the
/// absolute value of the difference, so it is positive even when calibration made things worse;
/// callers that need the sign should compare the two RMS values themselves.
///
/// # Errors
/// [`Error::ZeroBaseline`] when `rms_uncalibrated == 0`.
pub fn accuracy_improvement_pct(rms_calibrated: f64, rms_uncalibrated: f64) -> Result<f64, Error> {
    if rms_uncalibrated == 0.0 {
        return Err(Error::ZeroBaseline);
    }
    Ok((rms_calibrated - rms_uncalibrated).abs() / rms_uncalibrated.abs() * 100.0)
}

/// Position and orientation error between two poses of the same frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseError {
    /// Euclidean distance between the two origins, m.
    pub position_m: f64,
    /// Angle of the relative rotation `R_aᵀ·R_b`, rad, in [0, π].
    pub orientation_rad: f64,
}

/// Pose error between `truth` and `model` (both base_T_frame), docs/design.md §3 "Metrics".
pub fn pose_error(truth: &Isometry3<f64>, model: &Isometry3<f64>) -> PoseError {
    let rel = truth.rotation.inverse() * model.rotation;
    PoseError {
        position_m: (truth.translation.vector - model.translation.vector).norm(),
        orientation_rad: rel.angle(),
    }
}

/// MUKCa figures of merit of one tool placement (MUKCa README, "Their figures of merit").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SocketFigures {
    /// Mean over all rows of both sockets of the distance from each ball position to its socket
    /// mean, m (their "consistency").
    pub mean_absolute_error_m: f64,
    /// `| |mean_0 − mean_1| − nominal distance |`, m (their "distortion"); `None` unless the
    /// placement has exactly two sockets.
    pub distance_error_m: Option<f64>,
    /// Number of rows over all sockets.
    pub n_rows: usize,
}

/// Computes the MUKCa figures of one placement from the forward-kinematics ball positions of each
/// socket (`sockets[s][row]`, m) and the nominal socket distance (0.05 m for MUKCa's tool).
///
/// The mean absolute error weights each socket by its row count (a plain mean over all rows).
///
/// # Errors
/// [`Error::EmptySocket`] when a socket has no row.
pub fn socket_figures(
    sockets: &[Vec<Point3<f64>>],
    nominal_distance_m: f64,
) -> Result<SocketFigures, Error> {
    let mut means = Vec::with_capacity(sockets.len());
    let mut sum = 0.0;
    let mut n_rows = 0;
    for (socket, points) in sockets.iter().enumerate() {
        if points.is_empty() {
            return Err(Error::EmptySocket { socket });
        }
        let mean = points
            .iter()
            .fold(nalgebra::Vector3::zeros(), |acc, p| acc + p.coords)
            / points.len() as f64;
        sum += points.iter().map(|p| (p.coords - mean).norm()).sum::<f64>();
        n_rows += points.len();
        means.push(mean);
    }
    let distance_error_m = match means.as_slice() {
        [a, b] => Some(((a - b).norm() - nominal_distance_m).abs()),
        _ => None,
    };
    Ok(SocketFigures {
        mean_absolute_error_m: if n_rows == 0 {
            0.0
        } else {
            sum / n_rows as f64
        },
        distance_error_m,
        n_rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn rms_of_known_values() {
        assert!((rms(&[3.0, 4.0]) - (12.5f64).sqrt()).abs() < 1e-15);
        assert_eq!(rms(&[]), 0.0);
    }

    #[test]
    fn eq8_is_100_for_exact_and_0_for_nominal() {
        assert!((parameter_improvement_pct(0.01, 0.01, 0.0).unwrap() - 100.0).abs() < 1e-12);
        assert!(parameter_improvement_pct(0.01, 0.0, 0.0).unwrap().abs() < 1e-12);
        assert!((parameter_improvement_pct(0.01, 0.0099, 0.0).unwrap() - 99.0).abs() < 1e-9);
        assert_eq!(
            parameter_improvement_pct(0.2, 0.3, 0.2),
            Err(Error::ZeroAssignedDeviation { nominal: 0.2 })
        );
    }

    #[test]
    fn eq9_matches_hand_value() {
        assert!((accuracy_improvement_pct(0.25, 1.0).unwrap() - 75.0).abs() < 1e-12);
        assert_eq!(accuracy_improvement_pct(0.1, 0.0), Err(Error::ZeroBaseline));
        assert_eq!(
            Error::ZeroBaseline.to_string(),
            "accuracy improvement is undefined: the uncalibrated RMS is zero"
        );
    }

    #[test]
    fn pose_error_of_known_offset() {
        let a = Isometry3::identity();
        let b = Isometry3::from_parts(
            Translation3::new(0.003, 0.004, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.02),
        );
        let e = pose_error(&a, &b);
        assert!((e.position_m - 0.005).abs() < 1e-15);
        assert!((e.orientation_rad - 0.02).abs() < 1e-12);
    }

    #[test]
    fn socket_figures_by_hand() {
        // Socket 0: two points 2 mm apart (each 1 mm from the mean); socket 1: one point.
        let s0 = vec![Point3::new(0.0, 0.0, 0.001), Point3::new(0.0, 0.0, -0.001)];
        let s1 = vec![Point3::new(0.051, 0.0, 0.0)];
        let f = socket_figures(&[s0, s1], 0.05).unwrap();
        assert!((f.mean_absolute_error_m - 2.0e-3 / 3.0).abs() < 1e-15);
        assert!((f.distance_error_m.unwrap() - 0.001).abs() < 1e-12);
        assert_eq!(f.n_rows, 3);
        assert_eq!(
            socket_figures(&[vec![]], 0.05),
            Err(Error::EmptySocket { socket: 0 })
        );
    }
}
