//! The setup check of MUKCa socket folders (`hole_0.csv`, `hole_1.csv`, … of joint readings
//! with the tip held in a fixed socket).
//!
//! The socket analogue of the frames-only residual is closed-form: the scatter of the nominal
//! tip positions about each socket's mean (the mean is the socket position that minimises it),
//! together with the error of the distance between a placement's two socket means against the
//! known socket distance (`--socket-distance-m`). Right data leave the robot's manufacturing
//! deviations (millimetres); the same hypotheses as for measurement files (joint readings in
//! degrees, two joint columns swapped or all reversed, the ball on another link) are scored by
//! how many times they divide it, and decided by the rule of the other checks
//! ([`crate::setup_findings`]'s judge: an error at a factor of 5 with a plausible scatter left, a
//! warning from 2). The files are read without the joint-limit check, so that a file in
//! degrees or with swapped columns is named instead of the first reading outside a limit.

use std::path::Path;

use hapcal_io::SocketPlacement;
use hapcal_kinematics::Chain;

use crate::noise::PLAUSIBLE_FRAMES_ONLY_RMS_M;
use crate::setup_families::{Layout, SetupData, Tier, general_hypotheses, judge_with_fitted};
use crate::setup_findings::{
    Corrected, Finding, MistakeClass, Residual, ResidualOf, SetupReport, Severity, mm,
    tip_candidates,
};

/// Rows (over every socket of the training placements) below which the socket check judges
/// nothing: a scatter and a tip turn over fewer rows are too uncertain for a factor of
/// [`crate::setup_findings::OVERWHELMING_FACTOR`] to mean a mistake (MUKCa records about thirty rows a
/// socket).
pub const MIN_CHECK_ROWS: usize = 12;

/// What the socket check needs.
#[derive(Clone, Debug)]
pub struct SocketInput<'a> {
    /// The device's nominal chain (base → tip), as the calibration builds it.
    pub chain: &'a Chain,
    /// The chain's joint names, in column order.
    pub joint_names: &'a [String],
    /// The placements as read (joint readings in rad, rows × joints of `chain`).
    pub placements: &'a [SocketPlacement],
    /// The known distance between the two sockets of a placement, m.
    pub socket_distance_m: f64,
    /// The URDF the chain came from (`None` for a device file): the tip hypotheses need it.
    pub urdf: Option<&'a Path>,
    /// The tip link given.
    pub tip: &'a str,
}

/// The data as a hypothesis corrects them: another chain (another tip) or the same one, the
/// placements, and the distance between two sockets, m.
#[derive(Clone)]
struct SocketData {
    chain: Option<Chain>,
    placements: Vec<SocketPlacement>,
    distance_m: f64,
}

impl SetupData for SocketData {
    fn with_joints(&self, f: &(dyn Fn(&mut [f64]) + Sync)) -> Self {
        let mut placements = self.placements.clone();
        for q in (placements.iter_mut().flat_map(|p| &mut p.sockets)).flat_map(|s| &mut s.q) {
            f(&mut q[..]);
        }
        SocketData {
            chain: None,
            placements,
            distance_m: self.distance_m,
        }
    }

    /// Socket files hold no lengths (the distance is an option, a hypothesis of its own).
    fn with_lengths(&self, _group: Option<usize>, _factor: f64) -> Self {
        self.clone()
    }

    /// Socket rows pair no joint readings with measurements.
    fn with_shift(&self, _shift: isize, _from: Option<(usize, u64)>) -> Option<Self> {
        None
    }
}

/// Relative difference between the socket distance given and the one the nominal model puts
/// between the sockets' centres beyond which the estimated distance is a hypothesis: a real
/// robot's manufacturing deviations move the centres by millimetres over tens of centimetres.
const SOCKET_DISTANCE_TOLERANCE: f64 = 0.05;

/// Share of the nominal socket distance and multiple of the socket scatter by which the
/// distance given may differ from the nominal one before it is a finding: on the bundled
/// placements the two differ by up to about 11 % (Panda, whose nominal scatter is 8 mm).
const SOCKET_DISTANCE_SHARE: f64 = 0.25;

