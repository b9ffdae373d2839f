//! The setup check of socket recordings (MUKCa placement folders): the mistakes of
//! [`crate::setup`] for data that are joint readings alone.
//!
//! With the ball in a fixed socket, the nominal robot puts the ball at nearly one point for
//! every configuration of that socket: the counterpart of the frames-only residual is the
//! scatter of the nominal ball positions about each socket's mean (closed form, microseconds
//! per row), a fraction of a millimetre to a millimetre on a real robot. It is judged relative
//! to how far the arm moved between those configurations (the scatter of its joint origins): a
//! hypothesis that freezes the arm (readings in radians read as degrees barely move it) would
//! otherwise shrink the scatter without explaining anything. The hypotheses: joint readings in
//! degrees, two joint columns swapped or all reversed, and the ball on another link fixed to
//! the same joints (`--tip` naming the flange or a tool frame instead of the ball); a scatter
//! no hypothesis explains, far above a real robot's, says that the recordings do not come from
//! this robot. Readings outside the robot's limits are read again without them, so that the
//! unit or the column order is named instead of the first reading outside a limit.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use hapcal_io::{Device, SocketPlacement};
use hapcal_kinematics::{Chain, Vector3};

use crate::measured::PLAUSIBLE_FRAMES_ONLY_RMS_M;
use crate::setup::{
    Corrected, Finding, MistakeClass, Residual, ResidualOf, SetupReport, Severity, judge,
};

/// One socket's configurations: the joint readings of each row.
type Socket = Vec<Vec<f64>>;

/// The setup check of the socket folders `paths` recorded with `device` (from a URDF with the
/// tip `tip` when `urdf` is given).
///
/// # Errors
/// A folder that cannot be read even without the joint limits, or a device whose chain does
/// not compile.
pub fn check_sockets(
    device: &Device,
    urdf: Option<&Path>,
    tip: &str,
    paths: &[PathBuf],
) -> Result<SetupReport> {
    let chain = device
        .chain()
        .context("building the robot's kinematic chain")?;
    let (placements, outside_limits) = match hapcal_io::read_mukca_paths_for(paths, device) {
        Ok(p) => (p, None),
        Err(e) => {
            let open = hapcal_io::read_mukca_paths_for(paths, &unbounded(device))
                .context("reading the socket folders")?;
            (open, Some(e.to_string()))
        }
    };
    let sockets: Vec<Socket> = (placements.iter())
        .flat_map(|p: &SocketPlacement| p.sockets.iter().map(|s| s.q.clone()))
        .filter(|s| s.len() > 1)
        .collect();
    let as_given = scatter(&chain, &sockets);
    let n_joints = chain.n_joints();
    let mut hypotheses: Vec<Corrected<(Option<Chain>, Vec<Socket>)>> = Vec::new();
    let remap = |edit: &dyn Fn(&mut Vec<f64>)| -> Vec<Socket> {
        (sockets.iter())
            .map(|s| {
                (s.iter().cloned())
                    .map(|mut q| {
                        edit(&mut q);
                        q
                    })
                    .collect()
            })
            .collect()
    };
    hypotheses.push(Corrected::new(
        MistakeClass::AngleUnit,
        "the joint readings look like degrees read as radians".to_owned(),
        "write the joint columns in radians (multiply by π/180)".to_owned(),
        (
            None,
            remap(&|q| q.iter_mut().for_each(|v| *v = v.to_radians())),
        ),
    ));
    for a in 0..n_joints {
        for b in a + 1..n_joints {
            hypotheses.push(Corrected::new(
                MistakeClass::JointOrder,
                format!("joint columns {} and {} look swapped", a + 1, b + 1),
                format!("swap columns {} and {} of the socket files", a + 1, b + 1),
                (None, remap(&|q| q.swap(a, b))),
            ));
        }
    }
    hypotheses.push(Corrected::new(
        MistakeClass::JointOrder,
        format!("the joint columns look reversed (joint {n_joints} first)"),
        format!("reverse the order of the {n_joints} columns of the socket files"),
        (None, remap(&|q| q.reverse())),
    ));
    if let Some(urdf) = urdf {
        for link in fixed_neighbours(urdf, tip) {
            let Ok(other) = hapcal_io::import_urdf(urdf, &link) else {
                continue;
            };
            let Ok(other_chain) = other.chain() else {
                continue;
            };
            if other_chain.n_joints() != n_joints {
                continue;
            }
            hypotheses.push(Corrected::new(
                MistakeClass::TipLink,
                format!("the ball sits on {link}, not on {tip}"),
                format!("use --tip {link}"),
                (Some(other_chain), sockets.clone()),
            ));
        }
    }
    let n_hypotheses = hypotheses.len();
    let judged = judge(as_given, &hypotheses, |(other, sockets)| {
        scatter(other.as_ref().unwrap_or(&chain), sockets)
    });
    let mut findings: Vec<Finding> = judged.finding.into_iter().collect();
    let no_error = |f: &[Finding]| f.iter().all(|f| f.severity != Severity::Error);
    if !as_given.is_plausible() && no_error(&findings) {
        findings.insert(
            0,
            Finding {
                class: MistakeClass::NoHypothesis,
                severity: Severity::Error,
                message: format!(
                    "the nominal robot scatters the ball of each socket by {} RMS, more than \
                     manufacturing deviations produce ({:.0} mm), and none of the \
                     {n_hypotheses} checked mistakes explains it: these recordings do not come \
                     from this robot (or the setup is wrong in a way not checked)",
                    as_given.text(),
                    PLAUSIBLE_FRAMES_ONLY_RMS_M * 1e3
                ),
                fix: "check --device, --tip and the socket files' columns".to_owned(),
                before: as_given,
                after: None,
            },
        );
    }
    if no_error(&findings)
        && let Some(limit) = &outside_limits
    {
        findings.insert(
            0,
            Finding {
                class: MistakeClass::NoHypothesis,
                severity: Severity::Error,
                message: format!("{limit}, and none of the checked mistakes explains it"),
                fix: "check the socket files' columns and units against the robot".to_owned(),
                before: as_given,
                after: None,
            },
        );
    }
    findings.sort_by_key(|f| f.severity != Severity::Error);
    Ok(SetupReport {
        n_rows: sockets.iter().map(Vec::len).sum(),
        as_given,
        n_hypotheses,
        closest: judged.closest,
        findings,
    })
}

