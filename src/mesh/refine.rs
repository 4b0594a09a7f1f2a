//! A high-poly reference from a low-poly mesh, reproducibly: midpoint subdivision (each
//! triangle split in four, attributes interpolated) and a procedural displacement along
//! the normal (smooth 3D value noise, deterministic by seed), so that the result holds
//! detail that a mesh of the original size cannot.

use std::collections::HashMap;

use super::Mesh;
use crate::error::{Error, Result};

/// How [`refine`] displaces the subdivided surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Displacement {
    /// Largest displacement along the normal, as a fraction of the mesh's bounding radius
    /// (half its bounding box diagonal); 0 leaves the subdivided surface flat.
    pub amplitude: f64,
    /// Noise frequency of the first octave, cycles per bounding radius.
    pub frequency: f64,
    /// Octaves of noise (each doubles the frequency and halves the amplitude), 1 to 8.
    pub octaves: u32,
    /// Seed of the noise lattice.
    pub seed: u64,
}

impl Default for Displacement {
    fn default() -> Self {
        Displacement {
            amplitude: 0.03,
            frequency: 16.0,
            octaves: 3,
            seed: 1,
        }
    }
}

/// Splits every triangle into four at its edges' midpoints, `levels` times (×4ⁿ
/// triangles): positions, UVs and colors of a new vertex are the averages of its edge's
/// two ends, so the surface and its texture mapping are unchanged; the texture is kept.
/// An edge's midpoint is shared by the triangles on both sides (a closed mesh stays
/// closed); on a UV seam each side's copy gets its own UV at the same position. Refuses
/// (before allocating) a result past [`crate::limits::MAX_MESH_TRIANGLES`] or
/// [`crate::limits::MAX_MESH_VERTICES`].
pub fn subdivide(mesh: &Mesh, levels: u32) -> Result<Mesh> {
    let too_many = |what: &str, n: u128, limit: usize| Error::Setting {
        name: "levels".into(),
        message: format!(
            "{levels} levels give {n} {what}, past the limit of {limit}; use fewer levels"
        ),
    };
    let grow = 4u128.checked_pow(levels).unwrap_or(u128::MAX);
    let tris = (mesh.triangles.len() as u128).saturating_mul(grow);
    if tris > crate::limits::MAX_MESH_TRIANGLES as u128 {
        return Err(too_many(
            "triangles",
            tris,
            crate::limits::MAX_MESH_TRIANGLES,
        ));
    }
    // Each level adds at most three vertices per triangle of the level before (one per
    // edge, none shared): V + F·(4ⁿ − 1) in all.
    let verts = (mesh.positions.len() as u128)
        .saturating_add((mesh.triangles.len() as u128).saturating_mul(grow - 1));
    if verts > crate::limits::MAX_MESH_VERTICES as u128 {
        return Err(too_many(
            "vertices",
            verts,
            crate::limits::MAX_MESH_VERTICES,
        ));
    }
    mesh.validate(std::path::Path::new("<mesh>"))?;
    let mut m = mesh.clone();
    for _ in 0..levels {
        m = split_once(&m)?;
    }
    Ok(m)
}

fn split_once(m: &Mesh) -> Result<Mesh> {
    let mut out = Mesh {
        positions: m.positions.clone(),
        triangles: Vec::with_capacity(m.triangles.len() * 4),
        uvs: m.uvs.clone(),
        colors: m.colors.clone(),
        texture: m.texture.clone(),
    };
    let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(m.triangles.len() * 2);
    let mut midpoint = |a: u32, b: u32, out: &mut Mesh| -> Result<u32> {
        let key = (a.min(b), a.max(b));
        if let Some(&i) = mid.get(&key) {
            return Ok(i);
        }
        let (a, b) = (key.0 as usize, key.1 as usize);
        let avg3 = |p: [f64; 3], q: [f64; 3]| [0, 1, 2].map(|k| 0.5 * (p[k] + q[k]));
        out.positions.push(avg3(out.positions[a], out.positions[b]));
        if let Some(uv) = &mut out.uvs {
            let (p, q) = (uv[a], uv[b]);
            uv.push([0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])]);
        }
        if let Some(c) = &mut out.colors {
            c.push(avg3(c[a], c[b]));
        }
        let i = u32::try_from(out.positions.len() - 1).map_err(|_| Error::Setting {
            name: "levels".into(),
            message: "more than 2³² vertices".into(),
        })?;
        mid.insert(key, i);
        Ok(i)
    };
    for &[a, b, c] in &m.triangles {
        let ab = midpoint(a, b, &mut out)?;
        let bc = midpoint(b, c, &mut out)?;
        let ca = midpoint(c, a, &mut out)?;
        out.triangles
            .extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
    }
    Ok(out)
}

