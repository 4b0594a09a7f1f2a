//! Pairs of overlapping boxes.
//!
//! The tests of [`overlap`](super::overlap) that ask which edges, runs of edges or rings
//! lie near one another all come down to the pairs of axis-aligned boxes that overlap.
//! Sorting the boxes by their least x and comparing each with those after it until one
//! starts right of its end visits every pair whose x ranges overlap: quadratic as soon as
//! a few long boxes span the drawing (a baseline, a stroke's long sides, a glyph's stem).
//! [`overlapping_pairs`] first bins the boxes into horizontal strips (about `√n` of them;
//! a box goes into every strip its y range meets) and sweeps each strip by x, so a long
//! horizontal box meets only its strip's boxes and a long vertical one is thin in each
//! strip. A pair is reported in the strip holding the top of the two boxes' common y
//! range, so once.
//!
//! Boxes are `[x0, y0, x1, y1]` in any unit, closed: two boxes that share only a side or
//! a corner overlap.

/// How [`overlapping_pairs`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Pairs {
    /// Every overlapping pair was passed.
    All,
    /// The callback asked to stop.
    Stopped,
    /// More comparisons than the budget, or a box with a coordinate that is not finite:
    /// not every pair was passed.
    Unsure,
}

/// Reusable buffers of [`overlapping_pairs`].
#[derive(Default)]
pub(crate) struct Scratch {
    /// Box indices, strip after strip, each strip sorted by least x.
    order: Vec<u32>,
    /// Where each strip starts in `order` (one more entry: the end).
    starts: Vec<u32>,
    /// Where the next box goes in each strip, while filling.
    next: Vec<u32>,
}

