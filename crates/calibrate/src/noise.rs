//! Default instrument noise σ per kind of measurement, the scale the *calibrated* residual is
//! judged at when no `--sigma-m` is given (the frames-only residual is judged against what a
//! real robot's manufacturing deviations leave, [`PLAUSIBLE_FRAMES_ONLY_RMS_M`]).
//!
//! A right model leaves the instrument's noise; a calibrated residual more than
//! [`DEFAULT_SIGMA_RATIO`] times the σ of its instrument's class (or
//! [`CALIBRATED_SIGMA_RATIO`] times a stated σ) says the model lacks an
//! effect, or the setup is wrong. The data do not say which instrument measured
//! them (a laser tracker and a motion-capture system both write positions), so each default is
//! the *upper* end of the class that writes that kind of file: a finer instrument's user gives
//! `--sigma-m` (a laser tracker: about 2e-5). Every value is per axis, m.

/// Ratio of the calibrated residual (per axis) to a class's *default* σ above which the
/// report warns: 5, where a σ the user states is held to
/// [`CALIBRATED_SIGMA_RATIO`] (3). A default is the upper end of its class and
/// the instrument a guess, so the warning waits for a residual a right model with a working
/// instrument of that class cannot leave; the bundled recordings sit at 2.6× (TIAGo, motion
/// capture) and 2.5× (Panda panda_2 `high`, sockets) of their defaults.
pub const DEFAULT_SIGMA_RATIO: f64 = 5.0;

/// Frames-only 3-D RMS error beyond which the nominal model cannot be the robot's: joint
/// origin deviations of a fraction of a millimetre and a milliradian, and the elastic
/// deflection of an elastic humanoid's arms under their own weight, give millimetres to a
/// few centimetres; a file in millimetres read as metres, or joint columns in the wrong order,
/// give decimetres to metres.
pub const PLAUSIBLE_FRAMES_ONLY_RMS_M: f64 = 0.05;

/// Ratio of the calibrated model's σ per axis to the stated instrument σ (or the default of
/// its class, [`default_sigma_m`]) above which the report says the model lacks an effect (or the
/// setup is wrong): a right model leaves the noise, within a few per cent for hundreds of
/// residuals, and a default is the upper end of its class.
pub const CALIBRATED_SIGMA_RATIO: f64 = 3.0;

/// Marker positions (motion capture, or any instrument that writes positions only): 1 mm per
/// axis. Optical motion-capture makers state 0.1 to 0.5 mm per marker in a calibrated lab
/// volume (Vicon and Qualisys specifications); markers on a moving robot over a workspace of
/// metres reach about 1 mm. A laser tracker is far finer: ±(15 µm + 6 µm/m) maximum permissible
/// error (Leica AT960 data sheet, to ASME B89.4.19), which `--sigma-m` states.
pub const POSITIONS_SIGMA_M: f64 = 1e-3;

/// Poses from a camera (positions with orientations): 1 mm per axis. A calibrated camera's
/// fiducial-marker pose at about a metre is good to millimetres in depth and a fraction of a
/// millimetre across (AprilTag: E. Olson, "AprilTag: A robust and flexible visual fiducial
/// system", ICRA 2011); the frames-only fit of the setup check weights positions by the same
/// millimetre.
pub const POSES_SIGMA_M: f64 = 1e-3;

/// Distances to an anchor from a draw-wire (string-potentiometer) encoder: 1 mm. Draw-wire
/// sensors are specified at ±0.02 % to ±0.1 % of full scale, 0.2 to 1 mm over a metre of cable.
pub const ANCHOR_DISTANCE_SIGMA_M: f64 = 1e-3;

/// A ball held in a fixed socket (MUKCa socket recordings): 0.25 mm per axis. The robots'
/// stated pose repeatability is ±0.1 to ±0.15 mm (Franka Emika Panda: ±0.1 mm; KUKA LBR iiwa
/// 14 R820: ±0.15 mm; ISO 9283), and the ball is pressed into its socket by hand-guiding the
/// arm (MUKCa: Franzese et al., arXiv:2503.12584), so the contact force deflects the joints of
/// a torque-controlled arm by a further tenth of a millimetre or so. The bundled placements
/// leave 0.05 to 0.63 mm per axis after calibration (docs/results/reliability.md).
pub const SOCKET_SIGMA_M: f64 = 2.5e-4;

/// The default σ (m per axis) and the instrument class in words for data with orientations
/// (`poses`), marker positions (`positions`) or anchor distances only.
pub fn default_sigma_m(poses: bool, positions: bool) -> (f64, &'static str) {
    if poses {
        (POSES_SIGMA_M, "a camera's poses")
    } else if positions {
        (POSITIONS_SIGMA_M, "motion capture")
    } else {
        (ANCHOR_DISTANCE_SIGMA_M, "a draw-wire encoder")
    }
}

/// The warning for a calibrated residual `calibrated_m` (m per axis) of model `rung` more than
/// `ratio` times `sigma_m`, the stated σ or (`default_of` the instrument class) the default;
/// `None` below.
pub fn residual_warning(
    rung: &str,
    calibrated_m: f64,
    sigma_m: f64,
    default_of: Option<&str>,
    ratio: f64,
) -> Option<String> {
    if calibrated_m.is_nan() || calibrated_m <= ratio * sigma_m {
        return None;
    }
    let whose = match default_of {
        Some(class) => format!(
            "the typical σ of {class} ({:.3} mm; --sigma-m states yours)",
            sigma_m * 1e3
        ),
        None => format!("the stated σ of {:.3} mm", sigma_m * 1e3),
    };
    Some(format!(
        "the {rung} model leaves {:.3} mm per axis, {:.1}× {whose}: an effect the model lacks, \
         or a setup mistake",
        calibrated_m * 1e3,
        calibrated_m / sigma_m,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_residual_at_the_noise_passes_and_one_far_above_it_warns() {
        assert!(residual_warning("geometric", 2e-3, 1e-3, Some("motion capture"), 3.0).is_none());
        let w = residual_warning("geometric", 5e-3, 1e-3, Some("motion capture"), 3.0)
            .expect("a warning");
        assert!(
            w.contains("5.0× the typical σ of motion capture (1.000 mm"),
            "{w}"
        );
        let w = residual_warning("geometric", 5e-3, 1e-3, None, 3.0).expect("a warning");
        assert!(w.contains("the stated σ of 1.000 mm"), "{w}");
        assert!(residual_warning("geometric", f64::NAN, 1e-3, None, 3.0).is_none());
    }
}
