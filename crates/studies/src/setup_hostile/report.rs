//! The sweep's Markdown report: per family and per outcome, the invisible mistakes, the ones not named right, every residual ratio.

use super::*;

/// The outcomes in the order of the report's columns.
pub(super) const OUTCOME_COLUMNS: [Outcome; 10] = [
    Outcome::NamedRight,
    Outcome::ClassOnly,
    Outcome::Located,
    Outcome::WrongCause,
    Outcome::HarmfulFix,
    Outcome::Generic,
    Outcome::Warned,
    Outcome::Silent,
    Outcome::FalseAlarm,
    Outcome::Clean,
];

/// One table of counts per family (and a total row) over `sel`.
pub(super) fn family_table(s: &mut String, sel: &[&CaseResult]) {
    let _ = writeln!(
        s,
        "| family | expected | cases | named right | class only | located | wrong cause | harmful fix | generic | warned | silent | false alarm | clean |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut total: BTreeMap<Outcome, usize> = BTreeMap::new();
    for spec in FAMILIES {
        let fam: Vec<&CaseResult> = (sel.iter().copied())
            .filter(|r| r.case.family == spec.family)
            .collect();
        if fam.is_empty() {
            continue;
        }
        let c = counts(fam.iter().copied());
        for (k, v) in &c {
            *total.entry(*k).or_insert(0) += v;
        }
        let expected = match spec.expect {
            Expect::Stop(class, _) => format!("stop [{class}]"),
            Expect::Note(class) => format!("note [{class}]"),
            Expect::Clean => "nothing".to_owned(),
            Expect::Listed => "the row listed".to_owned(),
        };
        let cells: Vec<String> = (OUTCOME_COLUMNS.iter())
            .map(|o| c.get(o).copied().unwrap_or(0).to_string())
            .collect();
        let _ = writeln!(
            s,
            "| {} | {expected} | {} | {} |",
            spec.name,
            fam.len(),
            cells.join(" | ")
        );
    }
    let cells: Vec<String> = (OUTCOME_COLUMNS.iter())
        .map(|o| total.get(o).copied().unwrap_or(0).to_string())
        .collect();
    let _ = writeln!(s, "| **all** | | {} | {} |\n", sel.len(), cells.join(" | "));
}

/// What the check said, for a table cell: 150 characters, no `|` or backquote.
pub(super) fn said_cell(r: &CaseResult) -> String {
    let said: String = r.said.chars().take(150).collect();
    said.replace('|', "\\|").replace('`', "'")
}

/// The report page (markdown): how visibility is decided and the figures over visible
/// mistakes per half; per family and half the counts over all cases, then over visible
/// mistakes; the invisible mistakes; every case not named right (or a false alarm) with what
/// the check said; every mistake's ratio.
pub fn report_markdown(results: &[CaseResult], command: &str, machine: &str) -> String {
    let mut s = String::new();
    write_report_intro(&mut s, command, machine);
    write_visible_summaries(&mut s, results);
    write_family_tables(&mut s, results);
    write_invisible_mistakes(&mut s, results);
    write_not_named_right(&mut s, results);
    write_every_ratio(&mut s, results);
    s
}

/// The report's title, what the outcomes mean, how visibility is screened, and the command
/// and machine of the run.
pub(super) fn write_report_intro(s: &mut String, command: &str, machine: &str) {
    let frames = ModelName::FramesOnly.name();
    let geometric = ModelName::Geometric.name();
    let _ = writeln!(s, "# Setup check: the hostile sweep\n");
    let _ = writeln!(
        s,
        "Ordinary setup mistakes the check was not built on, written into the bundled \
         recordings and simulated ones (crates/studies/src/setup_hostile.rs has the table of \
         expectations), run through `hapcal calibrate` as a user runs it and judged only by \
         its exit code and what it prints. A mistake is *named right* when the command stops \
         (exit 2) with `setup check [<expected class>]` and the fix names the cause (the \
         column, the factor's unit, the flag, the line); *class only* when the class is right \
         but the fix does not name the cause; *located* when it stops without naming a cause \
         (`no-hypothesis`, an implausible estimate, the reader's error) but names the rows \
         (within two lines) or the column of the mistake; *wrong cause* when it stops naming \
         another cause whose fix is an edit in words; *harmful fix* when it stops naming \
         another cause with a flag to apply, or names the right cause with a flag that, \
         applied to the same command, stops it again (every flag a stop prints is applied and \
         the command rerun); *generic* when it stops otherwise; *warned* when it runs with a \
         setup warning; *silent* when it runs with none. On correct data any setup finding is \
         a *false alarm*. The glitch-row family (one joint reading 0.2 rad off) expects the \
         calibration to run and list the row (file:line) it bounded or left out; it is named \
         right when it does, located when it stops naming the row. The latency family expects \
         a note or warning \
         of class `{LATENCY_CLASS}`, and a stop on it is a false alarm.\n"
    );
    let _ = writeln!(
        s,
        "**Visibility.** A mistake may leave no trace in the data (the zero of a positioner's \
         joint absorbed by the fitted frames, the sign of a last joint whose axis passes \
         through the marker). Each mistake is screened without the check's code: \
         `hapcal calibrate <the case's arguments> --accept-setup --model {frames} --json` \
         (`--model {geometric}` for socket folders and haptic logs, the least model they \
         take; it also fits joint offsets and link lengths) is run on the mistaken data and \
         on the same data without the mistake (the same rows, the same simulation seed, the \
         recording's tips and socket distance). The ratio is the mistaken data's training \
         residual over the correct data's, the largest over the figures both reports have \
         (position RMS, orientation RMS, distance RMS, socket consistency, socket distance \
         error). A mistake is *invisible in the data* when the ratio is below \
         {INVISIBLE_RATIO}; a mistake whose screening fit fails (the reader refuses a reading \
         past a joint limit, the fit fails) is visible. The tables over all cases stay on \
         the page; the tables over visible mistakes follow them, with the correct data \
         unchanged.\n"
    );
    let _ = writeln!(s, "Command: `{command}`  ");
    let _ = writeln!(s, "Machine: {machine}\n");
}

/// Per half, and within it for the earlier and the newer families: the one-line summary over
/// visible mistakes ([`VisibleSummary::line`]).
pub(super) fn write_visible_summaries(s: &mut String, results: &[CaseResult]) {
    let _ = writeln!(s, "## Over visible mistakes\n");
    for half in [Half::Tuning, Half::HeldBack] {
        let sum = VisibleSummary::of(results.iter().filter(|r| r.case.half == half));
        let _ = writeln!(s, "- {} half: {}", half.name(), sum.line());
        for (name, sel) in [
            ("families of earlier sweeps", false),
            (
                "families added with the change-point, scale and coupling hypotheses",
                true,
            ),
        ] {
            let sum = VisibleSummary::of(
                (results.iter()).filter(|r| r.case.half == half && r.case.family.is_new() == sel),
            );
            let _ = writeln!(s, "  - {name}: {}", sum.line());
        }
    }
    let _ = writeln!(
        s,
        "\nFalse alarms are counted over the correct data and the visible mistakes of the \
         latency family (a stop on them is a false alarm).\n"
    );
}

/// The family tables over all cases and per half, then per half over the visible mistakes
/// and the correct data.
pub(super) fn write_family_tables(s: &mut String, results: &[CaseResult]) {
    let halves = [
        ("All cases", None),
        ("Tuning half", Some(Half::Tuning)),
        ("Held-back half", Some(Half::HeldBack)),
    ];
    for (title, filter) in halves {
        let sel: Vec<&CaseResult> = (results.iter())
            .filter(|r| filter.is_none_or(|h| r.case.half == h))
            .collect();
        let _ = writeln!(s, "## {title} ({} cases)\n", sel.len());
        family_table(s, &sel);
    }
    for (title, half) in [
        ("Tuning half", Half::Tuning),
        ("Held-back half", Half::HeldBack),
    ] {
        let sel: Vec<&CaseResult> = (results.iter())
            .filter(|r| {
                r.case.half == half && (r.case.family.is_correct() || is_visible_mistake(r))
            })
            .collect();
        let n_visible = sel.iter().filter(|r| !r.case.family.is_correct()).count();
        let _ = writeln!(
            s,
            "## {title}, visible mistakes only ({n_visible} mistakes, {} correct)\n",
            sel.len() - n_visible
        );
        family_table(s, &sel);
    }
}

/// The table of the mistakes invisible in the data, with their ratio and outcome.
pub(super) fn write_invisible_mistakes(s: &mut String, results: &[CaseResult]) {
    let invisible: Vec<&CaseResult> = (results.iter())
        .filter(|r| !r.case.family.is_correct() && r.visibility.is_invisible())
        .collect();
    let _ = writeln!(s, "## Invisible mistakes ({})\n", invisible.len());
    let _ = writeln!(
        s,
        "Mistakes whose data fit as well as the correct data (ratio below {INVISIBLE_RATIO}): \
         case, half, screening model, ratio, outcome, and what the check said.\n"
    );
    let _ = writeln!(s, "| case | half | model | ratio | outcome | said |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for r in &invisible {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            r.case.id,
            r.case.half.name(),
            screening_model(r.case.recording).name(),
            r.visibility.cell(),
            r.outcome.name(),
            said_cell(r)
        );
    }
    let _ = writeln!(s);
}

