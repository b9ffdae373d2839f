//! The truth file (TOML): what the simulated device really is.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use hapcal_io::Device;
use hapcal_transmission::{CapstanParams, Joint4Transmission};
use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::Error;

/// The "truth" of a simulated device: the nominal device file plus the deviations and
/// transmission errors the simulator applies (the paper's "assigned" values, Tables 2 and 3).
///
/// In the file (see `fixtures/reference-device/truth.toml`):
///
/// ```toml
/// device = "device.toml"      # nominal device file, relative to the truth file
///
/// [deviations]                # kinematic deviations, m or rad, by chain parameter name
/// dalpha0 = 1.5e-3
/// da0 = 1.9e-3
///
/// [[capstan]]                 # one per capstan drive (paper eq. 1)
/// joint = 1
/// c_rad = 0.0
/// re = -0.025
/// r_o_m = 0.2e-3
/// beta_o_rad = -1.832595714594046
/// r_i_m = 0.005e-3
/// beta_i_rad = -0.2617993877991494
///
/// [parallelogram]             # length deviations of the four-bar driving joint 4
/// dl1_m = -0.5e-3
/// dl2_m = -0.7e-3
/// dl3_m = 0.0
/// dl4_m = 0.0
/// phi0_rad = 0.5207963267948965
/// ```
///
/// [`read_truth`] checks the file; a value built by hand (or deserialised directly) is
/// checked against the device when [`simulate`](crate::simulate) uses it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truth {
    /// The nominal device file, relative to the truth file's folder (or absolute); see
    /// [`Truth::device_path`].
    pub device: PathBuf,
    /// Kinematic parameter deviations `(name, value)` in file order, SI units (m for
    /// `da*`, `dd*`; rad for `dalpha*`, `dtheta*`, `dbeta*`). Names are the chain's
    /// ([`hapcal_kinematics::Chain::params`]); parameters not listed are 0.
    #[serde(default, with = "ordered_map")]
    pub deviations: Vec<(String, f64)>,
    /// True capstan parameters, one per capstan drive of the device (`[[capstan]]`).
    #[serde(default, rename = "capstan")]
    pub capstans: Vec<CapstanTruth>,
    /// True parallelogram (`[parallelogram]`), required if the device has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parallelogram: Option<ParallelogramTruth>,
}

/// True parameters of one capstan drive (`[[capstan]]`, paper eq. 1 and Table 2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CapstanTruth {
    /// The driven joint, 1-based.
    pub joint: usize,
    /// Offset `c`, rad.
    pub c_rad: f64,
    /// Ratio error `Re` (dimensionless; the true ratio is `R + Re`).
    pub re: f64,
    /// Output-drum eccentricity radius `r_o`, m (≥ 0; its direction is `beta_o_rad`).
    pub r_o_m: f64,
    /// Output-drum eccentricity phase `beta_o`, rad.
    pub beta_o_rad: f64,
    /// Input-drum (motor) eccentricity radius `r_i`, m (≥ 0; its direction is `beta_i_rad`).
    pub r_i_m: f64,
    /// Input-drum eccentricity phase `beta_i`, rad.
    pub beta_i_rad: f64,
}

impl CapstanTruth {
    /// The values as the transmission model's [`CapstanParams`].
    pub fn params(&self) -> CapstanParams {
        CapstanParams {
            c_rad: self.c_rad,
            re: self.re,
            r_o_m: self.r_o_m,
            beta_o_rad: self.beta_o_rad,
            r_i_m: self.r_i_m,
            beta_i_rad: self.beta_i_rad,
        }
    }
}

/// True parallelogram (`[parallelogram]`, paper eq. 2): deviations of the four link
/// lengths from the device file's nominal `L1..L4` (m), and the crank angle offset.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParallelogramTruth {
    /// Crank length deviation `ΔL1`, m.
    pub dl1_m: f64,
    /// Coupler length deviation `ΔL2`, m.
    pub dl2_m: f64,
    /// Rocker length deviation `ΔL3`, m.
    pub dl3_m: f64,
    /// Ground length deviation `ΔL4`, m.
    pub dl4_m: f64,
    /// Crank angle offset `phi0`, rad, in (0, π), as
    /// [`Joint4Transmission::phi0_rad`](hapcal_transmission::Joint4Transmission): the crank
    /// angle at joint-4 reading 0, measured from the ground link; the four-bar folds flat at
    /// 0 and π.
    pub phi0_rad: f64,
}

