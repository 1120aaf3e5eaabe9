//! The sparse symmetric system shared by implicit Euler and the static solve, and its
//! preconditioned conjugate-gradient solver.
//!
//! Preconditioner: block SSOR, `M = (D/w + L) D^-1 (D/w + L^T)` (up to a constant factor) with
//! `D` the 3x3 diagonal blocks, `L` the strictly lower block triangle in the particle order and
//! `w` = [`preconditioner::SSOR_OMEGA`], applied with Eisenstat's trick: with `P = D/w + L`, `G` the Cholesky
//! factors of `D` (`G G^T = D`) and `K = (2/w - 1) D`, so that `A = P + P^T - K`, CG runs on
//! `C^-1 A C^-T` with `C = P G^-T` (so `C C^T = M`), whose product with `v` is
//! `G^T [t + P^-1 (G v - K t)]` with `t = P^-T G v`: one backward and one forward block sweep
//! over the springs per iteration, and no separate product with `A`. The iterate is kept in the
//! original variables (`x += alpha t`, as `C^-T v = t`). Systems that do not fit (a free
//! diagonal block that is not positive definite, a spring from a particle to itself) fall back
//! to block-Jacobi.
//!
//! The sweeps visit the particles in a nested-dissection order (see [`super::dissection`]):
//! two halves that no spring joins, then the separator between them. The solver works on
//! vectors gathered into that order; the halves' parts of each sweep run side by side on
//! rayon's threads (from [`PARALLEL_MIN_PARTICLES`] on) and the separator's after them, in the
//! same arithmetic on any number of threads, so a solve gives the same bits on one thread or
//! two.
//!
//! The matrix is `A = a_m M + sum over springs e of B_e`, where each spring contributes the
//! 3x3 block `B_e = beta_e I + gamma_e n_e n_e^T` (stored as `beta_e I + g_e g_e^T`,
//! `g_e = sqrt(gamma_e) n_e`) with the pattern `[+B, -B; -B, +B]` on its two particles. Held
//! particles are removed (their rows and columns act as identity on a zero right-hand side).
//! With `beta, gamma >= 0` the matrix is symmetric positive semi-definite, and positive
//! definite once a particle of every piece is held or `a_m > 0`.
//!
//! The files, by concern:
//!
//! - [`blocks`]: the 3x3 blocks (symmetric [`Sym3`], lower-triangular [`blocks::Lower3`]) and the
//!   spring blocks' stored form;
//! - [`operator`]: [`SpringSystem`], the block-sparse matrix: its assembly and its products;
//! - [`layout`]: where the blocks are stored, in the sweep order of halves and separator, and
//!   the [`SweepOrder`] a resume carries;
//! - [`lanes`]: one vector or several multiplied by the matrix in one pass over the springs;
//! - [`preconditioner`]: block SSOR (and block-Jacobi) from the diagonal blocks, and its
//!   forward and backward sweeps in Eisenstat's form;
//! - [`cg`]: the preconditioned conjugate-gradient solves and their start projected onto a
//!   span.

mod blocks;
mod cg;
mod lanes;
mod layout;
mod operator;
mod preconditioner;
#[cfg(test)]
mod tests;

pub use blocks::{Sym3, stiffness_block};
pub use cg::{CgReport, CgScratch, CgSettings, solve, solve_from_span};
pub use layout::{SweepOrder, SweepOrderError};
pub use operator::{BlockSystem, ElementSystem, SpringSystem};

/// Systems with at least this many particles sweep their two halves on two threads (fewer:
/// on one, in the same order, with the same result). Below it a half sweep is too short to be
/// worth waking another thread for (`docs/design/solver.md`).
pub const PARALLEL_MIN_PARTICLES: usize = 12_000;

/// The threads the solver's sweeps may use: rayon's (one per core; `RAYON_NUM_THREADS=1` for
/// one). Systems of [`PARALLEL_MIN_PARTICLES`] or more use two of them.
pub fn solver_threads() -> usize {
    rayon::current_num_threads().min(2)
}
