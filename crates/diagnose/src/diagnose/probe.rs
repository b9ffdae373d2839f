//! Which joint: how much of the gap a free joint-angle error (a degree-6 Chebyshev
//! polynomial of one joint's reading) would explain, joint by joint.

use hapcal_io::Device;
use hapcal_transmission::Chebyshev;
use rayon::prelude::*;

use super::JointProbe;
use super::baseline::{Baseline, Fit};
use crate::model::{Term, TermKind};
use crate::stats::f_sf;

/// Degree of a joint's probe polynomial.
const PROBE_DEGREE: usize = 6;

/// Smallest fraction of a probe column's norm left beside the baseline for it to count.
const PROBE_VISIBLE_TOL: f64 = 0.02;

/// The probes of every joint, in parallel (rayon), collected in joint order; a joint whose
/// probe cannot be built or evaluated is left out.
pub(super) fn joint_probes(device: &Device, b: &Baseline, fit: &Fit) -> Vec<JointProbe> {
    (0..b.n_joints)
        .into_par_iter()
        .map(|j| probe_joint(device, b, fit, j))
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect()
}

/// Joint `j`'s probe: the baseline's in-sample excess its visible columns explain, and their
/// F-test.
fn probe_joint(device: &Device, b: &Baseline, fit: &Fit, j: usize) -> Option<JointProbe> {
    let base = &fit.base;
    let terms = probe_terms(device, b, j)?;
    let (_, _, qc, _) = fit.beside(&b.setup, terms, PROBE_VISIBLE_TOL).ok()?;
    let k = qc.ncols() as f64;
    let drss = (qc.transpose() * &base.r_perp).norm_squared();
    let excess = base.rss - base.dof();
    let p = if k > 0.0 {
        f_sf(
            (drss / k) / ((base.rss - drss).max(1e-300) / (base.dof() - k).max(1.0)),
            k,
            (base.dof() - k).max(1.0),
        )
    } else {
        1.0
    };
    Some(JointProbe {
        joint: j + 1,
        explained_pct: if excess > 0.0 {
            100.0 * ((drss - k) / excess).clamp(0.0, 1.0)
        } else {
            0.0
        },
        p_value: p,
    })
}

/// The probe's terms on joint `j`: Chebyshev polynomials 1 to [`PROBE_DEGREE`] over the
/// joint's range.
fn probe_terms(device: &Device, b: &Baseline, j: usize) -> Option<Vec<Term>> {
    let (lo, hi) = device.joint_limits().get(j).copied().unwrap_or((-1.0, 1.0));
    let probe = Chebyshev::try_new(lo, hi, vec![0.0; PROBE_DEGREE + 1]).ok()?;
    let terms = (1..=PROBE_DEGREE)
        .map(|k| Term {
            name: format!("probe.j{}_cheb{k}", j + 1),
            unit: "rad",
            kind: TermKind::Joint {
                joint: j,
                g: (b.data.q().iter())
                    .map(|q| probe.basis(q[j]).get(k).copied().unwrap_or(0.0))
                    .collect(),
            },
        })
        .collect();
    Some(terms)
}
