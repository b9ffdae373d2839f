//! `cargo xtask tidy`: checks over the tracked files (`git ls-files`) that keep how the code
//! was written out of the product, and keep the repository's own references sound.
//!
//! Text files (valid UTF-8, no NUL byte) are checked, except `Cargo.lock`, the upstream
//! `fixtures/**/LICENSE*` and `fixtures/**/README.md` (their words belong to the upstream
//! project) and recorded data (`*.csv`, `*.yaml`, `*.yml`, `*.urdf`). The rules:
//!
//! - **Machine paths**: `/work/`, `/home/`, `/root/` or `/tmp/` at the start of a path. There is
//!   no exception for tests: they take their scratch directory from `std::env::temp_dir()`.
//! - **Development history**: an issue number (`issue #4`, `issue 4`, `issue4()`,
//!   `issue_4`), the word "session(s)", "project lead" (case-insensitive). This file spells the
//!   rules out and is exempt from these two rules.
//! - **Crate descriptions**: every `crates/*/Cargo.toml` and `xtask/Cargo.toml` has a
//!   `description` that says what the crate does, not a placeholder such as
//!   `"hapcal: identify"` (one word after `hapcal:`).
//! - **Markdown links**: a relative link `](path)` in `docs/**/*.md` or a `README.md` outside
//!   `fixtures/` names a tracked file or directory (resolved from the page's directory; a
//!   leading `/` from the repository root; `#fragment` ignored; code spans and fenced blocks
//!   skipped).
//! - **Duplicate data**: no two non-empty tracked files of different data sets have identical
//!   bytes (tests read the fixture instead of a copy). A data set is an entry directly under
//!   `fixtures/` or `crates/*/test_data/`; within one set identical files may be part of its
//!   layout (e.g. the valid socket files of the malformed MUKCa recordings of the io tests).
//!
//! - **One vocabulary**: the Rust sources of the crates and the Python bindings (`crates/*/src`,
//!   `python/src`; test modules, tests and examples excluded) never write an
//!   effect's name (`hapcal_contract::Effect::name`: `gravity_compliance`, …) as a string
//!   literal of their own: they take it from the type, whose module
//!   (`crates/contract/src/effect.rs`) is the one place that spells it. Likewise a model's
//!   name (`hapcal_contract::ModelName::name`: `transversal-compliance`, …), spelled only in
//!   `crates/contract/src/lib.rs`.
//!
//! Every finding is printed as `file:line: message`; the task fails if there is any.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

use anyhow::{Context, Result, bail};
use xshell::{Shell, cmd};

/// This file: it names the forbidden words and paths.
const SELF: &str = "xtask/src/tidy.rs";

/// Absolute paths of the build machine.
const MACHINE_PATHS: &[&str] = &["/work/", "/home/", "/root/", "/tmp/"];

/// One finding: file, 1-based line (0 = the whole file), message.
#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Finding {
    file: String,
    line: usize,
    message: String,
}

/// Runs every check from the repository root (`sh`'s directory).
pub(crate) fn run(sh: &Shell) -> Result<()> {
    let listed = cmd!(sh, "git ls-files -z").read()?;
    let root = sh.current_dir();
    // Tracked and present (a file deleted in the working tree but not yet in the index is
    // not checked).
    let files: Vec<String> = listed
        .split('\0')
        .filter(|f| !f.is_empty() && root.join(f).is_file())
        .map(str::to_owned)
        .collect();
    let tracked: BTreeSet<String> = files.iter().cloned().collect();
    let mut findings = Vec::new();
    let mut data: Vec<(String, Vec<u8>)> = Vec::new();
    for file in &files {
        let bytes = std::fs::read(root.join(file)).with_context(|| format!("reading {file}"))?;
        if is_data_dir(file) && !bytes.is_empty() {
            data.push((file.clone(), bytes.clone()));
        }
        if skipped(file) || bytes.contains(&0) {
            continue;
        }
        let Ok(text) = String::from_utf8(bytes) else {
            continue;
        };
        findings.extend(check_text(file, &text));
        if is_vocabulary_checked(file) {
            findings.extend(check_vocabulary(file, &text));
        }
        if is_crate_manifest(file) {
            findings.extend(check_description(file, &text));
        }
        if is_checked_markdown(file) {
            findings.extend(check_links(file, &text, &tracked));
        }
    }
    findings.extend(check_duplicates(&data));
    findings.sort();
    for f in &findings {
        if f.line == 0 {
            println!("{}: {}", f.file, f.message);
        } else {
            println!("{}:{}: {}", f.file, f.line, f.message);
        }
    }
    if !findings.is_empty() {
        bail!("tidy: {} finding(s)", findings.len());
    }
    println!("tidy: {} tracked files, no findings", files.len());
    Ok(())
}

