//! `cargo xtask diagnose-real`: `hapcal diagnose` on every real recording in `fixtures/` (the
//! MUKCa units that `hapcal calibrate` handles, and the published marker and pose data), into
//! docs/results/diagnose-real.md with the residual maps in docs/results/diagnose-real/.

use anyhow::{Context, Result, bail};
use hapcal_contract::{Effect, ModelName};
use serde_json::Value;
use std::path::Path;
use xshell::{Shell, cmd};

/// One diagnosed recording.
struct Recording {
    /// File stem of the residual maps.
    id: &'static str,
    /// What it is.
    name: &'static str,
    /// `hapcal diagnose` arguments (device, tips, data, held-out data).
    args: &'static [&'static str],
    /// Whether the last rows of the data are held out (`--test-last`, the fraction
    /// `cargo xtask real-data` holds out) rather than held-out files in `args`.
    test_last: bool,
    /// What is known about it from elsewhere (docs/results/mukca.md, the publishers).
    known: &'static str,
    /// The verdict the checks require, if any.
    /// (`Some(&[])`: none.)
    required: Option<&'static [Effect]>,
}

const M: &str = "fixtures/mukca";

/// The bundled Panda socket recordings (name, arguments of `hapcal calibrate` or `diagnose`:
/// device, training and held-out placements).
pub(crate) fn panda_recordings() -> impl Iterator<Item = (&'static str, &'static [&'static str])> {
    (RECORDINGS.iter())
        .filter(|r| r.id.starts_with("panda"))
        .map(|r| (r.name, r.args))
}

impl Recording {
    /// The full `hapcal diagnose` (and `calibrate`) arguments: `args`, then the split.
    fn args(&self) -> Vec<&'static str> {
        let split = ["--test-last", crate::real_data::TEST_LAST];
        let split = if self.test_last { &split[..] } else { &[] };
        [self.args, split].concat()
    }
}

const RECORDINGS: &[Recording] = &[
    Recording {
        id: "kuka_14",
        name: "MUKCa kuka_14 (KUKA LBR iiwa 14), sockets, train front",
        args: &[
            "--device",
            "fixtures/mukca/urdf/iiwa14.urdf",
            "--data",
            "fixtures/mukca/data/kuka_14/front",
            "--test",
            "fixtures/mukca/data/kuka_14/left_back",
            "fixtures/mukca/data/kuka_14/raised_left",
        ],
        test_last: false,
        known: "cross-validation of the calibration's models chooses gravity compliance with the \
                published link masses (docs/results/mukca.md): held-out 163 → 107 µm",
        required: Some(&[Effect::GravityCompliance]),
    },
    Recording {
        id: "panda_1",
        name: "MUKCa panda_1 (Franka Panda), sockets, train front",
        args: &[
            "--device",
            "fixtures/mukca/urdf/panda.urdf",
            "--data",
            "fixtures/mukca/data/panda_1/front",
            "--test",
            "fixtures/mukca/data/panda_1/back-high",
            "fixtures/mukca/data/panda_1/right",
        ],
        test_last: false,
        known: "no compliance model beats the geometric one by a standard error \
                (docs/results/mukca.md)",
        required: None,
    },
    Recording {
        id: "panda_2",
        name: "MUKCa panda_2 (Franka Panda), sockets, train back_left",
        args: &[
            "--device",
            "fixtures/mukca/urdf/panda.urdf",
            "--data",
            "fixtures/mukca/data/panda_2/back_left",
            "--test",
            "fixtures/mukca/data/panda_2/back_right",
            "fixtures/mukca/data/panda_2/front_center",
            "fixtures/mukca/data/panda_2/front_left",
            "fixtures/mukca/data/panda_2/front_right",
            "fixtures/mukca/data/panda_2/high",
            "fixtures/mukca/data/panda_2/mid-high",
            "fixtures/mukca/data/panda_2/mid_left",
            "fixtures/mukca/data/panda_2/mid_right",
        ],
        test_last: false,
        known: "geometric model chosen (docs/results/mukca.md)",
        required: None,
    },
    Recording {
        id: "panda_6",
        name: "MUKCa panda_6 (Franka Panda), sockets, train front",
        args: &[
            "--device",
            "fixtures/mukca/urdf/panda.urdf",
            "--data",
            "fixtures/mukca/data/panda_6/front",
            "--test",
            "fixtures/mukca/data/panda_6/left",
            "fixtures/mukca/data/panda_6/right",
        ],
        test_last: false,
        known: "no non-geometric model tried does better than the geometric one by more than \
                5 % on the test placements (docs/results/mukca.md)",
        required: Some(&[]),
    },
    Recording {
        id: "panda_7",
        name: "MUKCa panda_7 (Franka Panda), sockets, train front",
        args: &[
            "--device",
            "fixtures/mukca/urdf/panda.urdf",
            "--data",
            "fixtures/mukca/data/panda_7/front",
            "--test",
            "fixtures/mukca/data/panda_7/right",
        ],
        test_last: false,
        known: "compliance passes the calibration's one-standard-error rule by 1.8 standard \
                errors but no non-geometric model does better on the test placement by more than \
                5 % (docs/results/mukca.md)",
        required: Some(&[]),
    },
    Recording {
        id: "ur10",
        name: "UR10, camera + checkerboard poses (figaroh-examples), first 70 % train",
        args: crate::real_data::UR10,
        test_last: true,
        known: "23 poses; figaroh's full calibration lowers the held-out RMS from 4.45 to 4.04 mm \
                (docs/results/real-data.md)",
        required: None,
    },
    Recording {
        id: "tiago",
        name: "TIAGo, four motion-capture markers (figaroh-examples), first 70 % train",
        args: crate::real_data::TIAGO,
        test_last: true,
        known: "34 configurations; every calibrated rung is worse than frames only held out \
                (docs/results/real-data.md)",
        required: None,
    },
    Recording {
        id: "positioner",
        name: "Two-axis positioner seen by a camera (industrial_calibration), first 70 % train",
        args: crate::real_data::POSITIONER,
        test_last: true,
        known: "205 poses; the D-H calibration lowers the in-sample error from 3.82 to 1.74 mm \
                (the publisher's figure)",
        required: None,
    },
    Recording {
        id: "humanoid",
        name: "Simulated two-arm humanoid, a motion-capture marker on each hand (sim_humanoid), \
               first 70 % train",
        args: crate::real_data::HUMANOID,
        test_last: true,
        known: "simulated with geometric deviations, joint compliance and transversal compliance \
                under the links' weight (fixtures/sim-humanoid/truth.toml); the calibration's \
                ladder takes transversal-compliance (docs/results/real-data.md)",
        required: Some(&[Effect::GravityCompliance, Effect::TransversalCompliance]),
    },
];

