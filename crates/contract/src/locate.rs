//! Where a record's key stands in its text: the line of a value found by its key path through
//! the TOML parser's spans and the column where that line's text starts, so that every refusal points at its own line.

use crate::line_column;

/// One step of a key path: a table key or an array index.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Step<'a> {
    /// A table's key.
    Key(&'a str),
    /// An array's entry.
    Index(usize),
}

/// 1-based line of the value at `path` in `text`, and the column where that line's text
/// starts (its key), looked up at the top level (a
/// sidecar) or else under `[calibration]` (a device file's record); at the deepest step found
/// when the path ends early; `None` when not even its first step is in the text (or the text
/// is not TOML).
pub(crate) fn locate_path(text: &str, path: &[Step<'_>]) -> Option<(usize, usize)> {
    let root = toml::de::DeTable::parse(text).ok()?;
    let Some(Step::Key(first)) = path.first() else {
        return None;
    };
    let table = root.get_ref();
    let start = match table.get(*first) {
        Some(v) => v,
        None => table
            .get("calibration")
            .and_then(|c| c.get_ref().get(*first))?,
    };
    let mut span = start.span();
    let mut current = start;
    for step in &path[1..] {
        let next = match step {
            Step::Key(key) => current.get_ref().get(*key),
            Step::Index(i) => current.get_ref().get(*i),
        };
        let Some(next) = next else { break };
        span = next.span();
        current = next;
    }
    // The line's first character: where its key stands (the value's own column is past the
    // key on a `key = value` line).
    let (line, _) = line_column(text, span.start);
    let column = text.lines().nth(line - 1).map_or(1, |l| {
        1 + l.chars().take_while(|c| c.is_whitespace()).count()
    });
    Some((line, column))
}
