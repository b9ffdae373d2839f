//! hapcal-kinematics (stub).
