//! Linearised backward Euler (Baraff and Witkin): with `K = -df/dx`, `C = -df/dv`,
//!
//! `(M + h C + h^2 K) dv = h (f(x, v) - h K v)`, then `v += dv`, `x += h v`.
//!
//! Spring blocks: `K_e = k [alpha I + (1 - alpha) n n^T]` with `alpha = max(0, 1 - l0/l)`,
//! `C_e = c n n^T`, so each spring adds `B_e = h^2 alpha k I + (h c + h^2 (1 - alpha) k) n n^T`.
//! The system is solved by block-Jacobi preconditioned CG, warm-started from the linear
//! extrapolation `2 dv_prev - dv_prev2` of the last two steps' velocity changes. The forces,
//! the blocks, the right-hand side and the diagonal blocks are assembled in one pass over the
//! springs.

use crate::Vector3;
use crate::model::{Model, State};

use nalgebra::Matrix3;

use super::system::{self, CgReport, CgScratch, CgSettings, SpringSystem};

/// Buffers kept between implicit steps.
#[derive(Debug, Clone, Default)]
pub struct ImplicitScratch {
    pub system: SpringSystem,
    pub rhs: Vec<Vector3>,
    /// The previous step's velocity change: the warm start.
    pub dv: Vec<Vector3>,
    /// The velocity change of the step before: with `dv`, the linear extrapolation.
    pub dv_previous: Vec<Vector3>,
    pub cg: CgScratch,
}

/// One backward-Euler step of `h` seconds.
pub fn step(
    model: &Model,
    state: &mut State,
    external: &[Vector3],
    h: f64,
    cg: CgSettings,
    scratch: &mut ImplicitScratch,
) -> CgReport {
    let n = model.vertex_count();
    let ImplicitScratch { system: sys, rhs, dv, dv_previous, cg: cg_scratch } = scratch;
    rhs.resize(n, Vector3::zeros());
    dv.resize(n, Vector3::zeros());
    dv_previous.resize(n, Vector3::zeros());

    // One pass over the springs: forces, the blocks `B_e`, `rhs = h (f - h K v)` and the
    // diagonal blocks of `A` (into `sys.inv_diag`, inverted afterwards).
    let s = &model.springs;
    let m = s.len();
    sys.mass_weight = 1.0;
    sys.beta.resize(m, 0.0);
    sys.gamma.resize(m, 0.0);
    sys.direction.resize(m, Vector3::zeros());
    sys.inv_diag.clear();
    for i in 0..n {
        rhs[i] = (model.gravity * model.mass[i] + external[i]) * h;
        sys.inv_diag.push(Matrix3::identity() * model.mass[i]);
    }
    let (x, v) = (&state.positions, &state.velocities);
    let (hh, springs) = (h * h, s.ends.iter().zip(&s.rest_length).zip(&s.stiffness).zip(&s.damping));
    for (e, (((&[a, b], &rest), &k), &c)) in springs.enumerate() {
        let (a, b) = (a as usize, b as usize);
        let d = x[b] - x[a];
        let l = d.norm();
        if l == 0.0 {
            // direction undefined: no force and a zero block
            sys.beta[e] = 0.0;
            sys.gamma[e] = 0.0;
            sys.direction[e] = Vector3::zeros();
            continue;
        }
        let dir = d * (1.0 / l);
        let dvel = v[a] - v[b];
        let dvel_n = dir.dot(&dvel);
        // spring force on a: n (k (l - l0) + c (v_b - v_a) . n)
        let f = dir * (k * (l - rest) - c * dvel_n);
        let alpha = (1.0 - rest / l).max(0.0);
        let (ka, kn) = (alpha * k, (1.0 - alpha) * k);
        let (beta, gamma) = (hh * ka, h * c + hh * kn);
        sys.beta[e] = beta;
        sys.gamma[e] = gamma;
        sys.direction[e] = dir;
        // rhs += h f - h^2 K (v_a - v_b) on a, the opposite on b
        let w = f * h - (dvel * ka + dir * (kn * dvel_n)) * hh;
        rhs[a] += w;
        rhs[b] -= w;
        let block = Matrix3::identity() * beta + (dir * dir.transpose()) * gamma;
        sys.inv_diag[a] += block;
        sys.inv_diag[b] += block;
    }
    sys.invert_diagonal(model, n);
    for (d, p) in dv.iter_mut().zip(dv_previous.iter_mut()) {
        let last = *d;
        *d = last * 2.0 - *p;
        *p = last;
    }
    let report = system::solve(sys, model, rhs, dv, cg, cg_scratch);
    for i in 0..n {
        if model.held[i] {
            continue;
        }
        state.velocities[i] += dv[i];
        state.positions[i] += state.velocities[i] * h;
    }
    report
}
