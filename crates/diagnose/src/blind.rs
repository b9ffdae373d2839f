//! The blind test: draw a case (no effect, one library effect, one effect outside the
//! library, or two library effects) with its size and a seed, simulate the log without
//! telling [`crate::diagnose`] which, and score the verdict.
//!
//! **Sizing** (docs/diagnosis.md §5): an effect's size is the ratio `s` of the
//! baseline's residual RMS to the noise floor it would produce alone, drawn log-uniformly
//! in `[2, 20]` ("just detectable" to "dominant"). The visible RMS `σ·sqrt(s² − 1)` is set by
//! simulating the same seed with and without a reference-size effect, fitting the baseline
//! to both ([`crate::baseline_residuals_m`]), and scaling the effect's amplitudes by the
//! ratio of the target to the measured difference (effects are linear in their amplitudes
//! to first order).

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use hapcal_contract::Effect;
use hapcal_io::{Device, LogRow};
use hapcal_sim::{
    HAPTIC_LIBRARY, Injected, MotionConfig, NoiseModel, OUTSIDE_LIBRARY, SimConfig, Truth,
    injectable, simulate_motion,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::{DiagnoseConfig, Diagnosis, Error, Verdict, baseline_residuals_m, diagnose};

/// What a blind case holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CaseKind {
    /// No unmodelled effect: the answer must be `none`.
    None,
    /// One library effect: the answer must name it.
    One,
    /// One effect outside the library: the answer must be `none`, with a localisation.
    Outside,
    /// Two library effects: both should be named.
    Two,
}

impl CaseKind {
    /// The kind as the report writes it: `none`, `one`, `outside`, `two`.
    pub fn name(self) -> &'static str {
        match self {
            CaseKind::None => "none",
            CaseKind::One => "one",
            CaseKind::Outside => "outside",
            CaseKind::Two => "two",
        }
    }
}

/// One blind case.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Case {
    /// Seed of the simulation (and of the draw).
    pub seed: u64,
    /// Its kind.
    pub kind: CaseKind,
    /// The injected effects (already scaled).
    #[serde(serialize_with = "effects_as_strings")]
    pub effects: Vec<Injected>,
    /// Size `s`: the baseline residual RMS the effect alone produces, in floors (per effect).
    pub sizes: Vec<f64>,
}

fn effects_as_strings<S: serde::Serializer>(e: &[Injected], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(e.iter().map(ToString::to_string))
}

/// `verdict` with its effects in the simulator's order ([`injectable`]; any other effect
/// last): the order of a case's expected verdict.
fn in_library_order(verdict: &Verdict) -> Verdict {
    let mut effects = verdict.effects().to_vec();
    effects.sort_by_key(|&e| injectable().position(|i| i == e).unwrap_or(usize::MAX));
    match verdict {
        Verdict::Effects(_) => Verdict::Effects(effects),
        other => other.clone(),
    }
}

impl Case {
    /// The expected verdict: none, or the injected library effects in the simulator's order.
    pub fn expected(&self) -> Verdict {
        match self.kind {
            CaseKind::None | CaseKind::Outside => Verdict::None,
            _ => {
                let injected: Vec<Effect> = self.effects.iter().map(|e| e.effect).collect();
                in_library_order(&Verdict::of(&injected))
            }
        }
    }

    /// The row label of the confusion matrix: `none`, the effect's name, `outside:<name>`,
    /// or `two`.
    pub fn label(&self) -> String {
        match self.kind {
            CaseKind::None => "none".to_owned(),
            CaseKind::One => self
                .effects
                .first()
                .map_or("?".to_owned(), |e| e.effect.name().to_owned()),
            CaseKind::Outside => format!(
                "outside:{}",
                self.effects.first().map_or("?", |e| e.effect.name())
            ),
            CaseKind::Two => "two".to_owned(),
        }
    }
}