/// The one module that spells the effects' names.
const VOCABULARY: &str = "crates/contract/src/effect.rs";

/// Rust sources of the product (not tests, benches or examples), where an effect's name must
/// come from the type.
fn is_vocabulary_checked(file: &str) -> bool {
    let in_src =
        (file.starts_with("crates/") && file.contains("/src/")) || file.starts_with("python/src/");
    let test_module = file.ends_with("/tests.rs") || file.contains("/tests/");
    in_src && !test_module && file.ends_with(".rs") && file != VOCABULARY && file != SELF
}

/// The one module that spells the models' names.
const MODEL_VOCABULARY: &str = "crates/contract/src/lib.rs";

/// A string literal that is exactly an effect's or a model's name.
fn check_vocabulary(file: &str, text: &str) -> Vec<Finding> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break; // the file's test module, at its end
        }
        if line.trim_start().starts_with("//") {
            continue;
        }
        use hapcal_contract::Effect::{Capstans, Geometric, JointOffsets, Parallelogram};
        // These effects' words are also a model's `--model` name (the model that frees just
        // this effect) or a device file's element: written in those roles too.
        let effects = (hapcal_contract::Effect::ALL.into_iter())
            .filter(|e| !matches!(e, Geometric | JointOffsets | Capstans | Parallelogram))
            .map(|e| ("effect", e.name(), "Effect", VOCABULARY));
        // `geometric` is also the effect of that name, exempt above; a command-line
        // argument's id (`mut_arg("transmissions", …)`) is not a model's name.
        let models = (hapcal_contract::ModelName::ALL.into_iter())
            .filter(|m| {
                file != MODEL_VOCABULARY
                    && *m != hapcal_contract::ModelName::Geometric
                    && !line.contains("mut_arg(")
            })
            .map(|m| ("model", m.name(), "ModelName", MODEL_VOCABULARY));
        for (kind, name, type_name, vocabulary) in effects.chain(models) {
            if line.contains(&format!("\"{name}\"")) {
                out.push(Finding {
                    file: file.to_owned(),
                    line: i + 1,
                    message: format!(
                        "the {kind} name \"{name}\" written out: take it from \
                         hapcal_contract::{type_name} (one vocabulary, {vocabulary})"
                    ),
                });
            }
        }
    }
    out
}

/// Files whose words are not ours to check: the lock file, upstream notices, recorded data.
fn skipped(file: &str) -> bool {
    let name = file.rsplit('/').next().unwrap_or(file);
    let ext = name.rsplit_once('.').map_or("", |(_, e)| e);
    file == "Cargo.lock"
        || (file.starts_with("fixtures/") && (name.starts_with("LICENSE") || name == "README.md"))
        || matches!(ext, "csv" | "yaml" | "yml" | "urdf")
}

/// Directories where two identical files mean a copy that tests should not need.
fn is_data_dir(file: &str) -> bool {
    file.starts_with("fixtures/")
        || file
            .strip_prefix("crates/")
            .and_then(|rest| rest.split_once('/'))
            .is_some_and(|(_, rest)| rest.starts_with("test_data/"))
}

