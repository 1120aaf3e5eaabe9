//! The block-sparse symmetric system of the finite elements and its preconditioned CG.
//!
//! `A = sum_i D_i (diagonal 3x3 blocks) + sum over edges (a, b), a < b, of A_ab` with
//! `A_ba = A_ab^T`: the sparsity of the springs (the mesh's edges), but with general 3x3 blocks,
//! which the springs' `beta I + g g^T` storage cannot hold. Held particles are removed (their
//! rows and columns act as identity on a zero right-hand side).
//!
//! Preconditioner: block symmetric Gauss-Seidel, `P = (D + L) D^-1 (D + L^T)` with `L` the
//! strictly lower block triangle in particle order, applied by one forward and one backward
//! block sweep; block-Jacobi when a free diagonal block is not positive definite.

use nalgebra::Matrix3;

use crate::Vector3;

/// The system matrix.
#[derive(Debug, Clone, Default)]
pub struct BlockSystem {
    /// Diagonal blocks (zero for held particles after [`Self::prepare`]).
    pub diag: Vec<Matrix3<f64>>,
    /// `A_ab` per edge of `edges`.
    pub off: Vec<Matrix3<f64>>,
    /// Edges `[a, b]`, `a < b`, sorted (so grouped by `a`).
    pub edges: Vec<[u32; 2]>,
    /// Edges of first particle `i`: `start[i]..start[i + 1]`.
    start: Vec<usize>,
    /// Inverse diagonal blocks (zero for held particles).
    inv_diag: Vec<Matrix3<f64>>,
    held: Vec<bool>,
    sgs: bool,
}

/// Scratch vectors of the CG.
#[derive(Debug, Clone, Default)]
pub struct BlockCgScratch {
    r: Vec<Vector3>,
    z: Vec<Vector3>,
    p: Vec<Vector3>,
    q: Vec<Vector3>,
}

/// Outcome of a solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockCgReport {
    /// Iterations taken.
    pub iterations: usize,
    /// `|b - A x| / |b|` at the end.
    pub relative_residual: f64,
    /// Whether the residual reached the tolerance.
    pub converged: bool,
}

impl BlockSystem {
    /// Zeroes the blocks for `n` particles and the edges given (the layout is rebuilt only
    /// when the edges changed).
    pub fn begin(&mut self, n: usize, edges: &[[u32; 2]]) {
        if self.edges != edges || self.start.len() != n + 1 {
            self.edges = edges.to_vec();
            self.start = vec![0; n + 1];
            for &[a, _] in edges {
                self.start[a as usize + 1] += 1;
            }
            for i in 0..n {
                self.start[i + 1] += self.start[i];
            }
        }
        self.diag.clear();
        self.diag.resize(n, Matrix3::zeros());
        self.off.clear();
        self.off.resize(edges.len(), Matrix3::zeros());
    }

    /// Adds the element block `k` coupling local vertex `i` (particle `a`) to `j` (particle
    /// `b`) on edge `e`: `A_ab += k` if `a < b`, else `A_ba += k^T`.
    #[inline]
    pub fn add_off(&mut self, e: usize, a: u32, b: u32, k: &Matrix3<f64>) {
        if a < b {
            self.off[e] += k;
        } else {
            self.off[e] += k.transpose();
        }
    }

    /// Builds the preconditioner (held particles' diagonal blocks zeroed).
    pub fn prepare(&mut self, held: &[bool]) {
        self.held.clear();
        self.held.extend_from_slice(held);
        self.inv_diag.clear();
        let mut sgs = true;
        for (d, &h) in self.diag.iter_mut().zip(held) {
            if h {
                *d = Matrix3::zeros();
                self.inv_diag.push(Matrix3::zeros());
                continue;
            }
            let sym = (*d + d.transpose()) * 0.5;
            let pd = sym.cholesky().is_some();
            sgs &= pd;
            let inv = d
                .try_inverse()
                .filter(|m| pd && m.iter().all(|c| c.is_finite()))
                .unwrap_or_else(Matrix3::zeros);
            self.inv_diag.push(inv);
        }
        self.sgs = sgs;
    }

