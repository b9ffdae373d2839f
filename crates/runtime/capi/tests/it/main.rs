//! Integration tests of the C ABI: the committed header is cbindgen's output, and the C
//! example, compiled and run, prints the Rust library's numbers.

mod c_example;
mod ffi;
mod haptic_record;
mod header;
