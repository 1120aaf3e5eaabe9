//! Integrators and the static solve for the finite elements (see [`super`] for the element).
//!
//! - Forces: `f = f_el(x) - beta K(x) v - alpha M v + M g + f_ext`, with
//!   `f_el,i = -W R sigma(epsilon) b_i` and `(K v)_i = W R sigma(sym(R^T G)) b_i`.
//! - Implicit (linearised backward) Euler, as for the springs:
//!   `(M + h C + h^2 K) dv = h (f(x, v) - h K v)`, then `v += dv`, `x += h v`, with
//!   `C = alpha M + beta K`; assembled in passes that split in halves ([`super::assemble`])
//!   and solved on the springs' solver stack ([`crate::solver::system`]: block SSOR in
//!   Eisenstat's form on the nested-dissection order, two threads on large systems), started
//!   from the projection onto the last four `dv`.
//! - Symplectic Euler, sub-stepped below the stability limit of the bounds
//!   `omega^2 <= max_i sum_j |K_ij|_F / sqrt(m_i m_j)` (block Gershgorin on
//!   `M^-1/2 K M^-1/2`, rotation-invariant, so it holds in every configuration) and
//!   `gamma <= max alpha + max beta omega^2`.
//! - Static equilibrium `f_el(x) + M g + f_ext = 0` by Newton's method with the warped stiffness
//!   `K(x)` (modified Newton: the change of the rotations is left out) and backtracking on `|f|`.

use nalgebra::Matrix3;

use super::assemble::{StepInputs, TetTerms, implicit_system};
use super::{FemModel, rotation, strain, stress};
use crate::mesh::TET_EDGES;
use crate::model::{Model, State};
use crate::solver::explicit::critical_time_step;
use crate::solver::forces::max_free_force;
use crate::solver::implicit::{ImplicitSolve, apply_velocity_change, extrapolate_warm_start};
use crate::solver::statics::line_search;
use crate::solver::system::{self, CgReport, CgScratch, CgSettings, ElementSystem, Sym3};
use crate::solver::{StaticReport, StaticSettings};
use crate::{Point3, Vector3};

/// Buffers kept between steps.
#[derive(Debug, Clone, Default)]
pub struct FemScratch {
    /// The step's block system on the mesh edges.
    pub system: ElementSystem,
    /// The conjugate-gradient solver's buffers.
    pub cg: CgScratch,
    /// The right-hand side of the system.
    pub rhs: Vec<Vector3>,
    /// The previous step's velocity change, then the warm start and the solution.
    pub dv: Vec<Vector3>,
    /// The velocity changes of the three steps before: with `dv`, the span the start is
    /// projected onto.
    pub dv_previous: [Vec<Vector3>; 3],
    /// How many of `dv` and `dv_previous` hold solutions (0 after a reset).
    pub history: usize,
    /// The tetrahedra's terms of the step.
    terms: Vec<TetTerms>,
}

/// What one tetrahedron contributes: its rotation, and the matrices whose columns are the
/// forces on local vertices 1..3 (`-W R sigma(epsilon) D_m^-T`, the elastic force) and
/// `W R sigma(sym(R^T G)) D_m^-T` (the product `K v`); vertex 0 gets minus their sum.
#[inline]
pub(super) fn element(
    fem: &FemModel,
    t: usize,
    x: &[Point3],
    v: &[Vector3],
) -> (Matrix3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let w = fem.rest_volume_m3[t];
    if w == 0.0 {
        return (Matrix3::identity(), Matrix3::zeros(), Matrix3::zeros());
    }
    let (mu, lambda) = (fem.mu_pa[t], fem.lambda_pa[t]);
    let dm_inv = &fem.rest_inverse[t];
    let f = fem.deformation_gradient(t, x);
    let r = rotation(&f);
    let sigma = stress(mu, lambda, &strain(&r, &f));
    let [v0, v1, v2, v3] = fem.tets[t].map(|i| v[i as usize]);
    let g = Matrix3::from_columns(&[v1 - v0, v2 - v0, v3 - v0]) * dm_inv;
    let rg = r.transpose() * g;
    let eps_v = (rg + rg.transpose()) * 0.5;
    let sigma_v = stress(mu, lambda, &eps_v);
    let dm_inv_t = dm_inv.transpose();
    let h_el = -(r * sigma * dm_inv_t) * w;
    let h_kv = (r * sigma_v * dm_inv_t) * w;
    (r, h_el, h_kv)
}

