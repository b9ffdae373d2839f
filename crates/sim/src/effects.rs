//! Unmodelled effects (docs/design.md §6) and the time-ordered motion that reveals them.
//!
//! [`simulate_motion`] moves the truth device along a smooth multi-sine trajectory
//! (every joint in both directions, several cycles per log), samples it every
//! [`MotionConfig::sample_period_s`], and injects any number of [`Injected`]s on top of the
//! truth transmissions and deviations. Each effect is one of the one vocabulary's
//! ([`Effect`], its name), with parameters given by key (`backlash:j2=1e-3`), a physical model
//! and a source, listed on [`HAPTIC_LIBRARY`] and [`OUTSIDE_LIBRARY`].

use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

use hapcal_contract::Effect;
use hapcal_io::{Device, LogRow, N_EXT};
use hapcal_kinematics::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::{Error, SimConfig, Truth, quantise_readings, true_joint_angles, truth_deviations};

/// Handle mass used when the device file has no `[handle]`, kg (docs/design.md §2: 0.2 kg).
pub const DEFAULT_HANDLE_MASS_KG: f64 = 0.2;

/// The effects of the diagnosis library the simulator injects into a haptic device's log,
/// in docs/design.md §6 order (the one vocabulary, [`Effect`]; docs/design.md §6.1).
/// Parameters (key = value, SI units), with `j<k>` the 1-based joint `k`:
///
/// | name | keys | model |
/// |---|---|---|
/// | `cable_angle` | `k` (m) | `Δd = k·(γ − sin γ)`, γ the cable's angle from the rig z axis |
/// | `gravity_compliance` | `j1..j7` (rad/(N·m)) | `Δθ_j = c_j·τ_j(q)`, τ the handle's gravity torque |
/// | `backlash` | `j1..j7` (rad) | `Δθ_j = −b_j·sgn(θ̇_j)` |
/// | `first_harmonic` | `j<k>`, `phase<k>` (rad) | `Δθ_j = e_j·sin(θ_j + φ_j)` |
/// | `capstan_harmonic` | `j<k>`, `phase<k>` (rad) | `Δθ_j = h_j·sin(2·R_j·θ_j + φ_j)` |
/// | `thermal_drift` | `k` (1/s) | `d = d_true·(1 + k·(t − t_0))` |
/// | `latency` | `tau` (s) | `d(t) = d_true(t + τ)` |
/// | `cable_offset` | `c` (m) | `d = d_true + c` |
///
/// Joint effects change the true joint angle (the external encoders `ext1..ext4`, on the
/// output shafts, see them too); cable effects change only `distance_m`.
///
/// Sources: joint compliance, backlash and gear/drum harmonics as non-geometric errors,
/// Judd & Knasinski, "A technique to calibrate industrial robots with experimental
/// verification", IEEE T-RA 6(1), 1990, and Whitney, Lozinski & Rourke, "Industrial robot
/// forward calibration method and results", ASME JDSMC 108, 1986 (transmission error with
/// harmonics of the gear/drum rotation); encoder eccentricity as a once-per-revolution
/// error, Heidenhain, "Angle encoder accuracy" (eccentricity of the graduation); drum
/// eccentricity and capstan ratio, the paper's eq. 1 (whose first harmonic the baseline
/// models; the second harmonic is the next term of the same Fourier series); cable wrap
/// around the exit eyelet of radius `k` lengthens the path by `k·(γ − sin γ)` (belt-wrap
/// geometry); thermal expansion `ΔL = α·L·ΔT` with a temperature drifting linearly in time;
/// latency, sampling the cable encoder `τ` after the joints.
pub const HAPTIC_LIBRARY: [Effect; 8] = [
    Effect::CableAngle,
    Effect::GravityCompliance,
    Effect::Backlash,
    Effect::FirstHarmonic,
    Effect::CapstanHarmonic,
    Effect::ThermalDrift,
    Effect::Latency,
    Effect::CableOffset,
];

