//! Particle forces: springs, dampers, gravity and external forces.
//!
//! For a spring between particles a and b with rest length l0, stiffness k and damper c,
//! with `d = x_b - x_a`, `l = |d|`, `n = d / l`:
//!
//! `f_a = k (l - l0) n + c ((v_b - v_a) . n) n`, `f_b = -f_a`.

use crate::model::Model;
use crate::{Point3, Vector3};

/// Writes into `out` the total force on every particle (held ones included; the integrators
/// ignore those): springs, dampers, `m_i g` and `external[i]`.
pub fn total_forces(
    model: &Model,
    x: &[Point3],
    v: &[Vector3],
    external: &[Vector3],
    out: &mut [Vector3],
) {
    for ((f, &m), fe) in out.iter_mut().zip(&model.mass).zip(external) {
        *f = model.gravity * m + fe;
    }
    add_spring_forces(model, x, v, out);
}

/// The force of a spring and damper on its first particle `a` (minus it on `b`), with
/// `d = x_b - x_a` and `u = v_b - v_a`: `n (k (l - l0) + c u . n)`, `n = d / l`. Zero for a
/// zero-length spring (its direction is undefined).
#[inline]
pub fn spring_force(d: &Vector3, u: &Vector3, rest: f64, k: f64, c: f64) -> Vector3 {
    let l2 = d.norm_squared();
    if l2 == 0.0 {
        return Vector3::zeros();
    }
    let l = l2.sqrt();
    let inv_l = 1.0 / l;
    let magnitude = k * (l - rest) + c * u.dot(d) * inv_l;
    d * (magnitude * inv_l)
}

/// Adds the spring and damper forces to `out`.
pub fn add_spring_forces(model: &Model, x: &[Point3], v: &[Vector3], out: &mut [Vector3]) {
    let s = &model.springs;
    let springs = s
        .ends
        .iter()
        .zip(&s.rest_length)
        .zip(&s.stiffness)
        .zip(&s.damping);
    for (((&[a, b], &rest), &k), &c) in springs {
        let (a, b) = (a as usize, b as usize);
        let f = spring_force(&(x[b] - x[a]), &(v[b] - v[a]), rest, k, c);
        out[a] += f;
        out[b] -= f;
    }
}

/// Potential energy in joules: `sum 1/2 k (l - l0)^2 - sum m_i g . x_i`.
pub fn potential_energy(model: &Model, x: &[Point3]) -> f64 {
    let s = &model.springs;
    let mut energy = 0.0;
    for e in 0..s.ends.len() {
        let [a, b] = s.ends[e];
        let stretch = (x[b as usize] - x[a as usize]).norm() - s.rest_length[e];
        energy += 0.5 * s.stiffness[e] * stretch * stretch;
    }
    for (p, &m) in x.iter().zip(&model.mass) {
        energy -= m * model.gravity.dot(&p.coords);
    }
    energy
}

/// Kinetic energy in joules.
pub fn kinetic_energy(model: &Model, v: &[Vector3]) -> f64 {
    v.iter()
        .zip(&model.mass)
        .map(|(v, &m)| 0.5 * m * v.norm_squared())
        .sum()
}

/// Sum of the squared force magnitudes on the free particles, N^2 (the merit of the static
/// line search).
pub fn free_force_norm_squared(model: &Model, forces: &[Vector3]) -> f64 {
    forces
        .iter()
        .zip(&model.held)
        .filter(|(_, h)| !**h)
        .map(|(f, _)| f.norm_squared())
        .sum()
}

/// Largest force magnitude on a free particle (the equilibrium residual), in newtons.
pub fn max_free_force(model: &Model, forces: &[Vector3]) -> f64 {
    forces
        .iter()
        .zip(&model.held)
        .filter(|(_, h)| !**h)
        .map(|(f, _)| f.norm())
        .fold(0.0, f64::max)
}
