//! hapcal-identify (stub).
