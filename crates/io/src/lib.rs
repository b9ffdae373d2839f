//! hapcal-io (stub).
