//! Writing a case: the base recording loaded, the mistake made on its table or files, and the invocation a user would run.

use super::*;

/// Where a case's data come from before the mistake: a table, or socket files.
pub(super) enum Base {
    /// One measurement table.
    Table(Table),
    /// MUKCa socket files `hole_0`, `hole_1` (no header), joint names as columns.
    Sockets(Table, Table),
}

impl Base {
    /// The tables to write, in file order (a socket case: `hole_0`, then `hole_1`).
    fn tables_mut(&mut self) -> Vec<&mut Table> {
        match self {
            Base::Table(t) => vec![t],
            Base::Sockets(a, b) => vec![a, b],
        }
    }

    /// The first table (the socket case's `hole_0`).
    fn first(&self) -> &Table {
        match self {
            Base::Table(t) | Base::Sockets(t, _) => t,
        }
    }

    /// The file a line number names: the first socket file, or the measurement file.
    fn data_name(&self) -> &'static str {
        match self {
            Base::Table(_) => "data.csv",
            Base::Sockets(..) => "hole_0.csv",
        }
    }
}

/// The joint columns of a case's data, to name a column the way a fix does.
pub(super) struct JointColumns {
    /// The revolute joint columns, in the order the mistakes index them.
    revolute: Vec<String>,
    /// Every joint column, in chain order (a prismatic joint included).
    joints: Vec<String>,
}

impl JointColumns {
    /// The name of revolute column `c` (empty past the last).
    fn name_of(&self, c: usize) -> String {
        self.revolute.get(c).cloned().unwrap_or_default()
    }

    /// The words that name revolute column `c`: its joint name and `q<k>`, its place among all
    /// joints.
    fn words(&self, c: usize) -> Vec<String> {
        let name = self.name_of(c);
        let k = self.joints.iter().position(|j| *j == name).unwrap_or(c);
        vec![name, format!("q{}", k + 1)]
    }
}

/// The invocation of a case while its mistake is made: the device and tips it names, extra
/// arguments, and what the fix must name and what locates the mistake.
pub(super) struct InvocationDraft {
    /// The device file (absolute path).
    device: String,
    /// The tips, in `--tip` order.
    tips: Vec<String>,
    /// Arguments after the data.
    extra: Vec<String>,
    /// See [`Invocation::fix_words`].
    fix_words: Vec<Vec<String>>,
    /// See [`Invocation::locate_words`].
    locate_words: Vec<String>,
}

/// One table of a case as a mistake is made in it.
pub(super) struct TableSite<'a> {
    /// The case.
    case: &'a Case,
    /// Its joint columns (of the first table).
    columns: &'a JointColumns,
    /// The file a line number names ([`Base::data_name`]).
    data_name: &'static str,
    /// Index of this table among the case's tables (0: the first, which alone adds the words
    /// of a mistake made in every table).
    t_idx: usize,
    /// Number of tables (2 for socket files).
    n_tables: usize,
}

