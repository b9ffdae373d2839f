//! Judging a case from the command's exit code and standard error alone, and screening whether its mistake is visible in the data.

use super::*;

/// How the check answered a case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Outcome {
    /// Stopped (or, for a note family, ran) naming the expected class, the fix naming the cause
    /// (for a listed family: ran naming the row); or stopped naming another cause and, as one
    /// the data fit as well, the expected fix.
    NamedRight,
    /// Stopped naming the expected class, but the fix does not name the cause (the column,
    /// the factor's unit or the flag).
    ClassOnly,
    /// Stopped without naming a cause (`no-hypothesis`, an implausible estimate, the reader's
    /// own error) but naming where the mistake is: the rows or the column.
    Located,
    /// Stopped naming another cause whose fix is an edit, not a flag.
    WrongCause,
    /// Stopped with a fix that harms: another cause's flag, or the expected cause's flag that,
    /// applied, still stops.
    HarmfulFix,
    /// Stopped otherwise: no cause, no place.
    Generic,
    /// Ran with a setup warning (a mistake family).
    Warned,
    /// Ran with no setup finding (a mistake family).
    Silent,
    /// Correct data with a setup finding, or a stop on a note family.
    FalseAlarm,
    /// Correct data with no setup finding.
    Clean,
}

impl Outcome {
    /// Words of the report.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::NamedRight => "named right",
            Outcome::ClassOnly => "class only",
            Outcome::Located => "located",
            Outcome::WrongCause => "wrong cause",
            Outcome::HarmfulFix => "harmful fix",
            Outcome::Generic => "generic",
            Outcome::Warned => "warned",
            Outcome::Silent => "silent",
            Outcome::FalseAlarm => "false alarm",
            Outcome::Clean => "clean",
        }
    }

    /// Whether the answer names the cause (the class right).
    pub fn is_named(self) -> bool {
        matches!(self, Outcome::NamedRight | Outcome::ClassOnly)
    }
}

/// The setup findings of a command's standard error: (class, the line from the class on).
pub fn findings(stderr: &str) -> Vec<(String, String)> {
    findings_with_severity(stderr)
        .into_iter()
        .map(|(_, c, t)| (c, t))
        .collect()
}

/// The setup findings with whether each is a warning (the line says `warning` before the
/// finding, or the finding was accepted) rather than the error that stopped the command.
pub(super) fn findings_with_severity(stderr: &str) -> Vec<(bool, String, String)> {
    let mut out = Vec::new();
    for line in stderr.lines() {
        let Some(i) = line.find("setup check") else {
            continue;
        };
        let rest = &line[i..];
        let (Some(a), Some(b)) = (rest.find('['), rest.find(']')) else {
            continue;
        };
        if a < b {
            let warning = line[..i].contains("warning") || rest[..a].contains("accepted");
            out.push((warning, rest[a + 1..b].to_owned(), rest.to_owned()));
        }
    }
    out
}

/// Classes that name no cause: the residual nothing explains, an implausible estimate.
pub(super) const NO_CAUSE: [&str; 2] = ["no-hypothesis", "implausible-estimate"];

/// Whether `word` occurs in `text` with no letter, digit or `_` on either side.
pub(super) fn has_word(text: &str, word: &str) -> bool {
    if word.is_empty() {
        return false;
    }
    let bytes = text.as_bytes();
    let inner = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut from = 0;
    while let Some(i) = text[from..].find(word) {
        let s = from + i;
        let e = s + word.len();
        let before = s == 0 || !inner(bytes[s - 1]) || word.starts_with('-');
        let after = e >= bytes.len() || !inner(bytes[e]);
        if before && after {
            return true;
        }
        from = s + 1;
    }
    false
}

/// The flags of a fix (`--column-sign q3`, `use --tip l_link6`, `--gravity +z`): each
/// `--flag` with its value, from the fix's start (after a leading `use`); empty when the fix
/// is an edit in words.
pub fn fix_flags(fix: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let fix = fix.trim_start().strip_prefix("use ").unwrap_or(fix);
    let mut words = fix.split_whitespace().peekable();
    while let Some(w) = words.next() {
        let w = w.trim_end_matches([',', ';', ')']);
        if !w.starts_with("--") || w.len() < 3 {
            break;
        }
        match words.peek() {
            Some(v) if !v.starts_with("--") => {
                let v = v.trim_end_matches([',', ';', ')']).to_owned();
                words.next();
                out.push((w.to_owned(), v));
            }
            _ => out.push((w.to_owned(), String::new())),
        }
    }
    out
}

