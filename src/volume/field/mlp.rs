//! A tiny fully connected network evaluated one sample at a time, fused forward and
//! backward, `f32`: hidden layers with ReLU, a linear output layer.
//!
//! Layer `k` maps `n_in` to `n_out` values with weights stored input-major
//! (`w[i·n_out + j]` from input `i` to output `j`) followed by `n_out` biases. So the
//! forward pass is one `axpy` per input over the contiguous outputs, the weight gradient
//! one `axpy` per input, and the input gradient a dot product per input, all over
//! contiguous slices the compiler vectorizes (no BLAS: the layers are 64 wide).
//! Activations of one sample are
//! kept in one buffer (`input, hidden₁, …, output`) for the backward pass.

/// A network's layer sizes and parameters.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Mlp {
    /// `[n_in, hidden…, n_out]`.
    dims: Vec<usize>,
    /// Start of each layer's weights in `params`.
    offsets: Vec<usize>,
    /// All weights and biases, layer by layer.
    pub(crate) params: Vec<f32>,
}

/// Parameters of a network with layer sizes `dims`.
pub(crate) fn param_count(dims: &[usize]) -> usize {
    dims.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
}

impl Mlp {
    /// A network with layer sizes `dims` (at least input and output) and weights uniform
    /// in `±√(6 / (n_in + n_out))` (Glorot), biases 0, from `seed`.
    pub(crate) fn new(dims: &[usize], seed: u64) -> Mlp {
        let mut rng = crate::rng::Rng::new(seed);
        let mut params = Vec::with_capacity(param_count(dims));
        for w in dims.windows(2) {
            let a = (6.0 / (w[0] + w[1]) as f32).sqrt();
            params.extend((0..w[0] * w[1]).map(|_| (rng.uniform() * 2.0 - 1.0) * a));
            params.extend(std::iter::repeat_n(0.0, w[1]));
        }
        Mlp::from_params(dims, params)
    }

    /// A network from its parameters (`param_count(dims)` of them).
    pub(crate) fn from_params(dims: &[usize], params: Vec<f32>) -> Mlp {
        assert!(dims.len() >= 2 && params.len() == param_count(dims));
        let mut offsets = Vec::new();
        let mut at = 0;
        for w in dims.windows(2) {
            offsets.push(at);
            at += w[0] * w[1] + w[1];
        }
        Mlp {
            dims: dims.to_vec(),
            offsets,
            params,
        }
    }

    /// Layer sizes.
    pub(crate) fn dims(&self) -> &[usize] {
        &self.dims
    }

    /// Floats of one sample's activations: the sum of the layer sizes.
    pub(crate) fn acts_len(&self) -> usize {
        self.dims.iter().sum()
    }

    /// Output size.
    pub(crate) fn n_out(&self) -> usize {
        *self.dims.last().unwrap()
    }

    /// Forward pass of one sample: `acts` starts with the input (set by the caller) and
    /// receives every layer's output after it; the network's output is its last
    /// [`n_out`](Self::n_out) values.
    #[inline]
    pub(crate) fn forward(&self, acts: &mut [f32]) {
        let mut at = 0;
        let last = self.dims.len() - 2;
        for (k, w) in self.dims.windows(2).enumerate() {
            let (n_in, n_out) = (w[0], w[1]);
            let (head, tail) = acts.split_at_mut(at + n_in);
            let x = &head[at..];
            let y = &mut tail[..n_out];
            let p = &self.params[self.offsets[k]..self.offsets[k] + n_in * n_out + n_out];
            let (wt, b) = p.split_at(n_in * n_out);
            match n_out {
                64 => fwd_fixed::<64>(x, wt, b, y),
                32 => fwd_fixed::<32>(x, wt, b, y),
                16 => fwd_fixed::<16>(x, wt, b, y),
                _ => fwd_any(x, wt, b, y),
            }
            if k < last {
                for v in y.iter_mut() {
                    *v = v.max(0.0);
                }
            }
            at += n_in;
        }
    }

