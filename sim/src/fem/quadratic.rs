//! Quadratic (10-node) tetrahedra for linear elastostatics on the same mesh: the finite
//! elements' answer to bending.
//!
//! Linear tetrahedra have a constant strain, so a bent bar only a few elements thick cannot
//! carry the strain's linear variation across its height: the elements lock (shear locking,
//! worse as `nu -> 1/2`) and converge slowly (the cantilever on the IPC bars at nu = 0.45:
//! 70, 58 and 25 % too stiff). Quadratic tetrahedra carry a linear strain and represent pure
//! bending exactly.
//!
//! # The element
//!
//! Every tetrahedron of the mesh gets a node at the middle of each of its (straight) edges.
//! With the barycentric coordinates `L_0 .. L_3` and their gradients `b_i` (those of the
//! linear element, [`super::gradients`]), the shape functions are `N_i = L_i (2 L_i - 1)` at
//! the corners and `N_ij = 4 L_i L_j` at the middle of edge `(i, j)`, with gradients
//!
//! `grad N_i = (4 L_i - 1) b_i`, `grad N_ij = 4 (L_j b_i + L_i b_j)`.
//!
//! The stiffness block coupling nodes `a` and `c` (`g = grad N`; the Hessian of the energy
//! density `mu |epsilon|^2 + lambda / 2 tr(epsilon)^2`) is
//!
//! `K_ac = int [lambda g_a g_c^T + mu g_c g_a^T + mu (g_a . g_c) I] dV`,
//!
//! integrated exactly (the integrand is quadratic in `L`) by the 4-point rule: weights `V / 4`
//! at `L = (alpha, beta, beta, beta)` and its permutations, `alpha = (5 + 3 sqrt 5) / 20`,
//! `beta = (5 - sqrt 5) / 20`.
//!
//! Pre-tension: as for the linear elements a body held in its reference shape carries the
//! isotropic pre-strain `e = s / (1 - s)`, i.e. the stress `sigma_0 = (2 mu + 3 lambda) e I`,
//! whose nodal forces are `f_a = -int sigma_0 g_a dV`.
//!
//! # Scope
//!
//! Small displacements (linear elasticity), solved once by the block-SSOR PCG of
//! [`crate::solver::system`] (general 3x3 blocks), some nodes held at prescribed displacements. Static only: no mass
//! (the lumped mass of quadratic elements needs special treatment), no rotation, no cutting:
//! this is the converged reference beside the co-rotational linear elements of the same mesh,
//! for the problems whose answer is linear (small loads), not a model the session runs.

use nalgebra::Matrix3;

use super::gradients;
use crate::mesh::TET_EDGES;
use crate::solver::system::{self, CgReport, CgScratch, CgSettings, ElementSystem, Sym3};
use crate::{Point3, TetMesh, Vector3};

/// Nodes per element: four corners, then the middles of the edges in [`TET_EDGES`] order.
pub const NODES: usize = 10;

/// `alpha` and `beta` of the 4-point rule, exact for quadratic integrands.
const ALPHA: f64 = 0.585_410_196_624_968_5;
const BETA: f64 = 0.138_196_601_125_010_5;

/// The mesh's tetrahedra with a node at the middle of every edge.
#[derive(Debug, Clone)]
pub struct QuadraticMesh {
    /// The mesh's vertices (same ids), then one node per edge of its topology
    /// (id `vertex_count + edge id`).
    pub nodes: Vec<Point3>,
    /// Corners, then the edge middles in [`TET_EDGES`] order.
    pub tets: Vec<[u32; NODES]>,
    /// The region id of each tetrahedron (the mesh's).
    pub regions: Vec<u32>,
    /// The mesh's vertex count: the corner nodes are `0..vertex_count`.
    pub vertex_count: usize,
    /// The mesh's edges (sorted), whose middles are the nodes from `vertex_count` on.
    pub edges: Vec<[u32; 2]>,
}

