//! The per-pixel inner loops of the splat renderer, eight pixels at a time.
//!
//! A tile row of [`TILE`] = 16 pixels is two [`f32x8`] vectors. [`blend_row`] blends one
//! splat into a row front to back (the forward pass) and [`grad_row`] undoes it back to
//! front while summing its gradient terms (the backward pass). Written with the `wide`
//! crate's portable vectors rather than left to the compiler's auto-vectorizer, which
//! declined these loops on plain x86-64 (they ran scalar, at about 2.5× the time).
//!
//! A splat's opacity at a pixel `(dx, dy)` from its center, conic `[a, b, c]`, peak
//! opacity `o`: `power = −½(a·dx² + c·dy²) − b·dx·dy`, `raw = o·exp(power)`,
//! `alpha = min(raw, MAX_ALPHA)`, and the pixel counts when `power ≤ 0` and
//! `alpha ≥ MIN_ALPHA`. Each lane computes exactly what the scalar reference in the
//! tests does (the same operations in the same order; IEEE arithmetic is lane-wise), so
//! the vector width changes no bits.

use wide::{f32x8, i32x8, u32x8};

use super::render::{MAX_ALPHA, MIN_ALPHA, Projected, TILE, floor_within};

/// Vectors per tile row.
pub(crate) const HALVES: usize = TILE as usize / 8;

/// Pixel-center offsets within a tile row, `x + 0.5`, as two vectors.
const CENTERS: [f32x8; HALVES] = [
    f32x8::new([0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5]),
    f32x8::new([8.5, 9.5, 10.5, 11.5, 12.5, 13.5, 14.5, 15.5]),
];

/// A row of one per-pixel quantity.
pub(crate) type Row = [f32x8; HALVES];

/// `exp(x)` for `x ≤ 0`, lane by lane, without a library call or a float-to-integer
/// conversion: Cody–Waite reduction `x = n·ln 2 + r`, `|r| ≤ ln 2 / 2`, with `n` rounded
/// to nearest by adding 1.5·2²³ (which leaves it in the low mantissa bits), a degree-6
/// Taylor polynomial of `exp(r)` (relative error below 3·10⁻⁷) and `2ⁿ` built from its
/// bits. Inputs below −87 give `exp(−87)` (≈ 1.6·10⁻³⁸), negligible wherever it is used.
#[inline(always)]
fn exp_neg8(x: f32x8) -> f32x8 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    const ROUND: f32 = 12_582_912.0;
    let x = x.max(f32x8::splat(-87.0)).min(f32x8::ZERO);
    let shifted = x * f32x8::splat(LOG2E) + f32x8::splat(ROUND);
    let nf = shifted - f32x8::splat(ROUND);
    let n = shifted.to_bits() - u32x8::splat(ROUND.to_bits());
    let r = x - nf * f32x8::splat(LN2_HI) - nf * f32x8::splat(LN2_LO);
    let c = |v: f32| f32x8::splat(v);
    let p = c(1.0)
        + r * (c(1.0)
            + r * (c(0.5)
                + r * (c(1.0 / 6.0)
                    + r * (c(1.0 / 24.0) + r * (c(1.0 / 120.0) + r * c(1.0 / 720.0))))));
    p * f32x8::from_bits((n + u32x8::splat(127)) << 23)
}

/// Splat `p`'s opacity at eight pixels `(dx, dy)` from its center:
/// `(alpha, raw, exp(power), counts)` (see the module's notes), with `counts` a lane
/// mask.
#[inline(always)]
fn alpha8(p: &Projected, dx: f32x8, dy: f32) -> (f32x8, f32x8, f32x8, f32x8) {
    let [a, b, c] = p.conic.map(f32x8::splat);
    let dy = f32x8::splat(dy);
    let power = f32x8::splat(-0.5) * (a * dx * dx + c * dy * dy) - b * dx * dy;
    let g = exp_neg8(power);
    let raw = f32x8::splat(p.opacity) * g;
    let alpha = raw.min(f32x8::splat(MAX_ALPHA));
    let counts = power.simd_le(f32x8::ZERO) & alpha.simd_ge(f32x8::splat(MIN_ALPHA));
    (alpha, raw, g, counts)
}

