//! Simulated tracker recordings, the pieces the calibration tests and benchmarks share: the
//! KUKA LBR iiwa 14 of MUKCa, the tracker's and the markers' frames, configurations within the
//! limits, noisy marker samples, their rows and their tables.
#![allow(clippy::unwrap_used, dead_code, unreachable_pub)]

use std::ops::Index;
use std::path::PathBuf;

use hapcal_calibrate::measured::{MeasuredOutcome, Robot, robot_from_urdf};
use hapcal_io::{MarkerSample, MeasuredRow, MeasurementTable};
use hapcal_kinematics::{FrameSpec, Isometry3, Tree, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// MUKCa's URDF of the KUKA LBR iiwa 14.
pub fn iiwa_urdf() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/mukca/urdf/iiwa14.urdf")
}

/// The iiwa 14 with its ball on the last link.
pub fn iiwa() -> Robot {
    robot_from_urdf(&iiwa_urdf(), &["ball_link".to_owned()]).unwrap()
}

/// The tracker's frame `instrument` in the robot's base: at `translation` (m), rotated by
/// `rotation` (axis times angle, rad).
pub fn instrument(translation: [f64; 3], rotation: [f64; 3]) -> FrameSpec {
    FrameSpec {
        name: "instrument".into(),
        nominal: Isometry3::new(Vector3::from(translation), Vector3::from(rotation)),
    }
}

/// Marker frame `name` at (`x`, `y`, `z`) m in its tip's link.
pub fn marker(name: &str, x: f64, y: f64, z: f64) -> FrameSpec {
    FrameSpec {
        name: name.into(),
        nominal: Isometry3::translation(x, y, z),
    }
}

/// A configuration uniform within 80 % of the robot's limits.
pub fn within_limits(robot: &Robot, rng: &mut impl Rng) -> Vec<f64> {
    (robot.limits.iter())
        .map(|(lo, hi)| rng.random_range(0.8 * lo..0.8 * hi))
        .collect()
}

/// A value drawn from N(0, `sigma`) for every parameter of `framed` but the instrument frame's
/// (the first 6) and the markers'.
pub fn deviations(framed: &Tree, sigma: f64, rng: &mut impl Rng) -> Vec<f64> {
    let geometry = Normal::new(0.0, sigma).unwrap();
    (framed.params().iter().enumerate())
        .map(|(i, p)| {
            if i < 6 || p.name.starts_with("marker") {
                0.0
            } else {
                geometry.sample(rng)
            }
        })
        .collect()
}

/// Marker `k` seen at `p` (m) plus `noise` on each axis.
pub fn sample(
    k: usize,
    p: &impl Index<usize, Output = f64>,
    noise: &Normal<f64>,
    rng: &mut impl Rng,
) -> MarkerSample {
    MarkerSample {
        marker: k,
        position_m: std::array::from_fn(|a| p[a] + noise.sample(rng)),
        rotation: None,
    }
}

/// The row read at file line `line`: joint readings `q`, the marker samples `markers`.
pub fn row(line: u64, q: Vec<f64>, markers: Vec<MarkerSample>) -> MeasuredRow {
    MeasuredRow {
        line,
        q: q.into(),
        t_s: None,
        markers,
        distance_m: None,
    }
}

/// Simulated tracker tables of `robot`, one marker per tip (`marker<k+1>` 3 cm along x and
/// 5 cm along z of tip k's link): random geometric deviations (σ 0.5 mm, 0.5 mrad,
/// [`deviations`]), the instrument 2 m away, noise σ 50 µm; `n` training rows and `n / 2`
/// held-out ones at the readings `reading` draws.
pub fn tracker_tables(
    robot: &Robot,
    n: usize,
    seed: u64,
    mut reading: impl FnMut(&mut rand_chacha::ChaCha8Rng) -> Vec<f64>,
) -> (MeasurementTable, MeasurementTable) {
    use rand::SeedableRng;
    let n_tips = robot.tree.tips().len();
    let base = instrument([2.0, 0.3, -0.5], [0.0, 0.0, 2.9]);
    let markers: Vec<(usize, FrameSpec)> = (0..n_tips)
        .map(|k| (k, marker(&format!("marker{}", k + 1), 0.03, 0.0, 0.05)))
        .collect();
    let framed = (robot.tree.with_joint_offsets())
        .with_frames(&base, &markers)
        .unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let x = deviations(&framed, 5e-4, &mut rng);
    let noise = Normal::new(0.0, 5e-5).unwrap();
    let mut table = |rows: usize, name: &str| {
        let rows = (0..rows)
            .map(|i| {
                let q = reading(&mut rng);
                let samples = (0..n_tips)
                    .map(|k| sample(k, &framed.tips()[k].end_point(&x, &q), &noise, &mut rng))
                    .collect();
                row(i as u64 + 2, q, samples)
            })
            .collect();
        MeasurementTable::positions(name, format!("{name}.csv"), n_tips, rows)
    };
    let train = table(n, "train");
    let test = table(n / 2, "test");
    (train, test)
}

