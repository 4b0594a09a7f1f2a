//! The sparse grid: vertices, slots, trilinear resampling, pruning and the empty-space
//! skipping structure.

use std::sync::OnceLock;

use glam::Vec3;
use rayon::prelude::*;

use crate::volume::sh;

/// The largest supported resolution (cells per axis): the index grid has `(res + 1)³`
/// entries of 4 bytes, 541 MB at 512, so a model file's header cannot ask for more
/// (1024 would be 4.3 GB before a single voxel is read).
pub const MAX_RES: u32 = 512;

/// Cells per axis of one block of the empty-space skipping structure.
pub(crate) const BLOCK: u32 = 4;

/// A sparse voxel grid of density and spherical-harmonic color (Plenoxels).
///
/// **Geometry.** The axis-aligned box `[min, max]` (world units) is cut into `res` cells per
/// axis; data live at the `(res + 1)³` cell corners ("vertices"). Vertex `(x, y, z)`, each
/// in `0 ..= res`, sits at `min + (x, y, z) · voxel_size()` and has the linear index
/// `x + (res + 1)·(y + (res + 1)·z)`. A point between vertices takes the trilinear
/// interpolation of its cell's 8 corners.
///
/// **Sparsity.** Only *allocated* vertices store data, each in one *slot* (`0 ..
/// allocated()`); slots are ordered by increasing linear vertex index. An unallocated
/// vertex reads as density 0 and SH coefficients 0. Slots are created by the constructors,
/// [`Grid::upsample`] and [`Grid::prune`], never by editing values.
///
/// **Values per slot.** `density()[slot]` is the raw density; the renderer uses
/// `σ = max(raw, 0)` (ReLU after interpolation) in units of 1 / world length, so a
/// segment of length `δ` has opacity `1 − exp(−σ·δ)`. `sh()[slot·3K .. (slot + 1)·3K]`
/// holds `K = coeff_count(degree)` coefficients for red, then green, then blue; a channel's
/// color is `sigmoid(Σ_k c_k · Y_k(dir))` with `Y_k` from `crate::volume::sh::basis` and
/// `dir` the ray's unit direction (the direction of travel, from camera to scene).
#[derive(Clone, Debug)]
pub struct Grid {
    min: Vec3,
    max: Vec3,
    res: u32,
    degree: u32,
    /// `(res + 1)³` entries: the slot of each vertex, or −1.
    index: Vec<i32>,
    /// Linear vertex index of each slot, strictly increasing.
    vertices: Vec<u32>,
    density: Vec<f32>,
    sh: Vec<f32>,
    /// Built on first use after any change of the allocation or of densities.
    skip: OnceLock<Skip>,
}

/// Empty-space skipping: per block of `BLOCK³` cells, the Chebyshev distance (in blocks,
/// capped at 255) to the nearest block that has an *active* vertex (allocated, with
/// positive raw density) on its closed box; 0 for such blocks. A cell without active corners has
/// interpolated raw density ≤ 0, so σ = 0 there: it contributes nothing to the color and
/// (ReLU) nothing to any gradient. With distance `d > 0`, every block within `d − 1` is
/// free of such contributions, so a ray can jump out of that cube of blocks exactly.
#[derive(Clone, Debug, Default)]
pub(crate) struct Skip {
    /// Blocks per axis.
    pub(crate) nb: u32,
    pub(crate) dist: Vec<u8>,
}

impl Grid {
    /// A grid with every vertex allocated, raw density `init_density` everywhere and SH
    /// coefficients 0 (gray, `sigmoid(0) = 0.5`). A small positive density lets
    /// gradients flow from the start of training.
    ///
    /// `(res + 1)³ · (1 + 3K) · 4` bytes: dense grids are for coarse starts (64³, 128³);
    /// finer grids come from [`Grid::upsample`] after pruning.
    ///
    /// # Panics
    /// If `min < max` fails on some axis or a corner is not finite, `res` is 0 or above
    /// [`MAX_RES`], or `degree > 3`.
    pub fn dense(min: Vec3, max: Vec3, res: u32, degree: u32, init_density: f32) -> Grid {
        Grid::from_fn(min, max, res, degree, |_| Some(init_density))
    }

