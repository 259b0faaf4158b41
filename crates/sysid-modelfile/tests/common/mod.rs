//! Helpers shared by the model-file tests.

pub mod ar1;
