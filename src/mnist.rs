//! MNIST in the IDX format (LeCun et al.), gzip-compressed or not.
//!
//! An IDX file is a big-endian header — two zero bytes, a type byte (`0x08` = unsigned
//! byte), the number of dimensions, then one `u32` per dimension — followed by the data in
//! row-major order. Image files have three dimensions (count, rows, columns; pixel 0 is
//! background, 255 full ink), label files one (count; labels 0–9).
//!
//! ```
//! // A file of two 2 × 3 images: magic, count, rows, columns, then the pixels.
//! let mut idx = vec![0, 0, 0x08, 3, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 3];
//! idx.extend([0, 255, 0, 0, 255, 0, 9, 9, 9, 9, 9, 9]);
//! let path = std::env::temp_dir().join("diffsvg-doc.idx");
//! std::fs::write(&path, &idx)?;
//! let images = diffsvg::mnist::read_images(&path)?;
//! assert_eq!((images.len(), images.rows, images.cols), (2, 2, 3));
//! assert_eq!(images.get(0)[1], 1.0); // intensities in [0, 1]
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};
use crate::image_io::{describe_bytes, is_gzip, read_bounded};
use crate::limits::{MAX_DECOMPRESSED_BYTES, MAX_FILE_BYTES};

/// A set of equally sized grayscale images.
#[derive(Clone, Debug)]
pub struct Images {
    /// Rows of each image.
    pub rows: usize,
    /// Columns of each image.
    pub cols: usize,
    /// All pixels, image after image, row-major, 0 = background, 255 = ink.
    pub pixels: Vec<u8>,
}

impl Images {
    /// Number of images.
    pub fn len(&self) -> usize {
        self.pixels.len() / (self.rows * self.cols).max(1)
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Image `i` as intensities in `[0, 1]` (1 = ink), row-major.
    pub fn get(&self, i: usize) -> Vec<f32> {
        let n = self.rows * self.cols;
        self.pixels[i * n..(i + 1) * n]
            .iter()
            .map(|&v| v as f32 / 255.0)
            .collect()
    }
}

/// Reads an IDX image file (`*-images-idx3-ubyte`, optionally `.gz`).
pub fn read_images(path: &Path) -> Result<Images> {
    let (dims, data) = read_idx(path)?;
    if dims.len() != 3 {
        return Err(bad(
            path,
            format!(
                "expected 3 dimensions (an image file), found {}",
                dims.len()
            ),
        ));
    }
    Ok(Images {
        rows: dims[1],
        cols: dims[2],
        pixels: data,
    })
}

/// Reads an IDX label file (`*-labels-idx1-ubyte`, optionally `.gz`).
pub fn read_labels(path: &Path) -> Result<Vec<u8>> {
    let (dims, data) = read_idx(path)?;
    if dims.len() != 1 {
        return Err(bad(
            path,
            format!("expected 1 dimension (a label file), found {}", dims.len()),
        ));
    }
    Ok(data)
}

fn bad(path: &Path, message: String) -> Error {
    Error::InvalidValue {
        path: path.to_path_buf(),
        what: format!("not an IDX file: {message}"),
    }
}

/// Reads any unsigned-byte IDX file: its dimensions and its data, checked to be complete.
///
/// The file is read with a bound ([`MAX_FILE_BYTES`]); a gzip stream is decompressed only
/// after its header's counts have been checked against [`MAX_DECOMPRESSED_BYTES`], and
/// never past the size the header promises, so a small "gzip bomb" costs no memory.
fn read_idx(path: &Path) -> Result<(Vec<usize>, Vec<u8>)> {
    let raw = read_bounded(path, MAX_FILE_BYTES)?;
    if !is_gzip(&raw) {
        return parse_idx(&raw).map_err(|m| bad(path, m));
    }
    let gz = |e: std::io::Error| bad(path, format!("gzip: {e}"));
    let mut dec = flate2::read::GzDecoder::new(&raw[..]);
    let mut head = [0u8; 4];
    dec.read_exact(&mut head).map_err(gz)?;
    let nd = check_magic(&head).map_err(|m| bad(path, m))?;
    let mut header = head.to_vec();
    header.resize(4 + 4 * nd, 0);
    dec.read_exact(&mut header[4..]).map_err(gz)?;
    let (dims, n) = dims_and_size(&header, nd).map_err(|m| bad(path, m))?;
    if n as u64 > MAX_DECOMPRESSED_BYTES {
        return Err(bad(
            path,
            format!(
                "the header promises {n} bytes of data ({dims:?}), above the limit of {}",
                describe_bytes(MAX_DECOMPRESSED_BYTES)
            ),
        ));
    }
    // Read one byte more than promised, to tell a longer stream from a complete one.
    let mut body = Vec::new();
    dec.take(n as u64 + 1).read_to_end(&mut body).map_err(gz)?;
    if body.len() != n {
        return Err(bad(path, size_mismatch(n, &dims, body.len())));
    }
    Ok((dims, body))
}

/// Checks the first four header bytes; returns the number of dimensions.
fn check_magic(b: &[u8]) -> std::result::Result<usize, String> {
    if b.len() < 4 || b[0] != 0 || b[1] != 0 {
        return Err("the header does not start with two zero bytes".into());
    }
    if b[2] != 0x08 {
        return Err(format!(
            "element type 0x{:02x} (only unsigned bytes, 0x08, are read)",
            b[2]
        ));
    }
    match b[3] as usize {
        0 => Err("the header is cut short".into()),
        nd => Ok(nd),
    }
}

/// The dimensions in a complete header of `nd` dimensions, and the data size they promise.
fn dims_and_size(b: &[u8], nd: usize) -> std::result::Result<(Vec<usize>, usize), String> {
    if b.len() < 4 + 4 * nd {
        return Err("the header is cut short".into());
    }
    let dims: Vec<usize> = (0..nd)
        .map(|k| u32::from_be_bytes(b[4 + 4 * k..8 + 4 * k].try_into().unwrap()) as usize)
        .collect();
    match dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)) {
        Some(n) => Ok((dims, n)),
        None => Err(format!("dimensions {dims:?} overflow")),
    }
}

