//! Cross-crate safety harnesses; see SAFETY.md for the invariants they prove.
#![no_std]
#![forbid(unsafe_code)]
