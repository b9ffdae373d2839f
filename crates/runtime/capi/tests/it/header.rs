//! `include/hapcal_runtime.h` is what cbindgen generates from `src/lib.rs` now.

use std::path::Path;

#[test]
fn header_is_current() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen parses src/lib.rs");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let generated = String::from_utf8(generated).expect("UTF-8");
    let path = dir.join("include/hapcal_runtime.h");
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    if generated != committed {
        if std::env::var_os("UPDATE_HEADER").is_some() {
            std::fs::write(&path, &generated).expect("write header");
            panic!("rewrote {}: review the diff", path.display());
        }
        panic!(
            "{} is out of date: UPDATE_HEADER=1 cargo test -p hapcal-runtime-capi header",
            path.display()
        );
    }
    for name in [
        "hapcal_model_load",
        "hapcal_evaluate",
        "hapcal_last_error_message",
        "HAPCAL_STATUS_NULL_POINTER",
        "HapcalPose",
        "hapcal_robot_load",
        "hapcal_robot_deflected_tip_poses",
        "hapcal_robot_spatial_jacobian",
        "hapcal_robot_body_jacobian",
        "hapcal_robot_compensate",
        "hapcal_robot_outside_region",
        "HAPCAL_INSIDE_REGION",
        "HAPCAL_TARGET_POSE",
        "HAPCAL_STATUS_INVALID_ARGUMENT",
        "HapcalCompensationConfig",
        "hapcal_robot_deflect",
        "hapcal_robot_deflected_spatial_jacobian",
        "hapcal_robot_frame",
        "hapcal_robot_with_marker",
        "hapcal_robot_with_compliances",
        "hapcal_robot_with_value",
        "hapcal_robot_limits",
        "hapcal_robot_compliances",
        "hapcal_robot_is_prismatic",
        "hapcal_predictor_new",
        "hapcal_predictor_predict",
        "hapcal_predictor_marker_poses",
        "hapcal_predictor_outside_region",
        "hapcal_predictor_uncertainty_note",
        "hapcal_predictor_free",
        "HapcalTipPrediction",
        "HAPCAL_UNCERTAINTY_BASIS_STDS_ONLY",
        "HAPCAL_FRAME_INSTRUMENT",
    ] {
        assert!(generated.contains(name), "{name} missing from the header");
    }
}