/// A reference-size `effect` (one the simulator injects) with random joints and phases
/// (amplitudes are scaled later).
fn reference_effect(
    effect: Effect,
    device: &Device,
    rng: &mut ChaCha8Rng,
) -> Result<Injected, Error> {
    let n = device.n_joints();
    let capstan_joints: Vec<usize> = device.capstans.iter().map(|c| c.joint).collect();
    let direct: Vec<usize> = (1..=n).filter(|j| !capstan_joints.contains(j)).collect();
    let pick = |rng: &mut ChaCha8Rng, from: &[usize]| -> usize {
        from.get(rng.random_range(0..from.len().max(1)))
            .copied()
            .unwrap_or(1)
    };
    let phase = |rng: &mut ChaCha8Rng| TAU * rng.random::<f64>();
    let all: Vec<usize> = (1..=n).collect();
    // Joints with a gravity torque that varies (not the vertical joint 1, not the tip joint).
    let torque_joints: Vec<usize> = (2..n.max(2)).collect();
    let params: Vec<(String, f64)> = match effect {
        Effect::CableAngle => vec![("k".into(), 1e-3)],
        Effect::ThermalDrift => vec![("k".into(), 1e-6)],
        Effect::Latency => vec![("tau".into(), 1e-3)],
        Effect::CableOffset => vec![("c".into(), 1e-3)],
        Effect::GravityCompliance => vec![(format!("j{}", pick(rng, &torque_joints)), 1e-3)],
        Effect::Backlash => vec![(format!("j{}", pick(rng, &all)), 1e-3)],
        Effect::FirstHarmonic => {
            let j = pick(rng, if direct.is_empty() { &all } else { &direct });
            vec![(format!("j{j}"), 1e-3), (format!("phase{j}"), phase(rng))]
        }
        Effect::CapstanHarmonic => {
            let j = pick(rng, &capstan_joints);
            vec![(format!("j{j}"), 1e-3), (format!("phase{j}"), phase(rng))]
        }
        Effect::JointBump => {
            let j = pick(rng, &all);
            let (lo, hi) = device
                .joint_limits()
                .get(j - 1)
                .copied()
                .unwrap_or((-1.0, 1.0));
            let at = lo + (hi - lo) * (0.3 + 0.4 * rng.random::<f64>());
            vec![
                (format!("j{j}"), 1e-3),
                (format!("at{j}"), at),
                ("width".into(), 0.12 * (hi - lo)),
            ]
        }
        Effect::CableDrumRunout => vec![("a".into(), 1e-4), ("phase".into(), phase(rng))],
        _ => Vec::new(),
    };
    Injected::try_new(effect, params).map_err(|e| Error::Blind {
        message: e.to_string(),
    })
}

/// The effect with its amplitudes (not phases, positions or widths) multiplied by `factor`.
fn scaled(e: &Injected, factor: f64) -> Injected {
    Injected {
        effect: e.effect,
        params: e
            .params
            .iter()
            .map(|(k, v)| {
                let amplitude = !(k.starts_with("phase") || k.starts_with("at") || k == "width");
                (k.clone(), if amplitude { v * factor } else { *v })
            })
            .collect(),
    }
}

/// The settings of a blind run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlindConfig {
    /// Samples per log.
    pub n_samples: usize,
    /// Smallest and largest size `s` (residual RMS in floors).
    pub size_range: (f64, f64),
    /// The diagnosis settings.
    pub diagnose: DiagnoseConfig,
}

impl Default for BlindConfig {
    /// 200 samples (the paper's pose count), sizes 2–20 floors, default diagnosis.
    fn default() -> BlindConfig {
        BlindConfig {
            n_samples: 200,
            size_range: (2.0, 20.0),
            diagnose: DiagnoseConfig::default(),
        }
    }
}

fn sim_cfg(device: &Device, seed: u64, n: usize) -> SimConfig {
    let mut cfg = SimConfig::new(seed, n);
    if let Some(cable) = device.cable_encoder.as_ref() {
        cfg = cfg.with_noise(NoiseModel::paper(cable));
    }
    cfg
}

