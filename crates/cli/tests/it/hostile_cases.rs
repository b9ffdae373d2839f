//! The hostile-input table: every `hapcal` command fed empty, malformed, absurd and
//! contradictory files and options. Each case states the exit code and the parts of the
//! message (file, line, column or the option, and the value) it must print; every case also
//! checks that nothing panicked (exit code 101) and that no input file changed (a hash of
//! every file named on the command line, and of the files in every folder named, before and
//! after). Fixtures are written into a scratch folder or read from `fixtures/` (never written).

use super::{force_args, root, scratch, show};
use std::collections::BTreeMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// One command line and what it must do.
struct Case {
    /// Category of the table in docs/results/reliability.md.
    category: &'static str,
    /// What is hostile about it.
    name: String,
    args: Vec<String>,
    /// Expected exit code.
    code: i32,
    /// Parts the message must contain (standard error; standard output too for exit code 0,
    /// where the report carries the warnings).
    needles: Vec<String>,
}

/// Longest a case may run: every hostile case fails (or warns) within seconds.
const TIMEOUT: Duration = Duration::from_secs(120);

fn fixture(relative: &str) -> String {
    show(&root().join("fixtures").join(relative))
}

/// Hash of every file `args` name, and of the files directly inside every folder they name.
fn input_hashes(args: &[String]) -> BTreeMap<PathBuf, u64> {
    let mut hashes = BTreeMap::new();
    let mut add = |p: &Path| {
        if let Ok(bytes) = std::fs::read(p) {
            let mut h = DefaultHasher::new();
            bytes.hash(&mut h);
            hashes.insert(p.to_path_buf(), h.finish());
        }
    };
    for arg in args {
        let p = Path::new(arg);
        if p.is_file() {
            add(p);
        } else if p.is_dir()
            && let Ok(entries) = std::fs::read_dir(p)
        {
            for e in entries.flatten() {
                if e.path().is_file() {
                    add(&e.path());
                }
            }
        }
    }
    hashes
}

/// Runs one case; `Err` says what went wrong.
fn run_case(case: &Case) -> Result<(), String> {
    let before = input_hashes(&case.args);
    let mut child = Command::new(env!("CARGO_BIN_EXE_hapcal"))
        .args(&case.args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start: {e}"))?;
    // Drain the pipes on threads so that a long report cannot block the child.
    let mut out_pipe = child.stdout.take().ok_or("no stdout")?;
    let mut err_pipe = child.stderr.take().ok_or("no stderr")?;
    let out_thread = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut out_pipe, &mut s);
        s
    });
    let err_thread = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut err_pipe, &mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break status;
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("still running after {TIMEOUT:?}"));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let stdout = String::from_utf8_lossy(&out_thread.join().unwrap_or_default()).into_owned();
    let stderr = String::from_utf8_lossy(&err_thread.join().unwrap_or_default()).into_owned();
    let code = status.code();
    if code == Some(101) || stderr.contains("panicked") {
        return Err(format!("panicked: {stderr}"));
    }
    if code != Some(case.code) {
        return Err(format!(
            "exit code {code:?}, expected {}: {stderr}",
            case.code
        ));
    }
    let text = if case.code == 0 {
        format!("{stderr}\n{stdout}")
    } else {
        stderr.clone()
    };
    let missing: Vec<&String> = (case.needles.iter())
        .filter(|n| !text.contains(n.as_str()))
        .collect();
    if !missing.is_empty() {
        return Err(format!("message lacks {missing:?}: {stderr}"));
    }
    let after = input_hashes(&case.args);
    for (path, hash) in &before {
        if after.get(path) != Some(hash) {
            return Err(format!("input {} changed", path.display()));
        }
    }
    Ok(())
}

/// The cases, built over fixtures written into `dir`.
struct Table {
    dir: PathBuf,
    cases: Vec<Case>,
}

impl Table {
    fn add(
        &mut self,
        category: &'static str,
        name: &str,
        args: &[&str],
        code: i32,
        needles: &[&str],
    ) {
        self.cases.push(Case {
            category,
            name: name.to_owned(),
            args: args.iter().map(|s| (*s).to_owned()).collect(),
            code,
            needles: needles.iter().map(|s| (*s).to_owned()).collect(),
        });
    }

    /// Writes `bytes` to `dir/name` and returns its path.
    fn file(&self, name: &str, bytes: impl AsRef<[u8]>) -> String {
        let path = self.dir.join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).expect("folder");
        }
        std::fs::write(&path, bytes).expect("write");
        show(&path)
    }

    fn path(&self, name: &str) -> String {
        show(&self.dir.join(name))
    }
}

/// The first `n` data rows of the reference log, with its header, as lines of cells.
fn reference_log(n: usize) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(root().join("fixtures/reference-device/log.csv"))
        .expect("reference log");
    (text.lines().take(n + 1))
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

fn csv(lines: &[Vec<String>]) -> String {
    lines.iter().map(|l| l.join(",") + "\n").collect()
}

/// `lines` with the cell at 1-based `line`, `column` replaced.
fn with_cell(lines: &[Vec<String>], line: usize, column: usize, value: &str) -> String {
    let mut lines = lines.to_vec();
    lines[line - 1][column - 1] = value.to_owned();
    csv(&lines)
}

