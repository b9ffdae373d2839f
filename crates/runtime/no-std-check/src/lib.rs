//! Loads `hapcal-runtime` without its `std` feature into a `#![no_std]` library that defines
//! its own panic handler: if the runtime, or anything it depends on, linked std, the build
//! would fail with "found duplicate lang item `panic_impl`". `cargo xtask ci` builds this
//! crate; it has no other use.
#![no_std]

/// The runtime, re-exported so that the build loads it (an unused dependency is not loaded).
pub use hapcal_runtime as runtime;

/// Never reached: present only because a `no_std` crate graph has to have one.
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    loop {}
}
