//! Writes the simulated two-arm humanoid recording (`tests/sim/humanoid.rs`) to a folder:
//! `humanoid.urdf` (a CAD mass on every link), `mocap.csv` (550 rows: the 17 joint readings,
//! then a motion-capture marker on each hand, 0.2 mm noise per axis) and `truth.toml` (every
//! simulated parameter by name: geometric deviations, axial and transversal compliance).
//!
//! ```sh
//! cargo run --release -p hapcal-calibrate --example sim_humanoid -- fixtures/sim-humanoid
//! hapcal calibrate --device fixtures/sim-humanoid/humanoid.urdf --tip l_hand --tip r_hand \
//!     --data fixtures/sim-humanoid/mocap.csv --test-last 0.3
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

#[path = "../tests/sim/humanoid.rs"]
mod sim;

use std::fmt::Write as _;
use std::path::PathBuf;

use hapcal_identify::Problem;

fn main() -> anyhow::Result<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fixtures/sim-humanoid".to_owned()),
    );
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("humanoid.urdf"), sim::humanoid_urdf())?;
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    let truth = sim::truth(&robot, 11);
    let table = sim::table(&robot, &truth, &[0, 1], 550, 12);
    let mut csv = robot.joint_names.join(",");
    csv.push_str(",x1,y1,z1,x2,y2,z2\n");
    for row in &table.rows {
        let q: Vec<String> = row.q.iter().map(|v| format!("{v:.9}")).collect();
        let p: Vec<String> = (row.markers.iter())
            .flat_map(|m| m.position_m.iter().map(|v| format!("{v:.9}")))
            .collect();
        writeln!(csv, "{},{}", q.join(","), p.join(","))?;
    }
    std::fs::write(out.join("mocap.csv"), csv)?;
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
