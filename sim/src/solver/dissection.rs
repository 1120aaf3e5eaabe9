//! The order in which the SSOR sweeps visit the particles: one level of nested dissection, so
//! that the sweeps can run on two threads without changing a bit of their result.
//!
//! The particles are split into two halves that no spring joins, and the separator between
//! them: breadth-first levels from a far end of the largest piece of the spring graph, the
//! level at which half the particles have been reached is the separator (no spring joins two
//! particles whose levels differ by more than one), the levels before it the first half, the
//! levels after it and the pieces not reached the second. Within each part the particles keep
//! their own order, which is what the Gauss-Seidel sweeps are good at: the separator is a few
//! per cent of the particles, and the solves need only a few per cent more CG iterations than
//! in the plain particle order (`docs/design/solver.md`).
//!
//! A forward sweep then visits the first half, the second half, the separator; a backward sweep
//! the reverse. The two halves touch each other only through the separator, so a sweep over one
//! half can run beside the sweep over the other.
//!
//! A cut keeps its particles and adds new ones after them, with springs among the particles
//! around it. The whole-body step carries the parts over ([`extend_parts`]: a new particle
//! joins the half its springs reach, or the separator) instead of dissecting again, as long as
//! no spring joins the halves and the separator stays small.

use crate::mesh::Csr;

/// Buffers of [`dissection_order_into`], kept between calls (a cut changes the springs, and
/// with them the order, every few steps).
#[derive(Debug, Clone, Default)]
pub(crate) struct DissectionScratch {
    /// The spring graph: the neighbours of each particle, in the springs' order.
    graph: Csr,
    level: Vec<u32>,
    queue: Vec<u32>,
}

/// The part of a particle: the first half, the second, the separator.
pub(crate) const FIRST: u8 = 0;
pub(crate) const SECOND: u8 = 1;
pub(crate) const SEPARATOR: u8 = 2;

/// The sweep order of `n` particles joined by springs `ends`: `order[k]` is the `k`-th
/// particle, and `parts = [h, s]` the ends of the first half (`order[..h]`) and of the second
/// (`order[h..s]`); the separator is `order[s..]`.
#[cfg(test)]
pub(crate) fn dissection_order(n: usize, ends: &[[u32; 2]]) -> (Vec<u32>, [usize; 2]) {
    let (mut order, mut part) = (Vec::new(), Vec::new());
    dissection_parts_into(n, ends, &mut DissectionScratch::default(), &mut part);
    let parts = order_of_parts(&part, &mut order);
    (order, parts)
}

/// The part ([`FIRST`], [`SECOND`], [`SEPARATOR`]) of each of `n` particles joined by springs
/// `ends` (see the module documentation), into `part`, with the buffers of `scratch`.
pub(crate) fn dissection_parts_into(
    n: usize,
    ends: &[[u32; 2]],
    scratch: &mut DissectionScratch,
    part: &mut Vec<u8>,
) {
    part.clear();
    if n == 0 {
        return;
    }
    let DissectionScratch {
        graph,
        level,
        queue,
    } = scratch;
    // the graph: each spring's ends are each other's neighbours, rows in the springs' order
    graph.refill(n, || {
        ends.iter()
            .filter(|[a, b]| a != b)
            .flat_map(|&[a, b]| [(a, b), (b, a)])
    });
    let graph = &*graph;
    level.clear();
    level.resize(n, u32::MAX);
    queue.clear();
    queue.reserve(n);
    // the particle with the most springs (the lowest such id) lies in the largest piece; the
    // particle reached last from it is a far end of that piece
    let seed = (0..n)
        .max_by_key(|&i| (graph.row(i).len(), std::cmp::Reverse(i)))
        .unwrap_or(0);
    let far = levels_from(graph, seed, level, queue);
    let far = levels_from(graph, far, level, queue);
    let depth = level[far] as usize;
    let mut count = vec![0usize; depth + 1];
    for &l in level.iter().filter(|&&l| l != u32::MAX) {
        count[l as usize] += 1;
    }
    let (mut separator, mut before) = (0, 0);
    while separator < depth && before + count[separator] < n / 2 {
        before += count[separator];
        separator += 1;
    }
    let separator = separator as u32;
    part.extend(level.iter().map(|&l| match l {
        u32::MAX => SECOND,
        l if l < separator => FIRST,
        l if l > separator => SECOND,
        _ => SEPARATOR,
    }));
}

/// The sweep order of particles in parts `part`: the first half, the second, the separator,
/// each in the particles' order. Returns the ends `[h, s]` of the halves.
pub(crate) fn order_of_parts(part: &[u8], order: &mut Vec<u32>) -> [usize; 2] {
    order.clear();
    order.reserve(part.len());
    let mut ends = [0; 2];
    for p in [FIRST, SECOND, SEPARATOR] {
        order.extend((0..part.len() as u32).filter(|&i| part[i as usize] == p));
        if p != SEPARATOR {
            ends[p as usize] = order.len();
        }
    }
    ends
}

