//! The neural field: a hash encoding, a density network and a color network, over an
//! axis-aligned box, with its occupancy grid.

use glam::Vec3;
use rayon::prelude::*;

use super::hash::{HashGrid, HashShape};
use super::mlp::Mlp;

/// Raw densities above this are clamped before the exponential (and get no gradient):
/// `exp(15)` is far beyond opaque for any step.
pub(crate) const MAX_RAW: f32 = 15.0;

/// Spherical-harmonic coefficients of the view direction fed to the color network
/// (degree 3).
pub(crate) const DIR_DIM: usize = 16;

/// Which encoding of the position a field uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    /// Instant-NGP: the multiresolution hash encoding ([`NgpShape::hash`]); `.ngp` files.
    Ngp,
    /// NeRF: the positional encoding of [`NgpShape::frequencies`] octaves and no
    /// trainable encoding; `.nerf` files.
    Nerf,
}

/// The shape of an [`Ngp`] model, as stored in its file. A field encodes positions
/// either with the hash grid (`frequencies` 0) or, the NeRF rung, with the positional
/// encoding (`frequencies` ≥ 1 and `hash` [`HashShape::NONE`]); see [`FieldKind`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NgpShape {
    /// The hash encoding ([`HashShape::NONE`] for a NeRF field).
    pub hash: HashShape,
    /// Octaves `K` of NeRF's positional encoding, 0 (a hash field) or 1 to 16.
    pub frequencies: u32,
    /// Neurons of every hidden layer, 8 to 256.
    pub width: u32,
    /// Hidden layers of the density network, 1 to 4.
    pub density_layers: u32,
    /// Hidden layers of the color network, 1 to 4.
    pub color_layers: u32,
    /// Features passed from the density network to the color network, 1 to 64.
    pub geo_features: u32,
    /// Occupancy grid cells per axis, 8 to 256.
    pub occupancy_res: u32,
}

impl Default for NgpShape {
    /// 16 levels from 16 to 1024 cells with 2¹⁶ entries of 2 features each (8 MiB in
    /// `f32`), width 64, one hidden layer for density and two for color, 15 geometry
    /// features, a 64³ occupancy grid.
    fn default() -> Self {
        NgpShape {
            hash: HashShape {
                levels: 16,
                log2_table: 16,
                n_min: 16,
                n_max: 1024,
            },
            width: 64,
            density_layers: 1,
            color_layers: 2,
            geo_features: 15,
            occupancy_res: 64,
            frequencies: 0,
        }
    }
}

impl NgpShape {
    /// The NeRF rung sized for a CPU: 10 octaves of positional encoding (NeRF's), a
    /// density network of 4 hidden layers of 64 (NeRF has 8 of 256: 16 times the work
    /// per layer, and 64 is the widest layer whose accumulator stays in registers), 15
    /// geometry features, a color network of 1 hidden layer of 64 (NeRF's color branch
    /// has one), a 64³ occupancy grid.
    pub fn nerf() -> NgpShape {
        NgpShape {
            hash: HashShape::NONE,
            frequencies: 10,
            width: 64,
            density_layers: 4,
            color_layers: 1,
            ..NgpShape::default()
        }
    }

    /// Which encoding the shape uses.
    pub fn kind(&self) -> FieldKind {
        if self.frequencies > 0 {
            FieldKind::Nerf
        } else {
            FieldKind::Ngp
        }
    }

    /// Floats of the position's encoding (the density network's input).
    pub(crate) fn encoding_dim(&self) -> usize {
        match self.kind() {
            FieldKind::Ngp => self.hash.levels as usize * super::hash::F,
            FieldKind::Nerf => super::freq::dim(self.frequencies),
        }
    }

