//! Integration tests of hapcal-studies.

mod arm_blind;
mod setup_hostile;
mod setup_sweep;