fn log_cases(t: &mut Table) {
    const C: &str = "log CSV (haptic device)";
    let device = fixture("reference-device/device.toml");
    let log = reference_log(60);
    let calibrate = |t: &mut Table, name: &str, file: &str, text: &[u8], code, needles: &[&str]| {
        let path = t.file(&format!("log/{file}"), text);
        let needles: Vec<String> = needles.iter().map(|n| n.replace("@", &path)).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(
            C,
            name,
            &["calibrate", "--device", &device, "--data", &path],
            code,
            &needles,
        );
    };
    let good = csv(&log);
    calibrate(
        t,
        "empty file",
        "empty.csv",
        b"",
        2,
        &["@: expected at least 1 data rows, found 0"],
    );
    calibrate(
        t,
        "header only",
        "header.csv",
        csv(&log[..1]).as_bytes(),
        2,
        &["@: expected at least 1 data rows, found 0"],
    );
    calibrate(
        t,
        "semicolons",
        "semicolons.csv",
        good.replace(',', ";").as_bytes(),
        2,
        &["@:1:1: expected comma-separated columns", "semicolons"],
    );
    calibrate(
        t,
        "tabs",
        "tabs.csv",
        good.replace(',', "\t").as_bytes(),
        2,
        &["@:1:1: expected comma-separated columns", "tabs"],
    );
    calibrate(
        t,
        "spaces",
        "spaces.csv",
        good.replace(',', " ").as_bytes(),
        2,
        &["@:1:1: expected comma-separated columns", "spaces"],
    );
    calibrate(
        t,
        "rows with semicolons",
        "row-semicolons.csv",
        format!("{}{}", csv(&log[..3]), csv(&log[3..]).replace(',', ";")).as_bytes(),
        2,
        &["@:4:1: expected comma-separated columns"],
    );
    for (name, line, column, value, needle) in [
        (
            "NaN joint reading",
            3,
            3,
            "NaN",
            "@:3:3: expected a finite number in \"q3\", found NaN",
        ),
        (
            "nan lower case",
            4,
            1,
            "nan",
            "@:4:1: expected a finite number in \"q1\", found nan",
        ),
        (
            "inf distance",
            5,
            8,
            "inf",
            "@:5:8: expected a finite number in \"distance_m\", found inf",
        ),
        (
            "-inf joint reading",
            6,
            2,
            "-inf",
            "@:6:2: expected a finite number in \"q2\", found -inf",
        ),
        (
            "+infinity",
            6,
            2,
            "+infinity",
            "@:6:2: expected a finite number in \"q2\", found +infinity",
        ),
        (
            "1e308 distance",
            7,
            8,
            "1e308",
            "@:7:8: distance_m = 1e308 m is out of range",
        ),
        (
            "-1e308 distance",
            7,
            8,
            "-1e308",
            "@:7:8: distance_m = -1e308 m is out of range",
        ),
        (
            "1e400 overflows to inf",
            7,
            8,
            "1e400",
            "@:7:8: expected a finite number in \"distance_m\", found 1e400",
        ),
        (
            "1e308 joint reading",
            8,
            2,
            "1e308",
            "@:8:2: joint \"q2\" = 1e308 rad is outside",
        ),
        (
            "negative distance",
            9,
            8,
            "-0.5",
            "@:9:8: distance_m = -0.5 m is negative",
        ),
        (
            "tiny negative distance",
            9,
            8,
            "-1e-9",
            "@:9:8: distance_m = -0.000000001 m is negative",
        ),
        (
            "joint far outside its limits",
            10,
            1,
            "50",
            "@:10:1: joint \"q1\" = 50 rad is outside [-1, 1] rad",
        ),
        (
            "joint just past its limit",
            10,
            4,
            "1.8000001",
            "@:10:4: joint \"q4\" = 1.8000001 rad is outside [0.3, 1.8] rad",
        ),
        (
            "joint below its limit",
            11,
            2,
            "-0.31",
            "@:11:2: joint \"q2\" = -0.31 rad is outside [-0.3, 1.2] rad",
        ),
        (
            "degrees instead of radians",
            12,
            5,
            "114.6",
            "@:12:5: joint \"q5\" = 114.6 rad is outside [-2, 2] rad",
        ),
        (
            "text in a cell",
            13,
            3,
            "abc",
            "@:13:3: expected a number in column \"q3\", found \"abc\"",
        ),
        (
            "empty joint cell",
            13,
            3,
            "",
            "@:13:3: expected a number in column \"q3\", found \"\"",
        ),
        (
            "empty distance cell",
            13,
            8,
            "",
            "@:13:8: expected a number in column \"distance_m\", found \"\"",
        ),
        (
            "hex number",
            14,
            1,
            "0x1",
            "@:14:1: expected a number in column \"q1\", found \"0x1\"",
        ),
        (
            "ext cell not a number",
            15,
            9,
            "x",
            "@:15:9: expected a number in column \"ext1\", found \"x\"",
        ),
        (
            "ext cell NaN",
            15,
            10,
            "NaN",
            "@:15:10: expected a finite number in \"ext2\"",
        ),
        (
            "a 100 000-digit number",
            16,
            8,
            &"9".repeat(100_000),
            "@:16:8: expected a finite number in \"distance_m\"",
        ),
    ] {
        let file = format!("cell-{}.csv", name.replace(' ', "-"));
        calibrate(
            t,
            name,
            &file,
            with_cell(&log, line, column, value).as_bytes(),
            2,
            &[needle],
        );
    }
    // A decimal comma splits the cell: one field too many.
    let mut comma = log.clone();
    comma[4][2] = "0,15".to_owned();
    calibrate(
        t,
        "decimal comma",
        "comma.csv",
        csv(&comma).as_bytes(),
        2,
        &["@:5: expected 12 fields, found 13"],
    );
    let mut short = log.clone();
    short[5].truncate(5);
    calibrate(
        t,
        "short row",
        "short.csv",
        csv(&short).as_bytes(),
        2,
        &["@:6: expected 12 fields, found 5"],
    );
    let mut long = log.clone();
    long[6].push("0.1".to_owned());
    calibrate(
        t,
        "long row",
        "long.csv",
        csv(&long).as_bytes(),
        2,
        &["@:7: expected 12 fields, found 13"],
    );
    let header = |f: &dyn Fn(&mut Vec<String>)| {
        let mut l = log.clone();
        f(&mut l[0]);
        csv(&l)
    };
    calibrate(
        t,
        "missing distance column",
        "no-distance.csv",
        header(&|h| h[7] = "dist".into()).as_bytes(),
        2,
        &["@:1: missing column \"distance_m\""],
    );
    calibrate(
        t,
        "missing joint column",
        "no-q3.csv",
        header(&|h| h[2] = "x3".into()).as_bytes(),
        2,
        &["@:1: expected 7 joints (as the device has), found 6"],
    );
    calibrate(
        t,
        "duplicated column",
        "dup-col.csv",
        header(&|h| h[2] = "q2".into()).as_bytes(),
        2,
        &["@:1:3: column \"q2\" appears twice"],
    );
    calibrate(
        t,
        "duplicated distance column",
        "dup-dist.csv",
        header(&|h| h[8] = "distance_m".into()).as_bytes(),
        2,
        &["@:1:9: column \"distance_m\" appears twice"],
    );
    calibrate(
        t,
        "eighth joint column",
        "q8.csv",
        header(&|h| h[8] = "q8".into()).as_bytes(),
        2,
        &["@:1: expected 7 joints (as the device has), found 8"],
    );
    calibrate(
        t,
        "upper-case header",
        "upper.csv",
        header(&|h| h[0] = "Q1".into()).as_bytes(),
        2,
        &["@:1: expected 7 joints (as the device has), found 6"],
    );
    let mut bom = vec![0xEF, 0xBB, 0xBF];
    bom.extend_from_slice(good.as_bytes());
    calibrate(
        t,
        "byte-order mark (read as UTF-8 text)",
        "bom.csv",
        &bom,
        0,
        &["bom "],
    );
    let mut invalid = good.clone().into_bytes();
    let at = invalid.iter().position(|b| *b == b'\n').unwrap_or(0) + 3;
    invalid[at] = 0xFF;
    calibrate(
        t,
        "invalid UTF-8",
        "utf8.csv",
        &invalid,
        2,
        &["@:2: invalid UTF-8 in field 1"],
    );
    let mut timed = log.clone();
    timed[0].push("t_s".into());
    for (i, l) in timed.iter_mut().enumerate().skip(1) {
        l.push(if i == 20 {
            "1.5".into()
        } else {
            format!("{}", i * 2)
        });
    }
    calibrate(
        t,
        "time going backwards",
        "time.csv",
        csv(&timed).as_bytes(),
        2,
        &["@:21: t_s = 1.5 s is before the previous row's 38 s"],
    );
    let mut quoted = log.clone();
    quoted[3][2] = "\"0.1\n5\"".into();
    calibrate(
        t,
        "quoted line break in a cell",
        "quoted.csv",
        csv(&quoted).as_bytes(),
        2,
        &["@:4:3: expected a number in column \"q3\""],
    );
    // Copies of rows.
    let copies: Vec<Vec<String>> = std::iter::once(log[0].clone())
        .chain(std::iter::repeat_n(log[1].clone(), 200))
        .collect();
    calibrate(
        t,
        "200 copies of one pose",
        "copies.csv",
        csv(&copies).as_bytes(),
        2,
        &[
            "@:1:8: distance_m is 0.6815299767718371 m in all 200 rows",
            "the measurement does not change",
        ],
    );
    let two: Vec<Vec<String>> = std::iter::once(log[0].clone())
        .chain((0..100).flat_map(|_| [log[1].clone(), log[2].clone()]))
        .collect();
    calibrate(
        t,
        "two poses 100 times each",
        "two.csv",
        csv(&two).as_bytes(),
        2,
        &[
            "the training logs hold 2 distinct",
            "(in 200 rows)",
            "kept parameters",
        ],
    );
    let few: Vec<Vec<String>> = log[..1]
        .iter()
        .chain(&log[1..11])
        .cloned()
        .collect::<Vec<_>>()
        .into_iter()
        .chain((0..20).flat_map(|_| log[1..11].to_vec()))
        .collect();
    calibrate(
        t,
        "10 poses 21 times each",
        "ten.csv",
        csv(&few).as_bytes(),
        2,
        &["the training logs hold 10 distinct", "(in 210 rows)"],
    );
    // The diagnosis of two poses repeated: an error, not a held-out RMS of 0.
    let path = t.file("log/diagnose-two.csv", csv(&two).as_bytes());
    t.add(
        C,
        "diagnose: two poses 100 times each",
        &["diagnose", "--device", &device, "--data", &path],
        2,
        &[
            &format!("diagnosing {path}"),
            "the log holds 2 distinct joint configurations (in 200 rows)",
            "identifiable parameters",
        ],
    );
    let mut repeated = log.clone();
    for k in 0..5 {
        repeated.push(log[1 + k].clone());
    }
    calibrate(
        t,
        "five duplicated rows",
        "dup-rows.csv",
        csv(&repeated).as_bytes(),
        0,
        &[
            "dup-rows.csv:62: the joint readings and measurements repeat those of line 2 (5 rows in all repeat an earlier row)",
        ],
    );
    calibrate(
        t,
        "three rows",
        "three.csv",
        csv(&log[..4]).as_bytes(),
        2,
        &["3 residuals for 3 kept parameters"],
    );
    calibrate(
        t,
        "unknown column",
        "unknown.csv",
        header(&|h| h[11] = "temperature".into()).as_bytes(),
        0,
        &["unknown.csv:1:12: unknown column \"temperature\" ignored"],
    );
    calibrate(
        t,
        "CRLF line ends",
        "crlf.csv",
        good.replace('\n', "\r\n").as_bytes(),
        0,
        &["crlf"],
    );
    calibrate(
        t,
        "blank lines",
        "blank.csv",
        good.replacen('\n', "\n\n\n", 5).as_bytes(),
        0,
        &["blank"],
    );
    let dir = t.path("log");
    t.add(
        C,
        "a folder as the log",
        &["calibrate", "--device", &device, "--data", &dir],
        2,
        &["a haptic device is calibrated from log files"],
    );
    let missing = t.path("log/no-such.csv");
    t.add(
        C,
        "missing log",
        &["calibrate", "--device", &device, "--data", &missing],
        2,
        &["no-such.csv: a haptic device is calibrated from log files"],
    );
    let good_path = t.file("log/good.csv", &good);
    let bad_test = t.file("log/bad-test.csv", with_cell(&log, 3, 3, "NaN"));
    t.add(
        C,
        "broken test log",
        &[
            "calibrate",
            "--device",
            &device,
            "--data",
            &good_path,
            "--test",
            &bad_test,
        ],
        2,
        &[&format!("{bad_test}:3:3: expected a finite number")],
    );
}

