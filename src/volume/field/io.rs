//! Saving and loading neural fields.
//!
//! **Format, version 1.** Little-endian throughout.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `DSNGPFLD` (ASCII) |
//! | 8 | 4 | `u32` version = 1 |
//! | 12 | 12 | box minimum corner, 3 × `f32`, world units |
//! | 24 | 12 | box maximum corner, 3 × `f32` |
//! | 36 | 36 | 9 × `u32`: levels, log2 table size, N_min, N_max, width, density layers, color layers, geometry features, occupancy resolution ([`NgpShape`]) |
//! | 72 | … | hash features, `f32`: per level, its used entries (`min((N_l+1)³, T)`) × 2 |
//! | … | … | density network parameters, `f32`, layer by layer (weights input-major, then biases) |
//! | … | … | color network parameters, `f32`, the same way |
//! | … | ⌈res³ / 8⌉ | occupancy bits, cell `x + res·(y + res·z)` at bit `i % 8` of byte `i / 8` |
//!
//! **NeRF fields** ([`FieldKind::Nerf`], `.nerf`) have their own magic `DSNERFLD`,
//! version 1, the same box, then 6 × `u32` (frequencies, width, density layers, color
//! layers, geometry features, occupancy resolution) ending the header at byte 60, and
//! then the same sections without the hash features.
//!
//! Loading checks the magic, the version, the header's ranges, then that the file has
//! exactly the size the header implies (before allocating anything it sizes), and that
//! every number is finite; each failure is an error naming the file and the problem.

use std::path::Path;

use glam::Vec3;

use super::hash::{F, HashShape};
use super::mlp::param_count;
use super::model::{FieldKind, Ngp, NgpShape};
use crate::error::{Error, Result};
use crate::image_io::write_atomic;

/// The first 8 bytes of an Instant-NGP field file.
pub const MAGIC: [u8; 8] = *b"DSNGPFLD";
/// The first 8 bytes of a NeRF field file.
pub const NERF_MAGIC: [u8; 8] = *b"DSNERFLD";
/// The format version written by [`save`] and the only one [`load`] reads (both kinds).
pub(crate) const VERSION: u32 = 1;

/// Bytes of the header of a file of this kind.
fn header_len(kind: FieldKind) -> usize {
    match kind {
        FieldKind::Ngp => 72,
        FieldKind::Nerf => 60,
    }
}

fn magic(kind: FieldKind) -> [u8; 8] {
    match kind {
        FieldKind::Ngp => MAGIC,
        FieldKind::Nerf => NERF_MAGIC,
    }
}

