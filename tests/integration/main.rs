//! Cross-cutting and command-line tests.

mod cli;
mod common;
mod exactness;
mod parity;
mod roundtrip;
