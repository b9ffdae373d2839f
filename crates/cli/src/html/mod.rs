//! The HTML report of `calibrate`, `diagnose` and `predict` (`--report FILE.html`): one
//! self-contained file, inline SVG figures drawn with `plotters`, inline CSS, no script and
//! nothing fetched, readable offline and printable; rendered from the typed reports, never from
//! their text.
//!
//! Every figure is a `<figure class="figure" id="…" data-values="…">`: the `data-values`
//! attribute holds the numbers it plots as JSON, which the golden check of `cargo xtask
//! html-check` compares.

mod calibration;
mod figures;
mod other;

pub use calibration::{calibration_page, figures as calibration_figures};
pub use figures::Figure;
pub use other::{
    DiagnosisView, diagnosis_figures, diagnosis_page, prediction_figures, prediction_page,
};

use anyhow::{Context, Result};
use hapcal_io::InputFile;
use std::fmt::Write;
use std::path::Path;

/// Escapes `text` for HTML element content and attribute values (`&`, `<`, `>`, `"`, `'`).
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Writes the HTML report `html` to `path` (atomically, never over one of `inputs`), after
/// checking that the name ends in `.html` or `.htm`.
///
/// # Errors
/// Another extension, an input as the output, or a failed write.
pub fn write(path: &Path, html: &str, inputs: &[&Path]) -> Result<()> {
    crate::calibrate::check_extension(path, &["html", "htm"], "the HTML report", true)?;
    crate::calibrate::write_new(path, html, inputs)
        .with_context(|| format!("writing the HTML report {}", path.display()))
}

/// Checks before the work that the report `path` can be written (its extension, its folder,
/// that it is none of `inputs`).
///
/// # Errors
/// As [`write()`], before anything is computed.
pub fn check(path: &Path, inputs: &[&Path]) -> Result<()> {
    crate::calibrate::check_extension(path, &["html", "htm"], "the HTML report", true)?;
    crate::calibrate::check_output(path, inputs)
}

/// Writes the HTML report of the calibration `report` of `device` from the data `inputs` to
/// `path`, with this process's command line and the files' hashes.
///
/// # Errors
/// As [`write()`].
pub fn write_calibration(
    path: &Path,
    report: &hapcal_calibrate::report::CalibrationReport,
    device: &Path,
    inputs: &[&Path],
) -> Result<()> {
    let files: Vec<&Path> = std::iter::once(device)
        .chain(inputs.iter().copied())
        .collect();
    write_page(path, &files, |command, files| {
        calibration_page(report, command, files)
    })
}

/// Writes the HTML report of a diagnosis (`view`, its text report `text` and residual maps
/// `maps_svg`) made from `inputs` (the device first) to `path`.
///
/// # Errors
/// As [`write()`].
pub fn write_diagnosis(
    path: &Path,
    view: &DiagnosisView,
    text: &str,
    maps_svg: &str,
    inputs: &[&Path],
) -> Result<()> {
    write_page(path, inputs, |command, files| {
        diagnosis_page(view, text, maps_svg, command, files)
    })
}

/// Writes the HTML report `page(command, inputs)` made from the files `inputs` by this
/// process's command line to `path`.
///
/// # Errors
/// As [`write()`].
pub fn write_page(
    path: &Path,
    inputs: &[&Path],
    page: impl FnOnce(&str, &[InputFile]) -> String,
) -> Result<()> {
    write(
        path,
        &page(&this_command(), &hapcal_io::input_files(inputs)),
        inputs,
    )
}

/// The command line of this process, as [`command_line`] writes it.
pub fn this_command() -> String {
    command_line(&std::env::args_os().collect::<Vec<_>>())
}

