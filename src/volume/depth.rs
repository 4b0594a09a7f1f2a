//! Depth images on disk: a 16-bit greyscale PNG (for looking at, with its scale stated)
//! and a NumPy `.npy` array of 32-bit floats (for measuring).
//!
//! **PNG:** level `round(depth / units_per_level)`, `units_per_level = max / 65535` with
//! `max` the image's largest depth, so the farthest pixel is white and a pixel with no
//! depth (0) is black; [`save_depth`] returns the scale and the `view` command writes it
//! to `depth.csv`. **NPY:** format version 1.0, `'<f4'`, C order, shape
//! `(height, width)`: the depths as computed, world units (0 where none).

use std::path::Path;

use crate::error::Result;
use crate::image_io::write_atomic;

/// Largest 16-bit level.
const LEVELS: f32 = 65535.0;

/// Encodes `depth` (`width × height`, row-major, ≥ 0) as a 16-bit greyscale PNG; returns
/// the bytes and the world units per level (0 when every depth is 0).
///
/// # Panics
/// If `depth` is not `width × height` long.
pub fn encode_png16(depth: &[f32], width: u32, height: u32) -> (Vec<u8>, f32) {
    assert_eq!(depth.len(), width as usize * height as usize, "depth size");
    let max = depth
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f32, f32::max);
    let unit = if max > 0.0 { max / LEVELS } else { 0.0 };
    let mut bytes = Vec::with_capacity(2 * depth.len());
    for &d in depth {
        let level = if unit > 0.0 && d.is_finite() {
            (d / unit).round().clamp(0.0, LEVELS) as u16
        } else {
            0
        };
        bytes.extend_from_slice(&level.to_ne_bytes());
    }
    let mut buf = Vec::new();
    let enc = image::codecs::png::PngEncoder::new(&mut buf);
    image::ImageEncoder::write_image(enc, &bytes, width, height, image::ExtendedColorType::L16)
        .expect("PNG encoding into memory");
    (buf, unit)
}

/// Encodes `depth` (`width × height`, row-major) as a NumPy `.npy` file of `float32`,
/// shape `(height, width)`.
///
/// # Panics
/// If `depth` is not `width × height` long.
pub fn encode_npy(depth: &[f32], width: u32, height: u32) -> Vec<u8> {
    assert_eq!(depth.len(), width as usize * height as usize, "depth size");
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({height}, {width}), }}");
    // Magic (6) + version (2) + length (2) + header, padded with spaces to a multiple of
    // 64 bytes, ending in a newline.
    let total = (10 + header.len() + 1).div_ceil(64) * 64;
    while 10 + header.len() + 1 < total {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(total + 4 * depth.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for &d in depth {
        out.extend_from_slice(&d.to_le_bytes());
    }
    out
}

/// Writes `depth` as `<stem>.png` (16-bit) and `<stem>.npy` (float32), atomically, and
/// returns the PNG's world units per level ([`encode_png16`]).
///
/// # Errors
/// If a file cannot be written.
///
/// # Panics
/// If `depth` is not `width × height` long.
pub fn save_depth(depth: &[f32], width: u32, height: u32, stem: &Path) -> Result<f32> {
    let (png, unit) = encode_png16(depth, width, height);
    let with = |ext: &str| {
        let mut s = stem.as_os_str().to_owned();
        s.push(ext);
        std::path::PathBuf::from(s)
    };
    write_atomic(&with(".png"), &png)?;
    write_atomic(&with(".npy"), &encode_npy(depth, width, height))?;
    Ok(unit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png16_levels_and_scale() {
        let depth = [0.0, 1.0, 2.5, 5.0, 4.0, 0.001];
        let (png, unit) = encode_png16(&depth, 3, 2);
        assert!((unit - 5.0 / 65535.0).abs() < 1e-9);
        let img = image::load_from_memory(&png).unwrap().to_luma16();
        assert_eq!(img.dimensions(), (3, 2));
        let levels: Vec<u16> = img.pixels().map(|p| p.0[0]).collect();
        assert_eq!(levels[0], 0);
        assert_eq!(levels[3], 65535);
        for (l, d) in levels.iter().zip(depth) {
            assert!((*l as f32 * unit - d).abs() <= unit, "{l} vs {d}");
        }
        // All zero: black, scale 0.
        let (png, unit) = encode_png16(&[0.0; 4], 2, 2);
        assert_eq!(unit, 0.0);
        let img = image::load_from_memory(&png).unwrap().to_luma16();
        assert!(img.pixels().all(|p| p.0[0] == 0));
    }

    #[test]
    fn npy_layout() {
        let depth: Vec<f32> = (0..6).map(|v| v as f32 * 0.5).collect();
        let b = encode_npy(&depth, 3, 2);
        assert!(b.starts_with(b"\x93NUMPY\x01\x00"));
        let hlen = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        let header = std::str::from_utf8(&b[10..10 + hlen]).unwrap();
        assert!(header.contains("'descr': '<f4'") && header.contains("'shape': (2, 3)"));
        assert!(header.ends_with('\n'));
        let data = &b[10 + hlen..];
        assert_eq!(data.len(), 24);
        assert_eq!(f32::from_le_bytes(data[20..24].try_into().unwrap()), 2.5);
    }
}