/// Factors a distance given in one unit and read in another is off by: powers of ten (mm,
/// cm, dm as m, and back) and inches and feet as m.
const UNIT_SLIPS: [(f64, &str); 10] = [
    (1e3, "millimetres given as metres"),
    (1e2, "centimetres given as metres"),
    (1e1, "ten times the distance"),
    (1e-1, "a tenth of the distance"),
    (1e-2, "a hundredth of the distance"),
    (1e-3, "a thousandth of the distance"),
    (1.0 / 0.0254, "inches given as metres"),
    (1.0 / 0.3048, "feet given as metres"),
    (0.0254, "metres given as inches"),
    (0.3048, "metres given as feet"),
];

/// The fix of a socket distance given wrong (`given_m`) where the nominal model measures
/// `nominal_m` (m): the given distance corrected by the unit slip that brings it within
/// [`SOCKET_DISTANCE_SHARE`] of the nominal one (the sockets were made to a round figure the
/// nominal model sees only to its own accuracy), else the words to give the distance the
/// sockets were made to. The nominal distance itself is never the fix: a robot's nominal
/// model is off by a few percent, which the calibration would then build into its lengths.
fn socket_distance_fix(given_m: f64, nominal_m: f64) -> String {
    let ratio = given_m / nominal_m;
    let slip = (UNIT_SLIPS.iter())
        .filter(|(f, _)| (ratio / f - 1.0).abs() < SOCKET_DISTANCE_SHARE)
        .min_by(|a, b| {
            (ratio / a.0 - 1.0)
                .abs()
                .total_cmp(&(ratio / b.0 - 1.0).abs())
        });
    match slip {
        Some(&(f, words)) => {
            let fixed = format!("{:.6}", given_m / f);
            let fixed = fixed.trim_end_matches('0').trim_end_matches('.');
            format!("--socket-distance-m {fixed} (the distance given looks like {words})")
        }
        None => format!(
            "give the distance the sockets were made to, in metres, with --socket-distance-m \
             (the nominal model measures {nominal_m:.4} m, to its own accuracy)"
        ),
    }
}
const SOCKET_DISTANCE_SCATTERS: f64 = 3.0;

/// The data of `input` as given.
fn given_data(input: &SocketInput<'_>) -> SocketData {
    SocketData {
        chain: None,
        placements: input.placements.to_vec(),
        distance_m: input.socket_distance_m,
    }
}

/// The distance (m) between the two sockets' centres of each placement of two, by the nominal
/// chain: their median; `None` without such a placement.
fn nominal_socket_distance(chain: &Chain, placements: &[SocketPlacement]) -> Option<f64> {
    let zero = vec![0.0; chain.n_params()];
    let mut d: Vec<f64> = placements
        .iter()
        .filter(|p| p.sockets.len() == 2)
        .filter_map(|p| {
            let centres: Vec<nalgebra::Vector3<f64>> = (p.sockets.iter())
                .map(|s| centre(&tip_points(chain, &zero, s)))
                .collect();
            Some((centres.first()? - centres.get(1)?).norm())
        })
        .collect();
    d.sort_by(f64::total_cmp);
    // Sockets that coincide are a copied file, which the reader names: no distance to judge.
    d.get(d.len() / 2)
        .copied()
        .filter(|v| v.is_finite() && *v > MIN_SOCKET_DISTANCE_M)
}

/// Nominal socket distance (m) below which the two sockets of a placement count as one point
/// (a socket file copied under the other's name): a millimetre.
const MIN_SOCKET_DISTANCE_M: f64 = 1e-3;

