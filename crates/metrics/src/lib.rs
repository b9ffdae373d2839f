//! hapcal-metrics (stub).
