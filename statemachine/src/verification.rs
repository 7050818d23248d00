//! Kani harnesses of the ladder invariants and their `cargo test` twins.