/// Writes `case` into `dir` (a fresh folder) and returns what to run. `simulate` runs
/// `hapcal simulate` with the given arguments (haptic logs along a motion: the sweep passes
/// the release binary; a test may pass a function that refuses).
///
/// # Errors
/// Unreadable fixtures, an unwritable folder, a failed simulation.
pub fn write_case(
    case: &Case,
    sources: &Sources,
    dir: &Path,
    simulate: &dyn Fn(&[String]) -> Result<()>,
) -> Result<Invocation> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let rec = case.recording;
    let mut draft = InvocationDraft {
        device: sources.abs(rec.device()),
        tips: rec.tips().iter().map(|s| (*s).to_owned()).collect(),
        extra: Vec::new(),
        fix_words: Vec::new(),
        locate_words: Vec::new(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(case.seed ^ 0xC0FF_EE00);
    let mut base = load_base(case, sources, dir, simulate)?;
    thin_recorded(case, &mut base, &mut rng);
    let columns = JointColumns {
        revolute: rec.revolute(base.first()),
        joints: joint_side(base.first()),
    };
    if let Expect::Stop(_, Some(flag)) = case.family.spec().expect {
        draft.fix_words.push(vec![flag.to_owned()]);
    }
    let data_name = base.data_name();
    let tables = base.tables_mut();
    let n_tables = tables.len();
    for (t_idx, t) in tables.into_iter().enumerate() {
        let site = TableSite {
            case,
            columns: &columns,
            data_name,
            t_idx,
            n_tables,
        };
        make_mistake(&site, sources, dir, t, &mut draft, &mut rng)?;
    }
    move_to_wrong_socket(&case.mistake, &mut base, &mut rng);
    write_data(rec, &base, dir, draft)
}

/// A repeat of a mistake on a recorded file (`case.part > 0`) first drops a seeded fifth of
/// the rows of each table (a simulated one differs by its seed instead).
pub(super) fn thin_recorded(case: &Case, base: &mut Base, rng: &mut ChaCha8Rng) {
    let rec = case.recording;
    let simulated = rec.sim_arm().is_some() || rec == R::HapticMotion;
    if case.part == 0 || simulated {
        return;
    }
    for t in base.tables_mut() {
        let n = t.rows.len();
        let mut keep: Vec<usize> = (0..n).collect();
        keep.shuffle(rng);
        keep.truncate(n - n / 5);
        keep.sort_unstable();
        t.rows = keep.iter().map(|&i| t.rows[i].clone()).collect();
    }
}

/// Makes the case's mistake in table `t` (or in the invocation), adding what the fix must name
/// and what locates it to `draft`.
///
/// # Errors
/// A recording without the tip or root joint the mistake needs, an unreadable or unwritable
/// device file.
pub(super) fn make_mistake(
    site: &TableSite<'_>,
    sources: &Sources,
    dir: &Path,
    t: &mut Table,
    draft: &mut InvocationDraft,
    rng: &mut ChaCha8Rng,
) -> Result<()> {
    match &site.case.mistake {
        Mistake::ColumnUnit { .. }
        | Mistake::AllDegrees
        | Mistake::Lengths(_)
        | Mistake::MarkerMm(_)
        | Mistake::Sign(_)
        | Mistake::Zero(..)
        | Mistake::Swap(..)
        | Mistake::Reverse
        | Mistake::Arms
        | Mistake::Scale { .. }
        | Mistake::Coupling { .. } => column_mistake(site, t, draft),
        Mistake::Shift(_)
        | Mistake::ShiftFrom(_)
        | Mistake::Decouple(_)
        | Mistake::Shuffled
        | Mistake::EveryNth(_) => row_mistake(&site.case.mistake, t, rng),
        Mistake::Xyzw
        | Mistake::Conjugate
        | Mistake::EulerXyz
        | Mistake::Mirror(_)
        | Mistake::SwapAxes(..) => frame_mistake(&site.case.mistake, t),
        Mistake::TrackerMoved { .. }
        | Mistake::MarkerMoved { .. }
        | Mistake::ZeroFrom { .. }
        | Mistake::PartMm(_)
        | Mistake::Glitch { .. } => partial_mistake(site, t, draft, rng),
        Mistake::TipsSwapped
        | Mistake::TipUp
        | Mistake::TipDown
        | Mistake::OtherRobot
        | Mistake::SocketDistance(_)
        | Mistake::Variant
        | Mistake::Ceiling => setup_mistake(site, sources, dir, t, draft)?,
        Mistake::WrongSocket(_)
        | Mistake::LongerLinks(_)
        | Mistake::LatencyMs(_)
        | Mistake::None
        | Mistake::Draw(_)
        | Mistake::HapticEffect(..) => {}
    }
    Ok(())
}

/// A mistake in whole columns: a unit, a sign, a zero, a scale or a coupling of a joint
/// column, swapped or reversed joint columns, the arms swapped, lengths or a marker in another
/// unit.
pub(super) fn column_mistake(site: &TableSite<'_>, t: &mut Table, draft: &mut InvocationDraft) {
    let (columns, first) = (site.columns, site.t_idx == 0);
    let revolute = &columns.revolute;
    let fix_words = &mut draft.fix_words;
    match &site.case.mistake {
        Mistake::ColumnUnit { col, unit } => {
            // The number written for 1 rad (the same f64 as 180/π, 200/π or 1/(2π)).
            let f = 1.0 / unit.to_rad();
            t.map_col(&columns.name_of(*col), |v| v * f);
            if first {
                fix_words.push(columns.words(*col));
                fix_words.push(vec![unit.symbol().to_owned()]);
            }
        }
        Mistake::AllDegrees => {
            let names: Vec<String> = (t.header.iter())
                .filter(|h| revolute.contains(h) || h.starts_with("phi"))
                .cloned()
                .collect();
            for n in names {
                t.map_col(&n, f64::to_degrees);
            }
            if first {
                fix_words.push(vec!["deg".to_owned()]);
            }
        }
        Mistake::Lengths(u) => {
            let f = 1.0 / u.to_m();
            let names: Vec<String> = (t.header.iter())
                .filter(|h| is_position(h) || *h == "distance_m")
                .cloned()
                .collect();
            for n in names {
                t.map_col(&n, |v| v * f);
            }
            fix_words.push(vec![u.symbol().to_owned()]);
        }
        Mistake::MarkerMm(m) => {
            for a in ["x", "y", "z"] {
                t.map_col(&format!("{a}{m}"), |v| v * 1e3);
            }
            fix_words.push(vec![format!("x{m}")]);
            fix_words.push(vec!["mm".to_owned()]);
        }
        Mistake::Sign(c) => {
            t.map_col(&columns.name_of(*c), |v| -v);
            if first {
                fix_words.push(columns.words(*c));
            }
        }
        Mistake::Zero(c, o) => {
            t.map_col(&columns.name_of(*c), |v| v + o);
            if first {
                fix_words.push(columns.words(*c));
            }
        }
        Mistake::Swap(a, b) => {
            t.swap_cols(&columns.name_of(*a), &columns.name_of(*b));
            if first {
                let mut w = columns.words(*a);
                w.extend(columns.words(*b));
                fix_words.push(w);
            }
        }
        Mistake::Reverse => {
            let n = revolute.len();
            for i in 0..n / 2 {
                t.swap_cols(&columns.name_of(i), &columns.name_of(n - 1 - i));
            }
        }
        Mistake::Arms => {
            for j in 1..=7 {
                t.swap_cols(&format!("l_{j}"), &format!("r_{j}"));
            }
        }
        Mistake::Scale { col, factor } => {
            let f = factor.per_rad();
            t.map_col(&columns.name_of(*col), |v| v * f);
            if first {
                fix_words.push(columns.words(*col));
                draft.locate_words.extend(columns.words(*col));
            }
        }
        Mistake::Coupling { col, centi } => {
            let c = f64::from(*centi) / 100.0;
            if let (Some(a), Some(b)) = (
                t.col(&columns.name_of(*col)),
                t.col(&columns.name_of(col - 1)),
            ) {
                for row in &mut t.rows {
                    row[a] += c * row[b];
                }
            }
            if first {
                fix_words.push(columns.words(*col));
                draft.locate_words.extend(columns.words(*col));
            }
        }
        _ => {}
    }
}

/// A mistake in the rows: joint readings shifted against the measurements (from the start or
/// from a row on), decoupled, shuffled, or every n-th row kept.
pub(super) fn row_mistake(mistake: &Mistake, t: &mut Table, rng: &mut ChaCha8Rng) {
    match mistake {
        Mistake::Shift(k) => shift_rows(t, &joint_side(t), 0, *k),
        Mistake::ShiftFrom(p) => {
            let from = t.rows.len() * p / 100;
            shift_rows(t, &joint_side(t), from, 1);
        }
        Mistake::Decouple(p) => decouple(t, &joint_side(t), *p, rng),
        Mistake::Shuffled => t.rows.shuffle(rng),
        Mistake::EveryNth(n) => {
            let rows = std::mem::take(&mut t.rows);
            t.rows = rows.into_iter().step_by(*n).collect();
        }
        _ => {}
    }
}

/// A mistake in the frames of the measurements: quaternions in x, y, z, w order or
/// conjugated, Euler angles of another convention, a position axis mirrored or two swapped.
pub(super) fn frame_mistake(mistake: &Mistake, t: &mut Table) {
    match mistake {
        Mistake::Xyzw => {
            let s = quaternion_suffix(t);
            // The file's qw,qx,qy,qz hold x, y, z, w.
            let idx: Vec<usize> = (["qw", "qx", "qy", "qz"].iter())
                .filter_map(|n| t.col(&format!("{n}{s}")))
                .collect();
            if idx.len() == 4 {
                for row in &mut t.rows {
                    let (w, x, y, z) = (row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]]);
                    row[idx[0]] = x;
                    row[idx[1]] = y;
                    row[idx[2]] = z;
                    row[idx[3]] = w;
                }
            }
        }
        Mistake::Conjugate => {
            let s = quaternion_suffix(t);
            for n in ["qx", "qy", "qz"] {
                t.map_col(&format!("{n}{s}"), |v| -v);
            }
        }
        Mistake::EulerXyz => {
            let s = if t.col("phix1").is_some() { "1" } else { "" };
            let idx: Vec<usize> = (["phix", "phiy", "phiz"].iter())
                .filter_map(|n| t.col(&format!("{n}{s}")))
                .collect();
            if idx.len() == 3 {
                for row in &mut t.rows {
                    let e = euler_xyz_of(row[idx[0]], row[idx[1]], row[idx[2]]);
                    for (i, v) in idx.iter().zip(e) {
                        row[*i] = v;
                    }
                }
            }
        }
        Mistake::Mirror(a) => {
            let names: Vec<String> = (t.header.iter())
                .filter(|h| is_position(h) && h.starts_with(axis(*a)))
                .cloned()
                .collect();
            for n in names {
                t.map_col(&n, |v| -v);
            }
        }
        Mistake::SwapAxes(a, b) => {
            let names: Vec<String> = (t.header.iter())
                .filter(|h| is_position(h) && h.starts_with(axis(*a)))
                .cloned()
                .collect();
            for n in names {
                let other = format!("{}{}", axis(*b), &n[1..]);
                t.swap_cols(&n, &other);
            }
        }
        _ => {}
    }
}

