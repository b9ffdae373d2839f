//! `cargo xtask html-check`: the HTML reports (`--report`) of the bundled kuka_14 calibration,
//! of every bundled recording of `cargo xtask real-data`, of a diagnosis and of a prediction,
//! written by the release binary into a scratch folder and opened in headless Chromium. Fails on
//! a console error, a figure of zero size, text that overflows its box, a missing figure, or a
//! kuka_14 figure whose numbers differ from fixtures/golden/ours/html-kuka_14.json
//! (`UPDATE_GOLDEN=1` rewrites that file and fails). `--figures` also writes the README's PNGs
//! of the simulated humanoid's ladder and residual-against-joint figures into docs/figures/.

use anyhow::{Context, Result, bail};
use serde_json::Value;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use xshell::{Shell, cmd};

/// The golden numbers of the kuka_14 report's figures.
const GOLDEN: &str = "fixtures/golden/ours/html-kuka_14.json";

/// Relative tolerance of a golden number (the figures record 6 significant digits).
const GOLDEN_RTOL: f64 = 1e-4;
/// Absolute tolerance of a golden number near zero (figures' units: mm, mm², share, count).
const GOLDEN_ATOL: f64 = 1e-9;

/// The figures every calibration on measurement files shows (`fig-parameters` too when a
/// kinematic parameter is kept).
const MEASURED_FIGURES: &[&str] = &[
    "fig-ladder",
    "fig-ladder-rms",
    "fig-sets",
    "fig-residual-rows",
    "fig-histograms",
    "fig-markers",
    "fig-residual-joint",
    "fig-ranges",
];

/// The figures of the kuka_14 socket calibration.
const KUKA_FIGURES: &[&str] = &["fig-ladder", "fig-ladder-rms", "fig-sets", "fig-parameters"];

/// The script the check appends to a copy of each report (never part of the report): once the
/// page has loaded, it lists every `<svg>` with an empty bounding box and every element whose
/// content is wider than its box (outside the SVGs, except boxes that scroll by design), and
/// writes them with the figures' ids into the DOM for `--dump-dom`.
const CHECK_SCRIPT: &str = r#"<script>
window.addEventListener('load', function () {
  var problems = [];
  document.querySelectorAll('svg').forEach(function (s, i) {
    var r = s.getBoundingClientRect();
    if (!(r.width > 0 && r.height > 0)) {
      var f = s.closest('figure');
      problems.push('figure of zero size: ' + (f && f.id ? f.id : 'svg ' + i));
    }
  });
  document.querySelectorAll('html, body, body *').forEach(function (e) {
    if (e.closest('svg') || e.clientWidth === 0) return;
    var o = getComputedStyle(e).overflowX;
    if (o === 'auto' || o === 'scroll') return;
    if (e.scrollWidth > e.clientWidth + 1) {
      problems.push('text overflows its box: ' + e.tagName.toLowerCase() + (e.id ? '#' + e.id : '') +
        ' is ' + e.scrollWidth + ' px wide in ' + e.clientWidth + ' px');
    }
  });
  var figures = Array.prototype.map.call(document.querySelectorAll('figure'), function (f) { return f.id; });
  var pre = document.createElement('pre');
  pre.textContent = 'HTML-CHECK-BEGIN' + JSON.stringify({ problems: problems, figures: figures }) + 'HTML-CHECK-END';
  document.body.appendChild(pre);
});
</script>"#;

/// One report to check: what it is, its file, the figures it must hold.
struct Report {
    name: String,
    path: PathBuf,
    figures: &'static [&'static str],
}

