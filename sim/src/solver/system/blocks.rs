//! The 3x3 blocks of the system: symmetric ([`Sym3`], the diagonal blocks and their inverses),
//! lower-triangular ([`Lower3`], the diagonal blocks' Cholesky factors), and the off-diagonal
//! blocks as stored ([`OffBlock`]): a spring's `B = beta I + gamma n n^T` in the form
//! `[g_x, g_y, g_z, beta]`, `g = sqrt(gamma) n` ([`SpringBlock`]), or a general 3x3 matrix (the
//! finite elements').

use nalgebra::Matrix3;

use super::lanes::Lanes;
use crate::Vector3;

/// A spring's block `B = beta I + g g^T` as `[g_x, g_y, g_z, beta]`.
pub type SpringBlock = [f64; 4];

/// An off-diagonal block as the system stores it: for the slot of particles `k` and `l`, `k`
/// first in the sweep order, `N = -A_kl` (so `A_lk = -N^T`).
pub trait OffBlock: Copy + Default + Send + Sync + std::fmt::Debug {
    /// Whether `A = a_m M + sum of the blocks' pattern [+N, -N; -N, +N]` (the springs': the
    /// diagonal blocks follow from the off-diagonal ones, and a product is taken in the
    /// difference form `N (p_k - p_l)`); otherwise `A`'s diagonal blocks are given.
    const LAPLACIAN: bool;
    /// `N v`.
    fn mul(&self, v: &Vector3) -> Vector3;
    /// `N^T v`.
    fn mul_transpose(&self, v: &Vector3) -> Vector3;
    /// The slot's part of `y = A p` (off the diagonal, and for [`Self::LAPLACIAN`] blocks the
    /// diagonal's share too): added to `y_k` and `y_l`.
    fn apply_pair<T: Lanes>(&self, p_k: T, p_l: T, y_k: &mut T, y_l: &mut T);
}

impl OffBlock for SpringBlock {
    const LAPLACIAN: bool = true;
    #[inline(always)]
    fn mul(&self, v: &Vector3) -> Vector3 {
        block_mul(self, v)
    }
    #[inline(always)]
    fn mul_transpose(&self, v: &Vector3) -> Vector3 {
        block_mul(self, v)
    }
    #[inline(always)]
    fn apply_pair<T: Lanes>(&self, p_k: T, p_l: T, y_k: &mut T, y_l: &mut T) {
        let w = p_k.block_mul_difference(self, p_l);
        y_k.add(w);
        y_l.sub(w);
    }
}

impl OffBlock for Matrix3<f64> {
    const LAPLACIAN: bool = false;
    #[inline(always)]
    fn mul(&self, v: &Vector3) -> Vector3 {
        self * v
    }
    #[inline(always)]
    fn mul_transpose(&self, v: &Vector3) -> Vector3 {
        self.tr_mul(v)
    }
    #[inline(always)]
    fn apply_pair<T: Lanes>(&self, p_k: T, p_l: T, y_k: &mut T, y_l: &mut T) {
        y_k.sub(p_l.matrix_mul(self));
        y_l.sub(p_k.matrix_tr_mul(self));
    }
}

/// A symmetric 3x3 matrix stored by its six distinct entries.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sym3 {
    /// Row x, column x.
    pub xx: f64,
    /// Row y, column y.
    pub yy: f64,
    /// Row z, column z.
    pub zz: f64,
    /// Rows x and y, columns y and x.
    pub xy: f64,
    /// Rows x and z, columns z and x.
    pub xz: f64,
    /// Rows y and z, columns z and y.
    pub yz: f64,
}

impl Sym3 {
    /// `s I`.
    #[inline]
    pub fn scalar(s: f64) -> Self {
        Self {
            xx: s,
            yy: s,
            zz: s,
            xy: 0.0,
            xz: 0.0,
            yz: 0.0,
        }
    }

    /// The matrix-vector product.
    #[inline]
    pub fn mul(&self, v: &Vector3) -> Vector3 {
        Vector3::new(
            self.xx * v.x + self.xy * v.y + self.xz * v.z,
            self.xy * v.x + self.yy * v.y + self.yz * v.z,
            self.xz * v.x + self.yz * v.y + self.zz * v.z,
        )
    }

    /// The inverse by cofactors, or zero when the determinant is not positive and finite
    /// (the blocks inverted here are positive definite or the particle is cut off).
    #[inline]
    pub fn inverse_or_zero(&self) -> Self {
        let c_xx = self.yy * self.zz - self.yz * self.yz;
        let c_xy = self.xz * self.yz - self.xy * self.zz;
        let c_xz = self.xy * self.yz - self.xz * self.yy;
        let det = self.xx * c_xx + self.xy * c_xy + self.xz * c_xz;
        if !(det > 0.0 && det.is_finite()) {
            return Self::default();
        }
        let inv = 1.0 / det;
        Self {
            xx: c_xx * inv,
            yy: (self.xx * self.zz - self.xz * self.xz) * inv,
            zz: (self.xx * self.yy - self.xy * self.xy) * inv,
            xy: c_xy * inv,
            xz: c_xz * inv,
            yz: (self.xy * self.xz - self.xx * self.yz) * inv,
        }
    }
}

impl Sym3 {
    /// The symmetric part `(m + m^T) / 2` of a 3x3 matrix.
    #[inline]
    pub fn symmetric_part(m: &Matrix3<f64>) -> Self {
        Self {
            xx: m[(0, 0)],
            yy: m[(1, 1)],
            zz: m[(2, 2)],
            xy: 0.5 * (m[(0, 1)] + m[(1, 0)]),
            xz: 0.5 * (m[(0, 2)] + m[(2, 0)]),
            yz: 0.5 * (m[(1, 2)] + m[(2, 1)]),
        }
    }

