//! The text report of a haptic device's diagnosis ([`crate::Diagnosis`]).

use std::fmt::{self, Write as _};

use super::{significance, write_step};
use crate::Diagnosis;
use crate::verdict::MICROMETRES;

fn um(m: f64) -> String {
    MICROMETRES.of(m)
}

/// The diagnosis as a text report: gap, where (flagged bins and signals), which (every
/// candidate), how far (accepted effects with their parameters), verdict.
pub fn render(d: &Diagnosis) -> String {
    let mut s = String::new();
    let sections: [fn(&mut String, &Diagnosis) -> fmt::Result; 4] = [gap, where_, which, how_far];
    for section in sections {
        let _ = section(&mut s, d);
    }
    s
}

/// The baseline, the noise floor and the gap above it.
fn gap(s: &mut String, d: &Diagnosis) -> fmt::Result {
    let (samples, params) = (d.n_samples, d.n_params);
    let baseline = d.baseline.name();
    writeln!(
        s,
        "baseline: {baseline}, {samples} samples, {params} identifiable parameters"
    )?;
    writeln!(s, "floor: {}", d.floor_method)?;
    let (heldout, floor, gap) = (um(d.heldout_rms_m), um(d.floor_rms_m), um(d.gap_rms_m));
    writeln!(
        s,
        "held-out RMS {heldout} µm, floor {floor} µm, gap {gap} µm = {:.2} floors (p = {:.1e}, {})",
        d.gap_in_floors,
        d.gap_p_value,
        significance(d.gap_significant)
    )
}

/// WHERE: the signals the residual depends on, with their bins above the floor, and how much
/// of it a free joint-angle error explains.
fn where_(s: &mut String, d: &Diagnosis) -> fmt::Result {
    writeln!(
        s,
        "\nWHERE (signals the residual depends on; bins above the floor)"
    )?;
    for t in d.signals.iter().filter(|t| t.significant) {
        let bins: Vec<String> = (d.where_.iter())
            .filter(|b| b.signal == t.signal && b.flagged)
            .map(|b| format!("[{:.3}, {:.3}) {} µm", b.lo, b.hi, um(b.rms_m)))
            .collect();
        let bins = bins.join("; ");
        writeln!(s, "  {:14} p = {:.1e}  {bins}", t.signal, t.p_value)?;
    }
    let flagged = d.where_.iter().filter(|b| b.flagged).count();
    writeln!(s, "  {flagged} of {} bins flagged", d.where_.len())?;
    let joints: Vec<String> = (d.joints.iter())
        .map(|j| format!("j{} {:.0}%", j.joint, j.explained_pct))
        .collect();
    writeln!(
        s,
        "  free joint-angle error explains: {}",
        joints.join(", ")
    )
}

/// WHICH: every candidate of every round, its held-out RMS before and after and the
/// decision.
fn which(s: &mut String, d: &Diagnosis) -> fmt::Result {
    writeln!(s, "\nWHICH (held-out RMS before → after, share of the gap)")?;
    writeln!(
        s,
        "  {:>2} {:22} {:>9} {:>9} {:>7} {:>9}  decision",
        "rd", "effect", "before µm", "after µm", "gap %", "p"
    )?;
    for c in &d.candidates {
        let (before, after) = (um(c.heldout_rms_before_m), um(c.heldout_rms_after_m));
        let accepted = if c.accepted { "ACCEPTED: " } else { "" };
        writeln!(
            s,
            "  {:>2} {:22} {before:>9} {after:>9} {:>7.0} {:>9.1e}  {accepted}{}",
            c.round, c.effect, c.gap_closed_pct, c.p_value, c.reason
        )?;
    }
    Ok(())
}

/// HOW FAR: each accepted effect's share of the gap and its parameters; what is still
/// unexplained, the notes and the verdict.
fn how_far(s: &mut String, d: &Diagnosis) -> fmt::Result {
    writeln!(s, "\nHOW FAR")?;
    for st in &d.steps {
        let rms = (
            st.heldout_rms_before_m,
            st.heldout_rms_after_m,
            st.gap_closed_pct,
        );
        write_step(s, st.effect, rms, &st.parameters, (34, MICROMETRES))?;
        if !st.confusable_with.is_empty() {
            let names: Vec<&str> = st.confusable_with.iter().map(|e| e.name()).collect();
            writeln!(s, "      resembles: {}", names.join(", "))?;
        }
    }
    let (rms, closed) = (um(d.heldout_rms_final_m), d.gap_closed_pct);
    writeln!(s, "  final held-out RMS {rms} µm; gap closed {closed:.0} %")?;
    if !d.leads.is_empty() {
        writeln!(s, "  still unexplained along: {}", d.leads.join(", "))?;
    }
    for n in &d.notes {
        writeln!(s, "note: {n}")?;
    }
    writeln!(s, "\nverdict: {}", d.verdict)
}