/// The effects outside every library the simulator injects, to test that the diagnosis
/// answers `none` honestly for an effect it does not know:
///
/// | name | keys | model |
/// |---|---|---|
/// | `joint_bump` | `j<k>` (rad), `at<k>` (rad), `width` (rad) | `Δθ_j = A_j·exp(−(θ_j − at_j)²/(2·width²))` |
/// | `cable_drum_runout` | `a` (m), `phase` (rad) | `Δd = a·sin(d/R_d + φ)` |
pub const OUTSIDE_LIBRARY: [Effect; 2] = [Effect::JointBump, Effect::CableDrumRunout];

/// Every effect the simulator injects: [`HAPTIC_LIBRARY`], then [`OUTSIDE_LIBRARY`]; the
/// order of its messages and of the blind test's expected verdicts.
pub fn injectable() -> impl Iterator<Item = Effect> {
    HAPTIC_LIBRARY.into_iter().chain(OUTSIDE_LIBRARY)
}

/// The keys `effect` takes, for messages; `None` for an effect the simulator does not inject.
fn keys_help(effect: Effect) -> Option<&'static str> {
    Some(match effect {
        Effect::CableAngle | Effect::ThermalDrift => "k",
        Effect::Latency => "tau",
        Effect::CableOffset => "c",
        Effect::GravityCompliance | Effect::Backlash => "j1, j2, …",
        Effect::FirstHarmonic | Effect::CapstanHarmonic => "j1, j2, …, phase1, phase2, …",
        Effect::JointBump => "j1, …, at1, …, width",
        Effect::CableDrumRunout => "a, phase",
        _ => return None,
    })
}

/// Whether a parameter key is valid for `effect` (one the simulator injects).
fn accepts(effect: Effect, key: &str) -> bool {
    let joint_key = |prefix: &str| {
        key.strip_prefix(prefix)
            .and_then(|d| d.parse::<usize>().ok())
            .is_some_and(|j| (1..=64).contains(&j))
    };
    match effect {
        Effect::CableAngle | Effect::ThermalDrift => key == "k",
        Effect::Latency => key == "tau",
        Effect::CableOffset => key == "c",
        Effect::GravityCompliance | Effect::Backlash => joint_key("j"),
        Effect::FirstHarmonic | Effect::CapstanHarmonic => joint_key("j") || joint_key("phase"),
        Effect::JointBump => joint_key("j") || joint_key("at") || key == "width",
        Effect::CableDrumRunout => key == "a" || key == "phase",
        _ => false,
    }
}

/// The values a parameter of `effect` may take: phases and bump positions within ±2π rad, a
/// bump width within [10⁻⁶, 2π] rad, a latency within [0, 1] s, a backlash half-width within
/// [0, 0.1] rad, every other amplitude or coefficient within ±1 (in its SI unit: rad, m,
/// m/rad, rad/(N·m), m/s). Wider values are not a perturbation of a haptic device: a
/// `cable_angle:k=1e300` writes distances of 1e299 m.
fn range(effect: Effect, key: &str) -> (f64, f64) {
    match effect {
        _ if key.starts_with("phase") || key.starts_with("at") => (-TAU, TAU),
        Effect::JointBump if key == "width" => (1e-6, TAU),
        Effect::Latency => (0.0, 1.0),
        Effect::Backlash => (0.0, 0.1),
        _ => (-1.0, 1.0),
    }
}

