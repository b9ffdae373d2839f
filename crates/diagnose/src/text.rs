//! The diagnoses as text reports, what `hapcal diagnose` prints: the gap above the floor,
//! where the residual lies, which candidate effects explain it and how far, and the verdict.

mod haptic;
mod serial_arm;

pub use haptic::render;
pub use serial_arm::render_arm;