    /// Checks the ranges in the field docs; the message names the bad value.
    pub fn validate(&self) -> Result<(), String> {
        match self.kind() {
            FieldKind::Ngp => self.hash.validate()?,
            FieldKind::Nerf => {
                if self.frequencies > super::freq::MAX_OCTAVES {
                    return Err(format!(
                        "frequencies {} must be 1 to {}",
                        self.frequencies,
                        super::freq::MAX_OCTAVES
                    ));
                }
                if self.hash != HashShape::NONE {
                    return Err("a field with frequencies has no hash grid (levels 0)".into());
                }
            }
        }
        let checks = [
            ("width", self.width, 8, 256),
            ("density_layers", self.density_layers, 1, 4),
            ("color_layers", self.color_layers, 1, 4),
            ("geo_features", self.geo_features, 1, 64),
            ("occupancy_res", self.occupancy_res, 8, 256),
        ];
        for (name, v, lo, hi) in checks {
            if !(lo..=hi).contains(&v) {
                return Err(format!("{name} {v} must be {lo} to {hi}"));
            }
        }
        Ok(())
    }

    pub(crate) fn density_dims(&self) -> Vec<usize> {
        let mut d = vec![self.encoding_dim()];
        d.extend(std::iter::repeat_n(
            self.width as usize,
            self.density_layers as usize,
        ));
        d.push(1 + self.geo_features as usize);
        d
    }

    pub(crate) fn color_dims(&self) -> Vec<usize> {
        let mut d = vec![self.geo_features as usize + DIR_DIM];
        d.extend(std::iter::repeat_n(
            self.width as usize,
            self.color_layers as usize,
        ));
        d.push(3);
        d
    }
}

/// Which cells of the box may hold density: a `res³` grid of flags over the box and the
/// running estimate of each cell's largest density (nerfacc's scheme).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Occupancy {
    pub(crate) res: u32,
    /// Exponential moving maximum of the density per cell, 1 / world units.
    pub(crate) density: Vec<f32>,
    pub(crate) bits: Vec<bool>,
}

impl Occupancy {
    /// Every cell occupied.
    pub(crate) fn full(res: u32) -> Occupancy {
        let n = (res as usize).pow(3);
        Occupancy {
            res,
            density: vec![0.0; n],
            bits: vec![true; n],
        }
    }

    /// Whether the cell of `x ∈ [0, 1]³` is occupied.
    #[inline(always)]
    pub(crate) fn at(&self, x: Vec3) -> bool {
        let r = self.res;
        let c = (x.clamp(Vec3::ZERO, Vec3::ONE) * r as f32)
            .as_uvec3()
            .min(glam::UVec3::splat(r - 1));
        self.bits[(c.x + r * (c.y + r * c.z)) as usize]
    }

    /// Fraction of occupied cells.
    pub(crate) fn fraction(&self) -> f32 {
        self.bits.iter().filter(|&&b| b).count() as f32 / self.bits.len().max(1) as f32
    }
}

/// An Instant-NGP model: a [hash encoding](HashGrid) of points of the box, a density
/// network (encoding → hidden layers → raw density and geometry features) and a color
/// network (geometry features and degree-3 spherical harmonics of the view direction →
/// hidden layers → RGB through a sigmoid); density `σ = exp(min(raw, 15))` in 1 / world
/// units. Points outside the box have no density.
#[derive(Clone, Debug, PartialEq)]
pub struct Ngp {
    min: Vec3,
    max: Vec3,
    shape: NgpShape,
    pub(crate) hash: HashGrid,
    pub(crate) density: Mlp,
    pub(crate) color: Mlp,
    pub(crate) occupancy: Occupancy,
}

/// `f32`s of one sample's record for the backward pass: position, density and color
/// network activations.
pub(crate) fn tape_len(m: &Ngp) -> usize {
    3 + m.density.acts_len() + m.color.acts_len()
}