impl Truth {
    /// The nominal device file of a truth read from `truth_file`: [`Truth::device`] itself
    /// if absolute, else relative to `truth_file`'s folder.
    pub fn device_path(&self, truth_file: &Path) -> PathBuf {
        if self.device.is_absolute() {
            return self.device.clone();
        }
        (truth_file.parent())
            .unwrap_or_else(|| Path::new(""))
            .join(&self.device)
    }

    /// Reads the nominal device of a truth read from `truth_file` (see
    /// [`Truth::device_path`]).
    ///
    /// # Errors
    ///
    /// [`Error::Device`] if [`hapcal_io::read_device`] fails.
    pub fn read_device(&self, truth_file: &Path) -> Result<Device, Error> {
        hapcal_io::read_device(&self.device_path(truth_file))
            .map_err(|source| Error::Device { source })
    }

    /// The true joint-4 transmission (paper eqs. 1–2): capstan `capstan` with the true
    /// eq.-1 `params`, driving the four-bar of `device`'s nominal link lengths plus this
    /// truth's deviations `ΔL` (m), with its crank offset `phi0_rad`.
    ///
    /// # Errors
    ///
    /// [`Error::Parallelogram`] if the device or this truth has no parallelogram, or if
    /// `phi0_rad` + the joint's limits leave (0, π);
    /// [`Error::Transmission`] for lengths that do not close a four-bar.
    pub fn joint4(
        &self,
        device: &Device,
        capstan: hapcal_transmission::Capstan,
        params: CapstanParams,
    ) -> Result<Joint4Transmission, Error> {
        let joint = crate::PARALLELOGRAM_JOINT;
        let missing = |what: &str| Error::Parallelogram {
            joint,
            message: format!("the {what} has no [parallelogram]"),
        };
        let p = device.parallelogram.ok_or_else(|| missing("device"))?;
        let pt = self.parallelogram.ok_or_else(|| missing("truth"))?;
        // The crank angle φ0 + θ must stay inside (0, π) over the joint's range, where the
        // parallelogram does not fold flat (see `Joint4Transmission`).
        if let Some(limits) = device.joints.get(joint - 1) {
            let (lo, hi) = (
                pt.phi0_rad + limits.lower_rad,
                pt.phi0_rad + limits.upper_rad,
            );
            if !(lo > 0.0 && hi < std::f64::consts::PI) {
                return Err(Error::Parallelogram {
                    joint,
                    message: format!(
                        "the truth's phi0_rad = {} rad puts the crank at {lo:.4}..{hi:.4} rad over joint {joint}'s range [{}, {}] rad, outside (0, π), where the parallelogram folds flat; π/2 − (lo + hi)/2 = {:.4} rad puts it perpendicular mid-range",
                        pt.phi0_rad,
                        limits.lower_rad,
                        limits.upper_rad,
                        Joint4Transmission::phi0_mid_range_rad(limits.lower_rad, limits.upper_rad)
                    ),
                });
            }
        }
        let four_bar = hapcal_transmission::FourBar::try_new(
            p.l1_m + pt.dl1_m,
            p.l2_m + pt.dl2_m,
            p.l3_m + pt.dl3_m,
            p.l4_m + pt.dl4_m,
        )
        .map_err(|source| Error::Transmission { joint, source })?;
        Ok(Joint4Transmission {
            capstan,
            params,
            four_bar,
            phi0_rad: pt.phi0_rad,
        })
    }

