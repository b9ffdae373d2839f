//! Units of data files, file-wide and per column: the unit of a column, its scale (a
//! motor-side reading, encoder counts, a gear ratio off), a reversed encoder, a joint's zero,
//! a reading coupled to another column's.
//!
//! Every reader (measurement CSV, industrial_calibration YAML, haptic log, MUKCa sockets)
//! converts each reading to SI before any check on it, so that joint limits and plausibility
//! checks see the corrected values: first each column on its own,
//! `own = raw · unit · scale · sign + offset`, then the couplings,
//! `si_j = own_j + Σ coef · own_k` over the columns `k` that `--column-coupling` couples to
//! `j` (the other column's own value: its unit, scale, sign and offset applied, not its
//! couplings).

use std::fmt;
use std::path::Path;

use crate::Error;

/// Unit of length columns (positions, distances, prismatic joints).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LengthUnit {
    /// Metres (the default).
    #[default]
    M,
    /// Millimetres.
    Mm,
    /// Centimetres.
    Cm,
    /// Inches (0.0254 m, international inch).
    In,
    /// Feet (0.3048 m, international foot).
    Ft,
}

impl LengthUnit {
    /// Every length unit, in the order help texts list them.
    pub const ALL: [LengthUnit; 5] = [Self::M, Self::Mm, Self::Cm, Self::In, Self::Ft];

    /// Metres per unit (exact by definition; the inch and foot of the 1959 agreement).
    pub fn to_m(self) -> f64 {
        match self {
            Self::M => 1.0,
            Self::Mm => 1e-3,
            Self::Cm => 1e-2,
            Self::In => 0.0254,
            Self::Ft => 0.3048,
        }
    }

    /// The unit's symbol as flags and files spell it (`m`, `mm`, `cm`, `in`, `ft`).
    pub fn symbol(self) -> &'static str {
        match self {
            Self::M => "m",
            Self::Mm => "mm",
            Self::Cm => "cm",
            Self::In => "in",
            Self::Ft => "ft",
        }
    }
}

/// Unit of angle columns (revolute joints, external encoders, `phix, phiy, phiz`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AngleUnit {
    /// Radians (the default).
    #[default]
    Rad,
    /// Degrees (π/180 rad).
    Deg,
    /// Gradians (π/200 rad; a right angle is 100 grad).
    Grad,
    /// Revolutions (2π rad).
    Rev,
}

impl AngleUnit {
    /// Every angle unit, in the order help texts list them.
    pub const ALL: [AngleUnit; 4] = [Self::Rad, Self::Deg, Self::Grad, Self::Rev];

    /// Radians per unit.
    pub fn to_rad(self) -> f64 {
        use std::f64::consts::PI;
        match self {
            Self::Rad => 1.0,
            Self::Deg => PI / 180.0,
            Self::Grad => PI / 200.0,
            Self::Rev => 2.0 * PI,
        }
    }

    /// The unit's symbol as flags and files spell it (`rad`, `deg`, `grad`, `rev`).
    pub fn symbol(self) -> &'static str {
        match self {
            Self::Rad => "rad",
            Self::Deg => "deg",
            Self::Grad => "grad",
            Self::Rev => "rev",
        }
    }
}

