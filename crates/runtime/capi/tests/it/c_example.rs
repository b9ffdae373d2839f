//! Compiles `examples/c/reference_reading.c` against the static library and the shared
//! library, runs it on the bundled calibrated reference device, and compares every printed
//! number with `hapcal_runtime`'s.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

use hapcal_runtime::{Evaluation, Model};

/// The folder cargo put this crate's libraries in (`target/<profile>/deps`), beside the test
/// binary `integration-…`.
pub(crate) fn lib_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    exe.parent().expect("target/<profile>/deps").to_path_buf()
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../fixtures/reference-device/calibrated.toml")
}

/// Compiles the example `examples/c/<source>` with the C compiler (`$CC`, else `cc`) into
/// `name`, linking `lib_args`.
pub(crate) fn compile(source: &str, name: &str, lib_args: &[String]) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".to_owned());
    let status = Command::new(&cc)
        .args([
            "-std=c99",
            "-D_POSIX_C_SOURCE=199309L",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-O2",
        ])
        .arg("-I")
        .arg(dir.join("include"))
        .arg(dir.join("examples/c").join(source))
        .args(lib_args)
        .args(["-lpthread", "-ldl", "-lm", "-o"])
        .arg(&out)
        .status()
        .unwrap_or_else(|e| panic!("running {cc}: {e}"));
    assert!(status.success(), "{cc} failed to build the C example");
    out
}

/// Runs `exe` with `args`; its standard output (exit code 0 asserted).
pub(crate) fn run(exe: &Path, args: &[&OsStr]) -> String {
    let output = Command::new(exe)
        .args(args)
        .output()
        .expect("run the C example");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "C example failed: {stderr}");
    String::from_utf8(output.stdout).expect("UTF-8")
}

/// The numbers after `key` on its line.
pub(crate) fn row(stdout: &str, key: &str) -> Vec<f64> {
    let line = (stdout.lines())
        .find(|l| l.split_whitespace().next() == Some(key))
        .unwrap_or_else(|| panic!("no line {key:?} in\n{stdout}"));
    (line.split_whitespace().skip(1))
        .map(|x| {
            x.parse()
                .unwrap_or_else(|_| panic!("{key}: not a number {x:?}"))
        })
        .collect()
}

/// Asserts that the line of each key of `expected` in a C program's output `stdout` holds
/// the library's numbers, each bit-identical (to the bit: the C library is the same compiled
/// code as the library the test links); returns how many numbers there were.
pub(crate) fn assert_rows_bit_identical(stdout: &str, expected: &[(&str, Vec<f64>)]) -> usize {
    let (mut identical, mut total) = (0, 0);
    for (key, want) in expected {
        let got = row(stdout, key);
        assert_eq!(got.len(), want.len(), "{key}");
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() <= 1e-12, "{key}: C {g:e} vs Rust {w:e}");
            identical += usize::from(g.to_bits() == w.to_bits());
            total += 1;
        }
    }
    assert_eq!(
        identical, total,
        "{identical} of {total} numbers bit-identical"
    );
    total
}

/// Checks the example's output against the library: every number bit-identical (the
/// libraries are the same compiled code as the library the test links).
fn check(stdout: &str) {
    let model = Model::load(&fixture()).expect("fixture");
    let theta = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
    let wrench = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1];
    let mut out = Evaluation::default();
    model.evaluate(&theta, &wrench, &mut out).expect("valid");
    let n = out.n_joints;
    let rotation: Vec<f64> = out.pose.rotation.iter().flatten().copied().collect();
    let jac: Vec<f64> = out.body_jacobian[..n].iter().flatten().copied().collect();
    let expected = [
        ("q_rad", out.q_rad[..n].to_vec()),
        ("dq_dtheta", out.dq_dtheta[..n].to_vec()),
        ("rotation", rotation),
        ("translation_m", out.pose.translation_m.to_vec()),
        ("body_jacobian", jac),
        ("motor_torques_nm", out.motor_torques_nm[..n].to_vec()),
    ];
    assert_rows_bit_identical(stdout, &expected);
    assert!(
        stdout.contains("wrong_length_status 2 n_joints: expected 7 values, found 6"),
        "{stdout}"
    );
    assert!(stdout.contains("null_status 1 theta is NULL"), "{stdout}");
}

#[test]
fn c_example_on_the_static_library_prints_the_library_numbers() {
    let lib = lib_dir().join("libhapcal_runtime_c.a");
    assert!(lib.exists(), "{} was not built", lib.display());
    let exe = compile(
        "reference_reading.c",
        "reference_reading_static",
        &[lib.display().to_string()],
    );
    check(&run(&exe, &[fixture().as_os_str()]));
}

#[test]
fn c_example_on_the_shared_library_prints_the_library_numbers() {
    let dir = lib_dir();
    assert!(
        dir.join("libhapcal_runtime_c.so").exists(),
        "no shared library"
    );
    let exe = compile(
        "reference_reading.c",
        "reference_reading_shared",
        &[
            format!("-L{}", dir.display()),
            format!("-Wl,-rpath,{}", dir.display()),
            "-lhapcal_runtime_c".to_owned(),
        ],
    );
    check(&run(&exe, &[fixture().as_os_str()]));
}
