//! The sparse symmetric system shared by implicit Euler and the static solve, and its
//! preconditioned conjugate-gradient solver.
//!
//! Preconditioner: block SSOR, `M = (D/w + L) D^-1 (D/w + L^T)` (up to a constant factor) with
//! `D` the 3x3 diagonal blocks, `L` the strictly lower block triangle in the particle order and
//! `w` = [`SSOR_OMEGA`], applied with Eisenstat's trick: with `P = D/w + L`, `G` the Cholesky
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
//! particles are removed (their rows and columns act as identity on a zero right-hand side). With `beta, gamma >= 0` the matrix is symmetric positive
//! semi-definite, and positive definite once a particle of every piece is held or `a_m > 0`.

use crate::Vector3;
use crate::model::Particles;

use super::dissection::{self, DissectionScratch};
use super::span::SPAN;

/// Systems with at least this many particles sweep their two halves on two threads (fewer:
/// on one, in the same order, with the same result). A half sweep of the 10k-tet chest wall
/// (2.9k particles) takes some 25 us, too little to be worth waking another thread for.
pub const PARALLEL_MIN_PARTICLES: usize = 4_000;

/// A symmetric 3x3 matrix stored by its six distinct entries.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sym3 {
    pub xx: f64,
    pub yy: f64,
    pub zz: f64,
    pub xy: f64,
    pub xz: f64,
    pub yz: f64,
}

impl Sym3 {
    /// `s I`.
    #[inline]
    pub fn scalar(s: f64) -> Self {
        Self {
            xx: s,
            yy: s,
            zz: s,
            xy: 0.0,
            xz: 0.0,
            yz: 0.0,
        }
    }

    /// The matrix-vector product.
    #[inline]
    pub fn mul(&self, v: &Vector3) -> Vector3 {
        Vector3::new(
            self.xx * v.x + self.xy * v.y + self.xz * v.z,
            self.xy * v.x + self.yy * v.y + self.yz * v.z,
            self.xz * v.x + self.yz * v.y + self.zz * v.z,
        )
    }

    /// The inverse by cofactors, or zero when the determinant is not positive and finite
    /// (the blocks inverted here are positive definite or the particle is cut off).
    #[inline]
    pub fn inverse_or_zero(&self) -> Self {
        let c_xx = self.yy * self.zz - self.yz * self.yz;
        let c_xy = self.xz * self.yz - self.xy * self.zz;
        let c_xz = self.xy * self.yz - self.xz * self.yy;
        let det = self.xx * c_xx + self.xy * c_xy + self.xz * c_xz;
        if !(det > 0.0 && det.is_finite()) {
            return Self::default();
        }
        let inv = 1.0 / det;
        Self {
            xx: c_xx * inv,
            yy: (self.xx * self.zz - self.xz * self.xz) * inv,
            zz: (self.xx * self.yy - self.xy * self.xy) * inv,
            xy: c_xy * inv,
            xz: c_xz * inv,
            yz: (self.xy * self.xz - self.xx * self.yz) * inv,
        }
    }
}

impl std::ops::AddAssign for Sym3 {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        self.xx += o.xx;
        self.yy += o.yy;
        self.zz += o.zz;
        self.xy += o.xy;
        self.xz += o.xz;
        self.yz += o.yz;
    }
}

/// A lower-triangular 3x3 matrix.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Lower3 {
    pub xx: f64,
    pub yx: f64,
    pub yy: f64,
    pub zx: f64,
    pub zy: f64,
    pub zz: f64,
}

impl Lower3 {
    /// The Cholesky factor `G` (`G G^T = d`), or `None` when `d` is not positive definite.
    pub fn cholesky(d: &Sym3) -> Option<Self> {
        let xx = d.xx.sqrt();
        let (yx, zx) = (d.xy / xx, d.xz / xx);
        let yy = (d.yy - yx * yx).sqrt();
        let zy = (d.yz - zx * yx) / yy;
        let zz = (d.zz - zx * zx - zy * zy).sqrt();
        let g = Self {
            xx,
            yx,
            yy,
            zx,
            zy,
            zz,
        };
        // positive pivots (NaN from a negative square root fails the comparisons too)
        (xx > 0.0 && yy > 0.0 && zz > 0.0 && [yx, zx, zy, zz].iter().all(|v| v.is_finite()))
            .then_some(g)
    }

    /// `G v`.
    #[inline]
    pub fn mul(&self, v: &Vector3) -> Vector3 {
        Vector3::new(
            self.xx * v.x,
            self.yx * v.x + self.yy * v.y,
            self.zx * v.x + self.zy * v.y + self.zz * v.z,
        )
    }

    /// `G^T v`.
    #[inline]
    pub fn mul_transpose(&self, v: &Vector3) -> Vector3 {
        Vector3::new(
            self.xx * v.x + self.yx * v.y + self.zx * v.z,
            self.yy * v.y + self.zy * v.z,
            self.zz * v.z,
        )
    }
}

/// Relaxation factor of the SSOR preconditioner. Mean iterations on the benchmark stroke at
/// 12.8k tets: 11.9 at 1.0, 10.6 at 1.2, 10.3 at 1.4 and 11.6 at 1.6 (relative tolerance 1e-6,
/// linear warm start); 4.68 at 1.15, 4.61 at 1.25, 4.62 at 1.3, 4.67 at 1.35 and 4.87 at 1.45
/// (1e-4, cubic warm start).
pub const SSOR_OMEGA: f64 = 1.3;

/// Where the spring blocks are stored: in the sweep order ([`super::dissection`]), by the
/// spring's end that comes first in it (its "first" particle), each particle's springs sorted
/// by the other's place in the order. Particles are named by their place `k` in the order
/// ("rank") inside the solver.
#[derive(Debug, Clone, Default)]
struct BlockLayout {
    /// The springs this was built for.
    ends: Vec<[u32; 2]>,
    /// The particle at each rank.
    order: Vec<u32>,
    /// Ranks `0..halves[0]` are the first half, `halves[0]..halves[1]` the second, the rest the
    /// separator.
    halves: [usize; 2],
    /// Slots of the springs whose first particle has rank `k`: `start[k]..start[k + 1]`.
    start: Vec<usize>,
    /// The rank of the other (later) particle of each slot.
    other: Vec<u32>,
    /// The slot of each spring.
    slot: Vec<u32>,
    /// The spring of each slot.
    spring: Vec<u32>,
    /// Whether the springs come sorted by their first end, each `[a, b]` with `a < b` (as a
    /// model's do): what the implicit assembly needs to split them in two.
    sorted_by_first: bool,
    /// Whether some spring joins a particle to itself.
    has_loop: bool,
    /// The part of each particle (see [`super::dissection`]), and whether a rebuild carries it
    /// over (see [`SpringSystem::carry_sweep_order`]).
    part: Vec<u8>,
    carry: bool,
    /// Particles in the separator when the parts were last found by dissection.
    separator_when_dissected: usize,
    scratch: LayoutScratch,
}

