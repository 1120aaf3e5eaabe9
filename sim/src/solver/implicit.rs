//! Linearised backward Euler (Baraff and Witkin): with `K = -df/dx`, `C = -df/dv`,
//!
//! `(M + h C + h^2 K) dv = h (f(x, v) - h K v)`, then `v += dv`, `x += h v`.
//!
//! Spring blocks: `K_e = k [alpha I + (1 - alpha) n n^T]` with `alpha = max(0, 1 - l0/l)`,
//! `C_e = c n n^T`, so each spring adds `B_e = h^2 alpha k I + (h c + h^2 (1 - alpha) k) n n^T`.
//! The system is solved by SSOR preconditioned CG (see [`super::system`]), started from the
//! combination of the last four steps' velocity changes closest to the solution in the norm of
//! the system's matrix (a Galerkin projection onto their span, see [`super::span`]; before,
//! their cubic extrapolation `4 dv_1 - 6 dv_2 + 4 dv_3 - dv_4`, which that span holds, and
//! which it starts from in fewer iterations: see `docs/design/solver.md`). The forces, the
//! blocks, the right-hand side and the diagonal blocks are assembled in one pass over the
//! springs, chunk by chunk (gather, vectorised arithmetic, scatter).

use crate::model::{Particles, SpringSet, State};
use crate::{Point3, Vector3};

use super::system::{self, CgReport, CgScratch, CgSettings, SpringSystem, Sym3};

/// Velocity change below which the solve need not resolve: the CG stops at the latest when
/// `|r| <= VELOCITY_FLOOR_M_PER_S sqrt(sum m_i^2)` over the free particles (`r = b - A dv` is a
/// momentum and `A` is close to `M` for the slow motions, so this is an error of about this
/// many m/s). It matters only near rest, where `rhs` is round-off and a relative tolerance
/// would have the solver chase noise.
pub const VELOCITY_FLOOR_M_PER_S: f64 = 1e-12;

/// Springs per chunk of the assembly (its buffers stay in the L1 cache).
const CHUNK: usize = 64;

/// Buffers kept between implicit steps.
#[derive(Debug, Clone, Default)]
pub struct ImplicitScratch {
    /// The step's matrix `M + h C + h^2 K` (see the module documentation).
    pub system: SpringSystem,
    /// The right-hand side `h (f(x, v) - h K v)`.
    pub rhs: Vec<Vector3>,
    /// The previous step's velocity change, then the warm start and the solution.
    pub dv: Vec<Vector3>,
    /// The velocity changes of the three steps before: with `dv`, the cubic extrapolation.
    pub dv_previous: [Vec<Vector3>; 3],
    /// How many of `dv` and `dv_previous` hold solutions (0 after a reset).
    pub history: usize,
    /// The conjugate-gradient solver's buffers.
    pub cg: CgScratch,
    /// The spring blocks in the springs' order, and the first part's contributions to the
    /// second's particles, when the assembly is split (see [`step`]).
    coef_by_spring: Vec<[f64; 4]>,
    spill_rhs: Vec<Vector3>,
    spill_diag: Vec<Sym3>,
    /// For the next step only: where `guess[i]` is known, CG starts from it instead of the
    /// projection, elsewhere from the extrapolation (the history still advances as usual).
    pub(crate) guess: Vec<Option<Vector3>>,
}

/// How an implicit step solves for its velocity change: the CG's settings, and the velocity
/// below which the change need not be resolved (m/s, at least [`VELOCITY_FLOOR_M_PER_S`]):
/// with the step's masses it raises the CG's absolute tolerance ([`velocity_floor`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImplicitSolve {
    /// The conjugate gradient's settings.
    pub cg: CgSettings,
    /// The velocity floor, m/s.
    pub velocity_floor_m_per_s: f64,
}

impl ImplicitSolve {
    /// The CG's settings for a step of `model`'s particles: the absolute tolerance raised to
    /// the velocity floor with their masses.
    pub(crate) fn cg_for(&self, model: &Particles<'_>) -> CgSettings {
        CgSettings {
            absolute_tolerance: self
                .cg
                .absolute_tolerance
                .max(velocity_floor(model, self.velocity_floor_m_per_s)),
            ..self.cg
        }
    }
}

/// One backward-Euler step of `h` seconds.
pub fn step(
    model: &Particles<'_>,
    state: &mut State,
    external: &[Vector3],
    h: f64,
    solve: ImplicitSolve,
    scratch: &mut ImplicitScratch,
) -> CgReport {
    step_on(model, state, external, h, solve, scratch, true)
}