/// A mistake from a row on: the tracker or the marker moved, a joint's zero moved, positions
/// in mm, or one glitched reading; each names the line where it starts.
pub(super) fn partial_mistake(
    site: &TableSite<'_>,
    t: &mut Table,
    draft: &mut InvocationDraft,
    rng: &mut ChaCha8Rng,
) {
    let (columns, data_name) = (site.columns, site.data_name);
    let (fix_words, locate_words) = (&mut draft.fix_words, &mut draft.locate_words);
    match &site.case.mistake {
        Mistake::TrackerMoved { from_pct, deg, mm } => {
            let from = t.rows.len() * *from_pct as usize / 100;
            let axis = nalgebra::Unit::new_normalize(random_direction(rng));
            let turn = UnitQuaternion::from_axis_angle(&axis, f64::from(*deg).to_radians());
            let shift = random_direction(rng) * (f64::from(*mm) / 1e3);
            move_poses(t, from, |p, q| (turn * p + shift, turn * q));
            locate_words.extend(lines_near(data_name, from + 2));
            fix_words.push(lines_near(data_name, from + 2));
        }
        Mistake::MarkerMoved { from_pct, mm } => {
            let from = t.rows.len() * *from_pct as usize / 100;
            let offset = random_direction(rng) * (f64::from(*mm) / 1e3);
            move_poses(t, from, |p, q| (p + q * offset, q));
            locate_words.extend(lines_near(data_name, from + 2));
            fix_words.push(lines_near(data_name, from + 2));
        }
        Mistake::ZeroFrom {
            col,
            from_pct,
            mrad,
        } => {
            let from = t.rows.len() * *from_pct as usize / 100;
            if let Some(c) = t.col(&columns.name_of(*col)) {
                for row in &mut t.rows[from..] {
                    row[c] += f64::from(*mrad) / 1e3;
                }
            }
            locate_words.extend(lines_near(data_name, from + 2));
            locate_words.extend(columns.words(*col));
            fix_words.push(lines_near(data_name, from + 2));
        }
        Mistake::PartMm(p) => {
            let from = t.rows.len() * *p as usize / 100;
            let cols: Vec<usize> = (t.header.iter().enumerate())
                .filter(|(_, h)| is_position(h))
                .map(|(i, _)| i)
                .collect();
            for row in &mut t.rows[from..] {
                for &c in &cols {
                    row[c] *= 1e3;
                }
            }
            let line = from + 2;
            locate_words.push(format!("{data_name}:{line}"));
            fix_words.push(vec![format!("{data_name}:{line}"), format!("{line}")]);
        }
        Mistake::Glitch { col, at_pct } if site.t_idx == 0 => {
            let row = t.rows.len() * *at_pct as usize / 100;
            if let Some(c) = t.col(&columns.name_of(*col)) {
                t.rows[row][c] += 0.2;
            }
            // Socket files have no header: row 0 is line 1.
            let line = if site.n_tables == 2 { row + 1 } else { row + 2 };
            locate_words.push(format!("{data_name}:{line}"));
        }
        _ => {}
    }
}