/// The refusal of an effect named `name` the simulator does not inject.
fn not_injectable(name: &str) -> Error {
    Error::Effect {
        spec: name.to_owned(),
        message: format!(
            "unknown effect; expected one of {}",
            injectable()
                .map(Effect::name)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// One injected effect and its parameters by key (SI units, see [`HAPTIC_LIBRARY`] and
/// [`OUTSIDE_LIBRARY`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Injected {
    /// Which effect: one of [`injectable`].
    pub effect: Effect,
    /// `(key, value)` pairs; keys not given are 0 (`width` defaults to 0.1 rad).
    pub params: Vec<(String, f64)>,
}

impl Injected {
    /// An effect with checked parameters.
    ///
    /// # Errors
    /// [`Error::Effect`] for an effect the simulator does not inject ([`injectable`]), a key
    /// the effect does not accept, a repeated key or a non-finite value.
    pub fn try_new(effect: Effect, params: Vec<(String, f64)>) -> Result<Injected, Error> {
        let keys = keys_help(effect).ok_or_else(|| not_injectable(effect.name()))?;
        let bad = |message: String| Error::Effect {
            spec: effect.name().to_owned(),
            message,
        };
        for (i, (key, value)) in params.iter().enumerate() {
            if !accepts(effect, key) {
                return Err(bad(format!("unknown parameter {key:?}; expected {keys}")));
            }
            if !value.is_finite() {
                return Err(bad(format!("{key} = {value} is not finite")));
            }
            if params[..i].iter().any(|(k, _)| k == key) {
                return Err(bad(format!("{key} is given twice")));
            }
            let (lo, hi) = range(effect, key);
            if !(lo..=hi).contains(value) {
                return Err(bad(format!(
                    "{key} = {value:e} is outside [{lo}, {hi}]: an unmodelled effect is a small \
                     perturbation of the device (rad, m, s, or per rad, per N·m)"
                )));
            }
        }
        Ok(Injected { effect, params })
    }

    /// The value of `key`, or 0 when it is not given.
    pub fn get(&self, key: &str) -> f64 {
        self.get_or(key, 0.0)
    }

    fn get_or(&self, key: &str, default: f64) -> f64 {
        (self.params.iter())
            .find(|(k, _)| k == key)
            .map_or(default, |(_, v)| *v)
    }

    /// The per-joint value `<prefix><joint_idx+1>` (0 when absent).
    pub fn joint(&self, prefix: &str, joint_idx: usize) -> f64 {
        self.get(&format!("{prefix}{}", joint_idx + 1))
    }
}

impl fmt::Display for Injected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.effect.name())?;
        for (i, (k, v)) in self.params.iter().enumerate() {
            write!(f, "{}{k}={v:e}", if i == 0 { ':' } else { ',' })?;
        }
        Ok(())
    }
}

impl FromStr for Injected {
    type Err = Error;
    /// Parses `name[:key=value,key=value…]`, e.g. `backlash:j2=1e-3,j3=5e-4`.
    ///
    /// # Errors
    /// [`Error::Effect`] for an unknown name or key, a malformed pair or a non-finite value.
    fn from_str(s: &str) -> Result<Injected, Error> {
        let (name, rest) = s.split_once(':').unwrap_or((s, ""));
        let name = name.trim();
        let effect = injectable()
            .find(|e| e.name() == name)
            .ok_or_else(|| not_injectable(name))?;
        let mut params = Vec::new();
        for pair in rest.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let bad = |message: String| Error::Effect {
                spec: s.to_owned(),
                message,
            };
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| bad(format!("expected key=value, found {pair:?}")))?;
            let value: f64 = value
                .trim()
                .parse()
                .map_err(|_| bad(format!("expected a number for {key}, found {value:?}")))?;
            params.push((key.trim().to_owned(), value));
        }
        Injected::try_new(effect, params)
    }
}

/// The time-ordered motion of [`simulate_motion`].
///
/// Each joint follows `θ_j(t) = mid_j + h_j·(0.6·sin(ω_1j·t + φ_1j) + 0.3·sin(ω_2j·t + φ_2j))`
/// with `h_j` the half-range of its limits, `ω_1j` giving 5–10 cycles and `ω_2j` 11–19 cycles
/// over the log (drawn from the seed): smooth, within 90 % of the range, both directions,
/// peak speeds of about 1 rad/s at the default period, and every fifth of the log (a
/// cross-validation block) covers each joint's range at least once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionConfig {
    /// Time between samples, s (> 0).
    pub sample_period_s: f64,
}