/// [`step`], with the assembly split in two on large systems where `split` (see below).
fn step_on(
    model: &Particles<'_>,
    state: &mut State,
    external: &[Vector3],
    h: f64,
    solve: ImplicitSolve,
    scratch: &mut ImplicitScratch,
    split: bool,
) -> CgReport {
    let n = model.vertex_count();
    let ImplicitScratch {
        system: sys,
        rhs,
        dv,
        dv_previous: [p1, p2, p3],
        history,
        cg: cg_scratch,
        coef_by_spring,
        spill_rhs,
        spill_diag,
        guess,
    } = scratch;
    for buf in [&mut *rhs, &mut *dv, &mut *p1, &mut *p2, &mut *p3] {
        buf.resize(n, Vector3::zeros());
    }

    // Systems of `PARALLEL_MIN_PARTICLES` or more split the springs (sorted by their first
    // particle) in two at a particle `A` near the middle: the first part's springs start below
    // `A` and add to the particles from `A` on through `spill` only, the second part's touch
    // only particles from `A` on. The parts run side by side on two threads, or one after the
    // other on one, with the same arithmetic; then `spill` is added. Smaller systems keep one
    // part (and the results they always had).
    let s = &model.springs;
    let m = s.len();
    sys.mass_weight = 1.0;
    sys.begin(model);
    let split = split && n >= system::PARALLEL_MIN_PARTICLES && sys.springs_sorted_by_first();
    let mid = if split {
        let first = |e: usize| s.ends[e][0];
        let half = m / 2;
        (half..m)
            .find(|&e| e == 0 || first(e) != first(e - 1))
            .unwrap_or(m)
    } else {
        m
    };
    let at = if mid < m { s.ends[mid][0] as usize } else { n };
    let (slots, coef, diag) = sys.parts_mut();
    diag.clear();
    for i in 0..n {
        rhs[i] = (model.gravity * model.mass[i] + external[i]) * h;
        diag.push(Sym3::scalar(model.mass[i]));
    }
    let (x, v) = (&state.positions[..n], &state.velocities[..n]);
    let (rhs, diag) = (&mut rhs[..n], &mut diag[..n]);
    if mid == m {
        let store = |e: usize, c: [f64; 4]| coef[slots[e] as usize] = c;
        assemble_springs(
            s,
            0..m,
            x,
            v,
            h,
            Part { rhs, diag, lo: 0 },
            Part {
                rhs: &mut [],
                diag: &mut [],
                lo: n,
            },
            store,
        );
    } else {
        spill_rhs.clear();
        spill_rhs.resize(n - at, Vector3::zeros());
        spill_diag.clear();
        spill_diag.resize(n - at, Sym3::default());
        let (rhs_lo, rhs_hi) = rhs.split_at_mut(at);
        let (diag_lo, diag_hi) = diag.split_at_mut(at);
        // on two threads the parts hand their blocks over in the springs' order, stored by
        // slot after; on one, each stores its own (the same blocks either way)
        let parallel = system::solver_threads() > 1;
        {
            let own_first = Part {
                rhs: rhs_lo,
                diag: diag_lo,
                lo: 0,
            };
            let spill = Part {
                rhs: &mut spill_rhs[..],
                diag: &mut spill_diag[..],
                lo: at,
            };
            let own_second = Part {
                rhs: &mut *rhs_hi,
                diag: &mut *diag_hi,
                lo: at,
            };
            let no_spill = Part {
                rhs: &mut [],
                diag: &mut [],
                lo: n,
            };
            if parallel {
                coef_by_spring.resize(m, [0.0; 4]);
                let (coef_lo, coef_hi) = coef_by_spring.split_at_mut(mid);
                crate::parallel::side_by_side(
                    || {
                        assemble_springs(s, 0..mid, x, v, h, own_first, spill, |e, c| {
                            coef_lo[e] = c
                        })
                    },
                    || {
                        assemble_springs(s, mid..m, x, v, h, own_second, no_spill, |e, c| {
                            coef_hi[e - mid] = c
                        })
                    },
                );
            } else {
                assemble_springs(s, 0..mid, x, v, h, own_first, spill, |e, c| {
                    coef[slots[e] as usize] = c
                });
                assemble_springs(s, mid..m, x, v, h, own_second, no_spill, |e, c| {
                    coef[slots[e] as usize] = c
                });
            }
        }
        for ((r, d), (sr, sd)) in rhs_hi
            .iter_mut()
            .zip(diag_hi.iter_mut())
            .zip(spill_rhs.iter().zip(spill_diag.iter()))
        {
            *r += sr;
            *d += *sd;
        }
        if parallel {
            sys.set_blocks_by_spring(coef_by_spring, true);
        }
    }
    sys.prepare(model);
    extrapolate_warm_start(dv, [p1, p2, p3], history);
    let guessed = guess.len() == n;
    if guessed {
        for (d, g) in dv.iter_mut().zip(guess.iter()) {
            if let Some(g) = g {
                *d = *g;
            }
        }
    }
    guess.clear();
    let cg = solve.cg_for(model);
    let report = if guessed {
        system::solve(sys, model.held, rhs, dv, cg, cg_scratch)
    } else {
        system::solve_from_span(sys, model.held, rhs, dv, [p1, p2, p3], cg, cg_scratch)
    };
    apply_velocity_change(model, state, dv, h);
    report
}

