//! How far: the gap the accepted effects close, the sufficiency rule that keeps an effect
//! explaining only a part of its round's gap from being named, the verdict, the signals the
//! final residual still depends on, and the notes on what is left.

use hapcal_io::Device;

use super::baseline::Baseline;
use super::residual_map::residual_map;
use super::which::Run;
use super::{DiagnoseConfig, SUFFICIENT_SHARE, SUFFICIENT_SHARE_IN_SAMPLE, SignalTest};
use crate::Verdict;

/// Most signals listed as leads.
const MAX_LEADS: usize = 6;

/// The how-far stage's output.
pub(super) struct HowFar {
    /// Cross-validated mean squared distance error after all accepted effects, m².
    pub(super) final_mse: f64,
    /// Share of the in-sample excess closed by all accepted effects, 0–1.
    pub(super) closed_in_sample: f64,
    pub(super) verdict: Verdict,
    /// Signals along which the final residual still varies, most significant first.
    pub(super) leads: Vec<String>,
    pub(super) notes: Vec<String>,
}

/// The stage on the run's accepted effects.
pub(super) fn how_far(device: &Device, b: &Baseline, run: &Run, cfg: &DiagnoseConfig) -> HowFar {
    let base = &run.fit.base;
    let excess0 = b.gap.excess0;
    let closed_in_sample = if excess0 > 0.0 {
        (excess0 - base.excess()) / excess0
    } else {
        0.0
    };
    let mut notes = Vec::new();
    let named = named(run, &mut notes);
    let verdict = Verdict::of(&run.accepted[..named]);
    if named > 0 && run.shares[named - 1].significant {
        notes.push(residual_note(b, run, named, &verdict, cfg));
    }
    HowFar {
        final_mse: base.cv.mse(),
        closed_in_sample,
        verdict,
        leads: leads(device, b, run, cfg.alpha),
        notes,
    }
}

/// The signals the final held-out residual significantly depends on, most significant first.
fn leads(device: &Device, b: &Baseline, run: &Run, alpha: f64) -> Vec<String> {
    let base = &run.fit.base;
    let (_, final_signals) = residual_map(device, &b.data, &base.lin, &base.cv, alpha);
    let mut leads: Vec<&SignalTest> = final_signals.iter().filter(|s| s.significant).collect();
    leads.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
    leads
        .iter()
        .take(MAX_LEADS)
        .map(|s| format!("{} (p = {:.1e})", s.signal, s.p_value))
        .collect()
}

/// How many of the accepted effects are named. Sufficiency, from the last accepted effect
/// back: one that closes less than [`SUFFICIENT_SHARE`] of its round's held-out gap (what the
/// effects before it left) and less than [`SUFFICIENT_SHARE_IN_SAMPLE`] of its round's
/// in-sample excess, leaving a significant gap, explains a part of something else; it is not
/// named (a note says so), and the rule goes on with the one before it.
fn named(run: &Run, notes: &mut Vec<String>) -> usize {
    let mut named = run.accepted.len();
    while named > 0 {
        let s = run.shares[named - 1];
        if s.heldout >= SUFFICIENT_SHARE
            || s.in_sample >= SUFFICIENT_SHARE_IN_SAMPLE
            || !s.significant
        {
            break;
        }
        notes.push(format!(
            "{} explains {:.0} % of the held-out gap left before it ({:.0} % in-sample) and a \
             significant residual remains: not enough to name it",
            run.accepted[named - 1],
            100.0 * s.heldout,
            100.0 * s.in_sample
        ));
        named -= 1;
    }
    named
}

/// The note on a significant residual left after the `named` effects of `verdict`.
fn residual_note(
    b: &Baseline,
    run: &Run,
    named: usize,
    verdict: &Verdict,
    cfg: &DiagnoseConfig,
) -> String {
    let final_mse = run.steps[named - 1].heldout_rms_after_m.powi(2);
    let floor0 = b.gap.floor0;
    let why = crate::verdict::stop_reason(named, cfg.max_effects);
    format!(
        "after {verdict} the cross-validated RMS is {:.1} µm, {:.1}× the floor's {:.1} µm, a \
         significant residual: another effect is at work that the verdict does not name \
         ({why})",
        final_mse.sqrt() * 1e6,
        (final_mse / floor0).sqrt(),
        floor0.sqrt() * 1e6
    )
}
