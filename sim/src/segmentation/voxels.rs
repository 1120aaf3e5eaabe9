//! Operations on the voxel set to be meshed (label 0 = empty): connected components and
//! manifoldness of the voxel surface.
//!
//! **Manifoldness.** The boundary of a union of cubes is a 2-manifold at a grid vertex iff,
//! among the 8 voxels around that vertex (its 2x2x2 block), both the occupied and the empty
//! ones are face-connected within the block. Two voxels that share only an edge or only a
//! vertex (or two empty voxels in such a position, a "pinched" void) violate it at some
//! vertex. The tetrahedral mesh is still conforming and valid there; only its boundary
//! surface touches itself.

const NONE: u32 = u32::MAX;

/// Inclusive index bounding box `[lo, hi]` of the non-zero voxels, or `None`.
pub(super) fn occupied_bounds(
    dims: [usize; 3],
    labels: &[u32],
) -> Option<([usize; 3], [usize; 3])> {
    let mut lo = dims;
    let mut hi = [0usize; 3];
    let mut any = false;
    for (n, _) in labels.iter().enumerate().filter(|(_, v)| **v != 0) {
        let ijk = unindex(dims, n);
        for a in 0..3 {
            lo[a] = lo[a].min(ijk[a]);
            hi[a] = hi[a].max(ijk[a]);
        }
        any = true;
    }
    any.then_some((lo, hi))
}

#[inline]
fn unindex(dims: [usize; 3], n: usize) -> [usize; 3] {
    [
        n % dims[0],
        (n / dims[0]) % dims[1],
        n / (dims[0] * dims[1]),
    ]
}

/// Keeps only the largest 6-connected (face-connected) component of the non-zero voxels,
/// all labels together; a tie goes to the component met first in x-fastest order.
/// Returns `(number of components, voxels removed)`.
pub(super) fn keep_largest_component(dims: [usize; 3], labels: &mut [u32]) -> (usize, usize) {
    let mut comp = vec![NONE; labels.len()];
    let mut sizes: Vec<usize> = Vec::new();
    let mut stack = Vec::new();
    let strides = [1, dims[0], dims[0] * dims[1]];
    for seed in 0..labels.len() {
        if labels[seed] == 0 || comp[seed] != NONE {
            continue;
        }
        let c = sizes.len() as u32;
        comp[seed] = c;
        stack.push(seed);
        let mut size = 0;
        while let Some(n) = stack.pop() {
            size += 1;
            let ijk = unindex(dims, n);
            for a in 0..3 {
                let mut visit = |m: usize| {
                    if labels[m] != 0 && comp[m] == NONE {
                        comp[m] = c;
                        stack.push(m);
                    }
                };
                if ijk[a] > 0 {
                    visit(n - strides[a]);
                }
                if ijk[a] + 1 < dims[a] {
                    visit(n + strides[a]);
                }
            }
        }
        sizes.push(size);
    }
    let Some(best) = (0..sizes.len()).max_by_key(|&c| (sizes[c], std::cmp::Reverse(c))) else {
        return (0, 0);
    };
    let mut removed = 0;
    for (v, &c) in labels.iter_mut().zip(&comp) {
        if c != NONE && c != best as u32 {
            *v = 0;
            removed += 1;
        }
    }
    (sizes.len(), removed)
}

/// For each 8-bit occupancy pattern of a 2x2x2 block (bit `dx + 2 dy + 4 dz`), whether the
/// voxel surface is manifold at the block's centre vertex.
fn manifold_table() -> [bool; 256] {
    fn connected(set: u8) -> bool {
        if set == 0 {
            return true;
        }
        let mut reached = 1u8 << set.trailing_zeros();
        loop {
            let mut grown = reached;
            for b in 0..8 {
                if reached & (1 << b) != 0 {
                    for step in [1, 2, 4] {
                        grown |= (1 << (b ^ step)) & set;
                    }
                }
            }
            if grown == reached {
                return reached == set;
            }
            reached = grown;
        }
    }
    std::array::from_fn(|m| connected(m as u8) && connected(!(m as u8)))
}

/// The up-to-8 voxels around grid vertex `c` (vertex `c` is the corner shared by voxels
/// `c - 1` and `c` along each axis): `(bit, linear index)` of those inside the grid.
fn block(dims: [usize; 3], c: [usize; 3]) -> impl Iterator<Item = (usize, usize)> {
    (0..8).filter_map(move |bit| {
        let d = [bit & 1, (bit >> 1) & 1, (bit >> 2) & 1];
        let mut ijk = [0; 3];
        for a in 0..3 {
            // voxel index c[a] - 1 + d[a], skipped when outside 0..dims[a]
            let i = (c[a] + d[a]).checked_sub(1)?;
            if i >= dims[a] {
                return None;
            }
            ijk[a] = i;
        }
        Some((bit, ijk[0] + dims[0] * (ijk[1] + dims[1] * ijk[2])))
    })
}

