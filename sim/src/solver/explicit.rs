//! Symplectic (semi-implicit) Euler with automatic sub-stepping:
//! `v += h M^-1 f(x, v)`, then `x += h v`.
//!
//! Stability: for one mode with angular frequency omega and damping rate gamma (= c/m), the
//! scheme is stable iff `gamma h < 2` and `omega^2 h^2 + 2 gamma h < 4`, i.e.
//! `h < h_crit = (-gamma + sqrt(gamma^2 + 4 omega^2)) / omega^2`.
//!
//! Bounds of omega^2 and gamma: every spring block satisfies `K_e <= k_e I` and
//! `C_e = c_e n n^T <= c_e I` (Loewner order; `K_e = k [alpha I + (1 - alpha) n n^T]` with
//! `alpha <= 1`, see [`super::system::stiffness_block`]), so in any configuration
//! `K <= L_k (x) I` and `C <= L_c (x) I`, where `L_w` is the scalar graph Laplacian of the
//! springs with edge weights `w`. Hence `omega^2 <= lambda_max(M^-1 L_k)` and
//! `gamma <= lambda_max(M^-1 L_c)`, restricted to the free particles. Those are estimated by
//! power iteration ([`POWER_ITERATIONS`] Rayleigh quotients, which approach `lambda_max` from
//! below) times the margin [`POWER_MARGIN`], and capped by the Gershgorin bounds
//! `max_i 2 sum_{e at i} w_e / m_i`, which hold rigorously. On the chest wall the Laplacian
//! maximum is about 0.65 of the Gershgorin bound.

use crate::Vector3;
use crate::model::{Model, State};

use super::forces::add_spring_forces;

/// Power iterations of the spectral estimate.
pub const POWER_ITERATIONS: usize = 64;
/// Factor applied to the power-iteration estimates: covers their shortfall (a few per cent
/// after [`POWER_ITERATIONS`] iterations on the chest wall; the substep safety factor
/// `explicit_safety` comes on top).
pub const POWER_MARGIN: f64 = 1.1;

/// Upper bounds of the highest angular frequency (rad/s) and damping rate (1/s) of the free
/// particles (see the module documentation).
pub fn spectral_bounds(model: &Model) -> (f64, f64) {
    let (k_gersh, c_gersh) = gershgorin_bounds(model);
    let s = &model.springs;
    let k_est = POWER_MARGIN * laplacian_max_eigenvalue(model, &s.stiffness, POWER_ITERATIONS);
    // Damping proportional to stiffness (uniform materials): same eigenvectors, one iteration.
    let ratio = s
        .damping
        .first()
        .zip(s.stiffness.first())
        .map_or(0.0, |(c, k)| c / k);
    let proportional = ratio.is_finite()
        && s.damping
            .iter()
            .zip(&s.stiffness)
            .all(|(&c, &k)| c == ratio * k);
    let c_est = if proportional {
        ratio * k_est
    } else {
        POWER_MARGIN * laplacian_max_eigenvalue(model, &s.damping, POWER_ITERATIONS)
    };
    (k_gersh.min(k_est).sqrt(), c_gersh.min(c_est))
}

/// The Gershgorin bounds `max_i 2 sum_{e at i} k_e / m_i` (of omega^2) and
/// `max_i 2 sum_{e at i} c_e / m_i` (of gamma) over the free particles.
pub fn gershgorin_bounds(model: &Model) -> (f64, f64) {
    let n = model.vertex_count();
    let mut k_sum = vec![0.0; n];
    let mut c_sum = vec![0.0; n];
    let s = &model.springs;
    for (e, &[a, b]) in s.ends.iter().enumerate() {
        for v in [a as usize, b as usize] {
            k_sum[v] += s.stiffness[e];
            c_sum[v] += s.damping[e];
        }
    }
    let (mut omega2, mut gamma) = (0.0f64, 0.0f64);
    for i in 0..n {
        if model.held[i] {
            continue;
        }
        omega2 = omega2.max(2.0 * k_sum[i] / model.mass[i]);
        gamma = gamma.max(2.0 * c_sum[i] / model.mass[i]);
    }
    (omega2, gamma)
}

