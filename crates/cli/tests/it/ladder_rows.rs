//! `hapcal calibrate --model auto` on recordings with copied rows and on few rows: copies are
//! held out with the rows they copy, so they cannot move the ladder; few rows stop the ladder
//! at the rungs every cross-validation fold can fit, with a note, not an error.

use super::{on_ur10, scratch, show, stderr, ur10_csv};
use serde_json::Value;
use std::path::Path;

/// The UR10's camera recording: its header and its 23 rows.
fn ur10_lines() -> (String, Vec<String>) {
    let text = std::fs::read_to_string(ur10_csv()).expect("the UR10 recording");
    let mut lines = text.lines().map(str::to_owned);
    let header = lines.next().expect("a header");
    (header, lines.collect())
}

fn write(dir: &Path, name: &str, header: &str, rows: &[String]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, format!("{header}\n{}\n", rows.join("\n"))).expect("write");
    show(&path)
}

/// The JSON report of `hapcal calibrate --model auto` on the UR10 and `data` (exit 0 asserted),
/// and its standard error.
fn auto(data: &str) -> (Value, String) {
    let out = on_ur10("calibrate", Path::new(data), &["--model", "auto", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v = serde_json::from_slice(&out.stdout).expect("one JSON document");
    (v, stderr(&out))
}

fn warnings(v: &Value) -> Vec<String> {
    (v["warnings"].as_array().expect("warnings").iter())
        .map(|w| w.as_str().unwrap_or_default().to_owned())
        .collect()
}

/// The ladder's rungs (tried), each with its held-out RMS (m) and its held-out score's
/// difference to frames only with the blocked standard error.
fn ladder(v: &Value) -> Vec<(String, f64, (f64, f64))> {
    (v["ladder"].as_array().expect("a ladder").iter())
        .map(|r| {
            let d = &r["score_difference_to_frames"];
            (
                r["rung"].as_str().expect("a rung").to_owned(),
                r["heldout_rms_m"].as_f64().expect("an RMS"),
                (
                    d[0].as_f64().expect("a mean"),
                    d[1].as_f64().expect("an SE"),
                ),
            )
        })
        .collect()
}

/// The recording appended to itself holds the recording's information once: each copy is
/// held out with its row, so every fold trains on its distinct rows twice over, whose
/// least-squares estimate is theirs. Frames only and joint offsets (every parameter kept
/// either way) are held out as on the recording, up to the fold refits' convergence (relative
/// cost 10⁻⁶). The richer rungs keep a few more parameters from the doubled rows (the copies
/// double what the pruning sees), and their held-out score moves, but by less than half the
/// blocked standard error the ladder judges it by, whose two-standard-error rule then chooses
/// as on the recording; nor do the copies shrink that standard error. With the copies in the
/// training folds of their rows, geometric's difference to frames only moved by 0.9 of its
/// standard error, which shrank threefold, and the ladder climbed to geometric.
#[test]
fn a_recording_appended_to_itself_chooses_as_the_recording() {
    let dir = scratch("ladder-copies");
    let (header, rows) = ur10_lines();
    let twice: Vec<String> = rows.iter().chain(&rows).cloned().collect();
    let (once, _) = auto(&write(&dir, "once.csv", &header, &rows));
    let (doubled, _) = auto(&write(&dir, "twice.csv", &header, &twice));
    assert_eq!(once["model"], doubled["model"]);
    let (a, b) = (ladder(&once), ladder(&doubled));
    assert_eq!(a.len(), b.len());
    for ((rung, x, (d, se)), (_, y, (d2, se2))) in a.iter().zip(&b) {
        if rung == "frames-only" || rung == "joint-offsets" {
            assert!(
                (x - y).abs() < 1e-6 * x,
                "{rung}: held out {x:e} m once, {y:e} m twice"
            );
        } else {
            assert!(
                (d2 - d).abs() < 0.5 * se && *se2 > 0.75 * se,
                "{rung}: difference to frames only {d} ± {se} once, {d2} ± {se2} twice"
            );
        }
    }
    assert!(
        (warnings(&doubled).iter()).any(|w| w.starts_with(
            "23 training rows repeat earlier rows: each is held out with the row it copies"
        )),
        "{:#?}",
        warnings(&doubled)
    );
}

/// The rungs the note on too few rows lists, each with its parameters, its residuals and
/// whether those are all training rows' (not a fold's).
fn untried(note: &str) -> Vec<(String, usize, usize, bool)> {
    let count = |s: &str| -> usize { s.trim().parse().expect("a count") };
    let list = (note.split(" too few rows were measured for ").nth(1))
        .and_then(|s| s.split("; measure more").next())
        .expect("the rungs not tried");
    (list.split("), "))
        .map(|item| {
            let (rung, why) = item.split_once(" (").expect("a rung and why");
            let (params, rest) = why.split_once(" parameters; ").expect("parameters");
            let residuals = (rest.split(" give ").nth(1))
                .and_then(|s| s.split(' ').next())
                .expect("residuals");
            let all = rest.starts_with("the training rows");
            (rung.to_owned(), count(params), count(residuals), all)
        })
        .collect()
}

/// The note on the rungs `--model auto` did not try, asserted on the report and on standard
/// error, with the ladder it tried.
fn note(v: &Value, err: &str) -> String {
    let note = (warnings(v).into_iter())
        .find(|w| w.starts_with("--model auto tried the ladder up to "))
        .expect("a note on the rungs not tried");
    assert!(err.contains(&note), "the note on standard error too: {err}");
    let tried = ladder(v);
    assert_eq!(tried[0].0, "frames-only");
    let top = &tried.last().expect("a rung").0;
    assert!(note.contains(&format!("up to {top}:")), "{note}");
    note
}

/// On the first 8 rows (48 residuals; a fold trains on 6 rows, 36 residuals) the ladder takes
/// the rungs every fold can fit, names those it did not try, each with more parameters than a
/// fold's residuals, and exits 0. On 6 rows some rungs cannot be fitted even on all rows; such
/// a model asked for by name stays an error with the numbers. On 16 rows every rung is tried,
/// with no note.
#[test]
fn few_rows_stop_the_ladder_at_the_rungs_every_fold_can_fit() {
    let dir = scratch("ladder-few");
    let (header, rows) = ur10_lines();
    let (v, err) = auto(&write(&dir, "eight.csv", &header, &rows[..8]));
    let note_8 = note(&v, &err);
    let listed = untried(&note_8);
    assert!(!listed.is_empty(), "{note_8}");
    for (rung, params, residuals, all) in &listed {
        assert!(params > residuals && !all, "{rung}: {note_8}");
        assert!(*residuals < 8 * 6, "{rung}: {note_8}");
    }
    assert_eq!(
        ladder(&v).len() + listed.len(),
        8,
        "the UR10's ladder has 8 rungs"
    );

    let six = write(&dir, "six.csv", &header, &rows[..6]);
    let (v, err) = auto(&six);
    let listed = untried(&note(&v, &err));
    let (rung, params, residuals, _) = (listed.iter())
        .find(|u| u.3)
        .expect("a rung 6 rows cannot fit at all")
        .clone();
    assert!(
        params >= residuals && residuals == 6 * 6,
        "{rung}: {params}, {residuals}"
    );
    let out = on_ur10("calibrate", Path::new(&six), &["--model", &rung]);
    assert_ne!(out.status.code(), Some(0), "--model {rung} on 6 rows");
    let err = stderr(&out);
    assert!(
        err.contains(&format!("{residuals} residuals")) && err.contains(&format!("{params} ")),
        "{err}"
    );

    let (v, _) = auto(&write(&dir, "sixteen.csv", &header, &rows[..16]));
    assert_eq!(ladder(&v).len(), 8, "every rung of the UR10's ladder");
    assert!(
        warnings(&v)
            .iter()
            .all(|w| !w.starts_with("--model auto tried"))
    );
}
