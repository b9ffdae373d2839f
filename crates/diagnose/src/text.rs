//! The diagnoses as text reports, what `hapcal diagnose` prints: the gap above the floor,
//! where the residual lies, which candidate effects explain it and how far, and the verdict.
//! The haptic and the arm report differ in what they test and map; a step is written once,
//! here, in the report's length unit.

mod haptic;
mod serial_arm;

use std::fmt::{self, Write as _};

use hapcal_contract::Effect;

use crate::ParamValue;
use crate::verdict::Length;

pub use haptic::render;
pub use serial_arm::render_arm;

/// `significant` or `not significant`.
fn significance(significant: bool) -> &'static str {
    if significant {
        "significant"
    } else {
        "not significant"
    }
}

/// An accepted effect's step (held-out RMS before and after, m; share of the gap, %), then its
/// `parameters`, their names padded to `name_width`.
fn write_step(
    s: &mut String,
    effect: Effect,
    (before_m, after_m, closed_pct): (f64, f64, f64),
    parameters: &[ParamValue],
    (name_width, length): (usize, Length),
) -> fmt::Result {
    let (before, after, unit) = (length.of(before_m), length.of(after_m), length.0);
    writeln!(
        s,
        "  + {effect}: held-out RMS {before} → {after} {unit}, closes {closed_pct:.0} % of the gap"
    )?;
    for p in parameters {
        let (name, value, std, unit) = (&p.name, p.value, p.std, &p.unit);
        writeln!(
            s,
            "      {name:name_width$} {value:>12.4e} ± {std:.1e} {unit}"
        )?;
    }
    Ok(())
}
