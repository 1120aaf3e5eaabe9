//! The implicit step's system from the elements, in two passes that each split in halves:
//!
//! 1. per tetrahedron ([`TetTerms`]): its rotation `R` (polar decomposition), its nodal forces
//!    `h f_el - (h beta + h^2) K v` and the rotated gradients `c_i = R b_i`;
//! 2. per particle and per edge, summing the terms of the tetrahedra around it: the right-hand
//!    side, the diagonal blocks `(m + h alpha m) I + sum (h beta + h^2) K_ii` and the edges'
//!    blocks `sum (h beta + h^2) K_ab`, with (see [`super`])
//!    `K_ab = W [mu (b_a . b_b) I + mu c_b c_a^T + lambda c_a c_b^T]`.
//!
//! Each pass writes only its own entries (a tetrahedron's terms, a particle's, an edge's), so
//! the two halves of each run side by side with no shared sums, and the results are the same
//! bits on one thread or two.

use nalgebra::Matrix3;

use super::FemModel;
use crate::mesh::{Csr, TET_EDGES};
use crate::model::Model;
use crate::parallel::join;
use crate::solver::system::{ElementSystem, Sym3};
use crate::{Point3, Vector3};

/// Tetrahedra from which the assembly's passes run on two threads (fewer: one, the same bits).
pub(crate) const PARALLEL_MIN_TETS: usize = 4_000;

/// Where each particle and each edge is in the tetrahedra: the passes' gather lists, derived
/// with the elements (after every topology change).
#[derive(Debug, Clone, Default)]
pub struct Incidence {
    /// Per particle: `4 t + i` for each tetrahedron `t` whose local vertex `i` it is.
    pub(crate) vertex: Csr,
    /// Per edge: `8 t + l` for each tetrahedron `t` whose local edge `l`
    /// ([`TET_EDGES`]) it is.
    pub(crate) edge: Csr,
}

impl Incidence {
    /// The lists of `tets` on `vertex_count` particles and `edge_count` edges (`tet_edges`:
    /// each tetrahedron's edge ids).
    pub fn build(
        vertex_count: usize,
        tets: &[[u32; 4]],
        edge_count: usize,
        tet_edges: &[[u32; 6]],
    ) -> Self {
        let mut incidence = Self::default();
        incidence.vertex.refill(vertex_count, || {
            tets.iter()
                .enumerate()
                .flat_map(|(t, tet)| (0..4).map(move |i| (tet[i], 4 * t as u32 + i as u32)))
        });
        incidence.edge.refill(edge_count, || {
            tet_edges
                .iter()
                .enumerate()
                .flat_map(|(t, edges)| (0..6).map(move |l| (edges[l], 8 * t as u32 + l as u32)))
        });
        incidence
    }
}

/// One tetrahedron's part of the step (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct TetTerms {
    /// The right-hand side's part on each local vertex.
    force: [Vector3; 4],
    /// `c_i = R b_i`.
    c: [Vector3; 4],
    /// `k (h beta + h^2)` for `k = 1`, `W mu`, `W lambda`.
    weight: f64,
    weight_mu: f64,
    weight_lambda: f64,
}

/// The step's inputs.
pub struct StepInputs<'a> {
    pub model: &'a Model,
    pub fem: &'a FemModel,
    pub x: &'a [Point3],
    pub v: &'a [Vector3],
    pub external: &'a [Vector3],
    pub h: f64,
}