impl BlockLayout {
    fn build(&mut self, n: usize, ends: &[[u32; 2]]) {
        let m = ends.len();
        self.ends.clear();
        self.ends.extend_from_slice(ends);
        self.has_loop = ends.iter().any(|&[a, b]| a == b);
        self.sorted_by_first =
            ends.iter().all(|&[a, b]| a < b) && crate::model::sorted_by_first_end(ends);
        // carried over while no spring joins the halves and the separator has not grown past
        // twice its dissected size (and 64 particles): it is swept on one thread
        let carried = self.carry
            && !self.part.is_empty()
            && dissection::extend_parts(&mut self.part, n, ends)
            && dissection::separator_count(&self.part)
                <= self
                    .separator_when_dissected
                    .saturating_mul(2)
                    .saturating_add(64);
        if !carried {
            dissection::dissection_parts_into(
                n,
                ends,
                &mut self.scratch.dissection,
                &mut self.part,
            );
            self.separator_when_dissected = dissection::separator_count(&self.part);
        }
        self.halves = dissection::order_of_parts(&self.part, &mut self.order);
        let rank = &mut self.scratch.rank;
        rank.clear();
        rank.resize(n, 0);
        for (k, &i) in self.order.iter().enumerate() {
            rank[i as usize] = k as u32;
        }
        self.start.clear();
        self.start.resize(n + 1, 0);
        for &[a, b] in ends {
            self.start[rank[a as usize].min(rank[b as usize]) as usize + 1] += 1;
        }
        for k in 0..n {
            self.start[k + 1] += self.start[k];
        }
        // (other, spring) per slot, stably by first particle, then each run sorted by the other
        let fill = &mut self.scratch.fill;
        fill.clear();
        fill.extend_from_slice(&self.start);
        let (other, spring) = (&mut self.other, &mut self.spring);
        other.clear();
        other.resize(m, 0);
        spring.clear();
        spring.resize(m, 0);
        for (e, &[a, b]) in ends.iter().enumerate() {
            let (ra, rb) = (rank[a as usize], rank[b as usize]);
            let s = &mut fill[ra.min(rb) as usize];
            (other[*s], spring[*s]) = (ra.max(rb), e as u32);
            *s += 1;
        }
        let mut keys: Vec<u64> = Vec::new();
        for k in 0..n {
            let run = self.start[k]..self.start[k + 1];
            if run.len() > 1 {
                keys.clear();
                keys.extend(
                    run.clone()
                        .map(|s| (u64::from(other[s]) << 32) | u64::from(spring[s])),
                );
                keys.sort_unstable();
                for (s, &key) in run.zip(&keys) {
                    (other[s], spring[s]) = ((key >> 32) as u32, key as u32);
                }
            }
        }
        self.slot.clear();
        self.slot.resize(m, 0);
        for (s, &e) in spring.iter().enumerate() {
            self.slot[e as usize] = s as u32;
        }
    }
}

/// The parts of a carried sweep order (see [`SpringSystem::carry_sweep_order`]): per particle
/// 0 (the first half), 1 (the second) or 2 (the separator).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SweepOrder {
    pub parts: Vec<u8>,
    pub separator_when_dissected: usize,
}

impl SweepOrder {
    /// Whether this fits `n` particles: at most `n` parts (particles a cut added since the
    /// order was last laid out get theirs at the next step, as in the captured run), each 0, 1
    /// or 2, and a dissected separator of at most `n` (the springs are checked when it is used).
    pub fn check(&self, n: usize) -> Result<(), SweepOrderError> {
        if self.parts.len() > n {
            return Err(SweepOrderError::TooManyParts {
                parts: self.parts.len(),
                particles: n,
            });
        }
        if let Some(&p) = self.parts.iter().find(|&&p| p > dissection::SEPARATOR) {
            return Err(SweepOrderError::Part(p));
        }
        if self.separator_when_dissected > n {
            return Err(SweepOrderError::Separator {
                separator: self.separator_when_dissected,
                particles: n,
            });
        }
        Ok(())
    }
}

/// A [`SweepOrder`] that does not fit the particles it is given for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SweepOrderError {
    #[error("sweep order of {parts} particles for {particles}")]
    TooManyParts { parts: usize, particles: usize },
    #[error("sweep order: part {0} (0, 1 or 2)")]
    Part(u8),
    #[error("sweep order: a separator of {separator} particles for {particles}")]
    Separator { separator: usize, particles: usize },
}

/// Buffers of [`BlockLayout::build`], kept between builds.
#[derive(Debug, Clone, Default)]
struct LayoutScratch {
    dissection: DissectionScratch,
    /// The rank of each particle.
    rank: Vec<u32>,
    /// The next free slot of each rank's run.
    fill: Vec<usize>,
}

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
    layout: BlockLayout,
    /// `[g_x, g_y, g_z, beta]` per slot.
    coef: Vec<[f64; 4]>,
    /// By rank: `w D_i^-1` (zero for held particles and singular blocks): the sweeps' diagonal
    /// solves, and (the factor `w` changes nothing there) the block-Jacobi preconditioner.
    inv_diag: Vec<Sym3>,
    /// By rank: Cholesky factors of the diagonal blocks (zero for held particles).
    chol: Vec<Lower3>,
    /// By rank: `a_m m_i`, and whether the particle is held.
    mass: Vec<f64>,
    held: Vec<bool>,
    /// Whether [`solve`] uses SSOR (otherwise block-Jacobi).
    ssor: bool,
}

/// Stiffness blocks `K_e = k [alpha I + (1 - alpha) n n^T]` with `alpha = max(0, 1 - l0 / l)`:
/// the exact spring Hessian for stretched springs, its positive part for compressed ones.
/// Returns `(alpha k, (1 - alpha) k, n)`; a zero-length spring gives zeros.
#[inline]
pub fn stiffness_block(k: f64, rest: f64, d: &Vector3) -> (f64, f64, Vector3) {
    let l = d.norm();
    if l == 0.0 {
        return (0.0, 0.0, Vector3::zeros());
    }
    let alpha = (1.0 - rest / l).max(0.0);
    (alpha * k, (1.0 - alpha) * k, d / l)
}

/// The stored form `[g_x, g_y, g_z, beta]` of `B = beta I + gamma n n^T`.
#[inline(always)]
pub fn block_coefficients(beta: f64, gamma: f64, n: &Vector3) -> [f64; 4] {
    let g = n * gamma.sqrt();
    [g.x, g.y, g.z, beta]
}

