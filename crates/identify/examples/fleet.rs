//! A fleet of simulated reference devices (docs/design.md §2) measured on one rig: each device has
//! its own 28 identifiable kinematic deviations, the rig's cable encoder a zero offset and a
//! cable-angle error coefficient shared by all. Identifies everything at once (the sparse back
//! end, chosen by `identify` from the Jacobian's structure) and prints one JSON object:
//! sizes, wall time, the shared parameters against their truth in standard deviations, the
//! RMS error of the per-device deviations, and what the dense back end says about the size.
//!
//! ```text
//! fleet [--devices 1000] [--poses 200] [--seed 1]
//! ```
//! Peak memory: run it under `/usr/bin/time -v`.
#![allow(missing_docs, clippy::print_stdout, clippy::unwrap_used)] // a command-line tool

use std::path::PathBuf;
use std::time::Instant;

use hapcal_identify::{Backend, IdentifyConfig, LmConfig, Problem, identify};
use hapcal_problems::{FleetDevice, FleetProblem, cable_angle, fleet_initial_guess};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// The 4 deviations that distance data cannot determine (docs/design.md §2).
const HELD: [&str; 4] = ["dalpha0", "dd0", "dtheta0", "dalpha7"];
/// Truth of the rig: zero offset (m) and cable-angle coefficient (m/rad).
const CABLE_OFFSET_M: f64 = 2.0e-4;
const CABLE_ANGLE_M_PER_RAD: f64 = 1.5e-4;

fn arg(args: &[String], name: &str, default: u64) -> Result<u64> {
    Ok(match args.iter().position(|a| a == name) {
        Some(i) => args.get(i + 1).ok_or("missing value")?.parse()?,
        None => default,
    })
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n_devices = arg(&args, "--devices", 1000)? as usize;
    let n_poses = arg(&args, "--poses", 200)? as usize;
    let seed = arg(&args, "--seed", 1)?;
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let device = hapcal_io::read_device(&root.join("fixtures/reference-device/device.toml"))?;
    let chain = device.chain()?;
    let limits = device.joint_limits();
    let sigma_e = std::f64::consts::TAU / 20000.0 / 3.0;
    let sigma_m = std::f64::consts::TAU * 0.015 * sigma_e;
    let device_params: Vec<usize> = (0..chain.n_params())
        .filter(|&j| !HELD.contains(&chain.params()[j].name.as_str()))
        .collect();

    // Each device: deviations N(0, (1 mm or 1 mrad)²) on the 28, poses uniform in the limits.
    let t0 = Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut truths = Vec::with_capacity(n_devices);
    let mut devices = Vec::with_capacity(n_devices);
    for _ in 0..n_devices {
        let mut x = vec![0.0; chain.n_params()];
        for &j in &device_params {
            let z: f64 = rng.sample(StandardNormal);
            x[j] = 1e-3 * z;
        }
        let frozen = chain.freeze(&x);
        let mut dev = FleetDevice::default();
        for _ in 0..n_poses {
            let start = dev.q_rad.len();
            for &(lo, hi) in &limits {
                let u: f64 = rng.random();
                dev.q_rad.push(lo + (hi - lo) * u);
            }
            let p = frozen.end_point(&dev.q_rad[start..]);
            let (phi, _) = cable_angle(&p);
            let z: f64 = rng.sample(StandardNormal);
            dev.distance_m
                .push(p.coords.norm() + CABLE_OFFSET_M + CABLE_ANGLE_M_PER_RAD * phi + sigma_m * z);
        }
        truths.push(x);
        devices.push(dev);
    }
    let problem = FleetProblem::new(chain, device_params.clone(), devices, sigma_m)?;
    let simulate_s = t0.elapsed().as_secs_f64();
    let m = problem.n_residuals();
    let n = problem.layout().len();

    // The dense back end refuses the size (its Jacobian alone would be m·n·8 bytes).
    let dense = identify(
        &problem,
        fleet_initial_guess(&problem),
        &IdentifyConfig {
            backend: Backend::Dense,
            ..IdentifyConfig::default()
        },
    );
    let dense_message = match dense {
        Ok(_) => "solved".to_owned(),
        Err(e) => e.to_string(),
    };

    let t1 = Instant::now();
    let id = identify(
        &problem,
        fleet_initial_guess(&problem),
        &IdentifyConfig {
            // Started at the nominal, near the solution: the first step is the full
            // Gauss–Newton step (MINPACK's default radius, 100·‖D·x0‖, would take one
            // doubling per iteration to reach it; see `LmConfig::factor`).
            lm: LmConfig {
                factor: f64::INFINITY,
                ..LmConfig::default()
            },
            ..IdentifyConfig::default()
        },
    )?;
    let solve_s = t1.elapsed().as_secs_f64();
    let [ci, ki] = problem.shared();
    let z = |i: usize, truth: f64| {
        let name = problem.layout().name(i);
        let v = id.value(name).unwrap_or(f64::NAN);
        let s = id.std(name).unwrap_or(f64::NAN);
        (v, s, (v - truth) / s)
    };
    let (c, c_std, c_z) = z(ci, CABLE_OFFSET_M);
    let (k, k_std, k_z) = z(ki, CABLE_ANGLE_M_PER_RAD);
    let mut sq = 0.0;
    let mut count = 0;
    for (d, truth) in truths.iter().enumerate() {
        for (a, &j) in device_params.iter().enumerate() {
            sq += (id.fit.x[problem.device_offset(d) + a] - truth[j]).powi(2);
            count += 1;
        }
    }
    println!(
        "{{\"n_devices\": {n_devices}, \"poses_per_device\": {n_poses}, \"n_residuals\": {m}, \"n_params\": {n}, \"dense_jacobian_bytes\": {}, \"dense\": {dense_message:?}, \"simulate_s\": {simulate_s:.3}, \"solve_s\": {solve_s:.3}, \"termination\": \"{:?}\", \"n_evaluations\": {}, \"n_iterations\": {}, \"sigma_m\": {:e}, \"cable_offset\": {{\"truth\": {CABLE_OFFSET_M:e}, \"estimate\": {c:e}, \"std\": {c_std:e}, \"z\": {c_z:.3}}}, \"cable_angle\": {{\"truth\": {CABLE_ANGLE_M_PER_RAD:e}, \"estimate\": {k:e}, \"std\": {k_std:e}, \"z\": {k_z:.3}}}, \"device_deviation_rms_error\": {:e}}}",
        8 * m as u128 * n as u128,
        id.fit.termination,
        id.fit.n_evaluations,
        id.fit.n_iterations,
        id.sigma,
        (sq / count as f64).sqrt(),
    );
    Ok(())
}
