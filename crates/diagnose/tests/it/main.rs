//! Integration tests of `hapcal-diagnose`: verdicts on simulated logs with known effects, and
//! the serial-arm diagnosis on recorded and simulated arm data.

mod arm;
mod arm_transversal;
mod diagnose;