/// `B v = beta v + g (g . v)` from the stored form.
#[inline(always)]
fn block_mul(c: &[f64; 4], v: &Vector3) -> Vector3 {
    let g = Vector3::new(c[0], c[1], c[2]);
    v * c[3] + g * g.dot(v)
}

/// The diagonal contribution `beta I + g g^T` of a stored block.
#[inline(always)]
pub fn block_matrix(c: &[f64; 4]) -> Sym3 {
    let [gx, gy, gz, beta] = *c;
    Sym3 {
        xx: beta + gx * gx,
        yy: beta + gy * gy,
        zz: beta + gz * gz,
        xy: gx * gy,
        xz: gx * gz,
        yz: gy * gz,
    }
}

impl SpringSystem {
    /// From now on, a change of the springs on the same particles and new ones after them (a
    /// cut's) keeps each particle in the part of the sweep order it had (new ones in the half
    /// their springs reach, or the separator) instead of dissecting the spring graph again:
    /// 1.2 ms of the 2.3 ms the layout takes on the 100k-tet chest wall. The order then depends
    /// on the cuts before, so it is part of a resume state ([`Self::sweep_order`]).
    pub fn carry_sweep_order(&mut self) {
        self.layout.carry = true;
    }

    /// The sweep order's parts, where carried over (see [`Self::carry_sweep_order`]).
    pub fn sweep_order(&self) -> Option<SweepOrder> {
        (self.layout.carry && !self.layout.part.is_empty()).then(|| SweepOrder {
            parts: self.layout.part.clone(),
            separator_when_dissected: self.layout.separator_when_dissected,
        })
    }

    /// Continues from a [`SweepOrder`] (checked by [`SweepOrder::check`]): the next
    /// [`Self::begin`] lays the springs out in it, or dissects anew where a carried order would
    /// (a spring joining its halves, a separator grown past twice its dissected size and 64).
    pub(crate) fn install_sweep_order(&mut self, order: &SweepOrder) {
        self.layout.carry = true;
        self.layout.part.clone_from(&order.parts);
        self.layout.separator_when_dissected = order.separator_when_dissected;
        self.layout.ends.clear();
        self.layout.start.clear();
    }

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

    /// Builds the preconditioner from the diagonal blocks in `diag` (zeroing the held ones),
    /// in the sweep order of the layout [`Self::begin`] built.
    pub fn prepare(&mut self, model: &Particles<'_>) {
        let n = model.vertex_count();
        for (d, &h) in self.diag[..n].iter_mut().zip(model.held) {
            if h {
                *d = Sym3::default();
            }
        }
        self.inv_diag.resize(n, Sym3::default());
        self.chol.resize(n, Lower3::default());
        self.mass.resize(n, 0.0);
        self.held.resize(n, false);
        // each rank on its own: the two halves of the ranks side by side on a large system
        let (diag, weight, order) = (&self.diag, self.mass_weight, &self.layout.order[..n]);
        let fill = |order: &[u32],
                    inv_diag: &mut [Sym3],
                    chol: &mut [Lower3],
                    mass: &mut [f64],
                    held: &mut [bool]| {
            let mut all_factored = true;
            for (k, &i) in order.iter().enumerate() {
                let (i, h) = (i as usize, model.held[i as usize]);
                mass[k] = weight * model.mass[i];
                held[k] = h;
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
        let (mass_lo, mass_hi) = self.mass[..n].split_at_mut(half);
        let (held_lo, held_hi) = self.held[..n].split_at_mut(half);
        let parallel = n >= PARALLEL_MIN_PARTICLES && solver_threads() > 1;
        let (lo, hi) = join(
            parallel,
            || fill(&order[..half], inv_lo, chol_lo, mass_lo, held_lo),
            || fill(&order[half..], inv_hi, chol_hi, mass_hi, held_hi),
        );
        self.ssor = !self.layout.has_loop && lo && hi;
    }

    /// `y = A p` with held rows zeroed (after [`Self::prepare`]).
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
    fn apply_ranked<T: Lanes>(&self, p: &[T], y: &mut [T], spill: &mut Vec<T>, parallel: bool) {
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

    /// The start of a solve projected onto the span of `span` (by rank, held entries zero;
    /// see [`super::span`]): `x = U c` and its residual `r = b - A x = b - (A U) c` (held
    /// entries zero), whose norm this returns. The Gram matrix and `U^T b` are summed over the
    /// two halves of the ranks, side by side when `parallel` (the same bits either way).
    fn project_start(
        &self,
        span: &[SpanEntries],
        b: &[Vector3],
        x: &mut [Vector3],
        r: &mut [Vector3],
        scratch: &mut SpanScratch,
        parallel: bool,
    ) -> f64 {
        let n = b.len();
        let SpanScratch { y, spill } = scratch;
        y.resize(n, SpanEntries::ZERO);
        self.apply_ranked(span, y, spill, parallel);
        let sums = |k0: usize, k1: usize| {
            let (mut g, mut f) = ([[0.0; SPAN]; SPAN], [0.0; SPAN]);
            for k in k0..k1 {
                let (u, y) = (&span[k], &y[k]);
                for i in 0..SPAN {
                    f[i] += u.get(i).dot(&b[k]);
                    for j in i..SPAN {
                        g[i][j] += u.get(i).dot(&y.get(j));
                    }
                }
            }
            (g, f)
        };
        let m = n / 2;
        let ((g1, f1), (g2, f2)) = join(parallel, || sums(0, m), || sums(m, n));
        let g = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let (i, j) = (i.min(j), i.max(j));
                g1[i][j] + g2[i][j]
            })
        });
        let f = std::array::from_fn(|i| f1[i] + f2[i]);
        let c = super::span::coefficients(&g, &f);
        let mut rr = 0.0;
        for k in 0..n {
            x[k] = span[k].combine(&c);
            r[k] = if self.held[k] {
                Vector3::zeros()
            } else {
                b[k] - y[k].combine(&c)
            };
            rr += r[k].norm_squared();
        }
        rr.sqrt()
    }
}

/// A particle's entries of one vector or of several multiplied by the matrix together (the
/// springs' blocks read once for all).
trait Lanes: Copy + Send + Sync {
    const ZERO: Self;
    fn scaled(self, m: f64) -> Self;
    /// `B (self - other)` for the stored block `c`.
    fn block_mul_difference(self, c: &[f64; 4], other: Self) -> Self;
    fn add(&mut self, v: Self);
    fn sub(&mut self, v: Self);
}

impl Lanes for Vector3 {
    const ZERO: Self = Vector3::new(0.0, 0.0, 0.0);
    #[inline(always)]
    fn scaled(self, m: f64) -> Self {
        self * m
    }
    #[inline(always)]
    fn block_mul_difference(self, c: &[f64; 4], other: Self) -> Self {
        block_mul(c, &(self - other))
    }
    #[inline(always)]
    fn add(&mut self, v: Self) {
        *self += v;
    }
    #[inline(always)]
    fn sub(&mut self, v: Self) {
        *self -= v;
    }
}

