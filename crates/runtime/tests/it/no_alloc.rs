//! Evaluation calls allocate nothing: a counting global allocator for this test binary
//! counts the allocations of the current thread around the calls.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use hapcal_runtime::{Evaluation, Model};

use crate::fixture;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator; the counter is a const-initialised thread-local
// that never allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        // SAFETY: the caller's contract.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

#[test]
fn evaluation_calls_do_not_allocate() {
    let model = Model::load(&fixture("reference-device/calibrated.toml")).expect("fixture");
    let theta = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
    let wrench = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1];
    let (mut q, mut dq, mut tau) = ([0.0; 7], [0.0; 7], [0.0; 7]);
    let mut jac = [[0.0; 6]; 7];
    let mut out = Evaluation::default();
    let before = allocations();
    for _ in 0..100 {
        model.joint_angles(&theta, &mut q, &mut dq).expect("valid");
        model.end_pose(&theta).expect("valid");
        model.end_pose_at_joints(&q).expect("valid");
        model.body_jacobian(&theta, &mut jac).expect("valid");
        model.spatial_jacobian(&theta, &mut jac).expect("valid");
        model
            .motor_torques(&theta, &wrench, &mut tau)
            .expect("valid");
        model.evaluate(&theta, &wrench, &mut out).expect("valid");
        // The error path allocates nothing either.
        assert!(model.end_pose(&theta[..6]).is_err());
    }
    assert_eq!(allocations() - before, 0);
    // Negative control: the counter sees an allocation.
    let v = std::hint::black_box(vec![1.0; 3]);
    assert_eq!(allocations() - before, 1, "{v:?}");
}
