//! Integration tests of hapcal-studies.

mod arm_blind;
