//! Integration tests of `hapcal-identify`: classic least-squares problems with known minima,
//! pruning, the calibration of the covariance against Monte Carlo, and the whole procedure.

mod covariance;
mod identify;
mod lm;
mod problems;
mod rank;