/// Particles `lo..lo + rhs.len()`: their entries of the right-hand side and of the diagonal
/// blocks.
struct Part<'a> {
    rhs: &'a mut [Vector3],
    diag: &'a mut [Sym3],
    lo: usize,
}

/// Assembles the springs `range` of `s` (whose first particles all lie in `own`, their second
/// in `own` or `spill`): their blocks handed to `store(spring, [g_x, g_y, g_z, beta])`, their
/// contributions to the right-hand side `h (f - h K v)` and to the diagonal blocks added to
/// `own` and `spill`.
///
/// The springs go in chunks, each in three passes: the differences of positions and of
/// velocities are gathered, everything per spring (forces, blocks `B_e`, the contributions to
/// the right-hand side and to the diagonal blocks) is computed in loops that vectorise, and the
/// results are scattered. The sums on the current first particle are kept in registers and
/// stored once per run (a fixed order, so results stay deterministic).
#[allow(clippy::too_many_arguments)]
fn assemble_springs(
    s: &SpringSet,
    range: std::ops::Range<usize>,
    x: &[Point3],
    v: &[Vector3],
    h: f64,
    own: Part<'_>,
    spill: Part<'_>,
    mut store: impl FnMut(usize, [f64; 4]),
) {
    let own_hi = own.lo + own.rhs.len();
    let hh = h * h;
    let mut run = usize::MAX;
    let (mut rhs_run, mut diag_run) = (Vector3::zeros(), Sym3::default());
    let mut buf = [[0.0; CHUNK]; 19];
    let (mut inv_len, mut length, mut sqrt_gamma, mut ka_buf) =
        ([0.0; CHUNK], [0.0; CHUNK], [0.0; CHUNK], [0.0; CHUNK]);
    for start in range.clone().step_by(CHUNK) {
        let end = (start + CHUNK).min(range.end);
        let len = end - start;
        let ends = &s.ends[start..end];
        let [
            dx,
            dy,
            dz,
            ux,
            uy,
            uz,
            gx,
            gy,
            gz,
            beta,
            wx,
            wy,
            wz,
            bxx,
            byy,
            bzz,
            bxy,
            bxz,
            byz,
        ] = &mut buf;
        // d = x_b - x_a and u = v_a - v_b
        for (j, &[a, b]) in ends.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let d = x[b] - x[a];
            let u = v[a] - v[b];
            (dx[j], dy[j], dz[j]) = (d.x, d.y, d.z);
            (ux[j], uy[j], uz[j]) = (u.x, u.y, u.z);
        }
        let (rest, k, c) = (
            &s.rest_length[start..end],
            &s.stiffness[start..end],
            &s.damping[start..end],
        );
        let (dx, dy, dz, ux, uy, uz) = (
            &dx[..len],
            &dy[..len],
            &dz[..len],
            &ux[..len],
            &uy[..len],
            &uz[..len],
        );
        let (gx, gy, gz, beta) = (
            &mut gx[..len],
            &mut gy[..len],
            &mut gz[..len],
            &mut beta[..len],
        );
        let (wx, wy, wz) = (&mut wx[..len], &mut wy[..len], &mut wz[..len]);
        let (bxx, byy, bzz, bxy, bxz, byz) = (
            &mut bxx[..len],
            &mut byy[..len],
            &mut bzz[..len],
            &mut bxy[..len],
            &mut bxz[..len],
            &mut byz[..len],
        );
        // (three loops: one long chain of square roots and divisions per spring would leave the
        // processor waiting)
        let (inv_len, length, sqrt_gamma, ka_buf) = (
            &mut inv_len[..len],
            &mut length[..len],
            &mut sqrt_gamma[..len],
            &mut ka_buf[..len],
        );
        for j in 0..len {
            let l2 = dx[j] * dx[j] + dy[j] * dy[j] + dz[j] * dz[j];
            // a zero-length spring has no direction: no force and a zero block
            let inv_l = if l2 == 0.0 { 0.0 } else { 1.0 / l2.sqrt() };
            inv_len[j] = inv_l;
            length[j] = l2 * inv_l;
        }
        for j in 0..len {
            let inv_l = inv_len[j];
            let alpha = 1.0 - rest[j] * inv_l;
            let alpha = if alpha > 0.0 { alpha } else { 0.0 };
            ka_buf[j] = if inv_l == 0.0 { 0.0 } else { alpha * k[j] };
            // B = h^2 ka I + (h c + h^2 kn) n n^T, stored as beta I + g g^T
            sqrt_gamma[j] = (h * c[j] + hh * ((1.0 - alpha) * k[j])).sqrt();
        }
        for j in 0..len {
            let inv_l = inv_len[j];
            let (nx, ny, nz) = (dx[j] * inv_l, dy[j] * inv_l, dz[j] * inv_l);
            let l = length[j];
            let dvel_n = nx * ux[j] + ny * uy[j] + nz * uz[j];
            // spring force on a: n (k (l - l0) + c (v_b - v_a) . n)
            let f = k[j] * (l - rest[j]) - c[j] * dvel_n;
            let ka = ka_buf[j];
            let kn = k[j] - ka;
            let b = hh * ka;
            let sg = sqrt_gamma[j];
            let (px, py, pz) = (nx * sg, ny * sg, nz * sg);
            (gx[j], gy[j], gz[j], beta[j]) = (px, py, pz, b);
            // rhs += h f - h^2 K (v_a - v_b) on a, the opposite on b
            let along = f * h - kn * dvel_n * hh;
            (wx[j], wy[j], wz[j]) = (
                nx * along - ux[j] * b,
                ny * along - uy[j] * b,
                nz * along - uz[j] * b,
            );
            (bxx[j], byy[j], bzz[j]) = (b + px * px, b + py * py, b + pz * pz);
            (bxy[j], bxz[j], byz[j]) = (px * py, px * pz, py * pz);
        }
        for (j, &[a, b]) in ends.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            if a != run {
                if run != usize::MAX {
                    own.rhs[run - own.lo] += rhs_run;
                    own.diag[run - own.lo] += diag_run;
                }
                run = a;
                rhs_run = Vector3::zeros();
                diag_run = Sym3::default();
            }
            store(start + j, [gx[j], gy[j], gz[j], beta[j]]);
            let w = Vector3::new(wx[j], wy[j], wz[j]);
            rhs_run += w;
            let block = Sym3 {
                xx: bxx[j],
                yy: byy[j],
                zz: bzz[j],
                xy: bxy[j],
                xz: bxz[j],
                yz: byz[j],
            };
            diag_run += block;
            if b < own_hi {
                own.rhs[b - own.lo] -= w;
                own.diag[b - own.lo] += block;
            } else {
                spill.rhs[b - spill.lo] -= w;
                spill.diag[b - spill.lo] += block;
            }
        }
    }
    if run != usize::MAX {
        own.rhs[run - own.lo] += rhs_run;
        own.diag[run - own.lo] += diag_run;
    }
}