    /// `s a a^T`.
    #[inline(always)]
    pub fn outer(a: &Vector3, s: f64) -> Self {
        let sa = a * s;
        Self {
            xx: sa.x * a.x,
            yy: sa.y * a.y,
            zz: sa.z * a.z,
            xy: sa.x * a.y,
            xz: sa.x * a.z,
            yz: sa.y * a.z,
        }
    }
}

impl std::ops::AddAssign for Sym3 {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        self.xx += o.xx;
        self.yy += o.yy;
        self.zz += o.zz;
        self.xy += o.xy;
        self.xz += o.xz;
        self.yz += o.yz;
    }
}

/// A lower-triangular 3x3 matrix.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Lower3 {
    /// Row x, column x.
    pub xx: f64,
    /// Row y, column x.
    pub yx: f64,
    /// Row y, column y.
    pub yy: f64,
    /// Row z, column x.
    pub zx: f64,
    /// Row z, column y.
    pub zy: f64,
    /// Row z, column z.
    pub zz: f64,
}

impl Lower3 {
    /// The Cholesky factor `G` (`G G^T = d`), or `None` when `d` is not positive definite.
    pub fn cholesky(d: &Sym3) -> Option<Self> {
        let xx = d.xx.sqrt();
        let (yx, zx) = (d.xy / xx, d.xz / xx);
        let yy = (d.yy - yx * yx).sqrt();
        let zy = (d.yz - zx * yx) / yy;
        let zz = (d.zz - zx * zx - zy * zy).sqrt();
        let g = Self {
            xx,
            yx,
            yy,
            zx,
            zy,
            zz,
        };
        // positive pivots (NaN from a negative square root fails the comparisons too)
        (xx > 0.0 && yy > 0.0 && zz > 0.0 && [yx, zx, zy, zz].iter().all(|v| v.is_finite()))
            .then_some(g)
    }

    /// `G v`.
    #[inline]
    pub fn mul(&self, v: &Vector3) -> Vector3 {
        Vector3::new(
            self.xx * v.x,
            self.yx * v.x + self.yy * v.y,
            self.zx * v.x + self.zy * v.y + self.zz * v.z,
        )
    }

    /// `G^T v`.
    #[inline]
    pub fn mul_transpose(&self, v: &Vector3) -> Vector3 {
        Vector3::new(
            self.xx * v.x + self.yx * v.y + self.zx * v.z,
            self.yy * v.y + self.zy * v.z,
            self.zz * v.z,
        )
    }
}

/// Stiffness blocks `K_e = k [alpha I + (1 - alpha) n n^T]` with `alpha = max(0, 1 - l0 / l)`:
/// the exact spring Hessian for stretched springs, its positive part for compressed ones.
/// Returns `(alpha k, (1 - alpha) k, n)`; a zero-length spring gives zeros.
#[inline]
pub fn stiffness_block(k: f64, rest: f64, d: &Vector3) -> (f64, f64, Vector3) {
    let l = d.norm();
    if l == 0.0 {
        return (0.0, 0.0, Vector3::zeros());
    }
    let alpha = (1.0 - rest / l).max(0.0);
    (alpha * k, (1.0 - alpha) * k, d / l)
}

/// The stored form `[g_x, g_y, g_z, beta]` of `B = beta I + gamma n n^T`.
#[inline(always)]
pub fn block_coefficients(beta: f64, gamma: f64, n: &Vector3) -> [f64; 4] {
    let g = n * gamma.sqrt();
    [g.x, g.y, g.z, beta]
}

/// `B v = beta v + g (g . v)` from the stored form.
#[inline(always)]
pub(super) fn block_mul(c: &[f64; 4], v: &Vector3) -> Vector3 {
    let g = Vector3::new(c[0], c[1], c[2]);
    v * c[3] + g * g.dot(v)
}

/// The diagonal contribution `beta I + g g^T` of a stored block.
#[inline(always)]
pub fn block_matrix(c: &[f64; 4]) -> Sym3 {
    let [gx, gy, gz, beta] = *c;
    Sym3 {
        xx: beta + gx * gx,
        yy: beta + gy * gy,
        zz: beta + gz * gz,
        xy: gx * gy,
        xz: gx * gz,
        yz: gy * gz,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sym(xx: f64, yy: f64, zz: f64, xy: f64, xz: f64, yz: f64) -> Sym3 {
        Sym3 {
            xx,
            yy,
            zz,
            xy,
            xz,
            yz,
        }
    }

    #[test]
    fn inverse_and_cholesky_of_a_positive_definite_block() {
        let d = sym(4.0, 3.0, 2.0, 0.5, -0.3, 0.2);
        let inv = d.inverse_or_zero();
        for v in [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(0.3, -1.2, 2.5),
        ] {
            assert!((inv.mul(&d.mul(&v)) - v).norm() < 1e-14 * v.norm());
        }
        let g = Lower3::cholesky(&d).expect("positive definite");
        for v in [Vector3::x(), Vector3::new(1.0, -2.0, 0.5)] {
            assert!((g.mul(&g.mul_transpose(&v)) - d.mul(&v)).norm() < 1e-14 * d.mul(&v).norm());
        }
        assert!(Lower3::cholesky(&sym(1.0, 1.0, 1.0, 2.0, 0.0, 0.0)).is_none());
        assert!(Lower3::cholesky(&Sym3::default()).is_none());
        assert_eq!(
            sym(1.0, 1.0, 0.0, 1.0, 0.0, 0.0).inverse_or_zero(),
            Sym3::default()
        );
    }
}