/// A mistake in the setup rather than the data: the tips swapped or one joint off, another
/// robot's joint names or device, a wrong socket distance, a variant's or a ceiling-mounted
/// device file (written into `dir`).
///
/// # Errors
/// A recording without a tip one joint up, an unreadable device file or one whose root joint
/// is not upright, an unwritable `dir`.
pub(super) fn setup_mistake(
    site: &TableSite<'_>,
    sources: &Sources,
    dir: &Path,
    t: &mut Table,
    draft: &mut InvocationDraft,
) -> Result<()> {
    let rec = site.case.recording;
    let first = site.t_idx == 0;
    match &site.case.mistake {
        Mistake::TipsSwapped => draft.tips.reverse(),
        Mistake::TipUp if first => {
            let up = rec.tip_up().context("a tip one joint up")?;
            draft.tips[0] = up.to_owned();
            (draft.fix_words).push(rec.tip_aliases().iter().map(|s| (*s).to_owned()).collect());
        }
        Mistake::TipDown if first => {
            (draft.fix_words).push(vec![rec.tip_up().unwrap_or_default().to_owned()]);
        }
        Mistake::OtherRobot if rec == R::SimIiwa => {
            draft.device = sources.abs(R::SimPanda.device());
            let panda = &sources.arm(ArmRobot::Panda).robot.joint_names;
            for (h, p) in t
                .header
                .iter_mut()
                .filter(|h| h.starts_with("joint_a"))
                .zip(panda)
            {
                h.clone_from(p);
            }
        }
        Mistake::SocketDistance(f) if first => {
            draft.extra.push("--socket-distance-m".to_owned());
            draft.extra.push(format!("{}", SOCKET_DISTANCE_M * f));
        }
        Mistake::Variant if first => {
            draft.device = sources.abs(match rec {
                R::Ur10 => "fixtures/wrong-robot/ur5e_lengths.urdf",
                _ => "fixtures/wrong-robot/iiwa7_lengths.urdf",
            });
        }
        Mistake::Ceiling if first => {
            draft.device = write_ceiling_device(sources, rec, dir)?;
        }
        _ => {}
    }
    Ok(())
}