fn mm(v: &Value) -> String {
    v.as_f64()
        .map_or_else(|| "–".to_owned(), |m| format!("{:.3}", m * 1e3))
}

/// How the diagnosis's verdict compares with the rung `hapcal calibrate --model auto` takes
/// on the same files (`calibrated`, its JSON report): the same model (the same effects), or
/// why not, from the calibration's own ladder (docs/design.md §6.1).
fn agreement(verdict: &str, calibrated: &Value) -> String {
    let named: Vec<Effect> = if verdict == "none" {
        Vec::new()
    } else {
        verdict.split('+').filter_map(Effect::from_name).collect()
    };
    let rung_name = calibrated["model"].as_str().unwrap_or("?");
    let rung = ModelName::ALL.into_iter().find(|m| m.name() == rung_name);
    let same = |a: ModelName, b: ModelName| {
        [true, false].into_iter().any(|masses| {
            let (mut x, mut y) = (a.effects(masses), b.effects(masses));
            x.sort();
            y.sort();
            x == y
        })
    };
    let kinematic = |m: ModelName| {
        matches!(
            m,
            ModelName::FramesOnly | ModelName::JointOffsets | ModelName::Geometric
        )
    };
    let f = ModelName::for_effects(&named);
    let mut words = format!("Calibration: `--model auto` takes **{rung_name}**; ");
    match (&f.model, rung) {
        (Ok(None), Some(r)) if kinematic(r) => {
            words.push_str("the diagnosis names no effect a model frees: they agree");
        }
        (Ok(None), _) => words.push_str(
            "the diagnosis names no effect a model frees, the ladder a model beyond the \
             kinematics: its cross-validation sees an effect (two standard errors) that closes \
             less than the diagnosis's share of the gap (20 %)",
        ),
        (Ok(Some(m)), Some(r)) if same(*m, r) => {
            words.push_str(&format!(
                "the named effects are that model ({m}): they agree"
            ));
        }
        (Ok(Some(m)), _) => {
            words.push_str(&format!("the named effects are the model {m}; "));
            let stopped = (calibrated["coverage"]["stopped"]
                .as_array()
                .into_iter()
                .flatten())
            .any(|s| s["rung"].as_str() == Some(m.name()));
            let row = (calibrated["ladder"].as_array().into_iter().flatten())
                .find(|l| l["rung"].as_str() == Some(m.name()));
            words.push_str(&match row {
                _ if stopped => format!(
                    "the joint-range folds stopped {m}: where the calibration is used beyond its \
                     training range it is not shown to do better"
                ),
                Some(_) => format!(
                    "{m} is a rung of this ladder that did not beat the rung chosen below it by \
                     two standard errors of the held-out difference"
                ),
                None => format!("{m} is not a rung of the ladder for these data"),
            });
        }
        (Err(together), _) => {
            let names: Vec<&str> = together.iter().map(|e| e.name()).collect();
            words.push_str(&format!(
                "no one calibration model frees {} together",
                names.join(" and ")
            ));
        }
    }
    for (e, reason) in &f.beyond {
        words.push_str(&format!("; {e}: {reason}"));
    }
    words.push('.');
    words
}

