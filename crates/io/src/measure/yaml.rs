//! The observations of ROS-Industrial `industrial_calibration` (YAML), in stages: the
//! conversions the unit edits ask for, the text (its nesting bounded), the observations with
//! the line of each key, each observation checked and converted to a row, and the rows
//! checked together.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion};
use serde::Deserialize;

use super::rows::Outside;
use super::{
    JointSchema, MAX_YAML_DEPTH, MarkerSample, MeasuredRow, MeasurementTable, Reach,
    measured_values, reach, stem,
};
use crate::Error;
use crate::columns::{ColumnInfo, Conversion, Quantity, Units, conversions, si_of};
use crate::table::{Frozen, Repeats, metres};

/// The observations of an `industrial_calibration` file in its order, with their keys.
struct Observations(Vec<(serde_yaml_ng::Value, Observation)>);

impl Observations {
    /// Whether no key is given twice (a YAML mapping read as values refuses that).
    fn distinct_keys(&self) -> bool {
        let mut seen = std::collections::HashSet::new();
        self.0.iter().all(|(k, _)| seen.insert(key_name(k)))
    }
}

impl<'de> Deserialize<'de> for Observations {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Entries;
        impl<'de> serde::de::Visitor<'de> for Entries {
            type Value = Observations;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a mapping of observations")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<Observations, A::Error> {
                let mut out = Vec::with_capacity(map.size_hint().unwrap_or(0));
                while let Some(entry) = map.next_entry()? {
                    out.push(entry);
                }
                Ok(Observations(out))
            }
        }
        deserializer.deserialize_map(Entries)
    }
}

/// An observation's key as the findings name it: the text of a string key, else the key
/// written as YAML.
fn key_name(key: &serde_yaml_ng::Value) -> String {
    match key {
        serde_yaml_ng::Value::String(s) => s.clone(),
        other => serde_yaml_ng::to_string(other)
            .unwrap_or_default()
            .trim()
            .to_owned(),
    }
}

/// One observation of `industrial_calibration`'s kinematic calibration.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Observation {
    camera_joints: Vec<f64>,
    pose: Pose,
    target_joints: Vec<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    qw: f64,
    qx: f64,
    qy: f64,
    qz: f64,
    x: f64,
    y: f64,
    z: f64,
}

/// What the observations are checked against and converted by.
struct Context<'a> {
    path: &'a Path,
    schema: &'a JointSchema<'a>,
    /// The conversions of the columns `x, y, z`, `qw..qz`, `q1..qn`, in that order.
    conversion: Vec<Conversion>,
}

impl Context<'_> {
    /// [`Error::Yaml`] at `line`, column 1.
    fn bad(&self, line: u64, message: String) -> Error {
        Error::Yaml {
            path: self.path.to_path_buf(),
            line,
            column: 1,
            message,
        }
    }
}

/// [`super::read_industrial_yaml`] with its positions and joint readings in `units`.
pub(super) fn read_industrial_yaml_in(
    path: &Path,
    schema: &JointSchema<'_>,
    units: &Units,
) -> Result<MeasurementTable, Error> {
    let ctx = Context {
        path,
        schema,
        conversion: yaml_conversions(path, schema, units)?,
    };
    let text = Error::read_text(path, |line, column, message| Error::Yaml {
        path: path.to_path_buf(),
        line,
        column,
        message,
    })?;
    check_yaml_depth(path, &text)?;
    let key_lines = key_lines(&text);
    let at = |key: &str| key_lines.get(key).copied().unwrap_or(0);
    let observations = observations(path, &text, &at)?;
    let mut rows = Vec::with_capacity(observations.len());
    let mut outside = Outside::default();
    let mut repeats = Repeats::default();
    let mut frozen = Frozen::default();
    for (key, o) in observations {
        let key = key_name(&key);
        let row = observation_row(&ctx, &key, at(&key), o, &mut outside)?;
        frozen.see(&row.markers[0].position_m);
        repeats.see(measured_values(&row), row.line);
        rows.push(row);
    }
    check_rows(path, &rows, &frozen)?;
    Ok(MeasurementTable {
        name: stem(path),
        path: path.to_path_buf(),
        rows,
        warnings: (outside.warning().into_iter())
            .chain(repeats.warning(path))
            .collect(),
        n_markers: 1,
        has_orientation: true,
        has_distance: false,
        ignored_columns: Vec::new(),
    })
}

