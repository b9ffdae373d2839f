//! Throwaway probe (not committed).
#![allow(missing_docs, clippy::unwrap_used, clippy::print_stdout)]
use hapcal::plan::*;
use hapcal_identify::Criterion;
use rand::SeedableRng;
fn main() {
    let root = hapcal::project_root();
    let r =
        hapcal::paper::Reference::load(&root.join("fixtures/reference-device/truth.toml")).unwrap();
    let c = hapcal_sim::SimConfig::new(4_000_000, 2000)
        .with_noise(hapcal_sim::NoiseModel::new(0.0, r.noise.sigma_m_m));
    let rows = hapcal_sim::simulate(&r.device, &r.truth, &c).unwrap();
    let t = hapcal::paper::identify_transmissions(&r, &rows).unwrap();
    for seed in 0..6u64 {
        let plan = plan_poses(
            &r.device,
            &PlanConfig {
                measurement: Measurement::Distance,
                count: 30,
                n_candidates: 2000,
                seed: seed + 2_000_000,
                criterion: Criterion::IOptimal,
                sigma_m: Some(r.noise.sigma_m_m),
                transmission_rows: false,
                refine: true,
            },
        )
        .unwrap();
        let mut out = vec![];
        for (k, noise) in [
            r.noise,
            hapcal_sim::NoiseModel::new(r.noise.sigma_e_rad, 0.0),
        ]
        .iter()
        .enumerate()
        {
            let mut rr = r.clone();
            rr.noise = *noise;
            let rows = simulate_at(&rr, &plan.readings, seed + 3_000_000).unwrap();
            let (_, kin) = hapcal::paper::identify_kinematics(&r, &rows, Some(&t)).unwrap();
            let (v, _) =
                hapcal::paper::validate(&r, seed + 1_000_000, 200, &t, &kin, &kin).unwrap();
            out.push(format!(
                "{}: {:.4} pruned {:?}",
                k,
                v.position_rms_after_m * 1e3,
                kin.identifiability.pruned_names()
            ));
        }
        // predicted
        let mut vr = rand_chacha::ChaCha8Rng::seed_from_u64(seed + 1_000_000);
        let _ = &mut vr;
        println!(
            "seed {seed} refined tr(W M^-1)^.5 = {:.4} mm | {}",
            plan.refined_value.unwrap().sqrt() * 1e3,
            out.join(" | ")
        );
    }
}