/// Placement deviations drawn from N(0, 0.5 mm × `scale`) for every length and N(0, 1 mrad ×
/// `scale`) for every angle of `framed` but the instrument frame's (the first 6) and the
/// markers'.
pub fn placement_deviations(framed: &Tree, scale: f64, rng: &mut impl Rng) -> Vec<f64> {
    let lin = Normal::new(0.0, 5e-4 * scale).unwrap();
    let ang = Normal::new(0.0, 1e-3 * scale).unwrap();
    (framed.params().iter().enumerate())
        .map(|(i, p)| {
            let name = &p.name;
            if i < 6 || name.starts_with("marker") {
                0.0
            } else if name.ends_with(".x") || name.ends_with(".y") || name.ends_with(".z") {
                lin.sample(rng)
            } else {
                ang.sample(rng)
            }
        })
        .collect()
}

/// Asserts that the setup check finds nothing in `table` of `robot` (read from `urdf` with
/// `tips`), and that the closest hypothesis gains less than a suggestive factor.
pub fn assert_no_setup_finding(
    robot: &Robot,
    table: &MeasurementTable,
    urdf: &std::path::Path,
    tips: &[String],
) {
    use hapcal_calibrate::setup::{SUGGESTIVE_FACTOR, SetupInput, check_setup};
    let report = check_setup(&SetupInput {
        robot,
        tables: std::slice::from_ref(table),
        urdf: Some(urdf),
        tips,
        units: hapcal_io::Units::default(),
    })
    .unwrap();
    assert!(report.findings.is_empty(), "{}", report.render());
    let gain = report.closest.as_ref().and_then(|c| c.gain);
    assert!(
        gain.is_some_and(|g| g < SUGGESTIVE_FACTOR),
        "{}",
        report.render()
    );
}

/// The iiwa 14 with joint offsets of `offset_rad` (alternating sign from the first joint),
/// behind a tracker 2 m away, with a marker 5 cm off the ball: the framed tree and its
/// parameter vector.
pub fn offsets_truth(robot: &Robot, offset_rad: f64) -> (Tree, Vec<f64>) {
    let base = instrument([2.0, 0.3, -0.5], [0.1, -0.05, 2.9]);
    let tree = robot.tree.with_joint_offsets();
    let offsets = tree.joint_offset_params();
    let framed = (tree.with_frames(&base, &[(0, marker("marker1", 0.03, -0.02, 0.05))])).unwrap();
    let mut x = vec![0.0; framed.n_params()];
    for (j, p) in offsets.iter().enumerate() {
        x[6 + p.unwrap()] = if j % 2 == 0 { offset_rad } else { -offset_rad };
    }
    (framed, x)
}

/// Asserts the 3-D position RMS of the first test set of `out`, in units of `floor` (the
/// noise's 3-D RMS, m): the calibrated model's below `calibrated_below`, frames only's above
/// `frames_only.0` and below `frames_only.1`.
#[track_caller]
pub fn assert_test_rms(
    out: &MeasuredOutcome,
    floor: f64,
    calibrated_below: f64,
    (above, below): (f64, f64),
) {
    let (_, _, _, frames_only, calibrated) = &out.sets[1];
    let (frames_only, calibrated) = (frames_only.position_rms_m, calibrated.position_rms_m);
    assert!(
        calibrated < calibrated_below * floor,
        "test RMS {calibrated} m, floor {floor} m"
    );
    assert!(
        frames_only > above * floor && frames_only < below * floor,
        "frames only {frames_only} m, floor {floor} m"
    );
}
