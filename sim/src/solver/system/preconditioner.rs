//! The preconditioner: block SSOR applied in Eisenstat's form (see the parent module's
//! documentation), built from the diagonal blocks, with block-Jacobi as the fallback; and the
//! forward and backward block sweeps over a part of the sweep order that apply it.

use crate::Vector3;
use crate::model::Particles;

use super::blocks::{Lower3, OffBlock, Sym3, block_matrix};
use super::{BlockSystem, PARALLEL_MIN_PARTICLES, SpringSystem, solver_threads};
use crate::parallel::join;

/// Relaxation factor `w` of the SSOR preconditioner `M = (D/w + L) D^-1 (D/w + L^T)`, where
/// the chest wall's solves took the fewest iterations (`docs/design/solver.md`).
pub const SSOR_OMEGA: f64 = 1.3;

impl SpringSystem {
    /// Recomputes the diagonal blocks from the spring blocks and the masses, then the
    /// preconditioner.
    pub fn update_preconditioner(&mut self, model: &Particles<'_>) {
        let n = model.vertex_count();
        self.diag.clear();
        self.diag.extend(
            model
                .mass
                .iter()
                .map(|&m| Sym3::scalar(self.mass_weight * m)),
        );
        let order = &self.layout.order;
        for (k, &i) in order[..n].iter().enumerate() {
            let slots = self.layout.start[k]..self.layout.start[k + 1];
            for (&other, c) in self.layout.other[slots.clone()]
                .iter()
                .zip(&self.coef[slots])
            {
                let block = block_matrix(c);
                self.diag[i as usize] += block;
                self.diag[order[other as usize] as usize] += block;
            }
        }
        self.prepare(model);
    }

    /// [`BlockSystem::prepare`] for the particles of `model`.
    pub fn prepare(&mut self, model: &Particles<'_>) {
        self.prepare_held(model.held, model.mass);
    }
}

impl<B: OffBlock> BlockSystem<B> {
    /// Builds the preconditioner from the diagonal blocks in `diag` (zeroing those of the
    /// `held` particles), in the sweep order of the layout [`Self::begin_edges`] built. `mass`:
    /// the particles' masses (weighted by `mass_weight` in `A`), for springs only.
    pub fn prepare_held(&mut self, held: &[bool], mass: &[f64]) {
        let n = held.len();
        for (d, &h) in self.diag[..n].iter_mut().zip(held) {
            if h {
                *d = Sym3::default();
            }
        }
        self.inv_diag.resize(n, Sym3::default());
        self.chol.resize(n, Lower3::default());
        self.mass.resize(if B::LAPLACIAN { n } else { 0 }, 0.0);
        self.diag_ranked
            .resize(if B::LAPLACIAN { 0 } else { n }, Sym3::default());
        self.held.resize(n, false);
        // each rank on its own: the two halves of the ranks side by side on a large system
        let (diag, weight, order) = (&self.diag, self.mass_weight, &self.layout.order[..n]);
        let fill = |order: &[u32],
                    inv_diag: &mut [Sym3],
                    chol: &mut [Lower3],
                    ranked_mass: &mut [f64],
                    ranked_diag: &mut [Sym3],
                    ranked_held: &mut [bool]| {
            let mut all_factored = true;
            for (k, &i) in order.iter().enumerate() {
                let (i, h) = (i as usize, held[i as usize]);
                if B::LAPLACIAN {
                    ranked_mass[k] = weight * mass[i];
                } else {
                    ranked_diag[k] = diag[i];
                }
                ranked_held[k] = h;
                if h {
                    inv_diag[k] = Sym3::default();
                    chol[k] = Lower3::default();
                    continue;
                }
                let d = &diag[i];
                let inv = d.inverse_or_zero();
                inv_diag[k] = Sym3 {
                    xx: SSOR_OMEGA * inv.xx,
                    yy: SSOR_OMEGA * inv.yy,
                    zz: SSOR_OMEGA * inv.zz,
                    xy: SSOR_OMEGA * inv.xy,
                    xz: SSOR_OMEGA * inv.xz,
                    yz: SSOR_OMEGA * inv.yz,
                };
                let g = Lower3::cholesky(d);
                all_factored &= g.is_some();
                chol[k] = g.unwrap_or_default();
            }
            all_factored
        };
        let half = n / 2;
        let (inv_lo, inv_hi) = self.inv_diag[..n].split_at_mut(half);
        let (chol_lo, chol_hi) = self.chol[..n].split_at_mut(half);
        let (mass_len, diag_len) = (self.mass.len(), self.diag_ranked.len());
        let (mass_lo, mass_hi) = self.mass.split_at_mut(half.min(mass_len));
        let (diag_lo, diag_hi) = self.diag_ranked.split_at_mut(half.min(diag_len));
        let (held_lo, held_hi) = self.held[..n].split_at_mut(half);
        let parallel = n >= PARALLEL_MIN_PARTICLES && solver_threads() > 1;
        let (lo, hi) = join(
            parallel,
            || fill(&order[..half], inv_lo, chol_lo, mass_lo, diag_lo, held_lo),
            || fill(&order[half..], inv_hi, chol_hi, mass_hi, diag_hi, held_hi),
        );
        self.ssor = !self.layout.has_loop && lo && hi;
    }
}