/// The file image of `m`.
pub(crate) fn to_bytes(m: &Ngp) -> Vec<u8> {
    let s = m.shape();
    let mut b = Vec::with_capacity(file_size(&s) as usize);
    b.extend_from_slice(&magic(s.kind()));
    b.extend_from_slice(&VERSION.to_le_bytes());
    for v in [m.min(), m.max()] {
        for c in v.to_array() {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    for v in header_u32s(&s) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let ll = m.hash.level_len();
    for (l, &r) in s.hash.resolutions().iter().enumerate() {
        let used = s.hash.used(r) * F;
        for v in &m.hash.params[l * ll..l * ll + used] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    for v in m.density.params.iter().chain(&m.color.params) {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let mut bits = vec![0u8; m.occupancy.bits.len().div_ceil(8)];
    for (i, &o) in m.occupancy.bits.iter().enumerate() {
        if o {
            bits[i / 8] |= 1 << (i % 8);
        }
    }
    b.extend_from_slice(&bits);
    b
}

fn header_u32s(s: &NgpShape) -> Vec<u32> {
    let net = [
        s.width,
        s.density_layers,
        s.color_layers,
        s.geo_features,
        s.occupancy_res,
    ];
    let head = match s.kind() {
        FieldKind::Ngp => vec![s.hash.levels, s.hash.log2_table, s.hash.n_min, s.hash.n_max],
        FieldKind::Nerf => vec![s.frequencies],
    };
    head.into_iter().chain(net).collect()
}

/// Floats of hash features a file of shape `s` holds.
fn hash_floats(s: &HashShape) -> u64 {
    s.resolutions()
        .iter()
        .map(|&r| (s.used(r) * F) as u64)
        .sum()
}

/// The exact size of a file of a (valid) shape, bytes.
pub(crate) fn file_size(s: &NgpShape) -> u64 {
    let floats = hash_floats(&s.hash)
        + param_count(&s.density_dims()) as u64
        + param_count(&s.color_dims()) as u64;
    header_len(s.kind()) as u64 + 4 * floats + (s.occupancy_res as u64).pow(3).div_ceil(8)
}

/// Writes `model` to `path` atomically (a temporary file renamed into place, parent
/// folders created), so a failure never leaves a partial file.
pub fn save(model: &Ngp, path: impl AsRef<Path>) -> Result<()> {
    write_atomic(path.as_ref(), &to_bytes(model))
}

/// Reads a model written by [`save`].
pub fn load(path: impl AsRef<Path>) -> Result<Ngp> {
    let path = path.as_ref();
    let bytes = crate::image_io::read_bounded(path, crate::limits::MAX_MODEL_BYTES)?;
    from_bytes(&bytes, path)
}

/// Parses a file image; `path` only names the input in errors.
pub(crate) fn from_bytes(b: &[u8], path: &Path) -> Result<Ngp> {
    let bad = |what: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    };
    let kind = if b.len() >= 8 && b[..8] == MAGIC {
        FieldKind::Ngp
    } else if b.len() >= 8 && b[..8] == NERF_MAGIC {
        FieldKind::Nerf
    } else {
        return Err(bad("not a diffsvg neural field (bad magic)".into()));
    };
    if b.len() < 12 {
        return Err(bad(format!("{} bytes: shorter than the header", b.len())));
    }
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let f32_at = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let version = u32_at(8);
    if version != VERSION {
        return Err(bad(format!(
            "version {version} is not supported (this build reads {VERSION})"
        )));
    }
    let header = header_len(kind);
    if b.len() < header {
        return Err(bad(format!(
            "{} bytes: shorter than the {header}-byte header",
            b.len()
        )));
    }
    let min = Vec3::new(f32_at(12), f32_at(16), f32_at(20));
    let max = Vec3::new(f32_at(24), f32_at(28), f32_at(32));
    if !(min.is_finite() && max.is_finite() && min.cmplt(max).all()) {
        return Err(bad(format!(
            "box {min} .. {max} is not a finite, non-empty box"
        )));
    }
    let h: Vec<u32> = (0..(header - 36) / 4).map(|i| u32_at(36 + 4 * i)).collect();
    let (hash, frequencies, net) = match kind {
        FieldKind::Ngp => (
            HashShape {
                levels: h[0],
                log2_table: h[1],
                n_min: h[2],
                n_max: h[3],
            },
            0,
            &h[4..],
        ),
        // Frequencies 0 would make the shape a hash field's: refuse it here.
        FieldKind::Nerf if h[0] == 0 => {
            return Err(bad("header: frequencies 0 must be 1 to 16".into()));
        }
        FieldKind::Nerf => (HashShape::NONE, h[0], &h[1..]),
    };
    let shape = NgpShape {
        hash,
        frequencies,
        width: net[0],
        density_layers: net[1],
        color_layers: net[2],
        geo_features: net[3],
        occupancy_res: net[4],
    };
    shape.validate().map_err(|e| bad(format!("header: {e}")))?;
    let want = file_size(&shape);
    if b.len() as u64 != want {
        return Err(bad(format!(
            "{} bytes, but its header implies {want}",
            b.len()
        )));
    }
    // Sizes are known to match the file now, so the allocations below are bounded by it.
    let mut at = header;
    let mut floats = |n: usize| -> std::result::Result<Vec<f32>, usize> {
        let v: Vec<f32> = b[at..at + 4 * n]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(at + 4 * i);
        }
        at += 4 * n;
        Ok(v)
    };
    let not_finite = |o: usize| bad(format!("the number at byte {o} is not finite"));
    let t = shape.hash.table();
    let mut hash = vec![0.0f32; shape.hash.levels as usize * t * F];
    for (l, &r) in shape.hash.resolutions().iter().enumerate() {
        let used = shape.hash.used(r) * F;
        let v = floats(used).map_err(not_finite)?;
        hash[l * t * F..l * t * F + used].copy_from_slice(&v);
    }
    let density = floats(param_count(&shape.density_dims())).map_err(not_finite)?;
    let color = floats(param_count(&shape.color_dims())).map_err(not_finite)?;
    let cells = (shape.occupancy_res as usize).pow(3);
    let bits: Vec<bool> = (0..cells)
        .map(|i| b[at + i / 8] >> (i % 8) & 1 == 1)
        .collect();
    Ok(Ngp::from_parts(min, max, shape, hash, density, color, bits))
}
