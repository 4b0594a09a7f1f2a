//! Cross-cutting and command-line tests.

mod architecture;
mod batch;
mod cli;
mod common;
mod compare;
mod digits;
mod exactness;
mod fit;
mod fuzz;
mod glyphs;
mod gradcheck_cli;
mod gradients;
mod images;
mod layers;
mod options;
mod parity;
mod regress_cli;
mod regress_input;
mod regress_raster;
mod regress_volume;
mod roundtrip;
mod splat;
mod splat_cli;
mod text;
mod vectorize;
mod volume;