/// `a, b, c` of the symbols of `units`.
fn listed<T: Copy>(units: &[T], symbol: fn(T) -> &'static str) -> String {
    units
        .iter()
        .map(|u| symbol(*u))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The unit of `units` whose symbol is `s`; otherwise `expected {what}, one of {symbols},
/// found "s"`.
fn by_symbol<T: Copy>(
    units: &[T],
    symbol: fn(T) -> &'static str,
    what: &str,
    s: &str,
) -> Result<T, String> {
    (units.iter().copied().find(|u| symbol(*u) == s)).ok_or_else(|| {
        format!(
            "expected {what}, one of {}, found {s:?}",
            listed(units, symbol)
        )
    })
}

impl fmt::Display for LengthUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

impl fmt::Display for AngleUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

impl std::str::FromStr for LengthUnit {
    type Err = String;
    /// One of [`LengthUnit::ALL`]'s symbols: `m`, `mm`, `cm`, `in`, `ft`.
    fn from_str(s: &str) -> Result<Self, String> {
        by_symbol(&Self::ALL, Self::symbol, "a length unit", s)
    }
}

impl std::str::FromStr for AngleUnit {
    type Err = String;
    /// One of [`AngleUnit::ALL`]'s symbols: `rad`, `deg`, `grad`, `rev`.
    fn from_str(s: &str) -> Result<Self, String> {
        by_symbol(&Self::ALL, Self::symbol, "an angle unit", s)
    }
}

/// The unit of one column: a length or an angle unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColumnUnit {
    /// A length unit (for position, distance and prismatic joint columns).
    Length(LengthUnit),
    /// An angle unit (for revolute joint, external encoder and `phix, phiy, phiz` columns).
    Angle(AngleUnit),
}

impl ColumnUnit {
    /// SI units (m or rad) per unit.
    pub fn to_si(self) -> f64 {
        match self {
            Self::Length(u) => u.to_m(),
            Self::Angle(u) => u.to_rad(),
        }
    }
}

impl ColumnUnit {
    /// What the unit is, in words: `a length unit` or `an angle unit`.
    pub fn kind_words(self) -> &'static str {
        match self {
            Self::Length(_) => "a length unit",
            Self::Angle(_) => "an angle unit",
        }
    }

    /// The quantities of the other kind, in words: `angles` for a length unit, `lengths` for
    /// an angle unit.
    pub fn other_words(self) -> &'static str {
        match self {
            Self::Length(_) => "angles",
            Self::Angle(_) => "lengths",
        }
    }
}

impl fmt::Display for ColumnUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Length(u) => u.fmt(f),
            Self::Angle(u) => u.fmt(f),
        }
    }
}

impl std::str::FromStr for ColumnUnit {
    type Err = String;
    /// A length unit (`m`, `mm`, `cm`, `in`, `ft`) or an angle unit (`rad`, `deg`, `grad`,
    /// `rev`); the symbols do not overlap.
    fn from_str(s: &str) -> Result<Self, String> {
        if let Ok(u) = s.parse() {
            return Ok(Self::Length(u));
        }
        if let Ok(u) = s.parse() {
            return Ok(Self::Angle(u));
        }
        Err(format!(
            "expected a unit, one of {} (lengths) or {} (angles), found {s:?}",
            listed(&LengthUnit::ALL, LengthUnit::symbol),
            listed(&AngleUnit::ALL, AngleUnit::symbol)
        ))
    }
}

/// What a [`ColumnEdit`] changes in its columns.
#[derive(Clone, Debug, PartialEq)]
pub enum ColumnChange {
    /// The columns are in this unit (overriding the file-wide unit of their kind).
    Unit(ColumnUnit),
    /// The readings count the other way (a reversed encoder): the sign is flipped after the
    /// unit conversion.
    Reverse,
    /// Added to each reading after its unit conversion and sign, in SI units (rad, or m for a
    /// length column): a joint's zero.
    Offset(f64),
    /// Each reading multiplied by this factor after its unit conversion, before its sign and
    /// offset: a joint read on the motor side of its gear (`0.01` for a 100:1 gear), in
    /// encoder counts (`2π/2¹⁷`), or through a gear ratio a few per cent off.
    Scale(f64),
    /// The column's value plus `coef` times the value of the column `other` (its own unit,
    /// scale, sign and offset applied, in rad or m): a reading that depends on another joint,
    /// `q_j + c·q_k` (a coupled wrist), is fixed by `coef = −c`.
    Coupling {
        /// The column whose value is added.
        other: String,
        /// Times this coefficient (rad per rad, or per m).
        coef: f64,
    },
}

