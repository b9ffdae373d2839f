//! Shared CSV reading: records with their line numbers, cells parsed to finite numbers.

use std::path::Path;

use crate::Error;

/// A CSV file read record by record, without header handling, fields trimmed, streamed
/// from the file (memory bounded by the longest record, whatever the file's size).
///
/// Line numbers are counted here from the records' byte offsets, because the csv crate's
/// own line count skips blank lines: the bytes pass through [`LineBreaks`] on their way to
/// the csv reader, which notes where the line breaks lie.
pub(crate) struct Table<'p> {
    path: &'p Path,
    reader: csv::Reader<LineBreaks<std::fs::File>>,
    record: csv::StringRecord,
    /// Line breaks counted before the byte offset of the last record.
    counted: u64,
}

/// A reader that notes the byte offset of every line break (`\n` or `\r`) passing through
/// it, so that a line number can be given to a byte offset the csv reader reports. Breaks
/// before the last offset asked for are forgotten: memory is bounded by the bytes read
/// ahead of the record being read.
pub(crate) struct LineBreaks<R> {
    inner: R,
    /// Bytes passed through so far.
    offset: u64,
    /// Offsets of the line breaks not yet counted, and whether each is a `\n`.
    breaks: std::collections::VecDeque<(u64, bool)>,
}

impl<R: std::io::Read> std::io::Read for LineBreaks<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let read = buf.get(..n).unwrap_or_default();
        for i in memchr::memchr2_iter(b'\n', b'\r', read) {
            let newline = read.get(i) == Some(&b'\n');
            self.breaks.push_back((self.offset + i as u64, newline));
        }
        self.offset += n as u64;
        Ok(n)
    }
}

impl<'p> Table<'p> {
    /// Opens `path` for reading.
    pub(crate) fn open(path: &'p Path) -> Result<Self, Error> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let breaks = LineBreaks {
            inner: file,
            offset: 0,
            breaks: std::collections::VecDeque::new(),
        };
        let reader = csv::ReaderBuilder::new()
            .buffer_capacity(1 << 16)
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(breaks);
        Ok(Table {
            path,
            reader,
            record: csv::StringRecord::new(),
            counted: 0,
        })
    }

    /// 1-based line of the first character at or after byte offset `byte` that is not a
    /// line break (the csv crate reports a record's position before the blank lines it
    /// skipped); offsets must not decrease between calls.
    fn line_at(&mut self, byte: u64) -> u64 {
        let breaks = &mut self.reader.get_mut().breaks;
        let mut end = byte;
        while let Some(&(at, newline)) = breaks.front() {
            if at < end {
                // A break before the offset asked for.
            } else if at == end {
                // A line break at the offset: a blank line the record comes after.
                end += 1;
            } else {
                break;
            }
            self.counted += u64::from(newline);
            breaks.pop_front();
        }
        self.counted + 1
    }

    /// The next non-empty record and its 1-based line, or `None` at the end.
    pub(crate) fn next_record(&mut self) -> Result<Option<(u64, &csv::StringRecord)>, Error> {
        match self.reader.read_record(&mut self.record) {
            Ok(true) => {
                let byte = self.record.position().map_or(0, |p| p.byte());
                let line = self.line_at(byte);
                Ok(Some((line, &self.record)))
            }
            Ok(false) => Ok(None),
            Err(e) => {
                let byte = e.position().map_or(0, |p| p.byte());
                Err(Error::Csv {
                    path: self.path.to_path_buf(),
                    line: self.line_at(byte),
                    message: csv_message(&e),
                })
            }
        }
    }
}

fn csv_message(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::Utf8 { err, .. } => {
            format!("invalid UTF-8 in field {}", err.field() + 1)
        }
        _ => e.to_string(),
    }
}

/// Parses one cell as a finite number; `column` is 1-based, `name` the column's name.
pub(crate) fn number(
    path: &Path,
    line: u64,
    column: u64,
    name: &str,
    cell: &str,
) -> Result<f64, Error> {
    let value: f64 = cell.parse().map_err(|_| Error::NotANumber {
        path: path.to_path_buf(),
        line,
        column,
        name: name.to_owned(),
        found: cell.to_owned(),
    })?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Error::NotFinite {
            path: path.to_path_buf(),
            line,
            column,
            name: name.to_owned(),
            found: cell.to_owned(),
        })
    }
}

/// Rows whose joint readings and measurements repeat an earlier row's: kept (poses may be
/// repeated on purpose), but reported once, since each copy counts as an independent sample
/// and shrinks the σ reported for the fit.
#[derive(Default)]
pub(crate) struct Repeats {
    /// A 64-bit hash of each distinct row's values (bit patterns, −0 as +0) → its line: 16
    /// bytes a row whatever the row's width. Two different rows share a hash with
    /// probability about n²/2⁶⁵ among n rows (3·10⁻⁸ for a million).
    seen: std::collections::HashMap<u64, u64>,
    /// The first repeated row's line and the line it repeats.
    first: Option<(u64, u64)>,
    /// How many rows repeat an earlier one.
    count: usize,
}

impl Repeats {
    /// Records the row at `line` holding `values`.
    pub(crate) fn see(&mut self, values: impl IntoIterator<Item = f64>, line: u64) {
        match self.seen.entry(row_hash(values)) {
            std::collections::hash_map::Entry::Occupied(earlier) => {
                self.count += 1;
                self.first.get_or_insert((line, *earlier.get()));
            }
            std::collections::hash_map::Entry::Vacant(slot) => {
                slot.insert(line);
            }
        }
    }