    /// A grid allocated where `f(vertex position)` (world units) is `Some(raw density)`,
    /// with SH coefficients 0.
    ///
    /// # Panics
    /// As [`Grid::dense`].
    pub fn from_fn(
        min: Vec3,
        max: Vec3,
        res: u32,
        degree: u32,
        f: impl Fn(Vec3) -> Option<f32> + Sync,
    ) -> Grid {
        check_geometry(min, max, res, degree).unwrap_or_else(|e| panic!("Grid: {e}"));
        let n = res + 1;
        let vs = (max - min) / res as f32;
        let planes: Vec<(Vec<u32>, Vec<f32>)> = (0..n)
            .into_par_iter()
            .map(|z| {
                let (mut v, mut d) = (Vec::new(), Vec::new());
                for y in 0..n {
                    for x in 0..n {
                        let p = min + Vec3::new(x as f32, y as f32, z as f32) * vs;
                        if let Some(raw) = f(p) {
                            v.push(x + n * (y + n * z));
                            d.push(raw);
                        }
                    }
                }
                (v, d)
            })
            .collect();
        let vertices: Vec<u32> = planes.iter().flat_map(|p| p.0.iter().copied()).collect();
        let density: Vec<f32> = planes.into_iter().flat_map(|p| p.1).collect();
        let sh = vec![0.0; density.len() * 3 * sh::coeff_count(degree)];
        Grid::assemble(min, max, res, degree, vertices, density, sh)
    }

    /// Builds a grid from checked parts (slots in increasing vertex order).
    pub(crate) fn assemble(
        min: Vec3,
        max: Vec3,
        res: u32,
        degree: u32,
        vertices: Vec<u32>,
        density: Vec<f32>,
        sh: Vec<f32>,
    ) -> Grid {
        let n = (res + 1) as usize;
        debug_assert_eq!(vertices.len(), density.len());
        debug_assert_eq!(sh.len(), density.len() * 3 * sh::coeff_count(degree));
        debug_assert!(vertices.windows(2).all(|w| w[0] < w[1]));
        let mut index = vec![-1i32; n * n * n];
        for (slot, &v) in vertices.iter().enumerate() {
            index[v as usize] = slot as i32;
        }
        Grid {
            min,
            max,
            res,
            degree,
            index,
            vertices,
            density,
            sh,
            skip: OnceLock::new(),
        }
    }

    /// Lower corner of the box, world units.
    pub fn min(&self) -> Vec3 {
        self.min
    }

    /// Upper corner of the box, world units.
    pub fn max(&self) -> Vec3 {
        self.max
    }

    /// Cells per axis (vertices per axis are `res + 1`).
    pub fn res(&self) -> u32 {
        self.res
    }

    /// Spherical-harmonic degree, 0 to 3.
    pub fn degree(&self) -> u32 {
        self.degree
    }

    /// SH coefficients per color channel, `(degree + 1)²`.
    pub fn coeffs(&self) -> usize {
        sh::coeff_count(self.degree)
    }

    /// Floats per slot in [`Grid::sh`]: `3 · coeffs()`.
    pub fn sh_stride(&self) -> usize {
        3 * self.coeffs()
    }

    /// Edge lengths of one cell, world units.
    pub fn voxel_size(&self) -> Vec3 {
        (self.max - self.min) / self.res as f32
    }

    /// Number of allocated vertices (slots).
    pub fn allocated(&self) -> usize {
        self.vertices.len()
    }

    /// Raw density per slot (before the ReLU), 1 / world units.
    pub fn density(&self) -> &[f32] {
        &self.density
    }

    /// Raw density per slot, writable. (The empty-space skipping structure is rebuilt,
    /// in time linear in the allocation, at the next rendering.)
    pub fn density_mut(&mut self) -> &mut [f32] {
        self.skip = OnceLock::new();
        &mut self.density
    }

    /// SH coefficients, [`Grid::sh_stride`] per slot (red, green, blue blocks of
    /// [`Grid::coeffs`] each).
    pub fn sh(&self) -> &[f32] {
        &self.sh
    }