/// One edit of named columns, as one `--column-unit`, `--column-scale`, `--column-sign`,
/// `--column-offset` or `--column-coupling` flag gives it.
///
/// A column is named as the file's header spells it (`q3`, a joint's name, `x2`, …); a
/// joint's column may also be named `q1..qn` (chain order) or by the joint's name whatever
/// the header calls it, which is how files without a header (MUKCa sockets) and
/// industrial_calibration's `target_joints` name their joints. YAML poses name `x, y, z`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColumnEdit {
    /// The columns edited (at least one).
    pub columns: Vec<String>,
    /// What is changed.
    pub change: ColumnChange,
}

/// `a,b,c` split into trimmed names, each non-empty.
fn column_names(text: &str) -> Result<Vec<String>, String> {
    let names: Vec<String> = text.split(',').map(|c| c.trim().to_owned()).collect();
    if names.iter().any(String::is_empty) {
        return Err(format!(
            "expected column names separated by commas, found {text:?}"
        ));
    }
    Ok(names)
}

/// `text` split at its one `=` into `(columns, value)`.
fn split_assignment<'a>(text: &'a str, example: &str) -> Result<(&'a str, &'a str), String> {
    match text.split_once('=') {
        Some((columns, value)) if !value.contains('=') => Ok((columns, value.trim())),
        _ => Err(format!(
            "expected COLUMNS=VALUE (e.g. {example}), found {text:?}"
        )),
    }
}

impl ColumnEdit {
    /// Parses `--column-unit`'s value: `COLUMNS=UNIT`, columns separated by commas
    /// (`q3=deg`, `x2,y2,z2=mm`).
    ///
    /// # Errors
    /// A message naming the value and what was expected: no `=`, an empty column name, a
    /// unit that is none of [`LengthUnit::ALL`] and [`AngleUnit::ALL`].
    pub fn parse_unit(text: &str) -> Result<Self, String> {
        let (columns, unit) = split_assignment(text, "q3=deg or x2,y2,z2=mm")?;
        Ok(Self {
            columns: column_names(columns)?,
            change: ColumnChange::Unit(unit.parse()?),
        })
    }

    /// Parses `--column-sign`'s value: the columns whose readings count the other way
    /// (`q3`, or `q3,q5`).
    ///
    /// # Errors
    /// A message naming the value: an empty column name or one holding `=`.
    pub fn parse_sign(text: &str) -> Result<Self, String> {
        if text.contains('=') {
            return Err(format!(
                "expected column names (e.g. q3 or q3,q5), found {text:?}"
            ));
        }
        Ok(Self {
            columns: column_names(text)?,
            change: ColumnChange::Reverse,
        })
    }

