//! Integration tests of hapcal-studies.

mod arm_blind;
mod setup_sweep;