/// The entries of [`SPAN`] vectors at one particle, by coordinate (`x[j]` of vector `j`), so
/// that the products of the four run in the same vector instructions.
#[derive(Debug, Clone, Copy, Default)]
struct SpanEntries {
    x: [f64; SPAN],
    y: [f64; SPAN],
    z: [f64; SPAN],
}

impl SpanEntries {
    fn of(v: [Vector3; SPAN]) -> Self {
        Self {
            x: v.map(|v| v.x),
            y: v.map(|v| v.y),
            z: v.map(|v| v.z),
        }
    }

    fn get(&self, j: usize) -> Vector3 {
        Vector3::new(self.x[j], self.y[j], self.z[j])
    }

    /// `sum_j c_j v_j`.
    fn combine(&self, c: &[f64; SPAN]) -> Vector3 {
        let dot = |a: &[f64; SPAN]| a.iter().zip(c).map(|(a, c)| a * c).sum::<f64>();
        Vector3::new(dot(&self.x), dot(&self.y), dot(&self.z))
    }
}

impl Lanes for SpanEntries {
    const ZERO: Self = Self {
        x: [0.0; SPAN],
        y: [0.0; SPAN],
        z: [0.0; SPAN],
    };
    #[inline(always)]
    fn scaled(self, m: f64) -> Self {
        Self {
            x: self.x.map(|v| v * m),
            y: self.y.map(|v| v * m),
            z: self.z.map(|v| v * m),
        }
    }
    #[inline(always)]
    fn block_mul_difference(self, c: &[f64; 4], other: Self) -> Self {
        // B d = beta d + g (g . d), lane by lane
        let [gx, gy, gz, beta] = *c;
        let mut out = Self::ZERO;
        for j in 0..SPAN {
            let (dx, dy, dz) = (
                self.x[j] - other.x[j],
                self.y[j] - other.y[j],
                self.z[j] - other.z[j],
            );
            let gd = gx * dx + gy * dy + gz * dz;
            out.x[j] = beta * dx + gx * gd;
            out.y[j] = beta * dy + gy * gd;
            out.z[j] = beta * dz + gz * gd;
        }
        out
    }
    #[inline(always)]
    fn add(&mut self, v: Self) {
        for j in 0..SPAN {
            self.x[j] += v.x[j];
            self.y[j] += v.y[j];
            self.z[j] += v.z[j];
        }
    }
    #[inline(always)]
    fn sub(&mut self, v: Self) {
        for j in 0..SPAN {
            self.x[j] -= v.x[j];
            self.y[j] -= v.y[j];
            self.z[j] -= v.z[j];
        }
    }
}

/// Settings of the conjugate-gradient solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgSettings {
    /// Stop when `|r| <= max(relative_tolerance |b|, absolute_tolerance)`.
    pub relative_tolerance: f64,
    /// In the units of `b`; zero for a purely relative tolerance.
    pub absolute_tolerance: f64,
    pub max_iterations: usize,
}

/// Outcome of a conjugate-gradient solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgReport {
    pub iterations: usize,
    pub relative_residual: f64,
    pub converged: bool,
}

/// Scratch vectors of the solver (kept between calls so steps do not allocate). All by rank.
#[derive(Debug, Clone, Default)]
pub struct CgScratch {
    r: Vec<Vector3>,
    z: Vec<Vector3>,
    p: Vec<Vector3>,
    q: Vec<Vector3>,
    t: Vec<Vector3>,
    /// The right-hand side and the iterate, gathered into the sweep order.
    b: Vec<Vector3>,
    x: Vec<Vector3>,
    /// The second half's products with the separator in a forward sweep (the first half adds
    /// its own to the separator's entries directly).
    spill: Vec<Vector3>,
    /// The vectors a start is projected onto, by rank, and their products with the matrix.
    span: Vec<SpanEntries>,
    span_products: SpanScratch,
    /// Last seen `(|r| / |r_0|) / (|r^| / |r^_0|)` of the SSOR solve (carried to the next
    /// solve's stopping test, so part of a [`super::resume::WarmStart`]).
    pub(crate) residual_ratio: f64,
}

/// Buffers of [`SpringSystem::project_start`].
#[derive(Debug, Clone, Default)]
struct SpanScratch {
    y: Vec<SpanEntries>,
    spill: Vec<SpanEntries>,
}

fn dot(a: &[Vector3], b: &[Vector3]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a.dot(b)).sum()
}

/// The threads the solver's sweeps may use: rayon's (one per core; `RAYON_NUM_THREADS=1` for
/// one). Systems of [`PARALLEL_MIN_PARTICLES`] or more use two of them.
pub fn solver_threads() -> usize {
    rayon::current_num_threads().min(2)
}

/// `a` and `b`, on two threads when `parallel` (the same results either way).
pub(crate) fn join<RA: Send, RB: Send>(
    parallel: bool,
    a: impl FnOnce() -> RA + Send,
    b: impl FnOnce() -> RB + Send,
) -> (RA, RB) {
    if parallel {
        side_by_side(a, b)
    } else {
        (a(), b())
    }
}

/// `a` and `b` on two threads. Called from outside rayon's pool (the simulation's own thread),
/// `a` runs on the calling thread while a worker takes `b`, instead of both waiting for
/// workers to wake while the caller sleeps ([`rayon::join`] from outside the pool).
pub(crate) fn side_by_side<RA: Send, RB: Send>(
    a: impl FnOnce() -> RA + Send,
    b: impl FnOnce() -> RB + Send,
) -> (RA, RB) {
    if rayon::current_thread_index().is_some() {
        return rayon::join(a, b);
    }
    let mut rb = None;
    let ra = rayon::in_place_scope(|s| {
        s.spawn(|_| rb = Some(b()));
        a()
    });
    (ra, rb.expect("the scope waits for its spawned job"))
}

/// `v` cut at `h` and `s` (the halves and the separator).
fn split3<T>(v: &mut [T], h: usize, s: usize) -> (&mut [T], &mut [T], &mut [T]) {
    let (first, rest) = v.split_at_mut(h);
    let (second, separator) = rest.split_at_mut(s - h);
    (first, second, separator)
}

/// Solves `A x = b` by preconditioned conjugate gradients (SSOR, or block-Jacobi when SSOR does
/// not apply; see the module documentation), starting from the `x` given (warm start). Held
/// entries of `b` and `x` are treated as zero. Stops when
/// `|b - A x| <= max(relative_tolerance |b|, absolute_tolerance)`.
pub fn solve(
    sys: &SpringSystem,
    model: &Particles<'_>,
    b: &[Vector3],
    x: &mut [Vector3],
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let parallel = b.len() >= PARALLEL_MIN_PARTICLES && solver_threads() > 1;
    solve_on(sys, model, b, x, None, settings, scratch, parallel)
}