/// Splat `p`'s opacity at one pixel `(dx, dy)` from its center, the same bits as lane
/// by lane in [`alpha8`], and whether the pixel counts.
#[inline]
pub(crate) fn alpha1(p: &Projected, dx: f32, dy: f32) -> (f32, bool) {
    let (alpha, _, _, counts) = alpha8(p, f32x8::splat(dx), dy);
    (alpha.to_array()[0], counts.to_bitmask() & 1 != 0)
}

/// The halves `[h0, h1)` of a tile row that splat `p` can reach: those with a pixel
/// center within a pixel of the row's chord of the contour where the opacity falls to
/// 1/255 (`a·dx² + 2b·dx·dy + c·dy² ≤ reach`). Pixels outside count for nothing, so
/// skipping them changes no bits; the one-pixel margin covers rounding.
#[inline]
pub(crate) fn row_halves(p: &Projected, left: f32, dy: f32) -> (usize, usize) {
    let [a, b, c] = p.conic;
    let disc = b * b * dy * dy - a * (c * dy * dy - p.reach);
    if !(disc >= 0.0) {
        return (0, 0);
    }
    let root = disc.sqrt();
    // The chord in pixel-center offsets from the row's start: x + 0.5 − left ∈ [lo, hi].
    let lo = (-b * dy - root) / a + left - 0.5 - 1.0;
    let hi = (-b * dy + root) / a + left - 0.5 + 1.0;
    (
        floor_within(lo / 8.0, HALVES),
        floor_within(hi / 8.0 + 1.0, HALVES),
    )
}

/// A lane mask (all bits set or clear) of floats as one of integers.
#[inline(always)]
fn int_mask(m: f32x8) -> i32x8 {
    m.to_bits().cast_signed()
}

/// One row of a tile's pixels while blending.
#[derive(Clone, Copy)]
pub(crate) struct BlendRow {
    /// Accumulated color (without the background yet).
    pub rgb: [Row; 3],
    /// Transmittance so far.
    pub t: Row,
    /// One past the last blended entry of the tile's list (0: none).
    pub end: [i32x8; HALVES],
    /// All bits set while the pixel blends, clear once its transmittance would fall below
    /// the early stop (and from the start past the image's edge).
    pub live: Row,
}

impl BlendRow {
    /// A row of `width` live pixels (≤ [`TILE`]), the rest done from the start.
    pub(crate) fn new(width: usize) -> BlendRow {
        let live: [f32; TILE as usize] =
            std::array::from_fn(|x| f32::from_bits(if x < width { u32::MAX } else { 0 }));
        BlendRow {
            rgb: [[f32x8::ZERO; HALVES]; 3],
            t: [f32x8::ONE; HALVES],
            end: [i32x8::ZERO; HALVES],
            live: [0, 1].map(|h| f32x8::new(live[8 * h..8 * h + 8].try_into().unwrap())),
        }
    }
}

/// Blends splat `p`, entry `entry − 1` of the tile's list, into `row`, whose pixel
/// centers lie `dy` below and `x + 0.5 − left` right of the splat's center. Returns how
/// many pixels stopped (transmittance would fall below `eps`; that splat is not blended).
#[inline]
pub(crate) fn blend_row(
    row: &mut BlendRow,
    p: &Projected,
    left: f32,
    dy: f32,
    entry: i32,
    eps: f32,
) -> u32 {
    let mut stopped = 0;
    let (h0, h1) = row_halves(p, left, dy);
    for h in h0..h1 {
        let dx = CENTERS[h] - f32x8::splat(left);
        let (alpha, _, _, counts) = alpha8(p, dx, dy);
        let t = row.t[h];
        let next = t * (f32x8::ONE - alpha);
        let counts = counts & row.live[h];
        let stop = counts & next.simd_lt(f32x8::splat(eps));
        let blend = counts & !stop;
        let weight = blend.select(alpha * t, f32x8::ZERO);
        for (c, channel) in row.rgb.iter_mut().enumerate() {
            channel[h] += f32x8::splat(p.color[c]) * weight;
        }
        row.t[h] = blend.select(next, t);
        row.end[h] = int_mask(blend).select(i32x8::splat(entry), row.end[h]);
        row.live[h] &= !stop;
        stopped += stop.to_bitmask().count_ones();
    }
    stopped
}

