//! Integration tests of `hapcal-diagnose`: verdicts on simulated logs with known effects.

mod diagnose;
