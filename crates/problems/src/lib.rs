//! hapcal-problems (stub).
