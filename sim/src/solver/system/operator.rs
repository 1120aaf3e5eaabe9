//! [`SpringSystem`], the block-sparse matrix `A = a_m M + sum over springs e of B_e`: its
//! assembly from the springs' blocks and its products with one vector or several.

use crate::Vector3;
use crate::model::Particles;

use super::blocks::{Lower3, Sym3, block_coefficients};
use super::lanes::Lanes;
use super::layout::{BlockLayout, split3};
use crate::parallel::join;

/// The system matrix: per-spring blocks, diagonal blocks and the preconditioner.
///
/// Each spring block is stored as `B_e = beta I + g g^T` with `g = sqrt(gamma) n` (which needs
/// `gamma >= 0`, as non-negative stiffness and damping give), by the spring's lower-numbered
/// particle. Fill it with [`Self::begin`] and [`Self::set_block`] (or [`Self::parts_mut`]),
/// then either fill `diag` and call [`Self::prepare`], or call
/// [`Self::update_preconditioner`], which computes `diag` from the blocks and the masses.
#[derive(Debug, Clone, Default)]
pub struct SpringSystem {
    /// Weight `a_m` of the lumped masses in `A`.
    pub mass_weight: f64,
    /// The 3x3 diagonal blocks `D_i` of `A` (zero for held particles after [`Self::prepare`]).
    pub diag: Vec<Sym3>,
    pub(super) layout: BlockLayout,
    /// `[g_x, g_y, g_z, beta]` per slot.
    pub(super) coef: Vec<[f64; 4]>,
    /// By rank: `w D_i^-1` (zero for held particles and singular blocks): the sweeps' diagonal
    /// solves, and (the factor `w` changes nothing there) the block-Jacobi preconditioner.
    pub(super) inv_diag: Vec<Sym3>,
    /// By rank: Cholesky factors of the diagonal blocks (zero for held particles).
    pub(super) chol: Vec<Lower3>,
    /// By rank: `a_m m_i`, and whether the particle is held.
    pub(super) mass: Vec<f64>,
    pub(super) held: Vec<bool>,
    /// Whether [`solve`] uses SSOR (otherwise block-Jacobi).
    pub(super) ssor: bool,
}

impl SpringSystem {
    /// Sizes the block storage for the springs of `model` (the layout is rebuilt only when the
    /// springs changed).
    pub fn begin(&mut self, model: &Particles<'_>) {
        let n = model.vertex_count();
        let ends = &model.springs.ends;
        if self.layout.ends != *ends || self.layout.start.len() != n + 1 {
            self.layout.build(n, ends);
        }
        self.coef.resize(ends.len(), [0.0; 4]);
    }

    /// For assembling in one pass: the slot of each spring (after [`Self::begin`]), the block
    /// storage by slot (see [`block_coefficients`]) and the diagonal blocks.
    pub fn parts_mut(&mut self) -> (&[u32], &mut [[f64; 4]], &mut Vec<Sym3>) {
        (&self.layout.slot, &mut self.coef, &mut self.diag)
    }

    /// Whether the springs (of [`Self::begin`]) come sorted by their first end, each `[a, b]`
    /// with `a < b`.
    pub fn springs_sorted_by_first(&self) -> bool {
        self.layout.sorted_by_first
    }

    /// Stores the blocks given in the springs' order (see [`block_coefficients`]), the two
    /// halves of the storage side by side when `parallel`.
    pub fn set_blocks_by_spring(&mut self, by_spring: &[[f64; 4]], parallel: bool) {
        let half = self.coef.len() / 2;
        let (lo, hi) = self.coef.split_at_mut(half);
        let (spring_lo, spring_hi) = self.layout.spring.split_at(half);
        let gather = |out: &mut [[f64; 4]], springs: &[u32]| {
            for (c, &e) in out.iter_mut().zip(springs) {
                *c = by_spring[e as usize];
            }
        };
        join(parallel, || gather(lo, spring_lo), || gather(hi, spring_hi));
    }

    /// Sets the block of spring `e` to `beta I + gamma n n^T` (`gamma >= 0`).
    pub fn set_block(&mut self, e: usize, beta: f64, gamma: f64, n: &Vector3) {
        self.coef[self.layout.slot[e] as usize] = block_coefficients(beta, gamma, n);
    }

    /// `y = A p` with held rows zeroed (after [`Self::prepare`]).
    #[cfg(test)]
    pub fn apply(&self, model: &Particles<'_>, p: &[Vector3], y: &mut [Vector3]) {
        let n = model.vertex_count();
        let order = &self.layout.order[..n];
        let p_ranked: Vec<Vector3> = order.iter().map(|&i| p[i as usize]).collect();
        let mut y_ranked = vec![Vector3::zeros(); n];
        self.apply_ranked(&p_ranked, &mut y_ranked, &mut Vec::new(), false);
        for (&i, y_k) in order.iter().zip(&y_ranked) {
            y[i as usize] = *y_k;
        }
    }

    /// `y = A p` with held rows zeroed, both by rank: the halves side by side when `parallel`
    /// (the second's products with the separator gathered in `spill` first), then the
    /// separator; the same bits either way. `p` may hold one vector or several ([`Lanes`]).
    pub(super) fn apply_ranked<T: Lanes>(
        &self,
        p: &[T],
        y: &mut [T],
        spill: &mut Vec<T>,
        parallel: bool,
    ) {
        let n = self.mass.len();
        let (p, y) = (&p[..n], &mut y[..n]);
        for ((y, p), &m) in y.iter_mut().zip(p).zip(&self.mass) {
            *y = p.scaled(m);
        }
        let [h, s] = self.layout.halves;
        spill.clear();
        spill.resize(n - s, T::ZERO);
        let (y1, y2, y_s) = split3(y, h, s);
        join(
            parallel,
            || self.apply_part(p, 0, y1, y_s),
            || self.apply_part(p, h, y2, spill),
        );
        y_s.iter_mut()
            .zip(spill.iter())
            .for_each(|(a, v)| a.add(*v));
        self.apply_part(p, s, y_s, &mut []);
        for (y, &h) in y.iter_mut().zip(&self.held) {
            if h {
                *y = T::ZERO;
            }
        }
    }

    /// The springs of the part of ranks from `lo` whose entries of `y` are `own`: their products
    /// added to `own` or, beyond it, to the separator's `spill`. The products on the first
    /// particle are summed in a register and stored once per particle; the summation order is
    /// fixed, so results stay deterministic.
    fn apply_part<T: Lanes>(&self, p: &[T], lo: usize, own: &mut [T], spill: &mut [T]) {
        let (hi, s) = (lo + own.len(), self.layout.halves[1]);
        let (start, other) = (&self.layout.start, &self.layout.other);
        for k in lo..hi {
            let slots = start[k]..start[k + 1];
            let pk = p[k];
            let mut yk = T::ZERO;
            for (&o, c) in other[slots.clone()].iter().zip(&self.coef[slots]) {
                let o = o as usize;
                let w = pk.block_mul_difference(c, p[o]);
                yk.add(w);
                if o < hi {
                    own[o - lo].sub(w);
                } else {
                    spill[o - s].sub(w);
                }
            }
            own[k - lo].add(yk);
        }
    }
}