fn is_crate_manifest(file: &str) -> bool {
    file == "xtask/Cargo.toml"
        || file
            .strip_prefix("crates/")
            .and_then(|rest| rest.strip_suffix("/Cargo.toml"))
            .is_some_and(|krate| !krate.contains('/'))
}

fn is_checked_markdown(file: &str) -> bool {
    (file.starts_with("docs/") && file.ends_with(".md"))
        || ((file == "README.md" || file.ends_with("/README.md")) && !file.starts_with("fixtures/"))
}

/// Machine paths and development history, line by line.
fn check_text(file: &str, text: &str) -> Vec<Finding> {
    if file == SELF {
        return Vec::new();
    }
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let lower = line.to_lowercase();
        let mut messages = Vec::new();
        if let Some(p) = machine_path(&lower) {
            messages.push(format!("absolute path of the build machine (`{p}`)"));
        }
        if let Some(w) = history_word(&lower) {
            messages.push(format!("development history in the product (`{w}`)"));
        }
        out.extend(messages.into_iter().map(|message| Finding {
            file: file.to_owned(),
            line: i + 1,
            message,
        }));
    }
    out
}

/// The first machine path in `line` that starts a path (not inside a longer one such as
/// `example.org/work/`).
fn machine_path(line: &str) -> Option<&'static str> {
    MACHINE_PATHS.iter().copied().find(|p| {
        line.match_indices(p).any(|(at, _)| {
            line[..at]
                .chars()
                .next_back()
                .is_none_or(|c| !(c.is_alphanumeric() || matches!(c, '_' | '.' | '-' | '/')))
        })
    })
}

/// Whether `line` (lower case) has `word` at `at` with no word character before it.
fn starts_word(line: &str, at: usize) -> bool {
    line[..at]
        .chars()
        .next_back()
        .is_none_or(|c| !(c.is_alphanumeric() || c == '_'))
}

/// The first history word in `line` (lower case): an issue number, "session(s)", "project lead".
fn history_word(line: &str) -> Option<String> {
    for (at, _) in line.match_indices("issue") {
        if !starts_word(line, at) {
            continue;
        }
        let rest = &line[at + "issue".len()..];
        let number = rest
            .strip_prefix(" #")
            .or_else(|| rest.strip_prefix('#'))
            .or_else(|| rest.strip_prefix(' '))
            .or_else(|| rest.strip_prefix('_'))
            .unwrap_or(rest);
        if number.starts_with(|c: char| c.is_ascii_digit()) {
            let end = at + "issue".len() + (rest.len() - number.len()) + 1;
            return Some(line[at..end].to_owned());
        }
    }
    for (at, _) in line.match_indices("session") {
        let rest = &line[at + "session".len()..];
        let rest = rest.strip_prefix('s').unwrap_or(rest);
        if starts_word(line, at) && !rest.starts_with(|c: char| c.is_alphanumeric() || c == '_') {
            return Some("session".to_owned());
        }
    }
    line.contains("project lead")
        .then(|| "project lead".to_owned())
}

/// The crate's `description`: present, and more than `hapcal: <one word>`.
fn check_description(file: &str, text: &str) -> Vec<Finding> {
    let finding = |line, message: &str| Finding {
        file: file.to_owned(),
        line,
        message: message.to_owned(),
    };
    let mut section = "";
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.starts_with('[') {
            section = t;
            continue;
        }
        if section != "[package]" {
            continue;
        }
        let Some((key, value)) = t.split_once('=') else {
            continue;
        };
        if key.trim() != "description" {
            continue;
        }
        let value = value.trim().trim_matches('"').trim();
        let after_name = value
            .strip_prefix("hapcal:")
            .or_else(|| value.strip_prefix("hapcal-"))
            .map(str::trim);
        if value.is_empty() || after_name.is_some_and(|w| !w.contains(char::is_whitespace)) {
            return vec![finding(
                i + 1,
                &format!("placeholder crate description `{value}`: say what the crate does"),
            )];
        }
        return Vec::new();
    }
    vec![finding(0, "no `description` in [package]")]
}