/// The socket scatter of `placements` on `chain` ([`ResidualOf::SocketScatter`]): the RMS,
/// over the `KEPT_SHARE` of each socket's rows closest to its centre, of the distance (m) of
/// the nominal tip position from that centre (the mean of those rows),
/// and, for each placement of exactly two sockets, of the error of the distance between the
/// two means against `socket_distance_m`, as one more term of the RMS.
///
/// Its scale ([`Residual::spread_m`]) is how far the tip frame turns about each socket: the
/// RMS angle (rad) of the nominal tip rotations from their mean rotation, times 1 m. A
/// hypothesis that shrinks the joint readings (degrees read as radians, the other way round)
/// brings every row near one configuration and shrinks the scatter with it, without explaining
/// anything; relative to the turn it does not. `None` without rows or when a row's length is
/// not the chain's joint count.
pub fn socket_scatter(
    chain: &Chain,
    placements: &[SocketPlacement],
    socket_distance_m: f64,
) -> Option<Residual> {
    use nalgebra::{Matrix3, Rotation3, Vector3};
    let zero = vec![0.0; chain.n_params()];
    let (mut sq, mut n) = (0.0, 0usize);
    let (mut turn_sq, mut n_turn) = (0.0, 0usize);
    for p in placements {
        let mut means = Vec::new();
        for socket in &p.sockets {
            if socket.q.iter().any(|q| q.len() != chain.n_joints()) {
                return None;
            }
            let poses: Vec<_> = (socket.q.iter())
                .map(|q| chain.end_pose(&zero, q))
                .collect();
            if poses.is_empty() {
                continue;
            }
            let points: Vec<Vector3<f64>> = poses.iter().map(|p| p.translation.vector).collect();
            // The socket's centre and scatter from the rows closest to it: a few rows off
            // their socket (a reading edited or mistyped) do not make the placement implausible.
            let center = centre(&points);
            let mut d: Vec<f64> = points.iter().map(|p| (p - center).norm_squared()).collect();
            d.sort_by(f64::total_cmp);
            let k = n_kept(points.len());
            sq += d.iter().take(k).sum::<f64>();
            n += k;
            means.push(center);
            let rotations: Vec<Matrix3<f64>> = (poses.iter())
                .map(|p| p.rotation.to_rotation_matrix().into_inner())
                .collect();
            let mean_rotation =
                crate::setup_findings::nearest_rotation(&rotations.iter().sum::<Matrix3<f64>>());
            for r in &rotations {
                turn_sq += Rotation3::from_matrix_unchecked(mean_rotation.transpose() * r)
                    .angle()
                    .powi(2);
                n_turn += 1;
            }
        }
        if let [a, b] = means.as_slice() {
            sq += ((a - b).norm() - socket_distance_m).powi(2);
            n += 1;
        }
    }
    let turn_m = (n_turn > 0).then(|| (turn_sq / n_turn as f64).sqrt() * TURN_LEVER_M);
    (n > 0 && sq.is_finite()).then(|| Residual {
        of: ResidualOf::SocketScatter,
        length_rms_m: Some((sq / n as f64).sqrt()),
        orientation_rms_rad: None,
        spread_m: turn_m.filter(|t| *t > 0.0 && t.is_finite()),
    })
}

/// Share of each socket's rows, the closest to its centre, whose scatter counts: the rest may
/// be rows off their socket (an edited or mistyped reading), which an RMS over every row would
/// turn into a placement no robot fits. Every hypothesis is scored the same way.
pub const KEPT_SHARE: f64 = 0.9;

/// How many of `n` rows [`KEPT_SHARE`] keeps (at least one).
fn n_kept(n: usize) -> usize {
    ((n as f64 * KEPT_SHARE).ceil() as usize).clamp(1, n.max(1))
}

/// The nominal tip positions (m) of the rows of `socket` that have `chain`'s joint count, at
/// the parameters `x`.
fn tip_points(
    chain: &Chain,
    x: &[f64],
    socket: &hapcal_io::SocketSamples,
) -> Vec<nalgebra::Vector3<f64>> {
    (socket.q.iter())
        .filter(|q| q.len() == chain.n_joints())
        .map(|q| chain.end_pose(x, q).translation.vector)
        .collect()
}

/// A socket's centre: the mean of the [`n_kept`] `points` closest to the mean of those
/// closest to the mean of all (the origin for no points).
fn centre(points: &[nalgebra::Vector3<f64>]) -> nalgebra::Vector3<f64> {
    let mean = points.iter().sum::<nalgebra::Vector3<f64>>() / points.len().max(1) as f64;
    trimmed_mean(points, &trimmed_mean(points, &mean))
}

