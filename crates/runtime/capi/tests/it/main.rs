//! Integration tests of the C ABI.