/// Largest Rayleigh quotient `x^T L_w x / x^T M x` met in `iterations` power iterations on
/// `M^-1 L_w` over the free particles (held entries zero), from a fixed pseudo-random start:
/// a lower estimate of `lambda_max(M^-1 L_w)`. Deterministic.
pub fn laplacian_max_eigenvalue(model: &Model, w: &[f64], iterations: usize) -> f64 {
    let n = model.vertex_count();
    let s = &model.springs;
    let mut x: Vec<f64> = (0..n)
        .map(|i| {
            if model.held[i] {
                return 0.0;
            }
            let bits = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
            bits as f64 / (1u64 << 24) as f64 - 0.5
        })
        .collect();
    let mut y = vec![0.0; n];
    let mut best = 0.0f64;
    for _ in 0..iterations {
        y.iter_mut().for_each(|v| *v = 0.0);
        for (e, &[a, b]) in s.ends.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let t = w[e] * (x[a] - x[b]);
            y[a] += t;
            y[b] -= t;
        }
        let (mut xlx, mut xmx) = (0.0, 0.0);
        for i in 0..n {
            if model.held[i] {
                y[i] = 0.0;
            }
            xlx += x[i] * y[i];
            xmx += x[i] * x[i] * model.mass[i];
        }
        if !(xmx > 0.0) {
            break;
        }
        best = best.max(xlx / xmx);
        // x <- M^-1 L x, normalised in the M-norm
        let mut norm = 0.0;
        for i in 0..n {
            y[i] *= model.inv_mass[i];
            norm += y[i] * y[i] * model.mass[i];
        }
        if !(norm > 0.0 && norm.is_finite()) {
            break;
        }
        let scale = 1.0 / norm.sqrt();
        for i in 0..n {
            x[i] = y[i] * scale;
        }
    }
    best
}

/// Largest stable step `h_crit` in seconds for the bounds of [`spectral_bounds`].
pub fn critical_time_step(omega: f64, gamma: f64) -> f64 {
    if omega == 0.0 {
        return if gamma == 0.0 {
            f64::INFINITY
        } else {
            2.0 / gamma
        };
    }
    (-gamma + (gamma * gamma + 4.0 * omega * omega).sqrt()) / (omega * omega)
}

/// Number of equal sub-steps of `dt` that keeps each below `safety * h_crit`.
pub fn substeps_for(model: &Model, dt: f64, safety: f64) -> u32 {
    let (omega, gamma) = spectral_bounds(model);
    let h = safety * critical_time_step(omega, gamma);
    ((dt / h).ceil().max(1.0)).min(u32::MAX as f64) as u32
}

/// Advances `state` by `substeps` sub-steps of `dt / substeps`. Held particles keep their
/// position and zero velocity.
pub fn step(
    model: &Model,
    state: &mut State,
    external: &[Vector3],
    dt: f64,
    substeps: u32,
    forces: &mut Vec<Vector3>,
) {
    let h = dt / substeps as f64;
    let n = model.vertex_count();
    forces.resize(n, Vector3::zeros());
    // The forces that do not depend on the state (gravity, external) are set before the first
    // sub-step and again in the update pass, ready for the next.
    let constant = |i: usize| model.gravity * model.mass[i] + external[i];
    for (i, f) in forces.iter_mut().enumerate() {
        *f = constant(i);
    }
    for _ in 0..substeps {
        add_spring_forces(model, &state.positions, &state.velocities, forces);
        for i in 0..n {
            let w = model.inv_mass[i];
            let v = &mut state.velocities[i];
            *v += forces[i] * (h * w);
            state.positions[i] += *v * h;
            forces[i] = constant(i);
        }
    }
}
