//! The keyboard teleop (placeholder).
