//! Saving and loading [`Gaussians`] as SPZ files, Niantic's compressed format for
//! Gaussian splats (<https://github.com/nianticlabs/spz>), about a tenth of the PLY's size.
//!
//! **Layout** (version 3, the gzip form that every SPZ reader reads; version 4 readers
//! read it too): a gzip stream of a 16-byte header and then, attribute by attribute for
//! all `N` Gaussians:
//!
//! ```text
//! header      magic u32 0x5053474e ("NGSP"), version u32 (3), N u32, SH degree u8,
//!             fractional bits u8 (f), flags u8 (0x1: antialiased), reserved u8 (0)
//! positions   N × 3 × 3 bytes: x, y, z as 24-bit signed little-endian fixed point,
//!             value = integer / 2^f (world units)
//! alphas      N bytes: round(255 · sigmoid(logit opacity))
//! colors      N × 3 bytes: round(f_dc · 0.15 · 255 + 127.5), the SH constant term
//! scales      N × 3 bytes: round((log scale + 10) · 16)
//! rotations   N × 4 bytes: the unit quaternion (x, y, z, w) as its "smallest three":
//!             2 bits for the index of the largest component (made positive), then per
//!             other component a sign bit and 9 bits of |q| / √½
//! sh          N × 3·((d + 1)² − 1) bytes: higher SH terms, coefficient-major with the
//!             channel inside (r, g, b of coefficient 1, then of 2, …), each
//!             round(x · 128 + 128) rounded to the center of buckets of 4 levels
//!             (degree 1) or 8 (higher): 6 and 5 bits of precision
//! ```
//!
//! The SH buckets are half the reference writer's default (5 and 4 bits): on lego at
//! 200² the reference's cost 0.33 dB of test PSNR against the PLY for a file 7.2% of its
//! size, these 0.07 dB for 8.7% (`docs/3d.md`, "Compressed models"). A reader needs
//! nothing to know them: the bytes are ordinary SPZ values. Every byte is clamped to
//! `[0, 255]`. World axes are written as they are (the
//! reference `ply_to_spz` converts nothing by default either). The reader takes versions
//! 2 (three-byte rotations `x, y, z` with `w ≥ 0`) and 3, SH degree 0 to 3; alphas of 0
//! and 255 read as 0.5/255 and 254.5/255 so that the logit stays finite. Reading is
//! bounded: the file must fit [`MAX_SPLAT_BYTES`], it inflates to at most the size of
//! [`MAX_GAUSSIANS`] Gaussians of degree 3, the count is checked against the inflated
//! size before anything is allocated, and each failure is one error naming the file.
//!
//! What the quantization costs is measured in `docs/3d.md` ("Compressed models").
//!
//! [`MAX_SPLAT_BYTES`]: crate::limits::MAX_SPLAT_BYTES
//! [`MAX_GAUSSIANS`]: crate::limits::MAX_GAUSSIANS

use std::io::Write as _;
use std::path::Path;

use super::Gaussians;
use crate::error::{Error, Result};
use crate::image_io::{gunzip_bounded, is_gzip, read_bounded, write_atomic};
use crate::limits::{MAX_GAUSSIANS, MAX_SPLAT_BYTES};
use crate::volume::sh;

/// "NGSP", little-endian.
const MAGIC: u32 = 0x5053_474e;
/// Version written.
const VERSION: u32 = 3;
/// Header bytes.
const HEADER: usize = 16;
/// Flag bit of an antialiased model.
const ANTIALIASED: u8 = 0x1;
/// Scale of the SH constant term in the color bytes.
const COLOR_SCALE: f32 = 0.15;
/// SH buckets, in levels of 1/128: degree 1, and degrees 2 and 3 (module doc).
const SH1_BUCKET: i32 = 4;
const SH_REST_BUCKET: i32 = 8;
/// Fractional bits of positions, as the reference writes them (about 0.24 mm if the
/// units are meters), fewer for scenes larger than ±2048 units.
const FRACTIONAL_BITS: u8 = 12;

/// Bytes per Gaussian after the header: positions, alpha, color, scales, rotation and
/// `rest` higher SH terms.
fn per_point(rotation_bytes: usize, rest: usize) -> usize {
    9 + 1 + 3 + 3 + rotation_bytes + rest
}

