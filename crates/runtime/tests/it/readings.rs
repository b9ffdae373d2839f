//! Deterministic joint readings over a box of joint ranges, shared with `hapcal-force`'s
//! runtime test.

/// `n` readings spread over the joint ranges `limits` (rad), deterministic (a Weyl sequence
/// per joint; no RNG needed to cover the box).
pub(crate) fn readings(limits: &[(f64, f64)], n: usize) -> Vec<Vec<f64>> {
    const PHI: [f64; 12] = [
        0.618_033_988_7,
        0.414_213_562_4,
        0.732_050_807_6,
        0.236_067_977_5,
        0.645_751_311_1,
        0.316_624_790_4,
        0.872_983_346_2,
        0.162_277_660_2,
        0.464_101_615_1,
        0.741_657_386_8,
        0.123_105_625_6,
        0.358_898_943_5,
    ];
    (0..n)
        .map(|i| {
            (limits.iter().enumerate())
                .map(|(j, &(lo, hi))| lo + (hi - lo) * ((i as f64 + 0.5) * PHI[j % 12]).fract())
                .collect()
        })
        .collect()
}