/// Calls `f(i, j)`, `i < j`, once for every pair of `boxes` that overlap (closed boxes),
/// until `f` returns `false`. Gives up ([`Pairs::Unsure`]) after `budget` comparisons of
/// boxes whose x ranges overlap within a strip, which bounds the time by
/// `O(n log n + budget)` plus the strips' insertions (at most `16 n`, else one strip).
pub(crate) fn overlapping_pairs(
    boxes: &[[f64; 4]],
    budget: usize,
    scratch: &mut Scratch,
    mut f: impl FnMut(usize, usize) -> bool,
) -> Pairs {
    let n = boxes.len();
    if n < 2 {
        return Pairs::All;
    }
    if n > u32::MAX as usize || boxes.iter().flatten().any(|v| !v.is_finite()) {
        return Pairs::Unsure;
    }
    let (ylo, yhi) = boxes
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
            (lo.min(b[1]), hi.max(b[3]))
        });
    // About √n strips, each a box height at least; one when the boxes would be copied
    // into too many.
    let mut strips = ((n as f64).sqrt() as usize).clamp(1, 1024);
    // Strips per unit of y (a product, not a quotient, in the loops below).
    let mut per = strips as f64 / (yhi - ylo);
    let strip_of = |y: f64, strips: usize, per: f64| -> usize {
        if strips == 1 {
            0
        } else {
            (((y - ylo) * per) as usize).min(strips - 1)
        }
    };
    if !(per > 0.0 && per.is_finite()) {
        strips = 1;
    } else {
        let copies: usize = boxes
            .iter()
            .map(|b| strip_of(b[3], strips, per) - strip_of(b[1], strips, per) + 1)
            .sum();
        if copies > 16 * n {
            strips = 1;
        }
    }
    if strips == 1 {
        per = 1.0;
    }
    // Counting sort into strips.
    let Scratch {
        order,
        starts,
        next,
    } = scratch;
    starts.clear();
    starts.resize(strips + 1, 0);
    for b in boxes {
        for s in strip_of(b[1], strips, per)..=strip_of(b[3], strips, per) {
            starts[s + 1] += 1;
        }
    }
    for s in 0..strips {
        starts[s + 1] += starts[s];
    }
    order.clear();
    order.resize(starts[strips] as usize, 0);
    next.clear();
    next.extend_from_slice(&starts[..strips]);
    for (i, b) in boxes.iter().enumerate() {
        for s in strip_of(b[1], strips, per)..=strip_of(b[3], strips, per) {
            order[next[s] as usize] = i as u32;
            next[s] += 1;
        }
    }
    let mut tests = 0usize;
    for s in 0..strips {
        let strip = &mut order[starts[s] as usize..starts[s + 1] as usize];
        strip.sort_unstable_by(|&a, &b| boxes[a as usize][0].total_cmp(&boxes[b as usize][0]));
        for a in 0..strip.len() {
            let i = strip[a] as usize;
            let bi = boxes[i];
            for &j in &strip[a + 1..] {
                let j = j as usize;
                let bj = boxes[j];
                if bj[0] > bi[2] {
                    break;
                }
                tests += 1;
                if tests > budget {
                    return Pairs::Unsure;
                }
                if bj[1] > bi[3] || bi[1] > bj[3] {
                    continue;
                }
                // Reported in the strip of the top of the common y range only.
                if strips > 1 && strip_of(bi[1].max(bj[1]), strips, per) != s {
                    continue;
                }
                if !f(i.min(j), i.max(j)) {
                    return Pairs::Stopped;
                }
            }
        }
    }
    Pairs::All
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn brute(boxes: &[[f64; 4]]) -> Vec<(usize, usize)> {
        let mut v = Vec::new();
        for i in 0..boxes.len() {
            for j in i + 1..boxes.len() {
                let (a, b) = (boxes[i], boxes[j]);
                if a[0] <= b[2] && b[0] <= a[2] && a[1] <= b[3] && b[1] <= a[3] {
                    v.push((i, j));
                }
            }
        }
        v
    }

    /// Random boxes: small ones, long horizontal and vertical ones, some touching only at
    /// a side (integer coordinates), some of zero size.
    fn random_boxes(rng: &mut Rng, n: usize) -> Vec<[f64; 4]> {
        (0..n)
            .map(|k| {
                let x = (rng.range(0.0, 100.0)).floor();
                let y = (rng.range(0.0, 100.0)).floor();
                let (w, h) = match k % 5 {
                    0 => (rng.range(0.0, 90.0), rng.range(0.0, 2.0)),
                    1 => (rng.range(0.0, 2.0), rng.range(0.0, 90.0)),
                    2 => (0.0, 0.0),
                    3 => ((rng.range(0.0, 4.0)).floor(), (rng.range(0.0, 4.0)).floor()),
                    _ => (rng.range(0.0, 5.0), rng.range(0.0, 5.0)),
                };
                [x, y, x + w, y + h]
            })
            .collect()
    }

    #[test]
    fn every_overlapping_pair_once() {
        let mut rng = Rng::new(7);
        let mut scratch = Scratch::default();
        for n in [0, 1, 2, 3, 10, 50, 300, 1000] {
            let boxes = random_boxes(&mut rng, n);
            let mut got = Vec::new();
            let end = overlapping_pairs(&boxes, usize::MAX, &mut scratch, |i, j| {
                got.push((i, j));
                true
            });
            assert_eq!(end, Pairs::All);
            got.sort_unstable();
            assert_eq!(got, brute(&boxes), "{n} boxes");
        }
    }

    #[test]
    fn stops_and_gives_up() {
        let mut rng = Rng::new(3);
        let boxes = random_boxes(&mut rng, 400);
        let mut scratch = Scratch::default();
        let mut seen = 0;
        let end = overlapping_pairs(&boxes, usize::MAX, &mut scratch, |_, _| {
            seen += 1;
            seen < 5
        });
        assert_eq!((end, seen), (Pairs::Stopped, 5));
        let end = overlapping_pairs(&boxes, 10, &mut scratch, |_, _| true);
        assert_eq!(end, Pairs::Unsure);
        // Identical boxes: every pair overlaps; the budget bounds the work.
        let same = vec![[0.0, 0.0, 1.0, 1.0]; 5000];
        assert_eq!(
            overlapping_pairs(&same, 1 << 16, &mut scratch, |_, _| true),
            Pairs::Unsure
        );
        let nan = vec![[0.0, 0.0, 1.0, 1.0], [f64::NAN, 0.0, 1.0, 1.0]];
        assert_eq!(
            overlapping_pairs(&nan, 100, &mut scratch, |_, _| true),
            Pairs::Unsure
        );
    }
}