fn to_u8(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// SH quantization to 8 bits, then to the center of a bucket of `bucket` levels (0 is
/// always a bucket center), as the reference does.
fn quantize_sh(x: f32, bucket: i32) -> u8 {
    let q = (x * 128.0).round() as i32 + 128;
    let q = (q + bucket / 2) / bucket * bucket;
    q.clamp(0, 255) as u8
}

/// The smallest-three encoding of quaternion `[w, x, y, z]` (module doc).
fn pack_rotation(q: [f32; 4]) -> [u8; 4] {
    let [w, x, y, z] = q;
    let len = (w * w + x * x + y * y + z * z).sqrt();
    let q = [x / len, y / len, z / len, w / len];
    let largest = (1..4).fold(0, |b, i| if q[i].abs() > q[b].abs() { i } else { b });
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (i, &v) in q.iter().enumerate() {
        if i != largest {
            let neg = ((v < 0.0) ^ negate) as u32;
            let mag = (511.0 * (v.abs() / std::f32::consts::FRAC_1_SQRT_2) + 0.5) as u32;
            comp = (comp << 10) | (neg << 9) | mag.min(511);
        }
    }
    comp.to_le_bytes()
}

/// The inverse of [`pack_rotation`], as `[w, x, y, z]`.
fn unpack_rotation(r: [u8; 4]) -> [f32; 4] {
    let mut comp = u32::from_le_bytes(r);
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i != largest {
            let mag = comp & 511;
            let neg = (comp >> 9) & 1;
            comp >>= 10;
            let v = std::f32::consts::FRAC_1_SQRT_2 * mag as f32 / 511.0;
            q[i] = if neg == 1 { -v } else { v };
            sum += v * v;
        }
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    [q[3], q[0], q[1], q[2]]
}

/// The uncompressed SPZ image of `g` (header and attributes, before gzip). `g` must be
/// valid.
///
/// # Errors
/// If a position is beyond ±2²³ units (no fixed point fits it).
pub(crate) fn to_raw(g: &Gaussians) -> std::result::Result<Vec<u8>, String> {
    let n = g.len();
    let k = g.coeffs_per_channel();
    let rest = 3 * (k - 1);
    let largest = g.means.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
    // The most fractional bits (at most the reference's 12) that fit ±largest in 24 bits.
    let mut bits = FRACTIONAL_BITS;
    while bits > 0 && largest * (1u32 << bits) as f32 >= 8_388_607.0 {
        bits -= 1;
    }
    if largest >= 8_388_607.0 {
        return Err(format!(
            "a position of {largest} units does not fit SPZ's 24-bit fixed point"
        ));
    }
    let mut b = Vec::with_capacity(HEADER + n * per_point(4, rest));
    b.extend_from_slice(&MAGIC.to_le_bytes());
    b.extend_from_slice(&VERSION.to_le_bytes());
    b.extend_from_slice(&(n as u32).to_le_bytes());
    let flags = if g.antialiased { ANTIALIASED } else { 0 };
    b.extend_from_slice(&[g.sh_degree as u8, bits, flags, 0]);
    let unit = (1u32 << bits) as f32;
    for m in &g.means {
        for v in m {
            let fixed = (v * unit).round() as i32;
            b.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    for i in 0..n {
        b.push(to_u8(g.opacity(i) * 255.0));
    }
    for i in 0..n {
        for c in 0..3 {
            let dc = g.sh[i * 3 * k + c * k];
            b.push(to_u8(dc * (COLOR_SCALE * 255.0) + 0.5 * 255.0));
        }
    }
    for ls in &g.log_scales {
        for v in ls {
            b.push(to_u8((v + 10.0) * 16.0));
        }
    }
    for q in &g.rotations {
        b.extend_from_slice(&pack_rotation(*q));
    }
    for i in 0..n {
        let coeffs = &g.sh[i * 3 * k..(i + 1) * 3 * k];
        for j in 1..k {
            let bucket = if j < 4 { SH1_BUCKET } else { SH_REST_BUCKET };
            for c in 0..3 {
                b.push(quantize_sh(coeffs[c * k + j], bucket));
            }
        }
    }
    Ok(b)
}

/// Writes `g` as an SPZ file (module doc), atomically. An invalid model
/// ([`Gaussians::validate`]) is refused.
///
/// # Errors
/// An invalid model, a position beyond the fixed point's range, or the write's failure.
pub fn save_spz(g: &Gaussians, path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    let bad = |what: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    };
    g.validate().map_err(bad)?;
    let raw = to_raw(g).map_err(bad)?;
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(&raw)
        .and_then(|_| enc.try_finish())
        .map_err(|e| Error::io(path, e))?;
    let gz = enc.finish().map_err(|e| Error::io(path, e))?;
    write_atomic(path, &gz)
}

/// Reads an SPZ file (module doc): one written by [`save_spz`] or by Niantic's library
/// (versions 2 and 3).
///
/// # Errors
/// The file cannot be read, is not a gzip stream, inflates past the bound, or its header
/// or size is wrong; each as one error naming the file.
pub fn load_spz(path: impl AsRef<Path>) -> Result<Gaussians> {
    let path = path.as_ref();
    let bytes = read_bounded(path, MAX_SPLAT_BYTES)?;
    from_bytes(&bytes, path)
}

/// The most bytes an SPZ stream may inflate to: [`MAX_GAUSSIANS`] of degree 3.
fn inflate_limit() -> u64 {
    HEADER as u64 + MAX_GAUSSIANS as u64 * per_point(4, 45) as u64
}

/// Parses a compressed SPZ file image; `path` names the input in errors.
pub(crate) fn from_bytes(bytes: &[u8], path: &Path) -> Result<Gaussians> {
    let bad = |what: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    };
    if !is_gzip(bytes) {
        if bytes.starts_with(&MAGIC.to_le_bytes()) {
            return Err(bad(
                "SPZ version 4 (ZSTD streams) is not read; write version 3 (gzip) with \
                 Niantic's tools, or save a PLY"
                    .into(),
            ));
        }
        return Err(bad("not an SPZ file (not a gzip stream)".into()));
    }
    let raw = gunzip_bounded(bytes, inflate_limit(), path)?;
    from_raw(&raw).map_err(bad)
}

/// Parses an uncompressed SPZ image (header and attributes).
pub(crate) fn from_raw(raw: &[u8]) -> std::result::Result<Gaussians, String> {
    if raw.len() < HEADER {
        return Err(format!(
            "{} bytes after decompression: shorter than the 16-byte SPZ header",
            raw.len()
        ));
    }
    let word = |at: usize| u32::from_le_bytes(raw[at..at + 4].try_into().expect("4 bytes"));
    if word(0) != MAGIC {
        return Err(format!(
            "SPZ magic is {:#010x}, expected {MAGIC:#010x} (\"NGSP\")",
            word(0)
        ));
    }
    let version = word(4);
    if !(2..=3).contains(&version) {
        return Err(format!("SPZ version {version}: versions 2 and 3 are read"));
    }
    let n = word(8) as u64;
    let (degree, bits, flags) = (raw[12] as u32, raw[13], raw[14]);
    if degree > sh::MAX_DEGREE {
        return Err(format!("SPZ SH degree {degree}: at most 3 is read"));
    }
    if bits > 24 {
        return Err(format!("SPZ fractional bits {bits}: at most 24"));
    }
    if n > MAX_GAUSSIANS as u64 {
        return Err(format!(
            "{n} Gaussians in the SPZ header, above the limit of {MAX_GAUSSIANS}"
        ));
    }
    let k = sh::coeff_count(degree);
    let rest = 3 * (k - 1);
    let rot_bytes = if version >= 3 { 4 } else { 3 };
    let want = HEADER as u64 + n * per_point(rot_bytes, rest) as u64;
    let have = raw.len() as u64;
    // Extensions (flag 0x2) may follow the attributes; otherwise the size is exact.
    if have < want || (have > want && flags & 0x2 == 0) {
        return Err(format!(
            "{have} bytes after decompression, expected {want} for {n} Gaussians of SH degree \
             {degree} ({})",
            if have < want {
                "truncated"
            } else {
                "trailing bytes"
            }
        ));
    }
    let n = n as usize;
    let mut at = HEADER;
    let mut take = |len: usize| {
        let s = &raw[at..at + len];
        at += len;
        s
    };
    let positions = take(9 * n);
    let alphas = take(n);
    let colors = take(3 * n);
    let scales = take(3 * n);
    let rotations = take(rot_bytes * n);
    let shs = take(rest * n);
    let mut g = Gaussians::new(degree);
    g.antialiased = flags & ANTIALIASED != 0;
    let unit = 1.0 / (1u64 << bits) as f32;
    let mut coeffs = vec![0.0f32; 3 * k];
    for i in 0..n {
        let p = &positions[9 * i..9 * i + 9];
        let mean = std::array::from_fn(|c| {
            let b = &p[3 * c..3 * c + 3];
            // Sign-extend 24 bits.
            let v = i32::from_le_bytes([b[0], b[1], b[2], 0]) << 8 >> 8;
            v as f32 * unit
        });
        let a = (alphas[i] as f32).clamp(0.5, 254.5) / 255.0;
        let scale = std::array::from_fn(|c| scales[3 * i + c] as f32 / 16.0 - 10.0);
        let rot = if rot_bytes == 4 {
            unpack_rotation(rotations[4 * i..4 * i + 4].try_into().expect("4 bytes"))
        } else {
            let r = &rotations[3 * i..3 * i + 3];
            let [x, y, z] = [0, 1, 2].map(|c| r[c] as f32 / 127.5 - 1.0);
            [(1.0 - x * x - y * y - z * z).max(0.0).sqrt(), x, y, z]
        };
        let rot = if rot.iter().all(|&v| v == 0.0) {
            [1.0, 0.0, 0.0, 0.0]
        } else {
            rot
        };
        for c in 0..3 {
            coeffs[c * k] = (colors[3 * i + c] as f32 / 255.0 - 0.5) / COLOR_SCALE;
            for j in 1..k {
                coeffs[c * k + j] = (shs[rest * i + 3 * (j - 1) + c] as f32 - 128.0) / 128.0;
            }
        }
        g.push(mean, scale, rot, (a / (1.0 - a)).ln(), &coeffs);
    }
    Ok(g)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reproducible model of degree `degree` with values in SPZ's ranges.
    fn sample(degree: u32, n: usize) -> Gaussians {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut g = Gaussians::new(degree);
        let k3 = 3 * g.coeffs_per_channel();
        for _ in 0..n {
            let mean = [0.0; 3].map(|_: f32| (next() - 0.5) * 8.0);
            let ls = [0.0; 3].map(|_: f32| -6.0 + 5.0 * next());
            let rot = [next() - 0.5, next() - 0.5, next() - 0.5, next() - 0.5];
            let sh: Vec<f32> = (0..k3).map(|_| (next() - 0.5) * 1.2).collect();
            g.push(mean, ls, rot, (next() - 0.5) * 8.0, &sh);
        }
        g
    }

    fn temp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("diffsvg-spz-{}-{name}", std::process::id()))
    }

    /// Saved and loaded, every value is within its quantization step of the original.
    #[test]
    fn round_trip_within_the_quantization() {
        for degree in 0..=3 {
            let mut g = sample(degree, 200);
            g.antialiased = degree == 2;
            let path = temp(&format!("d{degree}.spz"));
            save_spz(&g, &path).unwrap();
            let h = load_spz(&path).unwrap();
            std::fs::remove_file(&path).ok();
            assert_eq!(
                (h.len(), h.sh_degree, h.antialiased),
                (200, degree, degree == 2)
            );
            let k = g.coeffs_per_channel();
            for i in 0..200 {
                for c in 0..3 {
                    assert!((h.means[i][c] - g.means[i][c]).abs() <= 0.5 / 4096.0 + 1e-6);
                    assert!((h.log_scales[i][c] - g.log_scales[i][c]).abs() <= 1.0 / 32.0 + 1e-5);
                    let dc = (h.sh[i * 3 * k + c * k] - g.sh[i * 3 * k + c * k]).abs();
                    assert!(dc <= 0.5 / (COLOR_SCALE * 255.0) + 1e-5, "DC off by {dc}");
                    for j in 1..k {
                        // Half a level of 8 bits, then half a bucket (4 or 8 levels).
                        let bucket = if j < 4 { SH1_BUCKET } else { SH_REST_BUCKET } as f32;
                        let e = (h.sh[i * 3 * k + c * k + j] - g.sh[i * 3 * k + c * k + j]).abs();
                        assert!(
                            e <= (0.5 + 0.5 * bucket) / 128.0 + 1e-5,
                            "SH {j} off by {e}"
                        );
                    }
                }
                assert!((h.opacity(i) - g.opacity(i)).abs() <= 0.5 / 255.0 + 1e-6);
                // The same rotation: |⟨q, q'⟩| near 1 (q and −q are the same rotation).
                let dot = h.rotation(i).dot(g.rotation(i)).abs();
                assert!(dot > 0.9995, "rotation {i}: {dot}");
            }
        }
    }

    #[test]
    fn the_file_is_small_and_gzip() {
        let g = sample(3, 2000);
        let path = temp("size.spz");
        save_spz(&g, &path).unwrap();
        let spz = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert!(is_gzip(&spz));
        let ply = super::super::ply::to_bytes(&g).len();
        // Random values compress poorly; still at most a quarter of the PLY.
        assert!(spz.len() * 4 < ply, "{} vs {ply}", spz.len());
    }

    /// Reads what Niantic's version-2 writer makes (three-byte rotations).
    #[test]
    fn version_2_rotations_are_read() {
        let mut raw = Vec::new();
        raw.extend_from_slice(&MAGIC.to_le_bytes());
        raw.extend_from_slice(&2u32.to_le_bytes());
        raw.extend_from_slice(&1u32.to_le_bytes());
        raw.extend_from_slice(&[0, 12, 0, 0]);
        raw.extend_from_slice(&[0, 16, 0, 0, 0, 0, 0xf0, 0xff, 0xff]); // x = 1, y = 0, z = −1/256
        raw.push(255); // alpha
        raw.extend_from_slice(&[128, 128, 128]);
        raw.extend_from_slice(&[160, 160, 160]); // log scale 0
        // Rotation (x, y, z) = (0, 0, 0) → identity.
        raw.extend_from_slice(&[128, 128, 128]);
        let g = from_raw(&raw).unwrap();
        assert_eq!(g.means[0], [1.0, 0.0, -1.0 / 256.0]);
        assert_eq!(g.log_scales[0], [0.0; 3]);
        assert!(g.opacity(0) > 0.99 && g.logit_opacities[0].is_finite());
        let q = g.rotation(0);
        assert!((q.w - 1.0).abs() < 1e-4, "{q}");
    }

    #[test]
    fn bad_files_are_one_line_errors() {
        let g = sample(1, 3);
        let raw = to_raw(&g).unwrap();
        let err = |raw: &[u8]| from_raw(raw).unwrap_err();
        assert!(err(&raw[..10]).contains("shorter than the 16-byte"));
        assert!(err(&raw[..raw.len() - 1]).contains("truncated"));
        let mut more = raw.clone();
        more.push(0);
        assert!(err(&more).contains("trailing bytes"));
        let mut bad = raw.clone();
        bad[0] = b'X';
        assert!(err(&bad).contains("magic"));
        let mut bad = raw.clone();
        bad[4] = 9;
        assert!(err(&bad).contains("version 9"));
        let mut bad = raw.clone();
        bad[12] = 4;
        assert!(err(&bad).contains("SH degree 4"));
        // A count far beyond the data is refused before anything is allocated.
        let mut bad = raw.clone();
        bad[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(err(&bad).contains("above the limit"));
        let mut bad = raw.clone();
        bad[8..12].copy_from_slice(&1000u32.to_le_bytes());
        assert!(err(&bad).contains("truncated"));
        // Not gzip, a version-4 file, and a gzip bomb's bound, naming the file.
        let p = Path::new("m.spz");
        let e = from_bytes(b"hello", p).unwrap_err().to_string();
        assert!(e.contains("m.spz") && e.contains("not an SPZ file"), "{e}");
        let e = from_bytes(&raw, p).unwrap_err().to_string();
        assert!(e.contains("version 4"), "{e}");
        let e = from_bytes(&[0x1f, 0x8b, 1, 2, 3], p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.spz") && !e.contains('\n'), "{e}");
        assert!(load_spz(temp("missing.spz")).is_err());
    }
}