/// What the sweeps read of the system, by rank.
pub(super) struct Sweeps<'a, B> {
    pub(super) start: &'a [usize],
    pub(super) other: &'a [u32],
    pub(super) coef: &'a [B],
    pub(super) inv_diag: &'a [Sym3],
    pub(super) chol: &'a [Lower3],
    /// Where the separator starts.
    pub(super) s: usize,
}

impl<B> Clone for Sweeps<'_, B> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<B> Copy for Sweeps<'_, B> {}

impl<B: OffBlock> Sweeps<'_, B> {
    /// The forward sweep at rank `k` of a part starting at `lo` whose entries of the sweep's
    /// vector are `own`: `u = w D_k^-1 own_k`, then `N^T u` added to the later particles of
    /// `k`'s slots, in `own` or, beyond it, in the separator's `spill`. Returns `u`.
    #[inline(always)]
    fn forward_at(
        &self,
        k: usize,
        lo: usize,
        own: &mut [Vector3],
        spill: &mut [Vector3],
    ) -> Vector3 {
        let u = self.inv_diag[k].mul(&own[k - lo]);
        let hi = lo + own.len();
        let slots = self.start[k]..self.start[k + 1];
        for (&o, c) in self.other[slots.clone()].iter().zip(&self.coef[slots]) {
            let (o, w) = (o as usize, c.mul_transpose(&u));
            if o < hi {
                own[o - lo] += w;
            } else {
                spill[o - self.s] += w;
            }
        }
        u
    }

    /// The first forward sweep over a part: `r^ = G^T P^-1 r` (`acc` holds `r`), `p = 0`.
    pub(super) fn forward_first(
        &self,
        lo: usize,
        acc: &mut [Vector3],
        spill: &mut [Vector3],
        r: &mut [Vector3],
        p: &mut [Vector3],
    ) {
        for j in 0..acc.len() {
            let k = lo + j;
            let u = self.forward_at(k, lo, acc, spill);
            r[j] = self.chol[k].mul_transpose(&u);
            p[j] = Vector3::zeros();
        }
    }

    /// An iteration's forward sweep over a part: `u = P^-1 acc`, `q = G^T (t + u)`; returns
    /// the part's `p . q`.
    pub(super) fn forward(
        &self,
        lo: usize,
        acc: &mut [Vector3],
        spill: &mut [Vector3],
        t: &[Vector3],
        p: &[Vector3],
        q: &mut [Vector3],
    ) -> f64 {
        let mut pq = 0.0;
        for j in 0..acc.len() {
            let k = lo + j;
            let u = self.forward_at(k, lo, acc, spill);
            let qj = self.chol[k].mul_transpose(&(t[j] + u));
            q[j] = qj;
            pq += p[j].dot(&qj);
        }
        pq
    }

    /// An iteration's backward sweep over a part: `p = r^ + beta p`, `t = P^-T G p`,
    /// `acc = G p - K t`, with `t` of the separator (`t_separator`) already known. With
    /// `s = G p + sum of N t` over the later particles, `t = w D^-1 s` and `K t = (2 - w) s`. A
    /// particle's springs are summed from the last down, so that the product with the most
    /// recent result comes last in the dependency chain from one particle to the next.
    pub(super) fn backward(
        &self,
        lo: usize,
        beta: f64,
        r: &[Vector3],
        p: &mut [Vector3],
        t: &mut [Vector3],
        t_separator: &[Vector3],
        acc: &mut [Vector3],
    ) {
        let two_minus_omega = 2.0 - SSOR_OMEGA;
        let hi = lo + t.len();
        for j in (0..t.len()).rev() {
            let k = lo + j;
            let pk = r[j] + p[j] * beta;
            p[j] = pk;
            let g = self.chol[k].mul(&pk);
            let mut sum = g;
            let slots = self.start[k]..self.start[k + 1];
            for (&o, c) in self.other[slots.clone()]
                .iter()
                .zip(&self.coef[slots])
                .rev()
            {
                let o = o as usize;
                let to = if o < hi {
                    t[o - lo]
                } else {
                    t_separator[o - self.s]
                };
                sum += c.mul(&to);
            }
            t[j] = self.inv_diag[k].mul(&sum);
            acc[j] = g - sum * two_minus_omega;
        }
    }
}