    /// SH coefficients, writable.
    pub fn sh_mut(&mut self) -> &mut [f32] {
        &mut self.sh
    }

    /// Density and SH coefficients together, writable.
    pub fn data_mut(&mut self) -> (&mut [f32], &mut [f32]) {
        self.skip = OnceLock::new();
        (&mut self.density, &mut self.sh)
    }

    /// The slot of vertex `(x, y, z)` (each `0 ..= res`), or `None` when it is unallocated or
    /// outside the grid.
    pub fn slot(&self, x: u32, y: u32, z: u32) -> Option<usize> {
        if x > self.res || y > self.res || z > self.res {
            return None;
        }
        let n = self.res as usize + 1;
        let i = self.index[x as usize + n * (y as usize + n * z as usize)];
        (i >= 0).then_some(i as usize)
    }

    /// The vertex `(x, y, z)` of a slot.
    ///
    /// # Panics
    /// If `slot >= allocated()`.
    pub fn vertex(&self, slot: usize) -> [u32; 3] {
        let n = self.res + 1;
        let v = self.vertices[slot];
        [v % n, (v / n) % n, v / (n * n)]
    }

    /// World position of a slot's vertex.
    ///
    /// # Panics
    /// If `slot >= allocated()`.
    pub fn position(&self, slot: usize) -> Vec3 {
        let [x, y, z] = self.vertex(slot);
        self.min + Vec3::new(x as f32, y as f32, z as f32) * self.voxel_size()
    }

    /// Linear vertex index of every slot, strictly increasing.
    pub fn vertex_indices(&self) -> &[u32] {
        &self.vertices
    }

    /// The per-vertex slot table, `(res + 1)³` entries, −1 where unallocated.
    pub(crate) fn index_table(&self) -> &[i32] {
        &self.index
    }

    /// The skipping structure, rebuilt here if densities changed since it was last built.
    pub(crate) fn skip(&self) -> &Skip {
        self.skip.get_or_init(|| Skip::build(self))
    }

    /// Keeps the slots for which `keep(slot)` is true and frees the others (their vertices
    /// read as zero afterwards). Slot numbers change; order is kept. Returns the number of
    /// slots removed.
    pub fn prune(&mut self, keep: impl Fn(usize) -> bool) -> usize {
        let before = self.allocated();
        let stride = self.sh_stride();
        let kept: Vec<usize> = (0..before).filter(|&s| keep(s)).collect();
        let vertices = kept.iter().map(|&s| self.vertices[s]).collect();
        let density = kept.iter().map(|&s| self.density[s]).collect();
        let mut sh = Vec::with_capacity(kept.len() * stride);
        for &s in &kept {
            sh.extend_from_slice(&self.sh[s * stride..(s + 1) * stride]);
        }
        let (min, max, res, degree) = (self.min, self.max, self.res, self.degree);
        *self = Grid::assemble(min, max, res, degree, vertices, density, sh);
        before - self.allocated()
    }

    /// Pruning by rendering weight: keeps each slot whose `weights[slot]` (e.g. from
    /// [`crate::volume::voxel::max_weights`]) is at least `threshold`, plus every allocated
    /// vertex within `dilate` vertices (Chebyshev distance) of a kept one, so that the
    /// allocation keeps a margin around occupied space. Returns the number removed.
    ///
    /// # Panics
    /// If `weights.len() != allocated()`.
    pub fn prune_by_weight(&mut self, weights: &[f32], threshold: f32, dilate: u32) -> usize {
        let keep = self.weight_mask(weights, threshold, dilate);
        self.prune(|s| keep[s])
    }

