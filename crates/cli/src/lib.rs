//! The `hapcal` command line: argument parsing and rendering over [`hapcal_calibrate`] (the
//! workflows) and [`hapcal_studies`] (what needs a simulated truth).
//!
//! Architecture invariant: *the library part never prints; `main.rs` prints what it returns.*

pub mod diagnose;
pub mod diagnose_arm;
pub mod plan_args;
pub mod report;

pub use hapcal_calibrate::{calibrate, haptic, plan, project_root, support};
pub use hapcal_studies::{figures, force, paper, pose_study, reproduce};

/// Parses a whole number within `MIN..=MAX` (poses, candidates, cases, seeds); clap reports
/// any other value as a usage error naming the argument. The upper bounds keep a typo (an
/// extra three zeros) from asking for more memory than a workstation has: every count is
/// bounded where its arrays are allocated.
///
/// # Errors
/// A message with the bounds and the value found.
pub fn count_in<const MIN: usize, const MAX: usize>(
    text: &str,
) -> std::result::Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (MIN..=MAX).contains(&n) => Ok(n),
        Ok(n) => Err(format!("must lie between {MIN} and {MAX}, got {n}")),
        Err(_) => Err(format!("expected a whole number, got {text:?}")),
    }
}