    /// Parses `--column-offset`'s value: `COLUMNS=VALUE`, the value in rad (m for a length
    /// column) added after the unit conversion (`q3=0.05`, `q2=-1.5708`).
    ///
    /// # Errors
    /// A message naming the value: no `=`, an empty column name, a value that is not a finite
    /// number.
    pub fn parse_offset(text: &str) -> Result<Self, String> {
        let (columns, value) = split_assignment(text, "q3=0.05")?;
        let offset: f64 = value
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| {
                format!("expected a finite number (rad, or m for a length column), found {value:?}")
            })?;
        Ok(Self {
            columns: column_names(columns)?,
            change: ColumnChange::Offset(offset),
        })
    }

    /// Parses `--column-scale`'s value: `COLUMNS=FACTOR`, each reading multiplied by the
    /// factor after its unit conversion (`q3=0.01` for a reading on the motor side of a 100:1
    /// gear, `q2=0.95238`).
    ///
    /// # Errors
    /// A message naming the value: no `=`, an empty column name, a factor that is not a
    /// finite number or is zero.
    pub fn parse_scale(text: &str) -> Result<Self, String> {
        let (columns, value) = split_assignment(text, "q3=0.01")?;
        let factor: f64 = value
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && *v != 0.0)
            .ok_or_else(|| format!("expected a finite, non-zero factor, found {value:?}"))?;
        Ok(Self {
            columns: column_names(columns)?,
            change: ColumnChange::Scale(factor),
        })
    }

    /// Parses `--column-coupling`'s value: `COLUMN=COEF*OTHER`, the value of column `OTHER`
    /// times `COEF` added to column `COLUMN`'s (`q6=-0.5*q5`: the reading of `q6` was
    /// `q6 + 0.5·q5`).
    ///
    /// # Errors
    /// A message naming the value: no `=`, not one column on the left, no `*` on the right, a
    /// coefficient that is not a finite number, an empty other column, a column coupled to
    /// itself.
    pub fn parse_coupling(text: &str) -> Result<Self, String> {
        let example = "q6=-0.5*q5";
        let (column, value) = split_assignment(text, example)?;
        let columns = column_names(column)?;
        if columns.len() != 1 {
            return Err(format!(
                "expected one column before `=` (e.g. {example}), found {column:?}"
            ));
        }
        let Some((coef, other)) = value.split_once('*') else {
            return Err(format!(
                "expected COEF*OTHER after `=` (e.g. {example}), found {value:?}"
            ));
        };
        let coef: f64 = (coef.trim().parse().ok())
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| format!("expected a finite coefficient before `*`, found {coef:?}"))?;
        let other = other.trim();
        if other.is_empty() || other.contains([',', '*']) {
            return Err(format!(
                "expected one column name after `*` (e.g. {example}), found {other:?}"
            ));
        }
        if columns.iter().any(|c| c == other) {
            return Err(format!(
                "expected another column after `*` than the one coupled, found {other:?} on both \
                 sides"
            ));
        }
        Ok(Self {
            columns,
            change: ColumnChange::Coupling {
                other: other.to_owned(),
                coef,
            },
        })
    }

    /// The flag that gives this edit, as a user types it (`--column-unit x2,y2,z2=mm`).
    pub fn flag(&self) -> String {
        let columns = self.columns.join(",");
        match &self.change {
            ColumnChange::Unit(u) => format!("--column-unit {columns}={u}"),
            ColumnChange::Reverse => format!("--column-sign {columns}"),
            ColumnChange::Offset(v) => format!("--column-offset {columns}={v}"),
            ColumnChange::Scale(v) => format!("--column-scale {columns}={v}"),
            ColumnChange::Coupling { other, coef } => {
                format!("--column-coupling {columns}={coef}*{other}")
            }
        }
    }
}

impl fmt::Display for ColumnEdit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.flag())
    }
}

/// The units of a data file's columns (SI by default): file-wide units per kind of column,
/// and edits of named columns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Units {
    /// Positions and distances (what the instrument measured).
    pub length: LengthUnit,
    /// Revolute joints, external encoders and `phix, phiy, phiz`.
    pub angle: AngleUnit,
    /// Prismatic joint readings (what the robot's encoders report): their own unit, since an
    /// instrument in millimetres says nothing about the robot's controller (a torso lift read
    /// in m stays in m).
    pub joint_length: LengthUnit,
    /// Edits of named columns, applied over the file-wide units in this order (a later unit
    /// or offset of the same column replaces an earlier one; a reversal once is enough). A
    /// column named here that a file does not have is an error when that file is read.
    pub columns: Vec<ColumnEdit>,
}

impl Units {
    /// Units of the measurements' lengths and angles; prismatic joints in m; no column edits.
    pub fn new(length: LengthUnit, angle: AngleUnit) -> Self {
        Self {
            length,
            angle,
            joint_length: LengthUnit::M,
            columns: Vec::new(),
        }
    }

