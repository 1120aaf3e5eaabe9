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

/// One layer of a [`layered_block`], listed from the top down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer {
    /// Its thickness (m).
    pub thickness: f64,
    /// The region id its tetrahedra get.
    pub region: u32,
}

/// A disc set into the top of a [`layered_block`] (a lesion in the skin): the tetrahedra whose
/// centroids lie within `radius` of the vertical axis through `centre` and less than `depth`
/// below the top get `region`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inclusion {
    /// The disc's centre on the top face, `(x, y)` (m).
    pub centre: [f64; 2],
    /// Its radius (m).
    pub radius: f64,
    /// How far below the top it reaches (m).
    pub depth: f64,
    /// The region id its tetrahedra get.
    pub region: u32,
}

/// An axis-aligned bar set into a [`layered_block`] (a rib, a costal cartilage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bar {
    /// Its corner of least x, y and z (m).
    pub min: [f64; 3],
    /// Its corner of greatest x, y and z (m).
    pub max: [f64; 3],
    /// The region id its tetrahedra get.
    pub region: u32,
}

impl Bar {
    fn contains(&self, p: &Point3) -> bool {
        (0..3).all(|i| (self.min[i]..=self.max[i]).contains(&p[i]))
    }
}

/// The cells through each layer of a [`layered_block`] of cells `cell` across: the nearest
/// whole number to `thickness / cell`, at least one, so the layers' interfaces lie on grid
/// planes and no tetrahedron straddles two.
pub fn layer_cells(layers: &[Layer], cell: f64) -> Vec<usize> {
    layers
        .iter()
        .map(|l| ((l.thickness / cell).round() as usize).max(1))
        .collect()
}

/// A block of layered tissue: `size = [x, y]` (m) centred on the origin, its top face at
/// `z = 0` and its layers below it, top first, each its own region; cells `cell` (m) across,
/// and [`layer_cells`] through each layer. The [`Inclusion`]s then take the tetrahedra of
/// their discs, and the [`Bar`]s those whose centroids they hold.
pub fn layered_block(
    size: [f64; 2],
    cell: f64,
    layers: &[Layer],
    inclusions: &[Inclusion],
    bars: &[Bar],
) -> Result<GeneratedMesh, MeshError> {
    let through = layer_cells(layers, cell);
    // the grid planes' heights, from the bottom up, and each cell row's layer
    let mut top = -layers.iter().map(|l| l.thickness).sum::<f64>();
    let (mut z, mut row_layer) = (vec![top], Vec::new());
    for (l, (layer, &n)) in layers.iter().zip(&through).enumerate().rev() {
        for i in 1..=n {
            z.push(top + layer.thickness * i as f64 / n as f64);
            row_layer.push(l);
        }
        top += layer.thickness;
    }
    let nz = row_layer.len();
    let cells = GridCells {
        nx: ((size[0] / cell).round() as usize).max(1),
        ny: ((size[1] / cell).round() as usize).max(1),
        nz,
    };
    let g = grid(cells, |u, v, w| {
        let k = ((w * nz as f64).round() as usize).min(nz);
        Point3::new((u - 0.5) * size[0], (v - 0.5) * size[1], z[k])
    })?;
    let (positions, tets) = (g.mesh.positions().to_vec(), g.mesh.tets().to_vec());
    let regions = tets
        .iter()
        .map(|tet| {
            let c = tet.iter().fold(Point3::origin(), |c, &v| {
                c + positions[v as usize].coords / 4.0
            });
            let inside = |d: &Inclusion| {
                (c.x - d.centre[0]).hypot(c.y - d.centre[1]) < d.radius && -c.z < d.depth
            };
            if let Some(b) = bars.iter().rev().find(|b| b.contains(&c)) {
                return b.region;
            }
            match inclusions.iter().rev().find(|d| inside(d)) {
                Some(d) => d.region,
                None => {
                    let row = z.partition_point(|&h| h <= c.z).clamp(1, nz) - 1;
                    layers[row_layer[row]].region
                }
            }
        })
        .collect();
    let mesh = TetMesh::new(positions, tets, regions)?;
    Ok(GeneratedMesh { mesh, ..g })
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
    /// Each layer's tetrahedra lie between its planes and fill its volume; the disc takes the
    /// top layer's tetrahedra under it and none elsewhere.
    #[test]
    fn a_layered_block_keeps_each_layer_between_its_planes() {
        let layers = [
            Layer {
                thickness: 0.002,
                region: 1,
            },
            Layer {
                thickness: 0.009,
                region: 2,
            },
            Layer {
                thickness: 0.006,
                region: 4,
            },
        ];
        let disc = Inclusion {
            centre: [0.0, 0.0],
            radius: 0.004,
            depth: 0.002,
            region: 5,
        };
        let g = layered_block([0.04, 0.03], 0.003, &layers, &[disc], &[]).unwrap();
        let mesh = &g.mesh;
        assert!(mesh.validate().is_ok(), "{}", mesh.validate());
        assert_eq!(layer_cells(&layers, 0.003), vec![1, 3, 2]);
        let (lo, hi) = mesh.bounding_box();
        assert!((hi.z - 0.0).abs() < 1e-15 && (lo.z + 0.017).abs() < 1e-15);
        assert!((hi.x - 0.02).abs() < 1e-15 && (lo.y + 0.015).abs() < 1e-15);
        let mut volume = std::collections::BTreeMap::<u32, f64>::new();
        for (t, tet) in mesh.tets().iter().enumerate() {
            let p = tet.map(|v| mesh.positions()[v as usize]);
            let (zmin, zmax) = p
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), q| (a.min(q.z), b.max(q.z)));
            let (top, bottom) = match mesh.regions()[t] {
                1 | 5 => (0.0, -0.002),
                2 => (-0.002, -0.011),
                _ => (-0.011, -0.017),
            };
            assert!(zmax <= top + 1e-15 && zmin >= bottom - 1e-15, "tet {t}");
            *volume.entry(mesh.regions()[t]).or_default() +=
                crate::mesh::tet_signed_volume(&p[0], &p[1], &p[2], &p[3]);
        }
        let area = 0.04 * 0.03;
        assert!((volume[&2] - area * 0.009).abs() < 1e-12);
        assert!((volume[&4] - area * 0.006).abs() < 1e-12);
        let disc_volume = std::f64::consts::PI * 0.004f64.powi(2) * 0.002;
        // the disc's tetrahedra by centroid: its area within a cell's rim
        assert!(
            (volume[&5] / disc_volume - 1.0).abs() < 0.5,
            "{}",
            volume[&5]
        );
        assert!((volume[&1] + volume[&5] - area * 0.002).abs() < 1e-12);
    }
}
