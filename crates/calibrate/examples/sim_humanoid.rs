//! Writes the simulated two-arm humanoid recording (`tests/sim/humanoid.rs`) to a folder:
//! `humanoid.urdf` (a CAD mass on every link), `mocap.csv` (550 rows: the 17 joint readings,
//! then a motion-capture marker on each hand, 0.2 mm noise per axis) and `truth.toml` (every
//! simulated parameter by name: geometric deviations, axial and transversal compliance).
//!
//! `--rows N` writes `mocap.csv` of `N` rows instead (the same seed: its first 550 rows are
//! the recording's), each row written as it is drawn, so a file of millions of rows takes no
//! more memory than one of ten: the long marker files of `cargo xtask bench --scale`.
//!
//! ```sh
//! cargo run --release -p hapcal-calibrate --example sim_humanoid -- fixtures/sim-humanoid
//! cargo run --release -p hapcal-calibrate --example sim_humanoid -- --rows 1000000 long-humanoid
//! hapcal calibrate --device fixtures/sim-humanoid/humanoid.urdf --tip l_hand --tip r_hand \
//!     --data fixtures/sim-humanoid/mocap.csv --test-last 0.3
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

#[path = "../tests/sim/humanoid.rs"]
mod sim;

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

use hapcal_identify::Problem;

/// Rows of the bundled recording.
const RECORDING_ROWS: usize = 550;

fn main() -> anyhow::Result<()> {
    let mut out = PathBuf::from("fixtures/sim-humanoid");
    let mut n_rows = RECORDING_ROWS;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--rows" {
            let value = args.next().unwrap_or_default();
            n_rows = value.parse().map_err(|_| {
                anyhow::anyhow!("--rows: expected a number of rows, found {value:?}")
            })?;
        } else {
            out = PathBuf::from(arg);
        }
    }
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("humanoid.urdf"), sim::humanoid_urdf())?;
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    let truth = sim::truth(&robot, 11);
    let mut csv = std::io::BufWriter::new(std::fs::File::create(out.join("mocap.csv"))?);
    writeln!(csv, "{},x1,y1,z1,x2,y2,z2", robot.joint_names.join(","))?;
    let mut line = String::new();
    for row in sim::rows_with_noise(&robot, &truth, &[0, 1], 12, sim::NOISE_M).take(n_rows) {
        line.clear();
        let values = (row.q.iter()).chain(row.markers.iter().flat_map(|m| &m.position_m));
        for (i, v) in values.enumerate() {
            let comma = if i == 0 { "" } else { "," };
            write!(line, "{comma}{v:.9}")?;
        }
        writeln!(csv, "{line}")?;
    }
    csv.flush()?;
    let mut toml = String::from(
        "# The simulated truth of mocap.csv: every parameter of the measurement model by name\n\
         # (m, rad; compliance in rad/(N·m)); instrument and marker frames at their nominal\n\
         # values. Marker noise 0.2 mm per axis.\n",
    );
    let layout = truth.problem.layout();
    for i in 0..layout.len() {
        writeln!(toml, "\"{}\" = {:e}", layout.name(i), truth.x[i])?;
    }
    std::fs::write(out.join("truth.toml"), toml)?;
    println!("wrote {}", out.display());
    Ok(())
}
