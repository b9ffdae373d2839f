//! The modules of `src/` form layers: no module names, in code or in a doc link, a module that
//! names it back, directly or through others (docs/engine.md, "Module layers of
//! hapcal-calibrate"). A `crate::<module>` or `super::<module>` path (also inside a
//! `crate::{…}` group) is an edge from the file's module to `<module>`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module name → the modules its file names.
type Graph = BTreeMap<String, BTreeSet<String>>;

/// The identifier at the start of `text` (letters, digits, `_`).
fn identifier(text: &str) -> &str {
    let end = text
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(text.len());
    &text[..end]
}

/// The first identifier of each top-level item of the group that starts right after a `{` at
/// the start of `text`: `data, fit::{a, b}, model}` gives `data`, `fit`, `model`.
fn group_heads(text: &str) -> Vec<&str> {
    let mut heads = Vec::new();
    let (mut depth, mut item_start) = (0usize, 0);
    for (i, c) in text.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                heads.push(identifier(text[item_start..i].trim_start()));
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                heads.push(identifier(text[item_start..i].trim_start()));
                item_start = i + 1;
            }
            _ => {}
        }
    }
    heads
}

/// The module graph of the files `(module, text)`: an edge for every `crate::<m>` and
/// `super::<m>` naming another of the modules.
fn graph(files: &[(String, String)]) -> Graph {
    let modules: BTreeSet<&str> = files.iter().map(|(m, _)| m.as_str()).collect();
    let mut graph = Graph::new();
    for (module, text) in files {
        let edges = graph.entry(module.clone()).or_default();
        for prefix in ["crate::", "super::"] {
            for (at, _) in text.match_indices(prefix) {
                let rest = &text[at + prefix.len()..];
                let named = match rest.strip_prefix('{') {
                    Some(group) => group_heads(group),
                    None => vec![identifier(rest)],
                };
                for name in named {
                    if name != module && modules.contains(name) {
                        edges.insert(name.to_owned());
                    }
                }
            }
        }
    }
    graph
}

/// A cycle of `graph` as its modules in order (the first repeated at the end), if it has one.
fn cycle(graph: &Graph) -> Option<Vec<String>> {
    /// Depth-first search from `module`, `path` the modules on the way to it; `done` the
    /// modules whose every path was followed.
    fn visit(
        graph: &Graph,
        module: &str,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(start) = path.iter().position(|m| m == module) {
            let mut found = path[start..].to_vec();
            found.push(module.to_owned());
            return Some(found);
        }
        if done.contains(module) {
            return None;
        }
        path.push(module.to_owned());
        for next in graph.get(module).into_iter().flatten() {
            if let Some(found) = visit(graph, next, path, done) {
                return Some(found);
            }
        }
        path.pop();
        done.insert(module.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|m| visit(graph, m, &mut Vec::new(), &mut done))
}

/// The graph as one line per module: `calibrate -> data fit …`.
fn render(graph: &Graph) -> String {
    graph
        .iter()
        .map(|(m, edges)| {
            let to: Vec<&str> = edges.iter().map(String::as_str).collect();
            format!("{m} -> {}\n", to.join(" "))
        })
        .collect()
}

/// Appends the text of every `.rs` file under `dir` (none when it is not a directory).
fn append_submodules(dir: &Path, text: &mut String) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            append_submodules(&path, text);
        } else if path.extension().is_some_and(|e| e == "rs") {
            text.push('\n');
            text.push_str(&std::fs::read_to_string(&path).expect("a readable source file"));
        }
    }
}

#[test]
fn the_modules_of_the_crate_import_each_other_in_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    for entry in std::fs::read_dir(&src).expect("src/ is readable") {
        let path = entry.expect("a directory entry").path();
        let module = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        if let Some(module) = module
            && path.extension().is_some_and(|e| e == "rs")
            && module != "lib"
        {
            let mut text = std::fs::read_to_string(&path).expect("a readable source file");
            // A module's submodules (src/<module>/…) are part of its text: their imports are
            // the module's.
            append_submodules(&src.join(&module), &mut text);
            files.push((module, text));
        }
    }
    assert!(files.len() > 5, "no modules found in {}", src.display());
    let graph = graph(&files);
    if let Some(found) = cycle(&graph) {
        panic!(
            "modules that name each other in a circle: {}\nthe module graph:\n{}",
            found.join(" -> "),
            render(&graph)
        );
    }
}

#[test]
fn a_circle_through_a_doc_link_or_a_use_group_is_found() {
    let files = [
        ("inputs", "/// Handed to [`crate::calibrate::run`]."),
        ("data", "use crate::{inputs::Plan, model};"),
        (
            "calibrate",
            "use crate::data::load;\nuse super::{model, noise};",
        ),
        ("model", "pub fn terms() {}"),
        ("noise", ""),
    ]
    .map(|(m, t)| (m.to_owned(), t.to_owned()));
    let graph = graph(&files);
    assert_eq!(
        render(&graph),
        "calibrate -> data model noise\ndata -> inputs model\ninputs -> calibrate\nmodel -> \n\
         noise -> \n"
    );
    assert_eq!(
        cycle(&graph).map(|c| c.join(" -> ")).as_deref(),
        Some("calibrate -> data -> inputs -> calibrate")
    );
    let without_link = [&files[1..], &[("inputs".to_owned(), String::new())]].concat();
    assert_eq!(cycle(&self::graph(&without_link)), None);
}