/// The table of the mistakes not named right and of the false alarms.
pub(super) fn write_not_named_right(s: &mut String, results: &[CaseResult]) {
    let _ = writeln!(s, "## Cases not named right\n");
    let _ = writeln!(
        s,
        "Mistakes not named right and false alarms: case, half, expected, outcome, exit code, \
         visibility ratio, and what the check said (first setup line, else the error; 150 \
         characters).\n"
    );
    let _ = writeln!(
        s,
        "| case | half | expected | outcome | exit | ratio | said |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for r in results {
        if matches!(r.outcome, Outcome::NamedRight | Outcome::Clean) {
            continue;
        }
        let expected = match r.case.family.spec().expect {
            Expect::Stop(class, _) | Expect::Note(class) => class.to_owned(),
            Expect::Clean => "nothing".to_owned(),
            Expect::Listed => "the row listed".to_owned(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {expected} | {} | {} | {} | {} |",
            r.case.id,
            r.case.half.name(),
            r.outcome.name(),
            r.code.map_or("none".to_owned(), |c| c.to_string()),
            r.visibility.cell(),
            said_cell(r)
        );
    }
    let _ = writeln!(s);
}

/// The table of every mistake's screening: its ratio, or why there is none.
pub(super) fn write_every_ratio(s: &mut String, results: &[CaseResult]) {
    let _ = writeln!(s, "## Every mistake's ratio\n");
    let _ = writeln!(
        s,
        "The screening of every mistake: case, half, screening model, ratio (or why there is \
         none: the mistaken data's fit failed, or the correct data's), outcome.\n"
    );
    let _ = writeln!(s, "| case | half | model | ratio | outcome |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for r in results.iter().filter(|r| !r.case.family.is_correct()) {
        let why = match &r.visibility {
            Visibility::MistakenFailed(e) | Visibility::Undecided(e) => {
                let e: String = e.chars().take(140).collect();
                format!(" ({})", e.replace('|', "\\|").replace('`', "'"))
            }
            _ => String::new(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}{why} | {} |",
            r.case.id,
            r.case.half.name(),
            screening_model(r.case.recording).name(),
            r.visibility.cell(),
            r.outcome.name(),
        );
    }
}
