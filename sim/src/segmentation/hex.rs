//! Voxels to tetrahedra with the Kuhn (Freudenthal) split.
//!
//! Corners of the unit cube are numbered by `c = dx + 2 dy + 4 dz`. For each permutation
//! `s` of the axes, the simplex `{x in [0,1]^3 : x_s0 >= x_s1 >= x_s2}` has the vertices
//! `0, e_s0, e_s0 + e_s1, (1,1,1)`; the six of them tile the cube and all share the main
//! diagonal. On a cube face the split draws the face diagonal parallel to the one drawn on
//! the opposite face (e.g. `(0,0,0)-(0,1,1)` on `x = 0` and `(1,0,0)-(1,1,1)` on `x = 1`), so
//! two voxels split the same way induce the same two triangles on their common face: the
//! mesh is conforming across voxels, whatever their labels.
//!
//! Each tetrahedron has index-space volume 1/6; in world space it is `det(A)/6`, `A` the
//! linear part of the voxel-to-world affine, so when `det A < 0` (a left-handed index frame)
//! the last two vertices are swapped to keep every tetrahedron positively oriented.

use super::LabelVolume;
use crate::Point3;

/// The six Kuhn tetrahedra as cube-corner numbers, positively oriented in index space.
pub const KUHN_TETS: [[usize; 4]; 6] = [
    [0, 1, 3, 7], // x >= y >= z
    [0, 1, 7, 5], // x >= z >= y (odd permutation: last two swapped)
    [0, 2, 7, 3], // y >= x >= z (odd)
    [0, 2, 6, 7], // y >= z >= x
    [0, 4, 5, 7], // z >= x >= y
    [0, 4, 7, 6], // z >= y >= x (odd)
];

const NONE: u32 = u32::MAX;

/// Vertices (metres), tetrahedra and regions (labels) of the voxel mesh.
#[derive(Debug, Default)]
pub(super) struct VoxelMesh {
    pub positions: Vec<Point3>,
    pub tets: Vec<[u32; 4]>,
    pub regions: Vec<u32>,
}

/// Six tetrahedra per non-zero voxel, region = label. Only corners of non-zero voxels become
/// vertices, numbered in x-fastest order of the corner grid; tetrahedra follow the voxels in
/// x-fastest order, six per voxel in the order of [`KUHN_TETS`]. Corner `(i, j, k)` of the
/// corner grid is the voxel-index point `(i - 1/2, j - 1/2, k - 1/2)`.
pub(super) fn voxel_tets(vol: &LabelVolume) -> Option<VoxelMesh> {
    let dims = vol.dims();
    let labels = vol.labels();
    let (lo, hi) = super::voxels::occupied_bounds(dims, labels)?;
    // Corner grid covering the occupied box: corners lo ..= hi + 1 along each axis.
    let cd = [0, 1, 2].map(|a| hi[a] - lo[a] + 2);
    let corner =
        |i: usize, j: usize, k: usize| (i - lo[0]) + cd[0] * ((j - lo[1]) + cd[1] * (k - lo[2]));
    let mut ids = vec![NONE; cd[0] * cd[1] * cd[2]];
    let mut voxels = 0usize;
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            for i in lo[0]..=hi[0] {
                if vol.label([i, j, k]) != 0 {
                    voxels += 1;
                    for c in 0..8 {
                        ids[corner(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))] = 0;
                    }
                }
            }
        }
    }
    let mut mesh = VoxelMesh {
        positions: Vec::new(),
        tets: Vec::with_capacity(6 * voxels),
        regions: Vec::with_capacity(6 * voxels),
    };
    for k in 0..cd[2] {
        for j in 0..cd[1] {
            for i in 0..cd[0] {
                let n = i + cd[0] * (j + cd[1] * k);
                if ids[n] != NONE {
                    ids[n] = mesh.positions.len() as u32;
                    let ijk = [i + lo[0], j + lo[1], k + lo[2]].map(|x| x as f64 - 0.5);
                    mesh.positions.push(vol.world(ijk));
                }
            }
        }
    }
    let flip = vol.signed_voxel_volume() < 0.0;
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            for i in lo[0]..=hi[0] {
                let label = vol.label([i, j, k]);
                if label == 0 {
                    continue;
                }
                let v: [u32; 8] = std::array::from_fn(|c| {
                    ids[corner(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))]
                });
                for t in KUHN_TETS {
                    let mut tet = t.map(|c| v[c]);
                    if flip {
                        tet.swap(2, 3);
                    }
                    mesh.tets.push(tet);
                    mesh.regions.push(label);
                }
            }
        }
    }
    Some(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::tet_signed_volume;

    #[test]
    fn kuhn_tets_are_positive_and_fill_the_cube() {
        let corner =
            |c: usize| Point3::new((c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64);
        let mut total = 0.0;
        for t in KUHN_TETS {
            let [a, b, c, d] = t.map(corner);
            let v = tet_signed_volume(&a, &b, &c, &d);
            assert!((v - 1.0 / 6.0).abs() < 1e-15, "{t:?}: {v}");
            total += v;
        }
        assert!((total - 1.0).abs() < 1e-15);
    }
}