    /// The one warning about repeated rows, if any, starting with `file:line:`.
    pub(crate) fn warning(&self, path: &Path) -> Option<String> {
        let (line, earlier) = self.first?;
        let more = match self.count {
            1 => String::new(),
            n => format!(" ({n} rows in all repeat an earlier row)"),
        };
        Some(format!(
            "{}:{line}: the joint readings and measurements repeat those of line {earlier}{more}; \
             repeated rows are kept, but each counts as an independent sample and shrinks the \
             reported σ",
            path.display()
        ))
    }
}

/// A 64-bit hash of a row's values as [`Repeats`] compares them: each value's bit pattern
/// (−0 as +0) folded in by a multiply and a rotation, the whole then mixed by SplitMix64's
/// finaliser (Steele, Lea & Flood 2014, "Fast splittable pseudorandom number generators",
/// OOPSLA): the same hash on every run and machine.
pub(crate) fn row_hash(values: impl IntoIterator<Item = f64>) -> u64 {
    let mut h: u64 = 0x243F_6A88_85A3_08D3;
    for bits in values.into_iter().map(|v| (v + 0.0).to_bits()) {
        h = (h ^ bits)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(29);
    }
    h ^= h >> 30;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^ (h >> 31)
}

/// The values of a row as [`Repeats`] compares them: bit patterns, −0 as +0 (a NaN, which
/// stands for an absent value, equals itself).
pub(crate) fn repeat_key(values: impl IntoIterator<Item = f64>) -> Vec<u64> {
    values.into_iter().map(|v| (v + 0.0).to_bits()).collect()
}

/// `Err(`[`Error::Separator`]`)` if `record` (at `line`) is one field although `expected`
/// (more than one) fields were expected and the field holds a semicolon, a tab, a bar or
/// white space: a file written with another separator than the comma.
pub(crate) fn check_separator(
    path: &Path,
    line: u64,
    record: &csv::StringRecord,
    expected: usize,
) -> Result<(), Error> {
    if expected < 2 || record.len() != 1 {
        return Ok(());
    }
    let field = record.get(0).unwrap_or("");
    let separator = [
        (';', "semicolons"),
        ('\t', "tabs"),
        ('|', "bars"),
        (' ', "spaces"),
    ]
    .into_iter()
    .find_map(|(c, name)| field.contains(c).then_some(name));
    match separator {
        Some(separator) => Err(Error::Separator {
            path: path.to_path_buf(),
            line,
            found: field.chars().take(60).collect(),
            separator,
        }),
        None => Ok(()),
    }
}

/// 0-based index of the first name that repeats an earlier one, found in linear time (a
/// header of a million columns is checked as fast as it is read).
pub(crate) fn first_duplicate(names: &[String]) -> Option<usize> {
    let mut seen = std::collections::HashSet::with_capacity(names.len());
    names.iter().position(|name| !seen.insert(name.as_str()))
}

/// Watches one measured quantity (a distance, a position) over the rows of a file, to refuse
/// a frozen or disconnected sensor: a quantity bit-identical (−0 counted as +0) in every one
/// of at least two rows.
#[derive(Default)]
pub(crate) struct Frozen {
    /// The first row's values.
    first: Vec<f64>,
    /// The rows seen.
    rows: usize,
    /// Whether some row differs from the first.
    changed: bool,
}

impl Frozen {
    /// Records one row's values of the quantity (the same number of values each time).
    pub(crate) fn see(&mut self, values: &[f64]) {
        if self.rows == 0 {
            self.first = values.to_vec();
        } else if !self.changed {
            let bits = |v: &f64| (v + 0.0).to_bits();
            self.changed = !(self.first.iter().map(bits)).eq(values.iter().map(bits));
        }
        self.rows += 1;
    }

    /// The constant values and the number of rows, if at least two rows were seen and all
    /// hold the same values.
    pub(crate) fn frozen(&self) -> Option<(&[f64], usize)> {
        (self.rows >= 2 && !self.changed).then_some((&self.first, self.rows))
    }
}

/// `values` in metres as a message shows them: `0.512 m`, or `(0.1, 0.2, 0.3) m` for more
/// than one value, each in [`readable`](crate::error::readable) form.
pub(crate) fn metres(values: &[f64]) -> String {
    let cells: Vec<String> = values.iter().map(|v| crate::error::readable(*v)).collect();
    match cells.as_slice() {
        [one] => format!("{one} m"),
        _ => format!("({}) m", cells.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::{Frozen, first_duplicate, metres};

    #[test]
    fn first_duplicate_is_the_second_occurrence() {
        let names: Vec<String> = ["a", "b", "c", "b", "a"].map(String::from).to_vec();
        assert_eq!(first_duplicate(&names), Some(3));
        assert_eq!(first_duplicate(&names[..3]), None);
    }

    #[test]
    fn frozen_needs_two_identical_rows_and_counts_minus_zero_as_zero() {
        let mut f = Frozen::default();
        f.see(&[0.0]);
        assert_eq!(f.frozen(), None, "one row is no evidence");
        f.see(&[-0.0]);
        assert_eq!(f.frozen(), Some((&[0.0][..], 2)));
        f.see(&[1e-300]);
        assert_eq!(f.frozen(), None);
        assert_eq!(metres(&[0.512]), "0.512 m");
        assert_eq!(metres(&[1.0, 2e7, 3.5]), "(1, 2e7, 3.5) m");
    }
}