/// Draws case `seed` of kind `kind` and simulates its log.
///
/// # Errors
/// [`Error::Blind`] if the simulation fails; the errors of [`baseline_residuals_m`].
pub fn draw_case(
    device: &Device,
    truth: &Truth,
    kind: CaseKind,
    seed: u64,
    cfg: &BlindConfig,
) -> Result<(Case, Vec<LogRow>), Error> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_b11d);
    let n_effects = match kind {
        CaseKind::None => 0,
        CaseKind::One | CaseKind::Outside => 1,
        CaseKind::Two => 2,
    };
    let mut drawn: Vec<Effect> = Vec::new();
    while drawn.len() < n_effects {
        let e = if kind == CaseKind::Outside {
            OUTSIDE_LIBRARY[rng.random_range(0..OUTSIDE_LIBRARY.len())]
        } else {
            HAPTIC_LIBRARY[rng.random_range(0..HAPTIC_LIBRARY.len())]
        };
        if !drawn.contains(&e) {
            drawn.push(e);
        }
    }
    let sim = sim_cfg(device, seed, cfg.n_samples);
    let motion = MotionConfig::default();
    let simulate = |effects: &[Injected]| {
        simulate_motion(device, truth, &sim, &motion, effects).map_err(|e| Error::Blind {
            message: e.to_string(),
        })
    };
    let clean = simulate(&[])?;
    let mut effects = Vec::new();
    let mut sizes = Vec::new();
    if !drawn.is_empty() {
        let r0 = baseline_residuals_m(device, &clean, &cfg.diagnose)?;
        let floor = (r0.iter().map(|r| r * r).sum::<f64>() / r0.len().max(1) as f64).sqrt();
        for e in drawn {
            let reference = reference_effect(e, device, &mut rng)?;
            let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
            let (lo, hi) = cfg.size_range;
            let s = lo * (hi / lo).powf(rng.random::<f64>());
            let r1 = baseline_residuals_m(
                device,
                &simulate(std::slice::from_ref(&reference))?,
                &cfg.diagnose,
            )?;
            let visible = (r1
                .iter()
                .zip(&r0)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / r0.len().max(1) as f64)
                .sqrt();
            let target = floor * (s * s - 1.0).max(0.0).sqrt();
            let factor = if visible > 0.0 { target / visible } else { 1.0 };
            effects.push(scaled(&reference, sign * factor));
            sizes.push(s);
        }
    }
    let rows = if effects.is_empty() {
        clean
    } else {
        simulate(&effects)?
    };
    Ok((
        Case {
            seed,
            kind,
            effects,
            sizes,
        },
        rows,
    ))
}

/// One scored case.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Outcome {
    /// The case.
    pub case: Case,
    /// Its confusion-matrix row label ([`Case::label`]).
    pub label: String,
    /// The expected verdict.
    pub expected: Verdict,
    /// The verdict.
    pub verdict: Verdict,
    /// Whether the verdict is right.
    pub correct: bool,
    /// For outside effects: whether the residual map points at it (joint probe or signal of
    /// the bumped joint; drum phase for the runout).
    pub localised: Option<bool>,
    /// Gap closed by the accepted effects, %.
    pub gap_closed_pct: f64,
    /// Gap in floors.
    pub gap_in_floors: f64,
}

/// Scores a diagnosis against its case.
pub fn score(case: &Case, d: &Diagnosis) -> Outcome {
    let expected = case.expected();
    let localised = (case.kind == CaseKind::Outside).then(|| {
        let Some(e) = case.effects.first() else {
            return false;
        };
        match e.effect {
            Effect::JointBump => {
                let j = e
                    .params
                    .iter()
                    .find_map(|(k, _)| k.strip_prefix('j')?.parse::<usize>().ok())
                    .unwrap_or(0);
                let best = d
                    .joints
                    .iter()
                    .max_by(|a, b| a.explained_pct.total_cmp(&b.explained_pct))
                    .map(|p| p.joint);
                best == Some(j)
                    || d.signals
                        .iter()
                        .any(|s| s.significant && s.signal == format!("q{j}"))
            }
            _ => d
                .signals
                .iter()
                .any(|s| s.significant && s.signal == "drum_phase"),
        }
    });
    Outcome {
        label: case.label(),
        correct: in_library_order(&d.verdict) == expected,
        expected,
        verdict: d.verdict.clone(),
        localised,
        gap_closed_pct: d.gap_closed_pct,
        gap_in_floors: d.gap_in_floors,
        case: case.clone(),
    }
}

/// Draws, simulates, diagnoses and scores case `seed` of kind `kind`.
///
/// # Errors
/// The errors of [`draw_case`] and [`diagnose`].
pub fn run_case(
    device: &Device,
    truth: &Truth,
    kind: CaseKind,
    seed: u64,
    cfg: &BlindConfig,
) -> Result<(Outcome, Diagnosis), Error> {
    let (case, rows) = draw_case(device, truth, kind, seed, cfg)?;
    let d = diagnose(device, &rows, &cfg.diagnose)?;
    Ok((score(&case, &d), d))
}