/// The mean of the [`n_kept`] `points` closest to `center`.
fn trimmed_mean(
    points: &[nalgebra::Vector3<f64>],
    center: &nalgebra::Vector3<f64>,
) -> nalgebra::Vector3<f64> {
    let mut d: Vec<(f64, usize)> = (points.iter().enumerate())
        .map(|(i, p)| ((p - center).norm_squared(), i))
        .collect();
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    d.truncate(n_kept(points.len()));
    let sum: nalgebra::Vector3<f64> = d.iter().filter_map(|&(_, i)| points.get(i)).sum();
    sum / d.len().max(1) as f64
}

/// The lever (m) that turns the tip's RMS turn about a socket (rad) into the length scale of
/// [`socket_scatter`]: only ratios of the scale enter the judgement, so any length works.
const TURN_LEVER_M: f64 = 1.0;

/// The links joined to `link` by fixed joints only (children and parents, transitively),
/// `link` excluded: the other names of the same rigid body.
fn fixed_relatives(urdf: &urdf_rs::Robot, link: &str) -> Vec<String> {
    let mut seen = vec![link.to_owned()];
    let mut frontier = vec![link.to_owned()];
    while let Some(l) = frontier.pop() {
        for next in crate::setup_change::fixed_neighbours(urdf, &l) {
            if !seen.contains(next) {
                seen.push(next.clone());
                frontier.push(next.clone());
            }
        }
    }
    seen.remove(0);
    seen
}

/// The tips to try instead of `tip` for data of `n_columns` joint columns: the links one and
/// two moving joints up or down from it ([`tip_candidates`]) and every link fixed to one of
/// them or to `tip`, whose chain from the URDF has `n_columns` joints; with the chain of each.
fn tip_chains(urdf: &Path, tip: &str, n_columns: usize) -> Vec<(String, Chain)> {
    let Ok(description) = hapcal_io::read_urdf(urdf) else {
        return Vec::new();
    };
    let mut links: Vec<String> = fixed_relatives(&description, tip);
    for (link, _, _) in tip_candidates(&description, tip) {
        links.extend(fixed_relatives(&description, &link));
        links.push(link);
    }
    let mut out: Vec<(String, Chain)> = Vec::new();
    for link in links {
        if link == tip || out.iter().any(|(l, _)| *l == link) {
            continue;
        }
        let Ok(chain) = hapcal_io::import_urdf(urdf, &link).and_then(|d| d.chain()) else {
            continue;
        };
        if chain.n_joints() == n_columns {
            out.push((link, chain));
        }
    }
    out
}

/// The rows (file, line) whose nominal tip lies near the centre of the other socket of their
/// placement (within a fifth of the two centres' distance) and far from their own (beyond half
/// of it): rows filed under the wrong socket. A real robot's deviations move the tip by
/// millimetres, never by a socket distance.
fn rows_in_the_other_socket(
    chain: &Chain,
    placements: &[SocketPlacement],
) -> Vec<(std::path::PathBuf, u64)> {
    let zero = vec![0.0; chain.n_params()];
    let mut out = Vec::new();
    for p in placements.iter().filter(|p| p.sockets.len() == 2) {
        let points: Vec<Vec<nalgebra::Vector3<f64>>> = (p.sockets.iter())
            .map(|s| tip_points(chain, &zero, s))
            .collect();
        let centres: Vec<nalgebra::Vector3<f64>> = points.iter().map(|pts| centre(pts)).collect();
        let apart = (centres[0] - centres[1]).norm();
        if !apart.is_finite() || apart <= 0.0 {
            continue;
        }
        for (k, (socket, pts)) in p.sockets.iter().zip(&points).enumerate() {
            let (own, other) = (centres[k], centres[1 - k]);
            for (pt, line) in pts.iter().zip(&socket.line_numbers) {
                if (pt - own).norm() > apart / 2.0 && (pt - other).norm() < apart / 5.0 {
                    out.push((socket.file.clone(), *line));
                }
            }
        }
    }
    out
}

/// The layout of socket files: joint columns by position (`q1..qn`, in words `joint_a3
/// (column 3)`), no lengths, no rows that pair readings with measurements.
fn layout_of(input: &SocketInput<'_>) -> Layout {
    let name = |j: usize| input.joint_names.get(j).map_or("?", String::as_str);
    Layout::numbered(input.chain.n_joints(), |j| {
        format!("{} (column {})", name(j), j + 1)
    })
}