fn device_cases(t: &mut Table) {
    const C: &str = "device TOML";
    let text = std::fs::read_to_string(root().join("fixtures/reference-device/device.toml"))
        .expect("device");
    let simulate = |t: &mut Table, name: &str, body: String, needles: &[&str]| {
        let file = format!("device/{}.toml", name.replace(' ', "-"));
        let path = t.file(&file, body);
        let out = t.path(&format!("device/{}.csv", name.replace(' ', "-")));
        let needles: Vec<String> = needles.iter().map(|n| n.replace("@", &path)).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(
            C,
            name,
            &["simulate", "--device", &path, "--poses", "5", "--out", &out],
            2,
            &needles,
        );
    };
    let edit = |from: &str, to: &str| {
        assert!(text.contains(from), "{from}");
        text.replacen(from, to, 1)
    };
    simulate(
        t,
        "empty",
        String::new(),
        &["@:1:1: no kinematic chain: expected [[dh]] rows or [[placement]] rows"],
    );
    simulate(
        t,
        "not TOML",
        "<robot/>".into(),
        &["@:1:9: key with no value"],
    );
    simulate(
        t,
        "missing a_m",
        edit("a_m = 0.35\n", ""),
        &["@:", "missing field `a_m`"],
    );
    simulate(
        t,
        "misspelt key",
        edit(
            "alpha_rad = -1.5707963267948966\nd_m = 0.10",
            "alfa_rad = -1.5707963267948966\nd_m = 0.10",
        ),
        &["@:", "alfa_rad"],
    );
    simulate(
        t,
        "negative counts",
        edit("counts_per_rev = 20000", "counts_per_rev = -5"),
        &["@:67:18: invalid value: integer `-5`, expected u32"],
    );
    simulate(
        t,
        "counts as text",
        edit("counts_per_rev = 20000", "counts_per_rev = \"many\""),
        &["@:67:18: ", "many"],
    );
    simulate(
        t,
        "negative drum radius",
        edit("drum_radius_m = 0.015", "drum_radius_m = -0.015"),
        &["@:133:17: drum_radius_m = -0.015 must be positive"],
    );
    simulate(
        t,
        "zero drum radius",
        edit("drum_radius_m = 0.015", "drum_radius_m = 0.0"),
        &["@:133:17: drum_radius_m = 0 must be positive"],
    );
    simulate(
        t,
        "negative ratio",
        edit("ratio = 10.0", "ratio = -10.0"),
        &["@:108:9: ratio = -10 must be positive"],
    );
    simulate(
        t,
        "negative drum distance",
        edit("drum_distance_m = 0.06", "drum_distance_m = -0.06"),
        &["@:109:19: drum_distance_m = -0.06 must be positive"],
    );
    simulate(
        t,
        "negative link",
        edit("l1_m = 0.05", "l1_m = -0.05"),
        &["@:127:8: l1_m = -0.05 must be positive"],
    );
    simulate(
        t,
        "negative mass",
        edit("mass_kg = 0.2", "mass_kg = -0.2"),
        &["@:137:11: mass_kg = -0.2 must not be negative"],
    );
    simulate(
        t,
        "limits reversed",
        edit("upper_rad = 1.0\n", "upper_rad = -2.0\n"),
        &["@:65:13: joint \"q1\": lower_rad = -1 must be below upper_rad = -2"],
    );
    simulate(
        t,
        "NaN limit",
        edit("upper_rad = 1.0\n", "upper_rad = nan\n"),
        &["@:66:13: expected a finite number in \"joint[0].upper_rad\", found NaN"],
    );
    simulate(
        t,
        "infinite limit",
        edit("upper_rad = 1.0\n", "upper_rad = inf\n"),
        &["@:66:13: expected a finite number in \"joint[0].upper_rad\", found inf"],
    );
    simulate(
        t,
        "1e308 limit",
        edit("upper_rad = 1.0\n", "upper_rad = 1e308\n"),
        &[
            "@:66:13: joint[0].upper_rad = 1e308 rad is out of range: an angle must lie within ±1000 rad",
        ],
    );
    simulate(
        t,
        "1e308 length",
        edit("a_m = 0.35", "a_m = 1e308"),
        &["@:", "a_m = 1e308 m is out of range"],
    );
    simulate(
        t,
        "infinite length",
        edit("a_m = 0.35", "a_m = inf"),
        &["@:", "found inf"],
    );
    simulate(
        t,
        "joint out of order",
        edit("joint = 7\n", "joint = 9\n"),
        &["@:60:9: [[dh]] row 7 has joint 9, expected 7"],
    );
    simulate(
        t,
        "joint twice",
        edit("joint = 4\n", "joint = 3\n"),
        &["@:39:9: [[dh]] row 4 has joint 3, expected 4"],
    );
    simulate(
        t,
        "joint name twice",
        edit("name = \"q2\"", "name = \"q1\""),
        &["@:70:8: joint name \"q1\" is used twice"],
    );
    simulate(
        t,
        "deep array",
        format!("name = {}{}", "[".repeat(100_000), "]".repeat(100_000)),
        &["@:1:", "recurs"],
    );
    simulate(
        t,
        "deep inline table",
        format!("a = {}1{}", "{b = ".repeat(50_000), "}".repeat(50_000)),
        &["@:1:", "recurs"],
    );
    simulate(
        t,
        "deep dotted table",
        format!("[{}]\n", vec!["a"; 20_000].join(".")),
        &["@:1:1: recursion limit"],
    );
    simulate(
        t,
        "huge file of unknown keys",
        (0..50_000).map(|i| format!("k{i} = {i}\n")).collect(),
        &["@:1:1: "],
    );
    simulate(
        t,
        "no cable encoder",
        {
            let i = text.find("[cable_encoder]").unwrap_or(text.len());
            text[..i].to_owned()
        },
        &["the device has no [cable_encoder]"],
    );
}

fn urdf_cases(t: &mut Table) {
    const C: &str = "URDF";
    let text =
        std::fs::read_to_string(root().join("fixtures/mukca/urdf/iiwa14.urdf")).expect("urdf");
    let import = |t: &mut Table, name: &str, body: String, tip: &str, needles: &[&str]| {
        let path = t.file(&format!("urdf/{}.urdf", name.replace(' ', "-")), body);
        let needles: Vec<String> = needles.iter().map(|n| n.replace("@", &path)).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(C, name, &["import-urdf", &path, "--tip", tip], 2, &needles);
    };
    let edit = |from: &str, to: &str| {
        assert!(text.contains(from), "{from}");
        text.replacen(from, to, 1)
    };
    import(
        t,
        "empty",
        String::new(),
        "ball_link",
        &["@: not a valid URDF"],
    );
    import(
        t,
        "truncated",
        text[..text.len() / 2].to_owned(),
        "ball_link",
        &["@:", "syntax error"],
    );
    import(t, "not XML", "robot: {}".into(), "ball_link", &["@:"]);
    import(
        t,
        "missing parent link",
        edit(
            "<parent link=\"link_2\"/>",
            "<parent link=\"link_nowhere\"/>",
        ),
        "ball_link",
        &["@:89:3: joint \"joint_a3\": parent link \"link_nowhere\" is not defined"],
    );
    import(
        t,
        "a length with a unit (360mm)",
        edit("xyz=\"-0.00043624 0 0.36\"", "xyz=\"-0.00043624 0 360mm\""),
        "ball_link",
        &[
            "@:83:5: joint \"joint_a2\" <origin xyz>: expected 3 numbers separated by spaces (m: URDF values carry no unit), found \"-0.00043624 0 360mm\" (\"360mm\" is not a number)",
        ],
    );
    import(
        t,
        "a joint name twice",
        edit("<joint name=\"joint_a2\"", "<joint name=\"joint_a1\""),
        "ball_link",
        &["@:82:3: a second <joint> named \"joint_a1\": joint names must be unique"],
    );
    import(
        t,
        "missing child link",
        edit("<child link=\"link_3\"/>", "<child link=\"link_nowhere\"/>"),
        "ball_link",
        &["@:89:3: joint \"joint_a3\": child link \"link_nowhere\" is not defined"],
    );
    import(
        t,
        "two parents",
        edit("<child link=\"link_3\"/>", "<child link=\"link_2\"/>"),
        "ball_link",
        &["@:89:3: link \"link_2\" has two parent joints, \"joint_a2\" and \"joint_a3\""],
    );
    import(
        t,
        "loop",
        edit("<parent link=\"base_link\"/>", "<parent link=\"link_5\"/>"),
        "ball_link",
        &["@: the joints above link \"ball_link\" form a loop"],
    );
    import(
        t,
        "unconnected tip",
        edit(
            "<link name=\"ball_link\">",
            "<link name=\"lost_link\"/>\n  <link name=\"ball_link\">",
        ),
        "lost_link",
        &["@:", "link \"lost_link\" is not connected to \"base_link\""],
    );
    import(
        t,
        "tip without moving joint",
        text.clone(),
        "base",
        &["@: no moving joint between the root link \"base_link\" and \"base\""],
    );
    import(
        t,
        "tip not a link",
        text.clone(),
        "no_link",
        &["@: no link named \"no_link\"; the links are: base_link"],
    );
    let mm = {
        let mut s = String::new();
        let mut rest = text.as_str();
        while let Some(i) = rest.find("xyz=\"") {
            s.push_str(&rest[..i + 5]);
            rest = &rest[i + 5..];
            let end = rest.find('"').unwrap_or(0);
            let scaled: Vec<String> = rest[..end]
                .split_whitespace()
                .map(|v| format!("{}", v.parse::<f64>().unwrap_or(0.0) * 1000.0))
                .collect();
            s.push_str(&scaled.join(" "));
            rest = &rest[end..];
        }
        s.push_str(rest);
        s
    };
    import(
        t,
        "lengths in mm",
        mm.clone(),
        "ball_link",
        &[
            "@:",
            "more than 50 m: URDF lengths are in metres, these look like millimetres",
        ],
    );
    import(
        t,
        "origin 1e308",
        edit("xyz=\"-0.00043624 0 0.36\"", "xyz=\"-0.00043624 0 1e308\""),
        "ball_link",
        &[
            "@:",
            "joint \"joint_a2\" <origin xyz> = 1e308 m is out of range",
        ],
    );
    import(
        t,
        "origin NaN",
        edit("xyz=\"-0.00043624 0 0.36\"", "xyz=\"-0.00043624 0 NaN\""),
        "ball_link",
        &["@:", "joint_a2"],
    );
    import(
        t,
        "origin text",
        edit("xyz=\"-0.00043624 0 0.36\"", "xyz=\"left up 0.36\""),
        "ball_link",
        &["@:"],
    );
    import(
        t,
        "zero axis",
        text.replace("<axis xyz=\"0 0 1\"/>", "<axis xyz=\"0 0 0\"/>"),
        "ball_link",
        &["@: joint \"joint_a1\": axis [0.0, 0.0, 0.0] has no direction"],
    );
    import(
        t,
        "unknown joint type",
        edit("type=\"revolute\"", "type=\"wobbly\""),
        "ball_link",
        &["@: not a valid URDF", "wobbly"],
    );
    import(
        t,
        "limits reversed",
        edit(
            "lower=\"-2.9668\" upper=\"2.9668\"",
            "lower=\"2.9668\" upper=\"-2.9668\"",
        ),
        "ball_link",
        &["@:", "joint_a1"],
    );
    import(
        t,
        "deep nesting",
        format!(
            "<robot name=\"r\">{}{}</robot>",
            "<link name=\"a\">".repeat(100_000),
            "</link>".repeat(100_000)
        ),
        "a",
        &["@:1:"],
    );
    // The calibration path reads the same URDF.
    let front = fixture("mukca/data/kuka_14/front");
    let mm_path = t.file("urdf/calibrate-mm.urdf", &mm);
    t.add(
        C,
        "calibrating a URDF in mm",
        &[
            "calibrate",
            "--device",
            &mm_path,
            "--data",
            &front,
            "--model",
            "geometric",
        ],
        2,
        &[
            &format!("importing {mm_path}"),
            "these look like millimetres",
        ],
    );
    let nop = t.file(
        "urdf/calibrate-two-parents.urdf",
        edit("<child link=\"link_3\"/>", "<child link=\"link_2\"/>"),
    );
    t.add(
        C,
        "calibrating a URDF with two parents",
        &["calibrate", "--device", &nop, "--data", &front],
        2,
        &[&format!(
            "{nop}:89:3: link \"link_2\" has two parent joints"
        )],
    );
}

