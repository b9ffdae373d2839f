//! Calibration workflows: load a device (URDF, D-H or modified D-H table, the haptic device's
//! TOML) and its measurements, choose the model the data support, identify it, report and
//! write the result back. The `hapcal` command line is argument parsing and rendering on top
//! of this crate; a Rust program calibrates through it alone.
//!
//! Architecture invariant: *`calibrate` never prints and never needs a truth: everything it
//! does, a user with a real device and real measurements can do.*

pub mod baseline;
pub mod calibrate;
pub mod compensate;
pub mod data;
pub mod fit;
pub mod haptic;
pub mod inputs;
pub mod measured;
pub mod model;
pub mod noise;
pub mod plan;
pub mod predict;
pub mod record;
pub mod report;
pub mod robust;
pub mod setup;
pub mod setup_change;
pub mod setup_families;
pub mod setup_findings;
pub mod setup_haptic;
pub mod setup_sockets;
mod solve;
pub mod support;

use std::path::{Path, PathBuf};

/// The folder that holds `fixtures/` (the bundled data: MUKCa, the reference device, the
/// paper's tables), found in this order:
///
/// 1. `$HAPCAL_DATA`, if it holds `fixtures/`;
/// 2. the current folder or one of its parents (a clone of the repository), as a relative path
///    (`""`, `".."`, …), so that reports and written files carry no absolute path;
/// 3. the folder of the running executable or one of its parents (an install that copied
///    `fixtures/` beside the binary);
/// 4. the source tree the binary was built from (a `cargo run` from elsewhere).
///
/// Never fails: when none holds the data, it returns the source tree's path and the caller's
/// read fails with that path in its message.
pub fn project_root() -> PathBuf {
    let has_data = |d: &Path| d.join("fixtures").join("mukca").is_dir();
    if let Some(dir) = std::env::var_os("HAPCAL_DATA").map(PathBuf::from)
        && has_data(&dir)
    {
        return dir;
    }
    if let Ok(cwd) = std::env::current_dir()
        && let Some(up) = cwd.ancestors().position(has_data)
    {
        return std::iter::repeat_n("..", up).collect();
    }
    if let Ok(exe) = std::env::current_exe()
        && let Some(dir) = exe.ancestors().skip(1).find(|d| has_data(d))
    {
        return dir.to_path_buf();
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    root.canonicalize().unwrap_or(root)
}
