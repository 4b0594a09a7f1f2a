//! A small forward-mode dual number for local Jacobians.
//!
//! Stroke outline vertices are short closed-form functions of at most three centerline
//! points and the half width. The stroker is written once, generic over [`Scalar`]; the
//! forward pass runs it on `f64`, the backward pass on [`Jet`] seeded on those seven inputs
//! to get the exact local Jacobian.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Number of seeded inputs of a [`Jet`]: three points (six numbers) and the half width.
pub(crate) const N: usize = 7;

/// Arithmetic the stroker needs.
pub(crate) trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// A constant.
    fn c(v: f64) -> Self;
    /// The value, without derivatives.
    fn v(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// `atan2(self, x)`.
    fn atan2(self, x: Self) -> Self;
    /// `self^e` for a constant exponent (derivative 0 at 0 where it is not finite).
    fn powf(self, e: f64) -> Self;
    /// `f(self)` given its value `v` and derivative `dv` at `self` (a function evaluated
    /// elsewhere, e.g. from a table).
    fn then(self, v: f64, dv: f64) -> Self;
}

impl Scalar for f64 {
    #[inline]
    fn c(v: f64) -> Self {
        v
    }
    #[inline]
    fn v(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline]
    fn sin(self) -> Self {
        f64::sin(self)
    }
    #[inline]
    fn cos(self) -> Self {
        f64::cos(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        f64::atan2(self, x)
    }
    #[inline]
    fn powf(self, e: f64) -> Self {
        f64::powf(self, e)
    }
    #[inline]
    fn then(self, v: f64, _dv: f64) -> Self {
        v
    }
}

/// A value with its derivatives with respect to `K` inputs ([`N`] unless said).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Jet<const K: usize = N> {
    /// Value.
    pub(crate) v: f64,
    /// Partial derivatives.
    pub(crate) d: [f64; K],
}

impl<const K: usize> Jet<K> {
    /// The input number `i` with value `v`.
    pub(crate) fn var(v: f64, i: usize) -> Self {
        let mut d = [0.0; K];
        d[i] = 1.0;
        Jet { v, d }
    }

    #[inline]
    fn chain(self, v: f64, dv: f64) -> Self {
        Jet {
            v,
            d: self.d.map(|x| x * dv),
        }
    }
}

impl<const K: usize> Add for Jet<K> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a += b;
        }
        Jet { v: self.v + o.v, d }
    }
}

impl<const K: usize> Sub for Jet<K> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        self + (-o)
    }
}

impl<const K: usize> Neg for Jet<K> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Jet {
            v: -self.v,
            d: self.d.map(|x| -x),
        }
    }
}

impl<const K: usize> Mul for Jet<K> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut d = [0.0; K];
        for (i, x) in d.iter_mut().enumerate() {
            *x = self.d[i] * o.v + self.v * o.d[i];
        }
        Jet { v: self.v * o.v, d }
    }
}

impl<const K: usize> Div for Jet<K> {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        let v = self.v / o.v;
        let mut d = [0.0; K];
        for (i, x) in d.iter_mut().enumerate() {
            *x = (self.d[i] - v * o.d[i]) / o.v;
        }
        Jet { v, d }
    }
}

impl<const K: usize> Scalar for Jet<K> {
    fn c(v: f64) -> Self {
        Jet { v, d: [0.0; K] }
    }
    fn v(self) -> f64 {
        self.v
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, if s > 0.0 { 0.5 / s } else { 0.0 })
    }
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = self.v * self.v + x.v * x.v;
        let v = self.v.atan2(x.v);
        if r2 == 0.0 {
            return Self::c(v);
        }
        let mut d = [0.0; K];
        for (i, o) in d.iter_mut().enumerate() {
            *o = (x.v * self.d[i] - self.v * x.d[i]) / r2;
        }
        Jet { v, d }
    }
    fn powf(self, e: f64) -> Self {
        let v = self.v.powf(e);
        let dv = e * self.v.powf(e - 1.0);
        self.chain(v, if dv.is_finite() { dv } else { 0.0 })
    }
    fn then(self, v: f64, dv: f64) -> Self {
        self.chain(v, dv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_match_differences() {
        let f = |x: Jet, y: Jet| (x * y + x.sin()) / (y.sqrt() + <Jet>::c(1.0)) + y.atan2(x).cos();
        let (x0, y0) = (0.7, 1.3);
        let j = f(<Jet>::var(x0, 0), <Jet>::var(y0, 1));
        let fv = |x: f64, y: f64| f(<Jet>::c(x), <Jet>::c(y)).v;
        let e = 1e-6;
        let dx = (fv(x0 + e, y0) - fv(x0 - e, y0)) / (2.0 * e);
        let dy = (fv(x0, y0 + e) - fv(x0, y0 - e)) / (2.0 * e);
        assert!((j.d[0] - dx).abs() < 1e-6 && (j.d[1] - dy).abs() < 1e-6);
    }
}