/// Grid vertices at which the voxel surface is not manifold, in x-fastest order.
pub(super) fn non_manifold_vertices(dims: [usize; 3], labels: &[u32]) -> Vec<[usize; 3]> {
    let Some((lo, hi)) = occupied_bounds(dims, labels) else {
        return Vec::new();
    };
    let table = manifold_table();
    let mut bad = Vec::new();
    for k in lo[2]..=hi[2] + 1 {
        for j in lo[1]..=hi[1] + 1 {
            for i in lo[0]..=hi[0] + 1 {
                let mask = block(dims, [i, j, k])
                    .filter(|&(_, n)| labels[n] != 0)
                    .fold(0usize, |m, (bit, _)| m | 1 << bit);
                if !table[mask] {
                    bad.push([i, j, k]);
                }
            }
        }
    }
    bad
}

/// Makes the voxel surface manifold by filling: at every offending vertex, the empty voxels
/// of its 2x2x2 block (inside the grid) get the most frequent label of the block's occupied
/// voxels (smallest on a tie); repeated until no offending vertex is left. This terminates
/// (the occupied set only grows, and a block whose in-grid voxels are all occupied is always
/// manifold) but may fill a lot in a very ragged segmentation; `max_passes` bounds it.
/// Returns `(voxels filled, offending vertices left)`.
pub(super) fn fill_non_manifold(
    dims: [usize; 3],
    labels: &mut [u32],
    max_passes: usize,
) -> (usize, usize) {
    let table = manifold_table();
    let mut filled = 0;
    for _ in 0..max_passes {
        let bad = non_manifold_vertices(dims, labels);
        if bad.is_empty() {
            return (filled, 0);
        }
        for c in bad {
            let mut votes: Vec<(u32, usize)> = Vec::with_capacity(8);
            for (_, n) in block(dims, c) {
                let v = labels[n];
                if v != 0 {
                    match votes.iter_mut().find(|(l, _)| *l == v) {
                        Some((_, k)) => *k += 1,
                        None => votes.push((v, 1)),
                    }
                }
            }
            // An earlier fill in this pass may have fixed the block already; refilling a
            // manifold block is harmless but changes more than needed, so re-check.
            let Some(&(fill, _)) = votes
                .iter()
                .max_by_key(|&&(l, k)| (k, std::cmp::Reverse(l)))
            else {
                continue;
            };
            let mask = block(dims, c)
                .filter(|&(_, n)| labels[n] != 0)
                .fold(0usize, |m, (b, _)| m | 1 << b);
            if table[mask] {
                continue;
            }
            for (_, n) in block(dims, c) {
                if labels[n] == 0 {
                    labels[n] = fill;
                    filled += 1;
                }
            }
        }
    }
    (filled, non_manifold_vertices(dims, labels).len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_flags_edge_and_vertex_contacts() {
        let t = manifold_table();
        assert!(t[0] && t[255]);
        assert!(t[0b0000_0001] && t[0b0000_0011]); // one voxel; two sharing a face
        assert!(!t[0b0000_1001]); // 0 and 3 share only an edge
        assert!(!t[0b1000_0001]); // 0 and 7 share only a vertex
        assert!(!t[0b0111_1110]); // pinched void: empty 0 and 7
        assert!(!t[0b1111_0110]); // empty 0 and 3 across an edge
    }

    #[test]
    fn fill_repairs_edge_contact() {
        let dims = [2, 2, 1];
        let mut labels = vec![1, 0, 0, 2];
        assert_eq!(
            non_manifold_vertices(dims, &labels),
            vec![[1, 1, 0], [1, 1, 1]]
        );
        let (filled, left) = fill_non_manifold(dims, &mut labels, 10);
        assert_eq!((filled, left), (2, 0));
        assert_eq!(labels, vec![1, 1, 1, 2]);
    }

    #[test]
    fn largest_component_is_kept() {
        let dims = [5, 1, 1];
        let mut labels = vec![1, 0, 2, 2, 0];
        assert_eq!(keep_largest_component(dims, &mut labels), (2, 1));
        assert_eq!(labels, vec![0, 0, 2, 2, 0]);
    }
}
