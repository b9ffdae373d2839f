//! Where a value stands in a file's text, for the line and column of an error: the position of
//! a byte offset, of a value found by its key path through the TOML parser's spans, and of a
//! key named on a line. Every reader of a device file, a sidecar, a truth file or a URDF points
//! at its faults through these, so that each counts lines and columns the same way.

use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// 1-based (line, column) of byte offset `offset` in `text`; the column counts characters (so
/// a message points where an editor does). An offset past the end or inside a multi-byte
/// character is clamped to the character boundary before it; never panics.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    // Step back to a char boundary so that slicing cannot panic.
    let offset = (0..=offset)
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    let before = text.get(..offset).unwrap_or("");
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before.get(line_start..).unwrap_or("").chars().count() + 1;
    (line, column)
}

/// Where and what a TOML syntax, key or type error is, the parts of a `file:line:column:
/// message` error: the 1-based line and column of the start of its span in `text`
/// ([`line_column`]; 1, 1 when the error has no span, the file as a whole) and its message
/// without trailing white space. Every TOML reader (device files, sidecars, truth files)
/// reports its parser's errors through this.
pub fn toml_error_at(text: &str, e: &toml::de::Error) -> (usize, usize, String) {
    let (line, column) = e
        .span()
        .map_or((1, 1), |span| line_column(text, span.start));
    (line, column, e.message().trim_end().to_owned())
}

/// One step of a key path into a TOML document: a table's key or an array's index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step<'a> {
    /// A table's key.
    Key(&'a str),
    /// An array's entry (0-based).
    Index(usize),
}

/// The dotted name of the value at `path` as messages give it: `dh[2].a_m`.
pub fn dotted_name(path: &[Step<'_>]) -> String {
    let name: String = (path.iter())
        .map(|step| match step {
            Step::Key(k) => format!(".{k}"),
            Step::Index(i) => format!("[{i}]"),
        })
        .collect();
    name.trim_start_matches('.').to_owned()
}

/// A TOML text parsed once for the spans of its values, to find the line and column of the
/// value at a key path ([`TomlSpans::line_column`]) or of a calibration record's key
/// ([`TomlSpans::record_line`]). Text that is not TOML has no spans: every look-up is `None`.
pub struct TomlSpans<'a> {
    text: &'a str,
    root: Option<Spanned<DeTable<'a>>>,
}

