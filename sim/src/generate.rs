//! Built-in structured meshes: a grid of hexahedral cells, each split into six tetrahedra
//! along its main diagonal (the Kuhn / Freudenthal split). The split is identical in every
//! cell, so neighbouring cells agree on the diagonals of shared faces and the mesh is
//! conforming. A mapping function bends the grid (e.g. into a curved slab).

use crate::{MeshError, Point3, TetMesh};

/// A generated mesh with the vertex sets that scenes refer to by name.
#[derive(Debug, Clone)]
pub struct GeneratedMesh {
    /// The mesh.
    pub mesh: TetMesh,
    /// Vertices on the lateral sides of the grid (i or j at its first or last index): the
    /// rim by which a slab or sheet is held.
    pub rim: Vec<u32>,
    /// Vertices on the face i = 0 (the clamped end of a bar).
    pub end_i0: Vec<u32>,
}

/// Cell counts along the grid's three index directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GridCells {
    /// Cells along i (x before any bending).
    pub nx: usize,
    /// Cells along j (y).
    pub ny: usize,
    /// Cells along k (z, through the thickness).
    pub nz: usize,
}

impl GridCells {
    /// Number of tetrahedra the grid produces.
    pub fn tet_count(&self) -> usize {
        6 * self.nx * self.ny * self.nz
    }

    /// Smallest cell counts with roughly cubic cells over a box of `size` that give at least
    /// `min_tets` tetrahedra.
    pub fn for_tet_count(size: [f64; 3], min_tets: usize) -> Self {
        let volume = size[0] * size[1] * size[2];
        let mut h = (volume * 6.0 / min_tets.max(6) as f64).cbrt();
        loop {
            let n = size.map(|s| ((s / h).round() as usize).max(1));
            let cells = Self {
                nx: n[0],
                ny: n[1],
                nz: n[2],
            };
            if cells.tet_count() >= min_tets {
                return cells;
            }
            h *= 0.98;
        }
    }
}

/// The six tetrahedra of a unit cube as paths from corner 000 to corner 111, one per
/// permutation of the axes. Corners are numbered by bits: x = 1, y = 2, z = 4.
const KUHN: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// Builds the grid over the unit parameter cube `[0, 1]^3`, mapped to space by `map`, which
/// must be smooth and one-to-one. All tetrahedra come out positively oriented.
pub fn grid(
    cells: GridCells,
    map: impl Fn(f64, f64, f64) -> Point3,
) -> Result<GeneratedMesh, MeshError> {
    let GridCells { nx, ny, nz } = cells;
    let id = |i: usize, j: usize, k: usize| ((k * (ny + 1) + j) * (nx + 1) + i) as u32;
    let mut positions = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    let mut rim = Vec::new();
    let mut end_i0 = Vec::new();
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                positions.push(map(
                    i as f64 / nx as f64,
                    j as f64 / ny as f64,
                    k as f64 / nz as f64,
                ));
                if i == 0 || i == nx || j == 0 || j == ny {
                    rim.push(id(i, j, k));
                }
                if i == 0 {
                    end_i0.push(id(i, j, k));
                }
            }
        }
    }
    let mut tets = Vec::with_capacity(cells.tet_count());
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let corner = |c: usize| id(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                for t in KUHN {
                    tets.push(t.map(corner));
                }
            }
        }
    }
    let mut mesh = TetMesh::with_single_region(positions, tets)?;
    mesh.orient_positively();
    Ok(GeneratedMesh { mesh, rim, end_i0 })
}

/// An axis-aligned box `[0, size]` (metres) with its minimum corner at `origin`.
pub fn boxed(origin: Point3, size: [f64; 3], cells: GridCells) -> Result<GeneratedMesh, MeshError> {
    grid(cells, |u, v, w| {
        origin + nalgebra::Vector3::new(u * size[0], v * size[1], w * size[2])
    })
}

/// A slab curved about an axis parallel to y: arc length `size[0]` across, `size[1]` along the
/// axis, thickness `size[2]`; the outer surface has radius `radius` and its apex at z = 0,
/// centred on x = 0, y = 0; the tissue lies below (z <= 0), like a chest wall seen from outside.
pub fn curved_slab(
    size: [f64; 3],
    radius: f64,
    cells: GridCells,
) -> Result<GeneratedMesh, MeshError> {
    grid(cells, |u, v, w| {
        let theta = (u - 0.5) * size[0] / radius;
        // w = 0 is the inner surface, w = 1 the outer one, so the parameter frame is
        // right-handed in space.
        let r = radius - (1.0 - w) * size[2];
        Point3::new(
            r * theta.sin(),
            (v - 0.5) * size[1],
            r * theta.cos() - radius,
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_grid_is_valid_and_closed() {
        let g = boxed(
            Point3::origin(),
            [3.0, 2.0, 1.0],
            GridCells {
                nx: 3,
                ny: 2,
                nz: 1,
            },
        )
        .unwrap();
        assert_eq!(g.mesh.tet_count(), 36);
        assert_eq!(g.mesh.vertex_count(), 4 * 3 * 2);
        assert!(g.mesh.validate().is_ok(), "{}", g.mesh.validate());
        assert!(g.mesh.topology().boundary_non_manifold_edges().is_empty());
        assert!((g.mesh.volume() - 6.0).abs() < 1e-12);
        // 2 triangles per boundary cell face
        assert_eq!(g.mesh.topology().boundary.len(), 2 * 2 * (6 + 3 + 2));
    }

    #[test]
    fn curved_slab_volume_matches_annulus_sector() {
        let (size, radius) = ([0.12, 0.08, 0.015], 0.15);
        let g = curved_slab(
            size,
            radius,
            GridCells {
                nx: 60,
                ny: 4,
                nz: 3,
            },
        )
        .unwrap();
        assert!(g.mesh.validate().is_ok());
        let angle = size[0] / radius;
        let exact = 0.5 * angle * (radius * radius - (radius - size[2]).powi(2)) * size[1];
        // chords instead of arcs: relative error ~ (angle / nx)^2 / 12 per cell
        assert!(
            (g.mesh.volume() - exact).abs() / exact < 1e-4,
            "{} vs {exact}",
            g.mesh.volume()
        );
    }

    #[test]
    fn tet_count_request_is_met() {
        let c = GridCells::for_tet_count([0.12, 0.08, 0.015], 10_000);
        assert!(c.tet_count() >= 10_000 && c.tet_count() < 14_000, "{c:?}");
        let c = GridCells::for_tet_count([0.12, 0.08, 0.015], 200_000);
        assert!(c.tet_count() >= 200_000, "{c:?}");
    }
}