    /// Backward pass of one sample whose activations `acts` came from
    /// [`forward`](Self::forward): adds `∂L/∂params` to `grad` given `d_out = ∂L/∂output`,
    /// and writes `∂L/∂input` into `d_in`. `scratch` holds at least twice the widest layer.
    #[inline]
    pub(crate) fn backward(
        &self,
        acts: &[f32],
        d_out: &[f32],
        grad: &mut [f32],
        d_in: &mut [f32],
        scratch: &mut [f32],
    ) {
        let widest = *self.dims.iter().max().unwrap();
        let (dy_buf, dx_buf) = scratch.split_at_mut(widest);
        let n_layers = self.dims.len() - 1;
        let mut end = acts.len();
        dy_buf[..d_out.len()].copy_from_slice(d_out);
        for k in (0..n_layers).rev() {
            let (n_in, n_out) = (self.dims[k], self.dims[k + 1]);
            let y = &acts[end - n_out..end];
            let x = &acts[end - n_out - n_in..end - n_out];
            let dy = &mut dy_buf[..n_out];
            if k + 1 < n_layers {
                // ReLU: no gradient where the output was clipped to 0.
                for (d, &v) in dy.iter_mut().zip(y) {
                    if v <= 0.0 {
                        *d = 0.0;
                    }
                }
            }
            let off = self.offsets[k];
            let g = &mut grad[off..off + n_in * n_out + n_out];
            let (gw, gb) = g.split_at_mut(n_in * n_out);
            for (b, d) in gb.iter_mut().zip(dy.iter()) {
                *b += d;
            }
            let wt = &self.params[off..off + n_in * n_out];
            let dx = &mut dx_buf[..n_in];
            match n_out {
                64 => bwd_fixed::<64>(x, wt, dy, gw, dx),
                32 => bwd_fixed::<32>(x, wt, dy, gw, dx),
                16 => bwd_fixed::<16>(x, wt, dy, gw, dx),
                _ => bwd_any(x, wt, dy, gw, dx),
            }
            end -= n_out;
            if k == 0 {
                d_in[..n_in].copy_from_slice(dx);
            } else {
                dy_buf[..n_in].copy_from_slice(dx);
            }
        }
    }
}

/// `y = b + Σ_i x[i]·w[i, ·]` for `N` outputs, the accumulator in registers.
#[inline(always)]
fn fwd_fixed<const N: usize>(x: &[f32], wt: &[f32], b: &[f32], y: &mut [f32]) {
    let mut acc: [f32; N] = b.try_into().expect("N biases");
    for (i, &xi) in x.iter().enumerate() {
        if xi == 0.0 {
            continue;
        }
        let row: &[f32; N] = wt[i * N..(i + 1) * N].try_into().expect("a row");
        for j in 0..N {
            acc[j] += xi * row[j];
        }
    }
    y.copy_from_slice(&acc);
}

/// [`fwd_fixed`] for any output count.
#[inline(always)]
fn fwd_any(x: &[f32], wt: &[f32], b: &[f32], y: &mut [f32]) {
    let n_out = y.len();
    y.copy_from_slice(b);
    for (i, &xi) in x.iter().enumerate() {
        if xi == 0.0 {
            continue;
        }
        let row = &wt[i * n_out..(i + 1) * n_out];
        for (yj, wj) in y.iter_mut().zip(row) {
            *yj += xi * wj;
        }
    }
}

/// One layer's backward for `N` outputs: `gw[i, ·] += x[i]·dy`, `dx[i] = w[i, ·]·dy`.
#[inline(always)]
fn bwd_fixed<const N: usize>(x: &[f32], wt: &[f32], dy: &[f32], gw: &mut [f32], dx: &mut [f32]) {
    let d: &[f32; N] = dy.try_into().expect("N gradients");
    for i in 0..x.len() {
        let row: &[f32; N] = wt[i * N..(i + 1) * N].try_into().expect("a row");
        dx[i] = dot(row, d);
        let xi = x[i];
        if xi != 0.0 {
            let grow: &mut [f32; N] = (&mut gw[i * N..(i + 1) * N]).try_into().expect("a row");
            for j in 0..N {
                grow[j] += xi * d[j];
            }
        }
    }
}

/// [`bwd_fixed`] for any output count.
#[inline(always)]
fn bwd_any(x: &[f32], wt: &[f32], dy: &[f32], gw: &mut [f32], dx: &mut [f32]) {
    let n_out = dy.len();
    for i in 0..x.len() {
        let row = &wt[i * n_out..(i + 1) * n_out];
        dx[i] = dot(row, dy);
        let xi = x[i];
        if xi != 0.0 {
            let grow = &mut gw[i * n_out..(i + 1) * n_out];
            for (gj, dj) in grow.iter_mut().zip(dy) {
                *gj += xi * dj;
            }
        }
    }
}