impl Ngp {
    /// A fresh model over the box `[min, max]` (the shape must pass
    /// [`NgpShape::validate`] and the box be finite and non-empty), parameters drawn from
    /// `seed`, every occupancy cell occupied.
    pub fn new(min: Vec3, max: Vec3, shape: NgpShape, seed: u64) -> Ngp {
        assert!(shape.validate().is_ok(), "invalid shape {shape:?}");
        Ngp {
            min,
            max,
            shape,
            hash: HashGrid::new(shape.hash, seed),
            density: Mlp::new(&shape.density_dims(), seed ^ 0xD3),
            color: Mlp::new(&shape.color_dims(), seed ^ 0xC0),
            occupancy: Occupancy::full(shape.occupancy_res),
        }
    }

    /// A model from its parts (checked by the caller, see the `io` module).
    pub(crate) fn from_parts(
        min: Vec3,
        max: Vec3,
        shape: NgpShape,
        hash: Vec<f32>,
        density: Vec<f32>,
        color: Vec<f32>,
        bits: Vec<bool>,
    ) -> Ngp {
        let n = bits.len();
        Ngp {
            min,
            max,
            shape,
            hash: HashGrid::from_params(shape.hash, hash),
            density: Mlp::from_params(&shape.density_dims(), density),
            color: Mlp::from_params(&shape.color_dims(), color),
            occupancy: Occupancy {
                res: shape.occupancy_res,
                density: vec![0.0; n],
                bits,
            },
        }
    }

    /// The box's minimum corner, world units.
    pub fn min(&self) -> Vec3 {
        self.min
    }

    /// The box's maximum corner, world units.
    pub fn max(&self) -> Vec3 {
        self.max
    }

    /// The shape.
    pub fn shape(&self) -> NgpShape {
        self.shape
    }

    /// Parameters (hash table features and network weights).
    pub fn param_count(&self) -> usize {
        self.hash.params.len() + self.density.params.len() + self.color.params.len()
    }

    /// Fraction of the occupancy grid's cells marked occupied.
    pub fn occupied_fraction(&self) -> f32 {
        self.occupancy.fraction()
    }

    /// `p` in box coordinates, `[0, 1]³` inside the box.
    #[inline(always)]
    pub(crate) fn normalize(&self, p: Vec3) -> Vec3 {
        (p - self.min) / (self.max - self.min)
    }

    /// The density at world point `p` (1 / world units; 0 outside the box).
    pub fn density_at(&self, p: Vec3) -> f32 {
        let x = self.normalize(p);
        if !(x.cmpge(Vec3::ZERO).all() && x.cmple(Vec3::ONE).all()) {
            return 0.0;
        }
        let mut acts = vec![0.0; self.density.acts_len()];
        self.raw_density(x, &mut acts).0
    }

    /// `(σ, raw)` at `x ∈ [0, 1]³`, with the density network's activations in `acts`.
    #[inline]
    fn raw_density(&self, x: Vec3, acts: &mut [f32]) -> (f32, f32) {
        let n_in = self.shape.encoding_dim();
        match self.shape.kind() {
            FieldKind::Ngp => self.hash.encode(x, &mut acts[..n_in]),
            FieldKind::Nerf => super::freq::encode(self.shape.frequencies, x, &mut acts[..n_in]),
        }
        self.density.forward(acts);
        let raw = acts[acts.len() - self.density.n_out()];
        (raw.min(MAX_RAW).exp(), raw)
    }

    /// One sample at `x ∈ [0, 1]³` seen along a direction with SH basis `dir`: its
    /// density and color, with everything the backward pass needs in `tape`
    /// ([`tape_len`] floats).
    #[inline]
    pub(crate) fn sample(&self, x: Vec3, dir: &[f32; 16], tape: &mut [f32]) -> (f32, [f32; 3]) {
        tape[..3].copy_from_slice(&x.to_array());
        let nd = self.density.acts_len();
        let (dacts, cacts) = tape[3..].split_at_mut(nd);
        let (sigma, _) = self.raw_density(x, dacts);
        let geo = self.shape.geo_features as usize;
        let dout = &dacts[nd - (1 + geo)..];
        cacts[..geo].copy_from_slice(&dout[1..]);
        cacts[geo..geo + DIR_DIM].copy_from_slice(dir);
        self.color.forward(cacts);
        let o = &cacts[cacts.len() - 3..];
        (sigma, [sigmoid(o[0]), sigmoid(o[1]), sigmoid(o[2])])
    }