impl<'a> TomlSpans<'a> {
    /// Parses `text` for its spans (its values are not checked: the typed reader does that).
    pub fn parse(text: &'a str) -> TomlSpans<'a> {
        TomlSpans {
            text,
            root: DeTable::parse(text).ok(),
        }
    }

    /// The values along `path` that exist, outermost first (empty when not even its first
    /// step is in the text, or the text is not TOML).
    fn walk(&self, path: &[Step<'_>]) -> Vec<&Spanned<DeValue<'a>>> {
        let mut found: Vec<&Spanned<DeValue<'a>>> = Vec::new();
        let Some(root) = self.root.as_ref() else {
            return found;
        };
        for step in path {
            let next = match (found.last(), step) {
                (None, Step::Key(key)) => root.get_ref().get(*key),
                (None, Step::Index(_)) => None,
                (Some(v), Step::Key(key)) => v.get_ref().get(*key),
                (Some(v), Step::Index(i)) => v.get_ref().get(*i),
            };
            let Some(next) = next else { break };
            found.push(next);
        }
        found
    }

    /// Byte range of the deepest value along `path` that exists; `None` when not even its
    /// first step does.
    pub fn span(&self, path: &[Step<'_>]) -> Option<Range<usize>> {
        self.walk(path).last().map(|v| v.span())
    }

    /// Whether the text has a value at exactly `path`.
    pub fn has(&self, path: &[Step<'_>]) -> bool {
        self.walk(path).len() == path.len() && !path.is_empty()
    }

    /// 1-based (line, column) of the deepest value along `path` that exists (the value
    /// itself: past its key on a `key = value` line); `None` when not even its first step
    /// does.
    pub fn line_column(&self, path: &[Step<'_>]) -> Option<(usize, usize)> {
        self.span(path).map(|s| line_column(self.text, s.start))
    }

    /// 1-based line of the value at `path` in a calibration record, looked up at the top
    /// level (a sidecar) or else under `[calibration]` (a device file's record), and the
    /// column where that line's text starts (its key); at the deepest step found when the
    /// path ends early; `None` when not even its first step is in the text.
    pub fn record_line(&self, path: &[Step<'_>]) -> Option<(usize, usize)> {
        let first = path.first()?;
        let span = if self.has(&[*first]) {
            self.span(path)?
        } else {
            let under: Vec<Step<'_>> = std::iter::once(Step::Key("calibration"))
                .chain(path.iter().copied())
                .collect();
            if !self.has(&under[..2]) {
                return None;
            }
            self.span(&under)?
        };
        let (line, _) = line_column(self.text, span.start);
        let column = self.text.lines().nth(line - 1).map_or(1, |l| {
            1 + l.chars().take_while(|c| c.is_whitespace()).count()
        });
        Some((line, column))
    }

    /// 1-based (line, column) of the calibration record's value `name` (a key of `[values]`,
    /// `[calibration.values]` in a device file; the column where its line starts), else of
    /// the first line that names `name` as a key ([`key_line`]); `None` when neither is found.
    pub fn value_line(&self, name: &str) -> Option<(usize, usize)> {
        let path = [Step::Key("values"), Step::Key(name)];
        let held = self.has(&path)
            || self.has(&[
                Step::Key("calibration"),
                Step::Key("values"),
                Step::Key(name),
            ]);
        if held {
            self.record_line(&path)
        } else {
            key_line(self.text, name)
        }
    }
}

/// 1-based (line, column) of the first line of `text` that starts, after white space, with
/// `key =`, `"key" =` or a table header `[key…` (`[[key…`), the column where its text starts;
/// `None` if none does. For a key the TOML spans cannot find ([`TomlSpans`]): a dotted name
/// such as `torque.mass`, or text that is not TOML.
pub fn key_line(text: &str, key: &str) -> Option<(usize, usize)> {
    let quoted = format!("\"{key}\"");
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let column = line.chars().count() - trimmed.chars().count() + 1;
        for candidate in [key, quoted.as_str()] {
            if let Some(rest) = trimmed.strip_prefix(candidate)
                && rest.trim_start().starts_with('=')
            {
                return Some((i + 1, column));
            }
        }
        if trimmed.starts_with('[') && trimmed.trim_start_matches('[').starts_with(key) {
            return Some((i + 1, column));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::{Step, TomlSpans, dotted_name, key_line, line_column};

    #[test]
    fn line_column_is_one_based_and_counts_characters() {
        let text = "ab\ncdé\nf";
        assert_eq!(line_column(text, 0), (1, 1));
        assert_eq!(line_column(text, 1), (1, 2));
        assert_eq!(line_column(text, 3), (2, 1));
        assert_eq!(line_column(text, 7), (2, 4)); // after 'é' (2 bytes)
        assert_eq!(line_column(text, 6), (2, 3)); // inside 'é': clamped to its start
        assert_eq!(line_column(text, 8), (3, 1));
        assert_eq!(line_column(text, 100), (3, 2));
    }

    #[test]
    fn spans_find_values_tables_and_record_keys() {
        let text = "a = 1\n\n[[dh]]\na_m = 0.5\n\n[calibration]\ntips = [\"t\"]\n\n\
                    [calibration.values]\n  \"da0\" = { value = 1e-3, std = 0.0, unit = \"m\" }\n\n\
                    [calibration.nominal.j2]\nxyz_m = [0.0, 0.0, 0.0]\n";
        let spans = TomlSpans::parse(text);
        let a_m = [Step::Key("dh"), Step::Index(0), Step::Key("a_m")];
        assert_eq!(spans.line_column(&a_m), Some((4, 7)));
        assert!(spans.has(&a_m));
        assert!(!spans.has(&[Step::Key("dh"), Step::Index(1)]));
        // The deepest value found when the path ends early.
        assert_eq!(
            spans.line_column(&[Step::Key("dh"), Step::Index(0), Step::Key("d_m")]),
            spans.line_column(&[Step::Key("dh"), Step::Index(0)])
        );
        assert_eq!(spans.line_column(&[Step::Key("b")]), None);
        assert_eq!(spans.record_line(&[Step::Key("tips")]), Some((7, 1)));
        assert_eq!(spans.value_line("da0"), Some((10, 3)));
        // A value the record does not hold: not the line of its table.
        assert_eq!(spans.value_line("dd0"), None);
        assert_eq!(
            spans.record_line(&[Step::Key("nominal"), Step::Key("j2")]),
            Some((12, 1))
        );
        assert_eq!(spans.record_line(&[Step::Key("region")]), None);
        assert_eq!(key_line(text, "calibration.nominal"), Some((12, 1)));
        assert_eq!(key_line(text, "tips"), Some((7, 1)));
        assert_eq!(key_line(text, "missing"), None);
        assert_eq!(dotted_name(&a_m), "dh[0].a_m");
        assert_eq!(TomlSpans::parse("a = [").span(&[Step::Key("a")]), None);
    }
}