/// Moves every vertex along its normal by `amplitude · r · noise(p)`, `r` the bounding
/// radius and `noise` a sum of [`Displacement::octaves`] octaves of smooth value noise
/// in `[−1, 1]`. Vertices at the same position (UV-seam copies) share one normal (the
/// area-weighted sum over every triangle at that position) and so move together: the
/// surface stays closed. Deterministic: the same mesh and settings give the same bits.
pub fn displace(mesh: &mut Mesh, d: &Displacement) -> Result<()> {
    for (name, v) in [("amplitude", d.amplitude), ("frequency", d.frequency)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(Error::Setting {
                name: name.into(),
                message: format!("{v} must be finite and not negative"),
            });
        }
    }
    if !(1..=8).contains(&d.octaves) {
        return Err(Error::Setting {
            name: "octaves".into(),
            message: format!("{} must be between 1 and 8", d.octaves),
        });
    }
    let (lo, hi) = mesh.bounds();
    let r = 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    if r == 0.0 || d.amplitude == 0.0 {
        return Ok(());
    }
    let (group, n_groups) = position_groups(&mesh.positions);
    let mut normal = vec![[0.0f64; 3]; n_groups];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let e1 = [0, 1, 2].map(|k| b[k] - a[k]);
        let e2 = [0, 1, 2].map(|k| c[k] - a[k]);
        let n = cross(e1, e2);
        for &i in t {
            let g = &mut normal[group[i as usize] as usize];
            for k in 0..3 {
                g[k] += n[k];
            }
        }
    }
    let noise = Noise::new(d.seed);
    for (i, p) in mesh.positions.iter_mut().enumerate() {
        let n = normal[group[i] as usize];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len == 0.0 {
            continue;
        }
        let q = [0, 1, 2].map(|k| p[k] / r * d.frequency);
        let h = d.amplitude * r * noise.fbm(q, d.octaves);
        for k in 0..3 {
            p[k] += h * n[k] / len;
        }
    }
    Ok(())
}

/// [`subdivide`] then [`displace`].
pub fn refine(mesh: &Mesh, levels: u32, d: &Displacement) -> Result<Mesh> {
    let mut m = subdivide(mesh, levels)?;
    displace(&mut m, d)?;
    Ok(m)
}