    /// The slots [`Grid::prune_by_weight`] keeps, as one flag per slot.
    ///
    /// # Panics
    /// If `weights.len() != allocated()`.
    pub fn weight_mask(&self, weights: &[f32], threshold: f32, dilate: u32) -> Vec<bool> {
        assert_eq!(weights.len(), self.allocated(), "one weight per slot");
        let mut keep: Vec<bool> = weights.iter().map(|&w| w >= threshold).collect();
        let r = dilate as i64;
        if r > 0 {
            let seeds: Vec<usize> = (0..keep.len()).filter(|&s| keep[s]).collect();
            for s in seeds {
                let [x, y, z] = self.vertex(s).map(|c| c as i64);
                for dz in -r..=r {
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let (a, b, c) = (x + dx, y + dy, z + dz);
                            if a < 0 || b < 0 || c < 0 {
                                continue;
                            }
                            if let Some(t) = self.slot(a as u32, b as u32, c as u32) {
                                keep[t] = true;
                            }
                        }
                    }
                }
            }
        }
        keep
    }

    /// Resamples onto `new_res` cells per axis over the same box (usually `2·res`).
    ///
    /// A new vertex is allocated when the old cell containing it has at least one
    /// allocated corner, so the allocation stays near the old one (prune first to keep it
    /// small); its density and SH coefficients are the trilinear interpolation of the old
    /// grid (unallocated corners count as 0), so the rendered field barely changes.
    ///
    /// # Panics
    /// If `new_res` is 0 or above [`MAX_RES`].
    pub fn upsample(&mut self, new_res: u32) {
        assert!(
            (1..=MAX_RES).contains(&new_res),
            "Grid::upsample: resolution {new_res} outside 1..={MAX_RES}"
        );
        let stride = self.sh_stride();
        let old = &*self;
        let n_new = new_res + 1;
        let scale = old.res as f32 / new_res as f32;
        let planes: Vec<(Vec<u32>, Vec<f32>, Vec<f32>)> = (0..n_new)
            .into_par_iter()
            .map(|z| {
                let (mut vs, mut ds, mut shs) = (Vec::new(), Vec::new(), Vec::new());
                let mut acc = vec![0.0f32; stride];
                for y in 0..n_new {
                    for x in 0..n_new {
                        let q = Vec3::new(x as f32, y as f32, z as f32) * scale;
                        let (slots, w) = old.corners(q);
                        if slots.iter().all(|&s| s < 0) {
                            continue;
                        }
                        acc.iter_mut().for_each(|a| *a = 0.0);
                        let mut d = 0.0;
                        for c in 0..8 {
                            if slots[c] >= 0 {
                                let s = slots[c] as usize;
                                d += w[c] * old.density[s];
                                let src = &old.sh[s * stride..(s + 1) * stride];
                                for (a, v) in acc.iter_mut().zip(src) {
                                    *a += w[c] * v;
                                }
                            }
                        }
                        vs.push(x + n_new * (y + n_new * z));
                        ds.push(d);
                        shs.extend_from_slice(&acc);
                    }
                }
                (vs, ds, shs)
            })
            .collect();
        let vertices = planes.iter().flat_map(|p| p.0.iter().copied()).collect();
        let density = planes.iter().flat_map(|p| p.1.iter().copied()).collect();
        let sh = planes.into_iter().flat_map(|p| p.2).collect();
        let (min, max, degree) = (self.min, self.max, self.degree);
        *self = Grid::assemble(min, max, new_res, degree, vertices, density, sh);
    }

    /// The 8 corner slots (−1 when unallocated) and trilinear weights of the cell holding
    /// grid-space point `q` (vertex units, clamped to `[0, res]`). Corner `c` has offset
    /// `(c & 1, (c >> 1) & 1, c >> 2)`.
    #[inline(always)]
    pub(crate) fn corners(&self, q: Vec3) -> ([i32; 8], [f32; 8]) {
        let r = self.res as f32;
        let q = q.clamp(Vec3::ZERO, Vec3::splat(r));
        let last = self.res - 1;
        let cx = (q.x as u32).min(last);
        let cy = (q.y as u32).min(last);
        let cz = (q.z as u32).min(last);
        let (fx, fy, fz) = (q.x - cx as f32, q.y - cy as f32, q.z - cz as f32);
        let n = self.res as usize + 1;
        let base = cx as usize + n * (cy as usize + n * cz as usize);
        let slots = cell_slots(&self.index, base, n);
        let w = trilinear(fx, fy, fz);
        (slots, w)
    }
}

