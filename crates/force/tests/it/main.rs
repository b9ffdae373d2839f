//! Integration tests: the models the force study evaluates through the runtime against the
//! same models in the calibration library.

mod runtime;