/// Writes `rec`'s device file turned upside down at its root joint into `dir`
/// (`humanoid_ceiling.urdf`) and returns its path.
///
/// # Errors
/// An unreadable device file, a root joint origin that is not upright, an unwritable `dir`.
pub(super) fn write_ceiling_device(
    sources: &Sources,
    rec: Recording,
    dir: &Path,
) -> Result<String> {
    let text = std::fs::read_to_string(sources.root.join(rec.device()))?;
    let upright = r#"<origin xyz="0 0 0.3" rpy="0 0 0"/>"#;
    let turned = text.replacen(
        upright,
        r#"<origin xyz="0 0 0.3" rpy="3.141592653589793 0 0"/>"#,
        1,
    );
    if turned == text {
        bail!("the humanoid's root joint origin is not {upright}");
    }
    let path = dir.join("humanoid_ceiling.urdf");
    write(&path, &turned)?;
    Ok(path.display().to_string())
}

/// The wrong-socket mistake: a seeded `p` % (at least one) of `hole_0`'s rows moved to the end
/// of `hole_1`.
pub(super) fn move_to_wrong_socket(mistake: &Mistake, base: &mut Base, rng: &mut ChaCha8Rng) {
    if let (Mistake::WrongSocket(p), Base::Sockets(a, b)) = (mistake, base) {
        let n_move = (a.rows.len() * *p as usize).div_ceil(100).max(1);
        let mut idx: Vec<usize> = (0..a.rows.len()).collect();
        idx.shuffle(rng);
        let mut moved: Vec<usize> = idx.into_iter().take(n_move).collect();
        moved.sort_unstable();
        for i in moved.into_iter().rev() {
            let row = a.rows.remove(i);
            b.rows.push(row);
        }
    }
}