/// Warm start of the velocity change `dv` (which holds the last one on entry): the cubic
/// extrapolation `4 dv_1 - 6 dv_2 + 4 dv_3 - dv_4` of the last four velocity changes, of lower
/// order while fewer are known (`history`, which this advances); `previous` shifts by one.
/// Each order up to the cubic starts the solve closer (`docs/design/solver.md`). Shared by the
/// springs and the finite elements.
pub(crate) fn extrapolate_warm_start(
    dv: &mut [Vector3],
    previous: [&mut Vec<Vector3>; 3],
    history: &mut usize,
) {
    let c = match *history {
        0 => [0.0, 0.0, 0.0, 0.0],
        1 => [1.0, 0.0, 0.0, 0.0],
        2 => [2.0, -1.0, 0.0, 0.0],
        3 => [3.0, -3.0, 1.0, 0.0],
        _ => [4.0, -6.0, 4.0, -1.0],
    };
    let [p1, p2, p3] = previous;
    for (((d, d2), d3), d4) in dv
        .iter_mut()
        .zip(p1.iter_mut())
        .zip(p2.iter_mut())
        .zip(p3.iter_mut())
    {
        let last = *d;
        *d = last * c[0] + *d2 * c[1] + *d3 * c[2] + *d4 * c[3];
        *d4 = *d3;
        *d3 = *d2;
        *d2 = last;
    }
    *history = (*history + 1).min(4);
}