/// The fix of the finding that stopped a command: the text after the last `fix: ` of its
/// first error line, up to the option that accepts the data.
pub fn stop_fix(stderr: &str) -> Option<String> {
    let (_, _, text) = (findings_with_severity(stderr).into_iter()).find(|(w, _, _)| !w)?;
    // The finding's own fix is its last: an alternative that fits as well is named before it
    // with its fix in parentheses.
    let fix = text.rsplit_once("; fix: ")?.1;
    let fix = fix.split("; --accept-setup").next().unwrap_or(fix);
    Some(fix.trim().to_owned())
}

/// A case's arguments with a fix's flags applied: a flag that takes one value (`--tip`,
/// `--length-unit`, `--gravity`, `--socket-distance-m`, …) replaces the one given (every
/// `--tip` by the fix's tips), a column edit (`--column-…`) is added.
pub fn with_fix(args: &[String], flags: &[(String, String)]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let replaced = |f: &str| !f.starts_with("--column-") && flags.iter().any(|(g, _)| g == f);
    let mut i = 0;
    while i < args.len() {
        if replaced(&args[i]) {
            i += 2;
            continue;
        }
        out.push(args[i].clone());
        i += 1;
    }
    for (f, v) in flags {
        out.push(f.clone());
        if !v.is_empty() {
            out.push(v.clone());
        }
    }
    out
}

/// Whether a printed fix, applied, let the command run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FixApplied {
    /// No flag to apply (no stop, or a fix in words).
    NotApplicable,
    /// Applied, the command ran (exit 0 or 1).
    Ran,
    /// Applied, the command stopped again.
    StoppedAgain,
}

/// Judges a case by the command's exit code (`None`: killed or no code), its output
/// (standard error, then standard output) and, for a stop with a flag in its fix, what
/// applying the fix did (`applied`). `fix_words`: what the fix must name; `locate_words`:
/// words that place the mistake (a line, a column).
pub fn judge(
    family: Family,
    words: (&[Vec<String>], &[String]),
    code: Option<i32>,
    output: &str,
    applied: FixApplied,
) -> Outcome {
    let (fix_words, locate_words) = words;
    let found = findings_with_severity(output);
    let stopped = code != Some(0) && code != Some(1);
    let located = || (locate_words.iter()).any(|w| has_word(output, w));
    match family.spec().expect {
        Expect::Clean => {
            if found.is_empty() {
                Outcome::Clean
            } else {
                Outcome::FalseAlarm
            }
        }
        Expect::Listed => match (stopped, located()) {
            (false, true) => Outcome::NamedRight,
            (false, false) if found.is_empty() => Outcome::Silent,
            (false, false) => Outcome::Warned,
            (true, true) => Outcome::Located,
            (true, false) => Outcome::Generic,
        },
        Expect::Note(class) => {
            if stopped {
                if found.is_empty() {
                    Outcome::Generic
                } else {
                    Outcome::FalseAlarm
                }
            } else if found.iter().any(|(_, c, _)| c == class) {
                Outcome::NamedRight
            } else if found.is_empty() {
                Outcome::Silent
            } else {
                Outcome::Warned
            }
        }
        Expect::Stop(class, _) => {
            if !stopped {
                return if found.is_empty() {
                    Outcome::Silent
                } else {
                    Outcome::Warned
                };
            }
            let named =
                |text: &str| (fix_words.iter()).all(|any| any.iter().any(|w| has_word(text, w)));
            let errors: Vec<&(bool, String, String)> = found.iter().filter(|f| !f.0).collect();
            let right = (errors.iter()).find(|(_, c, _)| c == class);
            let wrong = (errors.iter()).find(|(_, c, _)| c != class && !NO_CAUSE.contains(&&**c));
            if let Some((_, _, text)) = right {
                if applied == FixApplied::StoppedAgain {
                    Outcome::HarmfulFix
                } else if named(text) {
                    Outcome::NamedRight
                } else {
                    Outcome::ClassOnly
                }
            } else if let Some((_, _, text)) = wrong {
                let fix = text.rsplit_once("; fix: ").map_or("", |f| f.1);
                if !fix_words.is_empty() && named(text) {
                    // The data fit the cause named and the expected one as well, and the
                    // finding names both (the expected fix as the alternative's).
                    Outcome::NamedRight
                } else if fix_flags(fix).is_empty() {
                    Outcome::WrongCause
                } else {
                    Outcome::HarmfulFix
                }
            } else if located() {
                Outcome::Located
            } else {
                Outcome::Generic
            }
        }
    }
}