/// The report's title and how to read it: what the diagnosis starts from, when it names an
/// effect, what the ladder gives.
const INTRO: &str = "# The sim-to-real gap of real robots\n\nWritten by `cargo xtask diagnose-real` (release \
         build): one `hapcal diagnose … --json` per recording, the command below each heading. \
         The diagnosis starts from the geometric calibration of the training rows; its floor is \
         the stated instrument σ, else the repeatability of repeated poses, else the sockets' \
         replicates (an upper bound of the seating noise), else none (the gaps are then relative \
         to the best model found). An effect is named only when its in-sample F-test is \
         significant after Holm's correction over the candidates (α = 0.01), its held-out error \
         over the blocked cross-validation folds undercuts the baseline's by two standard \
         errors, and it closes at least 20 % of the gap above the floor (docs/diagnosis.md §7). The ladder gives the RMS of the 3-D error \
         (mm): cross-validated on the training rows, and on each held-out set. Residual maps: \
         docs/results/diagnose-real/*.svg.\n\nMachine: 2 cores.\n";

/// Folder of the residual maps.
const MAPS_DIR: &str = "docs/results/diagnose-real";

/// How to run `hapcal`: the program and the arguments before the subcommand.
#[derive(Clone, Copy)]
struct Hapcal<'a> {
    program: &'a std::ffi::OsStr,
    pre: &'a [std::ffi::OsString],
}

/// Runs every recording; with `check`, verifies the required verdicts without writing.
pub(crate) fn run(sh: &Shell, check: bool, bin: Option<&Path>) -> Result<()> {
    let (program, pre) = crate::hapcal_cmd(bin);
    let hapcal = Hapcal {
        program: &program,
        pre: pre.as_slice(),
    };
    let _ = M;
    let tmp = sh.create_temp_dir()?;
    let mut md = String::from(INTRO);
    let mut failures = Vec::new();
    for rec in RECORDINGS {
        let svg = if check {
            tmp.path().join(format!("{}.svg", rec.id))
        } else {
            sh.create_dir(MAPS_DIR)?;
            std::path::PathBuf::from(format!("{MAPS_DIR}/{}.svg", rec.id))
        };
        let d = diagnose(sh, hapcal, rec, &svg)?;
        let verdict = d["verdict"].as_str().unwrap_or("?").to_owned();
        failures.extend(required_failure(rec, &verdict));
        if check {
            println!("diagnose-real: {}: {verdict}", rec.id);
            continue;
        }
        write_recording(sh, hapcal, rec, &d, &verdict, &mut md)?;
    }
    if !failures.is_empty() {
        bail!("diagnose-real: {}", failures.join("; "));
    }
    if check {
        println!("diagnose-real: every required verdict holds");
        return Ok(());
    }
    sh.write_file("docs/results/diagnose-real.md", md)?;
    println!("wrote docs/results/diagnose-real.md");
    Ok(())
}

/// `hapcal diagnose` on `rec` with its residual maps written to `svg`: the JSON report.
///
/// # Errors
/// A failed diagnosis or a report that is not JSON.
fn diagnose(sh: &Shell, hapcal: Hapcal<'_>, rec: &Recording, svg: &Path) -> Result<Value> {
    let (hapcal, pre, args) = (hapcal.program, hapcal.pre, rec.args());
    let json = cmd!(
        sh,
        "{hapcal} {pre...} diagnose {args...} --json --svg {svg}"
    )
    .read()
    .with_context(|| format!("diagnosing {}", rec.name))?;
    serde_json::from_str(&json).context("parsing the JSON report")
}