/// The absolute floor of the CG residual, `v_floor sqrt(sum m_i^2)` over the free particles,
/// with `v_floor` the larger of `floor_m_per_s` and [`VELOCITY_FLOOR_M_PER_S`].
pub(crate) fn velocity_floor(model: &Particles<'_>, floor_m_per_s: f64) -> f64 {
    let mass_norm = model
        .mass
        .iter()
        .zip(model.held)
        .filter(|(_, h)| !**h)
        .map(|(m, _)| m * m)
        .sum::<f64>()
        .sqrt();
    floor_m_per_s.max(VELOCITY_FLOOR_M_PER_S) * mass_norm
}

/// `v += dv`, then `x += h v`, for the free particles (the end of an implicit Euler step).
pub(crate) fn apply_velocity_change(
    model: &Particles<'_>,
    state: &mut State,
    dv: &[Vector3],
    h: f64,
) {
    for i in 0..model.vertex_count() {
        if model.held[i] {
            continue;
        }
        state.velocities[i] += dv[i];
        state.positions[i] += state.velocities[i] * h;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{BuildOptions, Scene};
    use crate::solver::SolverSettings;

    /// Five steps of the chest wall at 64k tets (over `PARALLEL_MIN_PARTICLES`) pressed on its
    /// top, from rest, on a pool of `threads`, with the assembly split or not: the positions.
    fn pressed_steps(threads: usize, split: bool) -> Vec<crate::Point3> {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(64_000),
            },
        )
        .expect("built-in scene");
        let model = &scene.model;
        let particles = model.particles();
        assert!(particles.vertex_count() >= system::PARALLEL_MIN_PARTICLES);
        let mut state = State::at_rest(&model.mesh);
        let top = state
            .positions
            .iter()
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max);
        let external: Vec<Vector3> = state
            .positions
            .iter()
            .map(|p| {
                if p.z > top - 1e-3 && p.x.abs() < 0.01 {
                    Vector3::new(0.0, 0.0, -0.01)
                } else {
                    Vector3::zeros()
                }
            })
            .collect();
        let settings = SolverSettings::default();
        let solve = ImplicitSolve {
            cg: CgSettings {
                relative_tolerance: settings.cg_relative_tolerance,
                absolute_tolerance: 0.0,
                max_iterations: settings.cg_max_iterations,
            },
            velocity_floor_m_per_s: VELOCITY_FLOOR_M_PER_S,
        };
        let mut scratch = ImplicitScratch::default();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            for _ in 0..5 {
                let report = step_on(
                    &particles,
                    &mut state,
                    &external,
                    settings.time_step_s,
                    solve,
                    &mut scratch,
                    split,
                );
                assert!(report.converged, "{report:?}");
            }
        });
        state.positions
    }

    #[test]
    fn the_split_assembly_gives_the_same_bits_on_one_thread_or_two_and_the_same_motion_as_one_part()
    {
        let (one, two) = (pressed_steps(1, true), pressed_steps(2, true));
        assert!(
            one.iter()
                .zip(&two)
                .all(|(a, b)| a.coords.map(f64::to_bits) == b.coords.map(f64::to_bits))
        );
        // the split only sums in another order: the motion agrees to round-off (relative to
        // the largest displacement)
        let whole = pressed_steps(2, false);
        let start = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(64_000),
            },
        )
        .expect("built-in scene");
        let rest = start.model.mesh.positions();
        let moved = whole
            .iter()
            .zip(rest)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        let differ = whole
            .iter()
            .zip(&one)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(moved > 1e-7, "the press moved the wall {moved} m");
        assert!(
            differ > 0.0 && differ <= 1e-6 * moved,
            "split and whole differ by {differ} m of {moved} m"
        );
    }

    #[test]
    fn a_guess_starts_the_solve_where_it_is_known_and_only_for_one_step() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(2_000),
            },
        )
        .expect("built-in scene");
        let particles = scene.model.particles();
        let n = particles.vertex_count();
        let external = vec![Vector3::new(0.0, 0.0, -0.01); n];
        let settings = SolverSettings::default();
        let solve = ImplicitSolve {
            cg: CgSettings {
                relative_tolerance: 1e-10,
                absolute_tolerance: 0.0,
                max_iterations: 500,
            },
            velocity_floor_m_per_s: VELOCITY_FLOOR_M_PER_S,
        };
        let from_rest = State::at_rest(&scene.model.mesh);
        let (mut state, mut scratch) = (from_rest.clone(), ImplicitScratch::default());
        let plain = step(
            &particles,
            &mut state,
            &external,
            settings.time_step_s,
            solve,
            &mut scratch,
        );
        assert!(plain.converged && plain.iterations > 5, "{plain:?}");
        let solution = scratch.dv.clone();
        // the same step again, started from its solution: nothing left to solve
        let (mut again, mut guessed) = (from_rest.clone(), ImplicitScratch::default());
        guessed.guess = solution.iter().copied().map(Some).collect();
        let report = step(
            &particles,
            &mut again,
            &external,
            settings.time_step_s,
            solve,
            &mut guessed,
        );
        assert!(report.converged && report.iterations <= 1, "{report:?}");
        assert!(
            again
                .positions
                .iter()
                .zip(&state.positions)
                .all(|(a, b)| (a - b).norm() <= 1e-12)
        );
        assert!(guessed.guess.is_empty(), "one step only");
        // known nowhere: the extrapolation (from rest: zero), as without a guess
        let (mut third, mut unknown) = (from_rest, ImplicitScratch::default());
        unknown.guess = vec![None; n];
        let report = step(
            &particles,
            &mut third,
            &external,
            settings.time_step_s,
            solve,
            &mut unknown,
        );
        assert_eq!(report.iterations, plain.iterations);
    }

    /// The chest wall pressed on its top for 20 steps, then let go for 200, with the solve's
    /// velocity floor `floor_m_per_s`: the CG iterations of the steps after the release, the
    /// final positions and the largest displacement from the settled state on the way.
    fn released(floor_m_per_s: f64) -> (usize, Vec<crate::Point3>, f64) {
        let scene = Scene::load("chest-wall", BuildOptions::default()).expect("built-in scene");
        let mut sim = scene.simulation();
        sim.settings.cg_velocity_floor_m_per_s = floor_m_per_s;
        sim.settings.localisation = None;
        sim.settings.check().expect("settings in range");
        sim.settle(crate::solver::StaticSettings::default());
        let settled = sim.state.positions.clone();
        let free = |i: &u32| !sim.model.held[*i as usize];
        let top = (0..settled.len() as u32)
            .filter(free)
            .map(|i| settled[i as usize].z)
            .fold(f64::NEG_INFINITY, f64::max);
        let pressed: Vec<u32> = (0..settled.len() as u32)
            .filter(|i| free(i) && settled[*i as usize].z > top - 2e-3)
            .collect();
        assert!(!pressed.is_empty());
        for &v in &pressed {
            sim.add_external_force(v, Vector3::new(0.0, 0.0, -0.002));
        }
        let mut moved: f64 = 0.0;
        let mut iterations = 0;
        for k in 0..220 {
            if k == 20 {
                sim.clear_external_forces();
            }
            let report = sim.step().expect("a step");
            iterations += if k >= 20 { report.cg_iterations } else { 0 };
            let now = (sim.state.positions.iter().zip(&settled))
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            moved = moved.max(now);
        }
        (iterations, sim.state.positions.clone(), moved)
    }

    /// A velocity floor of 1 um/s spares the solve iterations as the tissue comes to rest,
    /// and moves it by far less than the integrator's own error (2e-3 of the largest
    /// displacement on this scene, `cutlab bench budget`).
    #[test]
    fn a_velocity_floor_spares_iterations_near_rest_within_the_budget() {
        let (tight_iterations, tight, moved) = released(VELOCITY_FLOOR_M_PER_S);
        let (loose_iterations, loose, _) = released(1e-6);
        assert!(
            loose_iterations < tight_iterations,
            "{loose_iterations} against {tight_iterations}"
        );
        let apart = tight
            .iter()
            .zip(&loose)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(
            moved > 0.0 && apart <= 0.1 * 1.8e-3 * moved,
            "{apart} of {moved}"
        );
        let mut bad = SolverSettings::default();
        for floor in [-1e-9, f64::NAN, f64::INFINITY] {
            bad.cg_velocity_floor_m_per_s = floor;
            assert!(bad.check().is_err(), "{floor} accepted");
        }
    }
}