/// The kind of blind case number `i` of a stratified run: one in eight `none`, one in
/// eight outside, one in eight two effects, the rest one library effect.
pub fn kind_of(i: u64) -> CaseKind {
    match i % 8 {
        0 => CaseKind::None,
        1 => CaseKind::Outside,
        2 => CaseKind::Two,
        _ => CaseKind::One,
    }
}

/// Summary of a blind run: rates and the confusion matrix (row = truth label, column =
/// verdict).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Cases per kind and how many were right: `(right, total)`.
    pub by_kind: BTreeMap<String, (usize, usize)>,
    /// Outside cases localised: `(localised, total)`.
    pub localised: (usize, usize),
    /// Right one-effect cases whose accepted effect closed ≥ 80 % of the gap: `(n, right)`.
    pub gap_closed_80: (usize, usize),
    /// Median gap closed over right one-effect cases, %.
    pub median_gap_closed_pct: f64,
    /// `matrix[label][verdict]` counts.
    pub matrix: BTreeMap<String, BTreeMap<String, usize>>,
}

/// Tallies outcomes.
pub fn summarise(outcomes: &[Outcome]) -> Summary {
    let mut s = Summary::default();
    let mut closed = Vec::new();
    for o in outcomes {
        let e = s
            .by_kind
            .entry(o.case.kind.name().to_owned())
            .or_insert((0, 0));
        e.0 += usize::from(o.correct);
        e.1 += 1;
        if let Some(l) = o.localised {
            s.localised.0 += usize::from(l);
            s.localised.1 += 1;
        }
        if o.case.kind == CaseKind::One && o.correct {
            s.gap_closed_80.1 += 1;
            s.gap_closed_80.0 += usize::from(o.gap_closed_pct >= 80.0);
            closed.push(o.gap_closed_pct);
        }
        let col = if o.case.kind == CaseKind::Two && o.correct {
            "both".to_owned()
        } else {
            o.verdict.to_string()
        };
        *s.matrix
            .entry(o.label.clone())
            .or_default()
            .entry(col)
            .or_insert(0) += 1;
    }
    closed.sort_by(f64::total_cmp);
    s.median_gap_closed_pct = closed.get(closed.len() / 2).copied().unwrap_or(0.0);
    s
}