/// The conversions of the columns the edits may name: the pose's x, y, z (qw..qz have no
/// unit) and the joints, q1..qn or by name.
fn yaml_conversions(
    path: &Path,
    schema: &JointSchema<'_>,
    units: &Units,
) -> Result<Vec<Conversion>, Error> {
    let n = schema.names.len();
    let infos: Vec<ColumnInfo> = (["x", "y", "z"].into_iter())
        .map(|c| ColumnInfo::plain(c, Quantity::Length))
        .chain(
            ["qw", "qx", "qy", "qz"]
                .into_iter()
                .map(|c| ColumnInfo::plain(c, Quantity::Fixed("a quaternion component (no unit)"))),
        )
        .chain((0..n).map(|j| {
            let prismatic = schema.prismatic.get(j).copied().unwrap_or(false);
            let quantity = if prismatic {
                Quantity::JointLength
            } else {
                Quantity::Angle
            };
            let name = format!("q{}", j + 1);
            ColumnInfo::joint(&name, j, schema.names.get(j).map(String::as_str), quantity)
        }))
        .collect();
    conversions(path, 1, &infos, units)
}

/// Lines of the top-level keys (the first of each), to locate each observation.
fn key_lines(text: &str) -> HashMap<String, u64> {
    let mut key_lines: HashMap<String, u64> = HashMap::new();
    for (i, l) in text.lines().enumerate() {
        if !l.starts_with([' ', '\t', '#', '-']) && l.contains(':') {
            let key = l.split(':').next().unwrap_or("").trim();
            key_lines
                .entry(key.trim_matches(['\'', '"']).to_owned())
                .or_insert(i as u64 + 1);
        }
    }
    key_lines
}

/// The observations of `text`, straight; a file that does not read so is read again through
/// YAML values, whose errors name the observation and its line (`at`).
fn observations(
    path: &Path,
    text: &str,
    at: &dyn Fn(&str) -> u64,
) -> Result<Vec<(serde_yaml_ng::Value, Observation)>, Error> {
    let direct = serde_yaml_ng::from_str::<Observations>(text)
        .ok()
        .filter(|o| o.distinct_keys());
    if let Some(o) = direct {
        return Ok(o.0);
    }
    let mapping: serde_yaml_ng::Mapping =
        serde_yaml_ng::from_str(text).map_err(|e| yaml_error(path, &e))?;
    (mapping.into_iter())
        .map(|(key, value)| {
            let name = key_name(&key);
            serde_yaml_ng::from_value(value)
                .map(|o| (key, o))
                .map_err(|e| (name, e))
        })
        .collect::<Result<_, _>>()
        .map_err(|(name, e)| Error::Yaml {
            path: path.to_path_buf(),
            line: at(&name),
            column: 1,
            message: format!("observation {name:?}: {e}"),
        })
}

/// Observation `key` (at `line`) as a row: a fixed camera, the device's joint count, its
/// values in SI, its joints within their limits (or noted in `outside`), a finite position
/// and a unit quaternion.
fn observation_row(
    ctx: &Context<'_>,
    key: &str,
    line: u64,
    o: Observation,
    outside: &mut Outside,
) -> Result<MeasuredRow, Error> {
    let n = ctx.schema.names.len();
    if !o.camera_joints.is_empty() {
        return Err(ctx.bad(
            line,
            format!(
                "observation {key:?}: camera_joints is not empty: a camera on a moving chain is not supported"
            ),
        ));
    }
    if o.target_joints.len() != n {
        return Err(ctx.bad(
            line,
            format!(
                "observation {key:?}: expected {n} target_joints (as the device has), found {}",
                o.target_joints.len()
            ),
        ));
    }
    let o = in_si(&ctx.conversion, o);
    check_joints(ctx, key, line, &o.target_joints, outside)?;
    let p = &o.pose;
    let quaternion = [p.qw, p.qx, p.qy, p.qz];
    let norm = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
    if ![p.x, p.y, p.z].iter().all(|v| v.is_finite()) || (norm - 1.0).abs() > 1e-3 {
        return Err(ctx.bad(
            line,
            format!(
                "observation {key:?}: expected a finite position and a unit quaternion, found quaternion norm {norm}"
            ),
        ));
    }
    let q = UnitQuaternion::from_quaternion(Quaternion::new(p.qw, p.qx, p.qy, p.qz));
    Ok(MeasuredRow {
        line,
        q: o.target_joints.into(),
        t_s: None,
        markers: vec![MarkerSample {
            marker: 0,
            position_m: [p.x, p.y, p.z],
            rotation: Some([q.w, q.i, q.j, q.k]),
        }],
        distance_m: None,
    })
}

/// The observation with its position and joints converted to SI by `conversion`.
fn in_si(conversion: &[Conversion], mut o: Observation) -> Observation {
    // The raw values in the order of the conversions: x, y, z, the quaternion, the joints.
    let p = &o.pose;
    let raw: Vec<f64> = [p.x, p.y, p.z, 0.0, 0.0, 0.0, 0.0]
        .into_iter()
        .chain(o.target_joints.iter().copied())
        .collect();
    let read = |c: usize| Ok::<f64, std::convert::Infallible>(raw.get(c).copied().unwrap_or(0.0));
    let si = |c: usize| match si_of(conversion, c, &read) {
        Ok(v) => v,
        Err(never) => match never {},
    };
    for (j, v) in o.target_joints.iter_mut().enumerate() {
        *v = si(7 + j);
    }
    let p = &mut o.pose;
    [p.x, p.y, p.z] = [si(0), si(1), si(2)];
    o
}