    /// The same units with prismatic joint readings in `joint_length`.
    pub fn with_joint_length(self, joint_length: LengthUnit) -> Self {
        Self {
            joint_length,
            ..self
        }
    }

    /// The same units with `edits` appended to [`Units::columns`].
    pub fn with_columns(mut self, edits: impl IntoIterator<Item = ColumnEdit>) -> Self {
        self.columns.extend(edits);
        self
    }
}

/// What a column holds, for its unit and edits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Quantity {
    /// A length the instrument measured ([`Units::length`]).
    Length,
    /// A prismatic joint's reading ([`Units::joint_length`]).
    JointLength,
    /// An angle ([`Units::angle`]).
    Angle,
    /// Something without a unit, sign or offset: the words say what (`time, s`).
    Fixed(&'static str),
}

/// One column of a file as the edits see it.
#[derive(Clone, Debug)]
pub(crate) struct ColumnInfo {
    /// Its name as the file spells it (for a file without a header, `q1..qn`).
    pub(crate) name: String,
    /// Other names that mean it (a joint's `q{j}` and the joint's name).
    pub(crate) aliases: Vec<String>,
    /// What it holds.
    pub(crate) quantity: Quantity,
}

impl ColumnInfo {
    /// A column without aliases.
    pub(crate) fn plain(name: impl Into<String>, quantity: Quantity) -> Self {
        Self {
            name: name.into(),
            aliases: Vec::new(),
            quantity,
        }
    }

    /// Joint `j` (0-based) of the chain, named `name` in the file, also known as `q{j+1}`
    /// and `joint`.
    pub(crate) fn joint(name: &str, j: usize, joint: Option<&str>, quantity: Quantity) -> Self {
        let aliases = [Some(format!("q{}", j + 1)), joint.map(str::to_owned)]
            .into_iter()
            .flatten()
            .filter(|a| a != name)
            .collect();
        Self {
            name: name.to_owned(),
            aliases,
            quantity,
        }
    }

    fn is_named(&self, name: &str) -> bool {
        self.name == name || self.aliases.iter().any(|a| a == name)
    }
}

/// How one column's raw readings become SI: `own = raw · factor + offset`, plus
/// `coef · own_k` for each coupling `(k, coef)`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Conversion {
    /// Unit (m or rad per unit) times the scale and the sign (−1 for a reversed column).
    pub(crate) factor: f64,
    /// Added after the factor, SI.
    pub(crate) offset: f64,
    /// The columns (indices) whose own value, times the coefficient, is added.
    pub(crate) coupled: Vec<(usize, f64)>,
}

impl Conversion {
    /// The reading `raw` in SI units, without couplings (the column's own value).
    pub(crate) fn apply(&self, raw: f64) -> f64 {
        raw * self.factor + self.offset
    }
}

/// Column `c`'s SI value in a row whose raw reading of column `k` is `raw(k)`: its own
/// conversion, plus each coupling's coefficient times the other column's own value (`raw`
/// is read for the coupled columns only).
///
/// # Errors
/// Whatever `raw` returns for column `c` or a column coupled to it.
pub(crate) fn si_of<E>(
    conversions: &[Conversion],
    c: usize,
    raw: &dyn Fn(usize) -> Result<f64, E>,
) -> Result<f64, E> {
    let own = |k: usize, r: f64| conversions.get(k).map_or(r, |conv| conv.apply(r));
    let mut v = own(c, raw(c)?);
    for &(k, coef) in conversions.get(c).map_or(&[][..], |conv| &conv.coupled) {
        v += coef * own(k, raw(k)?);
    }
    Ok(v)
}

