//! Linearised backward Euler (Baraff and Witkin): with `K = -df/dx`, `C = -df/dv`,
//!
//! `(M + h C + h^2 K) dv = h (f(x, v) - h K v)`, then `v += dv`, `x += h v`.
//!
//! Spring blocks: `K_e = k [alpha I + (1 - alpha) n n^T]` with `alpha = max(0, 1 - l0/l)`,
//! `C_e = c n n^T`, so each spring adds `B_e = h^2 alpha k I + (h c + h^2 (1 - alpha) k) n n^T`.
//! The system is solved by block-Jacobi preconditioned CG, warm-started from the linear
//! extrapolation `2 dv_prev - dv_prev2` of the last two steps' velocity changes. The forces,
//! the blocks, the right-hand side and the diagonal blocks are assembled in one pass over the
//! springs (chunk by chunk, after a vectorised pass for the inverse lengths).

use crate::Vector3;
use crate::model::{Model, State};

use super::system::{self, CgReport, CgScratch, CgSettings, SpringSystem, Sym3, block_coefficients, block_matrix};

/// Springs per chunk of the assembly's vectorised square roots.
const CHUNK: usize = 256;

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
    // diagonal blocks of `A` (then the preconditioner is built from them). The springs come
    // sorted by their first particle: the sums on the current first particle are kept in
    // registers and stored once per run (a fixed order, so results stay deterministic).
    let s = &model.springs;
    let m = s.len();
    sys.mass_weight = 1.0;
    sys.begin(model);
    let (slots, coef, diag) = sys.parts_mut();
    diag.clear();
    for i in 0..n {
        rhs[i] = (model.gravity * model.mass[i] + external[i]) * h;
        diag.push(Sym3::scalar(model.mass[i]));
    }
    let (x, v) = (&state.positions[..n], &state.velocities[..n]);
    let (rhs, diag) = (&mut rhs[..n], &mut diag[..n]);
    let hh = h * h;
    let mut run = usize::MAX;
    let (mut rhs_run, mut diag_run) = (Vector3::zeros(), Sym3::default());
    // The square roots and divisions go first, chunk by chunk, in a loop that vectorises: in
    // the main loop they would put a long latency chain into every spring.
    let mut inv_len = [0.0; CHUNK];
    for start in (0..m).step_by(CHUNK) {
        let end = (start + CHUNK).min(m);
        let inv_len = &mut inv_len[..end - start];
        for (il, &[a, b]) in inv_len.iter_mut().zip(&s.ends[start..end]) {
            *il = (x[b as usize] - x[a as usize]).norm_squared();
        }
        for il in inv_len.iter_mut() {
            *il = 1.0 / il.sqrt();
        }
        let springs = s.ends[start..end].iter().zip(&s.rest_length[start..end]).zip(&s.stiffness[start..end]).zip(&s.damping[start..end]);
        for ((((&[a, b], &rest), &k), &c), (&inv_l, &slot)) in springs.zip(inv_len.iter().zip(&slots[start..end])) {
            let (a, b) = (a as usize, b as usize);
            let d = x[b] - x[a];
            if a != run {
                if run != usize::MAX {
                    rhs[run] += rhs_run;
                    diag[run] += diag_run;
                }
                run = a;
                rhs_run = Vector3::zeros();
                diag_run = Sym3::default();
            }
            if inv_l == f64::INFINITY {
                // zero length: no direction, no force and a zero block
                coef[slot as usize] = [0.0; 4];
                continue;
            }
            let dir = d * inv_l;
            let l = d.dot(&dir);
            let dvel = v[a] - v[b];
            let dvel_n = dir.dot(&dvel);
            // spring force on a: n (k (l - l0) + c (v_b - v_a) . n)
            let f = dir * (k * (l - rest) - c * dvel_n);
            let alpha = (1.0 - rest * inv_l).max(0.0);
            let (ka, kn) = (alpha * k, (1.0 - alpha) * k);
            let block = block_coefficients(hh * ka, h * c + hh * kn, &dir);
            coef[slot as usize] = block;
            // rhs += h f - h^2 K (v_a - v_b) on a, the opposite on b
            let w = f * h - (dvel * ka + dir * (kn * dvel_n)) * hh;
            rhs_run += w;
            rhs[b] -= w;
            let block = block_matrix(&block);
            diag_run += block;
            diag[b] += block;
        }
    }
    if run != usize::MAX {
        rhs[run] += rhs_run;
        diag[run] += diag_run;
    }
    sys.prepare(model);
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