/// The socket folders' own hypotheses: another tip, the socket distance the nominal model
/// puts between the sockets.
fn own_hypotheses(input: &SocketInput<'_>) -> Vec<Corrected<SocketData>> {
    let mut out = Vec::new();
    let n = input.chain.n_joints();
    if let Some(urdf) = input.urdf {
        for (link, chain) in tip_chains(urdf, input.tip, n) {
            out.push(Corrected::new(
                MistakeClass::TipLink,
                format!(
                    "the point held in the sockets looks like the origin of {link}, not of the \
                     tip {}",
                    input.tip
                ),
                format!("use --tip {link}"),
                SocketData {
                    chain: Some(chain),
                    ..given_data(input)
                },
            ));
        }
    }
    if let Some(d) = nominal_socket_distance(input.chain, input.placements)
        && (d - input.socket_distance_m).abs() > SOCKET_DISTANCE_TOLERANCE * d
    {
        let given = input.socket_distance_m;
        let ratio = d / given;
        let unit = if (ratio - 1e-3).abs() < 1e-4 {
            " (a distance in millimetres given as metres)"
        } else {
            ""
        };
        out.push(Corrected::new(
            MistakeClass::SocketDistance,
            format!(
                "the sockets lie {} mm apart by the nominal model, not the {} mm given \
                 ({ratio:.3} times){unit}",
                mm(d),
                mm(given)
            ),
            socket_distance_fix(given, d),
            SocketData {
                distance_m: d,
                ..given_data(input)
            },
        ));
    }
    out
}

/// Every hypothesis of a mistake for `input` (the data as given, `given`): the folders' own
/// families and the general ones, per column too (a socket scatter costs microseconds a row).
fn socket_hypotheses(input: &SocketInput<'_>, given: &SocketData) -> Vec<Corrected<SocketData>> {
    let layout = layout_of(input);
    let mut hypotheses = own_hypotheses(input);
    hypotheses.extend(general_hypotheses(given, &layout, Tier::Always));
    hypotheses.extend(general_hypotheses(given, &layout, Tier::Suspicious));
    hypotheses
}

