//! Integration tests of the C ABI: the committed header is cbindgen's output, the C examples,
//! compiled and run, print the Rust library's numbers, and every failure is a status code
//! with a message.

mod binding;
mod c_example;
mod c_robot;
#[path = "../../../tests/it/counting.rs"]
mod counting;
mod ffi;
mod ffi_robot;
mod haptic_record;
mod header;
mod record;
