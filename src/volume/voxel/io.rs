//! Saving and loading grids.
//!
//! **Format, version 1.** Little-endian throughout; `K = (degree + 1)²`, `n = count`:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `DSVOXGRD` (ASCII) |
//! | 8 | 4 | `u32` version = 1 |
//! | 12 | 12 | box minimum corner, 3 × `f32`, world units |
//! | 24 | 12 | box maximum corner, 3 × `f32` |
//! | 36 | 4 | `u32` res: cells per axis (vertices per axis `res + 1`), 1 ..= 1024 |
//! | 40 | 4 | `u32` SH degree, 0 ..= 3 |
//! | 44 | 8 | `u64` count `n` of allocated vertices |
//! | 52 | 4·n | `u32` linear vertex indices `x + (res+1)·(y + (res+1)·z)`, strictly increasing |
//! | 52 + 4n | 4·n | `f32` raw density per vertex (before the ReLU), 1 / world units |
//! | 52 + 8n | 12·K·n | `f32` SH coefficients per vertex: K red, K green, K blue |
//!
//! The file is exactly `52 + 8n + 12Kn` bytes. Loading checks the magic, the version, the
//! header values, the exact size, the index order and range, and that every number is
//! finite; each failure is an error naming the file and the problem.

use std::path::Path;

use glam::Vec3;

use super::grid::{Grid, check_geometry};
use crate::error::{Error, Result};
use crate::image_io::write_atomic;
use crate::volume::sh;

/// The first 8 bytes of a grid file.
pub(crate) const MAGIC: [u8; 8] = *b"DSVOXGRD";
/// The format version written by [`save`] and the only one [`load`] reads.
pub(crate) const VERSION: u32 = 1;
const HEADER: usize = 52;

