//! Runs a few blind cases and prints each verdict: `cargo run --release -p hapcal-diagnose
//! --example blind_cases -- [first_seed] [count]`
//! (`KIND=two` keeps the two-effect cases, `VERBOSE=1` lists a wrong case's candidates).
#![allow(clippy::print_stdout)] // an example prints its results

use std::path::Path;

use hapcal_diagnose::blind::{BlindConfig, kind_of, run_case};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let first = args.first().copied().unwrap_or(0);
    let count = args.get(1).copied().unwrap_or(8);
    let truth_file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_file)?;
    let device = truth.read_device(&truth_file)?;
    let cfg = BlindConfig::default();
    // KIND=two (none, one, outside) runs only the cases of that kind among the seeds.
    let only = std::env::var("KIND").ok();
    for seed in first..first + count {
        if only
            .as_deref()
            .is_some_and(|k| !format!("{:?}", kind_of(seed)).eq_ignore_ascii_case(k))
        {
            continue;
        }
        let t = std::time::Instant::now();
        let (o, d) = run_case(&device, &truth, kind_of(seed), seed, &cfg)?;
        println!(
            "{seed:4} {:8} {:60} sizes {:?} -> {:30} {} gap {:.1}σ floor {:.1}µm closed {:.0}% ins {:.0}% loc {:?} ({:.1}s)",
            format!("{:?}", o.case.kind),
            o.case
                .effects
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(" "),
            o.case
                .sizes
                .iter()
                .map(|s| (s * 10.0).round() / 10.0)
                .collect::<Vec<_>>(),
            o.verdict,
            if o.correct { "OK " } else { "BAD" },
            d.gap_in_floors,
            d.floor_rms_m * 1e6,
            o.gap_closed_pct,
            d.gap_closed_in_sample_pct,
            o.localised,
            t.elapsed().as_secs_f64()
        );
        for n in &d.notes {
            println!("       note: {n}");
        }
        if !o.correct && std::env::var_os("VERBOSE").is_some() {
            for c in &d.candidates {
                println!(
                    "       r{} {:22} acc {} p {:.1e} closed {:.0}% vis {} : {}",
                    c.round,
                    c.effect,
                    c.accepted,
                    c.p_value,
                    c.gap_closed_pct,
                    c.n_visible,
                    c.reason
                );
            }
        }
    }
    Ok(())
}