/// Adds `columns` of `h` (vertices 1..3) and minus their sum (vertex 0) times `weight`.
#[inline]
fn scatter(tet: &[u32; 4], h: &Matrix3<f64>, weight: f64, out: &mut [Vector3]) {
    let (c1, c2, c3) = (
        h.column(0).into_owned(),
        h.column(1).into_owned(),
        h.column(2).into_owned(),
    );
    out[tet[0] as usize] -= (c1 + c2 + c3) * weight;
    out[tet[1] as usize] += c1 * weight;
    out[tet[2] as usize] += c2 * weight;
    out[tet[3] as usize] += c3 * weight;
}

/// Writes into `out` the total force on every particle:
/// `f_el(x) - beta K v - alpha M v + m g + f_ext`.
pub fn total_forces(
    model: &Model,
    fem: &FemModel,
    x: &[Point3],
    v: &[Vector3],
    external: &[Vector3],
    out: &mut [Vector3],
) {
    for i in 0..out.len() {
        out[i] = model.gravity * model.mass[i] + external[i] - v[i] * fem.damping_mass[i];
    }
    for t in 0..fem.len() {
        let (_, h_el, h_kv) = element(fem, t, x, v);
        scatter(&fem.tets[t], &h_el, 1.0, out);
        scatter(&fem.tets[t], &h_kv, -fem.beta_s[t], out);
    }
}

/// Potential energy in joules: elastic energy minus `sum m_i g . x_i`.
pub fn potential_energy(model: &Model, fem: &FemModel, x: &[Point3]) -> f64 {
    let gravity: f64 = x
        .iter()
        .zip(&model.mass)
        .map(|(p, &m)| m * model.gravity.dot(&p.coords))
        .sum();
    fem.elastic_energy(x) - gravity
}

/// Adds `weight K(x)` (the warped stiffness) to the blocks of `sys`.
fn add_stiffness(fem: &FemModel, t: usize, r: &Matrix3<f64>, weight: f64, sys: &mut ElementSystem) {
    if fem.rest_volume_m3[t] == 0.0 || weight == 0.0 {
        return;
    }
    add_blocks(fem, t, &fem.stiffness_blocks(t, r), weight, sys);
}

/// Adds `weight k` (element blocks of tetrahedron `t`) to the blocks of `sys`.
fn add_blocks(
    fem: &FemModel,
    t: usize,
    k: &[[Matrix3<f64>; 4]; 4],
    weight: f64,
    sys: &mut ElementSystem,
) {
    let tet = fem.tets[t];
    for i in 0..4 {
        sys.diag[tet[i] as usize] += Sym3::symmetric_part(&(k[i][i] * weight));
    }
    for (l, &[i, j]) in TET_EDGES.iter().enumerate() {
        let e = fem.tet_edges[t][l] as usize;
        sys.add_off(e, tet[i], tet[j], &(k[i][j] * weight));
    }
}

/// One implicit Euler step of `h` seconds.
pub fn implicit_step(
    model: &Model,
    fem: &FemModel,
    state: &mut State,
    external: &[Vector3],
    h: f64,
    solve: ImplicitSolve,
    scratch: &mut FemScratch,
) -> CgReport {
    let n = model.vertex_count();
    let FemScratch {
        system: sys,
        cg,
        rhs,
        dv,
        dv_previous: [p1, p2, p3],
        history,
        terms,
    } = scratch;
    for buf in [&mut *rhs, &mut *dv, &mut *p1, &mut *p2, &mut *p3] {
        buf.resize(n, Vector3::zeros());
    }
    sys.begin_edges(n, &fem.edges);
    let inputs = StepInputs {
        model,
        fem,
        x: &state.positions[..n],
        v: &state.velocities[..n],
        external,
        h,
    };
    implicit_system(&inputs, terms, sys, rhs);
    sys.prepare_held(&model.held, &[]);
    extrapolate_warm_start(dv, [p1, p2, p3], history);
    let particles = model.particles();
    let settings = solve.cg_for(&particles);
    let report = system::solve_from_span(sys, &model.held, rhs, dv, [p1, p2, p3], settings, cg);
    apply_velocity_change(&particles, state, dv, h);
    report
}