/// Writes the case's data into `dir` (`data.csv`, or `placement/hole_0.csv` and `hole_1.csv`)
/// and returns the invocation that reads them.
///
/// # Errors
/// An unwritable `dir`.
pub(super) fn write_data(
    rec: Recording,
    base: &Base,
    dir: &Path,
    draft: InvocationDraft,
) -> Result<Invocation> {
    let mut args = vec!["--device".to_owned(), draft.device];
    for tip in &draft.tips {
        args.push("--tip".to_owned());
        args.push(tip.clone());
    }
    match base {
        Base::Table(t) => {
            let path = dir.join("data.csv");
            write(&path, &t.to_csv(false))?;
            args.push("--data".to_owned());
            args.push(path.display().to_string());
            if !rec.is_haptic() {
                args.push("--test-last".to_owned());
                args.push("0.3".to_owned());
            }
        }
        Base::Sockets(a, b) => {
            let folder = dir.join("placement");
            std::fs::create_dir_all(&folder)?;
            write(&folder.join("hole_0.csv"), &a.to_csv(true))?;
            write(&folder.join("hole_1.csv"), &b.to_csv(true))?;
            args.push("--data".to_owned());
            args.push(folder.display().to_string());
        }
    }
    args.extend(draft.extra);
    Ok(Invocation {
        args,
        fix_words: draft.fix_words,
        locate_words: draft.locate_words,
    })
}

/// A unit vector drawn from `rng` (uniform on the sphere).
pub(super) fn random_direction(rng: &mut ChaCha8Rng) -> nalgebra::Vector3<f64> {
    loop {
        let v = nalgebra::Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

/// `file:line` for the lines within two of `line`: where a change found from the residuals
/// may be named (the last row before it or the first after it).
pub(super) fn lines_near(file: &str, line: usize) -> Vec<String> {
    (line.saturating_sub(2)..=line + 2)
        .map(|l| format!("{file}:{l}"))
        .collect()
}

/// Applies `f` to the measured poses of every row from `from` on: each position group
/// (`x,y,z`, `x2,y2,z2`, …) with the orientation of the same number (identity without one);
/// the orientation written back where the file has one.
pub(super) fn move_poses(
    t: &mut Table,
    from: usize,
    f: impl Fn(
        nalgebra::Vector3<f64>,
        UnitQuaternion<f64>,
    ) -> (nalgebra::Vector3<f64>, UnitQuaternion<f64>),
) {
    let suffixes: Vec<String> = (t.header.iter())
        .filter_map(|h| h.strip_prefix('x'))
        .filter(|r| r.chars().all(|c| c.is_ascii_digit()))
        .map(str::to_owned)
        .collect();
    for s in suffixes {
        let p: Vec<usize> = (["x", "y", "z"].iter())
            .filter_map(|a| t.col(&format!("{a}{s}")))
            .collect();
        let q: Vec<usize> = (["qw", "qx", "qy", "qz"].iter())
            .filter_map(|a| t.col(&format!("{a}{s}")))
            .collect();
        if p.len() != 3 {
            continue;
        }
        let from = from.min(t.rows.len());
        for row in &mut t.rows[from..] {
            let pos = nalgebra::Vector3::new(row[p[0]], row[p[1]], row[p[2]]);
            if pos.iter().any(|v| v.is_nan()) {
                continue;
            }
            let rot = if q.len() == 4 {
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    row[q[0]], row[q[1]], row[q[2]], row[q[3]],
                ))
            } else {
                UnitQuaternion::identity()
            };
            let (pos, rot) = f(pos, rot);
            for (c, v) in p.iter().zip(pos.iter()) {
                row[*c] = *v;
            }
            if q.len() == 4 {
                let r = rot.quaternion();
                for (c, v) in q.iter().zip([r.w, r.i, r.j, r.k]) {
                    row[*c] = v;
                }
            }
        }
    }
}