/// The device with every joint's range opened.
fn unbounded(device: &Device) -> Device {
    let mut open = device.clone();
    for joint in &mut open.joints {
        joint.lower_rad = -1e6;
        joint.upper_rad = 1e6;
    }
    open
}

/// The links joined to `tip` by fixed joints only (up and down the URDF), `tip` excluded: the
/// frames the ball could have been named by on the same moving joints.
fn fixed_neighbours(urdf: &Path, tip: &str) -> Vec<String> {
    let Ok(robot) = urdf_rs::read_file(urdf) else {
        return Vec::new();
    };
    let fixed = |j: &&urdf_rs::Joint| j.joint_type == urdf_rs::JointType::Fixed;
    let mut seen = vec![tip.to_owned()];
    let mut frontier = vec![tip.to_owned()];
    while let Some(link) = frontier.pop() {
        let up = (robot.joints.iter().filter(fixed))
            .filter(|j| j.child.link == link)
            .map(|j| j.parent.link.clone());
        let down = (robot.joints.iter().filter(fixed))
            .filter(|j| j.parent.link == link)
            .map(|j| j.child.link.clone());
        for next in up.chain(down).collect::<Vec<_>>() {
            if !seen.contains(&next) && seen.len() < 16 {
                seen.push(next.clone());
                frontier.push(next);
            }
        }
    }
    seen.remove(0);
    seen
}

/// The nominal ball's scatter about each socket's centre, judged at the scatter of the joint
/// origins over the same rows ([`Residual::spread_m`]). Both are robust RMS values
/// ([`crate::setup::robust_rms`]) about the coordinate-wise median: one mistyped reading
/// moves its row's ball by decimetres, which a plain RMS over a few tens of rows would read as
/// a wrong robot.
fn scatter(chain: &Chain, sockets: &[Socket]) -> Residual {
    let x0 = vec![0.0; chain.n_params()];
    let (mut ball_sq, mut joint_sq) = (Vec::new(), Vec::new());
    for socket in sockets {
        let poses: Vec<Vec<Vector3<f64>>> = (socket.iter())
            .map(|q| {
                (chain.frame_poses(&x0, q).iter())
                    .map(|p| p.translation.vector)
                    .collect()
            })
            .collect();
        let Some(n_frames) = poses.first().map(Vec::len) else {
            continue;
        };
        for f in 0..n_frames {
            let centre = Vector3::from_fn(|a, _| {
                crate::setup::median(poses.iter().map(|p| p[f][a]).collect())
            });
            let sq = poses.iter().map(|p| (p[f] - centre).norm_squared());
            if f + 1 == n_frames {
                ball_sq.extend(sq);
            } else {
                joint_sq.extend(sq);
            }
        }
    }
    Residual {
        of: ResidualOf::SocketScatter,
        length_rms_m: crate::setup::robust_rms(ball_sq, 3),
        orientation_rms_rad: None,
        spread_m: crate::setup::robust_rms(joint_sq, 3),
    }
}
