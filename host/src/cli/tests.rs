//! Tests of the frame tools.