/// Relative Markdown links whose target is not tracked.
fn check_links(file: &str, text: &str, tracked: &BTreeSet<String>) -> Vec<Finding> {
    let dir = Path::new(file).parent().unwrap_or(Path::new(""));
    let mut out = Vec::new();
    let mut fence: Option<&str> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        if let Some(f) = fence {
            if t.starts_with(f) {
                fence = None;
            }
            continue;
        }
        if t.starts_with("```") || t.starts_with("~~~") {
            fence = Some(&t[..3]);
            continue;
        }
        let prose = without_code_spans(line);
        for (at, _) in prose.match_indices("](") {
            let rest = &prose[at + 2..];
            let end = rest.find([')', ' ']).unwrap_or(rest.len());
            let target = rest[..end].trim_start_matches('<').trim_end_matches('>');
            let path = target.split('#').next().unwrap_or("");
            if path.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let resolved = match path.strip_prefix('/') {
                Some(from_root) => PathBuf::from(from_root),
                None => dir.join(path),
            };
            let exists = normalise(&resolved).is_some_and(|p| {
                tracked.contains(&p)
                    || tracked
                        .range(format!("{p}/")..)
                        .next()
                        .is_some_and(|f| f.starts_with(&format!("{p}/")))
            });
            if !exists {
                out.push(Finding {
                    file: file.to_owned(),
                    line: i + 1,
                    message: format!(
                        "link to `{target}`, which is not a tracked file or directory"
                    ),
                });
            }
        }
    }
    out
}

/// `line` with every inline code span (between backticks) removed.
fn without_code_spans(line: &str) -> String {
    line.split('`').step_by(2).collect::<Vec<_>>().join(" ")
}

