//! Symplectic (semi-implicit) Euler with automatic sub-stepping:
//! `v += h M^-1 f(x, v)`, then `x += h v`.
//!
//! Stability: for one mode with angular frequency omega and damping rate gamma (= c/m), the
//! scheme is stable iff `gamma h < 2` and `omega^2 h^2 + 2 gamma h < 4`, i.e.
//! `h < h_crit = (-gamma + sqrt(gamma^2 + 4 omega^2)) / omega^2`. omega^2 and gamma are bounded
//! from above by the Gershgorin row sums of `M^-1 K` and `M^-1 C` over the free particles:
//! `omega^2 <= max_i 2 sum_{e at i} k_e / m_i`, `gamma <= max_i 2 sum_{e at i} c_e / m_i`.

use crate::Vector3;
use crate::model::{Model, State};

use super::forces::total_forces;

/// Upper bounds of the highest angular frequency (rad/s) and damping rate (1/s) of the free
/// particles.
pub fn spectral_bounds(model: &Model) -> (f64, f64) {
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
    (omega2.sqrt(), gamma)
}

/// Largest stable step `h_crit` in seconds for the bounds of [`spectral_bounds`].
pub fn critical_time_step(omega: f64, gamma: f64) -> f64 {
    if omega == 0.0 {
        return if gamma == 0.0 { f64::INFINITY } else { 2.0 / gamma };
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
pub fn step(model: &Model, state: &mut State, external: &[Vector3], dt: f64, substeps: u32, forces: &mut Vec<Vector3>) {
    let h = dt / substeps as f64;
    forces.resize(model.vertex_count(), Vector3::zeros());
    for _ in 0..substeps {
        total_forces(model, &state.positions, &state.velocities, external, forces);
        for i in 0..model.vertex_count() {
            let w = model.inv_mass[i];
            let v = &mut state.velocities[i];
            *v += forces[i] * (h * w);
            state.positions[i] += *v * h;
        }
    }
}