    /// `y = A p`, held rows zeroed.
    pub fn apply(&self, p: &[Vector3], y: &mut [Vector3]) {
        let n = self.diag.len();
        for i in 0..n {
            y[i] = self.diag[i] * p[i];
        }
        for (e, &[a, b]) in self.edges.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let k = &self.off[e];
            y[a] += k * p[b];
            y[b] += k.tr_mul(&p[a]);
        }
        for (y, &h) in y.iter_mut().zip(&self.held) {
            if h {
                *y = Vector3::zeros();
            }
        }
    }

    /// `z = P^-1 r`.
    fn precondition(&self, r: &[Vector3], z: &mut [Vector3]) {
        let n = self.diag.len();
        if !self.sgs {
            for i in 0..n {
                z[i] = self.inv_diag[i] * r[i];
            }
            return;
        }
        // Forward: (D + L) y = r, with L_ba = A_ab^T for a < b. z accumulates r - L y.
        z[..n].copy_from_slice(&r[..n]);
        for i in 0..n {
            let yi = if self.held[i] {
                Vector3::zeros()
            } else {
                self.inv_diag[i] * z[i]
            };
            z[i] = yi;
            for e in self.start[i]..self.start[i + 1] {
                let o = self.edges[e][1] as usize;
                z[o] -= self.off[e].tr_mul(&yi);
            }
        }
        // Backward: (D + U) z = D y, i.e. z_i = y_i - D_i^-1 sum_{o > i} A_io z_o.
        for i in (0..n).rev() {
            if self.held[i] {
                z[i] = Vector3::zeros();
                continue;
            }
            let mut s = Vector3::zeros();
            for e in self.start[i]..self.start[i + 1] {
                s += self.off[e] * z[self.edges[e][1] as usize];
            }
            z[i] -= self.inv_diag[i] * s;
        }
    }

    /// Solves `A x = b` by preconditioned CG from the `x` given (warm start); held entries are
    /// zero. Stops at `|b - A x| <= max(relative_tolerance |b|, absolute_tolerance)`.
    pub fn solve(
        &self,
        b: &[Vector3],
        x: &mut [Vector3],
        relative_tolerance: f64,
        absolute_tolerance: f64,
        max_iterations: usize,
        scratch: &mut BlockCgScratch,
    ) -> BlockCgReport {
        let n = b.len();
        let BlockCgScratch { r, z, p, q } = scratch;
        for buf in [&mut *r, &mut *z, &mut *p, &mut *q] {
            buf.resize(n, Vector3::zeros());
        }
        for (xi, &h) in x.iter_mut().zip(&self.held) {
            if h {
                *xi = Vector3::zeros();
            }
        }
        let free = |i: usize| !self.held[i];
        let b_norm = (0..n)
            .filter(|&i| free(i))
            .map(|i| b[i].norm_squared())
            .sum::<f64>()
            .sqrt();
        if b_norm == 0.0 {
            x.iter_mut().for_each(|xi| *xi = Vector3::zeros());
            return BlockCgReport {
                iterations: 0,
                relative_residual: 0.0,
                converged: true,
            };
        }
        self.apply(x, q);
        let mut rr = 0.0;
        for i in 0..n {
            r[i] = if free(i) {
                b[i] - q[i]
            } else {
                Vector3::zeros()
            };
            rr += r[i].norm_squared();
        }
        let target = (relative_tolerance * b_norm).max(absolute_tolerance);
        self.precondition(r, z);
        p.copy_from_slice(z);
        let mut rz: f64 = r.iter().zip(z.iter()).map(|(a, b)| a.dot(b)).sum();
        let mut iterations = 0;
        while rr.sqrt() > target && iterations < max_iterations {
            self.apply(p, q);
            let pq: f64 = p.iter().zip(q.iter()).map(|(a, b)| a.dot(b)).sum();
            if !(pq > 0.0) || !(rz > 0.0) {
                break; // breakdown: singular along p (a free piece in statics) or bad numbers
            }
            let alpha = rz / pq;
            rr = 0.0;
            for i in 0..n {
                x[i] += p[i] * alpha;
                r[i] -= q[i] * alpha;
                rr += r[i].norm_squared();
            }
            self.precondition(r, z);
            let rz_next: f64 = r.iter().zip(z.iter()).map(|(a, b)| a.dot(b)).sum();
            let beta = rz_next / rz;
            rz = rz_next;
            for i in 0..n {
                p[i] = z[i] + p[i] * beta;
            }
            iterations += 1;
        }
        let r_norm = rr.sqrt();
        BlockCgReport {
            iterations,
            relative_residual: r_norm / b_norm,
            converged: r_norm <= target,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small chain: 4 particles, 3 edges, diagonally dominant blocks; the solution
    /// satisfies the system, with SGS and with block-Jacobi.
    #[test]
    fn solves_a_small_system() {
        let edges = vec![[0, 1], [0, 2], [1, 3], [2, 3]];
        let mut sys = BlockSystem::default();
        sys.begin(4, &edges);
        for d in &mut sys.diag {
            *d = Matrix3::new(4.0, 0.5, 0.1, 0.5, 3.0, 0.2, 0.1, 0.2, 5.0);
        }
        for (e, k) in sys.off.iter_mut().enumerate() {
            *k = Matrix3::new(-1.0, 0.3, 0.0, 0.1, -0.5, 0.2, 0.0, -0.1, -0.7)
                * (1.0 + 0.1 * e as f64);
        }
        let held = vec![false; 4];
        sys.prepare(&held);
        let b: Vec<Vector3> = (0..4)
            .map(|i| Vector3::new(1.0, -(i as f64), 0.5))
            .collect();
        for sgs in [true, false] {
            sys.sgs = sgs;
            let mut x = vec![Vector3::zeros(); 4];
            let report = sys.solve(&b, &mut x, 1e-13, 0.0, 100, &mut BlockCgScratch::default());
            assert!(report.converged, "{report:?}");
            let mut y = vec![Vector3::zeros(); 4];
            sys.apply(&x, &mut y);
            for i in 0..4 {
                assert!((y[i] - b[i]).norm() < 1e-12, "{sgs}: {} vs {}", y[i], b[i]);
            }
        }
    }
}
