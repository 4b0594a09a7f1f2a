//! Converts a NeRF-synthetic or instant-ngp folder into a COLMAP dataset, the format
//! Gaussian-splatting trainers read: `DST/sparse/0/{cameras,images,points3D}.bin` (or
//! `.txt` with `--text`) and the photos copied to `DST/images/`.
//!
//! ```sh
//! cargo run --release --example to_colmap -- SRC DST [--text] [--points N] [--seed S]
//! ```
//!
//! Cameras with lens distortion become `OPENCV`, others `PINHOLE`; poses are written
//! world-to-camera with OpenCV axes. Points: SRC's point-cloud file (`points3d.ply`,
//! `sparse_pc.ply`, `points.ply`) when it has one, otherwise `N` random points (default
//! 1000) in the box the cameras look at, colored from the first photo each lands in.
//! It also writes `DST/test.txt`, SRC's test views: `diffsvg recon splat --scene DST
//! --test-list DST/test.txt` then loads the same cameras as `--scene SRC`, in SRC's split
//! and order; without `--test-list`, COLMAP's split (every 8th photo by name held out).
//! See `diffsvg::volume::colmap`.

use std::path::PathBuf;

use diffsvg::volume::colmap::{Convert, Form, convert};

const USAGE: &str = "usage: to_colmap SRC DST [--text] [--points N] [--seed S]";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut paths: Vec<PathBuf> = Vec::new();
    let mut opts = Convert::default();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut number = |name: &str| -> Result<u64, Box<dyn std::error::Error>> {
            let v = args
                .next()
                .ok_or(format!("{name} needs a value; {USAGE}"))?;
            Ok(v.parse()
                .map_err(|_| format!("{name} {v:?} is not a whole number"))?)
        };
        match a.as_str() {
            "--text" => opts.form = Form::Text,
            "--points" => opts.points = number("--points")? as usize,
            "--seed" => opts.seed = number("--seed")?,
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            _ if a.starts_with('-') => return Err(format!("unknown option {a}; {USAGE}").into()),
            _ => paths.push(a.into()),
        }
    }
    let [src, dst] = paths.as_slice() else {
        return Err(USAGE.into());
    };
    if opts.points > diffsvg::limits::MAX_GAUSSIANS {
        return Err(format!("--points is above {}", diffsvg::limits::MAX_GAUSSIANS).into());
    }
    let out = convert(src, dst, &opts)?;
    println!(
        "to_colmap: {} images, {} cameras, {} points written to {}",
        out.images,
        out.cameras,
        out.points,
        dst.join("sparse/0").display()
    );
    Ok(())
}
