//! The text report of a serial arm's diagnosis ([`crate::arm`]), with the ladder of kinematic
//! rungs and the calibration model of the named effects.

use std::fmt::{self, Write as _};

use hapcal_calibrate::baseline::DataKind;
use hapcal_contract::{Effect, ModelName};

use super::{significance, write_step};
use crate::arm::ArmDiagnosis;
use crate::verdict::MILLIMETRES;

fn mm(m: f64) -> String {
    MILLIMETRES.of(m)
}

/// What the training rows measured, in words.
fn kind_name(kind: DataKind) -> &'static str {
    match kind {
        DataKind::Sockets => "socket",
        DataKind::Distances => "distance",
        DataKind::Measurements => "marker",
        DataKind::HapticLogs => "haptic log",
    }
}

/// A section of the text report, appended to the text.
type Section = fn(&mut String, &ArmDiagnosis) -> fmt::Result;

/// The diagnosis as a text report: floor and gap, where (flagged bins), which (every
/// candidate), how far (accepted effects with their parameters), the ladder, the verdict.
pub fn render_arm(d: &ArmDiagnosis) -> String {
    let mut s = String::new();
    let sections: [Section; 6] = [gap, where_, which, how_far, ladder, verdict];
    for section in sections {
        let _ = section(&mut s, d);
    }
    s
}

/// The baseline, the noise floor and the gap above it.
fn gap(s: &mut String, d: &ArmDiagnosis) -> fmt::Result {
    writeln!(
        s,
        "geometric baseline: {} data, {} training configurations, {} parameters kept",
        kind_name(d.kind),
        d.n_configurations,
        d.n_baseline_params
    )?;
    writeln!(s, "floor: {}", d.floor_method)?;
    let (heldout, gap) = (mm(d.heldout_rms_m), mm(d.gap_rms_m));
    let Some(floor) = d.floor_rms_m else {
        return writeln!(
            s,
            "held-out RMS {heldout} mm; no floor: gap to the best model found {gap} mm"
        );
    };
    let significant = significance(d.gap_significant);
    writeln!(
        s,
        "held-out RMS {heldout} mm, floor {} mm, gap {gap} mm (p = {:.1e}, {significant})",
        mm(floor),
        d.gap_p_value,
    )
}

/// WHERE: the bins of the residual maps significantly above the floor.
fn where_(s: &mut String, d: &ArmDiagnosis) -> fmt::Result {
    writeln!(s, "\nWHERE (bins significantly above the floor, Holm)")?;
    let flagged: Vec<_> = d.where_.iter().filter(|b| b.flagged).collect();
    for b in &flagged {
        let (rms, floor) = (mm(b.rms_m), mm(b.floor_rms_m));
        writeln!(
            s,
            "  {:10} [{:.3}, {:.3}]  {rms} mm over {floor} mm, n {}",
            b.signal, b.lo, b.hi, b.n
        )?;
    }
    writeln!(s, "  {} of {} bins flagged", flagged.len(), d.where_.len())
}

/// WHICH: every candidate of every round, its held-out RMS before and after and the
/// decision.
fn which(s: &mut String, d: &ArmDiagnosis) -> fmt::Result {
    writeln!(
        s,
        "\nWHICH (held-out RMS before → after; improvement ± blocked SE; Holm p)"
    )?;
    writeln!(
        s,
        "  {:>2} {:20} {:>4} {:>9} {:>9} {:>7} {:>9} {:>9}  decision",
        "rd", "effect", "k", "before mm", "after mm", "gap %", "p (cv)", "p (F)"
    )?;
    for c in &d.candidates {
        let (before, after) = (mm(c.heldout_rms_before_m), mm(c.heldout_rms_after_m));
        let named = if c.accepted { "NAMED: " } else { "" };
        writeln!(
            s,
            "  {:>2} {:20} {:>4} {before:>9} {after:>9} {:>7.0} {:>9.1e} {:>9.1e}  {named}{}",
            c.round,
            c.effect,
            c.n_visible,
            c.gap_closed_pct,
            c.heldout_p_value,
            c.f_p_value,
            c.reason
        )?;
    }
    Ok(())
}