/// A placement folder `name` with `hole_0.csv` = `hole_0` and the real `hole_1.csv`.
fn placement(t: &Table, name: &str, hole_0: &str) -> String {
    let front = root().join("fixtures/mukca/data/kuka_14/front");
    t.file(&format!("mukca/{name}/hole_0.csv"), hole_0);
    let one = std::fs::read(front.join("hole_1.csv")).expect("hole_1");
    t.file(&format!("mukca/{name}/hole_1.csv"), one);
    t.path(&format!("mukca/{name}"))
}

fn mukca_cases(t: &mut Table) {
    const C: &str = "MUKCa socket folders";
    let iiwa = fixture("mukca/urdf/iiwa14.urdf");
    let text = std::fs::read_to_string(root().join("fixtures/mukca/data/kuka_14/front/hole_0.csv"))
        .expect("hole_0");
    let rows: Vec<Vec<String>> = (text.lines())
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    let calibrate = |t: &mut Table, name: &str, body: String, code, needles: &[&str]| {
        let dir = placement(t, &name.replace(' ', "-"), &body);
        let hole = format!("{dir}/hole_0.csv");
        let needles: Vec<String> = needles.iter().map(|n| n.replace("@", &hole)).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(
            C,
            name,
            &[
                "calibrate",
                "--device",
                &iiwa,
                "--data",
                &dir,
                "--model",
                "geometric",
            ],
            code,
            &needles,
        );
    };
    calibrate(
        t,
        "empty socket file",
        String::new(),
        2,
        &["@: expected at least 1 data rows, found 0"],
    );
    calibrate(
        t,
        "semicolons",
        text.replace(',', ";"),
        2,
        &["@:1:1: expected comma-separated columns", "semicolons"],
    );
    calibrate(
        t,
        "tabs",
        text.replace(',', "\t"),
        2,
        &["@:1:1: expected comma-separated columns", "tabs"],
    );
    for (name, line, column, value, needle) in [
        (
            "NaN",
            2,
            2,
            "NaN",
            "@:2:2: expected a finite number in \"q2\", found NaN",
        ),
        (
            "inf",
            3,
            7,
            "inf",
            "@:3:7: expected a finite number in \"q7\", found inf",
        ),
        (
            "1e308",
            4,
            1,
            "1e308",
            "@:4:1: joint \"joint_a1\" = 1e308 rad is outside",
        ),
        (
            "far outside the limits",
            5,
            1,
            "10",
            "@:5:1: joint \"joint_a1\" = 10 rad is outside [-2.9668, 2.9668] rad",
        ),
        (
            "degrees",
            5,
            4,
            "45",
            "@:5:4: joint \"joint_a4\" = 45 rad is outside [-2.0942, 2.0942] rad",
        ),
        (
            "past the slack",
            6,
            2,
            "-2.6",
            "@:6:2: joint \"joint_a2\" = -2.6 rad is outside [-2.0942, 2.0942] rad",
        ),
        (
            "text",
            7,
            3,
            "abc",
            "@:7:3: expected a number in column \"q3\", found \"abc\"",
        ),
        (
            "empty cell",
            7,
            3,
            "",
            "@:7:3: expected a number in column \"q3\", found \"\"",
        ),
    ] {
        calibrate(t, name, with_cell(&rows, line, column, value), 2, &[needle]);
    }
    calibrate(
        t,
        "within the slack",
        with_cell(&rows, 6, 2, "2.2"),
        0,
        &[
            "@:6:2: joint \"joint_a2\" = 2.2 rad is outside its limits [-2.0942, 2.0942] rad; such readings are used as they are",
        ],
    );
    let mut short = rows.clone();
    short[3].truncate(6);
    calibrate(
        t,
        "short row",
        csv(&short),
        2,
        &["@:4: expected 7 fields, found 6"],
    );
    calibrate(
        t,
        "six joints",
        csv(&rows.iter().map(|r| r[..6].to_vec()).collect::<Vec<_>>()),
        2,
        &["@:1: expected 7 joints (as the device has), found 6"],
    );
    calibrate(
        t,
        "a header row",
        format!("q1,q2,q3,q4,q5,q6,q7\n{text}"),
        2,
        &["@:1:1: expected a number in column \"q1\", found \"q1\""],
    );
    let copies: String = std::iter::repeat_n(format!("{}\n", rows[0].join(",")), 200).collect();
    calibrate(
        t,
        "200 copies of one configuration",
        copies,
        2,
        &["@: the 200 rows are copies of one joint configuration"],
    );
    let mut dup = rows.clone();
    dup.push(rows[0].clone());
    dup.push(rows[1].clone());
    calibrate(
        t,
        "duplicated rows",
        csv(&dup),
        0,
        &[
            "the joint readings and measurements repeat those of line 1 (2 rows in all repeat an earlier row)",
        ],
    );
    // Folder structure.
    let gap = t.path("mukca/gap");
    t.file("mukca/gap/hole_0.csv", &text);
    t.file("mukca/gap/hole_2.csv", &text);
    t.add(
        C,
        "socket numbers with a gap",
        &["calibrate", "--device", &iiwa, "--data", &gap],
        2,
        &[&format!("{gap}: hole_1.csv is missing")],
    );
    let none = t.path("mukca/none");
    t.file("mukca/none/readme.txt", "nothing here");
    t.add(
        C,
        "no socket files",
        &["calibrate", "--device", &iiwa, "--data", &none],
        2,
        &[&format!("{none}: no socket file hole_0.csv")],
    );
    let front = fixture("mukca/data/kuka_14/front");
    let far = t.path("mukca/far-outside-the-limits");
    t.add(
        C,
        "bad test folder",
        &[
            "calibrate",
            "--device",
            &iiwa,
            "--data",
            &front,
            "--test",
            &far,
        ],
        2,
        &[
            &format!("reading measurements in {far}"),
            "joint \"joint_a1\" = 10 rad is outside",
        ],
    );
    t.add(
        C,
        "--folds above the data",
        &[
            "calibrate",
            "--device",
            &iiwa,
            "--data",
            &front,
            "--folds",
            "63",
        ],
        2,
        &["--folds 63 is not possible with 62 training configurations (2 to 62)"],
    );
    t.add(
        C,
        "--folds 1000",
        &[
            "calibrate",
            "--device",
            &iiwa,
            "--data",
            &front,
            "--folds",
            "1000",
        ],
        2,
        &["--folds 1000", "62 training configurations"],
    );
}