/// Runs `n_cases` blind cases (seeds `first_seed…`, kinds stratified by [`kind_of`]) on
/// `device` and its simulated `truth` (the reference device,
/// `fixtures/reference-device/truth.toml`) and the paper's story (geometric baseline on 200
/// static poses of that truth with the paper's noise, `n_story` seeds), and returns the
/// Markdown report of `docs/results/diagnose.md`. `progress` is called after each case.
///
/// # Errors
/// A case that cannot be simulated or diagnosed ([`run_case`], named with its seed), a device
/// without a cable encoder, or the story's simulation or diagnosis.
pub fn report(
    device: &Device,
    truth: &Truth,
    n_cases: usize,
    first_seed: u64,
    n_story: usize,
    progress: &dyn Fn(usize),
) -> Result<String, Error> {
    use std::fmt::Write as _;
    let cfg = BlindConfig::default();
    let mut outcomes = Vec::new();
    for (i, seed) in (first_seed..first_seed + n_cases as u64).enumerate() {
        let (o, _) =
            run_case(device, truth, kind_of(seed), seed, &cfg).map_err(|e| Error::Blind {
                message: format!("blind case {seed}: {e}"),
            })?;
        outcomes.push(o);
        progress(i + 1);
    }
    let s = summarise(&outcomes);
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# `hapcal diagnose`: blind test and the paper's story\n"
    );
    let _ = writeln!(
        md,
        "Generated by `cargo xtask blind-test --cases {n_cases}` (release build; seeds {first_seed}–{}). \
         Each case simulates 200 time-ordered samples of the reference truth \
         (`fixtures/reference-device/truth.toml`, paper noise, real reading quantisation) with \
         no effect, one library effect, one effect outside the library (`joint_bump`, \
         `cable_drum_runout`) or two library effects, each sized so that the baseline's residual \
         RMS is 2–20 × the floor (log-uniform); the log goes to `diagnose` without its label.\n",
        first_seed + n_cases as u64 - 1
    );
    let pct = |(a, b): (usize, usize)| {
        if b == 0 {
            "–".to_owned()
        } else {
            format!("{a}/{b} = {:.1} %", 100.0 * a as f64 / b as f64)
        }
    };
    let _ = writeln!(md, "| cases | right | target |\n|---|---|---|");
    for (kind, target) in [
        ("one", "≥ 90 %"),
        ("none", "≥ 95 %"),
        ("outside", "`none`"),
        ("two", "both named"),
    ] {
        let v = s.by_kind.get(kind).copied().unwrap_or((0, 0));
        let _ = writeln!(md, "| {kind} | {} | {target} |", pct(v));
    }
    let _ = writeln!(
        md,
        "| outside, localised | {} | residual map points at it |",
        pct(s.localised)
    );
    let _ = writeln!(
        md,
        "| one, right, gap closed ≥ 80 % | {} (median {:.0} %) | ≥ 80 % |\n",
        pct(s.gap_closed_80),
        s.median_gap_closed_pct
    );
    let mut cols: Vec<String> = Vec::new();
    for row in s.matrix.values() {
        for c in row.keys() {
            if !cols.contains(c) {
                cols.push(c.clone());
            }
        }
    }
    cols.sort_by_key(|c| (c != "none", c != "both", c.clone()));
    let _ = writeln!(
        md,
        "Confusion matrix (row: what was injected; column: verdict; `both`: both effects of a \
         two-effect case named):\n"
    );
    let _ = writeln!(md, "| injected \\ verdict | {} |", cols.join(" | "));
    let _ = writeln!(md, "|---|{}", "---|".repeat(cols.len()));
    for (label, row) in &s.matrix {
        let cells: Vec<String> = (cols.iter())
            .map(|c| row.get(c).map_or(String::new(), ToString::to_string))
            .collect();
        let _ = writeln!(md, "| {label} | {} |", cells.join(" | "));
    }
    let _ = writeln!(md, "\nWrong verdicts:\n");
    for o in outcomes.iter().filter(|o| !o.correct) {
        let effects: Vec<String> = o.case.effects.iter().map(ToString::to_string).collect();
        let _ = writeln!(
            md,
            "- seed {}: {} (size {:?}) → `{}`",
            o.case.seed,
            effects.join(" + "),
            (o.case.sizes.iter())
                .map(|x| (x * 10.0).round() / 10.0)
                .collect::<Vec<_>>(),
            o.verdict
        );
    }
    // The paper's story.
    let _ = writeln!(
        md,
        "\n## The paper's story: transmissions left out\n\n\
         `hapcal simulate --truth fixtures/reference-device/truth.toml --seed S --out log.csv` \
         (200 static random poses, the paper's transmission errors, no other effect), then \
         `hapcal diagnose --baseline geometric`:\n"
    );
    let _ = writeln!(
        md,
        "| seed | gap (floors) | joints explaining most (free joint-angle error) | verdict | gap closed |\n|---|---|---|---|---|"
    );
    let story_cfg = DiagnoseConfig {
        baseline: hapcal_calibrate::model::ModelName::Geometric,
        ..DiagnoseConfig::default()
    };
    for seed in 1..=n_story as u64 {
        let cable = device.cable_encoder.ok_or_else(|| Error::Blind {
            message: "the paper's story needs a device with a cable encoder".to_owned(),
        })?;
        let sim = SimConfig::new(seed, 200).with_noise(NoiseModel::paper(&cable));
        let rows = hapcal_sim::simulate(device, truth, &sim).map_err(|e| Error::Blind {
            message: format!("the paper's story, seed {seed}: {e}"),
        })?;
        let d = diagnose(device, &rows, &story_cfg)?;
        let mut joints = d.joints.clone();
        joints.sort_by(|a, b| b.explained_pct.total_cmp(&a.explained_pct));
        let top: Vec<String> = (joints.iter().take(4))
            .map(|j| format!("j{} {:.0} %", j.joint, j.explained_pct))
            .collect();
        let _ = writeln!(
            md,
            "| {seed} | {:.1} | {} | `{}` | {:.0} % |",
            d.gap_in_floors,
            top.join(", "),
            d.verdict,
            d.gap_closed_pct
        );
    }
    Ok(md)
}