/// Runs the check; `bin`: the release binary (else `cargo run --release`); `figures`: also
/// write the README's PNGs.
pub(crate) fn run(sh: &Shell, bin: Option<&Path>, figures: bool) -> Result<()> {
    let start = std::time::Instant::now();
    if std::env::var_os("HAPCAL_HTML_CHECK").is_some_and(|v| v == "skip") {
        println!(
            "html-check: skipped (HAPCAL_HTML_CHECK=skip: .ci/run found no apt-get to install \
             Chromium with)"
        );
        return Ok(());
    }
    let Some(chromium) = chromium() else {
        bail!(
            "html-check needs Chromium (the Debian package chromium) on PATH: apt-get install \
             chromium"
        );
    };
    let (hapcal, pre) = crate::hapcal_cmd(bin);
    let (hapcal, pre) = (&hapcal, pre.as_slice());
    let tmp = sh.create_temp_dir()?;
    let dir = tmp.path();
    let mut reports = Vec::new();
    let kuka = dir.join("kuka_14.html");
    cmd!(sh, "{hapcal} {pre...} calibrate --report {kuka}")
        .quiet()
        .ignore_stdout()
        .run()
        .context("calibrating kuka_14")?;
    reports.push(Report {
        name: "kuka_14 calibration".to_owned(),
        path: kuka.clone(),
        figures: KUKA_FIGURES,
    });
    for (i, (name, args)) in crate::real_data::recordings().enumerate() {
        let path = dir.join(format!("recording-{i}.html"));
        let mut args: Vec<OsString> = args.iter().map(OsString::from).collect();
        if i == 0 {
            // The first (the UR10) also writes the calibrated robot the prediction reads.
            args.extend(["--out".into(), dir.join("calibrated.urdf").into()]);
        }
        cmd!(
            sh,
            "{hapcal} {pre...} calibrate {args...} --test-last 0.3 --report {path}"
        )
        .quiet()
        .ignore_stdout()
        .run()
        .with_context(|| format!("calibrating {name}"))?;
        reports.push(Report {
            name: name.to_owned(),
            path,
            figures: MEASURED_FIGURES,
        });
    }
    // The Panda socket placements: kuka_14's figures.
    for (i, (name, args)) in crate::diagnose_real::panda_recordings().enumerate() {
        let path = dir.join(format!("panda-{i}.html"));
        cmd!(sh, "{hapcal} {pre...} calibrate {args...} --report {path}")
            .quiet()
            .ignore_stdout()
            .run()
            .with_context(|| format!("calibrating {name}"))?;
        reports.push(Report {
            name: name.to_owned(),
            path,
            figures: KUKA_FIGURES,
        });
    }
    let predict = dir.join("predict.html");
    let urdf = dir.join("calibrated.urdf");
    cmd!(
        sh,
        "{hapcal} {pre...} predict --device {urdf} --tip wrist_3_link --data fixtures/figaroh/ur10/calibration.csv --report {predict}"
    )
    .quiet()
    .ignore_stdout()
    .ignore_stderr()
    .run()
    .context("predicting the UR10")?;
    reports.push(Report {
        name: "UR10 prediction".to_owned(),
        path: predict,
        figures: &["fig-sigma"],
    });
    let diagnose = dir.join("diagnose.html");
    cmd!(
        sh,
        "{hapcal} {pre...} diagnose --device fixtures/industrial-calibration/two_axis_positioner.toml --data fixtures/industrial-calibration/measurements.yaml --report {diagnose}"
    )
    .quiet()
    .ignore_stdout()
    .ignore_stderr()
    .run()
    .context("diagnosing the two-axis positioner")?;
    reports.push(Report {
        name: "two-axis positioner diagnosis".to_owned(),
        path: diagnose,
        figures: &["fig-steps", "fig-maps"],
    });
    let mut failures = Vec::new();
    for r in &reports {
        let found = open(&chromium, r, dir)
            .with_context(|| format!("opening the report of the {} in Chromium", r.name))?;
        failures.extend(found.into_iter().map(|f| format!("{}: {f}", r.name)));
    }
    failures.extend(golden(&kuka)?);
    if figures {
        // The simulated humanoid: a compliance rung taken, joint-dependent frames-only errors.
        let humanoid = dir.join("recording-3.html");
        for (id, png) in [
            ("fig-ladder", "docs/figures/report-ladder.png"),
            (
                "fig-residual-joint",
                "docs/figures/report-residual-joint.png",
            ),
        ] {
            screenshot(&chromium, &humanoid, id, Path::new(png), dir)?;
            println!("html-check: wrote {png}");
        }
    }
    if !failures.is_empty() {
        bail!("html-check:\n  {}", failures.join("\n  "));
    }
    println!(
        "html-check: {} reports open in Chromium without error, every figure present, \
         kuka_14's figures as in {GOLDEN} ({:.1} s)",
        reports.len(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The Chromium executable on PATH, if any.
fn chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    for name in ["chromium", "chromium-browser", "google-chrome"] {
        for dir in std::env::split_paths(&path) {
            let candidate = dir.join(name);
            if candidate.is_file() {
                return Some(candidate);
            }
        }
    }
    None
}

/// Opens a copy of the report `r` with [`CHECK_SCRIPT`] appended in headless Chromium; returns
/// the problems found (console errors, figures of zero size, overflowing text, missing
/// figures).
fn open(chromium: &Path, r: &Report, dir: &Path) -> Result<Vec<String>> {
    let html = std::fs::read_to_string(&r.path)
        .with_context(|| format!("reading {}", r.path.display()))?;
    let Some(end) = html.rfind("</body>") else {
        bail!("{} has no </body>", r.path.display());
    };
    let checked = dir.join(format!(
        "{}.checked.html",
        r.path.file_stem().unwrap_or_default().to_string_lossy()
    ));
    std::fs::write(
        &checked,
        format!("{}{CHECK_SCRIPT}\n{}", &html[..end], &html[end..]),
    )?;
    let out = std::process::Command::new(chromium)
        .args([
            "--headless=new",
            "--disable-gpu",
            "--no-sandbox",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=1200,900",
            "--virtual-time-budget=5000",
            "--dump-dom",
        ])
        .arg(url(&checked))
        .output()
        .context("running chromium")?;
    let dom = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let mut problems: Vec<String> = (stderr.lines())
        .filter(|l| l.contains("CONSOLE") || l.contains("Uncaught"))
        .map(|l| format!("console: {}", l.trim()))
        .collect();
    let (Some(a), Some(b)) = (dom.rfind("HTML-CHECK-BEGIN"), dom.rfind("HTML-CHECK-END")) else {
        problems.push(format!(
            "the check script did not run (chromium exit status {})",
            out.status
        ));
        return Ok(problems);
    };
    let found: Value = serde_json::from_str(&unescape(&dom[a + "HTML-CHECK-BEGIN".len()..b]))
        .context("reading the check script's findings")?;
    for p in found["problems"].as_array().into_iter().flatten() {
        problems.push(p.as_str().unwrap_or("?").to_owned());
    }
    let ids: Vec<&str> = (found["figures"].as_array().into_iter().flatten())
        .filter_map(Value::as_str)
        .collect();
    for f in r.figures {
        if !ids.contains(f) {
            problems.push(format!("figure {f} missing"));
        }
    }
    Ok(problems)
}

/// The `file://` URL of `path` (made absolute).
fn url(path: &Path) -> String {
    let abs = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned());
    format!("file://{}", abs.display())
}

/// The text of HTML character references as a serialiser writes them.
fn unescape(text: &str) -> String {
    text.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

/// Every figure of an HTML report: its id and its `data-values` numbers.
fn figure_values(html: &str) -> Result<serde_json::Map<String, Value>> {
    let mut out = serde_json::Map::new();
    for chunk in html.split("<figure class=\"figure\" id=\"").skip(1) {
        let Some((id, rest)) = chunk.split_once('"') else {
            bail!("a figure without an id");
        };
        let Some(values) = rest
            .split_once("data-values=\"")
            .and_then(|(_, v)| v.split_once('"'))
            .map(|(v, _)| v)
        else {
            bail!("figure {id} without data-values");
        };
        let v: Value = serde_json::from_str(&unescape(values))
            .with_context(|| format!("figure {id}: data-values is not JSON"))?;
        out.insert(id.to_owned(), v);
    }
    Ok(out)
}

/// Compares the kuka_14 report's figures with the golden file, both ways; `UPDATE_GOLDEN=1`
/// rewrites the golden file (and fails, so that the change is reviewed).
fn golden(kuka: &Path) -> Result<Vec<String>> {
    let html = std::fs::read_to_string(kuka)?;
    let got = figure_values(&html)?;
    let path = crate::project_root().join(GOLDEN);
    if std::env::var_os("UPDATE_GOLDEN").is_some_and(|v| v == "1") {
        std::fs::write(&path, serde_json::to_string_pretty(&got)? + "\n")?;
        return Ok(vec![format!(
            "UPDATE_GOLDEN=1: rewrote {GOLDEN}; review and commit it"
        )]);
    }
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("reading {GOLDEN} (UPDATE_GOLDEN=1 writes it)"))?;
    let want: serde_json::Map<String, Value> =
        serde_json::from_str(&text).with_context(|| format!("parsing {GOLDEN}"))?;
    let mut out = Vec::new();
    for id in want.keys() {
        if !got.contains_key(id) {
            out.push(format!(
                "kuka_14: figure {id} of {GOLDEN} missing from the report"
            ));
        }
    }
    for (id, v) in &got {
        match want.get(id) {
            None => out.push(format!("kuka_14: figure {id} not in {GOLDEN}")),
            Some(w) => {
                if let Some(at) = differs(w, v, id) {
                    out.push(format!("kuka_14: {at} differs from {GOLDEN}"));
                }
            }
        }
    }
    Ok(out)
}

/// Where `got` differs from `want` (numbers within [`GOLDEN_RTOL`] / [`GOLDEN_ATOL`]), as a
/// path under `at`; `None` if nowhere.
fn differs(want: &Value, got: &Value, at: &str) -> Option<String> {
    match (want, got) {
        (Value::Number(a), Value::Number(b)) => {
            let (a, b) = (a.as_f64()?, b.as_f64()?);
            ((a - b).abs() > GOLDEN_RTOL * a.abs().max(b.abs()) + GOLDEN_ATOL)
                .then(|| format!("{at} ({b} instead of {a})"))
        }
        (Value::Array(a), Value::Array(b)) => {
            if a.len() != b.len() {
                return Some(format!("{at} ({} entries instead of {})", b.len(), a.len()));
            }
            (a.iter().zip(b).enumerate())
                .find_map(|(i, (x, y))| differs(x, y, &format!("{at}[{i}]")))
        }
        (Value::Object(a), Value::Object(b)) => {
            if a.len() != b.len() || a.keys().any(|k| !b.contains_key(k)) {
                return Some(format!("{at} (other keys)"));
            }
            a.iter()
                .find_map(|(k, x)| differs(x, &b[k], &format!("{at}.{k}")))
        }
        (a, b) => (a != b).then(|| format!("{at} ({b} instead of {a})")),
    }
}

/// Writes a PNG of the figure `id` of `report` to `png`: the figure alone on a page of its
/// SVG's size, screenshot by Chromium.
fn screenshot(chromium: &Path, report: &Path, id: &str, png: &Path, dir: &Path) -> Result<()> {
    let html = std::fs::read_to_string(report)?;
    let start = html
        .find(&format!("<figure class=\"figure\" id=\"{id}\""))
        .with_context(|| format!("{} has no figure {id}", report.display()))?;
    let svg_start = start
        + html[start..]
            .find("<svg")
            .context("a figure without an SVG")?;
    let svg_end = svg_start
        + html[svg_start..]
            .find("</svg>")
            .context("an unclosed SVG")?
        + 6;
    let svg = &html[svg_start..svg_end];
    let attr = |name: &str| -> Option<u32> {
        let key = format!(" {name}=\"");
        let i = svg.find(&key)? + key.len();
        svg[i..].split('"').next()?.parse().ok()
    };
    let (w, h) = (attr("width").unwrap_or(900), attr("height").unwrap_or(400));
    let page = dir.join(format!("{id}.png.html"));
    std::fs::write(
        &page,
        format!(
            "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><style>body{{margin:0;background:#fff}}</style></head><body>{svg}</body></html>"
        ),
    )?;
    let png_abs = crate::project_root().join(png);
    let status = std::process::Command::new(chromium)
        .args([
            "--headless=new",
            "--disable-gpu",
            "--no-sandbox",
            "--hide-scrollbars",
            "--default-background-color=ffffffff",
        ])
        .arg(format!("--window-size={w},{h}"))
        .arg(format!("--screenshot={}", png_abs.display()))
        .arg(url(&page))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()?;
    if !status.success() {
        bail!("chromium --screenshot of {id} failed ({status})");
    }
    Ok(())
}
