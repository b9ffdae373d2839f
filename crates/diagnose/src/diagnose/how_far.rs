//! How far: the gap the accepted effects close, the sufficiency rule that keeps an effect
//! explaining only a part of its round's gap from being named, the verdict, the signals the
//! final residual still depends on, and the notes on what is left.

use hapcal_io::Device;

use super::baseline::Baseline;
use super::residual_map::residual_map;
use super::which::Run;
use super::{DiagnoseConfig, SignalTest};
use crate::Verdict;
use crate::verdict::{MICROMETRES, residual_note, sufficient};

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
    let named = sufficient(&run.shares, |k| {
        notes.push(format!(
            "{} explains {:.0} % of the held-out gap left before it ({:.0} % in-sample) and a \
             significant residual remains: not enough to name it",
            run.accepted[k],
            100.0 * run.shares[k].heldout,
            100.0 * run.shares[k].in_sample
        ));
    });
    let verdict = Verdict::of(&run.accepted[..named]);
    if named > 0 && run.shares[named - 1].significant {
        let final_mse = run.steps[named - 1].heldout_rms_after_m.powi(2);
        notes.push(residual_note(
            &verdict,
            (final_mse, b.gap.floor0),
            (named, cfg.max_effects),
            MICROMETRES,
        ));
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