/// HOW FAR: each named effect's share of the gap, its parameters, and the effects it cannot
/// be told from on these data.
fn how_far(s: &mut String, d: &ArmDiagnosis) -> fmt::Result {
    writeln!(s, "\nHOW FAR")?;
    for st in &d.steps {
        let rms = (
            st.heldout_rms_before_m,
            st.heldout_rms_after_m,
            st.gap_closed_pct,
        );
        write_step(s, st.effect, rms, &st.parameters, (40, MILLIMETRES))?;
        for other in &st.alike {
            writeln!(
                s,
                "      the torque model is open: {other} in its place predicts as well (within two \
                 standard errors, beside the other named effects); to tell them apart record {}",
                st.effect.separating_measurement(*other)
            )?;
        }
        for (other, how) in (st.confusable_with.iter()).filter(|(o, _)| !st.alike.contains(o)) {
            writeln!(
                s,
                "      confusable with {other} on these data; to separate them record {how}"
            )?;
        }
    }
    writeln!(
        s,
        "  final held-out RMS {} mm; gap closed {:.0} %",
        mm(d.heldout_rms_final_m),
        d.gap_closed_pct
    )
}

/// LADDER: each kinematic rung's cross-validated and held-out RMS.
fn ladder(s: &mut String, d: &ArmDiagnosis) -> fmt::Result {
    let error = if d.kind == DataKind::Distances {
        "distance"
    } else {
        "3-D position"
    };
    writeln!(s, "\nLADDER (RMS of the {error} error, mm)")?;
    let tests = d.test_sets.join("  ");
    writeln!(s, "  {:40} {:>9}  {tests}", "rung", "CV train")?;
    for r in &d.ladder {
        let tests: Vec<String> = r.test_rms_m.iter().map(|v| mm(*v)).collect();
        writeln!(
            s,
            "  {:40} {:>9}  {}",
            r.rung,
            mm(r.cv_rms_m),
            tests.join("  ")
        )?;
    }
    Ok(())
}

/// The notes, the verdict (with the torque models left open) and the calibration model of
/// the named effects.
fn verdict(s: &mut String, d: &ArmDiagnosis) -> fmt::Result {
    for n in &d.notes {
        writeln!(s, "note: {n}")?;
    }
    let open: Vec<String> = (d.steps.iter())
        .filter(|st| d.verdict.effects().contains(&st.effect))
        .flat_map(|st| {
            st.alike
                .iter()
                .map(move |a| format!("{} or {a}", st.effect))
        })
        .collect();
    if open.is_empty() {
        writeln!(s, "\nverdict: {}", d.verdict)?;
    } else {
        let open = open.join(", ");
        writeln!(s, "\nverdict: {} (torque model open: {open})", d.verdict)?;
    }
    model_of_verdict(s, d.verdict.effects());
    Ok(())
}

/// The calibration model that describes the named effects (`hapcal calibrate --model …`), or
/// why none does: how this verdict compares with the rung `calibrate`'s ladder takes.
fn model_of_verdict(s: &mut String, named: &[Effect]) {
    if named.is_empty() {
        return;
    }
    let f = ModelName::for_effects(named);
    match f.model {
        Ok(Some(m)) => {
            let _ = writeln!(
                s,
                "calibration model of these effects: {m} (hapcal calibrate --model {m}; the \
                 ladder of --model auto takes it where cross-validation shows it)"
            );
        }
        Ok(None) => {
            let _ = writeln!(
                s,
                "no calibration model frees these effects: the kinematic rungs are what \
                 calibrate can fit"
            );
        }
        Err(together) => {
            let names: Vec<&str> = together.iter().map(|e| e.name()).collect();
            let _ = writeln!(
                s,
                "no one calibration model frees {} together: calibrate fits one of them at a \
                 time",
                names.join(" and ")
            );
        }
    }
    for (e, reason) in &f.beyond {
        let _ = writeln!(s, "  {e}: {reason}");
    }
}
