//! The multiresolution hash encoding of Instant-NGP (Müller et al. 2022).
//!
//! A point `x ∈ [0, 1]³` (the model's box, normalized) is looked up in `L` grids; level
//! `l` has `N_l = ⌊N_min·b^l⌋` cells per axis with `b = (N_max / N_min)^(1 / (L − 1))`.
//! Each level owns a table of `T` entries of `F = 2` features. A level whose
//! `(N_l + 1)³` vertices fit in `T` indexes them directly (`x + (N+1)·(y + (N+1)·z)`);
//! finer levels hash a vertex `(x, y, z)` to `(x ⊕ y·2654435761 ⊕ z·805459861) mod T`
//! (`T` a power of two, arithmetic on `u32` wrapping). The level's features at `x` are the
//! trilinear interpolation of its cell's 8 vertices; the encoding is the `L·F` features,
//! level by level.
//!
//! **Backward.** The encoding is linear in the table, so `∂L/∂entry` is the sum over
//! samples and corners of `w_corner · ∂L/∂feature`. [`HashGrid::scatter_level`] adds one
//! sample's share to one level's gradient; the trainer calls it per level in parallel
//! (levels own disjoint entries) and, within a level, in a fixed order of samples, so the
//! sums have the same bits on any number of threads.

use glam::Vec3;

/// Features per table entry.
pub(crate) const F: usize = 2;

/// The spatial hash's primes (the first is 1: `x` is used as it is).
const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

/// The shape of a hash encoding, as stored in a model file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HashShape {
    /// Levels `L`, 1 to 32.
    pub levels: u32,
    /// `log2` of the table size `T` per level, 4 to 24.
    pub log2_table: u32,
    /// Cells per axis of the coarsest level, at least 2.
    pub n_min: u32,
    /// Cells per axis of the finest level, `n_min` to 65536.
    pub n_max: u32,
}

impl HashShape {
    /// No hash grid (zero levels): the `hash` of a NeRF field's shape. It fails
    /// [`validate`](Self::validate), which is for fields that have a grid.
    pub const NONE: HashShape = HashShape {
        levels: 0,
        log2_table: 0,
        n_min: 0,
        n_max: 0,
    };

    /// Checks the ranges in the field docs; the message names the bad value.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=32).contains(&self.levels) {
            return Err(format!("levels {} must be 1 to 32", self.levels));
        }
        if !(4..=24).contains(&self.log2_table) {
            return Err(format!(
                "log2 table size {} must be 4 to 24",
                self.log2_table
            ));
        }
        if self.n_min < 2 || self.n_max < self.n_min || self.n_max > 65536 {
            return Err(format!(
                "resolutions {}..{} must satisfy 2 ≤ min ≤ max ≤ 65536",
                self.n_min, self.n_max
            ));
        }
        Ok(())
    }

    /// Table entries per level, `T`.
    pub fn table(&self) -> usize {
        1usize << self.log2_table
    }

    /// Cells per axis of every level.
    pub fn resolutions(&self) -> Vec<u32> {
        let l = self.levels;
        let b = if l > 1 {
            ((self.n_max as f64).ln() - (self.n_min as f64).ln()) / (l - 1) as f64
        } else {
            0.0
        };
        (0..l)
            .map(|i| {
                let r = (self.n_min as f64 * (b * i as f64).exp() + 1e-6).floor() as u32;
                r.clamp(self.n_min, self.n_max)
            })
            .collect()
    }

    /// Entries of level `l` actually used: `(N_l + 1)³` when that fits in `T`, else `T`.
    pub(crate) fn used(&self, res: u32) -> usize {
        let v = (res as u64 + 1).pow(3);
        v.min(self.table() as u64) as usize
    }
}

/// A hash encoding's parameters: `L` tables of `T·F` features (level `l` at
/// `l·T·F`; a directly indexed level uses the first `(N_l + 1)³` entries of its table).
#[derive(Clone, Debug, PartialEq)]
pub struct HashGrid {
    shape: HashShape,
    res: Vec<u32>,
    /// Features, `L·T·F`.
    pub(crate) params: Vec<f32>,
}