/// One run case: the case, what it ran, its outcome and the first setup line (or the last
/// line of the standard error).
#[derive(Clone, Debug)]
pub struct CaseResult {
    /// The case.
    pub case: Case,
    /// Its outcome.
    pub outcome: Outcome,
    /// Exit code (`None`: none).
    pub code: Option<i32>,
    /// What the check said: the first setup line, else the first error line, else empty.
    pub said: String,
    /// Seconds the command took.
    pub seconds: f64,
    /// Whether the mistake leaves a trace a fit of the least model can see ([`Visibility`]).
    pub visibility: Visibility,
}

/// A mistake is *invisible in the data* when the screening fit's training residual on the
/// mistaken data is below this many times the one on the same data without the mistake: the
/// data carry no trace of it that a fit of the nominal model (frames only) could see.
pub const INVISIBLE_RATIO: f64 = 1.05;

/// The model of the screening fit (`hapcal calibrate --model`): the least one the data's kind
/// takes. Measurement files (markers, poses, positions): frames-only, the nominal kinematics
/// with the instrument's and markers' frames fitted. Socket folders and haptic logs take no
/// frames-only fit: geometric, which also fits joint offsets and link lengths (a zero off or
/// a longer link can be absorbed there).
pub fn screening_model(rec: Recording) -> ModelName {
    match rec {
        R::SocketsIiwa | R::SocketsPanda | R::Haptic | R::HapticMotion => ModelName::Geometric,
        _ => ModelName::FramesOnly,
    }
}

/// The arguments that turn a case's `hapcal calibrate` arguments into its screening fit:
/// the setup check accepted, the [`screening_model`], the report as JSON on standard output.
pub fn screening_args(rec: Recording) -> Vec<String> {
    vec![
        "--accept-setup".to_owned(),
        "--model".to_owned(),
        screening_model(rec).name().to_owned(),
        "--json".to_owned(),
    ]
}

/// The training residual of a calibration, read from `hapcal calibrate --json`: the figures
/// the data's kind has after the fit, each over the training sets (test sets left out).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Residual {
    /// RMS of the 3-D marker position error, m (marker and pose data).
    pub position_rms_m: Option<f64>,
    /// RMS orientation error, rad (pose data).
    pub orientation_rms_rad: Option<f64>,
    /// RMS distance error, m (distance rows, haptic logs).
    pub distance_rms_m: Option<f64>,
    /// Mean absolute error of the tips about their sockets ("consistency"), m (socket data).
    pub consistency_m: Option<f64>,
    /// Socket distance error ("distortion"), m (socket data with two sockets).
    pub socket_distance_error_m: Option<f64>,
}

impl Residual {
    /// Reads the training residual from the JSON report of `hapcal calibrate --json`
    /// (`placements[]` with `role`, `n_rows` and `after`). Over several training sets each
    /// figure is the row-weighted root mean square of the sets' figures.
    ///
    /// # Errors
    /// Text that is not JSON, or a report without a training set or without a figure.
    pub fn from_report_json(text: &str) -> Result<Residual> {
        let doc: serde_json::Value =
            serde_json::from_str(text).context("the calibration report is not JSON")?;
        let sets = (doc.get("placements"))
            .and_then(serde_json::Value::as_array)
            .context("the calibration report has no data sets")?;
        // Per figure: Σ n·v², Σ n.
        let mut acc = [(0.0f64, 0.0f64); 5];
        let mut n_train = 0;
        for set in sets {
            if set.get("role").and_then(serde_json::Value::as_str) != Some("train") {
                continue;
            }
            n_train += 1;
            let n = (set.get("n_rows").and_then(serde_json::Value::as_f64)).unwrap_or(1.0);
            let after = set.get("after");
            let at = |path: &[&str]| -> Option<f64> {
                let mut v = after?;
                for k in path {
                    v = v.get(*k)?;
                }
                v.as_f64()
            };
            let figures = [
                at(&["pose", "position_rms_m"]),
                at(&["pose", "orientation_rms_rad"]),
                at(&["pose", "distance_rms_m"]).or_else(|| at(&["distance_rms_m"])),
                at(&["mean_absolute_error_m"]),
                at(&["distance_error_m"]),
            ];
            for (a, f) in acc.iter_mut().zip(figures) {
                if let Some(v) = f {
                    a.0 += n * v * v;
                    a.1 += n;
                }
            }
        }
        if n_train == 0 {
            bail!("the calibration report has no training set");
        }
        let [p, o, d, c, s] = acc.map(|(sum, n)| (n > 0.0).then(|| (sum / n).sqrt()));
        let r = Residual {
            position_rms_m: p,
            orientation_rms_rad: o,
            distance_rms_m: d,
            consistency_m: c,
            socket_distance_error_m: s,
        };
        if r.figures().iter().all(Option::is_none) {
            bail!("the calibration report has no residual figure");
        }
        Ok(r)
    }

