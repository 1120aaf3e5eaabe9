//! A particle's entries of one vector ([`Vector3`]) or of [`SPAN`] vectors side by side
//! ([`SpanEntries`]), so that one pass over the springs multiplies the matrix by all of them.

use nalgebra::Matrix3;

use crate::Vector3;

use super::super::span::SPAN;
use super::blocks::Sym3;
use super::blocks::block_mul;

/// A particle's entries of one vector or of several multiplied by the matrix together (the
/// springs' blocks read once for all).
pub trait Lanes: Copy + Send + Sync {
    const ZERO: Self;
    fn scaled(self, m: f64) -> Self;
    /// `d self`.
    fn sym_mul(self, d: &Sym3) -> Self;
    /// `m self`.
    fn matrix_mul(self, m: &Matrix3<f64>) -> Self;
    /// `m^T self`.
    fn matrix_tr_mul(self, m: &Matrix3<f64>) -> Self;
    /// `B (self - other)` for the stored block `c`.
    fn block_mul_difference(self, c: &[f64; 4], other: Self) -> Self;
    fn add(&mut self, v: Self);
    fn sub(&mut self, v: Self);
}

impl Lanes for Vector3 {
    const ZERO: Self = Vector3::new(0.0, 0.0, 0.0);
    #[inline(always)]
    fn scaled(self, m: f64) -> Self {
        self * m
    }
    #[inline(always)]
    fn sym_mul(self, d: &Sym3) -> Self {
        d.mul(&self)
    }
    #[inline(always)]
    fn matrix_mul(self, m: &Matrix3<f64>) -> Self {
        m * self
    }
    #[inline(always)]
    fn matrix_tr_mul(self, m: &Matrix3<f64>) -> Self {
        m.tr_mul(&self)
    }
    #[inline(always)]
    fn block_mul_difference(self, c: &[f64; 4], other: Self) -> Self {
        block_mul(c, &(self - other))
    }
    #[inline(always)]
    fn add(&mut self, v: Self) {
        *self += v;
    }
    #[inline(always)]
    fn sub(&mut self, v: Self) {
        *self -= v;
    }
}

/// The entries of [`SPAN`] vectors at one particle, by coordinate (`x[j]` of vector `j`), so
/// that the products of the four run in the same vector instructions.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct SpanEntries {
    x: [f64; SPAN],
    y: [f64; SPAN],
    z: [f64; SPAN],
}

impl SpanEntries {
    pub(super) fn of(v: [Vector3; SPAN]) -> Self {
        Self {
            x: v.map(|v| v.x),
            y: v.map(|v| v.y),
            z: v.map(|v| v.z),
        }
    }

    pub(super) fn get(&self, j: usize) -> Vector3 {
        Vector3::new(self.x[j], self.y[j], self.z[j])
    }

    /// `f` applied to each vector.
    #[inline(always)]
    fn each(self, f: impl Fn(Vector3) -> Vector3) -> Self {
        Self::of(std::array::from_fn(|j| f(self.get(j))))
    }

    /// `sum_j c_j v_j`.
    pub(super) fn combine(&self, c: &[f64; SPAN]) -> Vector3 {
        let dot = |a: &[f64; SPAN]| a.iter().zip(c).map(|(a, c)| a * c).sum::<f64>();
        Vector3::new(dot(&self.x), dot(&self.y), dot(&self.z))
    }
}

impl Lanes for SpanEntries {
    const ZERO: Self = Self {
        x: [0.0; SPAN],
        y: [0.0; SPAN],
        z: [0.0; SPAN],
    };
    #[inline(always)]
    fn scaled(self, m: f64) -> Self {
        Self {
            x: self.x.map(|v| v * m),
            y: self.y.map(|v| v * m),
            z: self.z.map(|v| v * m),
        }
    }
    #[inline(always)]
    fn sym_mul(self, d: &Sym3) -> Self {
        self.each(|v| d.mul(&v))
    }
    #[inline(always)]
    fn matrix_mul(self, m: &Matrix3<f64>) -> Self {
        self.each(|v| m * v)
    }
    #[inline(always)]
    fn matrix_tr_mul(self, m: &Matrix3<f64>) -> Self {
        self.each(|v| m.tr_mul(&v))
    }
    #[inline(always)]
    fn block_mul_difference(self, c: &[f64; 4], other: Self) -> Self {
        // B d = beta d + g (g . d), lane by lane
        let [gx, gy, gz, beta] = *c;
        let mut out = Self::ZERO;
        for j in 0..SPAN {
            let (dx, dy, dz) = (
                self.x[j] - other.x[j],
                self.y[j] - other.y[j],
                self.z[j] - other.z[j],
            );
            let gd = gx * dx + gy * dy + gz * dz;
            out.x[j] = beta * dx + gx * gd;
            out.y[j] = beta * dy + gy * gd;
            out.z[j] = beta * dz + gz * gd;
        }
        out
    }
    #[inline(always)]
    fn add(&mut self, v: Self) {
        for j in 0..SPAN {
            self.x[j] += v.x[j];
            self.y[j] += v.y[j];
            self.z[j] += v.z[j];
        }
    }
    #[inline(always)]
    fn sub(&mut self, v: Self) {
        for j in 0..SPAN {
            self.x[j] -= v.x[j];
            self.y[j] -= v.y[j];
            self.z[j] -= v.z[j];
        }
    }
}