/// [`solve`], starting from the projection onto the span of `x` (as given) and `more` (see
/// [`super::span`]): the start closest to the solution in the `A`-norm among their
/// combinations. Its residual comes with the products, so the projection costs one pass over
/// the springs that multiplies by all four vectors, in place of the first residual's. Vectors
/// of `more` that do not have one entry per particle are left out of the span.
pub fn solve_from_span(
    sys: &SpringSystem,
    model: &Particles<'_>,
    b: &[Vector3],
    x: &mut [Vector3],
    more: [&[Vector3]; SPAN - 1],
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let parallel = b.len() >= PARALLEL_MIN_PARTICLES && solver_threads() > 1;
    let n = b.len();
    let more = more.map(|v| if v.len() == n { v } else { &[] as &[Vector3] });
    solve_on(sys, model, b, x, Some(more), settings, scratch, parallel)
}

/// [`solve`] or [`solve_from_span`] (with `more`), with the halves' sweeps on two threads or
/// not (the same bits either way).
#[allow(clippy::too_many_arguments)]
fn solve_on(
    sys: &SpringSystem,
    model: &Particles<'_>,
    b: &[Vector3],
    x: &mut [Vector3],
    more: Option<[&[Vector3]; SPAN - 1]>,
    settings: CgSettings,
    scratch: &mut CgScratch,
    parallel: bool,
) -> CgReport {
    let n = b.len();
    for (xi, &h) in x.iter_mut().zip(model.held) {
        if h {
            *xi = Vector3::zeros();
        }
    }
    let b_norm = b
        .iter()
        .zip(model.held)
        .filter(|(_, h)| !**h)
        .map(|(b, _)| b.norm_squared())
        .sum::<f64>()
        .sqrt();
    if b_norm == 0.0 {
        x.iter_mut().for_each(|xi| *xi = Vector3::zeros());
        return CgReport {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
    }
    // (every entry is written before it is read: no need to clear)
    for buf in [
        &mut scratch.r,
        &mut scratch.z,
        &mut scratch.p,
        &mut scratch.q,
        &mut scratch.t,
    ] {
        buf.resize(n, Vector3::zeros());
    }
    let order = &sys.layout.order[..n];
    let (mut b_ranked, mut x_ranked) = (
        std::mem::take(&mut scratch.b),
        std::mem::take(&mut scratch.x),
    );
    b_ranked.clear();
    b_ranked.extend(order.iter().map(|&i| b[i as usize]));
    x_ranked.clear();
    let ssor = sys.ssor && sys.chol.len() == n && sys.layout.start.len() == n + 1;
    // with a span: its projection, and the residual in `z` (where the SSOR solve wants it)
    let known = match more {
        Some(more) => {
            let span = &mut scratch.span;
            span.clear();
            span.extend(order.iter().map(|&i| {
                let i = i as usize;
                let at = |v: &[Vector3]| v.get(i).copied().unwrap_or_else(Vector3::zeros);
                if model.held[i] {
                    SpanEntries::ZERO
                } else {
                    SpanEntries::of([x[i], at(more[0]), at(more[1]), at(more[2])])
                }
            }));
            x_ranked.resize(n, Vector3::zeros());
            let run = |scratch: &mut CgScratch, x: &mut [Vector3]| {
                let CgScratch {
                    span,
                    span_products,
                    z,
                    ..
                } = scratch;
                sys.project_start(span, &b_ranked, x, z, span_products, parallel)
            };
            Some(if parallel {
                rayon::scope(|_| run(scratch, &mut x_ranked))
            } else {
                run(scratch, &mut x_ranked)
            })
        }
        None => {
            x_ranked.extend(order.iter().map(|&i| x[i as usize]));
            None
        }
    };
    let report = if ssor {
        if parallel {
            // on one of rayon's threads, so that handing the other half of a sweep over is cheap
            rayon::scope(|_| {
                solve_ssor(
                    sys,
                    &b_ranked,
                    &mut x_ranked,
                    b_norm,
                    known,
                    settings,
                    scratch,
                    true,
                )
            })
        } else {
            solve_ssor(
                sys,
                &b_ranked,
                &mut x_ranked,
                b_norm,
                known,
                settings,
                scratch,
                false,
            )
        }
    } else {
        if known.is_some() {
            let CgScratch { r, z, .. } = &mut *scratch;
            r.copy_from_slice(z);
        }
        solve_jacobi(
            sys,
            &b_ranked,
            &mut x_ranked,
            b_norm,
            known,
            settings,
            scratch,
        )
    };
    for (&i, x_k) in order.iter().zip(&x_ranked) {
        x[i as usize] = *x_k;
    }
    (scratch.b, scratch.x) = (b_ranked, x_ranked);
    report
}

/// `r = b - A x` (held entries zero), by rank; returns `|r|`.
fn residual(
    sys: &SpringSystem,
    b: &[Vector3],
    x: &[Vector3],
    r: &mut [Vector3],
    ax: &mut [Vector3],
    spill: &mut Vec<Vector3>,
    parallel: bool,
) -> f64 {
    sys.apply_ranked(x, ax, spill, parallel);
    let mut rr = 0.0;
    for k in 0..b.len() {
        r[k] = if sys.held[k] {
            Vector3::zeros()
        } else {
            b[k] - ax[k]
        };
        rr += r[k].norm_squared();
    }
    rr.sqrt()
}

/// Block-Jacobi preconditioned CG, by rank.
/// `known`: the norm of the residual of `x`, already in `r`.
fn solve_jacobi(
    sys: &SpringSystem,
    b: &[Vector3],
    x: &mut [Vector3],
    b_norm: f64,
    known: Option<f64>,
    settings: CgSettings,
    scratch: &mut CgScratch,
) -> CgReport {
    let n = b.len();
    let CgScratch {
        r, z, p, q, spill, ..
    } = scratch;
    let mut r_norm = match known {
        Some(r_norm) => r_norm,
        None => residual(sys, b, x, r, q, spill, false),
    };
    for k in 0..n {
        z[k] = sys.inv_diag[k].mul(&r[k]);
        p[k] = z[k];
    }
    let mut rz = dot(r, z);
    let target = (settings.relative_tolerance * b_norm).max(settings.absolute_tolerance);
    let mut iterations = 0;
    while r_norm > target && iterations < settings.max_iterations {
        sys.apply_ranked(p, q, spill, false);
        let pq = dot(p, q);
        if !(pq > 0.0) {
            break; // breakdown: the matrix is singular along p, or the numbers are bad
        }
        let alpha = rz / pq;
        // One pass: x and r updated, z = P r, and the dot products r.z and r.r.
        let (mut rz_next, mut rr) = (0.0, 0.0);
        for k in 0..n {
            x[k] += p[k] * alpha;
            r[k] -= q[k] * alpha;
            z[k] = sys.inv_diag[k].mul(&r[k]);
            rz_next += r[k].dot(&z[k]);
            rr += r[k].norm_squared();
        }
        let beta = rz_next / rz;
        rz = rz_next;
        for k in 0..n {
            p[k] = z[k] + p[k] * beta;
        }
        r_norm = rr.sqrt();
        iterations += 1;
    }
    CgReport {
        iterations,
        relative_residual: r_norm / b_norm,
        converged: r_norm <= target,
    }
}

/// What the sweeps read of the system, by rank.
#[derive(Clone, Copy)]
struct Sweeps<'a> {
    start: &'a [usize],
    other: &'a [u32],
    coef: &'a [[f64; 4]],
    inv_diag: &'a [Sym3],
    chol: &'a [Lower3],
    /// Where the separator starts.
    s: usize,
}