/// Carries the parts over to springs `ends` on `n` particles, the particles from `part.len()`
/// on new (a cut's): a new particle goes to the half its springs reach, unless they reach both
/// halves or another new particle (then to the separator). Returns whether no spring joins the
/// halves (otherwise the parts must be found anew); `part` is extended either way.
pub(crate) fn extend_parts(part: &mut Vec<u8>, n: usize, ends: &[[u32; 2]]) -> bool {
    let old = part.len();
    if old > n {
        return false;
    }
    // per new particle: bit p set when a spring reaches part p, bit 3 when it reaches a new one
    let mut reach = vec![0u8; n - old];
    let mut joined = false;
    for &[a, b] in ends {
        let (a, b) = (a as usize, b as usize);
        if a < old && b < old {
            joined |= part[a] + part[b] == FIRST + SECOND;
            continue;
        }
        for (me, other) in [(a, b), (b, a)] {
            if me >= old {
                reach[me - old] |= if other >= old { 8 } else { 1 << part[other] };
            }
        }
    }
    // (a new particle joins a half only when its springs reach that half and the separator
    // alone: no spring of a new particle joins the halves)
    part.extend(reach.iter().map(|&r| match r {
        1 | 5 => FIRST,
        2 | 6 => SECOND,
        _ => SEPARATOR,
    }));
    !joined
}

/// Particles in the separator.
pub(crate) fn separator_count(part: &[u8]) -> usize {
    part.iter().filter(|&&p| p == SEPARATOR).count()
}

/// Breadth-first levels from `from` (`u32::MAX` where not reached); returns the particle
/// reached last.
fn levels_from(graph: &Csr, from: usize, level: &mut [u32], queue: &mut Vec<u32>) -> usize {
    level.iter_mut().for_each(|l| *l = u32::MAX);
    queue.clear();
    level[from] = 0;
    queue.push(from as u32);
    let mut head = 0;
    while let Some(&u) = queue.get(head) {
        head += 1;
        for &w in graph.row(u as usize) {
            if level[w as usize] == u32::MAX {
                level[w as usize] = level[u as usize] + 1;
                queue.push(w);
            }
        }
    }
    queue.last().map_or(from, |&u| u as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{BuildOptions, Scene};

    #[test]
    fn the_halves_touch_only_through_the_separator() {
        let scene = Scene::load(
            "chest-wall",
            BuildOptions {
                min_tets: Some(10_000),
            },
        )
        .expect("built-in scene");
        let model = scene.model.particles();
        let n = model.vertex_count();
        let (order, [h, s]) = dissection_order(n, &model.springs.ends);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>(), "a permutation");
        let mut part = vec![0; n];
        for (k, &i) in order.iter().enumerate() {
            part[i as usize] = if k < h {
                0
            } else if k < s {
                1
            } else {
                2
            };
        }
        assert!(
            model
                .springs
                .ends
                .iter()
                .all(|&[a, b]| part[a as usize] + part[b as usize] != 1),
            "a spring joins the halves"
        );
        // balanced halves, a thin separator
        assert!(h > n / 3 && s - h > n / 3, "{h} {s} {n}");
        assert!((n - s) * 10 < n, "separator of {} particles", n - s);
        // each part in the particle order
        for range in [0..h, h..s, s..n] {
            assert!(order[range].windows(2).all(|w| w[0] < w[1]));
        }
        // a graph without springs: every particle in the second half
        assert_eq!(dissection_order(3, &[]), (vec![1, 2, 0], [0, 2]));
    }

    #[test]
    fn new_particles_join_the_half_their_springs_reach() {
        // 0 and 1 in the first half, 2 the separator, 3 and 4 the second half
        let mut part = vec![FIRST, FIRST, SEPARATOR, SECOND, SECOND];
        // 5 reaches 0 and 2, 6 reaches 4, 7 reaches 2 alone, 8 reaches 0 and 3, 9 reaches 5
        let ends = [
            [0, 1],
            [1, 2],
            [2, 3],
            [3, 4],
            [0, 5],
            [2, 5],
            [4, 6],
            [2, 7],
            [0, 8],
            [3, 8],
            [5, 9],
        ];
        assert!(extend_parts(&mut part, 10, &ends));
        assert_eq!(
            part[5..],
            [SEPARATOR, SECOND, SEPARATOR, SEPARATOR, SEPARATOR],
            "5 reaches the new 9"
        );
        let mut part = vec![FIRST, FIRST, SEPARATOR, SECOND, SECOND];
        assert!(extend_parts(&mut part, 9, &ends[..10]));
        assert_eq!(part[5..], [FIRST, SECOND, SEPARATOR, SEPARATOR]);
        let mut order = Vec::new();
        assert_eq!(order_of_parts(&part, &mut order), [3, 6]);
        assert_eq!(order, [0, 1, 5, 3, 4, 6, 2, 7, 8]);
        // a new spring across the halves: the parts must be found anew
        let mut part = vec![FIRST, FIRST, SEPARATOR, SECOND, SECOND];
        assert!(!extend_parts(&mut part, 5, &[[1, 3]]));
        // fewer particles than before: likewise
        assert!(!extend_parts(&mut vec![FIRST; 4], 3, &[]));
    }
}
