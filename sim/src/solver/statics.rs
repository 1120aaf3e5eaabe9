//! Static equilibrium `f(x) = 0` by Newton's method on the potential energy: each iteration
//! solves `K dx = f(x)` by PCG (`K` the positive part of the stiffness matrix, see
//! [`super::system::stiffness_block`]), then backtracks on the residual norm.

use crate::model::{Model, State};
use crate::{Point3, Vector3};

use super::forces::{free_force_norm_squared, max_free_force, total_forces};
use super::system::{self, CgScratch, CgSettings, SpringSystem, stiffness_block};

/// Settings of the static solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticSettings {
    /// Converged when the largest force on a free particle is below this fraction of the
    /// largest spring force in the initial state.
    pub relative_force_tolerance: f64,
    /// The most Newton iterations the solve may take.
    pub max_newton_iterations: usize,
}

impl Default for StaticSettings {
    fn default() -> Self {
        Self {
            relative_force_tolerance: 1e-12,
            max_newton_iterations: 60,
        }
    }
}

/// What the static solve did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticReport {
    /// Newton iterations taken.
    pub newton_iterations: usize,
    /// CG iterations over all the Newton iterations' solves.
    pub cg_iterations: usize,
    /// Largest force on a free particle at the end, N.
    pub residual_newtons: f64,
    /// The residual the tolerance asked for, N.
    pub tolerance_newtons: f64,
    /// Whether the residual reached the tolerance.
    pub converged: bool,
}

/// Moves the free particles of `state` to static equilibrium and zeroes all velocities.
pub fn solve(model: &Model, state: &mut State, settings: StaticSettings) -> StaticReport {
    solve_loaded(
        model,
        state,
        &vec![Vector3::zeros(); model.vertex_count()],
        settings,
    )
}

/// [`solve`] under the constant external forces `external` (N per particle).
pub fn solve_loaded(
    model: &Model,
    state: &mut State,
    external: &[Vector3],
    settings: StaticSettings,
) -> StaticReport {
    let n = model.vertex_count();
    let zero_ext = external;
    state
        .velocities
        .iter_mut()
        .for_each(|v| *v = Vector3::zeros());
    let mut f = vec![Vector3::zeros(); n];
    let mut dx = vec![Vector3::zeros(); n];
    let mut trial = state.positions.clone();
    let mut f_trial = f.clone();
    let mut sys = SpringSystem::default(); // mass weight 0: the stiffness alone
    let mut cg_scratch = CgScratch::default();
    let s = &model.springs;

    // Scale: the largest spring force in the initial state (and the weight of a particle).
    let mut scale = 0.0f64;
    for (e, &[a, b]) in s.ends.iter().enumerate() {
        let l = (state.positions[b as usize] - state.positions[a as usize]).norm();
        scale = scale.max((s.stiffness[e] * (l - s.rest_length[e])).abs());
    }
    for (&m, fe) in model.mass.iter().zip(external) {
        scale = scale.max(m * model.gravity.norm()).max(fe.norm());
    }
    let tolerance = settings.relative_force_tolerance * scale;

    total_forces(model, &state.positions, &state.velocities, zero_ext, &mut f);
    let mut residual = max_free_force(model, &f);
    let mut cg_total = 0;
    let mut iter = 0;
    let mut stalls = 0;
    while residual > tolerance && iter < settings.max_newton_iterations && stalls < 4 {
        iter += 1;
        sys.begin(&model.particles());
        for (e, &[a, b]) in s.ends.iter().enumerate() {
            let d = state.positions[b as usize] - state.positions[a as usize];
            let (ka, kn, dir) = stiffness_block(s.stiffness[e], s.rest_length[e], &d);
            sys.set_block(e, ka, kn, &dir);
        }
        sys.update_preconditioner(&model.particles());
        dx.iter_mut().for_each(|d| *d = Vector3::zeros());
        let cg = CgSettings {
            relative_tolerance: 1e-10,
            absolute_tolerance: 0.0,
            max_iterations: 10 * n.max(100),
        };
        cg_total += system::solve(&sys, &model.held, &f, &mut dx, cg, &mut cg_scratch).iterations;

        match line_search(
            model,
            &mut state.positions,
            &mut f,
            &dx,
            residual,
            scale,
            &mut trial,
            &mut f_trial,
            |x, out| total_forces(model, x, &state.velocities, zero_ext, out),
        ) {
            Some(r) => residual = r,
            None => stalls += 1,
        }
    }
    StaticReport {
        newton_iterations: iter,
        cg_iterations: cg_total,
        residual_newtons: residual,
        tolerance_newtons: tolerance,
        converged: residual <= tolerance,
    }
}

/// The backtracking step of the static Newton iterations (the springs' and the finite
/// elements'): tries `x + s dx` for `s = 1, 1/2, 1/4, ...` (12 halvings) and takes the first
/// that lowers `sum |f|^2` over the free particles. Close to equilibrium (`residual < 1e-6
/// scale`) the (modified) Newton iteration contracts on its own and round-off makes `|f|` an
/// unreliable merit, so the full step is taken there. On success `x` and `f` hold the new
/// positions and forces (`forces(x, out)` computes them) and the new residual is returned;
/// `None` when no step was taken.
pub(crate) fn line_search(
    model: &Model,
    x: &mut Vec<Point3>,
    f: &mut Vec<Vector3>,
    dx: &[Vector3],
    residual: f64,
    scale: f64,
    trial: &mut Vec<Point3>,
    f_trial: &mut Vec<Vector3>,
    mut forces: impl FnMut(&[Point3], &mut [Vector3]),
) -> Option<f64> {
    let f0 = free_force_norm_squared(model, f);
    let mut step = 1.0;
    for _ in 0..12 {
        for ((t, p), d) in trial.iter_mut().zip(x.iter()).zip(dx) {
            *t = p + d * step;
        }
        forces(trial, f_trial);
        if free_force_norm_squared(model, f_trial) < f0 || residual < 1e-6 * scale {
            std::mem::swap(x, trial);
            std::mem::swap(f, f_trial);
            return Some(max_free_force(model, f));
        }
        step *= 0.5;
    }
    None
}