/// Upper bounds of the highest angular frequency (rad/s) and damping rate (1/s) of the free
/// particles (see the module documentation).
pub fn spectral_bounds(model: &Model, fem: &FemModel) -> (f64, f64) {
    let n = model.vertex_count();
    let mut row = vec![0.0; n];
    let identity = Matrix3::identity();
    for t in 0..fem.len() {
        if fem.rest_volume_m3[t] == 0.0 {
            continue;
        }
        let k = fem.stiffness_blocks(t, &identity);
        let tet = fem.tets[t].map(|v| v as usize);
        for i in 0..4 {
            for j in 0..4 {
                if model.held[tet[j]] {
                    continue;
                }
                row[tet[i]] += k[i][j].norm() / (model.mass[tet[i]] * model.mass[tet[j]]).sqrt();
            }
        }
    }
    let (mut omega2, mut alpha) = (0.0f64, 0.0f64);
    for i in 0..n {
        if !model.held[i] {
            omega2 = omega2.max(row[i]);
            alpha = alpha.max(fem.damping_mass[i] / model.mass[i]);
        }
    }
    let beta = fem.beta_s.iter().copied().fold(0.0, f64::max);
    (omega2.sqrt(), alpha + beta * omega2)
}

/// Sub-steps of `dt` for symplectic Euler at `safety` times the stability limit.
pub fn substeps_for(model: &Model, fem: &FemModel, dt: f64, safety: f64) -> u32 {
    let (omega, gamma) = spectral_bounds(model, fem);
    let h = safety * critical_time_step(omega, gamma);
    ((dt / h).ceil().max(1.0)).min(u32::MAX as f64) as u32
}

/// Symplectic Euler: `substeps` sub-steps of `dt / substeps`.
pub fn explicit_step(
    model: &Model,
    fem: &FemModel,
    state: &mut State,
    external: &[Vector3],
    dt: f64,
    substeps: u32,
    forces: &mut Vec<Vector3>,
) {
    let h = dt / substeps as f64;
    let n = model.vertex_count();
    forces.resize(n, Vector3::zeros());
    for _ in 0..substeps {
        total_forces(
            model,
            fem,
            &state.positions,
            &state.velocities,
            external,
            forces,
        );
        for i in 0..n {
            let v = &mut state.velocities[i];
            *v += forces[i] * (h * model.inv_mass[i]);
            state.positions[i] += *v * h;
        }
    }
}