impl QuadraticMesh {
    /// The quadratic elements of `mesh`: its vertices, then a node at the middle of each edge.
    pub fn new(mesh: &TetMesh) -> Self {
        let topology = mesh.topology();
        let vertex_count = mesh.vertex_count();
        let corners = mesh.positions();
        let middles = topology.edges.iter().map(|&[a, b]| {
            Point3::from((corners[a as usize].coords + corners[b as usize].coords) * 0.5)
        });
        let nodes: Vec<Point3> = corners.iter().copied().chain(middles).collect();
        let tets = mesh
            .tets()
            .iter()
            .map(|tet| {
                let edges = topology.tet_edge_ids(tet);
                let mut nodes = [0u32; NODES];
                nodes[..4].copy_from_slice(tet);
                for (k, &e) in edges.iter().enumerate() {
                    nodes[4 + k] = (vertex_count + e as usize) as u32;
                }
                nodes
            })
            .collect();
        Self {
            nodes,
            tets,
            regions: mesh.regions().to_vec(),
            vertex_count,
            edges: topology.edges.clone(),
        }
    }

    /// The node at the middle of the edge `a`-`b`, if it is an edge of the mesh.
    pub fn middle(&self, a: u32, b: u32) -> Option<u32> {
        let key = [a.min(b), a.max(b)];
        self.edges
            .binary_search(&key)
            .ok()
            .map(|e| (self.vertex_count + e) as u32)
    }

    /// The node ids of a boundary triangle of the linear mesh: corners `a, b, c`, then the
    /// middles of `ab`, `bc`, `ca`.
    pub fn triangle(&self, tri: [u32; 3]) -> Option<[u32; 6]> {
        let [a, b, c] = tri;
        Some([
            a,
            b,
            c,
            self.middle(a, b)?,
            self.middle(b, c)?,
            self.middle(c, a)?,
        ])
    }
}

/// The shape-function gradients at the barycentric point `l` of an element whose linear
/// gradients are `b`.
pub fn shape_gradients(l: &[f64; 4], b: &[Vector3; 4]) -> [Vector3; NODES] {
    let mut g = [Vector3::zeros(); NODES];
    for i in 0..4 {
        g[i] = b[i] * (4.0 * l[i] - 1.0);
    }
    for (k, &[i, j]) in TET_EDGES.iter().enumerate() {
        g[4 + k] = (b[i] * l[j] + b[j] * l[i]) * 4.0;
    }
    g
}

/// The quadrature points (barycentric) of the 4-point rule; each weighs a quarter of the volume.
fn quadrature() -> [[f64; 4]; 4] {
    let mut points = [[BETA; 4]; 4];
    for (q, p) in points.iter_mut().enumerate() {
        p[q] = ALPHA;
    }
    points
}

/// Volume and linear gradients of element `t`; `None` for a degenerate element.
fn linear_gradients(mesh: &QuadraticMesh, t: usize) -> Option<(f64, [Vector3; 4])> {
    let [x0, x1, x2, x3] = [0, 1, 2, 3].map(|k| mesh.nodes[mesh.tets[t][k] as usize]);
    let dm = Matrix3::from_columns(&[x1 - x0, x2 - x0, x3 - x0]);
    let volume = dm.determinant().abs() / 6.0;
    let inverse = dm.try_inverse().filter(|_| volume > 0.0)?;
    Some((volume, gradients(&inverse)))
}

/// The element stiffness blocks `K_ac` (`a <= c` filled; `K_ca = K_ac^T`) for the Lame
/// parameters `mu`, `lambda`; zero for a degenerate element.
pub fn element_stiffness(
    mesh: &QuadraticMesh,
    t: usize,
    mu: f64,
    lambda: f64,
) -> [[Matrix3<f64>; NODES]; NODES] {
    let mut k = [[Matrix3::zeros(); NODES]; NODES];
    let Some((volume, b)) = linear_gradients(mesh, t) else {
        return k;
    };
    let w = volume / 4.0;
    for l in quadrature() {
        let g = shape_gradients(&l, &b);
        for a in 0..NODES {
            for c in a..NODES {
                k[a][c] += (g[a] * g[c].transpose() * lambda
                    + g[c] * g[a].transpose() * mu
                    + Matrix3::identity() * (mu * g[a].dot(&g[c])))
                    * w;
            }
        }
    }
    k
}

