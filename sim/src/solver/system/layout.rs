//! Where the spring blocks are stored: in the sweep order of two halves no spring joins and
//! the separator between them (see [`super::super::dissection`]), each spring by the end that
//! comes first in it; and the [`SweepOrder`] carried across cuts and in a resume state.

use super::super::dissection::{self, DissectionScratch};
use super::SpringSystem;

/// Where the spring blocks are stored: in the sweep order ([`super::dissection`]), by the
/// spring's end that comes first in it (its "first" particle), each particle's springs sorted
/// by the other's place in the order. Particles are named by their place `k` in the order
/// ("rank") inside the solver.
#[derive(Debug, Clone, Default)]
pub(super) struct BlockLayout {
    /// The springs this was built for.
    pub(super) ends: Vec<[u32; 2]>,
    /// The particle at each rank.
    pub(super) order: Vec<u32>,
    /// Ranks `0..halves[0]` are the first half, `halves[0]..halves[1]` the second, the rest the
    /// separator.
    pub(super) halves: [usize; 2],
    /// Slots of the springs whose first particle has rank `k`: `start[k]..start[k + 1]`.
    pub(super) start: Vec<usize>,
    /// The rank of the other (later) particle of each slot.
    pub(super) other: Vec<u32>,
    /// The slot of each spring.
    pub(super) slot: Vec<u32>,
    /// The spring of each slot.
    pub(super) spring: Vec<u32>,
    /// Whether the springs come sorted by their first end, each `[a, b]` with `a < b` (as a
    /// model's do): what the implicit assembly needs to split them in two.
    pub(super) sorted_by_first: bool,
    /// Whether some spring joins a particle to itself.
    pub(super) has_loop: bool,
    /// The part of each particle (see [`super::dissection`]), and whether a rebuild carries it
    /// over (see [`SpringSystem::carry_sweep_order`]).
    pub(super) part: Vec<u8>,
    pub(super) carry: bool,
    /// Particles in the separator when the parts were last found by dissection.
    pub(super) separator_when_dissected: usize,
    scratch: LayoutScratch,
}

impl BlockLayout {
    /// Each particle's rank (after [`Self::build`]).
    pub(super) fn rank(&self) -> &[u32] {
        &self.scratch.rank
    }

    pub(super) fn build(&mut self, n: usize, ends: &[[u32; 2]]) {
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
    /// The part of each particle: 0, 1 or 2.
    pub parts: Vec<u8>,
    /// How many particles the separator had when the parts were last found by dissection
    /// (a carried order is dissected anew once its separator grows past twice that and 64).
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
    /// More parts than particles.
    #[error("sweep order of {parts} particles for {particles}")]
    TooManyParts {
        /// How many parts.
        parts: usize,
        /// How many particles.
        particles: usize,
    },
    /// A part (given) that is not 0, 1 or 2.
    #[error("sweep order: part {0} (0, 1 or 2)")]
    Part(u8),
    /// A dissected separator larger than the particles.
    #[error("sweep order: a separator of {separator} particles for {particles}")]
    Separator {
        /// The separator's size.
        separator: usize,
        /// How many particles.
        particles: usize,
    },
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

impl SpringSystem {
    /// From now on, a change of the springs on the same particles and new ones after them (a
    /// cut's) keeps each particle in the part of the sweep order it had (new ones in the half
    /// their springs reach, or the separator) instead of dissecting the spring graph again,
    /// the larger part of the layout's cost. The order then depends on the cuts before, so it
    /// is part of a resume state ([`Self::sweep_order`]).
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
}

/// `v` cut at `h` and `s` (the halves and the separator).
pub(super) fn split3<T>(v: &mut [T], h: usize, s: usize) -> (&mut [T], &mut [T], &mut [T]) {
    let (first, rest) = v.split_at_mut(h);
    let (second, separator) = rest.split_at_mut(s - h);
    (first, second, separator)
}