/// Fills `sys` (after `begin_edges` on the elements' edges: every block is written) and `rhs`
/// with the implicit step's system `(M + h C + h^2 K) dv = h (f - h K v)`, `terms` as scratch.
pub fn implicit_system(
    inputs: &StepInputs<'_>,
    terms: &mut Vec<TetTerms>,
    sys: &mut ElementSystem,
    rhs: &mut [Vector3],
) {
    let fem = inputs.fem;
    let nt = fem.len();
    let parallel = nt >= PARALLEL_MIN_TETS && crate::solver::solver_threads() > 1;
    terms.resize(nt, TetTerms::default());
    {
        let half = nt / 2;
        let (lo, hi) = terms.split_at_mut(half);
        join(
            parallel,
            || tet_terms(inputs, 0, lo),
            || tet_terms(inputs, half, hi),
        );
    }
    let terms = &terms[..];
    let n = rhs.len();
    let edges = &fem.edges;
    let (rank, edge_of_slot, coef, diag) = sys.slot_parts_mut();
    {
        let half = n / 2;
        let (rhs_lo, rhs_hi) = rhs.split_at_mut(half);
        let (diag_lo, diag_hi) = diag.split_at_mut(half);
        join(
            parallel,
            || particle_sums(inputs, terms, 0, rhs_lo, diag_lo),
            || particle_sums(inputs, terms, half, rhs_hi, diag_hi),
        );
    }
    // the edges' blocks by slot, each oriented to the slot's first particle
    let half = coef.len() / 2;
    let (coef_lo, coef_hi) = coef.split_at_mut(half);
    let edge_sums = |slot0: usize, out: &mut [Matrix3<f64>]| {
        for (j, block) in out.iter_mut().enumerate() {
            let e = edge_of_slot[slot0 + j] as usize;
            let [a, b] = edges[e];
            let first = if rank[a as usize] < rank[b as usize] {
                a
            } else {
                b
            };
            let mut sum = Matrix3::zeros();
            for &item in fem.incidence.edge.row(e) {
                let (t, l) = ((item >> 3) as usize, (item & 7) as usize);
                let [i, j] = TET_EDGES[l];
                let (i, j) = if fem.tets[t][i] == first {
                    (i, j)
                } else {
                    (j, i)
                };
                let w = &terms[t];
                let (ci, cj) = (w.c[i], w.c[j]);
                sum += Matrix3::identity() * (w.weight * fem.rest_dots[t][4 + l])
                    + cj * (ci * w.weight_mu).transpose()
                    + ci * (cj * w.weight_lambda).transpose();
            }
            *block = -sum;
        }
    };
    join(
        parallel,
        || edge_sums(0, coef_lo),
        || edge_sums(half, coef_hi),
    );
}

/// The terms of the tetrahedra from `t0` (one per entry of `out`).
fn tet_terms(inputs: &StepInputs<'_>, t0: usize, out: &mut [TetTerms]) {
    let StepInputs { fem, x, v, h, .. } = *inputs;
    for (j, terms) in out.iter_mut().enumerate() {
        let t = t0 + j;
        let w = fem.rest_volume_m3[t];
        if w == 0.0 {
            *terms = TetTerms::default();
            continue;
        }
        let (r, h_el, h_kv) = super::solve::element(fem, t, x, v);
        let kw = h * fem.beta_s[t] + h * h;
        let forces = h_el * h - h_kv * kw;
        let (c1, c2, c3) = (
            forces.column(0).into_owned(),
            forces.column(1).into_owned(),
            forces.column(2).into_owned(),
        );
        let b = super::gradients(&fem.rest_inverse[t]);
        *terms = TetTerms {
            force: [-(c1 + c2 + c3), c1, c2, c3],
            c: b.map(|bi| r * bi),
            weight: kw,
            weight_mu: kw * w * fem.mu_pa[t],
            weight_lambda: kw * w * fem.lambda_pa[t],
        };
    }
}

/// The right-hand side and diagonal blocks of the particles from `i0`.
fn particle_sums(
    inputs: &StepInputs<'_>,
    terms: &[TetTerms],
    i0: usize,
    rhs: &mut [Vector3],
    diag: &mut [Sym3],
) {
    let StepInputs {
        model,
        fem,
        v,
        external,
        h,
        ..
    } = *inputs;
    for (j, (rhs, diag)) in rhs.iter_mut().zip(diag.iter_mut()).enumerate() {
        let i = i0 + j;
        let mut force =
            (model.gravity * model.mass[i] + external[i] - v[i] * fem.damping_mass[i]) * h;
        let mut block = Sym3::scalar(model.mass[i] + h * fem.damping_mass[i]);
        for &item in fem.incidence.vertex.row(i) {
            let (t, l) = ((item >> 2) as usize, (item & 3) as usize);
            let w = &terms[t];
            force += w.force[l];
            block += Sym3::scalar(w.weight * fem.rest_dots[t][l]);
            block += Sym3::outer(&w.c[l], w.weight_mu + w.weight_lambda);
        }
        *rhs = force;
        *diag = block;
    }
}
