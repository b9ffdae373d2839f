//! Writes the simulated two-arm humanoid recording (`tests/sim/humanoid.rs`) to a folder:
//! `humanoid.urdf` (a CAD mass on every link), `mocap.csv` (550 rows: the 17 joint readings,
//! then a motion-capture marker on each hand, 0.2 mm noise per axis) and `truth.toml` (every
//! simulated parameter by name: geometric deviations, axial and transversal compliance).
//!
//! `--real-like` writes the recording that behaves like real motion capture instead
//! (`sim::real_like`): `real-like.csv` (350 rows, per-axis transversal compliance, link masses
//! 10 % off the URDF's CAD masses, 2 mm noise per axis) and `real-like-truth.toml` (its
//! parameters and the true masses beside the URDF's).
//!
//! `--rows N` writes `mocap.csv` of `N` rows instead (the same seed: its first 550 rows are
//! the recording's), each row written as it is drawn, so a file of millions of rows takes no
//! more memory than one of ten: the long marker files of `cargo xtask bench --scale`.
//!
//! ```sh
//! cargo run --release -p hapcal-calibrate --example sim_humanoid -- fixtures/sim-humanoid
//! cargo run --release -p hapcal-calibrate --example sim_humanoid -- --real-like fixtures/sim-humanoid
//! cargo run --release -p hapcal-calibrate --example sim_humanoid -- --rows 1000000 long-humanoid
//! hapcal calibrate --device fixtures/sim-humanoid/humanoid.urdf --tip l_hand --tip r_hand \
//!     --data fixtures/sim-humanoid/mocap.csv --test-last 0.3
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

#[path = "../tests/sim/humanoid.rs"]
mod sim;

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use hapcal_identify::Problem;

/// Rows of the bundled recording.
const RECORDING_ROWS: usize = 550;

fn main() -> anyhow::Result<()> {
    let mut out = PathBuf::from("fixtures/sim-humanoid");
    let mut n_rows = None;
    let mut real_like = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--rows" {
            let value = args.next().unwrap_or_default();
            n_rows = Some(value.parse().map_err(|_| {
                anyhow::anyhow!("--rows: expected a number of rows, found {value:?}")
            })?);
        } else if arg == "--real-like" {
            real_like = true;
        } else {
            out = PathBuf::from(arg);
        }
    }
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("humanoid.urdf"), sim::humanoid_urdf())?;
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    if real_like {
        let n_rows = n_rows.unwrap_or(sim::REAL_LIKE_ROWS);
        let (truth, masses) = sim::real_like_truth(&robot, sim::REAL_LIKE_SEED);
        let rows = sim::rows_with_noise(
            &robot,
            &truth,
            &[0, 1],
            sim::REAL_LIKE_SEED + 1,
            sim::REAL_LIKE_NOISE_M,
        );
        write_csv(&out.join("real-like.csv"), &robot, rows.take(n_rows))?;
        let mut toml = truth_toml(
            "# The simulated truth of real-like.csv: every parameter of the measurement model by\n\
             # name (m, rad; compliance in rad/(N·m)); instrument and marker frames at their\n\
             # nominal values. Marker noise 2 mm per axis. The gravity loads are those of the\n\
             # masses below (kg, per joint whose child link carries them), each off the URDF's\n\
             # by 10 % (standard deviation).\n",
            &truth,
        )?;
        for (m, cad) in masses.iter().zip(&robot.masses) {
            writeln!(
                toml,
                "\n[[mass]]\njoint = \"{}\"\nkg = {:e}\nurdf_kg = {:e}",
                robot.joint_names[m.joint], m.mass_kg, cad.mass_kg
            )?;
        }
        std::fs::write(out.join("real-like-truth.toml"), toml)?;
    } else {
        let n_rows = n_rows.unwrap_or(RECORDING_ROWS);
        let truth = sim::truth(&robot, 11);
        let rows = sim::rows_with_noise(&robot, &truth, &[0, 1], 12, sim::NOISE_M);
        write_csv(&out.join("mocap.csv"), &robot, rows.take(n_rows))?;
        let toml = truth_toml(
            "# The simulated truth of mocap.csv: every parameter of the measurement model by name\n\
             # (m, rad; compliance in rad/(N·m)); instrument and marker frames at their nominal\n\
             # values. Marker noise 0.2 mm per axis.\n",
            &truth,
        )?;
        std::fs::write(out.join("truth.toml"), toml)?;
    }
    println!("wrote {}", out.display());
    Ok(())
}

/// Writes `rows` to `path` as a marker file: the joint readings, then each hand's marker, one
/// row at a time.
fn write_csv(
    path: &Path,
    robot: &hapcal_calibrate::measured::Robot,
    rows: impl Iterator<Item = hapcal_io::MeasuredRow>,
) -> anyhow::Result<()> {
    let mut csv = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(csv, "{},x1,y1,z1,x2,y2,z2", robot.joint_names.join(","))?;
    let mut line = String::new();
    for row in rows {
        line.clear();
        let values = (row.q.iter()).chain(row.markers.iter().flat_map(|m| &m.position_m));
        for (i, v) in values.enumerate() {
            let comma = if i == 0 { "" } else { "," };
            write!(line, "{comma}{v:.9}")?;
        }
        writeln!(csv, "{line}")?;
    }
    csv.flush()?;
    Ok(())
}

/// `head` then every parameter of `truth` by name.
fn truth_toml(head: &str, truth: &sim::Truth) -> anyhow::Result<String> {
    let mut toml = String::from(head);
    let layout = truth.problem.layout();
    for i in 0..layout.len() {
        writeln!(toml, "\"{}\" = {:e}", layout.name(i), truth.x[i])?;
    }
    Ok(toml)
}