/// The columns read on the robot's side: joints (prismatic too) and a haptic device's
/// external encoders; the rest (positions, orientations, distances, time) are the
/// instrument's.
pub(super) fn joint_side(t: &Table) -> Vec<String> {
    (t.header.iter())
        .filter(|h| !(is_position(h) || is_orientation(h) || *h == "distance_m" || *h == "t_s"))
        .cloned()
        .collect()
}

/// Writes `text` to `path`.
pub(super) fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// The numbering of the quaternion columns (`1` for `qw1`, empty for `qw`).
pub(super) fn quaternion_suffix(t: &Table) -> &'static str {
    if t.col("qw1").is_some() { "1" } else { "" }
}

/// Pairs the joint readings of row `i` with the other columns of row `i + k`, from row
/// `from` on (rows before `from` unchanged; `k` rows dropped at the end).
pub(super) fn shift_rows(t: &mut Table, joints: &[String], from: usize, k: usize) {
    let idx: Vec<usize> = joints.iter().filter_map(|j| t.col(j)).collect();
    let n = t.rows.len();
    if n <= from + k {
        return;
    }
    let orig = t.rows.clone();
    for (row, later) in t.rows[from..n - k].iter_mut().zip(&orig[from + k..]) {
        for (c, (v, w)) in row.iter_mut().zip(later).enumerate() {
            if !idx.contains(&c) {
                *v = *w;
            }
        }
    }
    t.rows.truncate(n - k);
}

/// Shuffles the joint readings of `percent` % of the rows among themselves (a derangement
/// by rotation of the chosen rows, so every chosen row is decoupled).
pub(super) fn decouple(t: &mut Table, joints: &[String], percent: u32, rng: &mut ChaCha8Rng) {
    let idx: Vec<usize> = joints.iter().filter_map(|j| t.col(j)).collect();
    let n = t.rows.len();
    let n_pick = (n * percent as usize).div_ceil(100).max(2).min(n);
    let mut rows: Vec<usize> = (0..n).collect();
    rows.shuffle(rng);
    let picked: Vec<usize> = rows.into_iter().take(n_pick).collect();
    let orig = t.rows.clone();
    for (k, &r) in picked.iter().enumerate() {
        let src = picked[(k + 1) % picked.len()];
        for &c in &idx {
            t.rows[r][c] = orig[src][c];
        }
    }
}