fn measurement_cases(t: &mut Table) {
    const C: &str = "measurement CSV and YAML";
    let ur10 = fixture("figaroh/ur10/ur10_robot.urdf");
    let text = std::fs::read_to_string(root().join("fixtures/figaroh/ur10/calibration.csv"))
        .expect("ur10 data");
    let rows: Vec<Vec<String>> = (text.lines())
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    let calibrate = |t: &mut Table, name: &str, body: String, needles: &[&str]| {
        let path = t.file(&format!("measure/{}.csv", name.replace(' ', "-")), body);
        let needles: Vec<String> = needles.iter().map(|n| n.replace("@", &path)).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(
            C,
            name,
            &[
                "calibrate",
                "--device",
                &ur10,
                "--tip",
                "tool0",
                "--data",
                &path,
            ],
            2,
            &needles,
        );
    };
    calibrate(
        t,
        "NaN position",
        with_cell(&rows, 3, 1, "NaN"),
        &["@:3:1: expected a finite number in \"x1\", found NaN"],
    );
    calibrate(
        t,
        "1e308 position",
        with_cell(&rows, 3, 2, "1e308"),
        &["@:3:2: y1 = 1e308 m is out of range"],
    );
    calibrate(
        t,
        "joint far outside",
        with_cell(&rows, 4, 7, "40"),
        &["@:4:7: joint \"shoulder_pan_joint\" = 40 rad is outside"],
    );
    calibrate(
        t,
        "text in a cell",
        with_cell(&rows, 5, 9, "left"),
        &["@:5:9: expected a number in column \"elbow_joint\", found \"left\""],
    );
    calibrate(
        t,
        "semicolons",
        text.replace(',', ";"),
        &["@:1:1: expected comma-separated columns", "semicolons"],
    );
    let mut header = rows.clone();
    header[0][7] = "shoulder_pan_joint".into();
    calibrate(
        t,
        "duplicated column",
        csv(&header),
        &["@:1:8: column \"shoulder_pan_joint\" appears twice"],
    );
    let mut missing = rows.clone();
    for r in &mut missing {
        r.remove(8);
    }
    calibrate(
        t,
        "missing joint column",
        csv(&missing),
        &["@:", "elbow_joint"],
    );
    let mut distance = rows.clone();
    distance[0].push("distance_m".into());
    for (i, r) in distance.iter_mut().enumerate().skip(1) {
        r.push(if i == 4 { "-0.2".into() } else { "0.5".into() });
    }
    calibrate(
        t,
        "negative distance",
        csv(&distance),
        &["@:5: column 13 (\"distance_m\"): expected a distance ≥ 0, found -0.2"],
    );
    calibrate(
        t,
        "header only",
        csv(&rows[..1]),
        &["@: expected at least 1 data rows"],
    );
    calibrate(
        t,
        "missing header row",
        csv(&rows[1..]),
        &[
            "@:1:1: the first line holds numbers (0.9088284523365023 …), not column names: the header row is missing",
        ],
    );
    calibrate(
        t,
        "three rows with the default 5 folds",
        csv(&rows[..4]),
        &[
            "3 training rows (three-rows-with-the-default-5-folds: 3 rows) are too few for 5-fold cross-validation (--folds 5)",
            "needs at least 5 training rows",
        ],
    );
    let mut empty_markers = rows.clone();
    for r in empty_markers.iter_mut().skip(1) {
        for cell in r.iter_mut().take(6) {
            cell.clear();
        }
    }
    calibrate(
        t,
        "every marker cell empty",
        csv(&empty_markers),
        &[
            "@:1:1: the measurement columns (x1, y1, z1, phix1, phiy1, phiz1) are empty in all 23 rows",
        ],
    );
    // Semicolons with --test-last: the separator is the problem, not the option.
    let semicolons = t.file("measure/semicolons-test-last.csv", text.replace(',', ";"));
    t.add(
        C,
        "semicolons with --test-last",
        &[
            "calibrate",
            "--device",
            &ur10,
            "--tip",
            "tool0",
            "--data",
            &semicolons,
            "--test-last",
            "0.3",
        ],
        2,
        &[&format!("{semicolons}:1:1: expected comma-separated columns, found cells separated by semicolons")],
    );
    // industrial_calibration YAML on its positioner.
    let positioner = fixture("industrial-calibration/two_axis_positioner.toml");
    let measurements = fixture("industrial-calibration/measurements.yaml");
    // The unit flags apply to its pose and joints; an edit of a column without a unit or of
    // the wrong kind is refused.
    for (edit, said) in [
        (
            "qw=mm",
            "--column-unit qw=mm: column \"qw\" holds a quaternion component (no unit): it takes no unit, sign or offset",
        ),
        (
            "x=deg",
            "--column-unit x=deg: deg is an angle unit but column \"x\" holds lengths",
        ),
    ] {
        t.add(
            C,
            &format!("YAML with --column-unit {edit}"),
            &[
                "calibrate",
                "--device",
                &positioner,
                "--data",
                &measurements,
                "--column-unit",
                edit,
            ],
            2,
            &[&format!("{measurements}:1: {said}")],
        );
    }
    let yaml =
        std::fs::read_to_string(root().join("fixtures/industrial-calibration/measurements.yaml"))
            .expect("yaml");
    let read_yaml = |t: &mut Table, name: &str, body: String, needles: &[&str]| {
        let path = t.file(&format!("measure/{}.yaml", name.replace(' ', "-")), body);
        let needles: Vec<String> = needles.iter().map(|n| n.replace("@", &path)).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(
            C,
            name,
            &["calibrate", "--device", &positioner, "--data", &path],
            2,
            &needles,
        );
    };
    read_yaml(t, "empty YAML", String::new(), &["@:"]);
    read_yaml(
        t,
        "deep flow YAML",
        format!("a: {}{}", "[".repeat(100_000), "]".repeat(100_000)),
        &["@:1:", "deeper than 32 levels"],
    );
    read_yaml(
        t,
        "deep block YAML",
        (0..2000)
            .map(|i| format!("{}k{i}:\n", " ".repeat(i)))
            .collect(),
        &["@:33:33: ", "deeper than 32 levels"],
    );
    read_yaml(
        t,
        "deep sequence YAML",
        format!("a:\n  {}x\n", "- ".repeat(5000)),
        &["@:2:", "deeper than 32 levels"],
    );
    read_yaml(
        t,
        "YAML joint far outside",
        yaml.replacen("  - -0.5229825973510742", "  - -52.29825973510742", 1),
        &[
            "@:1:1: observation \"1593701755\": joint \"q1\" = -52.29825973510742 is outside [-3.141592653589793, 3.141592653589793]",
        ],
    );
    read_yaml(
        t,
        "YAML quaternion not unit",
        yaml.replacen("qw: 0.31366235539812415", "qw: 3.1366235539812415", 1),
        &["@:1:1: observation \"1593701755\"", "quaternion norm"],
    );
    read_yaml(
        t,
        "YAML NaN position",
        yaml.replacen("x: -0.5325496958762886", "x: .nan", 1),
        &["@:1:1: observation \"1593701755\"", "finite position"],
    );
    read_yaml(
        t,
        "YAML moving camera",
        yaml.replacen("camera_joints: []", "camera_joints: [0.1]", 1),
        &["@:1:1: observation \"1593701755\": camera_joints is not empty"],
    );
    read_yaml(
        t,
        "YAML unknown field",
        yaml.replacen("camera_joints: []", "camera_joints: []\n  colour: red", 1),
        &["@:1:1: observation \"1593701755\"", "colour"],
    );
    read_yaml(
        t,
        "YAML three joints",
        yaml.replacen("  target_joints:\n", "  target_joints:\n  - 0.1\n", 1),
        &[
            "@:1:1: observation \"1593701755\": expected 2 target_joints (as the device has), found 3",
        ],
    );
    read_yaml(t, "YAML not a mapping", "- 1\n- 2\n".into(), &["@:"]);
    read_yaml(
        t,
        "YAML tab indentation",
        yaml.replacen("  camera_joints", "\tcamera_joints", 1),
        &["@:2:"],
    );
}