    /// The truth of an error-free device: no deviations, every capstan of `device` with
    /// all-zero parameters and, if `device` has a parallelogram, zero length deviations with
    /// the crank perpendicular to the ground link at mid-range of its joint
    /// ([`Joint4Transmission::phi0_mid_range_rad`] of joint
    /// [`PARALLELOGRAM_JOINT`](crate::PARALLELOGRAM_JOINT)'s limits). `device_file` is stored
    /// as [`Truth::device`].
    pub fn nominal(device_file: PathBuf, device: &Device) -> Truth {
        let phi0_rad = (device.joints.get(crate::PARALLELOGRAM_JOINT - 1))
            .map_or(std::f64::consts::FRAC_PI_2, |j| {
                Joint4Transmission::phi0_mid_range_rad(j.lower_rad, j.upper_rad)
            });
        let capstans = (device.capstans.iter())
            .map(|c| CapstanTruth {
                joint: c.joint,
                c_rad: 0.0,
                re: 0.0,
                r_o_m: 0.0,
                beta_o_rad: 0.0,
                r_i_m: 0.0,
                beta_i_rad: 0.0,
            })
            .collect();
        let parallelogram = device.parallelogram.map(|_| ParallelogramTruth {
            dl1_m: 0.0,
            dl2_m: 0.0,
            dl3_m: 0.0,
            dl4_m: 0.0,
            phi0_rad,
        });
        Truth {
            device: device_file,
            deviations: Vec::new(),
            capstans,
            parallelogram,
        }
    }
}

/// Reads and checks a truth file.
///
/// Checks, beyond the TOML syntax and types (unknown keys are errors): every number is
/// finite and within its plausible range (length deviations and the parallelogram's
/// `dl1_m..dl4_m` within ±0.1 m, angle deviations within ±π/4 rad, phases and offsets within
/// ±2π rad, eccentricity radii within [0, 0.01] m, the ratio error within ±1, the crank angle
/// `phi0_rad` within (0, π), where the parallelogram does not fold flat); every `[deviations]`
/// name has the form of a chain parameter (`da`, `dalpha`,
/// `dd`, `dtheta` or `dbeta` followed by a row number); capstan joints are ≥ 1 and unique;
/// the device path is not empty. Whether the names and joints exist on the device is
/// checked by [`simulate`](crate::simulate) and [`truth_deviations`](crate::truth_deviations).
///
/// # Errors
///
/// [`Error::Io`] if the file cannot be read; [`Error::Toml`] for a syntax error, a missing
/// or unknown key or a value of the wrong type; [`Error::InvalidTruth`] for a failed check.
/// Both name the file, line and column.
pub fn read_truth(path: &Path) -> Result<Truth, Error> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_truth(&text, path)
}

/// Parses and checks truth-file text; `path` is only used in messages. See [`read_truth`].
///
/// # Errors
///
/// As [`read_truth`], except [`Error::Io`].
pub fn parse_truth(text: &str, path: &Path) -> Result<Truth, Error> {
    let raw: RawTruth = toml::from_str(text).map_err(|e| {
        let (line, column, message) = hapcal_io::toml_error_at(text, &e);
        Error::Toml {
            path: path.to_path_buf(),
            line,
            column,
            message,
        }
    })?;
    let at = TruthText { text, path };
    if raw.device.get_ref().as_os_str().is_empty() {
        return Err(at.invalid(
            raw.device.span().start,
            "the device path is empty".to_owned(),
        ));
    }
    let deviations = at.deviations(&raw)?;
    let capstans = at.capstans(&raw)?;
    let parallelogram = match &raw.parallelogram {
        None => None,
        Some(p) => Some(ParallelogramTruth {
            dl1_m: at.bounded("dl1_m", &p.dl1_m, LENGTH_DEVIATION_M, "m")?,
            dl2_m: at.bounded("dl2_m", &p.dl2_m, LENGTH_DEVIATION_M, "m")?,
            dl3_m: at.bounded("dl3_m", &p.dl3_m, LENGTH_DEVIATION_M, "m")?,
            dl4_m: at.bounded("dl4_m", &p.dl4_m, LENGTH_DEVIATION_M, "m")?,
            phi0_rad: at.crank_angle(&p.phi0_rad)?,
        }),
    };
    Ok(Truth {
        device: raw.device.into_inner(),
        deviations,
        capstans,
        parallelogram,
    })
}

// Plausible ranges: a truth is a small correction of the nominal device (its lengths are
// tenths of a metre, its deviations millimetres and milliradians), so a value outside these
// is a typo, not a device: `da1 = 1e10` would put the tool 10⁷ km away.
/// Largest length deviation of a truth, m.
const LENGTH_DEVIATION_M: f64 = 0.1;
/// Largest angle deviation of a truth, rad.
const ANGLE_DEVIATION_RAD: f64 = std::f64::consts::FRAC_PI_4;
/// Largest phase, rad.
const PHASE_RAD: f64 = std::f64::consts::TAU;
/// Largest eccentricity radius, m.
const ECCENTRICITY_M: f64 = 0.01;
/// Largest capstan ratio error (relative).
const RATIO_ERROR: f64 = 1.0;