/// The failure of `rec`'s check: its `verdict` is not the required one (`None`: it is, or none
/// is required).
fn required_failure(rec: &Recording, verdict: &str) -> Option<String> {
    let required = rec.required.map(|r| {
        let names: Vec<&str> = r.iter().map(|e| e.name()).collect();
        if names.is_empty() {
            "none".to_owned()
        } else {
            names.join("+")
        }
    });
    match required {
        Some(req) if verdict != req => {
            Some(format!("{}: verdict {verdict}, expected {req}", rec.id))
        }
        _ => None,
    }
}

/// The section of `rec` (diagnosis report `d`, its `verdict`): the command, what is known,
/// the verdict beside the calibration's rung (`hapcal calibrate` runs here), the floor and
/// gap, the test files, the named effects, the round-1 candidates and the ladder.
///
/// # Errors
/// A failed calibration or a report that is not JSON.
fn write_recording(
    sh: &Shell,
    hapcal: Hapcal<'_>,
    rec: &Recording,
    d: &Value,
    verdict: &str,
    md: &mut String,
) -> Result<()> {
    md.push_str(&format!(
        "\n## {}\n\n`hapcal diagnose {}`\n\nKnown: {}.\n\n",
        rec.name,
        rec.args().join(" "),
        rec.known
    ));
    md.push_str(&format!(
        "- **Verdict: {verdict}.** {} training configurations, {} geometric parameters kept.\n",
        d["n_configurations"], d["n_baseline_params"]
    ));
    let (program, pre, args) = (hapcal.program, hapcal.pre, rec.args());
    let calibrated = cmd!(sh, "{program} {pre...} calibrate {args...} --json")
        .ignore_stderr()
        .read()
        .with_context(|| format!("calibrating {}", rec.name))?;
    let c: Value = serde_json::from_str(&calibrated).context("parsing calibrate's JSON")?;
    md.push_str(&format!("- {}\n", agreement(verdict, &c)));
    write_floor_and_tests(d, md);
    let flagged = (d["where"].as_array().into_iter().flatten())
        .filter(|b| b["flagged"] == true)
        .count();
    let n_bins = d["where"].as_array().map_or(0, Vec::len);
    md.push_str(&format!(
        "- Where: {flagged} of {n_bins} bins of the residual map significantly above the \
         floor (Holm), [maps]({}/{}.svg).\n",
        "diagnose-real", rec.id
    ));
    write_named_effects(d, md);
    write_candidates(d, md);
    write_ladder(d, md);
    for n in d["notes"].as_array().into_iter().flatten() {
        md.push_str(&format!("\nNote: {}\n", n.as_str().unwrap_or("")));
    }
    Ok(())
}