fn option_cases(t: &mut Table) {
    const C: &str = "options";
    let device = fixture("reference-device/device.toml");
    let ur10_urdf = fixture("figaroh/ur10/ur10_robot.urdf");
    let truth = fixture("reference-device/truth.toml");
    let calibrated = fixture("reference-device/calibrated.toml");
    let iiwa = fixture("mukca/urdf/iiwa14.urdf");
    let front = fixture("mukca/data/kuka_14/front");
    t.file("options/unused.txt", "");
    let out_csv = t.path("options/out.csv");
    for command in [
        "calibrate",
        "reproduce",
        "simulate",
        "diagnose",
        "blind-test",
        "force",
        "plan-poses",
        "pose-study",
        "pose-bound",
        "import-urdf",
    ] {
        t.add(
            C,
            &format!("{command}: unknown option"),
            &[command, "--frobnicate", "3"],
            2,
            &["unexpected argument '--frobnicate' found"],
        );
    }
    t.add(
        C,
        "unknown command",
        &["calibrat"],
        2,
        &["unrecognized subcommand 'calibrat'"],
    );
    t.add(C, "no command", &[], 2, &["Usage: hapcal <COMMAND>"]);
    let arm = |extra: &[&str]| -> Vec<String> {
        [
            "calibrate",
            "--device",
            iiwa.as_str(),
            "--data",
            front.as_str(),
            "--model",
            "geometric",
        ]
        .iter()
        .chain(extra)
        .map(|s| (*s).to_owned())
        .collect()
    };
    for (name, extra, needles) in [
        (
            "--socket-distance-m negative",
            &["--socket-distance-m", "-0.05"][..],
            &["--socket-distance-m must be a positive length, got -0.05"][..],
        ),
        (
            "--socket-distance-m zero",
            &["--socket-distance-m", "0"],
            &["--socket-distance-m must be a positive length, got 0"],
        ),
        (
            "--socket-distance-m NaN",
            &["--socket-distance-m", "NaN"],
            &["--socket-distance-m must be a positive length, got NaN"],
        ),
        (
            "--socket-distance-m inf",
            &["--socket-distance-m", "inf"],
            &["--socket-distance-m must be a positive length, got inf"],
        ),
        (
            "--socket-distance-m text",
            &["--socket-distance-m", "five"],
            &["invalid value 'five' for '--socket-distance-m"],
        ),
        (
            "--sigma-m negative",
            &["--sigma-m", "-1e-4"],
            &["--sigma-m must lie between 1e-9 and 0.1 m, got -1e-4"],
        ),
        (
            "--sigma-m zero",
            &["--sigma-m", "0"],
            &["--sigma-m must lie between 1e-9 and 0.1 m, got 0e0"],
        ),
        (
            "--sigma-m NaN",
            &["--sigma-m", "nan"],
            &["--sigma-m must lie between 1e-9 and 0.1 m, got NaN"],
        ),
        (
            "--sigma-m 1e-300",
            &["--sigma-m", "1e-300"],
            &["--sigma-m must lie between 1e-9 and 0.1 m, got 1e-300"],
        ),
        (
            "--sigma-m 1 (a metre)",
            &["--sigma-m", "1"],
            &["--sigma-m must lie between 1e-9 and 0.1 m, got 1e0"],
        ),
        (
            "--sigma-rad negative",
            &["--sigma-rad", "-1"],
            &["--sigma-rad must lie between 1e-9 and 0.5 rad, got -1e0"],
        ),
        (
            "--test-last above 1",
            &["--test-last", "1.5"],
            &["--test-last must lie strictly between 0 and 1", "got 1.5"],
        ),
        (
            "--test-last zero",
            &["--test-last", "0"],
            &["--test-last must lie strictly between 0 and 1", "got 0"],
        ),
        (
            "--test-last negative",
            &["--test-last", "-0.3"],
            &["--test-last must lie strictly between 0 and 1", "got -0.3"],
        ),
        (
            "--folds 0",
            &["--folds", "0"],
            &["--folds", "must be at least 2, got 0"],
        ),
        (
            "--folds 1",
            &["--folds", "1"],
            &["--folds", "must be at least 2, got 1"],
        ),
        (
            "--folds negative",
            &["--folds", "-3"],
            &["--folds", "expected a whole number, got \"-3\""],
        ),
        (
            "--folds text",
            &["--folds", "many"],
            &["--folds", "expected a whole number, got \"many\""],
        ),
        (
            "--test-last text",
            &["--test-last", "most"],
            &["invalid value 'most' for '--test-last"],
        ),
        (
            "--length-unit km",
            &["--length-unit", "km"],
            &["invalid value 'km' for '--length-unit"],
        ),
        (
            "--angle-unit gon",
            &["--angle-unit", "gon"],
            &[
                "invalid value 'gon' for '--angle-unit",
                "rad, deg, grad, rev",
            ],
        ),
        (
            "--column-unit without a unit",
            &["--column-unit", "q3"],
            &[
                "invalid value 'q3' for '--column-unit <COLUMNS=UNIT>'",
                "expected COLUMNS=VALUE",
            ],
        ),
        (
            "--column-offset that is not a number",
            &["--column-offset", "q3=zero"],
            &[
                "invalid value 'q3=zero' for '--column-offset <COLUMNS=VALUE>'",
                "expected a finite number",
            ],
        ),
        (
            "--joint on an arm",
            &["--joint"],
            &["--joint applies to a haptic device"],
        ),
    ] {
        let args = arm(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        t.add(C, &format!("calibrate {name}"), &args, 2, needles);
    }
    for (name, args, needles) in [
        (
            "simulate --poses 0",
            vec!["simulate", "--poses", "0", "--out", &out_csv],
            vec!["--poses", "must lie between 1 and"],
        ),
        (
            "simulate --poses -1",
            vec!["simulate", "--poses", "-1", "--out", &out_csv],
            vec!["--poses", "expected a whole number, got \"-1\""],
        ),
        (
            "simulate --poses huge",
            vec![
                "simulate",
                "--poses",
                "99999999999999999999999",
                "--out",
                &out_csv,
            ],
            vec!["--poses", "expected a whole number"],
        ),
        (
            "simulate --seed negative",
            vec!["simulate", "--seed", "-4", "--out", &out_csv],
            vec!["invalid value '-4' for '--seed"],
        ),
        (
            "simulate --period-s 0",
            vec!["simulate", "--motion", "--period-s", "0", "--out", &out_csv],
            vec!["--period-s must be a finite, positive time, s, got 0"],
        ),
        (
            "simulate --period-s negative",
            vec![
                "simulate",
                "--motion",
                "--period-s",
                "-0.5",
                "--out",
                &out_csv,
            ],
            vec!["--period-s must be a finite, positive time, s, got -0.5"],
        ),
        (
            "simulate --period-s NaN",
            vec![
                "simulate",
                "--motion",
                "--period-s",
                "NaN",
                "--out",
                &out_csv,
            ],
            vec!["--period-s must be a finite, positive time, s, got NaN"],
        ),
        (
            "simulate --noise unknown",
            vec!["simulate", "--noise", "pink", "--out", &out_csv],
            vec!["--noise must be `paper` or `arc-length`, got \"pink\""],
        ),
        (
            "simulate --effect unknown",
            vec!["simulate", "--effect", "gremlins:j2=1", "--out", &out_csv],
            vec!["gremlins"],
        ),
        (
            "simulate --effect bad value",
            vec![
                "simulate",
                "--effect",
                "backlash:j2=lots",
                "--out",
                &out_csv,
            ],
            vec!["lots"],
        ),
        (
            "simulate missing --out",
            vec!["simulate"],
            vec!["--out <OUT>"],
        ),
        (
            "simulate missing truth",
            vec![
                "simulate",
                "--truth",
                "/no/such/truth.toml",
                "--out",
                &out_csv,
            ],
            vec!["/no/such/truth.toml"],
        ),
        (
            "force --gain negative",
            force_args(
                &device,
                &truth,
                &calibrated,
                &["--gain", "-5", "--svg", "unused.svg"],
            ),
            vec!["--gain must lie between 0 and 1000", "got -5e0"],
        ),
        (
            "force --gain NaN",
            force_args(
                &device,
                &truth,
                &calibrated,
                &["--gain", "NaN", "--svg", "unused.svg"],
            ),
            vec!["--gain must lie between 0 and 1000", "got NaN"],
        ),
        (
            "force --poses 0",
            force_args(&device, &truth, &calibrated, &["--poses", "0"]),
            vec!["--poses", "must lie between 1 and"],
        ),
        (
            "force missing --truth",
            vec!["force", "--device", &device, "--calibrated", &calibrated],
            vec!["--truth <TRUTH>"],
        ),
        (
            "plan-poses --count 0",
            vec![
                "plan-poses",
                "--device",
                &device,
                "--count",
                "0",
                "--candidates",
                "10",
                "--out",
                &out_csv,
            ],
            vec!["--count", "must lie between 1 and 10000, got 0"],
        ),
        (
            "plan-poses --count above --candidates",
            vec![
                "plan-poses",
                "--device",
                &device,
                "--count",
                "50",
                "--candidates",
                "10",
                "--out",
                &out_csv,
            ],
            vec!["--count must be between 1 and the number of candidates (10), got 50"],
        ),
        (
            "plan-poses --sigma-m 1e308",
            vec![
                "plan-poses",
                "--device",
                &device,
                "--sigma-m",
                "1e308",
                "--out",
                &out_csv,
            ],
            vec!["--sigma-m must lie between 1e-9 and 0.1 m, got 1e308"],
        ),
        (
            "plan-poses --sigma-m 1e-12",
            vec![
                "plan-poses",
                "--device",
                &device,
                "--sigma-m",
                "1e-12",
                "--out",
                &out_csv,
            ],
            vec!["--sigma-m must lie between 1e-9 and 0.1 m, got 1e-12"],
        ),
        (
            "plan-poses --criterion unknown",
            vec![
                "plan-poses",
                "--device",
                &device,
                "--criterion",
                "best",
                "--out",
                &out_csv,
            ],
            vec!["invalid value 'best' for '--criterion"],
        ),
        (
            "plan-poses --measurement unknown",
            vec![
                "plan-poses",
                "--device",
                &device,
                "--measurement",
                "vibes",
                "--out",
                &out_csv,
            ],
            vec!["invalid value 'vibes' for '--measurement"],
        ),
        (
            "blind-test --cases 0",
            vec!["blind-test", "--cases", "0"],
            vec!["--cases", "must lie between 1 and 100000, got 0"],
        ),
        (
            "reproduce --design unknown",
            vec!["reproduce", "--design", "z-optimal"],
            vec!["invalid value 'z-optimal' for '--design"],
        ),
        (
            "import-urdf without --tip",
            vec!["import-urdf", &iiwa],
            vec!["--tip <TIP>"],
        ),
        (
            "import-urdf without a file",
            vec!["import-urdf", "--tip", "ball_link"],
            vec!["<URDF>"],
        ),
        (
            "diagnose without --data",
            vec!["diagnose", "--device", &device],
            vec!["--data: give the log or the measurements to diagnose"],
        ),
        (
            "diagnose --baseline unknown",
            vec![
                "diagnose",
                "--device",
                &device,
                "--data",
                &fixture("reference-device/log.csv"),
                "--baseline",
                "most",
                "--svg",
                &t.path("options/d.svg"),
            ],
            vec!["most"],
        ),
        (
            "diagnose --baseline transmissions on a robot",
            vec![
                "diagnose",
                "--device",
                &ur10_urdf,
                "--tip",
                "wrist_3_link",
                "--data",
                &fixture("figaroh/ur10/calibration.csv"),
                "--baseline",
                "transmissions",
                "--svg",
                &t.path("options/d-robot.svg"),
            ],
            vec!["transmissions", "geometric calibration"],
        ),
    ] {
        t.add(C, name, &args, 2, &needles);
    }
    t.add(
        C,
        "calibrate --model unknown",
        &[
            "calibrate",
            "--device",
            &iiwa,
            "--data",
            &front,
            "--model",
            "quantum",
        ],
        2,
        &["invalid value 'quantum' for '--model"],
    );
}

fn output_cases(t: &mut Table) {
    const C: &str = "outputs";
    let device_copy = t.file(
        "outputs/device.toml",
        std::fs::read(root().join("fixtures/reference-device/device.toml")).expect("device"),
    );
    let log = t.file("outputs/log.csv", csv(&reference_log(60)));
    let truth = fixture("reference-device/truth.toml");
    let calibrated = fixture("reference-device/calibrated.toml");
    let iiwa = fixture("mukca/urdf/iiwa14.urdf");
    let front = fixture("mukca/data/kuka_14/front");
    let missing = t.path("outputs/no-such-folder/x");
    let calibrate = |extra: &[&str]| -> Vec<String> {
        [
            "calibrate",
            "--device",
            device_copy.as_str(),
            "--data",
            log.as_str(),
        ]
        .iter()
        .chain(extra)
        .map(|s| (*s).to_owned())
        .collect()
    };
    let cases: Vec<(&str, Vec<String>, Vec<String>)> = vec![
        (
            "calibrate --out = the device",
            calibrate(&["--out", &device_copy]),
            vec![format!("cannot write {device_copy}"), "is an input".into()],
        ),
        (
            "calibrate --out = the log",
            calibrate(&["--out", &log]),
            vec![format!("cannot write {log}")],
        ),
        (
            "calibrate --out = the test log",
            calibrate(&["--test", &log, "--out", &log]),
            vec![format!("cannot write {log}")],
        ),
        (
            "calibrate --out in a missing folder",
            calibrate(&["--out", &format!("{missing}/c.toml")]),
            vec![
                format!("cannot write {missing}/c.toml"),
                "does not exist".into(),
            ],
        ),
        (
            "calibrate --out .csv",
            calibrate(&["--out", &t.path("outputs/c.csv")]),
            vec!["the calibrated device is written as .toml or .urdf, not as .csv".into()],
        ),
        (
            "calibrate --out .json",
            calibrate(&["--out", &t.path("outputs/c.json")]),
            vec!["not as .json".into()],
        ),
        (
            "calibrate --out a folder",
            calibrate(&["--out", &t.path("outputs")]),
            vec![format!("cannot write {}", t.path("outputs"))],
        ),
        (
            "calibrate --out = the URDF",
            [
                "calibrate",
                "--device",
                &iiwa,
                "--data",
                &front,
                "--out",
                &iiwa,
            ]
            .map(str::to_owned)
            .to_vec(),
            vec![format!("cannot write {iiwa}")],
        ),
        (
            "simulate --out = the device",
            ["simulate", "--device", &device_copy, "--out", &device_copy]
                .map(str::to_owned)
                .to_vec(),
            vec!["the simulated log is written as .csv, not as .toml".into()],
        ),
        (
            "simulate --out in a missing folder",
            [
                "simulate",
                "--poses",
                "3",
                "--out",
                &format!("{missing}/log.csv"),
            ]
            .map(str::to_owned)
            .to_vec(),
            vec![
                format!("cannot write {missing}/log.csv"),
                "does not exist".into(),
            ],
        ),
        (
            "simulate --out .toml",
            ["simulate", "--out", &t.path("outputs/sim.toml")]
                .map(str::to_owned)
                .to_vec(),
            vec!["the simulated log is written as .csv, not as .toml".into()],
        ),
        (
            "simulate --out .urdf",
            ["simulate", "--out", &t.path("outputs/sim.urdf")]
                .map(str::to_owned)
                .to_vec(),
            vec!["the simulated log is written as .csv, not as .urdf".into()],
        ),
        (
            "plan-poses --out = the device",
            [
                "plan-poses",
                "--device",
                &device_copy,
                "--out",
                &device_copy,
            ]
            .map(str::to_owned)
            .to_vec(),
            vec!["not as .toml".into()],
        ),
        (
            "plan-poses --out in a missing folder",
            [
                "plan-poses",
                "--device",
                &device_copy,
                "--out",
                &format!("{missing}/p.csv"),
            ]
            .map(str::to_owned)
            .to_vec(),
            vec![format!("cannot write {missing}/p.csv")],
        ),
        (
            "plan-poses --out .svg",
            [
                "plan-poses",
                "--device",
                &device_copy,
                "--out",
                &t.path("outputs/p.svg"),
            ]
            .map(str::to_owned)
            .to_vec(),
            vec!["the planned poses is written as .csv, not as .svg".into()],
        ),
        (
            "force --svg = the device",
            force_args(&device_copy, &truth, &calibrated, &["--svg", &device_copy])
                .into_iter()
                .map(str::to_owned)
                .collect(),
            vec!["is written as .svg, not as .toml".into()],
        ),
        (
            "force --svg in a missing folder",
            force_args(
                &device_copy,
                &truth,
                &calibrated,
                &["--svg", &format!("{missing}/f.svg")],
            )
            .into_iter()
            .map(str::to_owned)
            .collect(),
            vec![format!("cannot write {missing}/f.svg")],
        ),
        (
            "force --svg .png",
            force_args(
                &device_copy,
                &truth,
                &calibrated,
                &["--svg", &t.path("outputs/f.png")],
            )
            .into_iter()
            .map(str::to_owned)
            .collect(),
            vec!["is written as .svg, not as .png".into()],
        ),
        (
            "diagnose --svg = the log",
            [
                "diagnose",
                "--device",
                &device_copy,
                "--data",
                &log,
                "--svg",
                &log,
            ]
            .map(str::to_owned)
            .to_vec(),
            vec!["not as .csv".into()],
        ),
        (
            "diagnose --svg in a missing folder",
            [
                "diagnose",
                "--device",
                &device_copy,
                "--data",
                &log,
                "--svg",
                &format!("{missing}/d.svg"),
            ]
            .map(str::to_owned)
            .to_vec(),
            vec![format!("cannot write {missing}/d.svg")],
        ),
        (
            "reproduce --out is a file",
            ["reproduce", "--out", &log].map(str::to_owned).to_vec(),
            vec![format!(
                "cannot write {log}: --out is an output folder, and this is a file"
            )],
        ),
        (
            "pose-study --out in a missing folder",
            ["pose-study", "--out", &format!("{missing}/s.md")]
                .map(str::to_owned)
                .to_vec(),
            vec![format!("{missing}/s.md")],
        ),
        (
            "pose-bound --out in a missing folder",
            ["pose-bound", "--out", &format!("{missing}/b.md")]
                .map(str::to_owned)
                .to_vec(),
            vec![format!("{missing}/b.md")],
        ),
    ];
    for (name, args, needles) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(C, name, &args, 2, &needles);
    }
}