/// `int g_a dV` per node of element `t` (the nodal forces of a unit isotropic stress are
/// `-int g_a dV`).
pub fn gradient_integrals(mesh: &QuadraticMesh, t: usize) -> [Vector3; NODES] {
    let mut out = [Vector3::zeros(); NODES];
    let Some((volume, b)) = linear_gradients(mesh, t) else {
        return out;
    };
    for l in quadrature() {
        for (o, g) in out.iter_mut().zip(shape_gradients(&l, &b)) {
            *o += g * (volume / 4.0);
        }
    }
    out
}

/// Per region: Lame parameters `(mu, lambda)` in Pa and the isotropic pre-strain `e`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadraticMaterial {
    /// The Lame parameter `mu`, Pa.
    pub mu_pa: f64,
    /// The Lame parameter `lambda`, Pa.
    pub lambda_pa: f64,
    /// The isotropic pre-strain `e` (the rest shape is the mesh scaled by `1 - e`).
    pub pre_strain: f64,
}

/// A linear static problem on a [`QuadraticMesh`].
#[derive(Debug, Clone)]
pub struct QuadraticStatics {
    /// `K`, its off-diagonal blocks on the node pairs that share an element, prepared with no
    /// node held (the preconditioner zeroes the held nodes' diagonal blocks): its `apply` is
    /// the whole `K u`.
    system: ElementSystem,
    /// The pre-strain's nodal forces.
    pre_stress_forces: Vec<Vector3>,
}

/// The solution of [`QuadraticStatics::solve`].
#[derive(Debug, Clone)]
pub struct QuadraticSolution {
    /// The displacement of every node (held nodes: zero), m.
    pub displacements: Vec<Vector3>,
    /// The elastic (internal) force on every node at the solution, `-(K u) - f_0` with `f_0`
    /// the pre-stress: the reactions at held nodes (with the sign of a force the body exerts).
    pub internal_forces: Vec<Vector3>,
    /// How the conjugate-gradient solve went.
    pub report: CgReport,
}