/// The conversion of each of `columns` (same order) under `units`, for the file `path` whose
/// column names are on line `line`.
///
/// # Errors
/// [`Error::UnknownColumn`] for an edit naming a column the file does not have (the error
/// lists the file's columns); [`Error::ColumnUnitKind`] for a length unit on an angle column
/// or the reverse; [`Error::ColumnNotEditable`] for an edit of a column without a unit
/// (time, a quaternion component, a column the reader ignores).
pub(crate) fn conversions(
    path: &Path,
    line: u64,
    columns: &[ColumnInfo],
    units: &Units,
) -> Result<Vec<Conversion>, Error> {
    let mut out: Vec<Conversion> = columns
        .iter()
        .map(|c| Conversion {
            factor: match c.quantity {
                Quantity::Length => units.length.to_m(),
                Quantity::JointLength => units.joint_length.to_m(),
                Quantity::Angle => units.angle.to_rad(),
                Quantity::Fixed(_) => 1.0,
            },
            offset: 0.0,
            coupled: Vec::new(),
        })
        .collect();
    // Unit, scale, sign, offset and couplings per column, from the edits in order.
    let mut unit: Vec<Option<f64>> = vec![None; columns.len()];
    let mut scale = vec![1.0; columns.len()];
    let mut reversed = vec![false; columns.len()];
    for edit in &units.columns {
        // The column named `name`, which must take an edit.
        let editable = |name: &str| {
            let Some(c) = columns.iter().position(|c| c.is_named(name)) else {
                return Err(Error::UnknownColumn {
                    path: path.to_path_buf(),
                    line,
                    flag: edit.flag(),
                    name: name.to_owned(),
                    columns: (columns.iter().map(|c| c.name.as_str()))
                        .collect::<Vec<_>>()
                        .join(", "),
                });
            };
            if let Quantity::Fixed(holds) = columns[c].quantity {
                return Err(Error::ColumnNotEditable {
                    path: path.to_path_buf(),
                    line,
                    flag: edit.flag(),
                    name: columns[c].name.clone(),
                    holds,
                });
            }
            Ok(c)
        };
        for name in &edit.columns {
            let c = editable(name)?;
            let info = &columns[c];
            match &edit.change {
                &ColumnChange::Unit(u) => {
                    let wrong_kind = matches!(
                        (info.quantity, u),
                        (
                            Quantity::Length | Quantity::JointLength,
                            ColumnUnit::Angle(_)
                        ) | (Quantity::Angle, ColumnUnit::Length(_))
                    );
                    if wrong_kind {
                        return Err(Error::ColumnUnitKind {
                            path: path.to_path_buf(),
                            line,
                            flag: edit.flag(),
                            name: info.name.clone(),
                            unit: u,
                        });
                    }
                    unit[c] = Some(u.to_si());
                }
                ColumnChange::Reverse => reversed[c] = true,
                ColumnChange::Offset(v) => out[c].offset = *v,
                ColumnChange::Scale(v) => scale[c] = *v,
                ColumnChange::Coupling { other, coef } => {
                    let k = editable(other)?;
                    out[c].coupled.retain(|(o, _)| *o != k);
                    out[c].coupled.push((k, *coef));
                }
            }
        }
    }
    for (((conversion, unit), scale), reversed) in out.iter_mut().zip(unit).zip(scale).zip(reversed)
    {
        if let Some(u) = unit {
            conversion.factor = u;
        }
        conversion.factor *= scale;
        if reversed {
            conversion.factor = -conversion.factor;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_unit_survives_the_round_trip_through_its_symbol() {
        for u in LengthUnit::ALL {
            assert_eq!(u.symbol().parse::<LengthUnit>(), Ok(u));
            assert_eq!(
                u.to_string().parse::<ColumnUnit>(),
                Ok(ColumnUnit::Length(u))
            );
        }
        for u in AngleUnit::ALL {
            assert_eq!(u.symbol().parse::<AngleUnit>(), Ok(u));
            assert_eq!(
                u.to_string().parse::<ColumnUnit>(),
                Ok(ColumnUnit::Angle(u))
            );
        }
    }

    #[test]
    fn unit_errors_list_every_unit() {
        let e = "inch".parse::<LengthUnit>().unwrap_err();
        assert_eq!(
            e,
            "expected a length unit, one of m, mm, cm, in, ft, found \"inch\""
        );
        let e = "degrees".parse::<AngleUnit>().unwrap_err();
        assert_eq!(
            e,
            "expected an angle unit, one of rad, deg, grad, rev, found \"degrees\""
        );
        let e = "km".parse::<ColumnUnit>().unwrap_err();
        assert!(
            e.contains("m, mm, cm, in, ft") && e.contains("rad, deg, grad, rev"),
            "{e}"
        );
    }

    #[test]
    fn edits_parse_and_print_as_their_flags() {
        let e = ColumnEdit::parse_unit("x2, y2,z2=mm").unwrap();
        assert_eq!(e.columns, ["x2", "y2", "z2"]);
        assert_eq!(e.flag(), "--column-unit x2,y2,z2=mm");
        assert_eq!(
            ColumnEdit::parse_sign("q3").unwrap().flag(),
            "--column-sign q3"
        );
        let e = ColumnEdit::parse_offset("q2=-1.5").unwrap();
        assert_eq!(e.change, ColumnChange::Offset(-1.5));
        assert!(
            ColumnEdit::parse_unit("q3")
                .unwrap_err()
                .contains("COLUMNS=VALUE")
        );
        assert!(
            ColumnEdit::parse_unit("q3,=deg")
                .unwrap_err()
                .contains("\"q3,\"")
        );
        assert!(
            ColumnEdit::parse_unit("q3=km")
                .unwrap_err()
                .contains("\"km\"")
        );
        assert!(ColumnEdit::parse_sign("q3=1").is_err());
        assert!(
            ColumnEdit::parse_offset("q3=inf")
                .unwrap_err()
                .contains("\"inf\"")
        );
        assert!(ColumnEdit::parse_offset("q3=1=2").is_err());
    }

    #[test]
    fn scale_edits_parse_and_print_as_their_flags() {
        let e = ColumnEdit::parse_scale("q3, q4=0.01").unwrap();
        assert_eq!(e.columns, ["q3", "q4"]);
        assert_eq!(e.change, ColumnChange::Scale(0.01));
        assert_eq!(e.flag(), "--column-scale q3,q4=0.01");
        assert_eq!(
            ColumnEdit::parse_scale(&e.flag()["--column-scale ".len()..]),
            Ok(e)
        );
        let e = ColumnEdit::parse_scale("q2=4.793689962e-5").unwrap();
        assert_eq!(e.change, ColumnChange::Scale(4.793689962e-5));
        assert_eq!(
            ColumnEdit::parse_scale("q3").unwrap_err(),
            "expected COLUMNS=VALUE (e.g. q3=0.01), found \"q3\""
        );
        for bad in ["inf", "NaN", "0", "x", ""] {
            let e = ColumnEdit::parse_scale(&format!("q3={bad}")).unwrap_err();
            assert_eq!(
                e,
                format!("expected a finite, non-zero factor, found {bad:?}"),
                "{bad}"
            );
        }
        assert!(ColumnEdit::parse_scale("=2").unwrap_err().contains("\"\""));
    }

    #[test]
    fn coupling_edits_parse_and_print_as_their_flags() {
        let e = ColumnEdit::parse_coupling("q6=-0.5*q5").unwrap();
        assert_eq!(e.columns, ["q6"]);
        let coupling = ColumnChange::Coupling {
            other: "q5".to_owned(),
            coef: -0.5,
        };
        assert_eq!(e.change, coupling);
        assert_eq!(e.flag(), "--column-coupling q6=-0.5*q5");
        let spaced = ColumnEdit::parse_coupling("q6 = -0.5 * q5").unwrap();
        assert_eq!(spaced, e);
        let err = |text: &str| ColumnEdit::parse_coupling(text).unwrap_err();
        assert!(err("q6").contains("COLUMNS=VALUE"), "{}", err("q6"));
        assert_eq!(
            err("q6,q7=0.5*q5"),
            "expected one column before `=` (e.g. q6=-0.5*q5), found \"q6,q7\""
        );
        assert_eq!(
            err("q6=0.5"),
            "expected COEF*OTHER after `=` (e.g. q6=-0.5*q5), found \"0.5\""
        );
        assert_eq!(
            err("q6=inf*q5"),
            "expected a finite coefficient before `*`, found \"inf\""
        );
        assert_eq!(
            err("q6=half*q5"),
            "expected a finite coefficient before `*`, found \"half\""
        );
        assert!(err("q6=0.5*").contains("after `*`"), "{}", err("q6=0.5*"));
        assert!(err("q6=0.5*q6").contains("both sides"));
    }

    #[test]
    fn conversions_apply_unit_then_sign_then_offset() {
        let columns = [
            ColumnInfo::joint("q1", 0, Some("shoulder"), Quantity::Angle),
            ColumnInfo::plain("x", Quantity::Length),
            ColumnInfo::plain("t", Quantity::Fixed("time, s")),
        ];
        let units = Units::new(LengthUnit::Mm, AngleUnit::Rad).with_columns([
            ColumnEdit::parse_unit("shoulder=deg").unwrap(),
            ColumnEdit::parse_sign("q1").unwrap(),
            ColumnEdit::parse_offset("q1=0.5").unwrap(),
        ]);
        let c = conversions(Path::new("f.csv"), 1, &columns, &units).unwrap();
        // 90° reversed is −π/2; plus 0.5 rad.
        assert!((c[0].apply(90.0) - (0.5 - std::f64::consts::FRAC_PI_2)).abs() < 1e-15);
        assert_eq!(c[1].apply(2.0), 2e-3);
        assert_eq!(c[2].apply(3.0), 3.0);
    }

    #[test]
    fn scale_comes_after_the_unit_and_couplings_after_every_own_edit() {
        let columns = [
            ColumnInfo::joint("q1", 0, None, Quantity::Angle),
            ColumnInfo::joint("q2", 1, Some("wrist"), Quantity::Angle),
            ColumnInfo::plain("t", Quantity::Fixed("time, s")),
        ];
        let units = Units::new(LengthUnit::M, AngleUnit::Rad).with_columns([
            ColumnEdit::parse_unit("q1=deg").unwrap(),
            ColumnEdit::parse_scale("q1=0.01").unwrap(),
            ColumnEdit::parse_offset("q1=0.5").unwrap(),
            ColumnEdit::parse_coupling("wrist=-0.5*q1").unwrap(),
        ]);
        let c = conversions(Path::new("f.csv"), 1, &columns, &units).unwrap();
        let raw = [9000.0, 2.0, 7.0];
        let read = |k: usize| Ok::<f64, ()>(raw[k]);
        // 9000° on the motor side of a 100:1 gear is 90° = π/2; plus 0.5 rad.
        let q1 = std::f64::consts::FRAC_PI_2 + 0.5;
        assert!((si_of(&c, 0, &read).unwrap() - q1).abs() < 1e-15);
        // q2 read as q2 + 0.5·q1.
        assert!((si_of(&c, 1, &read).unwrap() - (2.0 - 0.5 * q1)).abs() < 1e-15);
        assert_eq!(si_of(&c, 2, &read), Ok(7.0));
        // The other column must exist and take edits; the error names the flag.
        for (edit, found) in [("q2=1*q9", "no column \"q9\""), ("q2=1*t", "\"t\" holds")] {
            let units = Units::default().with_columns([ColumnEdit::parse_coupling(edit).unwrap()]);
            let e = conversions(Path::new("f.csv"), 1, &columns, &units)
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with(&format!("f.csv:1: --column-coupling {edit}: ")) && e.contains(found),
                "{e}"
            );
        }
    }
}