/// The floor, the cross-validated RMS and gap, and the test files' RMS (geometric, and with
/// the named effects) of diagnosis report `d`.
fn write_floor_and_tests(d: &Value, md: &mut String) {
    md.push_str(&format!(
        "- Floor: {}.\n",
        d["floor_method"].as_str().unwrap_or("?")
    ));
    match d["floor_rms_m"].as_f64() {
        Some(_) => md.push_str(&format!(
            "- Cross-validated RMS {} mm, floor {} mm, gap {} mm (p = {:.1e}).\n",
            mm(&d["cv_rms_m"]),
            mm(&d["floor_rms_m"]),
            mm(&d["gap_rms_m"]),
            d["gap_p_value"].as_f64().unwrap_or(f64::NAN)
        )),
        None => md.push_str(&format!(
            "- Cross-validated RMS {} mm; no floor.\n",
            mm(&d["cv_rms_m"])
        )),
    }
    let per_test = |key: &str| -> String {
        (d[key].as_array().into_iter().flatten())
            .map(mm)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let accepted: Vec<&str> = (d["steps"].as_array().into_iter().flatten())
        .filter_map(|s| s["effect"].as_str())
        .collect();
    if d["test_rms_m"].as_array().is_some_and(|t| !t.is_empty()) {
        md.push_str(&format!(
            "- Test-file RMS (training estimate carried over): {} mm geometric",
            per_test("test_rms_m")
        ));
        if !accepted.is_empty() {
            md.push_str(&format!(
                ", {} mm with {}",
                per_test("test_rms_final_m"),
                accepted.join(" + ")
            ));
        }
        md.push_str(".\n");
    }
}

/// Each effect diagnosis report `d` names: its gap closed and parameters, an open torque
/// model, what it is confusable with.
fn write_named_effects(d: &Value, md: &mut String) {
    for st in d["steps"].as_array().into_iter().flatten() {
        let params: Vec<String> = (st["parameters"].as_array().into_iter().flatten())
            .map(|p| {
                format!(
                    "{} = {:.3e} ± {:.1e} {}",
                    p["name"].as_str().unwrap_or("?"),
                    p["value"].as_f64().unwrap_or(f64::NAN),
                    p["std"].as_f64().unwrap_or(f64::NAN),
                    p["unit"].as_str().unwrap_or("")
                )
            })
            .collect();
        md.push_str(&format!(
            "- Named: **{}**, cross-validated RMS {} → {} mm, {:.0} % of the gap ({:.0} % of \
             the gap its round faced); {}.\n",
            st["effect"].as_str().unwrap_or("?"),
            mm(&st["cv_rms_before_m"]),
            mm(&st["cv_rms_after_m"]),
            st["gap_closed_pct"].as_f64().unwrap_or(f64::NAN),
            st["round_gap_closed_pct"].as_f64().unwrap_or(f64::NAN),
            params.join(", ")
        ));
        for a in st["alike"].as_array().into_iter().flatten() {
            md.push_str(&format!(
                "- Torque model open: {} in its place predicts as well (within two standard \
                 errors, beside the other named effects).\n",
                a.as_str().unwrap_or("?")
            ));
        }
        for c in st["confusable_with"].as_array().into_iter().flatten() {
            md.push_str(&format!(
                "- Confusable with {} on these data; to separate them, record {}.\n",
                c[0].as_str().unwrap_or("?"),
                c[1].as_str().unwrap_or("?")
            ));
        }
    }
}

/// The table of the candidates of the first round of diagnosis report `d`, best held-out
/// prediction first.
fn write_candidates(d: &Value, md: &mut String) {
    let mut cands: Vec<&Value> = (d["candidates"].as_array().into_iter().flatten())
        .filter(|c| c["round"] == 1)
        .collect();
    cands.sort_by(|a, b| {
        let f = |v: &Value| v["cv_rms_after_m"].as_f64().unwrap_or(f64::INFINITY);
        f(a).total_cmp(&f(b))
    });
    md.push_str(
        "\n| candidate (round 1) | k | CV RMS after, mm | CV improvement, standard errors | p (CV, one-sided) | p (F, Holm) | decision |\n|---|---|---|---|---|---|---|\n",
    );
    for c in cands {
        let imp = &c["cv_improvement"];
        md.push_str(&format!(
            "| {} | {} | {} | {} | {:.1e} | {:.1e} | {} |\n",
            c["effect"].as_str().unwrap_or("?"),
            c["n_visible"],
            mm(&c["cv_rms_after_m"]),
            match (imp[0].as_f64(), imp[1].as_f64()) {
                (Some(m), Some(se)) if se > 0.0 => format!("{:+.1}", m / se),
                _ => "–".to_owned(),
            },
            c["cv_p_value"].as_f64().unwrap_or(f64::NAN),
            c["f_p_value"].as_f64().unwrap_or(f64::NAN),
            c["reason"].as_str().unwrap_or("").replace('|', "/")
        ));
    }
}

/// The ladder of diagnosis report `d`: per rung, the cross-validated RMS and each test set's.
fn write_ladder(d: &Value, md: &mut String) {
    let tests: Vec<&str> = (d["test_sets"].as_array().into_iter().flatten())
        .filter_map(Value::as_str)
        .collect();
    md.push_str(&format!(
        "\n| rung | CV, training | {} |\n|---|---|{}\n",
        (tests.iter().map(|t| format!("test: {t}")))
            .collect::<Vec<_>>()
            .join(" | "),
        "---|".repeat(tests.len())
    ));
    for r in d["ladder"].as_array().into_iter().flatten() {
        let t: Vec<String> = (r["test_rms_m"].as_array().into_iter().flatten())
            .map(mm)
            .collect();
        md.push_str(&format!(
            "| {} | {} | {} |\n",
            r["rung"].as_str().unwrap_or("?"),
            mm(&r["cv_rms_m"]),
            t.join(" | ")
        ));
    }
}