impl Sweeps<'_> {
    /// The forward sweep at rank `k` of a part starting at `lo` whose entries of the sweep's
    /// vector are `own`: `u = w D_k^-1 own_k`, then `B u` added to the later particles of `k`'s
    /// springs, in `own` or, beyond it, in the separator's `spill`. Returns `u`.
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
            let (o, w) = (o as usize, block_mul(c, &u));
            if o < hi {
                own[o - lo] += w;
            } else {
                spill[o - self.s] += w;
            }
        }
        u
    }

    /// The first forward sweep over a part: `r^ = G^T P^-1 r` (`acc` holds `r`), `p = 0`.
    fn forward_first(
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
    fn forward(
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
    /// `s = G p + sum of B t` over the later particles, `t = w D^-1 s` and `K t = (2 - w) s`. A
    /// particle's springs are summed from the last down, so that the product with the most
    /// recent result comes last in the dependency chain from one particle to the next.
    fn backward(
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
                sum += block_mul(c, &to);
            }
            t[j] = self.inv_diag[k].mul(&sum);
            acc[j] = g - sum * two_minus_omega;
        }
    }
}

/// SSOR preconditioned CG in Eisenstat's form (see the module documentation), by rank; the
/// halves' parts of each sweep side by side when `parallel`. The recursive residual is the
/// transformed `r^ = C^-1 (b - A x)`; iterations stop once `|r^|` has fallen by the factor the
/// tolerance asks of `|b - A x|`, corrected by the ratio of the two reductions seen at the last
/// check (`|r|` falls about half as fast as `|r^|` on the chest wall). The true residual is then
/// checked, and the iteration continued with a tighter target if it is not yet small enough.
/// `known`: the norm of the residual of `x`, already in the scratch's `z`.
#[allow(clippy::too_many_arguments)]
fn solve_ssor(
    sys: &SpringSystem,
    b: &[Vector3],
    x: &mut [Vector3],
    b_norm: f64,
    known: Option<f64>,
    settings: CgSettings,
    scratch: &mut CgScratch,
    parallel: bool,
) -> CgReport {
    let n = b.len();
    let CgScratch {
        r,
        z: acc,
        p,
        q,
        t,
        spill,
        residual_ratio,
        ..
    } = scratch;
    let (r, acc, p, q, t) = (
        &mut r[..n],
        &mut acc[..n],
        &mut p[..n],
        &mut q[..n],
        &mut t[..n],
    );
    let [h, s] = sys.layout.halves;
    let sweeps = Sweeps {
        start: &sys.layout.start[..=n],
        other: &sys.layout.other,
        coef: &sys.coef,
        inv_diag: &sys.inv_diag[..n],
        chol: &sys.chol[..n],
        s,
    };
    spill.resize(n - s, Vector3::zeros());
    let target = (settings.relative_tolerance * b_norm).max(settings.absolute_tolerance);

    let mut r_norm = match known {
        Some(r_norm) => r_norm,
        None => residual(sys, b, x, acc, q, spill, parallel),
    };
    if r_norm <= target {
        return CgReport {
            iterations: 0,
            relative_residual: r_norm / b_norm,
            converged: true,
        };
    }
    // r^ = G^T P^-1 r: forward sweep on acc = r.
    {
        let (acc1, acc2, acc_s) = split3(acc, h, s);
        let (r1, r2, r_s) = split3(r, h, s);
        let (p1, p2, p_s) = split3(p, h, s);
        spill.iter_mut().for_each(|v| *v = Vector3::zeros());
        join(
            parallel,
            || sweeps.forward_first(0, acc1, acc_s, r1, p1),
            || sweeps.forward_first(h, acc2, spill, r2, p2),
        );
        acc_s
            .iter_mut()
            .zip(spill.iter())
            .for_each(|(a, v)| *a += v);
        sweeps.forward_first(s, acc_s, &mut [], r_s, p_s);
    }
    let mut rr = dot(r, r);
    let (r_norm0, rr0) = (r_norm, rr);
    let ratio = if *residual_ratio > 0.0 {
        residual_ratio.clamp(0.1, 10.0)
    } else {
        1.0
    };
    let mut target_hat = rr.sqrt() * (target / r_norm) / ratio;
    let mut beta = 0.0;
    let mut iterations = 0;
    while iterations < settings.max_iterations {
        let (r1, r2, r_s) = split3(r, h, s);
        let (p1, p2, p_s) = split3(p, h, s);
        let (t1, t2, t_s) = split3(t, h, s);
        let (acc1, acc2, acc_s) = split3(acc, h, s);
        let (q1, q2, q_s) = split3(q, h, s);
        // Backward sweep: the separator, then the halves.
        sweeps.backward(s, beta, r_s, p_s, t_s, &[], acc_s);
        let t_s: &[Vector3] = t_s;
        join(
            parallel,
            || sweeps.backward(0, beta, r1, p1, t1, t_s, acc1),
            || sweeps.backward(h, beta, r2, p2, t2, t_s, acc2),
        );
        // Forward sweep: the halves, then the separator with what both added to it.
        spill.iter_mut().for_each(|v| *v = Vector3::zeros());
        let (pq1, pq2) = join(
            parallel,
            || sweeps.forward(0, acc1, acc_s, t1, p1, q1),
            || sweeps.forward(h, acc2, spill, t2, p2, q2),
        );
        acc_s
            .iter_mut()
            .zip(spill.iter())
            .for_each(|(a, v)| *a += v);
        let pq = pq1 + pq2 + sweeps.forward(s, acc_s, &mut [], t_s, p_s, q_s);
        if !(pq > 0.0) {
            break; // breakdown: the matrix is singular along p, or the numbers are bad
        }
        let alpha = rr / pq;
        let update = |x: &mut [Vector3], r: &mut [Vector3], t: &[Vector3], q: &[Vector3]| {
            let mut rr_part = 0.0;
            for k in 0..x.len() {
                x[k] += t[k] * alpha;
                r[k] -= q[k] * alpha;
                rr_part += r[k].norm_squared();
            }
            rr_part
        };
        let m = n / 2;
        let (x1, x2) = x.split_at_mut(m);
        let (r1, r2) = r.split_at_mut(m);
        let (t1, t2) = t.split_at(m);
        let (q1, q2) = q.split_at(m);
        let (rr1, rr2) = join(
            parallel,
            || update(x1, r1, t1, q1),
            || update(x2, r2, t2, q2),
        );
        let rr_next = rr1 + rr2;
        beta = rr_next / rr;
        rr = rr_next;
        iterations += 1;
        if rr.sqrt() <= target_hat {
            r_norm = residual(sys, b, x, acc, q, spill, parallel);
            // an exact solve (rr = 0, as a few particles can reach) has no ratio: stored as 0,
            // which the next solve reads as none (as it read the NaN this once stored, which a
            // keyframe cannot carry); above 10 it is read as 10
            let ratio = (r_norm / r_norm0) / (rr.sqrt() / rr0.sqrt());
            *residual_ratio = if ratio.is_nan() { 0.0 } else { ratio.min(10.0) };
            if r_norm <= target {
                break;
            }
            // not there yet in the true norm: tighten the transformed target accordingly
            target_hat *= 0.5 * target / r_norm;
        }
    }
    if iterations == settings.max_iterations || !(r_norm <= target) {
        r_norm = residual(sys, b, x, acc, q, spill, parallel);
    }
    CgReport {
        iterations,
        relative_residual: r_norm / b_norm,
        converged: r_norm <= target,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{BuildOptions, Scene};

    fn sym(xx: f64, yy: f64, zz: f64, xy: f64, xz: f64, yz: f64) -> Sym3 {
        Sym3 {
            xx,
            yy,
            zz,
            xy,
            xz,
            yz,
        }
    }

    #[test]
    fn inverse_and_cholesky_of_a_positive_definite_block() {
        let d = sym(4.0, 3.0, 2.0, 0.5, -0.3, 0.2);
        let inv = d.inverse_or_zero();
        for v in [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(0.3, -1.2, 2.5),
        ] {
            assert!((inv.mul(&d.mul(&v)) - v).norm() < 1e-14 * v.norm());
        }
        let g = Lower3::cholesky(&d).expect("positive definite");
        for v in [Vector3::x(), Vector3::new(1.0, -2.0, 0.5)] {
            assert!((g.mul(&g.mul_transpose(&v)) - d.mul(&v)).norm() < 1e-14 * d.mul(&v).norm());
        }
        assert!(Lower3::cholesky(&sym(1.0, 1.0, 1.0, 2.0, 0.0, 0.0)).is_none());
        assert!(Lower3::cholesky(&Sym3::default()).is_none());
        assert_eq!(
            sym(1.0, 1.0, 0.0, 1.0, 0.0, 0.0).inverse_or_zero(),
            Sym3::default()
        );
    }

    /// An implicit-Euler-like system on the chest wall (1 ms step, current positions).
    fn system(model: &Particles<'_>, x: &[crate::Point3]) -> (SpringSystem, Vec<Vector3>) {
        let s = &model.springs;
        let h = 1e-3;
        let mut sys = SpringSystem {
            mass_weight: 1.0,
            ..Default::default()
        };
        sys.begin(model);
        for (e, &[a, b]) in s.ends.iter().enumerate() {
            let (ka, kn, n) = stiffness_block(
                s.stiffness[e],
                s.rest_length[e],
                &(x[b as usize] - x[a as usize]),
            );
            sys.set_block(e, h * h * ka, h * s.damping[e] + h * h * kn, &n);
        }
        sys.update_preconditioner(model);
        let rhs = (0..model.vertex_count())
            .map(|i| Vector3::new((i as f64).sin(), (0.7 * i as f64).cos(), 0.3) * 1e-6)
            .collect();
        (sys, rhs)
    }

    fn true_residual(
        sys: &SpringSystem,
        model: &Particles<'_>,
        b: &[Vector3],
        x: &[Vector3],
    ) -> f64 {
        let n = b.len();
        let mut ax = vec![Vector3::zeros(); n];
        sys.apply(model, x, &mut ax);
        let r_norm = (0..n)
            .filter(|&i| !model.held[i])
            .map(|i| (b[i] - ax[i]).norm_squared())
            .sum::<f64>()
            .sqrt();
        let b_norm = b
            .iter()
            .zip(model.held)
            .filter(|(_, h)| !**h)
            .map(|(b, _)| b.norm_squared())
            .sum::<f64>()
            .sqrt();
        r_norm / b_norm
    }

    #[test]
    fn ssor_and_jacobi_solve_the_same_system() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(1_000),
            },
        )
        .expect("built-in scene");
        let positions = scene.model.mesh.positions();
        let model = &scene.model.particles();
        let (mut sys, b) = system(model, positions);
        assert!(sys.ssor);
        let settings = CgSettings {
            relative_tolerance: 1e-10,
            absolute_tolerance: 0.0,
            max_iterations: 1000,
        };
        let n = b.len();
        let mut x_ssor = vec![Vector3::zeros(); n];
        let ssor = solve(
            &sys,
            model,
            &b,
            &mut x_ssor,
            settings,
            &mut CgScratch::default(),
        );
        assert!(ssor.converged, "{ssor:?}");
        assert!(true_residual(&sys, model, &b, &x_ssor) <= 1e-10);
        sys.ssor = false;
        let mut x_jacobi = vec![Vector3::zeros(); n];
        let jacobi = solve(
            &sys,
            model,
            &b,
            &mut x_jacobi,
            settings,
            &mut CgScratch::default(),
        );
        assert!(jacobi.converged, "{jacobi:?}");
        assert!(
            ssor.iterations * 2 < jacobi.iterations,
            "{ssor:?} vs {jacobi:?}"
        );
        let scale = x_jacobi.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let diff = x_ssor
            .iter()
            .zip(&x_jacobi)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(diff < 1e-8 * scale, "{diff} vs {scale}");
        for (x, &h) in x_ssor.iter().zip(model.held.iter()) {
            assert!(!h || *x == Vector3::zeros());
        }
    }

    #[test]
    fn one_thread_or_two_give_the_same_bits() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(1_000),
            },
        )
        .expect("built-in scene");
        let positions = scene.model.mesh.positions();
        let model = &scene.model.particles();
        let (sys, b) = system(model, positions);
        assert!(sys.ssor);
        let settings = CgSettings {
            relative_tolerance: 1e-8,
            absolute_tolerance: 0.0,
            max_iterations: 1000,
        };
        // the solve from `start` (and the span of `more`) on one thread and on two: the same
        // report and the same bits; returns them
        let same_bits = |start: Vec<Vector3>, more: Option<[&[Vector3]; SPAN - 1]>| {
            let (mut one, mut two) = (start.clone(), start);
            let a = solve_on(
                &sys,
                model,
                &b,
                &mut one,
                more,
                settings,
                &mut CgScratch::default(),
                false,
            );
            let c = solve_on(
                &sys,
                model,
                &b,
                &mut two,
                more,
                settings,
                &mut CgScratch::default(),
                true,
            );
            assert_eq!(a, c);
            assert!(
                one.iter()
                    .zip(&two)
                    .all(|(u, v)| u.map(f64::to_bits) == v.map(f64::to_bits))
            );
            (a, one)
        };
        let (a, one) = same_bits(vec![Vector3::zeros(); b.len()], None);
        assert!(a.converged && a.iterations > 5, "{a:?}");
        assert!(true_residual(&sys, model, &b, &one) <= 1e-8);
        // started from a span
        let more: Vec<Vec<Vector3>> = (1..SPAN)
            .map(|j| {
                one.iter()
                    .enumerate()
                    .map(|(i, v)| v * (1.0 + 0.1 * ((i * j) as f64).sin()))
                    .collect()
            })
            .collect();
        let (a, _) = same_bits(b.clone(), Some([&more[0][..], &more[1][..], &more[2][..]]));
        assert!(a.converged, "{a:?}");
    }

    /// `|x - y|_A`.
    fn a_norm_of_difference(
        sys: &SpringSystem,
        model: &Particles<'_>,
        x: &[Vector3],
        y: &[Vector3],
    ) -> f64 {
        let d: Vec<Vector3> = x.iter().zip(y).map(|(x, y)| x - y).collect();
        let mut ad = vec![Vector3::zeros(); d.len()];
        sys.apply(model, &d, &mut ad);
        d.iter()
            .zip(&ad)
            .zip(model.held)
            .filter(|(_, h)| !**h)
            .map(|((d, ad), _)| d.dot(ad))
            .sum::<f64>()
            .sqrt()
    }

    #[test]
    fn a_start_from_a_span_is_the_best_of_its_combinations() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(1_000),
            },
        )
        .expect("built-in scene");
        let positions = scene.model.mesh.positions();
        let model = &scene.model.particles();
        let (sys, b) = system(model, positions);
        let n = b.len();
        let tight = CgSettings {
            relative_tolerance: 1e-12,
            absolute_tolerance: 0.0,
            max_iterations: 1000,
        };
        let mut exact = vec![Vector3::zeros(); n];
        assert!(
            solve(
                &sys,
                model,
                &b,
                &mut exact,
                tight,
                &mut CgScratch::default()
            )
            .converged
        );
        // the solution disturbed in two ways, a vector with no part along it, and a repeat
        let wave = |k: f64| -> Vec<Vector3> {
            exact
                .iter()
                .enumerate()
                .map(|(i, v)| v * (1.0 + 0.3 * (k * i as f64).sin()))
                .collect()
        };
        let (u0, u1) = (wave(0.37), wave(1.9));
        let u2: Vec<Vector3> = (0..n)
            .map(|i| Vector3::new((0.5 * i as f64).cos(), 0.0, 1.0) * 1e-7)
            .collect();
        let no_iterations = CgSettings {
            max_iterations: 0,
            ..tight
        };
        let mut start = u0.clone();
        solve_from_span(
            &sys,
            model,
            &b,
            &mut start,
            [&u1, &u2, &u1],
            no_iterations,
            &mut CgScratch::default(),
        );
        let error = a_norm_of_difference(&sys, model, &start, &exact);
        let zero = vec![Vector3::zeros(); n];
        for (name, other) in [
            ("u0", &u0),
            ("u1", &u1),
            (
                "the mean",
                &u0.iter().zip(&u1).map(|(a, b)| (a + b) / 2.0).collect(),
            ),
            ("zero", &zero),
        ] {
            let e = a_norm_of_difference(&sys, model, other, &exact);
            assert!(error <= e, "{error} from the span, {e} from {name}");
        }
        // with the solution in the span, the start is the solution: no iteration needed
        let mut start = u0.clone();
        let report = solve_from_span(
            &sys,
            model,
            &b,
            &mut start,
            [&u1, &exact, &u2],
            CgSettings {
                relative_tolerance: 1e-8,
                ..tight
            },
            &mut CgScratch::default(),
        );
        assert_eq!(report.iterations, 0, "{report:?}");
        assert!(true_residual(&sys, model, &b, &start) <= 1e-8);
    }

    #[test]
    fn springs_in_any_order_and_orientation_give_the_same_solution() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(1_000),
            },
        )
        .expect("built-in scene");
        let positions = scene.model.mesh.positions();
        let model = &scene.model.particles();
        let (sys, b) = system(model, positions);
        let settings = CgSettings {
            relative_tolerance: 1e-10,
            absolute_tolerance: 0.0,
            max_iterations: 1000,
        };
        let n = b.len();
        let mut x = vec![Vector3::zeros(); n];
        assert!(solve(&sys, model, &b, &mut x, settings, &mut CgScratch::default()).converged);

        // the springs reversed in order, every other one with its ends swapped
        let mut shuffled = model.springs.clone();
        let m = shuffled.len();
        let order: Vec<usize> = (0..m).rev().collect();
        let s = &model.springs;
        shuffled.ends = order
            .iter()
            .map(|&e| {
                if e % 2 == 0 {
                    s.ends[e]
                } else {
                    [s.ends[e][1], s.ends[e][0]]
                }
            })
            .collect();
        shuffled.rest_length = order.iter().map(|&e| s.rest_length[e]).collect();
        shuffled.stiffness = order.iter().map(|&e| s.stiffness[e]).collect();
        shuffled.damping = order.iter().map(|&e| s.damping[e]).collect();
        let shuffled = Particles {
            springs: &shuffled,
            ..*model
        };
        let (sys2, _) = system(&shuffled, positions);
        assert!(sys2.ssor);
        let (mut y, mut y2) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        sys.apply(model, &b, &mut y);
        sys2.apply(&shuffled, &b, &mut y2);
        let scale = y.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(
            y.iter()
                .zip(&y2)
                .all(|(a, b)| (a - b).norm() <= 1e-12 * scale)
        );
        let mut x2 = vec![Vector3::zeros(); n];
        assert!(
            solve(
                &sys2,
                &shuffled,
                &b,
                &mut x2,
                settings,
                &mut CgScratch::default()
            )
            .converged
        );
        let scale = x.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(
            x.iter()
                .zip(&x2)
                .all(|(a, b)| (a - b).norm() <= 1e-8 * scale)
        );
    }
}
