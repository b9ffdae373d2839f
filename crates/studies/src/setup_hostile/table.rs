//! Tables of numbers as the sweep edits them: read from a recording, turned between rotation forms, written back; and the devices lengthened for the wrong-robot mistakes.

use super::*;

/// A table of numbers with a header (a CSV measurement file); NaN is an empty cell.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows, one value per column.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a CSV file with a header row (`headerless`: none, columns named so).
    ///
    /// # Errors
    /// An unreadable file or a cell that is not a number.
    pub fn read_csv(path: &Path, headerless: Option<Vec<String>>) -> Result<Table> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let header = match headerless {
            Some(h) => h,
            None => (lines.next().unwrap_or_default().split(','))
                .map(|s| s.trim().to_owned())
                .collect(),
        };
        let mut rows = Vec::new();
        for (i, line) in lines.enumerate() {
            let row = (line.split(','))
                .map(|c| {
                    let c = c.trim();
                    if c.is_empty() {
                        Ok(f64::NAN)
                    } else {
                        c.parse::<f64>().with_context(|| {
                            format!("{}: row {}: not a number: {c}", path.display(), i + 1)
                        })
                    }
                })
                .collect::<Result<Vec<f64>>>()?;
            rows.push(row);
        }
        Ok(Table { header, rows })
    }

    /// The CSV text (with the header row unless `headerless`); shortest round-trip numbers.
    pub fn to_csv(&self, headerless: bool) -> String {
        let mut s = String::new();
        if !headerless {
            s.push_str(&self.header.join(","));
            s.push('\n');
        }
        for row in &self.rows {
            let cells: Vec<String> = (row.iter())
                .map(|v| {
                    if v.is_nan() {
                        String::new()
                    } else {
                        format!("{v}")
                    }
                })
                .collect();
            s.push_str(&cells.join(","));
            s.push('\n');
        }
        s
    }

    /// Index of column `name`.
    pub fn col(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// Applies `f` to every cell of column `name` (empty cells stay empty).
    pub(super) fn map_col(&mut self, name: &str, f: impl Fn(f64) -> f64) {
        if let Some(c) = self.col(name) {
            for row in &mut self.rows {
                row[c] = f(row[c]);
            }
        }
    }

    /// Exchanges the data of two columns.
    pub(super) fn swap_cols(&mut self, a: &str, b: &str) {
        if let (Some(a), Some(b)) = (self.col(a), self.col(b)) {
            for row in &mut self.rows {
                row.swap(a, b);
            }
        }
    }
}

/// The two-axis positioner's `measurements.yaml` as a table `q1,q2,x,y,z,qw,qx,qy,qz` in
/// file order (its device file's joints are read by position).
///
/// # Errors
/// An unreadable file or an observation without its numbers.
pub fn read_positioner_yaml(path: &Path) -> Result<Table> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let header: Vec<String> = ["q1", "q2", "x", "y", "z", "qw", "qx", "qy", "qz"]
        .map(str::to_owned)
        .to_vec();
    let mut rows = Vec::new();
    let mut cur: BTreeMap<String, f64> = BTreeMap::new();
    let mut joints: Vec<f64> = Vec::new();
    let mut flush = |cur: &mut BTreeMap<String, f64>, joints: &mut Vec<f64>| -> Result<()> {
        if cur.is_empty() && joints.is_empty() {
            return Ok(());
        }
        let mut row = joints.clone();
        for k in ["x", "y", "z", "qw", "qx", "qy", "qz"] {
            row.push(
                *cur.get(k)
                    .with_context(|| format!("an observation without {k}"))?,
            );
        }
        if row.len() != 9 {
            bail!("an observation with {} joints, expected 2", joints.len());
        }
        rows.push(row);
        cur.clear();
        joints.clear();
        Ok(())
    };
    for line in text.lines() {
        if !line.starts_with(' ') && line.trim_end().ends_with(':') {
            flush(&mut cur, &mut joints)?;
            continue;
        }
        let t = line.trim();
        if let Some(v) = t.strip_prefix("- ") {
            joints.push(v.trim().parse()?);
        } else if let Some((k, v)) = t.split_once(':')
            && let Ok(v) = v.trim().parse::<f64>()
        {
            cur.insert(k.trim().to_owned(), v);
        }
    }
    flush(&mut cur, &mut joints)?;
    Ok(Table { header, rows })
}

/// Replaces the quaternion columns `qw{s},qx{s},qy{s},qz{s}` by figaroh's Euler angles
/// `phix{s},phiy{s},phiz{s}` (R = Rz·Ry·Rx).
pub(super) fn quaternion_to_euler(t: &mut Table, s: &str) {
    let names = ["qw", "qx", "qy", "qz"].map(|n| format!("{n}{s}"));
    let Some(idx) = names.iter().map(|n| t.col(n)).collect::<Option<Vec<_>>>() else {
        return;
    };
    for row in &mut t.rows {
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            row[idx[0]],
            row[idx[1]],
            row[idx[2]],
            row[idx[3]],
        ));
        let (r, p, y) = q.euler_angles();
        row[idx[0]] = r;
        row[idx[1]] = p;
        row[idx[2]] = y;
        row.remove(idx[3]);
    }
    t.header[idx[0]] = format!("phix{s}");
    t.header[idx[1]] = format!("phiy{s}");
    t.header[idx[2]] = format!("phiz{s}");
    t.header.remove(idx[3]);
}

