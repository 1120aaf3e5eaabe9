//! Linearised backward Euler (Baraff and Witkin): with `K = -df/dx`, `C = -df/dv`,
//!
//! `(M + h C + h^2 K) dv = h (f(x, v) - h K v)`, then `v += dv`, `x += h v`.
//!
//! Spring blocks: `K_e = k [alpha I + (1 - alpha) n n^T]` with `alpha = max(0, 1 - l0/l)`,
//! `C_e = c n n^T`, so each spring adds `B_e = h^2 alpha k I + (h c + h^2 (1 - alpha) k) n n^T`.
//! The system is solved by block-Jacobi preconditioned CG, warm-started from the previous
//! `dv`.

use crate::Vector3;
use crate::model::{Model, State};

use super::forces::total_forces;
use super::system::{self, CgReport, CgScratch, CgSettings, SpringSystem, stiffness_block};

/// Buffers kept between implicit steps.
#[derive(Debug, Clone, Default)]
pub struct ImplicitScratch {
    pub system: SpringSystem,
    pub forces: Vec<Vector3>,
    pub rhs: Vec<Vector3>,
    /// The previous step's velocity change: the warm start.
    pub dv: Vec<Vector3>,
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
    let ImplicitScratch { system: sys, forces, rhs, dv, cg: cg_scratch } = scratch;
    forces.resize(n, Vector3::zeros());
    rhs.resize(n, Vector3::zeros());
    dv.resize(n, Vector3::zeros());
    total_forces(model, &state.positions, &state.velocities, external, forces);

    let s = &model.springs;
    let m = s.len();
    sys.mass_weight = 1.0;
    sys.beta.resize(m, 0.0);
    sys.gamma.resize(m, 0.0);
    sys.direction.resize(m, Vector3::zeros());
    for i in 0..n {
        rhs[i] = forces[i] * h;
    }
    let (x, v) = (&state.positions, &state.velocities);
    for (e, &[a, b]) in s.ends.iter().enumerate() {
        let (a, b) = (a as usize, b as usize);
        let (ka, kn, dir) = stiffness_block(s.stiffness[e], s.rest_length[e], &(x[b] - x[a]));
        sys.beta[e] = h * h * ka;
        sys.gamma[e] = h * s.damping[e] + h * h * kn;
        sys.direction[e] = dir;
        // rhs -= h^2 K v on both ends
        let dvel = v[a] - v[b];
        let kv = dvel * ka + dir * (kn * dir.dot(&dvel));
        rhs[a] -= kv * (h * h);
        rhs[b] += kv * (h * h);
    }
    sys.update_preconditioner(model);
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
