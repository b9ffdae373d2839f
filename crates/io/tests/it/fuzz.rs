//! Fuzzing of the readers with proptest-generated inputs (cargo-fuzz needs a nightly
//! toolchain and sanitizers this project does not have).
//!
//! For each reader — [`read_log`], [`read_measurement_file`] (CSV and the
//! `industrial_calibration` YAML), [`read_mukca_placement`] (and, on 7 columns,
//! `read_mukca_placement_for` with the iiwa's joint limits), [`parse_device`] and
//! [`import_urdf`] — two properties run:
//!
//! - **arbitrary bytes**: random byte strings, biased towards the characters the format is
//!   made of (`,`, newlines, digits, `:`, `<`, `=`, …), as the file;
//! - **mutated fixtures**: a real fixture with a few mutations applied (a byte flipped, a
//!   byte inserted, the text truncated, a line duplicated or deleted, a number replaced by
//!   `nan`, `1e308`, `-0`, nothing, a huge integer, …).
//!
//! Each asserts that the reader returns (never panics, never aborts on a huge allocation)
//! and that every error's message starts with the file's path (followed by `:line:column`
//! where the error has a position), so that a user can always find what is wrong.
//!
//! The default case counts keep the whole module under 20 s in a debug build on 2 cores.
//! To fuzz longer, raise them (and vary the seed, which CI fixes with `PROPTEST_RNG_SEED`):
//!
//! ```text
//! PROPTEST_CASES=10000 cargo test -p hapcal-io --test integration fuzz
//! ```
//!
//! A failing case is printed minimised by proptest; add it to the regression tests at the
//! bottom of this module once fixed (no regression file is written into the tree).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use hapcal_io::{
    Device, Error, JointSchema, Units, import_urdf, parse_device, read_device, read_log,
    read_measurement_file, read_mukca_placement,
};
use proptest::prelude::*;
use proptest::test_runner::Config;

use crate::{mukca, reference_device};

/// The proptest configuration: `default_cases` unless `PROPTEST_CASES` says otherwise.
fn config(default_cases: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default_cases);
    Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    }
}

fn fixture(relative: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(relative)
}

fn fixture_bytes(relative: &str) -> Vec<u8> {
    std::fs::read(fixture(relative)).unwrap()
}