/// `path` with `.` and `..` resolved lexically, `/`-separated; `None` if it leaves the root.
fn normalise(path: &Path) -> Option<String> {
    let mut parts: Vec<String> = Vec::new();
    for c in path.components() {
        match c {
            Component::Normal(s) => parts.push(s.to_string_lossy().into_owned()),
            Component::ParentDir => {
                parts.pop()?;
            }
            Component::CurDir => {}
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    Some(parts.join("/"))
}

/// The data set of a file under `fixtures/` or `crates/*/test_data/`: the path up to and
/// including the first component below that directory.
fn data_set(file: &str) -> &str {
    let depth = if file.starts_with("fixtures/") { 2 } else { 4 };
    match file.match_indices('/').nth(depth - 1) {
        Some((at, _)) => &file[..at],
        None => file,
    }
}

/// Groups of identical files of more than one data set, reported at each copy after the
/// first (the one under `fixtures/` is kept).
fn check_duplicates(data: &[(String, Vec<u8>)]) -> Vec<Finding> {
    let mut by_content: BTreeMap<&[u8], Vec<&str>> = BTreeMap::new();
    for (file, bytes) in data {
        by_content.entry(bytes).or_default().push(file);
    }
    by_content
        .into_values()
        .filter(|files| files.iter().any(|f| data_set(f) != data_set(files[0])))
        .flat_map(|mut files| {
            // The copy under fixtures/ is the one to keep.
            files.sort_by_key(|f| (!f.starts_with("fixtures/"), *f));
            let first = files[0];
            files[1..]
                .iter()
                .map(|f| Finding {
                    file: (*f).to_owned(),
                    line: 0,
                    message: format!("identical bytes to {first}: read that file instead"),
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_words() {
        for hit in [
            "// see issue #4",
            "ForcePlan::issue4()",
            "issue 12's table",
            "as in Issue#2",
            "issue_5",
            "Earlier sessions:",
            "last session 8.6x",
            "run by the project lead",
        ] {
            assert!(history_word(&hit.to_lowercase()).is_some(), "{hit}");
        }
        for clean in [
            "the issue's target",
            "tissue4",
            "issues with the data",
            "sessionless",
            "possession",
        ] {
            assert!(history_word(&clean.to_lowercase()).is_none(), "{clean}");
        }
    }

    #[test]
    fn machine_paths() {
        assert!(machine_path("`/work/target-lead/bench-data`").is_some());
        assert!(machine_path("CARGO_TARGET_DIR=/work/target").is_some());
        assert!(machine_path("/tmp/x").is_some());
        assert!(machine_path("https://example.org/work/page").is_none());
        assert!(machine_path("docs/home/index.md").is_none());
    }

    #[test]
    fn descriptions() {
        let placeholder = "[package]\nname = \"hapcal-io\"\ndescription = \"hapcal: io\"\n";
        assert_eq!(
            check_description("crates/io/Cargo.toml", placeholder).len(),
            1
        );
        let real = "[package]\ndescription = \"hapcal: file formats (TOML, URDF, CSV)\"\n";
        assert!(check_description("crates/io/Cargo.toml", real).is_empty());
        let missing = "[package]\nname = \"x\"\n[dependencies]\ndescription = \"not here\"\n";
        assert_eq!(check_description("xtask/Cargo.toml", missing).len(), 1);
    }

    #[test]
    fn links() {
        let tracked: BTreeSet<String> = ["docs/results/a.md", "fixtures/x/y.csv", "README.md"]
            .into_iter()
            .map(str::to_owned)
            .collect();
        let text = "[a](a.md) [b](../../fixtures/x/y.csv#L2) [d](../../fixtures/x) \
                    [web](https://example.org/no) [top](#here) `[c](missing.md)`\n\
                    ```\n[e](missing.md)\n```\n[f](missing.md) [g](/README.md)";
        let found = check_links("docs/results/b.md", text, &tracked);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].line, 5);
    }

    #[test]
    fn vocabulary() {
        let effect = hapcal_contract::Effect::Backlash.name();
        let model = hapcal_contract::ModelName::FramesOnly.name();
        let text = format!(
            "let a = \"{effect}\";\nlet b = \"{model}\";\nlet c = mut_arg(\"{model}\");\n\
             // \"{effect}\"\nlet d = \"geometric\";\n"
        );
        let found = check_vocabulary("crates/x/src/a.rs", &text);
        let lines: Vec<usize> = found.iter().map(|f| f.line).collect();
        assert_eq!(lines, [1, 2]);
        assert_eq!(
            found[0].message,
            format!(
                "the effect name \"{effect}\" written out: take it from hapcal_contract::Effect \
                 (one vocabulary, {VOCABULARY})"
            )
        );
        assert_eq!(
            found[1].message,
            format!(
                "the model name \"{model}\" written out: take it from \
                 hapcal_contract::ModelName (one vocabulary, {MODEL_VOCABULARY})"
            )
        );
        // The models' own module spells their names.
        assert!(check_vocabulary(MODEL_VOCABULARY, &format!("\"{model}\"")).is_empty());
    }

    #[test]
    fn duplicates() {
        let data = vec![
            ("fixtures/a.toml".to_owned(), b"x = 1".to_vec()),
            ("crates/io/test_data/a.toml".to_owned(), b"x = 1".to_vec()),
            ("fixtures/b.toml".to_owned(), b"x = 2".to_vec()),
            (
                "crates/io/test_data/bad/a/x.csv".to_owned(),
                b"1,2".to_vec(),
            ),
            (
                "crates/io/test_data/bad/b/x.csv".to_owned(),
                b"1,2".to_vec(),
            ),
        ];
        let found = check_duplicates(&data);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].file, "crates/io/test_data/a.toml");
        assert!(is_data_dir("crates/io/test_data/a.toml"));
        assert!(!is_data_dir("crates/io/src/a.rs"));
        assert_eq!(data_set("fixtures/mukca/data/x.csv"), "fixtures/mukca");
        assert_eq!(
            data_set("crates/io/test_data/mukca_bad/gap/hole_0.csv"),
            "crates/io/test_data/mukca_bad"
        );
        assert_eq!(
            data_set("crates/io/test_data/planar.toml"),
            "crates/io/test_data/planar.toml"
        );
    }
}