    /// The figures in a fixed order (position, orientation, distance, consistency, socket
    /// distance).
    fn figures(&self) -> [Option<f64>; 5] {
        [
            self.position_rms_m,
            self.orientation_rms_rad,
            self.distance_rms_m,
            self.consistency_m,
            self.socket_distance_error_m,
        ]
    }
}

/// How much larger the mistaken data's residual is than the correct data's: the largest
/// ratio over the figures both have (a mistake in the orientations alone shows in the
/// orientation RMS only). A figure zero on the correct data counts 1 if it is zero on the
/// mistaken data too, else infinity. `None`: no figure in common.
pub fn residual_ratio(mistaken: &Residual, correct: &Residual) -> Option<f64> {
    (mistaken.figures().into_iter())
        .zip(correct.figures())
        .filter_map(|(m, c)| Some((m?, c?)))
        .map(|(m, c)| {
            let (m, c) = (m.abs(), c.abs());
            if c > 0.0 {
                m / c
            } else if m > 0.0 {
                f64::INFINITY
            } else {
                1.0
            }
        })
        .reduce(f64::max)
}

/// Whether a mistake leaves a trace the screening fit can see.
#[derive(Clone, Debug, PartialEq)]
pub enum Visibility {
    /// Correct data: not screened.
    NotScreened,
    /// The mistaken data's residual over the correct data's ([`residual_ratio`]).
    Ratio(f64),
    /// The screening fit of the mistaken data failed (the reader or the fit refused them:
    /// the data show the mistake); the message's first line.
    MistakenFailed(String),
    /// The screening fit of the correct data failed, or the two have no figure in common:
    /// not decided, counted visible.
    Undecided(String),
}

impl Visibility {
    /// Screens a mistake from its two screening fits: the mistaken data's and the correct
    /// data's (`Err`: the fit's error message).
    pub fn screen(
        mistaken: &std::result::Result<Residual, String>,
        correct: &std::result::Result<Residual, String>,
    ) -> Visibility {
        match (mistaken, correct) {
            (_, Err(e)) => Visibility::Undecided(format!("correct data: {e}")),
            (Err(e), Ok(_)) => Visibility::MistakenFailed(e.clone()),
            (Ok(m), Ok(c)) => residual_ratio(m, c).map_or_else(
                || Visibility::Undecided("no residual figure in common".to_owned()),
                Visibility::Ratio,
            ),
        }
    }

    /// Whether the mistake is invisible in the data: a ratio below [`INVISIBLE_RATIO`].
    pub fn is_invisible(&self) -> bool {
        matches!(self, Visibility::Ratio(r) if *r < INVISIBLE_RATIO)
    }

    /// The ratio, or a word for the report (`fit failed`, `undecided`, `—` unscreened).
    pub fn cell(&self) -> String {
        match self {
            Visibility::NotScreened => "—".to_owned(),
            Visibility::Ratio(r) if *r >= 1e4 => format!("{r:.1e}"),
            Visibility::Ratio(r) if *r >= 10.0 => format!("{r:.0}"),
            Visibility::Ratio(r) => format!("{r:.3}"),
            Visibility::MistakenFailed(_) => "fit failed".to_owned(),
            Visibility::Undecided(_) => "undecided".to_owned(),
        }
    }
}

/// The case's data without its mistake: the same recording, rows (a part drops the same
/// fifth) and simulation seed, read as the recording is (its tips, socket distance).
pub fn correct_twin(case: &Case) -> Case {
    Case {
        id: twin_key(case),
        family: Family::AsIs,
        recording: case.recording,
        mistake: Mistake::None,
        seed: case.seed,
        part: case.part,
        half: case.half,
    }
}