/// A truth file's text and path, for the errors of [`parse_truth`] at a value's line and
/// column.
struct TruthText<'a> {
    /// The file's text.
    text: &'a str,
    /// The file's path, for messages.
    path: &'a Path,
}

impl TruthText<'_> {
    /// An [`Error::InvalidTruth`] at byte `offset` of the text.
    fn invalid(&self, offset: usize, message: String) -> Error {
        let (line, column) = hapcal_io::line_column(self.text, offset);
        Error::InvalidTruth {
            path: self.path.to_path_buf(),
            line,
            column,
            message,
        }
    }

    /// `value` if finite.
    fn finite(&self, name: &str, value: &Spanned<f64>) -> Result<f64, Error> {
        let v = *value.get_ref();
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.invalid(
                value.span().start,
                format!("expected a finite number for {name:?}, found {v}"),
            ))
        }
    }

    /// `value` if finite and within ±`limit` (in `unit`, named in the message).
    fn bounded(
        &self,
        name: &str,
        value: &Spanned<f64>,
        limit: f64,
        unit: &str,
    ) -> Result<f64, Error> {
        let v = self.finite(name, value)?;
        if v.abs() <= limit {
            Ok(v)
        } else {
            let unit = if unit.is_empty() {
                String::new()
            } else {
                format!(" {unit}")
            };
            Err(self.invalid(
                value.span().start,
                format!(
                    "{name} = {v:e}{unit} is outside ±{limit}{unit}: a truth deviates from the \
                     nominal device by a small correction"
                ),
            ))
        }
    }

    /// An eccentricity radius, m: a radius and a phase, so a negative radius is the same
    /// eccentricity with the phase turned by π, a sign slip rather than a device.
    fn radius(&self, name: &str, value: &Spanned<f64>) -> Result<f64, Error> {
        let v = self.bounded(name, value, ECCENTRICITY_M, "m")?;
        if v < 0.0 {
            return Err(self.invalid(
                value.span().start,
                format!(
                    "{name} = {v:e} m is negative: an eccentricity radius lies in [0, {ECCENTRICITY_M}] m (its direction is the phase beta_*_rad)"
                ),
            ));
        }
        Ok(v)
    }

    /// The parallelogram's crank angle, rad: the ideal parallelogram folds flat at crank
    /// angles 0 and π, and outside (0, π) it renders the joint mirrored.
    fn crank_angle(&self, value: &Spanned<f64>) -> Result<f64, Error> {
        let v = self.finite("phi0_rad", value)?;
        if v > 0.0 && v < std::f64::consts::PI {
            return Ok(v);
        }
        Err(self.invalid(
            value.span().start,
            format!(
                "phi0_rad = {v} rad is outside (0, π) = (0, 3.14159…) rad: the crank angle at joint-4 reading 0, where the parallelogram does not fold flat (π/2 − (lo + hi)/2 puts the crank perpendicular mid-range)"
            ),
        ))
    }

    /// The D-H deviations, in the file's order: known parameter names, angles within
    /// ±[`ANGLE_DEVIATION_RAD`], lengths within ±[`LENGTH_DEVIATION_M`].
    fn deviations(&self, raw: &RawTruth) -> Result<Vec<(String, f64)>, Error> {
        let mut entries: Vec<_> = raw.deviations.iter().collect();
        entries.sort_by_key(|(name, _)| name.span().start);
        let mut deviations = Vec::with_capacity(entries.len());
        for (name, value) in entries {
            if !is_param_name(name.get_ref()) {
                return Err(self.invalid(
                    name.span().start,
                    format!(
                        "{:?} is not a parameter name: expected da, dalpha, dd, dtheta or dbeta \
                         followed by a row number, e.g. \"dtheta3\"",
                        name.get_ref()
                    ),
                ));
            }
            let n = name.get_ref();
            let angle = ["dalpha", "dtheta", "dbeta"]
                .iter()
                .any(|p| n.starts_with(p));
            let v = if angle {
                self.bounded(n, value, ANGLE_DEVIATION_RAD, "rad")?
            } else {
                self.bounded(n, value, LENGTH_DEVIATION_M, "m")?
            };
            deviations.push((n.clone(), v));
        }
        Ok(deviations)
    }

    /// The capstans' truths: 1-based joints, one per joint, values within their bounds.
    fn capstans(&self, raw: &RawTruth) -> Result<Vec<CapstanTruth>, Error> {
        let mut capstans: Vec<CapstanTruth> = Vec::with_capacity(raw.capstans.len());
        for c in &raw.capstans {
            let joint = *c.joint.get_ref();
            if joint == 0 {
                return Err(self.invalid(
                    c.joint.span().start,
                    "capstan joint numbers are 1-based; found 0".to_owned(),
                ));
            }
            if capstans.iter().any(|earlier| earlier.joint == joint) {
                return Err(self.invalid(
                    c.joint.span().start,
                    format!("a second [[capstan]] for joint {joint}"),
                ));
            }
            capstans.push(CapstanTruth {
                joint,
                c_rad: self.bounded("c_rad", &c.c_rad, PHASE_RAD, "rad")?,
                re: self.bounded("re", &c.re, RATIO_ERROR, "")?,
                r_o_m: self.radius("r_o_m", &c.r_o_m)?,
                beta_o_rad: self.bounded("beta_o_rad", &c.beta_o_rad, PHASE_RAD, "rad")?,
                r_i_m: self.radius("r_i_m", &c.r_i_m)?,
                beta_i_rad: self.bounded("beta_i_rad", &c.beta_i_rad, PHASE_RAD, "rad")?,
            });
        }
        Ok(capstans)
    }
}