/// A dot product summed in 8 lanes (so that it vectorizes), then the lanes in order.
#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let n8 = a.len() / 8 * 8;
    for (ca, cb) in a[..n8].chunks_exact(8).zip(b[..n8].chunks_exact(8)) {
        for l in 0..8 {
            acc[l] += ca[l] * cb[l];
        }
    }
    let mut s = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    for i in n8..a.len() {
        s += a[i] * b[i];
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Σ g·output` and its gradient with respect to every parameter and every input,
    /// against central differences in f64 (the same network evaluated in f64 here).
    #[test]
    fn backward_matches_finite_differences() {
        let dims = [5, 16, 9, 3];
        let mut net = Mlp::new(&dims, 11);
        // Nonzero biases so that the check sees them.
        for (i, p) in net.params.iter_mut().enumerate() {
            *p += 0.05 * ((i * 7 % 13) as f32 - 6.0) / 6.0;
        }
        let input = [0.3f32, -0.8, 0.5, 1.2, -0.1];
        let g = [0.7f32, -1.3, 0.4];
        let mut acts = vec![0.0; net.acts_len()];
        acts[..5].copy_from_slice(&input);
        net.forward(&mut acts);
        let mut grad = vec![0.0; net.params.len()];
        let mut d_in = vec![0.0; 5];
        let mut scratch = vec![0.0; 32];
        net.backward(&acts, &g, &mut grad, &mut d_in, &mut scratch);

        let f64_loss = |params: &[f64], x: &[f64]| -> f64 {
            let mut v = x.to_vec();
            let mut off = 0;
            for (k, w) in dims.windows(2).enumerate() {
                let mut y: Vec<f64> = params[off + w[0] * w[1]..off + w[0] * w[1] + w[1]].to_vec();
                for i in 0..w[0] {
                    for j in 0..w[1] {
                        y[j] += v[i] * params[off + i * w[1] + j];
                    }
                }
                if k + 2 < dims.len() {
                    y.iter_mut().for_each(|t| *t = t.max(0.0));
                }
                off += w[0] * w[1] + w[1];
                v = y;
            }
            v.iter().zip(&g).map(|(a, b)| a * *b as f64).sum()
        };
        let p64: Vec<f64> = net.params.iter().map(|&p| p as f64).collect();
        let x64: Vec<f64> = input.iter().map(|&p| p as f64).collect();
        // The f32 forward agrees with the f64 one.
        let out: f64 = acts[acts.len() - 3..]
            .iter()
            .zip(&g)
            .map(|(a, b)| (*a * *b) as f64)
            .sum();
        assert!((out - f64_loss(&p64, &x64)).abs() < 1e-5);
        let h = 1e-6;
        let mut nonzero = 0;
        for i in 0..p64.len() {
            let (mut a, mut b) = (p64.clone(), p64.clone());
            a[i] += h;
            b[i] -= h;
            let fd = (f64_loss(&a, &x64) - f64_loss(&b, &x64)) / (2.0 * h);
            assert!(
                (fd - grad[i] as f64).abs() < 1e-4 * (1.0 + fd.abs()),
                "parameter {i}: {} vs {fd}",
                grad[i]
            );
            nonzero += (grad[i] != 0.0) as usize;
        }
        assert!(nonzero > p64.len() / 3, "{nonzero} of {}", p64.len());
        for i in 0..5 {
            let (mut a, mut b) = (x64.clone(), x64.clone());
            a[i] += h;
            b[i] -= h;
            let fd = (f64_loss(&p64, &a) - f64_loss(&p64, &b)) / (2.0 * h);
            assert!(
                (fd - d_in[i] as f64).abs() < 1e-4 * (1.0 + fd.abs()),
                "input {i}"
            );
        }
    }

    #[test]
    fn dot_sums_every_lane_and_the_tail() {
        let a: Vec<f32> = (0..19).map(|i| i as f32).collect();
        let b: Vec<f32> = (0..19).map(|i| 1.0 + (i % 3) as f32).collect();
        let want: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert_eq!(dot(&a, &b), want);
    }
}