/// Replaces figaroh's Euler columns `phix{s},phiy{s},phiz{s}` by the quaternion
/// `qw{s},qx{s},qy{s},qz{s}` of the same rotation.
pub(super) fn euler_to_quaternion(t: &mut Table, s: &str) {
    let names = ["phix", "phiy", "phiz"].map(|n| format!("{n}{s}"));
    let Some(idx) = names.iter().map(|n| t.col(n)).collect::<Option<Vec<_>>>() else {
        return;
    };
    for row in &mut t.rows {
        let q = UnitQuaternion::from_euler_angles(row[idx[0]], row[idx[1]], row[idx[2]]);
        row[idx[0]] = q.w;
        row[idx[1]] = q.i;
        row[idx[2]] = q.j;
        row.insert(idx[2] + 1, q.k);
    }
    t.header[idx[0]] = format!("qw{s}");
    t.header[idx[1]] = format!("qx{s}");
    t.header[idx[2]] = format!("qy{s}");
    t.header.insert(idx[2] + 1, format!("qz{s}"));
}

/// The Euler angles (a, b, c) of R = Rx(a)·Ry(b)·Rz(c) for figaroh's (roll, pitch, yaw) of
/// R = Rz(yaw)·Ry(pitch)·Rx(roll).
pub fn euler_xyz_of(roll: f64, pitch: f64, yaw: f64) -> [f64; 3] {
    // Rᵀ = Rz(−c)·Ry(−b)·Rx(−a): figaroh's order with the angles negated.
    let rt = Rotation3::from_euler_angles(roll, pitch, yaw).transpose();
    let (r, p, y) = rt.euler_angles();
    [-r, -p, -y]
}

/// What a written case runs: the arguments of `hapcal calibrate` (without `--out`) and what
/// the fix must name.
#[derive(Clone, Debug, PartialEq)]
pub struct Invocation {
    /// Arguments after `hapcal calibrate`, paths absolute.
    pub args: Vec<String>,
    /// Words the fix must hold: each inner list is one requirement, met by any of its words
    /// (a column's name or its `q<k>` position, the factor's word, the flag).
    pub fix_words: Vec<Vec<String>>,
    /// Words that locate the mistake (`data.csv:61`, a column's name): a stop that names no
    /// cause but one of these locates it.
    pub locate_words: Vec<String>,
}

/// The loaded sources: the arm blind test's setups (loaded once).
pub struct Sources {
    pub(super) root: PathBuf,
    arms: Vec<arm_blind::ArmSetup>,
}

impl Sources {
    /// Loads the simulated arms' fixtures under `root` (the project root).
    ///
    /// # Errors
    /// Unreadable fixtures.
    pub fn load(root: &Path) -> Result<Sources> {
        let arms = (ArmRobot::ALL.iter())
            .map(|&r| arm_blind::load_setup(r))
            .collect::<Result<Vec<_>>>()?;
        Ok(Sources {
            root: root.to_owned(),
            arms,
        })
    }

    pub(super) fn arm(&self, robot: ArmRobot) -> &arm_blind::ArmSetup {
        &self.arms[robot as usize]
    }

    /// The absolute path of `path`, relative to the project root.
    pub(super) fn abs(&self, path: &str) -> String {
        self.root.join(path).display().to_string()
    }
}

/// A simulated arm's positions table (`t_s`, joints by name, `x,y,z`) for `case` with the
/// given setup.
pub(super) fn arm_table(case: &ArmCase, setup: &arm_blind::ArmSetup) -> Result<Table> {
    let m = arm_blind::simulate_positions_table(case, setup, SIM_ROWS)
        .context("a positions case has a table")?;
    let mut header = vec!["t_s".to_owned()];
    header.extend(setup.robot.joint_names.iter().cloned());
    header.extend(["x", "y", "z"].map(str::to_owned));
    let rows = (m.rows.iter())
        .enumerate()
        .map(|(i, r)| {
            let mut v = vec![r.t_s.unwrap_or(i as f64)];
            v.extend(r.q.iter());
            v.extend(r.markers.first().map_or([f64::NAN; 3], |s| s.position_m));
            v
        })
        .collect();
    Ok(Table { header, rows })
}

/// The URDF text with every joint origin of length over 5 cm longer by `extra_m` along itself.
pub fn lengthen_urdf(text: &str, extra_m: f64) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("<origin") {
        out.push_str(&rest[..i]);
        rest = &rest[i..];
        let end = rest.find('>').map_or(rest.len(), |e| e + 1);
        let tag = &rest[..end];
        out.push_str(&lengthen_origin(tag, extra_m));
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// One `<origin … xyz="…" …>` tag lengthened (see [`lengthen_urdf`]).
pub(super) fn lengthen_origin(tag: &str, extra_m: f64) -> String {
    let Some(s) = tag.find("xyz=\"") else {
        return tag.to_owned();
    };
    let a = s + 5;
    let Some(len) = tag[a..].find('"') else {
        return tag.to_owned();
    };
    let v: Vec<f64> = (tag[a..a + len].split_whitespace())
        .filter_map(|x| x.parse().ok())
        .collect();
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if v.len() != 3 || norm < 0.05 {
        return tag.to_owned();
    }
    let k = (norm + extra_m) / norm;
    format!(
        "{}{} {} {}{}",
        &tag[..a],
        v[0] * k,
        v[1] * k,
        v[2] * k,
        &tag[a + len..]
    )
}

/// The device TOML with every D-H length (`a_m`, `d_m`) over 5 cm in magnitude longer by
/// `extra_m`.
pub fn lengthen_device_toml(text: &str, extra_m: f64) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let t = line.trim_start();
        let is_len = t.starts_with("a_m") || t.starts_with("d_m");
        let value = (t.split_once('=')).and_then(|(_, v)| {
            v.split('#')
                .next()
                .and_then(|v| v.trim().parse::<f64>().ok())
        });
        match value {
            Some(v) if is_len && v.abs() > 0.05 => {
                let key = t.split('=').next().unwrap_or_default().trim();
                let _ = writeln!(out, "{key} = {}", v + extra_m * v.signum());
            }
            _ => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    out
}