/// The data of a case before its mistake.
pub(super) fn load_base(
    case: &Case,
    sources: &Sources,
    dir: &Path,
    simulate: &dyn Fn(&[String]) -> Result<()>,
) -> Result<Base> {
    let root = &sources.root;
    let csv = |p: &str| Table::read_csv(&root.join(p), None);
    Ok(match case.recording {
        R::Ur10 if case.mistake == Mistake::OtherRobot => {
            // TIAGo's first marker and its first six arm joints under the UR10's names.
            let tiago = csv("fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv")?;
            let ur10 = csv("fixtures/figaroh/ur10/calibration.csv")?;
            let mut header: Vec<String> = vec!["x1".into(), "y1".into(), "z1".into()];
            let names = R::Ur10.revolute(&ur10);
            header.extend(names.iter().cloned());
            let src: Vec<usize> = (["x1", "y1", "z1"].iter().map(|s| (*s).to_owned()))
                .chain((1..=6).map(|j| format!("arm_{j}_joint")))
                .filter_map(|n| tiago.col(&n))
                .collect();
            let rows = (tiago.rows.iter())
                .map(|r| src.iter().map(|&c| r[c]).collect())
                .collect();
            Base::Table(Table { header, rows })
        }
        R::Ur10 => Base::Table(csv("fixtures/figaroh/ur10/calibration.csv")?),
        R::Ur10Quaternion => {
            let mut t = csv("fixtures/figaroh/ur10/calibration.csv")?;
            euler_to_quaternion(&mut t, "1");
            Base::Table(t)
        }
        R::Tiago => Base::Table(csv(
            "fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv",
        )?),
        R::Humanoid => Base::Table(csv("fixtures/sim-humanoid/mocap.csv")?),
        R::Positioner | R::PositionerEuler => {
            let mut t = read_positioner_yaml(
                &root.join("fixtures/industrial-calibration/measurements.yaml"),
            )?;
            if case.recording == R::PositionerEuler {
                quaternion_to_euler(&mut t, "");
            }
            Base::Table(t)
        }
        R::SocketsIiwa | R::SocketsPanda => {
            let (robot, folder) = if case.recording == R::SocketsIiwa {
                (ArmRobot::Iiwa14, "fixtures/mukca/data/kuka_14/front")
            } else {
                (ArmRobot::Panda, "fixtures/mukca/data/panda_2/front_center")
            };
            let names = sources.arm(robot).robot.joint_names.clone();
            let read = |f: &str| Table::read_csv(&root.join(folder).join(f), Some(names.clone()));
            Base::Sockets(read("hole_0.csv")?, read("hole_1.csv")?)
        }
        R::Haptic => Base::Table(csv("fixtures/reference-device/log.csv")?),
        R::HapticMotion => {
            let out = dir.join("simulated.csv");
            let mut args: Vec<String> = vec![
                "--seed".into(),
                format!("{}", case.seed % 1000 + 1),
                "--poses".into(),
                "300".into(),
                "--motion".into(),
                "--period-s".into(),
                "0.05".into(),
                "--out".into(),
                out.display().to_string(),
            ];
            match &case.mistake {
                Mistake::LatencyMs(ms) => {
                    args.push("--effect".into());
                    args.push(format!(
                        "{}:tau={}",
                        Effect::Latency.name(),
                        f64::from(*ms) / 1e3
                    ));
                }
                Mistake::HapticEffect(e, p) => {
                    args.push("--effect".into());
                    args.push(format!("{}:{p}", e.name()));
                }
                Mistake::LongerLinks(mm) => {
                    let text = std::fs::read_to_string(root.join(R::Haptic.device()))?;
                    let dev = dir.join("longer-device.toml");
                    write(&dev, &lengthen_device_toml(&text, f64::from(*mm) / 1e3))?;
                    args.push("--device".into());
                    args.push(dev.display().to_string());
                }
                _ => {}
            }
            simulate(&args)?;
            Base::Table(Table::read_csv(&out, None)?)
        }
        R::SimIiwa | R::SimPanda => {
            let robot = case.recording.sim_arm().context("a simulated arm")?;
            let setup = sources.arm(robot);
            let arm_case = match &case.mistake {
                Mistake::Draw(i) => {
                    // The blind test's draw i on this robot, as positions data.
                    let mut c = arm_blind::draw_case(*i, setup.robot.joint_names.len());
                    c.robot = robot;
                    c.data = ArmData::Positions;
                    c.seed = *i;
                    c
                }
                _ => ArmCase {
                    seed: case.seed,
                    robot,
                    data: ArmData::Positions,
                    kind: ArmCaseKind::None,
                    injected: Injected::None,
                },
            };
            let mut setup = setup.clone();
            let urdf = root.join(case.recording.device());
            match &case.mistake {
                Mistake::LongerLinks(mm) => {
                    let text = std::fs::read_to_string(&urdf)?;
                    let longer = dir.join("longer.urdf");
                    write(&longer, &lengthen_urdf(&text, f64::from(*mm) / 1e3))?;
                    setup.robot = robot_from_urdf(&longer, &["ball_link".to_owned()])?;
                }
                Mistake::TipDown => {
                    let up = case.recording.tip_up().context("a tip one joint up")?;
                    setup.robot = robot_from_urdf(&urdf, &[up.to_owned()])?;
                }
                _ => {}
            }
            Base::Table(arm_table(&arm_case, &setup)?)
        }
    })
}
