//! How far: the share of the gap the named effects close, the sufficiency rule that keeps an
//! effect explaining only a part of the gap from being named, the verdict, and the notes on
//! what is left.

use hapcal_contract::Effect;

use super::baseline::Baseline;
use super::cv::HeldOut;
use super::{ArmConfig, ArmStep};
use crate::Verdict;
use crate::verdict::{MILLIMETRES, RoundShare, residual_note, sufficient};

/// The how-far stage's output.
pub(super) struct HowFar {
    pub(super) verdict: Verdict,
    /// Cross-validated mean squared 3-D error after the named effects, m².
    pub(super) final_mse: f64,
    /// The gap: above the floor, or (without one) what the best model found removes, m².
    pub(super) gap2: f64,
    /// Share of the gap closed by the named effects, 0–1.
    pub(super) closed: f64,
    pub(super) notes: Vec<String>,
}

/// The gap closed by the run's effects `accepted` (`steps`, whose shares are restated
/// without a floor; `base`, their held-out errors; `p_after` and `in_sample_share` per effect,
/// as [`super::which::Run`]), and the effects the verdict names.
pub(super) fn how_far(
    b: &Baseline<'_>,
    base: &HeldOut,
    steps: &mut [ArmStep],
    accepted: &[Effect],
    (p_after, in_sample_share): (&[f64], &[f64]),
    cfg: &ArmConfig,
) -> HowFar {
    let (mse0, floor0) = (b.mse0, b.floor0);
    let mut notes = Vec::new();
    let final_mse = base.mse();
    let gap2 = match floor0 {
        Some(f) => mse0 - f,
        None => mse0 - final_mse,
    };
    if floor0.is_none() && mse0 > final_mse {
        // Without a floor, each step's share is of what the best model found removes.
        for st in steps.iter_mut() {
            st.gap_closed_pct = 100.0
                * (st.heldout_rms_before_m.powi(2) - st.heldout_rms_after_m.powi(2))
                / (mse0 - final_mse);
        }
    }
    let closed = if gap2 > 0.0 {
        (mse0 - final_mse) / gap2
    } else {
        0.0
    };
    // Sufficiency (with a floor): the share of the gap its round faced is restated from the
    // steps' held-out errors.
    let named = match floor0 {
        Some(f) => {
            let shares: Vec<RoundShare> = (steps.iter().zip(in_sample_share).zip(p_after))
                .map(|((st, &in_sample), &p)| {
                    let before = st.heldout_rms_before_m.powi(2);
                    let after = st.heldout_rms_after_m.powi(2);
                    let faced = before - f;
                    RoundShare {
                        heldout: if faced > 0.0 {
                            (before - after) / faced
                        } else {
                            1.0
                        },
                        in_sample,
                        significant: p < cfg.alpha,
                    }
                })
                .collect();
            sufficient(&shares, |k| {
                notes.push(format!(
                    "{} closes {:.0} % of the gap left before it ({:.0} % in-sample) and a \
                     significant residual remains: not enough to name it (the effect at work \
                     is likely outside the library)",
                    steps[k].effect,
                    100.0 * shares[k].heldout,
                    100.0 * shares[k].in_sample
                ));
            })
        }
        None => accepted.len(),
    };
    let verdict = Verdict::of(&accepted[..named]);
    if named > 0
        && let Some(f) = floor0
        && p_after[named - 1] < cfg.alpha
    {
        let final_mse = steps[named - 1].heldout_rms_after_m.powi(2);
        notes.push(residual_note(
            &verdict,
            (final_mse, f),
            (named, cfg.max_effects),
            MILLIMETRES,
        ));
    }
    if let Some(step) = steps.first()
        && step.heldout_rms_after_m > 0.95 * step.heldout_rms_before_m
    {
        notes.push(format!(
            "{} is significant but buys little: held-out RMS {:.3} → {:.3} mm ({:+.1} %)",
            step.effect,
            step.heldout_rms_before_m * 1e3,
            step.heldout_rms_after_m * 1e3,
            100.0 * (step.heldout_rms_after_m / step.heldout_rms_before_m - 1.0)
        ));
    }
    HowFar {
        verdict,
        final_mse,
        gap2,
        closed,
        notes,
    }
}