/// A fresh, empty folder for one case (unique per process, test and case).
fn scratch(test: &str) -> PathBuf {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let dir = std::env::temp_dir().join(format!(
        "hapcal-io-fuzz-{}-{test}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Removes the folder when dropped, even if the case fails.
struct Cleanup(PathBuf);

impl Drop for Cleanup {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Writes `bytes` as `name` in a fresh folder, runs `read` on it and checks its result.
fn with_file<T>(
    test: &str,
    name: &str,
    bytes: &[u8],
    read: impl FnOnce(&Path) -> Result<T, Error>,
) -> Result<(), TestCaseError> {
    let dir = scratch(test);
    let _cleanup = Cleanup(dir.clone());
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    check(&path, read(&path))
}

/// The reader returned; an error names `path` first.
fn check<T>(path: &Path, result: Result<T, Error>) -> Result<(), TestCaseError> {
    if let Err(e) = result {
        let message = e.to_string();
        let prefix = path.display().to_string();
        prop_assert!(
            message.starts_with(&prefix) && message[prefix.len()..].starts_with([':', ' ', '/']),
            "error does not start with the path {prefix:?}: {message:?} ({e:?})"
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Inputs.

/// Bytes a text format is made of, to reach past the first character more often than
/// uniformly random bytes do.
const ALPHABET: &[u8] = b",,,\n\n\r \t.-+0123456789eEnaifxyzqd_:#[]{}<>/=\"'tsm";

/// Arbitrary byte strings, half from [`ALPHABET`].
fn arbitrary_bytes() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(
        prop_oneof![any::<u8>(), proptest::sample::select(ALPHABET)],
        0..600,
    )
}

/// What replaces a number of a fixture.
const REPLACEMENTS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e309",
    "-0",
    "",
    "123456789012",
    "18446744073709551615",
    "99999999999999999999999999",
    "4e-324",
    "0x10",
    "1,2",
    "\"",
    "é",
];

/// One mutation of a text.
#[derive(Clone, Debug)]
enum Mutation {
    /// XOR the byte at (index mod len) with the value.
    FlipByte(usize, u8),
    /// Insert a byte at (index mod len + 1).
    InsertByte(usize, u8),
    /// Keep the first (index mod len + 1) bytes.
    Truncate(usize),
    /// Repeat line (index mod lines) just after itself.
    DuplicateLine(usize),
    /// Delete line (index mod lines).
    DeleteLine(usize),
    /// Replace number (index mod numbers) by `REPLACEMENTS[k]`.
    ReplaceNumber(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let index = any::<usize>();
    prop_oneof![
        1 => (index, 1..=255u8).prop_map(|(i, b)| Mutation::FlipByte(i, b)),
        1 => (index, any::<u8>()).prop_map(|(i, b)| Mutation::InsertByte(i, b)),
        1 => index.prop_map(Mutation::Truncate),
        1 => index.prop_map(Mutation::DuplicateLine),
        1 => index.prop_map(Mutation::DeleteLine),
        3 => (index, 0..REPLACEMENTS.len()).prop_map(|(i, k)| Mutation::ReplaceNumber(i, k)),
    ]
}

fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
    proptest::collection::vec(mutation(), 1..5)
}

/// Byte ranges of the lines of `bytes`, each with its line break.
fn lines(bytes: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, b) in bytes.iter().enumerate() {
        if *b == b'\n' {
            out.push(start..i + 1);
            start = i + 1;
        }
    }
    if start < bytes.len() {
        out.push(start..bytes.len());
    }
    out
}

/// Byte ranges of the numbers of `bytes`: maximal runs of digits, `.`, `e`, `E`, `+`, `-`
/// that hold a digit.
fn numbers(bytes: &[u8]) -> Vec<std::ops::Range<usize>> {
    let is_part = |b: u8| b.is_ascii_digit() || matches!(b, b'.' | b'e' | b'E' | b'+' | b'-');
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if is_part(bytes[i]) {
            let start = i;
            while i < bytes.len() && is_part(bytes[i]) {
                i += 1;
            }
            if bytes[start..i].iter().any(u8::is_ascii_digit) {
                out.push(start..i);
            }
        } else {
            i += 1;
        }
    }
    out
}

/// `bytes` with `mutations` applied in order.
fn mutate(bytes: &[u8], mutations: &[Mutation]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for m in mutations {
        let len = out.len();
        match *m {
            Mutation::FlipByte(i, x) if len > 0 => out[i % len] ^= x,
            Mutation::InsertByte(i, b) => out.insert(i % (len + 1), b),
            Mutation::Truncate(i) if len > 0 => out.truncate(i % len + 1),
            Mutation::DuplicateLine(i) => {
                let lines = lines(&out);
                if !lines.is_empty() {
                    let line = lines[i % lines.len()].clone();
                    let copy = out[line.clone()].to_vec();
                    out.splice(line.end..line.end, copy);
                }
            }
            Mutation::DeleteLine(i) => {
                let lines = lines(&out);
                if !lines.is_empty() {
                    out.drain(lines[i % lines.len()].clone());
                }
            }
            Mutation::ReplaceNumber(i, k) => {
                let numbers = numbers(&out);
                if !numbers.is_empty() {
                    let range = numbers[i % numbers.len()].clone();
                    out.splice(range, REPLACEMENTS[k].bytes());
                }
            }
            Mutation::FlipByte(..) | Mutation::Truncate(_) => {}
        }
    }
    out
}

// ---------------------------------------------------------------------------------------
// The readers, on a file of the given bytes.

fn reference() -> Device {
    read_device(&reference_device()).unwrap()
}

fn fuzz_log(bytes: &[u8], device: &Device) -> Result<(), TestCaseError> {
    with_file("log", "log.csv", bytes, |path| read_log(path, device))
}

/// Owned parts of a [`JointSchema`].
struct Schema {
    names: Vec<String>,
    prismatic: Vec<bool>,
    limits: Vec<(f64, f64)>,
}

impl Schema {
    fn of(device: &Device) -> Self {
        Self {
            names: device.joints.iter().map(|j| j.name.clone()).collect(),
            prismatic: vec![false; device.joints.len()],
            limits: device.joint_limits(),
        }
    }

    fn get(&self) -> JointSchema<'_> {
        JointSchema {
            names: &self.names,
            prismatic: &self.prismatic,
            limits: &self.limits,
        }
    }
}

fn ur10() -> Schema {
    Schema::of(&import_urdf(&fixture("figaroh/ur10/ur10_robot.urdf"), "wrist_3_link").unwrap())
}

fn positioner() -> Schema {
    Schema::of(&read_device(&fixture("industrial-calibration/two_axis_positioner.toml")).unwrap())
}

fn fuzz_measurement(bytes: &[u8], schema: &Schema, name: &str) -> Result<(), TestCaseError> {
    with_file("measure", name, bytes, |path| {
        read_measurement_file(path, &schema.get(), &Units::default())
    })
}

/// A placement folder with `hole_0.csv` … holding `files`.
fn fuzz_mukca(files: &[Vec<u8>], n_joints: usize) -> Result<(), TestCaseError> {
    let dir = scratch("mukca");
    let _cleanup = Cleanup(dir.clone());
    let placement = dir.join("front");
    std::fs::create_dir_all(&placement).unwrap();
    for (k, bytes) in files.iter().enumerate() {
        std::fs::write(placement.join(format!("hole_{k}.csv")), bytes).unwrap();
    }
    check(&placement, read_mukca_placement(&placement, n_joints))?;
    // The reader that checks the readings against the iiwa's joint limits, on 7 columns.
    if n_joints == 7 {
        let iiwa = import_urdf(&fixture("mukca/urdf/iiwa14.urdf"), "ball_link").unwrap();
        check(
            &placement,
            hapcal_io::read_mukca_placement_for(&placement, &iiwa),
        )?;
    }
    Ok(())
}

fn fuzz_device(bytes: &[u8]) -> Result<(), TestCaseError> {
    let text = String::from_utf8_lossy(bytes);
    let path = Path::new("fuzz/device.toml");
    check(path, parse_device(&text, path))
}

fn fuzz_urdf(bytes: &[u8], tip: &str) -> Result<(), TestCaseError> {
    with_file("urdf", "robot.urdf", bytes, |path| import_urdf(path, tip))
}

fn mukca_front() -> [Vec<u8>; 2] {
    [0, 1].map(|k| std::fs::read(mukca(&format!("data/kuka_14/front/hole_{k}.csv"))).unwrap())
}

// ---------------------------------------------------------------------------------------
// The properties.

proptest! {
    #![proptest_config(config(256))]

    #[test]
    fn log_of_arbitrary_bytes(bytes in arbitrary_bytes()) {
        fuzz_log(&bytes, &reference())?;
    }

    #[test]
    fn log_mutated(m in mutations()) {
        fuzz_log(&mutate(&fixture_bytes("reference-device/log.csv"), &m), &reference())?;
    }

    #[test]
    fn measurement_csv_of_arbitrary_bytes(bytes in arbitrary_bytes()) {
        fuzz_measurement(&bytes, &ur10(), "calibration.csv")?;
    }

    #[test]
    fn measurement_csv_mutated(m in mutations()) {
        let bytes = mutate(&fixture_bytes("figaroh/ur10/calibration.csv"), &m);
        fuzz_measurement(&bytes, &ur10(), "calibration.csv")?;
    }

    #[test]
    fn measurement_yaml_of_arbitrary_bytes(bytes in arbitrary_bytes()) {
        fuzz_measurement(&bytes, &positioner(), "measurements.yaml")?;
    }

    #[test]
    fn mukca_of_arbitrary_bytes(bytes in arbitrary_bytes(), n_joints in 0..9usize) {
        fuzz_mukca(&[bytes], n_joints)?;
    }

    #[test]
    fn mukca_mutated(m in mutations(), which in 0..2usize) {
        let mut files = mukca_front();
        files[which] = mutate(&files[which], &m);
        fuzz_mukca(&files, 7)?;
    }

    #[test]
    fn device_of_arbitrary_bytes(bytes in arbitrary_bytes()) {
        fuzz_device(&bytes)?;
    }

    #[test]
    fn device_mutated(m in mutations()) {
        fuzz_device(&mutate(&std::fs::read(reference_device()).unwrap(), &m))?;
    }

    #[test]
    fn urdf_of_arbitrary_bytes(bytes in arbitrary_bytes()) {
        fuzz_urdf(&bytes, "ball_link")?;
    }

    #[test]
    fn urdf_mutated(m in mutations()) {
        fuzz_urdf(&mutate(&fixture_bytes("mukca/urdf/iiwa14.urdf"), &m), "ball_link")?;
    }
}

proptest! {
    // The YAML fixture is 60 kB: fewer cases.
    #![proptest_config(config(64))]

    #[test]
    fn measurement_yaml_mutated(m in mutations()) {
        let bytes = mutate(&fixture_bytes("industrial-calibration/measurements.yaml"), &m);
        fuzz_measurement(&bytes, &positioner(), "measurements.yaml")?;
    }
}

// ---------------------------------------------------------------------------------------
// Inputs that once made a reader panic or abort.

/// A marker number in the billions made the measurement reader allocate room for that many
/// markers (an abort, not even a panic).
#[test]
fn huge_marker_number_is_an_error_not_an_allocation() {
    let text = "shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint,x123456789012,y123456789012,z123456789012\n0,0,0,0,0,0,1,2,3\n";
    let dir = scratch("huge-marker");
    let _cleanup = Cleanup(dir.clone());
    let path = dir.join("calibration.csv");
    std::fs::write(&path, text).unwrap();
    let message = crate::message(read_measurement_file(
        &path,
        &ur10().get(),
        &Units::default(),
    ));
    crate::assert_contains(
        &message,
        &["calibration.csv:1:10: column \"x1\" of marker 1 is missing from the header"],
    );
}

/// Nesting depth of the deep-nesting tests.
const DEPTH: usize = 100_000;

/// Deeply nested values must not overflow the stack of a parser.
#[test]
fn deep_toml_array() {
    fuzz_device(format!("name = {}", "[".repeat(DEPTH)).as_bytes()).unwrap();
}

#[test]
fn deep_toml_inline_table() {
    fuzz_device(format!("name = {}", "{a=".repeat(DEPTH)).as_bytes()).unwrap();
}

#[test]
fn deep_yaml_flow() {
    // The YAML scanner takes time quadratic in the depth (13 s for 10⁵); the reader refuses
    // nesting past MAX_YAML_DEPTH in one linear pass before it.
    let yaml = format!("a: {}", "[".repeat(DEPTH));
    fuzz_measurement(yaml.as_bytes(), &positioner(), "measurements.yaml").unwrap();
}

#[test]
fn deep_yaml_block() {
    let yaml: String = (0..2000)
        .map(|i| format!("{}- \n", " ".repeat(i)))
        .collect();
    fuzz_measurement(
        format!("a:\n{yaml}").as_bytes(),
        &positioner(),
        "measurements.yaml",
    )
    .unwrap();
}

#[test]
fn deep_urdf() {
    let urdf = format!(
        "<robot name=\"r\">{}{}</robot>",
        "<link name=\"a\">".repeat(DEPTH),
        "</link>".repeat(DEPTH)
    );
    fuzz_urdf(urdf.as_bytes(), "a").unwrap();
    // The deepest nesting allowed is read by urdf-rs without overflowing the stack.
    let urdf = format!(
        "<robot name=\"r\">{}{}</robot>",
        "<link name=\"a\">".repeat(63),
        "</link>".repeat(63)
    );
    fuzz_urdf(urdf.as_bytes(), "a").unwrap();
}