/// The command line that made a report, each argument quoted for a POSIX shell where it
/// needs it.
pub fn command_line(args: &[std::ffi::OsString]) -> String {
    let words: Vec<String> = (args.iter())
        .enumerate()
        .map(|(i, a)| {
            let a = a.to_string_lossy();
            let a = if i == 0 {
                Path::new(a.as_ref())
                    .file_name()
                    .map_or(a.to_string(), |n| n.to_string_lossy().into_owned())
            } else {
                a.into_owned()
            };
            let plain = !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
            if plain {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect();
    words.join(" ")
}

/// An HTML report being built: a title, what made it, then sections of figures, tables and
/// text.
#[derive(Clone, Debug)]
pub struct Page {
    title: String,
    body: String,
    /// Whether a section is open.
    open: bool,
}

impl Page {
    /// A page titled `title` that records the command line `command` and the `inputs`.
    pub fn new(title: &str, command: &str, inputs: &[InputFile]) -> Page {
        let mut body = String::new();
        let _ = write!(
            body,
            "<h1>{}</h1>\n<section id=\"provenance\"><h2>How it was made</h2>\n\
             <p class=\"command\"><code>{}</code></p>\n<p>hapcal {}</p>\n",
            escape(title),
            escape(command),
            escape(env!("CARGO_PKG_VERSION"))
        );
        if !inputs.is_empty() {
            body.push_str("<table class=\"inputs\"><tr><th>data file</th><th>SHA-256</th></tr>\n");
            for i in inputs {
                let hash = match &i.sha256 {
                    Ok(h) => format!("<code>{h}</code>"),
                    Err(e) => format!("not read: {}", escape(e)),
                };
                let _ = writeln!(
                    body,
                    "<tr><td><code>{}</code></td><td class=\"hash\">{hash}</td></tr>",
                    escape(&i.path)
                );
            }
            body.push_str("</table>\n");
        }
        body.push_str("</section>\n");
        Page {
            title: title.to_owned(),
            body,
            open: false,
        }
    }

    /// Opens a section headed `heading` with the element id `id`.
    pub fn section(&mut self, id: &str, heading: &str) {
        self.close_section();
        let _ = writeln!(
            self.body,
            "<section id=\"{}\"><h2>{}</h2>",
            escape(id),
            escape(heading)
        );
        self.open = true;
    }

    fn close_section(&mut self) {
        if self.open {
            self.body.push_str("</section>\n");
            self.open = false;
        }
    }

    /// A paragraph of plain text.
    pub fn paragraph(&mut self, text: &str) {
        let _ = writeln!(self.body, "<p>{}</p>", escape(text));
    }

    /// A bulleted list of plain-text items, with the class `class`.
    pub fn list(&mut self, class: &str, items: &[String]) {
        let _ = writeln!(self.body, "<ul class=\"{}\">", escape(class));
        for item in items {
            let _ = writeln!(self.body, "<li>{}</li>", escape(item));
        }
        self.body.push_str("</ul>\n");
    }

    /// A table with the header `head` and the rows `rows` (plain text; cells that parse as
    /// numbers are right-aligned).
    pub fn table(&mut self, head: &[&str], rows: &[Vec<String>]) {
        self.body.push_str("<div class=\"table\"><table>\n<tr>");
        for h in head {
            let _ = write!(self.body, "<th>{}</th>", escape(h));
        }
        self.body.push_str("</tr>\n");
        for row in rows {
            self.body.push_str("<tr>");
            for cell in row {
                let numeric = cell
                    .trim_start_matches(['+', '-', '±', ' '])
                    .split_whitespace()
                    .next()
                    .is_some_and(|w| w.parse::<f64>().is_ok());
                let class = if numeric { " class=\"num\"" } else { "" };
                let _ = write!(self.body, "<td{class}>{}</td>", escape(cell));
            }
            self.body.push_str("</tr>\n");
        }
        self.body.push_str("</table></div>\n");
    }

    /// The finished document, ending with the section "The text report": `text` as
    /// `command` (`hapcal calibrate`, …) prints it, preformatted and folded.
    pub fn finish_with_text(mut self, command: &str, text: &str) -> String {
        self.section("text", "The text report");
        let _ = writeln!(
            self.body,
            "<details open><summary>{}</summary><pre>{}</pre></details>",
            escape(&format!("as {command} prints it")),
            escape(text)
        );
        self.finish()
    }

    /// A figure (its SVG, its caption and its numbers).
    pub fn figure(&mut self, figure: &Figure) {
        self.body.push_str(&figure.html());
    }

    /// The finished document.
    fn finish(mut self) -> String {
        self.close_section();
        format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
             <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{}</body>\n</html>\n",
            escape(&self.title),
            self.body
        )
    }
}

/// The page's inline style sheet: system fonts only, figures scale to the page, tables scroll
/// inside their box rather than overflow it, one figure per printed page at most.
const STYLE: &str = "
body { font-family: system-ui, -apple-system, 'Segoe UI', sans-serif; margin: 1.5em auto;
  max-width: 62em; padding: 0 1em; color: #111; line-height: 1.4; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; }
code, pre { font-family: ui-monospace, 'DejaVu Sans Mono', monospace; font-size: 0.85em; }
p.command code { white-space: pre-wrap; overflow-wrap: anywhere; }
td.hash code { overflow-wrap: anywhere; word-break: break-all; }
table { border-collapse: collapse; margin: 0.5em 0; }
th, td { border: 1px solid #ccc; padding: 0.15em 0.5em; text-align: left; vertical-align: top;
  overflow-wrap: break-word; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
div.table { max-width: 100%; overflow-x: auto; }
table.inputs { table-layout: fixed; width: 100%; }
table.inputs td:first-child { width: 40%; }
figure.figure { margin: 1em 0; break-inside: avoid; }
figure.figure svg { display: block; max-width: 100%; height: auto; }
figcaption { font-size: 0.9em; color: #333; }
ul.warnings li { color: #8a4b00; }
pre { white-space: pre-wrap; overflow-wrap: anywhere; background: #f6f6f6; padding: 0.5em; }
@media print { body { max-width: none; } }
";
