//! The `hapcal` command line: argument parsing and rendering over [`hapcal_calibrate`] (the
//! workflows) and [`hapcal_studies`] (what needs a simulated truth).
//!
//! Architecture invariant: *the library part never prints; `main.rs` prints what it returns.*

pub mod compensate;
pub mod html;
pub mod plan_args;
pub mod predict;
pub mod report;

pub use hapcal_calibrate::{calibrate, haptic, plan, project_root, support};
pub use hapcal_studies::{figures, force, paper, pose_study, reproduce};

/// Parses a whole number within `MIN..=MAX` (poses, candidates, cases, seeds, folds); clap
/// reports any other value as a usage error naming the argument. The upper bounds keep a typo
/// (an extra three zeros) from asking for more memory than a workstation has: every count is
/// bounded where its arrays are allocated. `MAX = usize::MAX`: at least `MIN` (folds).
///
/// # Errors
/// A message with the bounds and the value found.
pub fn count_in<const MIN: usize, const MAX: usize>(
    text: &str,
) -> std::result::Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (MIN..=MAX).contains(&n) => Ok(n),
        Ok(n) if MAX == usize::MAX => Err(format!("must be at least {MIN}, got {n}")),
        Ok(n) => Err(format!("must lie between {MIN} and {MAX}, got {n}")),
        Err(_) => Err(format!("expected a whole number, got {text:?}")),
    }
}

/// The σ ranges `calibrate` and `plan-poses` accept, and their check: one definition, in the
/// calibration library, so that the Rust API and the Python package refuse the same values.
pub use hapcal_calibrate::calibrate::{SIGMA_M_RANGE, SIGMA_RAD_RANGE, check_sigma};

/// `text` (a doc comment) as plain text for `--help`: rustdoc links (`` [`x`] ``) and code
/// spans (`` `x` ``) become their bare words.
pub fn plain_text(text: &str) -> String {
    text.replace("[`", "").replace("`]", "").replace('`', "")
}

/// clap's value parser for the value enum `E`, with each value's help as [`plain_text`]: for an
/// enum of another crate whose doc comments, written for rustdoc, carry links and code spans.
#[derive(Clone, Copy, Debug)]
pub struct PlainEnum<E>(std::marker::PhantomData<E>);

impl<E> Default for PlainEnum<E> {
    fn default() -> Self {
        Self(std::marker::PhantomData)
    }
}

impl<E: clap::ValueEnum + Clone + Send + Sync + 'static> clap::builder::TypedValueParser
    for PlainEnum<E>
{
    type Value = E;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> std::result::Result<E, clap::Error> {
        clap::builder::EnumValueParser::<E>::new().parse_ref(cmd, arg, value)
    }

    fn possible_values(
        &self,
    ) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        let values = (E::value_variants().iter())
            .filter_map(clap::ValueEnum::to_possible_value)
            .map(|v| match v.get_help().map(|h| plain_text(&h.to_string())) {
                Some(help) => v.help(help),
                None => v,
            });
        Some(Box::new(values))
    }
}

/// A progress bar of `len` steps drawn with the `indicatif` template `template` (the default
/// bar if the template does not parse).
pub fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

/// Runs `work` with a progress callback `(done, all)` that draws a progress bar with the
/// `indicatif` template `template` from its first call (work that never reports draws none),
/// cleared when `work` returns; on a terminal only, as [`with_spinner`].
pub fn with_bar<T>(template: &str, work: impl FnOnce(&mut dyn FnMut(usize, usize)) -> T) -> T {
    let mut bar: Option<indicatif::ProgressBar> = None;
    let out = work(&mut |done, all| {
        let bar = bar.get_or_insert_with(|| progress_bar(all as u64, template));
        bar.set_position(done as u64);
    });
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    out
}

/// Runs `work` under a spinner on standard error that says `message` and the time elapsed, for
/// a command whose length is not known beforehand (a calibration, a diagnosis, a setup check:
/// tens of seconds on a day's log); cleared when `work` returns. Drawn on a terminal only
/// (indicatif hides it when standard error is a file or a pipe), so no output changes.
pub fn with_spinner<T>(message: &str, work: impl FnOnce() -> T) -> T {
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    bar.set_message(message.to_owned());
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let out = work();
    bar.finish_and_clear();
    out
}