/// The 8 corner entries of `index` (slot or −1) of the cell whose lowest vertex has flat
/// index `base`, with `n` vertices per axis; corner `c` has offset
/// `(c & 1, (c >> 1) & 1, c >> 2)`.
#[inline(always)]
pub(crate) fn cell_slots(index: &[i32], base: usize, n: usize) -> [i32; 8] {
    let nn = n * n;
    [
        index[base],
        index[base + 1],
        index[base + n],
        index[base + n + 1],
        index[base + nn],
        index[base + nn + 1],
        index[base + nn + n],
        index[base + nn + n + 1],
    ]
}

/// Trilinear weights of the 8 corners (ordered as in [`cell_slots`]) at fractional
/// position `(fx, fy, fz)` in `[0, 1]³` inside the cell. They sum to 1.
#[inline(always)]
pub(crate) fn trilinear(fx: f32, fy: f32, fz: f32) -> [f32; 8] {
    let (gx, gy, gz) = (1.0 - fx, 1.0 - fy, 1.0 - fz);
    [
        gx * gy * gz,
        fx * gy * gz,
        gx * fy * gz,
        fx * fy * gz,
        gx * gy * fz,
        fx * gy * fz,
        gx * fy * fz,
        fx * fy * fz,
    ]
}

/// Checks a grid's box, resolution and degree; the message says what is wrong.
pub(crate) fn check_geometry(min: Vec3, max: Vec3, res: u32, degree: u32) -> Result<(), String> {
    if !min.is_finite() || !max.is_finite() || !min.cmplt(max).all() {
        return Err(format!(
            "box {min} .. {max} is not a finite box with min < max"
        ));
    }
    if !(1..=MAX_RES).contains(&res) {
        return Err(format!("resolution {res} outside 1..={MAX_RES}"));
    }
    if degree > sh::MAX_DEGREE {
        return Err(format!("spherical harmonics degree {degree} above 3"));
    }
    Ok(())
}

impl Skip {
    /// Distances from the allocation of `g`.
    fn build(g: &Grid) -> Skip {
        let nb = g.res.div_ceil(BLOCK);
        let nbu = nb as usize;
        let mut dist = vec![u8::MAX; nbu * nbu * nbu];
        // The blocks whose closed box holds coordinate `x`.
        let range = |x: u32| {
            let hi = (x / BLOCK).min(nb - 1);
            let lo = if x.is_multiple_of(BLOCK) && x > 0 {
                (x / BLOCK - 1).min(nb - 1)
            } else {
                hi
            };
            lo..=hi
        };
        for s in 0..g.allocated() {
            if !(g.density[s] > 0.0) {
                continue;
            }
            let [x, y, z] = g.vertex(s);
            for bz in range(z) {
                for by in range(y) {
                    for bx in range(x) {
                        dist[bx as usize + nbu * (by as usize + nbu * bz as usize)] = 0;
                    }
                }
            }
        }
        chessboard_distance(&mut dist, nbu);
        Skip { nb, dist }
    }
}

