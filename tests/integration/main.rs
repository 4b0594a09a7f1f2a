//! Cross-cutting and command-line tests.

mod batch;
mod cli;
mod common;
mod digits;
mod exactness;
mod fit;
mod fuzz;
mod glyphs;
mod gradients;
mod parity;
mod regress_volume;
mod roundtrip;
mod vectorize;
mod volume;
