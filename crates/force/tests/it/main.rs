//! Integration tests: the models the force study evaluates through the runtime against the
//! same models in the calibration library.

#[path = "../../../runtime/tests/it/readings.rs"]
mod readings;
mod runtime;
