//! The same per-cycle evaluation as `hapcal-runtime`'s `reference_device/evaluate`, called
//! through the C ABI (`hapcal_evaluate`, by a function pointer the optimiser cannot see
//! through): pointer checks, the panic guard and the copies out.

use std::ffi::CString;
use std::hint::black_box;
use std::ptr;

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_runtime_c::{
    HapcalModel, HapcalPose, HapcalStatus, hapcal_evaluate, hapcal_model_free, hapcal_model_load,
};

const THETA: [f64; 7] = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
const WRENCH: [f64; 6] = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1];

type Evaluate = unsafe extern "C" fn(
    *const HapcalModel,
    *const f64,
    usize,
    *const f64,
    *mut HapcalPose,
    *mut f64,
    *mut f64,
) -> HapcalStatus;

fn bench(c: &mut Criterion) {
    let path = CString::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../fixtures/reference-device/calibrated.toml"
    ))
    .expect("no NUL");
    let mut model = ptr::null_mut();
    // SAFETY: a valid string and out pointer.
    let status = unsafe { hapcal_model_load(path.as_ptr(), &mut model) };
    assert_eq!(status, HapcalStatus::Ok);
    let evaluate: Evaluate = black_box(hapcal_evaluate);
    let mut pose = HapcalPose {
        rotation: [[0.0; 3]; 3],
        translation_m: [0.0; 3],
    };
    let (mut jac, mut tau) = ([0.0; 42], [0.0; 7]);
    let mut group = c.benchmark_group("c_abi");
    group.bench_function("hapcal_evaluate", |b| {
        b.iter(|| {
            let theta = black_box(&THETA);
            // SAFETY: a live model and arrays of the stated sizes.
            unsafe {
                evaluate(
                    model,
                    theta.as_ptr(),
                    7,
                    WRENCH.as_ptr(),
                    &mut pose,
                    jac.as_mut_ptr(),
                    tau.as_mut_ptr(),
                )
            }
        })
    });
    group.finish();
    // SAFETY: a live model, freed once.
    unsafe { hapcal_model_free(model) };
}

criterion_group!(benches, bench);
criterion_main!(benches);