/// Moves the free particles to static equilibrium under gravity and `external` forces;
/// velocities are zeroed.
pub fn statics(
    model: &Model,
    fem: &FemModel,
    state: &mut State,
    external: &[Vector3],
    settings: StaticSettings,
) -> StaticReport {
    let n = model.vertex_count();
    state
        .velocities
        .iter_mut()
        .for_each(|v| *v = Vector3::zeros());
    let zero_v = vec![Vector3::zeros(); n];
    let mut f = vec![Vector3::zeros(); n];
    let mut f_trial = f.clone();
    let mut dx = vec![Vector3::zeros(); n];
    let mut trial = state.positions.clone();
    let mut sys = ElementSystem::default();
    let mut cg = CgScratch::default();

    // Scale: the largest elastic nodal force magnitude of an element in the initial state, the
    // largest weight and the largest external force.
    let mut scale = 0.0f64;
    for t in 0..fem.len() {
        let (_, h_el, _) = element(fem, t, &state.positions, &zero_v);
        scale = scale.max(h_el.column_iter().map(|c| c.norm()).fold(0.0, f64::max));
    }
    for i in 0..n {
        scale = scale
            .max(model.mass[i] * model.gravity.norm())
            .max(external[i].norm());
    }
    let tolerance = settings.relative_force_tolerance * scale;
    total_forces(model, fem, &state.positions, &zero_v, external, &mut f);
    let mut residual = max_free_force(model, &f);
    let (mut iter, mut cg_total, mut stalls) = (0, 0, 0);
    let mut exact = true;
    while residual > tolerance && iter < settings.max_newton_iterations && stalls < 4 {
        iter += 1;
        // Newton with the exact tangent where it is positive definite; where the solve breaks
        // down on it (an indefinite tangent far from equilibrium), the warped stiffness.
        for attempt in [exact, false] {
            sys.begin_sums(n, &fem.edges);
            for t in 0..fem.len() {
                match attempt
                    .then(|| fem.exact_stiffness_blocks(t, &state.positions))
                    .flatten()
                {
                    Some(k) => add_blocks(fem, t, &k, 1.0, &mut sys),
                    None => add_stiffness(
                        fem,
                        t,
                        &rotation(&fem.deformation_gradient(t, &state.positions)),
                        1.0,
                        &mut sys,
                    ),
                }
            }
            sys.prepare_held(&model.held, &[]);
            dx.iter_mut().for_each(|d| *d = Vector3::zeros());
            // (an inexact Newton step: the force tolerance decides the accuracy; a tighter
            // true residual is out of reach on the stiffest bars and would mark the exact
            // tangent as failed)
            let settings = CgSettings {
                relative_tolerance: 1e-8,
                absolute_tolerance: 0.0,
                max_iterations: 10 * n.max(100),
            };
            let report = system::solve(&sys, &model.held, &f, &mut dx, settings, &mut cg);
            cg_total += report.iterations;
            if report.converged || !attempt {
                break;
            }
            exact = false; // the exact tangent was not positive definite here: stay warped
        }
        match line_search(
            model,
            &mut state.positions,
            &mut f,
            &dx,
            residual,
            scale,
            &mut trial,
            &mut f_trial,
            |x, out| total_forces(model, fem, x, &zero_v, external, out),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::FemMaterial;
    use crate::generate::{GridCells, boxed};
    use crate::model::Material;

    fn model(pretension: f64) -> (Model, FemModel) {
        let mesh = boxed(
            Point3::origin(),
            [0.02, 0.01, 0.01],
            GridCells {
                nx: 2,
                ny: 1,
                nz: 1,
            },
        )
        .expect("box")
        .mesh;
        let material = Material {
            pretension,
            ..Material::default()
        };
        let model = Model::new(mesh, &[(0, material)], &[], Vector3::zeros()).expect("model");
        let fem = FemModel::build(
            &model.mesh,
            &model.materials,
            &[(0, FemMaterial::CHEST_WALL)],
        )
        .expect("fem");
        (model, fem)
    }

    /// An empty system on the elements' edges.
    fn stiffness_system(n: usize, fem: &FemModel) -> ElementSystem {
        let mut sys = ElementSystem::default();
        sys.begin_sums(n, &fem.edges);
        sys
    }

    #[test]
    fn rotation_is_proper_even_for_inverted_elements() {
        let f = Matrix3::new(1.0, 0.2, 0.0, 0.1, -0.8, 0.3, 0.0, 0.1, 1.2);
        assert!(f.determinant() < 0.0);
        let r = rotation(&f);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
        let s = r.transpose() * f;
        assert!((s - s.transpose()).norm() < 1e-12, "R^T F symmetric");
        assert_eq!(
            rotation(&Matrix3::from_element(f64::NAN)),
            Matrix3::identity()
        );
    }

    /// The Newton polar factor agrees with the SVD's, from mild to strong deformations.
    #[test]
    fn newton_polar_factor_matches_the_svd() {
        for k in 0..200 {
            let a = k as f64;
            let rot = nalgebra::Rotation3::from_euler_angles(0.1 * a, -0.07 * a, 0.03 * a);
            let stretch = Matrix3::new(
                1.0 + 0.3 * (0.9 * a).sin(),
                0.2 * (1.1 * a).cos(),
                0.1,
                0.0,
                1.0 + 0.5 * (0.4 * a).cos().powi(2),
                -0.3 * (0.3 * a).sin(),
                0.0,
                0.0,
                0.2 + (0.7 * a).sin().abs(),
            );
            let f = rot.matrix() * stretch * (1.0 + 0.01 * a);
            assert!(f.determinant() > 0.0);
            let (r, r_svd) = (rotation(&f), crate::fem::rotation_by_svd(&f));
            assert!((r - r_svd).norm() < 1e-10, "{k}: {r} vs {r_svd}");
        }
    }

    /// A rigid rotation of the rest shape gives no force, and the stiffness is the derivative
    /// of the force there (finite differences).
    #[test]
    fn rigid_motion_is_force_free_and_stiffness_matches_finite_differences() {
        let (model, fem) = model(0.0);
        let n = model.vertex_count();
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 0.9);
        let x: Vec<Point3> = model
            .mesh
            .positions()
            .iter()
            .map(|p| rot * p + Vector3::new(0.1, 0.2, 0.3))
            .collect();
        let v = vec![Vector3::zeros(); n];
        let zero = vec![Vector3::zeros(); n];
        let mut f = vec![Vector3::zeros(); n];
        total_forces(&model, &fem, &x, &v, &zero, &mut f);
        let scale = 30e3 * 0.01 * 0.01;
        assert!(f.iter().all(|f| f.norm() < 1e-12 * scale), "{f:?}");
        let mut sys = stiffness_system(n, &fem);
        for t in 0..fem.len() {
            let r = rotation(&fem.deformation_gradient(t, &x));
            add_stiffness(&fem, t, &r, 1.0, &mut sys);
        }
        sys.prepare_held(&model.held, &[]);
        let dir: Vec<Vector3> = (0..n)
            .map(|i| Vector3::new((i as f64).sin(), (1.3 * i as f64).cos(), 0.2))
            .collect();
        assert_is_force_derivative(&model, &fem, &x, &sys, &dir);
    }

    /// Asserts that the stiffness `sys` applied to `dir` is minus the derivative of the forces
    /// at rest velocity along `dir` (central differences).
    fn assert_is_force_derivative(
        model: &Model,
        fem: &FemModel,
        x: &[Point3],
        sys: &ElementSystem,
        dir: &[Vector3],
    ) {
        let n = x.len();
        let v = vec![Vector3::zeros(); n];
        let mut kd = vec![Vector3::zeros(); n];
        sys.apply(dir, &mut kd);
        let eps = 1e-7;
        let xp: Vec<Point3> = x.iter().zip(dir).map(|(p, d)| p + d * eps).collect();
        let xm: Vec<Point3> = x.iter().zip(dir).map(|(p, d)| p - d * eps).collect();
        let (mut fp, mut fm) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        total_forces(model, fem, &xp, &v, &v, &mut fp);
        total_forces(model, fem, &xm, &v, &v, &mut fm);
        let k_scale = kd.iter().map(|k| k.norm()).fold(0.0, f64::max);
        for i in 0..n {
            let fd = -(fp[i] - fm[i]) / (2.0 * eps);
            assert!(
                (fd - kd[i]).norm() < 1e-5 * k_scale,
                "{i}: {fd} vs {}",
                kd[i]
            );
        }
    }

    /// The exact tangent is the derivative of the forces in a deformed, rotated, pre-stressed
    /// state.
    #[test]
    fn exact_stiffness_matches_finite_differences() {
        let (model, fem) = model(0.04);
        let n = model.vertex_count();
        let rot = nalgebra::Rotation3::from_euler_angles(0.2, 0.4, -0.3);
        let x: Vec<Point3> = model
            .mesh
            .positions()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                rot * p + Vector3::new((i as f64).sin(), (2.0 * i as f64).cos(), 0.5) * 1e-3
            })
            .collect();
        let mut sys = stiffness_system(n, &fem);
        for t in 0..fem.len() {
            let k = fem
                .exact_stiffness_blocks(t, &x)
                .expect("not near inversion");
            add_blocks(&fem, t, &k, 1.0, &mut sys);
        }
        sys.prepare_held(&model.held, &[]);
        let dir: Vec<Vector3> = (0..n)
            .map(|i| Vector3::new((0.7 * i as f64).cos(), (1.1 * i as f64).sin(), -0.4))
            .collect();
        assert_is_force_derivative(&model, &fem, &x, &sys, &dir);
    }

    #[test]
    fn pretension_scales_the_rest_shape() {
        let (model, fem) = model(0.04);
        let x = model.mesh.positions();
        for t in 0..fem.len() {
            let f = fem.deformation_gradient(t, x);
            assert!((f - Matrix3::identity() / 0.96).norm() < 1e-12);
            assert!(
                (fem.rest_volume_m3[t] - 0.96f64.powi(3) * model.mesh.tet_volume(t)).abs()
                    < 1e-12 * fem.rest_volume_m3[t]
            );
        }
    }
}