/// One row of a tile's pixels in the backward pass.
#[derive(Clone, Copy)]
pub(crate) struct GradRow {
    /// ∂L/∂rgb.
    pub d: [Row; 3],
    /// Transmittance in front of the splat after the current one.
    pub t: Row,
    /// Color that the splats after the current one add, background included.
    pub behind: [Row; 3],
    /// One past the last blended entry of the tile's list (0 past the image's edge).
    pub end: [i32x8; HALVES],
}

/// Undoes entry `k` of the tile's list (splat `p`) on `row` and adds its per-pixel
/// gradient terms to `lanes` (the nine [`PairGrad`](super::backward) components, per
/// pixel column).
#[inline]
pub(crate) fn grad_row(
    row: &mut GradRow,
    lanes: &mut [Row; 9],
    p: &Projected,
    left: f32,
    dy: f32,
    k: i32,
) {
    let [ca, cb, cc] = p.conic.map(f32x8::splat);
    let color = [p.color.x, p.color.y, p.color.z].map(f32x8::splat);
    let dyv = f32x8::splat(dy);
    let (h0, h1) = row_halves(p, left, dy);
    for h in h0..h1 {
        let dx = CENTERS[h] - f32x8::splat(left);
        let (alpha, raw, g, counts) = alpha8(p, dx, dy);
        let on = counts & f32x8::from_bits(i32x8::splat(k).simd_lt(row.end[h]).cast_unsigned());
        let keep = f32x8::ONE - alpha;
        let t = row.t[h];
        let t_here = on.select(t / keep, t);
        let weight = on.select(alpha * t_here, f32x8::ZERO);
        let d = [row.d[0][h], row.d[1][h], row.d[2][h]];
        let mut d_alpha = f32x8::ZERO;
        for c in 0..3 {
            lanes[6 + c][h] += d[c] * weight;
            let term = d[c] * (color[c] * t_here - row.behind[c][h] / keep);
            d_alpha = if c == 0 { term } else { d_alpha + term };
            row.behind[c][h] += color[c] * weight;
        }
        row.t[h] = t_here;
        // A clamped opacity passes no gradient to the opacity or the shape.
        let free = on & raw.simd_lt(f32x8::splat(MAX_ALPHA));
        let d_alpha = free.select(d_alpha, f32x8::ZERO);
        lanes[5][h] += d_alpha * g;
        // ∂L/∂power, with power = −½(a·dx² + c·dy²) − b·dx·dy, dx = px − center.
        let gp = d_alpha * raw;
        let half = f32x8::splat(-0.5);
        lanes[0][h] += gp * (ca * dx + cb * dyv);
        lanes[1][h] += gp * (cc * dyv + cb * dx);
        lanes[2][h] += half * gp * dx * dx;
        lanes[3][h] += -gp * dx * dyv;
        lanes[4][h] += half * gp * dyv * dyv;
    }
}

/// The sum of a row's sixteen lanes, in lane order.
#[inline]
pub(crate) fn lane_sum(row: &Row) -> f32 {
    row.iter().flat_map(|v| v.to_array()).sum()
}

/// Lane `x` of a row.
#[inline]
pub(crate) fn lane(row: &Row, x: usize) -> f32 {
    row[x / 8].as_array()[x % 8]
}

