//! Converts a Gaussian-splatting model between PLY and SPZ (Niantic's compressed format),
//! by the extension of the output, and prints both sizes.
//!
//! ```sh
//! cargo run --release --example to_spz -- model.ply model.spz
//! cargo run --release --example to_spz -- model.spz back.ply
//! ```
//!
//! See `diffsvg::volume::splat::spz` for the layout and what the quantization keeps.

use std::path::PathBuf;

use diffsvg::volume::splat;

const USAGE: &str = "usage: to_spz IN.(ply|spz) OUT.(ply|spz)";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let [input, output] = args.as_slice() else {
        return Err(USAGE.into());
    };
    let is_spz = |p: &PathBuf| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("spz"));
    let g = if is_spz(input) {
        splat::load_spz(input)?
    } else {
        splat::load(input)?
    };
    if is_spz(output) {
        splat::save_spz(&g, output)?;
    } else {
        splat::save(&g, output)?;
    }
    let size = |p: &PathBuf| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    println!(
        "{} Gaussians (SH degree {}): {} ({} bytes) -> {} ({} bytes, {:.1}%)",
        g.len(),
        g.sh_degree,
        input.display(),
        size(input),
        output.display(),
        size(output),
        100.0 * size(output) as f64 / size(input).max(1) as f64
    );
    Ok(())
}