/// Special output files, counts that would not fit in memory, absurd option values, options
/// that do not apply, and data given twice.
///
/// Returns the links to `/dev/null` and `/dev/full` that two cases write through: they must
/// still be links afterwards (a rename over them would have replaced the link, never the
/// device).
fn limit_cases(t: &mut Table) -> Vec<PathBuf> {
    const C: &str = "limits and misuse";
    let null = t.path("limits/null.csv");
    let full = t.path("limits/full.csv");
    for (link, device) in [(&null, "/dev/null"), (&full, "/dev/full")] {
        let folder = Path::new(link).parent().expect("in the scratch folder");
        std::fs::create_dir_all(folder).expect("scratch folder is writable");
        std::os::unix::fs::symlink(device, link).expect("scratch folder is writable");
    }
    let full_svg = t.path("limits/full.svg");
    std::os::unix::fs::symlink("/dev/full", &full_svg).expect("scratch folder is writable");
    let scratch_out = t.path("limits/x.csv");
    let truth_text = std::fs::read_to_string(root().join("fixtures/reference-device/truth.toml"))
        .expect("truth fixture");
    let far_truth = t.file(
        "limits/far-truth.toml",
        truth_text.replace("da1 = -1.1e-3", "da1 = 1e10"),
    );
    // Truths next to the fixture's device (their device path made absolute).
    let device_abs = show(&root().join("fixtures/reference-device/device.toml"));
    let truth_with = |t: &Table, name: &str, from: &str, to: &str| {
        let text = truth_text
            .replace(
                "device = \"device.toml\"",
                &format!("device = {device_abs:?}"),
            )
            .replacen(from, to, 1);
        assert!(text.contains(to), "{name}: {from} not in the truth fixture");
        t.file(&format!("limits/{name}"), text)
    };
    let phi0_high = truth_with(
        t,
        "phi0-high.toml",
        "phi0_rad = 0.5207963267948965",
        "phi0_rad = 3.5",
    );
    let phi0_negative = truth_with(
        t,
        "phi0-negative.toml",
        "phi0_rad = 0.5207963267948965",
        "phi0_rad = -0.1",
    );
    let phi0_folds = truth_with(
        t,
        "phi0-folds.toml",
        "phi0_rad = 0.5207963267948965",
        "phi0_rad = 2.0",
    );
    let negative_radius = truth_with(
        t,
        "negative-radius.toml",
        "r_o_m = 0.2e-3",
        "r_o_m = -0.2e-3",
    );
    let ratio_truth = t.file(
        "limits/ratio-truth.toml",
        truth_text.replacen("re = -0.025", "re = 1e6", 1),
    );
    let hole_1 =
        std::fs::read_to_string(root().join("fixtures/mukca/data/kuka_14/front/hole_1.csv"))
            .expect("hole_1");
    let copied = placement(t, "copied-socket", &hole_1);
    let ext_typo = t.file(
        "limits/ext-typo.csv",
        with_cell(&reference_log(60), 6, 10, "1e10"),
    );
    let device = fixture("reference-device/device.toml");
    let truth = fixture("reference-device/truth.toml");
    let calibrated = fixture("reference-device/calibrated.toml");
    let log = t.file("limits/log.csv", csv(&reference_log(60)));
    let log_copy = t.file("limits/log-copy.csv", csv(&reference_log(60)));
    let iiwa = fixture("mukca/urdf/iiwa14.urdf");
    let front = fixture("mukca/data/kuka_14/front");
    let calibrate = |extra: &[&str]| -> Vec<String> {
        [
            "calibrate",
            "--device",
            device.as_str(),
            "--data",
            log.as_str(),
        ]
        .iter()
        .chain(extra)
        .map(|s| (*s).to_owned())
        .collect()
    };
    let args = |a: &[&str]| -> Vec<String> { a.iter().map(|s| (*s).to_owned()).collect() };
    let cases: Vec<(&str, Vec<String>, i32, Vec<String>)> = vec![
        (
            "simulate --out a link to /dev/full",
            args(&["simulate", "--poses", "10", "--out", &full]),
            2,
            vec![format!("cannot write {full}: No space left on device")],
        ),
        (
            "diagnose --svg a link to /dev/full",
            args(&[
                "diagnose", "--device", &device, "--data", &log, "--svg", &full_svg,
            ]),
            2,
            vec![format!("cannot write {full_svg}: No space left on device")],
        ),
        (
            "diagnose (arm) --svg a link to /dev/full",
            args(&[
                "diagnose", "--device", &iiwa, "--data", &front, "--svg", &full_svg,
            ]),
            2,
            vec![format!("cannot write {full_svg}: No space left on device")],
        ),
        (
            "simulate --out a link to /dev/null",
            args(&["simulate", "--poses", "10", "--out", &null]),
            0,
            vec![],
        ),
        (
            "simulate --poses 10⁸",
            args(&["simulate", "--poses", "100000000", "--out", &scratch_out]),
            2,
            vec![
                "--poses".to_owned(),
                "must lie between 1 and 1000000, got 100000000".to_owned(),
            ],
        ),
        (
            "force --poses 10⁸",
            args(&force_args(&device, &truth, &calibrated, &["--poses", "100000000"])),
            2,
            vec![
                "--poses".to_owned(),
                "must lie between 1 and 100000".to_owned(),
            ],
        ),
        (
            "plan-poses --candidates 10⁶",
            args(&[
                "plan-poses",
                "--device",
                &device,
                "--candidates",
                "1000000",
                "--out",
                &scratch_out,
            ]),
            2,
            vec![
                "--candidates".to_owned(),
                "must lie between 1 and 100000".to_owned(),
            ],
        ),
        (
            "force --gain 1e300",
            args(&force_args(&device, &truth, &calibrated, &["--gain", "1e300"])),
            2,
            vec![
                "--gain must lie between 0 and 1000".to_owned(),
                "got 1e300".to_owned(),
            ],
        ),
        (
            "simulate --effect backlash:j2=1e10",
            args(&[
                "simulate",
                "--effect",
                "backlash:j2=1e10",
                "--out",
                &scratch_out,
            ]),
            2,
            vec!["j2 = 1e10 is outside [0, 0.1]".to_owned()],
        ),
        (
            "simulate --effect cable_angle:k=1e300",
            args(&[
                "simulate",
                "--effect",
                "cable_angle:k=1e300",
                "--out",
                &scratch_out,
            ]),
            2,
            vec!["k = 1e300 is outside [-1, 1]".to_owned()],
        ),
        (
            "simulate a truth with da1 = 1e10",
            args(&["simulate", "--truth", &far_truth, "--out", &scratch_out]),
            2,
            vec![format!("{far_truth}:22:7: da1 = 1e10 m is outside ±0.1 m")],
        ),
        (
            "simulate a truth with phi0_rad = 3.5 (past π)",
            args(&["simulate", "--truth", &phi0_high, "--out", &scratch_out]),
            2,
            vec![format!("{phi0_high}:106:12: phi0_rad = 3.5 rad is outside (0, π)")],
        ),
        (
            "force with a truth whose phi0_rad = -0.1",
            args(&force_args(&device, &phi0_negative, &calibrated, &[])),
            2,
            vec![format!("{phi0_negative}:106:12: phi0_rad = -0.1 rad is outside (0, π)")],
        ),
        (
            "simulate a truth whose crank folds flat within joint 4's range (phi0_rad = 2)",
            args(&["simulate", "--truth", &phi0_folds, "--out", &scratch_out]),
            2,
            vec![
                "phi0_rad = 2 rad puts the crank at 2.3000..3.8000 rad over joint 4's range [0.3, 1.8] rad, outside (0, π)".to_owned(),
            ],
        ),
        (
            "force with a truth whose capstan eccentricity radius is negative",
            args(&force_args(&device, &negative_radius, &calibrated, &[])),
            2,
            vec![format!("{negative_radius}:53:9: r_o_m = -2e-4 m is negative")],
        ),
        (
            "force with a truth whose capstan ratio error is 1e6",
            args(&force_args(&device, &ratio_truth, &calibrated, &[])),
            2,
            vec![format!("{ratio_truth}:52:6: re = 1e6 is outside ±1")],
        ),
        (
            "calibrate a log with ext2 = 1e10 on one row",
            args(&["calibrate", "--device", &device, "--data", &ext_typo]),
            2,
            vec![
                format!("{ext_typo}:6:10: ext2 = 1e10 rad"),
                "is outside".to_owned(),
            ],
        ),
        (
            "calibrate MUKCa sockets whose hole_1.csv is a copy of hole_0.csv",
            args(&["calibrate", "--device", &iiwa, "--data", &copied]),
            2,
            vec![format!(
                "{copied}/hole_1.csv repeats {copied}/hole_0.csv row for row: two sockets are two \
                 points"
            )],
        ),
        (
            "calibrate a MUKCa folder and a measurement file together",
            args(&["calibrate", "--device", &iiwa, "--data", &front, &log]),
            2,
            vec![format!(
                "{front} is a folder (MUKCa sockets) and {log} a measurement file: calibrate \
                 from one kind of data at a time"
            )],
        ),
        (
            "calibrate a haptic log with --sigma-m",
            calibrate(&["--sigma-m", "1e-5"]),
            2,
            vec!["--sigma-m does not apply to a haptic device's log".to_owned()],
        ),
        (
            "calibrate a haptic log with --test-last",
            calibrate(&["--test-last", "0.3"]),
            2,
            vec!["--test-last does not apply to a haptic device's log".to_owned()],
        ),
        (
            "calibrate a haptic log with a column it does not have",
            calibrate(&["--column-sign", "ext7"]),
            2,
            vec!["--column-sign ext7: the file has no column \"ext7\"; its columns are q1,".to_owned()],
        ),
        (
            "calibrate --test = --data",
            calibrate(&["--test", &log]),
            2,
            vec![format!(
                "--data {log} and --test {log} are the same file: held-out data must not be \
                 training data"
            )],
        ),
        (
            "calibrate --test a byte-identical copy of --data",
            calibrate(&["--test", &log_copy]),
            2,
            vec!["are byte-identical files".to_owned()],
        ),
        (
            "calibrate --data twice",
            args(&["calibrate", "--device", &device, "--data", &log, &log]),
            2,
            vec!["every row would count twice".to_owned()],
        ),
        (
            "calibrate MUKCa sockets with --test-last",
            args(&[
                "calibrate",
                "--device",
                &iiwa,
                "--data",
                &front,
                "--test-last",
                "0.5",
            ]),
            2,
            vec!["--test-last applies to measurement files".to_owned()],
        ),
        (
            "diagnose a haptic log with --sigma-m",
            args(&[
                "diagnose",
                "--device",
                &device,
                "--data",
                &log,
                "--sigma-m",
                "1e-300",
            ]),
            2,
            vec!["--sigma-m does not apply to a haptic device's diagnosis".to_owned()],
        ),
        (
            "diagnose a haptic log with --test-last",
            args(&[
                "diagnose",
                "--device",
                &device,
                "--data",
                &log,
                "--test-last",
                "0.99",
            ]),
            2,
            vec!["--test-last does not apply to a haptic device's diagnosis".to_owned()],
        ),
    ];
    for (name, args, code, needles) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        t.add(C, name, &args, *code, &needles);
    }
    vec![PathBuf::from(null), PathBuf::from(full)]
}