/// The file image of `grid` (see the module doc).
pub(crate) fn to_bytes(grid: &Grid) -> Vec<u8> {
    let n = grid.allocated();
    let mut b = Vec::with_capacity(HEADER + 8 * n + 4 * grid.sh().len());
    b.extend_from_slice(&MAGIC);
    b.extend_from_slice(&VERSION.to_le_bytes());
    for v in [grid.min(), grid.max()] {
        for c in v.to_array() {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    b.extend_from_slice(&grid.res().to_le_bytes());
    b.extend_from_slice(&grid.degree().to_le_bytes());
    b.extend_from_slice(&(n as u64).to_le_bytes());
    for v in grid.vertex_indices() {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in grid.density().iter().chain(grid.sh()) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

/// Writes `grid` to `path` atomically (a temporary file renamed into place, parent folders
/// created), so a failure never leaves a partial file.
pub fn save(grid: &Grid, path: impl AsRef<Path>) -> Result<()> {
    write_atomic(path.as_ref(), &to_bytes(grid))
}

/// Reads a grid written by [`save`].
pub fn load(path: impl AsRef<Path>) -> Result<Grid> {
    let path = path.as_ref();
    let bytes = crate::image_io::read_bounded(path, crate::limits::MAX_MODEL_BYTES)?;
    from_bytes(&bytes, path)
}

/// Parses a file image; `path` only names the input in errors.
pub(crate) fn from_bytes(b: &[u8], path: &Path) -> Result<Grid> {
    let bad = |what: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    };
    if b.len() < 12 || b[..8] != MAGIC {
        return Err(bad(
            "not a diffsvg voxel grid (missing DSVOXGRD magic)".into()
        ));
    }
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
    let f32_at = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"));
    let version = u32_at(8);
    if version != VERSION {
        return Err(bad(format!(
            "voxel grid format version {version}; this build reads version {VERSION}"
        )));
    }
    if b.len() < HEADER {
        return Err(bad(format!(
            "truncated header: {} bytes, need {HEADER}",
            b.len()
        )));
    }
    let min = Vec3::new(f32_at(12), f32_at(16), f32_at(20));
    let max = Vec3::new(f32_at(24), f32_at(28), f32_at(32));
    let (res, degree) = (u32_at(36), u32_at(40));
    let count = u64::from_le_bytes(b[44..52].try_into().expect("8 bytes"));
    check_geometry(min, max, res, degree).map_err(bad)?;
    let vertices_total = (res as u64 + 1).pow(3);
    if count > vertices_total {
        return Err(bad(format!(
            "{count} allocated vertices but the grid has only {vertices_total}"
        )));
    }
    let n = count as usize;
    let k = sh::coeff_count(degree);
    let want = HEADER as u64 + count * (8 + 12 * k as u64);
    if b.len() as u64 != want {
        return Err(bad(format!(
            "size {} bytes, expected {want} for {count} vertices of degree {degree}",
            b.len()
        )));
    }
    let words = |start: usize, len: usize| (0..len).map(move |i| start + 4 * i);
    let vertices: Vec<u32> = words(HEADER, n).map(u32_at).collect();
    if let Some(i) = (1..n).find(|&i| vertices[i] <= vertices[i - 1]) {
        return Err(bad(format!(
            "vertex indices not strictly increasing at entry {i} ({} after {})",
            vertices[i],
            vertices[i - 1]
        )));
    }
    if let Some(&last) = vertices.last().filter(|&&v| v as u64 >= vertices_total) {
        return Err(bad(format!(
            "vertex index {last} outside the {vertices_total} vertices of a {res}³ grid"
        )));
    }
    let density: Vec<f32> = words(HEADER + 4 * n, n).map(f32_at).collect();
    let shv: Vec<f32> = words(HEADER + 8 * n, 3 * k * n).map(f32_at).collect();
    if let Some(i) = density.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!("density of entry {i} is {}", density[i])));
    }
    if let Some(i) = shv.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!(
            "SH coefficient {} of entry {} is {}",
            i % (3 * k),
            i / (3 * k),
            shv[i]
        )));
    }
    Ok(Grid::assemble(
        min, max, res, degree, vertices, density, shv,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Grid {
        let mut g = Grid::from_fn(
            Vec3::new(-1.0, -2.0, 0.0),
            Vec3::new(1.0, 0.5, 3.0),
            6,
            2,
            |p| (p.length() < 1.8).then_some(p.x - 0.25 * p.z),
        );
        for (i, v) in g.sh_mut().iter_mut().enumerate() {
            *v = (i as f32 * 0.37).sin();
        }
        g
    }

    #[test]
    fn round_trip() {
        let g = sample();
        let dir = std::env::temp_dir().join(format!("diffsvg-voxel-io-{}", std::process::id()));
        let path = dir.join("grid.dsvox");
        save(&g, &path).unwrap();
        let h = load(&path).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(
            (h.min(), h.max(), h.res(), h.degree()),
            (g.min(), g.max(), 6, 2)
        );
        assert_eq!(h.vertex_indices(), g.vertex_indices());
        assert_eq!(h.density(), g.density());
        assert_eq!(h.sh(), g.sh());
        assert_eq!(to_bytes(&h), to_bytes(&g));
    }

    #[test]
    fn rejects_bad_files_with_reasons() {
        let p = Path::new("bad.dsvox");
        let good = to_bytes(&sample());
        let err = |b: &[u8]| from_bytes(b, p).unwrap_err().to_string();
        assert!(err(b"PNG").contains("magic"));
        let mut v = good.clone();
        v[8] = 9;
        assert!(err(&v).contains("version 9"), "{}", err(&v));
        let mut v = good.clone();
        v[36..40].copy_from_slice(&0u32.to_le_bytes());
        assert!(err(&v).contains("resolution 0"), "{}", err(&v));
        // A header claiming 1024 cells per axis would make the dense index 4.3 GB.
        let mut v = good.clone();
        v[36..40].copy_from_slice(&1024u32.to_le_bytes());
        assert!(err(&v).contains("resolution 1024"), "{}", err(&v));
        let mut v = good.clone();
        v[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(err(&v).contains("box"), "{}", err(&v));
        assert!(err(&good[..good.len() - 4]).contains("size"));
        let mut v = good.clone();
        v[HEADER..HEADER + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(err(&v).contains("increasing"), "{}", err(&v));
        let mut v = good.clone();
        let last = v.len() - 4;
        v[last..].copy_from_slice(&f32::INFINITY.to_le_bytes());
        assert!(err(&v).contains("SH coefficient"), "{}", err(&v));
        assert!(
            err(&v).starts_with("bad.dsvox: "),
            "names the file: {}",
            err(&v)
        );
        let missing = load("/nonexistent/dir/grid.dsvox").unwrap_err().to_string();
        assert!(
            missing.starts_with("/nonexistent/dir/grid.dsvox"),
            "{missing}"
        );
    }
}