impl Default for MotionConfig {
    /// 0.5 s between samples (a 200-sample log lasts 100 s), chosen so that joints reach a
    /// few tenths of rad/s: a 5 ms latency then moves the tip by tens of µm.
    fn default() -> MotionConfig {
        MotionConfig {
            sample_period_s: 0.5,
        }
    }
}

/// One joint's trajectory: two sines around the mid-range.
#[derive(Clone, Copy, Debug)]
struct JointPath {
    mid: f64,
    half: f64,
    w: [f64; 2],
    phi: [f64; 2],
}

impl JointPath {
    fn angle(&self, t: f64) -> f64 {
        self.mid
            + self.half
                * (0.6 * (self.w[0] * t + self.phi[0]).sin()
                    + 0.3 * (self.w[1] * t + self.phi[1]).sin())
    }
    fn rate(&self, t: f64) -> f64 {
        self.half
            * (0.6 * self.w[0] * (self.w[0] * t + self.phi[0]).cos()
                + 0.3 * self.w[1] * (self.w[1] * t + self.phi[1]).cos())
    }
}

/// Checks the effects against the device: joints exist, capstan harmonics on capstan joints.
fn check_effects(device: &Device, effects: &[Injected]) -> Result<(), Error> {
    let n = device.n_joints();
    for e in effects {
        for (key, _) in &e.params {
            let digits: String = key.chars().filter(char::is_ascii_digit).collect();
            let Ok(j) = digits.parse::<usize>() else {
                continue;
            };
            let bad = |message: String| Error::Effect {
                spec: e.to_string(),
                message,
            };
            if j == 0 || j > n {
                return Err(bad(format!("{key}: the device has joints 1..{n}")));
            }
            if e.effect == Effect::CapstanHarmonic && !device.capstans.iter().any(|c| c.joint == j)
            {
                return Err(bad(format!("{key}: joint {j} has no capstan")));
            }
        }
    }
    Ok(())
}

/// The noise and the motion of [`simulate_motion`] checked: finite σ ≥ 0, a sample period
/// > 0.
///
/// # Errors
/// [`Error::InvalidNoise`], [`Error::Effect`] for the motion.
fn check_motion(cfg: &SimConfig, motion: &MotionConfig) -> Result<(), Error> {
    let noise = cfg.noise;
    for (name, value) in [
        ("sigma_e_rad", noise.sigma_e_rad),
        ("sigma_m_m", noise.sigma_m_m),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(Error::InvalidNoise { name, value });
        }
    }
    if !(motion.sample_period_s.is_finite() && motion.sample_period_s > 0.0) {
        return Err(Error::Effect {
            spec: "motion".to_owned(),
            message: format!("sample period {} s must be > 0", motion.sample_period_s),
        });
    }
    Ok(())
}

/// Each joint's path over `duration_s` within its `limits` (rad or m): two sines of 5–10 and
/// 11–19 periods over the log, at random phases, drawn from `rng` joint after joint.
fn joint_paths(limits: &[(f64, f64)], rng: &mut ChaCha8Rng, duration_s: f64) -> Vec<JointPath> {
    (limits.iter())
        .map(|&(lo, hi)| {
            let c1: f64 = 5.0 + 5.0 * rng.random::<f64>();
            let c2: f64 = 11.0 + 8.0 * rng.random::<f64>();
            JointPath {
                mid: 0.5 * (lo + hi),
                half: 0.5 * (hi - lo),
                w: [TAU * c1 / duration_s, TAU * c2 / duration_s],
                phi: [TAU * rng.random::<f64>(), TAU * rng.random::<f64>()],
            }
        })
        .collect()
}