#[test]
fn every_hostile_input_ends_with_its_exit_code_and_a_located_message() {
    let mut t = Table {
        dir: scratch("hostile-cases"),
        cases: Vec::new(),
    };
    log_cases(&mut t);
    device_cases(&mut t);
    urdf_cases(&mut t);
    mukca_cases(&mut t);
    measurement_cases(&mut t);
    option_cases(&mut t);
    output_cases(&mut t);
    let device_links = limit_cases(&mut t);
    let cases = &t.cases;
    assert!(cases.len() >= 150, "{} cases", cases.len());
    // Two workers: the cases are independent processes.
    let results: Vec<(usize, Result<(), String>)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..2)
            .map(|w| {
                s.spawn(move || {
                    (cases.iter().enumerate())
                        .filter(|(i, _)| i % 2 == w)
                        .map(|(i, c)| (i, run_case(c)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().unwrap_or_default())
            .collect()
    });
    assert_eq!(results.len(), cases.len(), "every case ran");
    let mut per_category: BTreeMap<&str, usize> = BTreeMap::new();
    for c in cases {
        *per_category.entry(c.category).or_default() += 1;
    }
    let failures: Vec<String> = (results.iter())
        .filter_map(|(i, r)| {
            let c = &cases[*i];
            r.as_ref()
                .err()
                .map(|e| format!("[{}] {}: {:?}\n    {e}", c.category, c.name, c.args))
        })
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed ({per_category:?}):\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    // Written through, not replaced.
    for link in &device_links {
        let kind = std::fs::symlink_metadata(link).map(|m| m.file_type().is_symlink());
        assert!(
            matches!(kind, Ok(true)),
            "{} is no longer a link",
            link.display()
        );
    }
    assert!(!t.dir.join("limits/x.csv").exists());
    // Nothing but the fixtures was written: no output of a refused command.
    assert!(!t.dir.join("outputs/no-such-folder").exists());
    assert!(!t.dir.join("outputs/c.csv").exists());
    eprintln!("{} hostile cases passed: {per_category:?}", cases.len());
}