/// Exact chessboard (L∞, 26-neighbour) distance transform in place, two raster passes
/// (forward with the 13 neighbours before each block in raster order, backward with the
/// 13 after); `d` holds 0 at sources and 255 elsewhere, distances saturate at 255.
fn chessboard_distance(d: &mut [u8], n: usize) {
    let n = n as isize;
    // Offsets (dx, dy, dz) of the neighbours that precede a block in raster order.
    let mut before = Vec::with_capacity(13);
    for dz in -1isize..=1 {
        for dy in -1isize..=1 {
            for dx in -1isize..=1 {
                if (dz * 3 + dy) * 3 + dx < 0 {
                    before.push((dx, dy, dz));
                }
            }
        }
    }
    let mut relax = |x: isize, y: isize, z: isize, sign: isize| {
        let i = (x + n * (y + n * z)) as usize;
        let mut best = d[i];
        if best == 0 {
            return;
        }
        for &(dx, dy, dz) in &before {
            let (a, b, c) = (x + sign * dx, y + sign * dy, z + sign * dz);
            if a >= 0 && b >= 0 && c >= 0 && a < n && b < n && c < n {
                best = best.min(d[(a + n * (b + n * c)) as usize].saturating_add(1));
            }
        }
        d[i] = best;
    };
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                relax(x, y, z, 1);
            }
        }
    }
    for z in (0..n).rev() {
        for y in (0..n).rev() {
            for x in (0..n).rev() {
                relax(x, y, z, -1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chessboard_transform_is_exact() {
        let n = 9usize;
        let mut seed = 12345u64;
        let mut d = vec![u8::MAX; n * n * n];
        let mut src = Vec::new();
        for i in 0..d.len() {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            if (seed >> 33).is_multiple_of(40) {
                d[i] = 0;
                src.push((i % n, (i / n) % n, i / (n * n)));
            }
        }
        assert!(!src.is_empty());
        chessboard_distance(&mut d, n);
        for i in 0..d.len() {
            let (x, y, z) = (i % n, (i / n) % n, i / (n * n));
            let want = src
                .iter()
                .map(|&(a, b, c)| x.abs_diff(a).max(y.abs_diff(b)).max(z.abs_diff(c)))
                .min()
                .unwrap();
            assert_eq!(d[i] as usize, want, "block ({x}, {y}, {z})");
        }
    }

    #[test]
    fn slots_vertices_and_positions() {
        let g = Grid::from_fn(Vec3::splat(-1.0), Vec3::splat(1.0), 4, 1, |p| {
            (p.x >= 0.0).then_some(p.y)
        });
        assert_eq!(g.allocated(), 3 * 25);
        assert_eq!(g.sh().len(), g.allocated() * 12);
        assert_eq!(g.slot(1, 0, 0), None);
        let s = g.slot(3, 4, 2).unwrap();
        assert_eq!(g.vertex(s), [3, 4, 2]);
        assert_eq!(g.position(s), Vec3::new(0.5, 1.0, 0.0));
        assert_eq!(g.density()[s], 1.0);
        assert!(g.vertex_indices().windows(2).all(|w| w[0] < w[1]));
    }

    /// Upsampling reproduces a trilinear field exactly (a linear function is its own
    /// trilinear interpolant) and allocates only next to old allocations.
    #[test]
    fn upsample_interpolates_and_stays_near() {
        let f = |p: Vec3| 1.0 + p.x - 2.0 * p.y + 0.5 * p.z;
        let mut g = Grid::from_fn(Vec3::ZERO, Vec3::splat(1.0), 4, 0, |p| {
            (p.x <= 0.5).then_some(f(p))
        });
        for s in 0..g.allocated() {
            let p = g.position(s);
            g.sh_mut()[3 * s + 1] = p.y;
        }
        g.upsample(8);
        assert_eq!(g.res(), 8);
        for s in 0..g.allocated() {
            let p = g.position(s);
            assert!(
                p.x <= 0.75 + 1e-6,
                "allocated far from the old allocation: {p}"
            );
            if p.x <= 0.5 {
                assert!((g.density()[s] - f(p)).abs() < 1e-5, "density at {p}");
                assert!((g.sh()[3 * s + 1] - p.y).abs() < 1e-5, "sh at {p}");
            }
        }
        assert_eq!(g.allocated(), 6 * 81, "old x-cells 0, 1, 2 → new x 0 ..= 5");
    }

    #[test]
    fn prune_by_weight_keeps_a_margin() {
        let mut g = Grid::dense(Vec3::ZERO, Vec3::splat(1.0), 8, 0, 0.1);
        let centre = g.slot(4, 4, 4).unwrap();
        let w: Vec<f32> = (0..g.allocated())
            .map(|s| if s == centre { 1.0 } else { 0.0 })
            .collect();
        let removed = g.prune_by_weight(&w, 0.5, 1);
        assert_eq!(g.allocated(), 27);
        assert_eq!(removed, 729 - 27);
        assert!(g.slot(3, 5, 4).is_some() && g.slot(2, 4, 4).is_none());
        // The skip structure sees only the blocks around the kept vertices.
        let skip = g.skip();
        assert_eq!(skip.nb, 2);
        assert!(
            skip.dist.iter().all(|&d| d == 0),
            "vertex 4 is on every block's box"
        );
        g.prune(|_| false);
        assert_eq!(g.allocated(), 0);
        assert!(g.skip().dist.iter().all(|&d| d == u8::MAX));
    }
}