/// Each joint reading finite and within its limits, or past them by at most the slack
/// (noted in `outside`).
fn check_joints(
    ctx: &Context<'_>,
    key: &str,
    line: u64,
    target_joints: &[f64],
    outside: &mut Outside,
) -> Result<(), Error> {
    for (j, &v) in target_joints.iter().enumerate() {
        let (min, max) = (ctx.schema.limits.get(j).copied()).unwrap_or((f64::MIN, f64::MAX));
        let within = reach(v, (min, max));
        if v.is_finite() && within == Reach::Slack {
            outside.see(|| {
                format!(
                    "{}:{line}: observation {key:?}: joint {:?} = {v} is outside its limits [{min}, {max}]",
                    ctx.path.display(),
                    ctx.schema.names[j]
                )
            });
        } else if !(v.is_finite() && within == Reach::Within) {
            return Err(ctx.bad(
                line,
                format!(
                    "observation {key:?}: joint {:?} = {v} is outside [{min}, {max}]",
                    ctx.schema.names[j]
                ),
            ));
        }
    }
    Ok(())
}

/// At least one observation, and not all at the same pose translation (a frozen camera or
/// target detection).
fn check_rows(path: &Path, rows: &[MeasuredRow], frozen: &Frozen) -> Result<(), Error> {
    if rows.is_empty() {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    }
    if let Some((value, n_rows)) = frozen.frozen() {
        let first = rows.first().map_or(0, |r| r.line);
        return Err(Error::FrozenMeasurement {
            path: path.to_path_buf(),
            line: first,
            column: 1,
            name: "pose x, y, z".to_owned(),
            value: metres(value),
            rows: n_rows,
            what: "observations",
        });
    }
    Ok(())
}

/// `Err(`[`Error::Yaml`]`)` at the first place (line, column) where `text` nests collections
/// deeper than [`MAX_YAML_DEPTH`]. One pass over the text: block nesting from the indentation
/// (a stack of open indents) and `- ` / `? ` entry markers, flow nesting from brackets and
/// braces outside quotes and comments. It may count a level too many (a block scalar holding
/// brackets), never one too few where it matters: a collection is always opened by an indent,
/// a marker or a bracket.
fn check_yaml_depth(path: &Path, text: &str) -> Result<(), Error> {
    let too_deep = |line: usize, column: usize| Error::Yaml {
        path: path.to_path_buf(),
        line: line as u64 + 1,
        column: column as u64 + 1,
        message: format!(
            "collections nest deeper than {MAX_YAML_DEPTH} levels (industrial_calibration's observations nest 3 deep)"
        ),
    };
    let mut indents: Vec<usize> = Vec::new();
    let mut flow = 0usize;
    // An open quoted scalar, which may span lines: its quote character.
    let mut quote: Option<char> = None;
    for (i, line) in text.lines().enumerate() {
        let content = line.trim_start_matches([' ', '\t']);
        let mut block = indents.len();
        if flow == 0 && quote.is_none() && !content.is_empty() && !content.starts_with('#') {
            let indent = line.len() - content.len();
            while indents.last().is_some_and(|&open| open >= indent) {
                indents.pop();
            }
            indents.push(indent);
            // `- - - x`: each entry marker opens one more collection on the same line.
            let mut rest = content;
            let mut markers = 0;
            while let Some(after) = rest.strip_prefix("- ").or_else(|| rest.strip_prefix("? ")) {
                markers += 1;
                rest = after.trim_start_matches(' ');
            }
            block = indents.len() + markers;
            if block > MAX_YAML_DEPTH {
                return Err(too_deep(i, indent));
            }
        }
        let mut previous = ' ';
        for (column, c) in line.chars().enumerate() {
            match (quote, c) {
                (Some('"'), '"') if previous != '\\' => quote = None,
                (Some('\''), '\'') => quote = None,
                (Some(_), _) => {}
                (None, '#') if previous == ' ' || previous == '\t' || column == 0 => break,
                (None, '"' | '\'')
                    if matches!(previous, ' ' | '\t' | '[' | '{' | ',' | ':') || column == 0 =>
                {
                    quote = Some(c);
                }
                (None, '[' | '{') => {
                    flow += 1;
                    if block + flow > MAX_YAML_DEPTH {
                        return Err(too_deep(i, column));
                    }
                }
                (None, ']' | '}') => flow = flow.saturating_sub(1),
                (None, _) => {}
            }
            previous = if previous == '\\' && c == '\\' {
                ' '
            } else {
                c
            };
        }
    }
    Ok(())
}

fn yaml_error(path: &Path, e: &serde_yaml_ng::Error) -> Error {
    let (line, column) = e
        .location()
        .map_or((0, 0), |l| (l.line() as u64, l.column() as u64));
    Error::Yaml {
        path: path.to_path_buf(),
        line,
        column,
        message: e.to_string(),
    }
}