/// Checks the setup of a socket calibration: the socket scatter of the data as given against
/// each hypothesis of a mistake; findings, errors first, by the rule of the module docs.
///
/// # Errors
/// None of the rows has the chain's joint count (the reader refuses such files first).
pub fn check_sockets(input: &SocketInput<'_>) -> anyhow::Result<SetupReport> {
    let as_given = socket_scatter(input.chain, input.placements, input.socket_distance_m)
        .ok_or_else(|| anyhow::anyhow!("the socket files do not read on this chain"))?;
    let given = given_data(input);
    // A socket scatter costs microseconds a row: every family, whatever the residual; the
    // free scales and couplings when the scatter is more than right data leave.
    let mut hypotheses = socket_hypotheses(input, &given);
    let screen = |d: &SocketData| {
        let chain = d.chain.as_ref().unwrap_or(input.chain);
        Some(
            socket_scatter(chain, &d.placements, d.distance_m).unwrap_or(Residual {
                of: ResidualOf::SocketScatter,
                length_rms_m: Some(f64::INFINITY),
                ..Residual::default()
            }),
        )
    };
    let layout = layout_of(input);
    let judged = judge_with_fitted(as_given, &given, &layout, &mut hypotheses, &screen);
    let n_hypotheses = hypotheses.len();
    let mut findings: Vec<Finding> = judged.finding.into_iter().collect();
    // The socket distance judged directly: the nominal model measures it to a few millimetres
    // (the scatter), so a distance given wrong by a factor stands out however little it
    // weighs in the scatter's RMS.
    if let Some(d) = nominal_socket_distance(input.chain, input.placements)
        && findings
            .iter()
            .all(|f| f.class != MistakeClass::SocketDistance)
    {
        let given = input.socket_distance_m;
        let scatter = as_given.length_rms_m.unwrap_or(0.0);
        if (d - given).abs() > (SOCKET_DISTANCE_SHARE * d).max(SOCKET_DISTANCE_SCATTERS * scatter) {
            let after = screen(&SocketData {
                distance_m: d,
                ..given_data(input)
            });
            let message = format!(
                "the sockets lie {} mm apart by the nominal model, {:.3} times the {} mm given: a \
                 distance cannot be off by more than {:.0} % or {SOCKET_DISTANCE_SCATTERS} times \
                 the scatter",
                mm(d),
                d / given,
                mm(given),
                100.0 * SOCKET_DISTANCE_SHARE,
            );
            let fix = socket_distance_fix(given, d);
            let finding = Finding::new(MistakeClass::SocketDistance, Severity::Error, message, fix);
            findings.insert(0, finding.with_residuals(as_given, after));
        }
    }
    let misfiled = rows_in_the_other_socket(input.chain, input.placements);
    if let Some(first) = misfiled.first() {
        let lines: Vec<String> = (misfiled.iter().take(6))
            .map(|(file, line)| format!("{}:{line}", file.display()))
            .collect();
        let more = if misfiled.len() > 6 { ", …" } else { "" };
        let message = format!(
            "{} row{} put the tip in the other socket of {} ({}{more})",
            misfiled.len(),
            if misfiled.len() == 1 { "" } else { "s" },
            (first.0.parent()).map_or_else(String::new, |p| p.display().to_string()),
            lines.join(", ")
        );
        let fix = "move these rows to the other socket's file";
        let finding = Finding::new(MistakeClass::WrongSocket, Severity::Error, message, fix);
        findings.push(finding.with_residuals(as_given, None));
    }
    SetupReport::add_implausible(
        &mut findings,
        as_given,
        format!(
            "the nominal tip positions scatter by {} RMS about each socket's centre, more \
                     than manufacturing deviations of a real robot produce ({:.0} mm), and none \
                     of the {n_hypotheses} checked mistakes explains it: these data do not come \
                     from this robot (or the setup is wrong in a way not checked)",
            as_given.text(),
            PLAUSIBLE_FRAMES_ONLY_RMS_M * 1e3
        ),
        "check --device, --tip and the columns and units of the socket files",
    );
    findings.sort_by_key(|f| f.severity != Severity::Error);
    Ok(SetupReport {
        n_rows: n_rows(input.placements),
        as_given,
        n_hypotheses,
        closest: judged.closest,
        findings,
    })
}

/// The rows of every socket of `placements`.
fn n_rows(placements: &[SocketPlacement]) -> usize {
    (placements.iter().flat_map(|p| &p.sockets))
        .map(|s| s.q.len())
        .sum()
}

/// The number of cells on the first line of the first socket file under `paths` (a placement
/// folder or a run folder of placements); `None` when there is none.
fn n_columns(paths: &[std::path::PathBuf]) -> Option<usize> {
    let first_line = |dir: &Path| -> Option<usize> {
        let text = std::fs::read_to_string(dir.join("hole_0.csv")).ok()?;
        let line = text.lines().find(|l| !l.trim().is_empty())?;
        Some(line.split(',').count())
    };
    for path in paths {
        if let Some(n) = first_line(path) {
            return Some(n);
        }
        let mut subs: Vec<_> = std::fs::read_dir(path)
            .ok()?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_dir())
            .collect();
        subs.sort();
        if let Some(n) = subs.iter().find_map(|s| first_line(s)) {
            return Some(n);
        }
    }
    None
}

