//! The command lines of the `arm-blind` and `tree-blind` binaries: one parser of their options
//! and one runner that counts the cases done on standard error and writes the outcomes as JSON.

use anyhow::{Context, Result};
use serde::Serialize;

/// The options of a blind-test binary.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BlindArgs {
    /// `--cases N`: the cases `0..N`.
    pub cases: u64,
    /// `--rows N`: rows (configurations) per case.
    pub rows: usize,
    /// `--json FILE`: where the outcomes are written as JSON, if anywhere.
    pub json: Option<String>,
    /// `--folds K` (the arm test only): the diagnosis's cross-validation folds.
    pub folds: Option<usize>,
    /// `--setup-check` (the arm test only): the setup sweep instead of the blind test.
    pub setup_check: bool,
}

impl BlindArgs {
    /// Parses `args` (the program name left out) over the defaults `cases` and `rows`; `arm`
    /// admits the arm test's `--folds` and `--setup-check`.
    ///
    /// # Errors
    /// An option without its value, a value that is not a whole number, an unknown argument.
    pub fn parse(
        args: impl IntoIterator<Item = String>,
        cases: u64,
        rows: usize,
        arm: bool,
    ) -> Result<Self> {
        let mut out = BlindArgs {
            cases,
            rows,
            json: None,
            folds: None,
            setup_check: false,
        };
        let mut args = args.into_iter();
        while let Some(a) = args.next() {
            let mut value = || args.next().with_context(|| format!("{a} needs a value"));
            match a.as_str() {
                "--cases" => out.cases = value()?.parse().context("--cases")?,
                "--rows" => out.rows = value()?.parse().context("--rows")?,
                "--json" => out.json = Some(value()?),
                "--folds" if arm => out.folds = Some(value()?.parse().context("--folds")?),
                "--setup-check" if arm => out.setup_check = true,
                other => anyhow::bail!("unknown argument {other:?}"),
            }
        }
        Ok(out)
    }

    /// The outcomes of `run`, given a progress callback that prints the count of cases done
    /// on standard error; written to the `--json` file if one was given.
    ///
    /// # Errors
    /// `run`'s error, or the JSON file that cannot be written.
    #[allow(clippy::print_stderr)] // the progress of a command-line run
    pub fn run_cases<T: Serialize>(
        &self,
        run: impl FnOnce(&(dyn Fn(usize) + Sync)) -> Result<T>,
    ) -> Result<T> {
        let total = self.cases as usize;
        let outcomes = run(&|done| {
            eprint!("\r{done}/{total} cases");
        })?;
        eprintln!();
        if let Some(path) = &self.json {
            std::fs::write(path, serde_json::to_string_pretty(&outcomes)?)
                .with_context(|| format!("writing {path}"))?;
        }
        Ok(outcomes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str], arm: bool) -> Result<BlindArgs> {
        BlindArgs::parse(args.iter().map(|a| (*a).to_owned()), 64, 300, arm)
    }

    #[test]
    fn options_override_the_defaults_and_the_arm_options_are_the_arm_tests() -> Result<()> {
        let args = parse(&["--rows", "40", "--json", "o.json", "--folds", "5"], true)?;
        assert_eq!(
            args,
            BlindArgs {
                cases: 64,
                rows: 40,
                json: Some("o.json".to_owned()),
                folds: Some(5),
                setup_check: false,
            }
        );
        let refused = parse(&["--folds", "5"], false).map(|_| ()).unwrap_err();
        assert_eq!(refused.to_string(), "unknown argument \"--folds\"");
        let missing = parse(&["--cases"], false).map(|_| ()).unwrap_err();
        assert_eq!(missing.to_string(), "--cases needs a value");
        Ok(())
    }
}