/// The 8 corners of one level's cell around a point: entry indices (within the level) and
/// trilinear weights, corner `c` at offset `(c & 1, c >> 1 & 1, c >> 2 & 1)`.
pub(crate) type Corners = ([u32; 8], [f32; 8]);

impl HashGrid {
    /// A grid of the given shape with features uniform in `[−1e-4, 1e-4)` from `seed`
    /// (Instant-NGP's initialization). The shape must pass [`HashShape::validate`].
    pub fn new(shape: HashShape, seed: u64) -> HashGrid {
        let mut rng = crate::rng::Rng::new(seed);
        let n = shape.levels as usize * shape.table() * F;
        let params = (0..n).map(|_| (rng.uniform() * 2.0 - 1.0) * 1e-4).collect();
        HashGrid::from_params(shape, params)
    }

    /// A grid from its parameters (`L·T·F` of them).
    pub(crate) fn from_params(shape: HashShape, params: Vec<f32>) -> HashGrid {
        assert_eq!(params.len(), shape.levels as usize * shape.table() * F);
        HashGrid {
            res: shape.resolutions(),
            shape,
            params,
        }
    }

    /// The shape.
    pub fn shape(&self) -> HashShape {
        self.shape
    }

    /// Levels `L`.
    pub fn levels(&self) -> usize {
        self.res.len()
    }

    /// Encoded features per point, `L·F`.
    pub fn dim(&self) -> usize {
        self.res.len() * F
    }

    /// Floats per level in [`params`](Self::params), `T·F`.
    pub(crate) fn level_len(&self) -> usize {
        self.shape.table() * F
    }

    /// The cell corners of level `l` around `x ∈ [0, 1]³` (clamped to the box).
    #[inline(always)]
    pub(crate) fn corners(&self, l: usize, x: Vec3) -> Corners {
        let r = self.res[l];
        let p = x.clamp(Vec3::ZERO, Vec3::ONE) * r as f32;
        let c = [
            (p.x as u32).min(r - 1),
            (p.y as u32).min(r - 1),
            (p.z as u32).min(r - 1),
        ];
        let f = [p.x - c[0] as f32, p.y - c[1] as f32, p.z - c[2] as f32];
        let n = r + 1;
        let t = self.shape.table() as u32;
        let dense = (n as u64).pow(3) <= t as u64;
        let mut idx = [0u32; 8];
        let mut w = [0f32; 8];
        for k in 0..8 {
            let o = [k & 1, (k >> 1) & 1, (k >> 2) & 1];
            let v = [c[0] + o[0], c[1] + o[1], c[2] + o[2]];
            idx[k as usize] = if dense {
                v[0] + n * (v[1] + n * v[2])
            } else {
                (v[0].wrapping_mul(PRIMES[0])
                    ^ v[1].wrapping_mul(PRIMES[1])
                    ^ v[2].wrapping_mul(PRIMES[2]))
                    & (t - 1)
            };
            let mut wk = 1.0;
            for a in 0..3 {
                wk *= if o[a] == 1 { f[a] } else { 1.0 - f[a] };
            }
            w[k as usize] = wk;
        }
        (idx, w)
    }

    /// Writes the `L·F` features of `x ∈ [0, 1]³` into `out`.
    #[inline]
    pub(crate) fn encode(&self, x: Vec3, out: &mut [f32]) {
        let ll = self.level_len();
        for l in 0..self.res.len() {
            let (idx, w) = self.corners(l, x);
            let table = &self.params[l * ll..(l + 1) * ll];
            let mut acc = [0.0f32; F];
            for k in 0..8 {
                let e = idx[k] as usize * F;
                for j in 0..F {
                    acc[j] += w[k] * table[e + j];
                }
            }
            out[l * F..(l + 1) * F].copy_from_slice(&acc);
        }
    }