/// The identity of a case's [`correct_twin`]: cases with the same key have the same correct
/// data (a recording's part 0 is the recording; a part or a simulation has its own seed).
pub fn twin_key(case: &Case) -> String {
    let rec = case.recording;
    let simulated = rec.sim_arm().is_some() || rec == R::HapticMotion;
    if simulated {
        format!("{}/seed{}", rec.name(), case.seed)
    } else if case.part > 0 {
        format!("{}/part{}/seed{}", rec.name(), case.part, case.seed)
    } else {
        rec.name().to_owned()
    }
}

/// What the check said, for the report: the first setup finding's line, else the first
/// line with `error`, else the last line.
pub fn what_was_said(stderr: &str) -> String {
    if let Some((_, line)) = findings(stderr).into_iter().next() {
        return line;
    }
    (stderr.lines().find(|l| l.contains("error")))
        .or_else(|| stderr.lines().last())
        .unwrap_or_default()
        .trim()
        .to_owned()
}

/// Counts per outcome.
pub(super) fn counts<'a>(
    results: impl Iterator<Item = &'a CaseResult>,
) -> BTreeMap<Outcome, usize> {
    let mut m = BTreeMap::new();
    for r in results {
        *m.entry(r.outcome).or_insert(0) += 1;
    }
    m
}

/// Whether a case is a visible mistake: a mistake family (not correct data) whose screening
/// did not find it invisible ([`Visibility::is_invisible`]).
pub fn is_visible_mistake(r: &CaseResult) -> bool {
    !r.case.family.is_correct() && !r.visibility.is_invisible()
}

/// The figures the lead quotes for one selection of cases: over visible mistakes, how many
/// the check named, located, named wrongly, gave a harmful fix for, and was silent on; over
/// the cases where a finding or a stop is a false alarm (correct data, and visible mistakes
/// of a note family), how many.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VisibleSummary {
    /// Visible mistakes (stop, note and listed families).
    pub n_visible: usize,
    /// Of them, named (the class right, [`Outcome::is_named`]).
    pub named: usize,
    /// Of them, located without a cause.
    pub located: usize,
    /// Of them, another cause named with a fix in words.
    pub wrong_cause: usize,
    /// Of them, a harmful fix.
    pub harmful: usize,
    /// Of them, silent.
    pub silent: usize,
    /// False alarms.
    pub false_alarms: usize,
    /// Cases a false alarm is possible on: correct data and visible note-family mistakes.
    pub n_alarm_cases: usize,
}

impl VisibleSummary {
    /// Counts `results`.
    pub fn of<'a>(results: impl IntoIterator<Item = &'a CaseResult>) -> VisibleSummary {
        let mut s = VisibleSummary {
            n_visible: 0,
            named: 0,
            located: 0,
            wrong_cause: 0,
            harmful: 0,
            silent: 0,
            false_alarms: 0,
            n_alarm_cases: 0,
        };
        for r in results {
            let visible = is_visible_mistake(r);
            let note = matches!(r.case.family.spec().expect, Expect::Note(_));
            if visible {
                s.n_visible += 1;
                s.named += usize::from(r.outcome.is_named());
                s.located += usize::from(r.outcome == Outcome::Located);
                s.wrong_cause += usize::from(r.outcome == Outcome::WrongCause);
                s.harmful += usize::from(r.outcome == Outcome::HarmfulFix);
                s.silent += usize::from(r.outcome == Outcome::Silent);
            }
            if r.case.family.is_correct() || (visible && note) {
                s.n_alarm_cases += 1;
                s.false_alarms += usize::from(r.outcome == Outcome::FalseAlarm);
            }
        }
        s
    }

    /// One line: `visible mistakes N, named X (x %), located …, named or located (z %), wrong
    /// cause W, harmful fixes H, silent S (s %), false alarms F of G`.
    pub fn line(&self) -> String {
        let pct = |k: usize| {
            if self.n_visible == 0 {
                "—".to_owned()
            } else {
                format!("{:.0} %", 100.0 * k as f64 / self.n_visible as f64)
            }
        };
        format!(
            "visible mistakes {}, named {} ({}), located {} ({}), named or located {}, wrong \
             cause {}, harmful fixes {}, silent {} ({}), false alarms {} of {}",
            self.n_visible,
            self.named,
            pct(self.named),
            self.located,
            pct(self.located),
            pct(self.named + self.located),
            self.wrong_cause,
            self.harmful,
            self.silent,
            pct(self.silent),
            self.false_alarms,
            self.n_alarm_cases
        )
    }
}
