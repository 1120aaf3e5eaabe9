//! The sparse symmetric system shared by implicit Euler and the static solve, and its
//! preconditioned conjugate-gradient solver.
//!
//! The matrix is `A = a_m M + sum over springs e of B_e`, where each spring contributes the
//! 3x3 block `B_e = beta_e I + gamma_e n_e n_e^T` with the pattern `[+B, -B; -B, +B]` on its
//! two particles. Held particles are removed (their rows and columns act as identity on a
//! zero right-hand side). With `beta, gamma >= 0` the matrix is symmetric positive
//! semi-definite, and positive definite once a particle of every piece is held or `a_m > 0`.

use crate::Vector3;
use crate::model::Model;

/// A symmetric 3x3 matrix stored by its six distinct entries.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sym3 {
    pub xx: f64,
    pub yy: f64,
    pub zz: f64,
    pub xy: f64,
    pub xz: f64,
    pub yz: f64,
}

impl Sym3 {
    /// `s I`.
    #[inline]
    pub fn scalar(s: f64) -> Self {
        Self { xx: s, yy: s, zz: s, xy: 0.0, xz: 0.0, yz: 0.0 }
    }

    /// `beta I + gamma n n^T`.
    #[inline]
    pub fn spring_block(beta: f64, gamma: f64, n: &Vector3) -> Self {
        let g = n * gamma;
        Self { xx: beta + g.x * n.x, yy: beta + g.y * n.y, zz: beta + g.z * n.z, xy: g.x * n.y, xz: g.x * n.z, yz: g.y * n.z }
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

/// Per-spring block coefficients and the lumped-mass weight.
#[derive(Debug, Clone, Default)]
pub struct SpringSystem {
    pub mass_weight: f64,
    pub beta: Vec<f64>,
    pub gamma: Vec<f64>,
    pub direction: Vec<Vector3>,
    /// Inverse 3x3 diagonal blocks (zero for held particles): the block-Jacobi preconditioner.
    pub inv_diag: Vec<Sym3>,
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

impl SpringSystem {
    /// Recomputes the preconditioner from the current coefficients.
    pub fn update_preconditioner(&mut self, model: &Model) {
        let n = model.vertex_count();
        self.inv_diag.clear();
        self.inv_diag.extend(model.mass.iter().map(|&m| Sym3::scalar(self.mass_weight * m)));
        for (e, &[a, b]) in model.springs.ends.iter().enumerate() {
            let block = Sym3::spring_block(self.beta[e], self.gamma[e], &self.direction[e]);
            self.inv_diag[a as usize] += block;
            self.inv_diag[b as usize] += block;
        }
        self.invert_diagonal(model, n);
    }

    /// Replaces the diagonal blocks held in `inv_diag` by their inverses (zero for held
    /// particles and singular blocks).
    pub fn invert_diagonal(&mut self, model: &Model, n: usize) {
        for (d, &h) in self.inv_diag[..n].iter_mut().zip(&model.held) {
            *d = if h { Sym3::default() } else { d.inverse_or_zero() };
        }
    }

    /// `y = A p` with held rows zeroed.
    pub fn apply(&self, model: &Model, p: &[Vector3], y: &mut [Vector3]) {
        for ((y, p), &m) in y.iter_mut().zip(p).zip(&model.mass) {
            *y = p * (self.mass_weight * m);
        }
        // Springs come sorted by their first particle: the products on the current first
        // particle are summed in a register and stored once per run, which takes the store to
        // y[a] off the critical path. The summation order is fixed, so results stay
        // deterministic (and correct for any order).
        let mut run = usize::MAX;
        let mut y_run = Vector3::zeros();
        let springs = model.springs.ends.iter().zip(&self.direction).zip(&self.beta).zip(&self.gamma);
        for (((&[a, b], n), &beta), &gamma) in springs {
            let (a, b) = (a as usize, b as usize);
            if a != run {
                if run != usize::MAX {
                    y[run] += y_run;
                }
                run = a;
                y_run = Vector3::zeros();
            }
            let d = p[a] - p[b];
            let w = d * beta + n * (gamma * n.dot(&d));
            y_run += w;
            y[b] -= w;
        }
        if run != usize::MAX {
            y[run] += y_run;
        }
        for (y, &h) in y.iter_mut().zip(&model.held) {
            if h {
                *y = Vector3::zeros();
            }
        }
    }
}

/// Settings of the conjugate-gradient solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgSettings {
    /// Stop when `|r| <= relative_tolerance |b|`.
    pub relative_tolerance: f64,
    pub max_iterations: usize,
}

/// Outcome of a conjugate-gradient solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgReport {
    pub iterations: usize,
    pub relative_residual: f64,
    pub converged: bool,
}

/// Scratch vectors of the solver (kept between calls so steps do not allocate).
#[derive(Debug, Clone, Default)]
pub struct CgScratch {
    r: Vec<Vector3>,
    z: Vec<Vector3>,
    p: Vec<Vector3>,
    q: Vec<Vector3>,
}

fn dot(a: &[Vector3], b: &[Vector3]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a.dot(b)).sum()
}

/// Solves `A x = b` by block-Jacobi preconditioned conjugate gradients, starting from the
/// `x` given (warm start). Held entries of `b` and `x` are treated as zero.
pub fn solve(
    sys: &SpringSystem,
    model: &Model,
    b: &[Vector3],
    x: &mut [Vector3],
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let n = b.len();
    let CgScratch { r, z, p, q } = scratch;
    for buf in [&mut *r, &mut *z, &mut *p, &mut *q] {
        buf.clear();
        buf.resize(n, Vector3::zeros());
    }
    for (xi, &h) in x.iter_mut().zip(&model.held) {
        if h {
            *xi = Vector3::zeros();
        }
    }
    let b_norm = b.iter().zip(&model.held).filter(|(_, h)| !**h).map(|(b, _)| b.norm_squared()).sum::<f64>().sqrt();
    if b_norm == 0.0 {
        x.iter_mut().for_each(|xi| *xi = Vector3::zeros());
        return CgReport { iterations: 0, relative_residual: 0.0, converged: true };
    }
    sys.apply(model, x, q);
    for i in 0..n {
        r[i] = if model.held[i] { Vector3::zeros() } else { b[i] - q[i] };
        z[i] = sys.inv_diag[i].mul(&r[i]);
        p[i] = z[i];
    }
    let mut rz = dot(r, z);
    let target = settings.relative_tolerance * b_norm;
    let mut r_norm = dot(r, r).sqrt();
    let mut iterations = 0;
    while r_norm > target && iterations < settings.max_iterations {
        sys.apply(model, p, q);
        let pq = dot(p, q);
        if !(pq > 0.0) {
            break; // breakdown: the matrix is singular along p, or the numbers are bad
        }
        let alpha = rz / pq;
        // One pass: x and r updated, z = P r, and the dot products r.z and r.r.
        let (mut rz_next, mut rr) = (0.0, 0.0);
        for i in 0..n {
            x[i] += p[i] * alpha;
            r[i] -= q[i] * alpha;
            z[i] = sys.inv_diag[i].mul(&r[i]);
            rz_next += r[i].dot(&z[i]);
            rr += r[i].norm_squared();
        }
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            p[i] = z[i] + p[i] * beta;
        }
        r_norm = rr.sqrt();
        iterations += 1;
    }
    CgReport { iterations, relative_residual: r_norm / b_norm, converged: r_norm <= target }
}
