//! feTile and feDisplacementMap: resamplings by whole pixels, whose adjoints sum each
//! output's gradient back onto the pixel it copies.

/// For each pixel of a `w × h` image, the pixel it copies, or `None` (transparent).
pub(crate) type Sources = Vec<Option<usize>>;

/// feTile: the tile `tile = [x0, y0, x1, y1]` (image pixels, inside the image, not
/// empty) repeated with a copy's corner at `anchor`, as resvg's repeating pattern places
/// it.
pub(crate) fn tile_sources(w: usize, h: usize, tile: [usize; 4], anchor: [i64; 2]) -> Sources {
    let (tw, th) = ((tile[2] - tile[0]) as i64, (tile[3] - tile[1]) as i64);
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h as i64 {
        let sy = tile[1] as i64 + (y - anchor[1]).rem_euclid(th);
        for x in 0..w as i64 {
            let sx = tile[0] as i64 + (x - anchor[0]).rem_euclid(tw);
            out.push(Some(sy as usize * w + sx as usize));
        }
    }
    out
}

/// feDisplacementMap: pixel `(x, y)` copies `(round(x + (m_x − ½)·scale_x),
/// round(y + (m_y − ½)·scale_y))` where `m_x`, `m_y` are the map's premultiplied channels
/// `channels` at `(x, y)`; transparent where that falls outside. Rounding is to the
/// nearest pixel (half away from zero), so the output is piecewise constant in the map:
/// the map gets no gradient.
pub(crate) fn displacement_sources(
    map: &[[f32; 4]],
    w: usize,
    h: usize,
    scale: [f64; 2],
    channels: [usize; 2],
) -> Sources {
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let m = map[y * w + x];
            // In f32 as resvg computes it.
            let dx = m[channels[0]] - 0.5;
            let dy = m[channels[1]] - 0.5;
            let ox = (x as f32 + dx * scale[0] as f32).round();
            let oy = (y as f32 + dy * scale[1] as f32).round();
            let inside = ox >= 0.0 && oy >= 0.0 && ox < w as f32 && oy < h as f32;
            out.push(inside.then(|| oy as usize * w + ox as usize));
        }
    }
    out
}

/// The resampled image.
pub(crate) fn gather(img: &[[f32; 4]], src: &Sources) -> Vec<[f32; 4]> {
    src.iter().map(|s| s.map_or([0.0; 4], |i| img[i])).collect()
}

/// The adjoint of [`gather`]: `∂L/∂img` from `∂L/∂out`.
pub(crate) fn scatter(g: &[[f32; 4]], src: &Sources, n: usize) -> Vec<[f32; 4]> {
    let mut out = vec![[0.0f32; 4]; n];
    for (gv, s) in g.iter().zip(src) {
        if let Some(i) = *s {
            for c in 0..4 {
                out[i][c] += gv[c];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_repeats_from_the_anchor() {
        // A 5 × 1 image tiled by its pixels 1..3 anchored at x = 1: 2 1 2 1 2 → indices.
        let s = tile_sources(5, 1, [1, 0, 3, 1], [1, 0]);
        assert_eq!(s, vec![Some(2), Some(1), Some(2), Some(1), Some(2)]);
    }

    #[test]
    fn displacement_moves_by_the_map() {
        // Map red 1.0 with scale 2: x + 1; alpha 0: x − 1 (scale 2).
        let map = vec![[1.0, 0.5, 0.0, 0.0]; 4];
        let s = displacement_sources(&map, 4, 1, [2.0, 2.0], [0, 1]);
        assert_eq!(s, vec![Some(1), Some(2), Some(3), None]);
        let s = displacement_sources(&map, 4, 1, [2.0, 2.0], [3, 1]);
        assert_eq!(s, vec![None, Some(0), Some(1), Some(2)]);
    }

    #[test]
    fn scatter_is_the_transpose_of_gather() {
        let mut r = crate::rng::Rng::new(3);
        let (w, h) = (6, 5);
        let rnd = |r: &mut crate::rng::Rng| -> Vec<[f32; 4]> {
            (0..w * h)
                .map(|_| std::array::from_fn(|_| r.uniform()))
                .collect()
        };
        let (x, g, map) = (rnd(&mut r), rnd(&mut r), rnd(&mut r));
        let dot = |a: &[[f32; 4]], b: &[[f32; 4]]| -> f64 {
            a.iter()
                .zip(b)
                .map(|(p, q)| (0..4).map(|c| p[c] as f64 * q[c] as f64).sum::<f64>())
                .sum()
        };
        for src in [
            tile_sources(w, h, [1, 1, 4, 3], [1, 1]),
            displacement_sources(&map, w, h, [5.0, 3.0], [0, 3]),
        ] {
            let lhs = dot(&gather(&x, &src), &g);
            let rhs = dot(&x, &scatter(&g, &src, w * h));
            assert!((lhs - rhs).abs() < 1e-6 * lhs.abs().max(1.0), "{lhs} {rhs}");
        }
    }
}