    /// Adds one sample's gradient to level `l`'s gradient `grad` (`T·F` floats): `d` is
    /// `∂L/∂(level l's F features)` at `x`. Entries it touches for the first time (per
    /// `touched`, one flag per entry) are appended to `list`.
    #[inline]
    pub(crate) fn scatter_level(
        &self,
        l: usize,
        x: Vec3,
        d: &[f32],
        grad: &mut [f32],
        touched: &mut [bool],
        list: &mut Vec<u32>,
    ) {
        let (idx, w) = self.corners(l, x);
        for k in 0..8 {
            let e = idx[k] as usize;
            if !touched[e] {
                touched[e] = true;
                list.push(idx[k]);
            }
            for j in 0..F {
                grad[e * F + j] += w[k] * d[j];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> HashShape {
        HashShape {
            levels: 4,
            log2_table: 8,
            n_min: 2,
            n_max: 24,
        }
    }

    #[test]
    fn coarse_levels_are_indexed_directly_and_fine_ones_hashed() {
        let s = shape();
        assert_eq!(s.resolutions(), [2, 4, 10, 24]);
        let g = HashGrid::new(s, 1);
        // Level 0 (3³ = 27 vertices ≤ 256): direct indices of the cell's corners.
        let (idx, w) = g.corners(0, Vec3::new(0.75, 0.25, 0.25));
        assert_eq!(idx[0], 1);
        assert_eq!(idx[7], 2 + 3 * (1 + 3));
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        // Level 3 (25³ > 256): hashed into the table.
        let (idx, _) = g.corners(3, Vec3::new(0.5, 0.5, 0.5));
        assert!(idx.iter().all(|&i| i < 256));
        let v = [12u32, 12, 12];
        assert_eq!(
            idx[0],
            (v[0] ^ v[1].wrapping_mul(PRIMES[1]) ^ v[2].wrapping_mul(PRIMES[2])) & 255
        );
    }

    /// Interpolation reproduces a vertex's features at the vertex and is continuous
    /// across cell faces.
    #[test]
    fn interpolation_hits_vertices_and_is_continuous() {
        let g = HashGrid::new(shape(), 3);
        let mut a = vec![0.0; g.dim()];
        let mut b = vec![0.0; g.dim()];
        // Level 1 has 4 cells: x = 0.5 is a vertex.
        g.encode(Vec3::new(0.5, 0.25, 0.75), &mut a);
        let e = 2 + 5 * (1 + 5 * 3);
        let ll = g.level_len();
        for j in 0..F {
            assert!((a[F + j] - g.params[ll + e * F + j]).abs() < 1e-9);
        }
        g.encode(Vec3::new(0.5 - 1e-6, 0.25, 0.75), &mut b);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-7, "{a:?} vs {b:?}");
        }
    }

    /// The scatter is the transpose of the encoding: `Σ d·encode(x)` has gradient
    /// `scatter(x, d)` with respect to every table entry (central differences in f64 on
    /// a linear function, so to rounding).
    #[test]
    fn scatter_matches_finite_differences() {
        let mut g = HashGrid::new(shape(), 5);
        let x = Vec3::new(0.31, 0.77, 0.52);
        let d: Vec<f32> = (0..g.dim()).map(|i| 0.3 + 0.1 * i as f32).collect();
        let ll = g.level_len();
        let mut grad = vec![0.0f32; g.params.len()];
        for l in 0..g.levels() {
            let mut touched = vec![false; ll / F];
            let mut list = Vec::new();
            g.scatter_level(
                l,
                x,
                &d[l * F..(l + 1) * F],
                &mut grad[l * ll..(l + 1) * ll],
                &mut touched,
                &mut list,
            );
            assert!(!list.is_empty() && list.len() <= 8);
        }
        let loss = |g: &HashGrid| {
            let mut out = vec![0.0; g.dim()];
            g.encode(x, &mut out);
            out.iter().zip(&d).map(|(a, b)| (a * b) as f64).sum::<f64>()
        };
        let mut checked = 0;
        for i in 0..g.params.len() {
            let h = 1e-2;
            let v = g.params[i];
            g.params[i] = v + h;
            let lp = loss(&g);
            g.params[i] = v - h;
            let lm = loss(&g);
            g.params[i] = v;
            let fd = (lp - lm) / (2.0 * h as f64);
            assert!(
                (fd - grad[i] as f64).abs() < 1e-4,
                "entry {i}: scatter {} vs {fd}",
                grad[i]
            );
            if grad[i] != 0.0 {
                checked += 1;
            }
        }
        assert!(checked >= 4 * 8, "{checked} entries touched");
    }
}