impl QuadraticStatics {
    /// Assembles the stiffness of `mesh` with the material of each element's region
    /// (`material(region)`).
    pub fn new(mesh: &QuadraticMesh, material: impl Fn(u32) -> QuadraticMaterial) -> Self {
        let n = mesh.nodes.len();
        let mut pairs: Vec<[u32; 2]> = Vec::with_capacity(mesh.tets.len() * 30);
        for tet in &mesh.tets {
            for a in 0..NODES {
                for c in a + 1..NODES {
                    pairs.push([tet[a].min(tet[c]), tet[a].max(tet[c])]);
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut system = ElementSystem::default();
        system.begin_sums(n, &pairs);
        let mut pre_stress_forces = vec![Vector3::zeros(); n];
        for (t, tet) in mesh.tets.iter().enumerate() {
            let m = material(mesh.regions[t]);
            let k = element_stiffness(mesh, t, m.mu_pa, m.lambda_pa);
            for a in 0..NODES {
                system.diag[tet[a] as usize] += Sym3::symmetric_part(&k[a][a]);
                for c in a + 1..NODES {
                    let (ga, gc) = (tet[a], tet[c]);
                    let Ok(e) = pairs.binary_search(&[ga.min(gc), ga.max(gc)]) else {
                        continue;
                    };
                    system.add_off(e, ga, gc, &k[a][c]);
                }
            }
            if m.pre_strain != 0.0 {
                let sigma = (2.0 * m.mu_pa + 3.0 * m.lambda_pa) * m.pre_strain;
                for (a, g) in gradient_integrals(mesh, t).iter().enumerate() {
                    pre_stress_forces[tet[a] as usize] -= g * sigma;
                }
            }
        }
        system.prepare_held(&vec![false; n], &[]);
        Self {
            system,
            pre_stress_forces,
        }
    }

    /// Solves `K u = f + f_0` for the free nodes, with `held[i] = Some(u_i)` prescribing node
    /// `i`'s displacement; CG to `relative_tolerance` of the right-hand side.
    pub fn solve(
        &self,
        held: &[Option<Vector3>],
        external: &[Vector3],
        relative_tolerance: f64,
    ) -> QuadraticSolution {
        let n = self.system.diag.len();
        let prescribed: Vec<Vector3> = (0..n)
            .map(|i| {
                held.get(i)
                    .copied()
                    .flatten()
                    .unwrap_or_else(Vector3::zeros)
            })
            .collect();
        let mut k_prescribed = vec![Vector3::zeros(); n];
        self.system.apply(&prescribed, &mut k_prescribed);
        let rhs: Vec<Vector3> = (0..n)
            .map(|i| {
                external.get(i).copied().unwrap_or_else(Vector3::zeros) + self.pre_stress_forces[i]
                    - k_prescribed[i]
            })
            .collect();
        let is_held: Vec<bool> = (0..n)
            .map(|i| held.get(i).is_some_and(Option::is_some))
            .collect();
        // the preconditioner zeroes the held diagonal blocks: prepare a copy, keep K whole
        let mut system = self.system.clone();
        system.prepare_held(&is_held, &[]);
        let mut free = vec![Vector3::zeros(); n];
        let settings = CgSettings {
            relative_tolerance,
            absolute_tolerance: 0.0,
            max_iterations: 20 * n.max(100),
        };
        let report = system::solve(
            &system,
            &is_held,
            &rhs,
            &mut free,
            settings,
            &mut CgScratch::default(),
        );
        let displacements: Vec<Vector3> =
            free.iter().zip(&prescribed).map(|(x, p)| x + p).collect();
        let mut internal_forces = vec![Vector3::zeros(); n];
        self.system.apply(&displacements, &mut internal_forces);
        for (f, f0) in internal_forces.iter_mut().zip(&self.pre_stress_forces) {
            *f = -*f + f0;
        }
        QuadraticSolution {
            displacements,
            internal_forces,
            report,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::{GridCells, boxed};

    /// The shape functions' gradients sum to zero (partition of unity) and the element
    /// stiffness is symmetric, annihilates rigid translations and rotations, and has exactly
    /// the 6 rigid-body modes in its null space.
    #[test]
    fn element_stiffness_has_exactly_the_rigid_modes_in_its_kernel() {
        let mesh = boxed(
            Point3::origin(),
            [0.01, 0.008, 0.012],
            GridCells {
                nx: 1,
                ny: 1,
                nz: 1,
            },
        )
        .expect("box")
        .mesh;
        let q = QuadraticMesh::new(&mesh);
        let k = element_stiffness(&q, 0, 1e4, 3e4);
        let mut full = nalgebra::DMatrix::<f64>::zeros(3 * NODES, 3 * NODES);
        for a in 0..NODES {
            for c in a..NODES {
                full.fixed_view_mut::<3, 3>(3 * a, 3 * c)
                    .copy_from(&k[a][c]);
                full.fixed_view_mut::<3, 3>(3 * c, 3 * a)
                    .copy_from(&k[a][c].transpose());
            }
        }
        let b = linear_gradients(&q, 0).expect("element").1;
        let sum: Vector3 = shape_gradients(&[0.1, 0.2, 0.3, 0.4], &b).iter().sum();
        assert!(sum.norm() < 1e-9 * b[0].norm(), "{sum}");
        let x: Vec<Point3> = q.tets[0].iter().map(|&i| q.nodes[i as usize]).collect();
        let rigid = |f: &dyn Fn(&Point3) -> Vector3| {
            nalgebra::DVector::from_iterator(3 * NODES, x.iter().flat_map(|p| f(p).data.0[0]))
        };
        let scale = full.norm();
        for mode in [
            rigid(&|_| Vector3::x()),
            rigid(&|p| Vector3::z().cross(&p.coords)),
            rigid(&|p| Vector3::new(1.0, 2.0, -1.0).cross(&p.coords)),
        ] {
            assert!(
                (&full * mode).norm() < 1e-12 * scale,
                "a rigid motion is resisted"
            );
        }
        let eigen = full.symmetric_eigen();
        let mut values: Vec<f64> = eigen.eigenvalues.iter().copied().collect();
        values.sort_by(f64::total_cmp);
        let zero = values
            .iter()
            .filter(|v| v.abs() < 1e-10 * values[values.len() - 1])
            .count();
        assert_eq!(zero, 6, "{values:?}");
        assert!(values[0] > -1e-10 * values[values.len() - 1]);
    }
}