/// `found` is what was read, at most one byte past the promise when the stream is longer.
fn size_mismatch(n: usize, dims: &[usize], found: usize) -> String {
    let holds = if found > n {
        "more".to_string()
    } else {
        found.to_string()
    };
    format!("the header promises {n} bytes of data ({dims:?}), the file holds {holds}")
}

fn parse_idx(b: &[u8]) -> std::result::Result<(Vec<usize>, Vec<u8>), String> {
    let nd = check_magic(b)?;
    let (dims, n) = dims_and_size(b, nd)?;
    let body = &b[4 + 4 * nd..];
    if n != body.len() {
        return Err(size_mismatch(n, &dims, body.len()));
    }
    Ok((dims, body.to_vec()))
}

/// Parses an index list such as `0..100`, `7`, `0..10,20,30..32` (ranges half-open) into
/// indices, each checked to be below `len`.
pub fn parse_indices(s: &str, len: usize) -> std::result::Result<Vec<usize>, String> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let num = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{part}` is not an index or a range A..B"))
        };
        let (a, b) = match part.split_once("..") {
            Some((a, b)) => (num(a)?, num(b)?),
            None => {
                let a = num(part)?;
                (a, a + 1)
            }
        };
        if a >= b {
            return Err(format!("range `{part}` is empty"));
        }
        if b > len {
            return Err(format!(
                "`{part}` goes past the last index, {}",
                len.saturating_sub(1)
            ));
        }
        out.extend(a..b);
    }
    if out.is_empty() {
        return Err("no indices given".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn idx(dims: &[u32], data: &[u8]) -> Vec<u8> {
        let mut b = vec![0, 0, 8, dims.len() as u8];
        for d in dims {
            b.extend_from_slice(&d.to_be_bytes());
        }
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn reads_plain_and_gzip() {
        let dir = std::env::temp_dir().join(format!("diffsvg-mnist-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bytes = idx(&[2, 2, 3], &[0, 255, 0, 0, 0, 0, 1, 2, 3, 4, 5, 6]);
        let plain = dir.join("i.idx");
        std::fs::write(&plain, &bytes).unwrap();
        let gz = dir.join("i.idx.gz");
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut enc, &bytes).unwrap();
        std::fs::write(&gz, enc.finish().unwrap()).unwrap();
        for p in [&plain, &gz] {
            let im = read_images(p).unwrap();
            assert_eq!((im.len(), im.rows, im.cols), (2, 2, 3));
            assert_eq!(im.get(0)[1], 1.0);
            assert_eq!(im.pixels[11], 6);
        }
        let err = read_labels(&plain).unwrap_err().to_string();
        assert!(
            err.contains("i.idx") && err.contains("1 dimension"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn rejects_short_or_foreign_files() {
        assert!(
            parse_idx(&idx(&[3], &[1, 2]))
                .unwrap_err()
                .contains("promises 3")
        );
        assert!(parse_idx(b"\x89PNG").is_err());
        assert!(
            parse_idx(&[0, 0, 0x0d, 1, 0, 0, 0, 0])
                .unwrap_err()
                .contains("0x0d")
        );
        assert!(
            parse_idx(&[0, 0, 8, 2, 0, 0])
                .unwrap_err()
                .contains("cut short")
        );
    }

    /// A 1.5 MB gzip stream whose header promises 60000 images of 28×28 ... and then
    /// 1.6 GB of zeros used to be inflated whole before the header was checked. Now the
    /// promise is checked against the limit first, and a stream longer than its promise
    /// is refused without inflating the rest.
    #[test]
    fn idx_gzip_bomb_is_refused_before_inflating() {
        let dir = std::env::temp_dir().join(format!("diffsvg-bomb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let gzip = |header: &[u8], zeros: usize| {
            let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
            std::io::Write::write_all(&mut enc, header).unwrap();
            let chunk = vec![0u8; 1 << 20];
            for _ in 0..zeros >> 20 {
                std::io::Write::write_all(&mut enc, &chunk).unwrap();
            }
            enc.finish().unwrap()
        };
        // A header promising 20 GB (200000 images of 300 × 333).
        let big = dir.join("big.gz");
        std::fs::write(&big, gzip(&idx(&[200_000, 300, 333], &[]), 1 << 20)).unwrap();
        let e = read_images(&big).unwrap_err().to_string();
        assert!(e.contains("big.gz") && e.contains("limit"), "{e}");
        // A small promise followed by far more data: refused, reading only one byte past.
        let long = dir.join("long.gz");
        std::fs::write(&long, gzip(&idx(&[2, 2, 2], &[0; 8]), 64 << 20)).unwrap();
        let e = read_images(&long).unwrap_err().to_string();
        assert!(
            e.contains("promises 8 bytes") && e.contains("holds more"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn index_lists() {
        assert_eq!(parse_indices("0..3,7", 10).unwrap(), vec![0, 1, 2, 7]);
        assert!(parse_indices("5..5", 10).is_err());
        assert!(
            parse_indices("8..11", 10)
                .unwrap_err()
                .contains("last index, 9")
        );
        assert!(parse_indices("x", 10).is_err());
        assert!(parse_indices("", 10).is_err());
    }
}
