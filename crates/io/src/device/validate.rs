//! Semantic checks of a parsed device file, with file:line:column of the offending value.

use std::collections::HashSet;
use std::path::Path;

use hapcal_contract::locate::{Step as Key, TomlSpans};

use super::{Device, JointRef};
use crate::Error;

use Key::{Index as I, Key as N};

/// Finds where a value sits in the device file's text ([`TomlSpans`], the one locator of
/// every TOML reader) and names the file in errors.
pub(super) struct Locator<'a> {
    path: &'a Path,
    text: &'a str,
    spans: TomlSpans<'a>,
}

impl<'a> Locator<'a> {
    pub(super) fn new(path: &'a Path, text: &'a str) -> Self {
        Locator {
            path,
            text,
            spans: TomlSpans::parse(text),
        }
    }

    /// Whether the file has a value at exactly `keys`.
    fn has(&self, keys: &[Key<'_>]) -> bool {
        self.spans.has(keys)
    }

    /// 1-based (line, column) of the value at `keys`, or of its nearest existing parent,
    /// or (1, 1).
    fn at(&self, keys: &[Key<'_>]) -> (u64, u64) {
        self.spans
            .line_column(keys)
            .map_or((1, 1), |(line, column)| (line as u64, column as u64))
    }

    pub(super) fn invalid(&self, keys: &[Key<'_>], message: impl Into<String>) -> Error {
        let (line, column) = self.at(keys);
        Error::InvalidDevice {
            path: self.path.to_path_buf(),
            line,
            column,
            message: message.into(),
        }
    }

    /// Checks the `what` name `name` at `keys` is not empty and not among `names` (then adds
    /// it): `{what} name is empty`, `{what} name "x" is used twice`.
    fn new_name<'n>(
        &self,
        keys: &[Key<'_>],
        what: &str,
        name: &'n str,
        names: &mut HashSet<&'n str>,
    ) -> Result<(), Error> {
        if name.is_empty() {
            return Err(self.invalid(keys, format!("{what} name is empty")));
        }
        if !names.insert(name) {
            return Err(self.invalid(keys, format!("{what} name {name:?} is used twice")));
        }
        Ok(())
    }

    /// Checks `ok(value)` (a number [`check_numbers`] has found finite), else reports
    /// `requirement` at `keys`.
    fn check(
        &self,
        keys: &[Key<'_>],
        value: f64,
        ok: impl Fn(f64) -> bool,
        requirement: &str,
    ) -> Result<(), Error> {
        if ok(value) {
            Ok(())
        } else {
            let field = match keys.last() {
                Some(N(n)) => (*n).to_owned(),
                _ => "value".to_owned(),
            };
            Err(self.invalid(
                keys,
                format!("{field} = {} {requirement}", crate::error::readable(value)),
            ))
        }
    }
}

fn positive(v: f64) -> bool {
    v > 0.0
}

/// Every check listed at [`read_device`](super::read_device).
pub(super) fn validate(device: &Device, loc: &Locator<'_>) -> Result<(), Error> {
    check_numbers(loc)?;
    check_chain(device, loc)?;
    check_joints(device, loc)?;
    check_transmissions(device, loc)?;
    check_calibration(device, loc)?;
    // Anything the kinematics crate still rejects (it should not) is reported at 1:1.
    device
        .chain()
        .map_err(|e| loc.invalid(&[], e.to_string()))?;
    device
        .tree()
        .map_err(|e| loc.invalid(&[N("branch")], e.to_string()))?;
    Ok(())
}

/// Every number of the file finite, every length and angle within ±1000 m or rad: the
/// contract's [`check_numbers`](hapcal_contract::device::check_numbers), which the runtime
/// makes too. A number that is not finite is an [`Error::NotFinite`], a length past the bound an
/// [`Error::LengthOutOfRange`] (worded as the contract words it), an angle an
/// [`Error::InvalidDevice`].
fn check_numbers(loc: &Locator<'_>) -> Result<(), Error> {
    let Err(bad) = hapcal_contract::device::check_numbers(loc.text) else {
        return Ok(());
    };
    let (path, line, column) = (loc.path.to_path_buf(), bad.line as u64, bad.column as u64);
    Err(match bad.past_bound {
        None => Error::NotFinite {
            path,
            line,
            column,
            found: format!("{}", bad.value),
            name: bad.name,
        },
        Some("m") => Error::LengthOutOfRange {
            path,
            line,
            column,
            value_m: bad.value,
            limit_m: crate::MAX_LENGTH_M,
            name: bad.name,
        },
        Some(_) => Error::InvalidDevice {
            path,
            line,
            column,
            message: bad.to_string(),
        },
    })
}

fn check_chain(device: &Device, loc: &Locator<'_>) -> Result<(), Error> {
    match (device.dh.is_empty(), device.placements.is_empty()) {
        (true, true) => {
            return Err(loc.invalid(
                &[],
                "no kinematic chain: expected [[dh]] rows or [[placement]] rows",
            ));
        }
        (false, false) => {
            return Err(loc.invalid(
                &[N("placement"), I(0)],
                "both [[dh]] and [[placement]] rows; a device has one or the other",
            ));
        }
        _ => {}
    }
    if device.urdf.is_some() && device.placements.is_empty() {
        return Err(loc.invalid(
            &[N("urdf")],
            "[urdf] needs the [[placement]] rows imported from it",
        ));
    }

    let mut previous = 0;
    for (i, row) in device.dh.iter().enumerate() {
        if let JointRef::Joint(j) = row.joint {
            if j != previous + 1 {
                return Err(loc.invalid(
                    &[N("dh"), I(i), N("joint")],
                    format!(
                        "[[dh]] row {i} has joint {j}, expected {}: joints are numbered 1, 2, … in row order",
                        previous + 1
                    ),
                ));
            }
            previous = j;
        }
    }

    let mut names = HashSet::new();
    let main = device.placements.iter().enumerate().map(|(i, p)| {
        let at: Vec<Key<'_>> = vec![N("placement"), I(i)];
        (at, p)
    });
    let branches = device.branches.iter().enumerate().flat_map(|(b, branch)| {
        branch.placements.iter().enumerate().map(move |(i, p)| {
            let at: Vec<Key<'_>> = vec![N("branch"), I(b), N("placement"), I(i)];
            (at, p)
        })
    });
    for (row, p) in main.chain(branches) {
        let at = |field| [row.as_slice(), &[N(field)]].concat();
        loc.new_name(&at("name"), "placement", &p.name, &mut names)?;
        if let Some(axis) = p.axis
            && axis.iter().map(|a| a * a).sum::<f64>().sqrt() < 1e-12
        {
            return Err(loc.invalid(
                &at("axis"),
                format!("placement {:?}: axis {axis:?} has zero length", p.name),
            ));
        }
    }
    if !device.branches.is_empty() && device.placements.is_empty() {
        return Err(loc.invalid(
            &[N("branch")],
            "[[branch]] rows need the [[placement]] rows of the main chain",
        ));
    }
    // A branch hangs from a placement above it: of the main chain or an earlier branch.
    let mut above: HashSet<&str> = device.placements.iter().map(|p| p.name.as_str()).collect();
    for (b, branch) in device.branches.iter().enumerate() {
        if let Some(from) = &branch.from
            && !above.contains(from.as_str())
        {
            return Err(loc.invalid(
                &[N("branch"), I(b), N("from")],
                format!(
                    "branch from = {from:?}: no placement of the main chain or of an earlier branch has that name"
                ),
            ));
        }
        above.extend(branch.placements.iter().map(|p| p.name.as_str()));
    }
    if device.n_joints() == 0 {
        return Err(loc.invalid(&[], "the kinematic chain has no joints"));
    }
    Ok(())
}

fn check_joints(device: &Device, loc: &Locator<'_>) -> Result<(), Error> {
    let n = device.n_joints();
    if device.joints.len() != n {
        let (line, _) = loc.at(&[N("joint"), I(device.joints.len().min(n))]);
        return Err(Error::JointCount {
            path: loc.path.to_path_buf(),
            line,
            expected: n,
            found: device.joints.len(),
        });
    }
    let prismatic = device.prismatic_joints();
    let mut names = HashSet::new();
    for (i, joint) in device.joints.iter().enumerate() {
        let at = |field| [N("joint"), I(i), N(field)];
        loc.new_name(&at("name"), "joint", &joint.name, &mut names)?;
        // A prismatic joint's limits are lengths (`lower_m`, `upper_m`), a revolute one's
        // angles (`lower_rad`, `upper_rad`): the key says the unit, and must match the joint.
        let is_prismatic = prismatic.get(i) == Some(&true);
        let unit = if is_prismatic { "m" } else { "rad" };
        let (lower_key, upper_key) = if is_prismatic {
            ("lower_m", "upper_m")
        } else {
            ("lower_rad", "upper_rad")
        };
        let wrong_keys: [(&str, &str); 2] = if is_prismatic {
            [("lower", "lower_rad"), ("upper", "upper_rad")]
        } else {
            [("lower", "lower_m"), ("upper", "upper_m")]
        };
        for (bound, wrong) in wrong_keys {
            if loc.has(&at(wrong)) {
                let kind = if is_prismatic {
                    "a prismatic joint: its limits are lengths"
                } else {
                    "a revolute joint: its limits are angles"
                };
                return Err(loc.invalid(
                    &at(wrong),
                    format!(
                        "joint {:?} is {kind}, expected {bound}_{unit} (in {unit}), found {wrong}",
                        joint.name
                    ),
                ));
            }
        }
        if joint.lower_rad >= joint.upper_rad {
            return Err(loc.invalid(
                &at(lower_key),
                format!(
                    "joint {:?}: {lower_key} = {} must be below {upper_key} = {}",
                    joint.name, joint.lower_rad, joint.upper_rad
                ),
            ));
        }
        if joint.counts_per_rev == Some(0) {
            return Err(loc.invalid(&at("counts_per_rev"), "counts_per_rev must be positive"));
        }
    }
    Ok(())
}

fn check_transmissions(device: &Device, loc: &Locator<'_>) -> Result<(), Error> {
    let n = device.n_joints();
    let mut driven = HashSet::new();
    for (i, c) in device.capstans.iter().enumerate() {
        let at = |field| [N("capstan"), I(i), N(field)];
        if c.joint == 0 || c.joint > n {
            return Err(loc.invalid(
                &at("joint"),
                format!(
                    "capstan joint = {} does not exist: joints are 1..={n}",
                    c.joint
                ),
            ));
        }
        if !driven.insert(c.joint) {
            return Err(loc.invalid(&at("joint"), format!("joint {} has two capstans", c.joint)));
        }
        loc.check(&at("ratio"), c.ratio, positive, "must be positive")?;
        loc.check(
            &at("drum_distance_m"),
            c.drum_distance_m,
            positive,
            "must be positive",
        )?;
    }
    if let Some(p) = &device.parallelogram {
        for (field, value) in [
            ("l1_m", p.l1_m),
            ("l2_m", p.l2_m),
            ("l3_m", p.l3_m),
            ("l4_m", p.l4_m),
        ] {
            loc.check(
                &[N("parallelogram"), N(field)],
                value,
                positive,
                "must be positive",
            )?;
        }
    }
    if let Some(c) = &device.cable_encoder {
        let at = |field| [N("cable_encoder"), N(field)];
        loc.check(
            &at("drum_radius_m"),
            c.drum_radius_m,
            positive,
            "must be positive",
        )?;
        if c.counts_per_rev == 0 {
            return Err(loc.invalid(&at("counts_per_rev"), "counts_per_rev must be positive"));
        }
    }
    if let Some(h) = &device.handle {
        loc.check(
            &[N("handle"), N("mass_kg")],
            h.mass_kg,
            |m| m >= 0.0,
            "must not be negative",
        )?;
    }
    Ok(())
}

fn check_calibration(device: &Device, loc: &Locator<'_>) -> Result<(), Error> {
    let Some(calibration) = &device.calibration else {
        return Ok(());
    };
    // A record of a schema (`schema_version`): the contract's checks, at the line of the
    // key at fault (else at `[calibration]`). An earlier hapcal's record: as before.
    if !calibration.is_legacy() {
        let origin = loc.path.display().to_string();
        if let Err(e) = calibration.check(loc.text, &origin) {
            let (line, column) = if e.line == 0 {
                loc.at(&[N("calibration")])
            } else {
                (e.line as u64, e.column as u64)
            };
            return Err(Error::InvalidDevice {
                path: loc.path.to_path_buf(),
                line,
                column,
                message: format!("[calibration]: {}", e.message),
            });
        }
    }
    // An earlier hapcal's record too: each value's numbers, at its std.
    for v in &calibration.values {
        if let Err(message) = v.check_numbers() {
            let at = [N("calibration"), N("values"), N(&v.name), N("std")];
            return Err(loc.invalid(&at, format!("{}: {message}", v.name)));
        }
    }
    Ok(())
}