/// The cable distance, m, to the end point `p` (m, base frame) at time `t_s`, with the cable
/// effects of `effects` (cable angle, thermal drift, offset, drum runout) added to `|p|`;
/// `drum_radius_m` the cable encoder's drum.
fn cable_distance_m(effects: &[Injected], p: &Vector3<f64>, t: f64, drum_radius_m: f64) -> f64 {
    let d_true = p.norm();
    let mut d = d_true;
    for e in effects {
        d += match e.effect {
            Effect::CableAngle => {
                let (g, _) = hapcal_problems::cable_angle(&Point3::from(*p));
                e.get("k") * (g - g.sin())
            }
            Effect::ThermalDrift => d_true * e.get("k") * t,
            Effect::CableOffset => e.get("c"),
            Effect::CableDrumRunout => e.get("a") * (d_true / drum_radius_m + e.get("phase")).sin(),
            _ => 0.0,
        };
    }
    d
}

/// Simulates a time-ordered log of the truth device with unmodelled `effects`.
///
/// Motion: [`MotionConfig`] (`cfg.n_poses` samples, `t_s = k·sample_period_s`). Per sample,
/// the continuous motor-side joint angle θ(t) is read through the encoders (quantised to
/// their resolution if `cfg.quantise_joints`, [`quantise_readings`]: the quantisation error
/// is real here, unlike [`crate::simulate`], where the truth starts from the reading); the
/// truth transmissions map θ to joint angles ([`true_joint_angles`]); the joint effects are
/// added; `ext1..ext4 = joint angle + N(0, σ_e)` on joints with a transmission; the cable
/// distance is `|P|` of the truth chain, modified by the cable effects, `+ N(0, σ_m)`.
/// Effects of the same kind add. Equal inputs give equal logs.
///
/// # Errors
/// [`Error::InvalidNoise`], [`Error::Effect`] (a joint the device does not have, a capstan
/// harmonic on a joint without capstan, a period ≤ 0), and the errors of [`crate::simulate`].
pub fn simulate_motion(
    device: &Device,
    truth: &Truth,
    cfg: &SimConfig,
    motion: &MotionConfig,
    effects: &[Injected],
) -> Result<Vec<LogRow>, Error> {
    let noise = cfg.noise;
    check_motion(cfg, motion)?;
    check_effects(device, effects)?;
    let chain = device.chain().map_err(|source| Error::Device { source })?;
    let x = truth_deviations(&chain, truth)?;
    let n_joints = device.n_joints();
    let limits = device.joint_limits();
    let ratios: Vec<f64> = (0..n_joints)
        .map(|j| {
            (device.capstans.iter())
                .find(|c| c.joint == j + 1)
                .map_or(1.0, |c| c.ratio)
        })
        .collect();
    let has_ext: Vec<bool> = (0..N_EXT)
        .map(|k| device.capstans.iter().any(|c| c.joint == k + 1))
        .collect();
    let mass_kg = device.handle.map_or(DEFAULT_HANDLE_MASS_KG, |h| h.mass_kg);
    let drum_radius_m = (device.cable_encoder)
        .unwrap_or(crate::REFERENCE_CABLE_ENCODER)
        .drum_radius_m;

    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let duration_s = motion.sample_period_s * cfg.n_poses.max(1) as f64;
    let paths = joint_paths(&limits, &mut rng, duration_s);

    // True joint angles at time t: truth transmissions of θ(t), then the joint effects.
    let joint_angles = |t: f64| -> Result<Vec<f64>, Error> {
        let theta: Vec<f64> = paths.iter().map(|p| p.angle(t)).collect();
        let rate: Vec<f64> = paths.iter().map(|p| p.rate(t)).collect();
        let mut q = true_joint_angles(device, truth, &theta)?;
        let torques = if effects
            .iter()
            .any(|e| e.effect == Effect::GravityCompliance)
        {
            hapcal_problems::handle_gravity_torques_nm(&chain, &x, &q, mass_kg).map_err(|e| {
                Error::Effect {
                    spec: "joint_compliance".to_owned(),
                    message: e.to_string(),
                }
            })?
        } else {
            vec![0.0; n_joints]
        };
        let mut dq = vec![0.0; n_joints];
        for e in effects {
            for j in 0..n_joints {
                let th = theta[j];
                dq[j] += match e.effect {
                    Effect::GravityCompliance => e.joint("j", j) * torques[j],
                    Effect::Backlash => -e.joint("j", j) * rate[j].signum(),
                    Effect::FirstHarmonic => e.joint("j", j) * (th + e.joint("phase", j)).sin(),
                    Effect::CapstanHarmonic => {
                        e.joint("j", j) * (2.0 * ratios[j] * th + e.joint("phase", j)).sin()
                    }
                    Effect::JointBump => {
                        let w = e.get_or("width", 0.1).abs().max(1e-6);
                        let u = (th - e.joint("at", j)) / w;
                        e.joint("j", j) * (-0.5 * u * u).exp()
                    }
                    _ => 0.0,
                };
            }
        }
        for (qj, d) in q.iter_mut().zip(&dq) {
            *qj += d;
        }
        Ok(q)
    };

    let latency_s: f64 = (effects.iter())
        .filter(|e| e.effect == Effect::Latency)
        .map(|e| e.get("tau"))
        .sum();
    let mut rows = Vec::with_capacity(cfg.n_poses);
    for k in 0..cfg.n_poses {
        let t = k as f64 * motion.sample_period_s;
        let theta: Vec<f64> = paths.iter().map(|p| p.angle(t)).collect();
        let reading = if cfg.quantise_joints {
            quantise_readings(device, &theta)
        } else {
            theta
        };
        let q_true = joint_angles(t)?;
        let q_cable = if latency_s != 0.0 {
            joint_angles(t + latency_s)?
        } else {
            q_true.clone()
        };
        let p = chain.end_point(&x, &q_cable).coords;
        let d = cable_distance_m(effects, &p, t, drum_radius_m);
        let z_m: f64 = rng.sample(StandardNormal);
        let distance_m = d + noise.sigma_m_m * z_m;
        let ext = (0..N_EXT)
            .map(|k| {
                let z_e: f64 = rng.sample(StandardNormal);
                let angle = q_true.get(k).filter(|_| has_ext[k])?;
                Some(angle + noise.sigma_e_rad * z_e)
            })
            .collect();
        rows.push(LogRow {
            q: reading,
            distance_m,
            ext,
            t_s: Some(t),
            line: k as u64 + 2,
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_injectable_effect_parses_by_its_name_and_no_other_effect_does() {
        for effect in Effect::ALL {
            let parsed = effect.name().parse::<Injected>().map(|i| i.effect);
            assert_eq!(parsed.ok(), injectable().find(|&e| e == effect), "{effect}");
        }
        assert_eq!(injectable().count(), 10);
        let refused = Injected::try_new(Effect::GearRatio, Vec::new()).expect_err("not injected");
        assert!(refused.to_string().contains("unknown effect"), "{refused}");
    }

    #[test]
    fn effect_specs_parse_and_reject_bad_input() {
        let e: Injected = "backlash:j2=1e-3,j3=5e-4".parse().expect("valid");
        assert_eq!(e.effect, Effect::Backlash);
        assert_eq!(e.joint("j", 1), 1e-3);
        assert_eq!(e.get("j1"), 0.0);
        let round: Injected = e.to_string().parse().expect("round trip");
        assert_eq!(round, e);
        for (spec, refusal) in [
            ("backlash:k=1", "unknown parameter \"k\""),
            ("wobble:k=1", "unknown effect"),
            ("latency:tau=x", "expected a number"),
            ("latency:tau=1,tau=2", "twice"),
        ] {
            let err = spec.parse::<Injected>().expect_err(spec);
            assert!(err.to_string().contains(refusal), "{spec}: {err}");
        }
        assert!("cable_offset".parse::<Injected>().is_ok());
    }
}