/// Whether `name` has the form of a D-H chain parameter: `da3`, `dalpha0`, `dbeta12`, …
fn is_param_name(name: &str) -> bool {
    ["dalpha", "dtheta", "dbeta", "da", "dd"]
        .iter()
        .any(|prefix| {
            name.strip_prefix(prefix).is_some_and(|digits| {
                !digits.is_empty()
                    && digits.bytes().all(|b| b.is_ascii_digit())
                    && (digits == "0" || !digits.starts_with('0'))
            })
        })
}

/// The file as parsed, with spans for messages.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTruth {
    device: Spanned<PathBuf>,
    #[serde(default)]
    deviations: BTreeMap<Spanned<String>, Spanned<f64>>,
    #[serde(default, rename = "capstan")]
    capstans: Vec<RawCapstan>,
    #[serde(default)]
    parallelogram: Option<RawParallelogram>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCapstan {
    joint: Spanned<usize>,
    c_rad: Spanned<f64>,
    re: Spanned<f64>,
    r_o_m: Spanned<f64>,
    beta_o_rad: Spanned<f64>,
    r_i_m: Spanned<f64>,
    beta_i_rad: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParallelogram {
    dl1_m: Spanned<f64>,
    dl2_m: Spanned<f64>,
    dl3_m: Spanned<f64>,
    dl4_m: Spanned<f64>,
    phi0_rad: Spanned<f64>,
}

/// `Vec<(String, f64)>` as a TOML table, keeping the order of the entries.
mod ordered_map {
    use std::fmt;

    use serde::de::{MapAccess, Visitor};
    use serde::{Deserializer, Serializer};

    pub(super) fn serialize<S: Serializer>(v: &[(String, f64)], s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(v.iter().map(|(k, v)| (k, v)))
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Vec<(String, f64)>, D::Error> {
        struct Entries;
        impl<'de> Visitor<'de> for Entries {
            type Value = Vec<(String, f64)>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a table of parameter names to numbers")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out = Vec::new();
                while let Some(entry) = map.next_entry::<String, f64>()? {
                    out.push(entry);
                }
                Ok(out)
            }
        }
        d.deserialize_map(Entries)
    }
}

#[cfg(test)]
mod tests {
    use super::is_param_name;

    #[test]
    fn parameter_names_have_the_chain_form() {
        for ok in ["da0", "dalpha7", "dd12", "dtheta3", "dbeta2"] {
            assert!(is_param_name(ok), "{ok}");
        }
        for bad in [
            "da", "dalpha", "dtheat3", "d3", "dd01", "da-1", "DA1", "da1x", "",
        ] {
            assert!(!is_param_name(bad), "{bad}");
        }
    }
}