/// The setup check of a plan whose training data are socket folders, on `device` (the device
/// of `plan.device` and `plan.tip`): the files read without the joint-limit check (a file in
/// degrees is a hypothesis here, not a reading error), then [`check_sockets`]. When a reading
/// lies past its joint's limits, the error finding that explains it (a mistake, or data of
/// another robot) starts with the reader's message (`file:line:column: joint … is outside …`);
/// without one, the reader's error is the result. When the files
/// do not read with the device's joint count and the device is a URDF, the tips whose chain
/// has the files' joint count are tried (the tip given one or two moving joints too high or
/// too low), and the one leaving a plausible scatter is the finding.
///
/// # Errors
/// Unreadable socket files that no other tip reads either, a reading past its joint's limits
/// that no finding explains (the reader's error), or a device without a chain.
pub fn check_socket_plan(
    plan: &crate::inputs::Plan,
    device: &hapcal_io::Device,
) -> anyhow::Result<SetupReport> {
    let chain = device.chain()?;
    let names: Vec<String> = device.joints.iter().map(|j| j.name.clone()).collect();
    let is_urdf = (plan.device.extension()).is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    let urdf = is_urdf.then_some(plan.device.as_path());
    // Read with the units and column edits given, the joint ranges open: a file in degrees
    // is a hypothesis here, not a reading error.
    let open = crate::setup_haptic::unbounded(device);
    match hapcal_io::read_mukca_paths_in(&plan.data, &open, &plan.units) {
        Ok(placements) => {
            // A scatter over a handful of rows says nothing about the setup (the calibration
            // refuses so few configurations in its own words).
            if n_rows(&placements) < MIN_CHECK_ROWS {
                return Ok(SetupReport {
                    n_rows: n_rows(&placements),
                    ..SetupReport::default()
                });
            }
            let mut report = check_sockets(&SocketInput {
                chain: &chain,
                joint_names: &names,
                placements: &placements,
                socket_distance_m: plan.socket_distance_m,
                urdf,
                tip: &plan.tip,
            })?;
            // The reader's joint-limit check: a reading past a limit that a finding explains
            // is named with it; one that no finding explains is the reader's error as before.
            if let Err(limit) = hapcal_io::read_mukca_paths_in(&plan.data, device, &plan.units) {
                // An error finding names the cause (a mistake, or another robot); without one,
                // a reading past a limit in data that fit the robot is the reader's error.
                match (report.findings.iter_mut()).find(|f| f.severity == Severity::Error) {
                    Some(f) => f.message = format!("{limit}: {}", f.message),
                    None => return Err(limit.into()),
                }
            }
            Ok(report)
        }
        Err(e) => {
            let Some(urdf) = urdf else {
                return Err(e.into());
            };
            // Another tip only for files of another joint count (a bad cell is the reader's).
            let Some(n) = n_columns(&plan.data).filter(|&n| n != chain.n_joints()) else {
                return Err(e.into());
            };
            let placements = hapcal_io::read_mukca_paths(&plan.data, n).unwrap_or_default();
            let rms = |r: &Residual| r.length_rms_m.unwrap_or(f64::INFINITY);
            let mut best: Option<(String, Residual)> = None;
            for (link, other) in tip_chains(urdf, &plan.tip, n) {
                let Some(r) = socket_scatter(&other, &placements, plan.socket_distance_m) else {
                    continue;
                };
                if r.is_plausible() && best.as_ref().is_none_or(|(_, b)| rms(&r) < rms(b)) {
                    best = Some((link, r));
                }
            }
            let Some((link, after)) = best else {
                return Err(e.into());
            };
            let m = chain.n_joints();
            let message = format!(
                "the socket files have {n} joint columns while the chain to the tip {} has {m} \
                 moving joints: the ball sits on {link}",
                plan.tip
            );
            let fix = format!("use --tip {link}");
            let finding = Finding::new(MistakeClass::TipLink, Severity::Error, message, fix);
            Ok(SetupReport::of_unread(n_rows(&placements), finding, after))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_socket_check_generates_every_family_of_its_kind() {
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
        let urdf = root.join("mukca/urdf/iiwa14.urdf");
        let device = hapcal_io::import_urdf(&urdf, "ball_link").expect("URDF");
        let chain = device.chain().expect("chain");
        let names: Vec<String> = device.joints.iter().map(|j| j.name.clone()).collect();
        let placements = hapcal_io::read_mukca_paths(&[root.join("mukca/data/kuka_14/front")], 7)
            .expect("sockets");
        let nominal = nominal_socket_distance(&chain, &placements).expect("two sockets");
        // A distance given in millimetres as metres: the estimated distance is a hypothesis.
        let input = SocketInput {
            chain: &chain,
            joint_names: &names,
            placements: &placements,
            socket_distance_m: nominal * 1e3,
            urdf: Some(&urdf),
            tip: "ball_link",
        };
        let hypotheses = socket_hypotheses(&input, &given_data(&input));
        crate::setup_families::assert_families(
            crate::setup_families::DataKind::SocketFolders,
            &hypotheses,
            &[MistakeClass::SocketDistance],
        );
    }
}
