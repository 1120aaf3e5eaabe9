//! [`BlockSystem`], the block-sparse symmetric matrix on the edges of a graph (the springs', or
//! the mesh edges the finite elements couple): its assembly and its products with one vector
//! or several. [`SpringSystem`] is `A = a_m M + sum over springs e of B_e`; [`ElementSystem`]
//! has general 3x3 blocks.

use nalgebra::Matrix3;

use crate::Vector3;
use crate::model::Particles;

use super::blocks::{Lower3, OffBlock, SpringBlock, Sym3, block_coefficients};
use super::lanes::Lanes;
use super::layout::{BlockLayout, split3};
use crate::parallel::join;

/// The springs' system: each spring block stored as `B_e = beta I + g g^T` with
/// `g = sqrt(gamma) n` (which needs `gamma >= 0`, as non-negative stiffness and damping give).
/// Fill it with [`BlockSystem::begin`] and [`BlockSystem::set_block`] (or
/// [`BlockSystem::parts_mut`]), then either fill `diag` and call [`BlockSystem::prepare`], or
/// call [`BlockSystem::update_preconditioner`], which computes `diag` from the blocks and the
/// masses.
pub type SpringSystem = BlockSystem<SpringBlock>;

/// The finite elements' system: general 3x3 blocks (`A_ab` of an edge `a < b` added by
/// [`BlockSystem::add_off`], or stored by slot as `-A` of the pair's first particle in the
/// sweep order), and the diagonal blocks given.
pub type ElementSystem = BlockSystem<Matrix3<f64>>;

/// The system matrix: off-diagonal blocks on the edges of a graph, diagonal blocks and the
/// preconditioner, stored in the sweep order of [`super::layout`].
#[derive(Debug, Clone, Default)]
pub struct BlockSystem<B> {
    /// Weight `a_m` of the lumped masses in `A` (springs only).
    pub mass_weight: f64,
    /// The 3x3 diagonal blocks `D_i` of `A` (zero for held particles after [`Self::prepare`]).
    pub diag: Vec<Sym3>,
    pub(super) layout: BlockLayout,
    /// The off-diagonal block of each slot (see [`OffBlock`]).
    pub(super) coef: Vec<B>,
    /// By rank: `w D_i^-1` (zero for held particles and singular blocks): the sweeps' diagonal
    /// solves, and (the factor `w` changes nothing there) the block-Jacobi preconditioner.
    pub(super) inv_diag: Vec<Sym3>,
    /// By rank: Cholesky factors of the diagonal blocks (zero for held particles).
    pub(super) chol: Vec<Lower3>,
    /// By rank: `a_m m_i` (springs) or the diagonal block (general blocks), and whether the
    /// particle is held.
    pub(super) mass: Vec<f64>,
    pub(super) diag_ranked: Vec<Sym3>,
    pub(super) held: Vec<bool>,
    /// Whether [`super::solve`] uses SSOR (otherwise block-Jacobi).
    pub(super) ssor: bool,
}

impl<B: OffBlock> BlockSystem<B> {
    /// Sizes the block storage for the edges `ends` of `n` particles (the layout is rebuilt
    /// only when they changed). The blocks keep what they held: for an assembly that writes
    /// every one (see [`Self::begin_sums`] for one that adds into them).
    pub fn begin_edges(&mut self, n: usize, ends: &[[u32; 2]]) {
        if self.layout.ends != *ends || self.layout.start.len() != n + 1 {
            self.layout.build(n, ends);
        }
        self.coef.resize(ends.len(), B::default());
        self.diag.resize(n, Sym3::default());
    }

    /// [`Self::begin_edges`] with every block (off the diagonal and on it) zeroed: for an
    /// assembly that adds into them.
    pub fn begin_sums(&mut self, n: usize, ends: &[[u32; 2]]) {
        self.begin_edges(n, ends);
        self.coef.fill(B::default());
        self.diag.fill(Sym3::default());
    }

    /// For assembling in one pass: the slot of each edge (after [`Self::begin`]), the block
    /// storage by slot (see [`OffBlock`]) and the diagonal blocks.
    pub fn parts_mut(&mut self) -> (&[u32], &mut [B], &mut Vec<Sym3>) {
        (&self.layout.slot, &mut self.coef, &mut self.diag)
    }

    /// For assembling by slot (after [`Self::begin_edges`]): each particle's place in the
    /// sweep order (a slot's first particle is its edge's end of lower rank), the edge of each
    /// slot, the block storage by slot (see [`OffBlock`]) and the diagonal blocks.
    pub fn slot_parts_mut(&mut self) -> (&[u32], &[u32], &mut [B], &mut [Sym3]) {
        (
            self.layout.rank(),
            &self.layout.spring,
            &mut self.coef,
            &mut self.diag,
        )
    }
}

impl ElementSystem {
    /// Adds `k` to `A_ab` (and so `k^T` to `A_ba`) for edge `e = [a, b]` of those
    /// [`Self::begin_edges`] was given.
    pub fn add_off(&mut self, e: usize, a: u32, b: u32, k: &Matrix3<f64>) {
        let rank = self.layout.rank();
        let slot = self.layout.slot[e] as usize;
        if rank[a as usize] < rank[b as usize] {
            self.coef[slot] -= k;
        } else {
            self.coef[slot] -= k.transpose();
        }
    }
}

impl SpringSystem {
    /// Sizes the block storage for the springs of `model` (the layout is rebuilt only when the
    /// springs changed).
    pub fn begin(&mut self, model: &Particles<'_>) {
        self.begin_edges(model.vertex_count(), &model.springs.ends);
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
}

impl<B: OffBlock> BlockSystem<B> {
    /// `y = A p` with held rows zeroed (after [`Self::prepare_held`]).
    pub fn apply(&self, p: &[Vector3], y: &mut [Vector3]) {
        let order = &self.layout.order[..p.len()];
        let p_ranked: Vec<Vector3> = order.iter().map(|&i| p[i as usize]).collect();
        let mut y_ranked = vec![Vector3::zeros(); p.len()];
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
        let n = self.held.len();
        let (p, y) = (&p[..n], &mut y[..n]);
        if B::LAPLACIAN {
            for ((y, p), &m) in y.iter_mut().zip(p).zip(&self.mass) {
                *y = p.scaled(m);
            }
        } else {
            for ((y, p), d) in y.iter_mut().zip(p).zip(&self.diag_ranked) {
                *y = p.sym_mul(d);
            }
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

    /// The slots of the part of ranks from `lo` whose entries of `y` are `own`: their products
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
                let yo = if o < hi {
                    &mut own[o - lo]
                } else {
                    &mut spill[o - s]
                };
                c.apply_pair(pk, p[o], &mut yk, yo);
            }
            own[k - lo].add(yk);
        }
    }
}