    /// Backward pass of one sample recorded by [`sample`](Self::sample): given
    /// `∂L/∂σ` and `∂L/∂rgb`, adds the networks' parameter gradients to `gd` and `gc`
    /// and writes `∂L/∂encoding` into `d_enc`. `scratch` holds at least 4·width + 4·64
    /// floats.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn sample_backward(
        &self,
        tape: &[f32],
        d_sigma: f32,
        d_rgb: [f32; 3],
        gd: &mut [f32],
        gc: &mut [f32],
        d_enc: &mut [f32],
        scratch: &mut [f32],
    ) {
        let nd = self.density.acts_len();
        let (dacts, cacts) = tape[3..].split_at(nd);
        let geo = self.shape.geo_features as usize;
        let o = &cacts[cacts.len() - 3..];
        let mut d_o = [0.0f32; 3];
        for ch in 0..3 {
            let s = sigmoid(o[ch]);
            d_o[ch] = d_rgb[ch] * s * (1.0 - s);
        }
        let (d_cin, rest) = scratch.split_at_mut(geo + DIR_DIM);
        let (d_dout, rest) = rest.split_at_mut(1 + geo);
        self.color.backward(cacts, &d_o, gc, d_cin, rest);
        let raw = dacts[nd - (1 + geo)];
        d_dout[0] = if raw < MAX_RAW {
            d_sigma * raw.exp()
        } else {
            0.0
        };
        d_dout[1..].copy_from_slice(&d_cin[..geo]);
        self.density.backward(dacts, d_dout, gd, d_enc, rest);
    }

    /// Updates the occupancy grid (nerfacc's scheme): the density at one random point of
    /// each chosen cell (all cells when `all`, else a random quarter, chosen by `seed`)
    /// raises the cell's running maximum, which otherwise decays by `decay` per update;
    /// a cell is occupied while `σ·step` (its opacity scale over one sample of `step`
    /// world units) exceeds `min(threshold, mean over cells)`. Same bits on any number of
    /// threads (one random stream per cell).
    pub(crate) fn update_occupancy(
        &mut self,
        seed: u64,
        all: bool,
        step: f32,
        threshold: f32,
        decay: f32,
    ) {
        let r = self.occupancy.res;
        let mut density = std::mem::take(&mut self.occupancy.density);
        let me: &Ngp = self;
        const CHUNK: usize = 4096;
        density
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(ci, part)| {
                let mut acts = vec![0.0; me.density.acts_len()];
                for (k, d) in part.iter_mut().enumerate() {
                    let cell = ci * CHUNK + k;
                    let h = mix(seed ^ (cell as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                    if !all && h & 3 != 0 {
                        continue;
                    }
                    let u = [(h >> 8) & 0xFFFF, (h >> 24) & 0xFFFF, (h >> 40) & 0xFFFF]
                        .map(|v| (v as f32 + 0.5) / 65536.0);
                    let c = cell as u32;
                    let (cx, cy, cz) = (c % r, (c / r) % r, c / (r * r));
                    let x =
                        Vec3::new(cx as f32 + u[0], cy as f32 + u[1], cz as f32 + u[2]) / r as f32;
                    let (sigma, _) = me.raw_density(x, &mut acts);
                    *d = (*d * decay).max(sigma);
                }
            });
        let mean = density.iter().map(|&d| (d * step) as f64).sum::<f64>() / density.len() as f64;
        let thr = (threshold as f64).min(mean) as f32;
        for (b, &d) in self.occupancy.bits.iter_mut().zip(&density) {
            *b = d * step > thr;
        }
        self.occupancy.density = density;
    }
}

#[inline(always)]
pub(crate) fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// SplitMix64's finalizer: 64 well-mixed bits from `z`.
#[inline(always)]
pub(crate) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