/// For each vertex the index of its group of vertices at bit-identical positions, and the
/// number of groups; groups are numbered in order of their first vertex.
pub(crate) fn position_groups(positions: &[[f64; 3]]) -> (Vec<u32>, usize) {
    let mut first: HashMap<[u64; 3], u32> = HashMap::with_capacity(positions.len());
    let mut group = Vec::with_capacity(positions.len());
    for p in positions {
        let key = p.map(|v| if v == 0.0 { 0 } else { v.to_bits() });
        let n = first.len() as u32;
        group.push(*first.entry(key).or_insert(n));
    }
    (group, first.len())
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Smooth 3D value noise: random values in `[−1, 1]` at the integer lattice (hashed from
/// the seed and the lattice point), blended with the quintic fade `6t⁵ − 15t⁴ + 10t³`
/// (continuous first and second derivatives).
struct Noise {
    seed: u64,
}

impl Noise {
    fn new(seed: u64) -> Noise {
        Noise {
            seed: crate::rng::Rng::new(seed).next_u64(),
        }
    }

    fn lattice(&self, x: i64, y: i64, z: i64) -> f64 {
        let mut h = self.seed
            ^ (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 31;
        (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// Value noise at `p`, in `[−1, 1]`.
    fn value(&self, p: [f64; 3]) -> f64 {
        let fl = p.map(f64::floor);
        let f = [0, 1, 2].map(|k| p[k] - fl[k]);
        let w = f.map(|t| t * t * t * (t * (6.0 * t - 15.0) + 10.0));
        let i = fl.map(|v| v as i64);
        let mut acc = 0.0;
        for corner in 0..8 {
            let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
            let weight: f64 = (0..3)
                .map(|k| if o[k] == 1 { w[k] } else { 1.0 - w[k] })
                .product();
            acc += weight * self.lattice(i[0] + o[0], i[1] + o[1], i[2] + o[2]);
        }
        acc
    }

    /// `octaves` octaves, normalized to `[−1, 1]`.
    fn fbm(&self, p: [f64; 3], octaves: u32) -> f64 {
        let (mut sum, mut norm, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0);
        for o in 0..octaves {
            // Each octave is shifted so that lattice points do not line up.
            let shift = 17.31 * o as f64;
            sum += amp * self.value(p.map(|v| v * freq + shift));
            norm += amp;
            amp *= 0.5;
            freq *= 2.0;
        }
        sum / norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::octahedron;

    /// Every undirected edge (by position group) is used by exactly two triangles.
    fn closed(m: &Mesh) -> bool {
        let (g, _) = position_groups(&m.positions);
        let mut count: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (g[t[k] as usize], g[t[(k + 1) % 3] as usize]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        count.values().all(|&c| c == 2)
    }

    #[test]
    fn subdivision_quadruples_triangles_keeps_the_mesh_closed_and_interpolates_uvs() {
        let mut m = octahedron();
        // UVs linear in the position, so every midpoint's UV is that function too.
        let uv_of = |p: [f64; 3]| [0.5 + 0.3 * p[0] + 0.1 * p[2], 0.5 + 0.2 * p[1]];
        m.uvs = Some(m.positions.iter().map(|&p| uv_of(p)).collect());
        assert!(closed(&m));
        let r = subdivide(&m, 3).unwrap();
        assert_eq!(r.triangles.len(), 8 * 64);
        // Closed: V − E + F = 2 with E = 3F/2.
        assert_eq!(r.positions.len(), 2 + r.triangles.len() / 2);
        assert!(closed(&r));
        for (p, uv) in r.positions.iter().zip(r.uvs.as_ref().unwrap()) {
            let want = uv_of(*p);
            assert!((uv[0] - want[0]).abs() < 1e-12 && (uv[1] - want[1]).abs() < 1e-12);
        }
        // The surface is unchanged: every vertex lies on the octahedron |x|+|y|+|z| = 1.
        for p in &r.positions {
            assert!((p.iter().map(|v| v.abs()).sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn displacement_moves_seam_copies_together_and_is_deterministic() {
        let mut m = octahedron();
        // A seam: vertex 0 split into two copies with different UVs.
        m.positions.push(m.positions[0]);
        m.uvs = Some(
            (0..m.positions.len())
                .map(|i| [i as f64 * 0.1, 0.5])
                .collect(),
        );
        for t in &mut m.triangles[..2] {
            for v in t.iter_mut() {
                if *v == 0 {
                    *v = 6;
                }
            }
        }
        let d = Displacement {
            amplitude: 0.05,
            ..Displacement::default()
        };
        let a = refine(&m, 2, &d).unwrap();
        let b = refine(&m, 2, &d).unwrap();
        assert_eq!(a, b);
        assert!(closed(&a), "seam copies moved apart");
        let flat = subdivide(&m, 2).unwrap();
        let moved = a
            .positions
            .iter()
            .zip(&flat.positions)
            .filter(|(p, q)| p != q)
            .count();
        assert!(moved > a.positions.len() / 2, "{moved} moved");
        let other = refine(&m, 2, &Displacement { seed: 2, ..d }).unwrap();
        assert_ne!(a.positions, other.positions);
        // Bounded by the amplitude: r = √3 for the octahedron's box.
        let r = 3f64.sqrt();
        for (p, q) in a.positions.iter().zip(&flat.positions) {
            let dist = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt();
            assert!(dist <= 0.05 * r + 1e-12);
        }
    }

    #[test]
    fn too_many_levels_are_refused_before_allocating() {
        let e = subdivide(&octahedron(), 12).unwrap_err().to_string();
        assert!(e.contains("levels") && e.contains("limit"), "{e}");
    }
}