/// Sets lane `x` of a row.
#[inline]
pub(crate) fn set_lane(row: &mut Row, x: usize, v: f32) {
    let mut a = row[x / 8].to_array();
    a[x % 8] = v;
    row[x / 8] = f32x8::new(a);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scalar reference of [`exp_neg8`].
    fn exp_neg(x: f32) -> f32 {
        const LOG2E: f32 = std::f32::consts::LOG2_E;
        const LN2_HI: f32 = 0.693_359_4;
        const LN2_LO: f32 = -2.121_944_4e-4;
        const ROUND: f32 = 12_582_912.0;
        let x = x.clamp(-87.0, 0.0);
        let shifted = x * LOG2E + ROUND;
        let nf = shifted - ROUND;
        let n = shifted.to_bits().wrapping_sub(ROUND.to_bits());
        let r = x - nf * LN2_HI - nf * LN2_LO;
        let p = 1.0
            + r * (1.0
                + r * (0.5
                    + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
        p * f32::from_bits(n.wrapping_add(127) << 23)
    }

    /// Scalar reference of [`alpha8`].
    fn alpha_at(o: f32, [a, b, c]: [f32; 3], dx: f32, dy: f32) -> (f32, f32, f32, bool) {
        let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
        let g = exp_neg(power);
        let raw = o * g;
        let alpha = raw.min(MAX_ALPHA);
        (alpha, raw, g, power <= 0.0 && alpha >= MIN_ALPHA)
    }

    #[test]
    fn vector_alpha_matches_the_scalar_reference_bits_and_skips_nothing_that_counts() {
        let mut s = 12345u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..2000 {
            // Positive definite, as every projected conic is.
            let (a, c) = (next() * 0.5 + 1e-3, next() * 0.5 + 1e-3);
            let conic = [a, (next() - 0.5) * 1.9 * (a * c).sqrt(), c];
            let p = Projected {
                index: 0,
                mean2d: glam::Vec2::new(next() * 16.0, next() * 16.0),
                conic,
                depth: 1.0,
                radius: 8.0,
                extent: glam::Vec2::splat(8.0),
                reach: 2.0,
                color: glam::Vec3::ONE,
                opacity: next(),
                compensation: 1.0,
            };
            let (left, dy) = (next() * 20.0 - 2.0, next() * 20.0 - 10.0);
            let mut p = p;
            p.reach = 2.0 * (p.opacity / MIN_ALPHA).max(1.0).ln();
            let (h0, h1) = row_halves(&p, left, dy);
            for h in 0..HALVES {
                let dx = CENTERS[h] - f32x8::splat(left);
                let (alpha, raw, g, counts) = alpha8(&p, dx, dy);
                for l in 0..8 {
                    let x = (8 * h + l) as f32 + 0.5 - left;
                    let want = alpha_at(p.opacity, conic, x, dy);
                    assert_eq!(alpha.to_array()[l].to_bits(), want.0.to_bits());
                    assert_eq!(raw.to_array()[l].to_bits(), want.1.to_bits());
                    assert_eq!(g.to_array()[l].to_bits(), want.2.to_bits());
                    assert_eq!(counts.to_bits().to_array()[l] != 0, want.3);
                    assert!(
                        !want.3 || (h0..h1).contains(&h),
                        "a counted pixel is skipped"
                    );
                }
            }
        }
    }

    #[test]
    fn vector_exp_matches_the_scalar_bits() {
        let mut x = 0.0f32;
        while x > -100.0 {
            let v = exp_neg8(f32x8::splat(x)).to_array()[3];
            assert_eq!(v.to_bits(), exp_neg(x).to_bits(), "at {x}");
            let exact = (x as f64).exp();
            if x > -80.0 {
                assert!(
                    ((v as f64 - exact) / exact).abs() < 3e-7,
                    "at {x}: {v} vs {exact}"
                );
            }
            x -= 0.013_7;
        }
    }

    #[test]
    fn lanes_read_and_write() {
        let mut row: Row = [f32x8::ZERO; HALVES];
        for x in 0..16 {
            set_lane(&mut row, x, x as f32);
        }
        assert_eq!(lane(&row, 11), 11.0);
        assert_eq!(lane_sum(&row), 120.0);
    }
}
