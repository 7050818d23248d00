//! Criterion benchmarks of encode, decode and CRC per frame (filled in below).
fn main() {}
