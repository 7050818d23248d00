//! The live view (placeholder).
