//! Co-rotational linear tetrahedral finite elements: a model of the tissue that converges to
//! the behaviour of an elastic solid as the mesh is refined (the paper's springs do not: they
//! cannot represent Poisson's ratio, and their stiffness depends on the mesh).
//!
//! # The element
//!
//! Each tetrahedron `t` with vertices `x_0 .. x_3` has a rest shape with edge matrix
//! `D_m = (1 - s) [X_1 - X_0, X_2 - X_0, X_3 - X_0]`, where `X` are the mesh's reference
//! positions and `s` the region's pre-tension: the rest shape is the reference shape shrunk by
//! `1 - s` (the analogue of the springs' `l = d (1 - s)`), so a body held in its reference
//! shape carries the pre-strain `s / (1 - s)` in every direction. Its rest volume is
//! `W = det(D_m) / 6` and its shape-function gradients are `b_1, b_2, b_3` (the rows of
//! `D_m^-1`) and `b_0 = -(b_1 + b_2 + b_3)`.
//!
//! With the deformed edge matrix `D_s = [x_1 - x_0, x_2 - x_0, x_3 - x_0]`, the deformation
//! gradient is `F = D_s D_m^-1`. Its rotation `R` comes from the polar decomposition
//! `F = R S` (Newton's iteration for the polar factor where `det F > 0`, see [`rotation`]),
//! for inverted elements from the singular value decomposition `F = U Sigma V^T` with the
//! reflection fix (when `det U < 0` or `det V < 0` the column of the smallest singular value is
//! negated, so `R = U V^T` is a proper rotation even for an inverted element, whose `S` then has
//! a negative eigenvalue and whose forces push it back out). In the element's rotated frame the
//! strain is linear: `epsilon = sym(R^T F) - I`, the stress `sigma = 2 mu epsilon +
//! lambda tr(epsilon) I` (Lame parameters `mu = E / (2 (1 + nu))`,
//! `lambda = E nu / ((1 + nu) (1 - 2 nu))`), the first Piola stress `P = R sigma` and the
//! nodal forces `f_i = -W P b_i` (energy `W (mu |epsilon|^2 + lambda / 2 tr(epsilon)^2)`).
//!
//! The stiffness used by the implicit solver is the warped linear stiffness `K = R K_0 R^T`
//! (the change of `R` is neglected, as in Mueller and Gross 2004): with `c_i = R b_i`,
//! `K_ij = W [mu (b_i . b_j) I + mu c_j c_i^T + lambda c_i c_j^T]`. `K v` for a vector field
//! `v` is computed like the force: `(K v)_i = W R sigma(sym(R^T G)) b_i` with
//! `G = [v_1 - v_0, v_2 - v_0, v_3 - v_0] D_m^-1`.
//!
//! # Mass and damping
//!
//! Masses are the model's lumped masses `m_i = sum rho V / 4` (on the reference volumes, as for
//! the springs). Rayleigh damping `C = alpha M + beta K` with `alpha` and `beta` per region.
//!
//! # Through cuts
//!
//! Everything here is derived from the mesh's reference positions, regions and materials by
//! [`FemModel::build`], which [`crate::model::Model::rebuild`] calls after every topology
//! change: the tetrahedra a cut creates get their rest shapes by the same pre-strain rule.
//! Tetrahedra of zero reference volume (possible slivers) get no stiffness.

pub(crate) mod assemble;
pub mod material;
pub(crate) mod quadratic;
pub(crate) mod solve;

pub use material::{FemMaterial, FemMaterialError};

use nalgebra::Matrix3;

use crate::model::{Material, ModelError};
use crate::{Point3, TetMesh, Vector3};

/// Everything the finite elements derive from the mesh and materials.
#[derive(Debug, Clone, Default)]
pub struct FemModel {
    /// Finite-element materials by region id, sorted by id.
    pub materials: Vec<(u32, FemMaterial)>,
    /// Vertices of each tetrahedron (a copy of the mesh's).
    pub tets: Vec<[u32; 4]>,
    /// `D_m^-1` of each rest shape (zero for degenerate tetrahedra).
    pub rest_inverse: Vec<Matrix3<f64>>,
    /// Rest volume `W = det(D_m) / 6` in m^3 (zero for degenerate tetrahedra).
    pub rest_volume_m3: Vec<f64>,
    /// The Lame parameter `mu` (the shear modulus) per tetrahedron, Pa.
    pub mu_pa: Vec<f64>,
    /// The Lame parameter `lambda` per tetrahedron, Pa.
    pub lambda_pa: Vec<f64>,
    /// Rayleigh stiffness coefficient beta per tetrahedron, s.
    pub beta_s: Vec<f64>,
    /// Mass-proportional damping `sum over tets around i of alpha rho V / 4` per vertex, N s/m.
    pub damping_mass: Vec<f64>,
    /// The mesh's edges `[a, b]`, `a < b`, sorted: the off-diagonal blocks of the stiffness.
    pub edges: Vec<[u32; 2]>,
    /// Edge ids of each tetrahedron in the local order of [`crate::mesh::topology::TET_EDGES`].
    pub tet_edges: Vec<[u32; 6]>,
    /// Tetrahedra that got no stiffness because their rest shape is degenerate.
    pub degenerate_tets: usize,
    /// `W mu (b_i . b_j)` of each tetrahedron: `i = j` for the four vertices, then the six
    /// edges of [`crate::mesh::topology::TET_EDGES`] (zero for degenerate tetrahedra).
    pub rest_dots: Vec<[f64; 10]>,
    /// Where each particle and edge is in the tetrahedra (the implicit step's gather lists).
    pub(crate) incidence: assemble::Incidence,
}

impl FemModel {
    /// Derives the elements from `mesh` (reference positions), the model's materials (density,
    /// pre-tension) and the finite-element materials, both sorted by region id.
    pub fn build(
        mesh: &TetMesh,
        materials: &[(u32, Material)],
        fem_materials: &[(u32, FemMaterial)],
    ) -> Result<Self, ModelError> {
        for (region, m) in fem_materials {
            m.check().map_err(|error| ModelError::FemMaterial {
                region: *region,
                error,
            })?;
        }
        let find = |r: u32| -> Result<(Material, FemMaterial), ModelError> {
            let m = materials
                .binary_search_by_key(&r, |(id, _)| *id)
                .map_err(|_| ModelError::MissingMaterial(r))?;
            let f = fem_materials
                .binary_search_by_key(&r, |(id, _)| *id)
                .map_err(|_| ModelError::MissingFemMaterial(r))?;
            Ok((materials[m].1, fem_materials[f].1))
        };
        let topo = mesh.topology();
        let pos = mesh.positions();
        let nt = mesh.tet_count();
        let mut model = Self {
            materials: fem_materials.to_vec(),
            tets: mesh.tets().to_vec(),
            rest_inverse: Vec::with_capacity(nt),
            rest_volume_m3: Vec::with_capacity(nt),
            rest_dots: Vec::with_capacity(nt),
            incidence: assemble::Incidence::default(),
            mu_pa: Vec::with_capacity(nt),
            lambda_pa: Vec::with_capacity(nt),
            beta_s: Vec::with_capacity(nt),
            damping_mass: vec![0.0; mesh.vertex_count()],
            edges: topo.edges.clone(),
            tet_edges: mesh
                .tets()
                .iter()
                .map(|tet| topo.tet_edge_ids(tet))
                .collect(),
            degenerate_tets: 0,
        };
        for (t, tet) in mesh.tets().iter().enumerate() {
            let (material, fem) = find(mesh.regions()[t])?;
            let [x0, x1, x2, x3] = tet.map(|v| pos[v as usize]);
            let d_m =
                Matrix3::from_columns(&[x1 - x0, x2 - x0, x3 - x0]) * (1.0 - material.pretension);
            let det = d_m.determinant();
            let inverse = d_m
                .try_inverse()
                .filter(|inv| det > 0.0 && inv.iter().all(|c| c.is_finite()));
            let (mu, lambda) = fem.lame_pa();
            match inverse {
                Some(inv) => {
                    let (b, w) = (gradients(&inv), det / 6.0);
                    let mut dots = [0.0; 10];
                    for i in 0..4 {
                        dots[i] = w * mu * b[i].dot(&b[i]);
                    }
                    for (l, &[i, j]) in crate::mesh::TET_EDGES.iter().enumerate() {
                        dots[4 + l] = w * mu * b[i].dot(&b[j]);
                    }
                    model.rest_dots.push(dots);
                    model.rest_inverse.push(inv);
                    model.rest_volume_m3.push(w);
                    model.mu_pa.push(mu);
                    model.lambda_pa.push(lambda);
                }
                None => {
                    model.degenerate_tets += 1;
                    model.rest_dots.push([0.0; 10]);
                    model.rest_inverse.push(Matrix3::zeros());
                    model.rest_volume_m3.push(0.0);
                    model.mu_pa.push(0.0);
                    model.lambda_pa.push(0.0);
                }
            }
            model.beta_s.push(fem.rayleigh_stiffness_s);
            let quarter = 0.25
                * fem.rayleigh_mass_per_s
                * material.density_kg_per_m3
                * mesh.tet_volume(t).abs();
            for &v in tet {
                model.damping_mass[v as usize] += quarter;
            }
        }
        model.incidence = assemble::Incidence::build(
            mesh.vertex_count(),
            &model.tets,
            model.edges.len(),
            &model.tet_edges,
        );
        Ok(model)
    }

    /// Number of tetrahedra.
    pub fn len(&self) -> usize {
        self.tets.len()
    }

    /// Whether there are no tetrahedra.
    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// The deformation gradient `F = D_s D_m^-1` of tetrahedron `t` at positions `x`.
    #[inline]
    pub fn deformation_gradient(&self, t: usize, x: &[Point3]) -> Matrix3<f64> {
        let [x0, x1, x2, x3] = self.tets[t].map(|v| x[v as usize]);
        Matrix3::from_columns(&[x1 - x0, x2 - x0, x3 - x0]) * self.rest_inverse[t]
    }

    /// Elastic energy `sum W (mu |epsilon|^2 + lambda / 2 tr(epsilon)^2)` in joules.
    pub fn elastic_energy(&self, x: &[Point3]) -> f64 {
        let mut energy = 0.0;
        for t in 0..self.tets.len() {
            if self.rest_volume_m3[t] == 0.0 {
                continue;
            }
            let f = self.deformation_gradient(t, x);
            let r = rotation(&f);
            let eps = strain(&r, &f);
            let tr = eps.trace();
            energy += self.rest_volume_m3[t]
                * (self.mu_pa[t] * eps.norm_squared() + 0.5 * self.lambda_pa[t] * tr * tr);
        }
        energy
    }

    /// The element stiffness blocks `K_ij` (`i, j` local vertices) of tetrahedron `t` with
    /// rotation `r`, see the module documentation.
    #[inline]
    pub fn stiffness_blocks(&self, t: usize, r: &Matrix3<f64>) -> [[Matrix3<f64>; 4]; 4] {
        let w = self.rest_volume_m3[t];
        let (mu, lambda) = (self.mu_pa[t], self.lambda_pa[t]);
        let b = gradients(&self.rest_inverse[t]);
        let c = b.map(|bi| r * bi);
        let mut k = [[Matrix3::zeros(); 4]; 4];
        for i in 0..4 {
            for j in 0..4 {
                k[i][j] = (Matrix3::identity() * (mu * b[i].dot(&b[j]))
                    + c[j] * c[i].transpose() * mu
                    + c[i] * c[j].transpose() * lambda)
                    * w;
            }
        }
        k
    }
}

impl FemModel {
    /// The exact stiffness blocks `K_ij = -d f_i / d x_j` of tetrahedron `t` at positions `x`,
    /// including the change of the rotation (the warped stiffness leaves it out; it matters for
    /// pre-stressed bodies, whose stress makes a rotated element push back: membrane tension).
    /// With `Y = R^T dF`, the rotation changes by `dR = R [w]_x` with
    /// `(tr(S) I - S) w = axial(Y - Y^T)`, and the stress by
    /// `dP = 2 mu dF + lambda tr(Y) R + (lambda tr(S - I) - 2 mu) dR`.
    /// `None` where `tr(S) I - S` is close to singular (an element near inversion): use the
    /// warped stiffness there.
    pub fn exact_stiffness_blocks(&self, t: usize, x: &[Point3]) -> Option<[[Matrix3<f64>; 4]; 4]> {
        let w_rest = self.rest_volume_m3[t];
        if w_rest == 0.0 {
            return None;
        }
        let (mu, lambda) = (self.mu_pa[t], self.lambda_pa[t]);
        let f = self.deformation_gradient(t, x);
        let r = rotation(&f);
        let s = r.transpose() * f;
        let s = (s + s.transpose()) * 0.5;
        let trace = s.trace();
        let m = Matrix3::identity() * trace - s;
        // eigenvalues of m are the pairwise sums of those of S: all near 2 at rest
        let m_inv = m
            .cholesky()
            .filter(|c| c.l().diagonal().iter().all(|&d| d * d > 0.2))?
            .inverse();
        let coefficient = lambda * (trace - 3.0) - 2.0 * mu;
        let mut dp = [[Matrix3::zeros(); 3]; 3];
        for bb in 0..3 {
            for d in 0..3 {
                let mut df = Matrix3::zeros();
                df[(bb, d)] = 1.0;
                let y = r.transpose() * df;
                let axial = Vector3::new(
                    y[(2, 1)] - y[(1, 2)],
                    y[(0, 2)] - y[(2, 0)],
                    y[(1, 0)] - y[(0, 1)],
                );
                let w = m_inv * axial;
                dp[bb][d] =
                    df * (2.0 * mu) + r * (lambda * y.trace()) + r * w.cross_matrix() * coefficient;
            }
        }
        let b = gradients(&self.rest_inverse[t]);
        let mut k = [[Matrix3::zeros(); 4]; 4];
        for i in 0..4 {
            for j in 0..4 {
                let mut block = Matrix3::zeros();
                for bb in 0..3 {
                    let mut col = Vector3::zeros();
                    for d in 0..3 {
                        col += dp[bb][d] * b[i] * b[j][d];
                    }
                    block.set_column(bb, &(col * w_rest));
                }
                k[i][j] = block;
            }
        }
        Some(k)
    }
}

/// The shape-function gradients `b_0 .. b_3` from `D_m^-1` (rows 1..3, and minus their sum).
#[inline]
pub fn gradients(rest_inverse: &Matrix3<f64>) -> [Vector3; 4] {
    let b1 = rest_inverse.row(0).transpose();
    let b2 = rest_inverse.row(1).transpose();
    let b3 = rest_inverse.row(2).transpose();
    [-(b1 + b2 + b3), b1, b2, b3]
}

/// The rotation `R` of the polar decomposition `F = R S`: a proper rotation (`det R = 1`) even
/// when `det F <= 0`. For `det F > 0`, by Higham's Newton iteration
/// `X <- (g X + X^-T / g) / 2` from `X = F` (scaled by `g = det(X)^(-1/3)` while far from
/// convergence, when `det F` is far from 1), which converges quadratically to `R`; otherwise, or if it does not converge in
/// [`POLAR_MAX_ITERATIONS`], by SVD with the reflection fix (when `det U < 0` or `det V < 0` the
/// singular vector of the smallest singular value is negated, so `R = U V^T`). Non-finite or
/// undecomposable `F` gives the identity (the step is then rejected by the solver's non-finite
/// check anyway).
pub fn rotation(f: &Matrix3<f64>) -> Matrix3<f64> {
    if !f.iter().all(|c| c.is_finite()) {
        return Matrix3::identity();
    }
    if f.determinant() > 0.0
        && let Some(r) = polar_newton(f)
    {
        return r;
    }
    rotation_by_svd(f)
}

/// Iterations of the polar Newton iteration before falling back to the SVD.
pub const POLAR_MAX_ITERATIONS: usize = 40;

/// The polar factor of `f` (`det f > 0`) by the scaled Newton iteration; `None` if it does not
/// converge (a nearly singular `f`). `X^-T = cof(X) / det X`, with the cofactor matrix's
/// columns the cross products of `X`'s (`[x_1 x x_2, x_2 x x_0, x_0 x x_1]`) and
/// `det X = x_0 . (x_1 x x_2)`.
fn polar_newton(f: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let mut x = *f;
    // scaling pays only for large volume changes (near rest, plain Newton takes ~4 steps)
    let mut scaled = (f.determinant() - 1.0).abs() > 0.2;
    for _ in 0..POLAR_MAX_ITERATIONS {
        let (c0, c1, c2) = (x.column(0), x.column(1), x.column(2));
        let cofactor = Matrix3::from_columns(&[c1.cross(&c2), c2.cross(&c0), c0.cross(&c1)]);
        let det = c0.dot(&cofactor.column(0));
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let g = if scaled { 1.0 / det.cbrt() } else { 1.0 };
        let next = (x * g + cofactor * (1.0 / (g * det))) * 0.5;
        let change = (next - x).norm();
        x = next;
        if change < 1e-3 {
            scaled = false; // close: plain Newton converges quadratically
        }
        // quadratic convergence: the error of `next` is about `change^2 / 2`
        if change < 1e-8 {
            return Some(x);
        }
    }
    None
}

/// The rotation by SVD with the reflection fix (see [`rotation`]).
pub fn rotation_by_svd(f: &Matrix3<f64>) -> Matrix3<f64> {
    if !f.iter().all(|c| c.is_finite()) {
        return Matrix3::identity();
    }
    // A bounded number of iterations: never a hang on a bad matrix.
    let Some(svd) = f.try_svd(true, true, f64::EPSILON, 200) else {
        return Matrix3::identity();
    };
    let (Some(mut u), Some(mut v_t)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let sv = svd.singular_values;
    let k = if sv[0] <= sv[1] && sv[0] <= sv[2] {
        0
    } else if sv[1] <= sv[2] {
        1
    } else {
        2
    };
    if u.determinant() < 0.0 {
        u.column_mut(k).neg_mut();
    }
    if v_t.determinant() < 0.0 {
        v_t.row_mut(k).neg_mut();
    }
    u * v_t
}

/// The co-rotated small strain `epsilon = sym(R^T F) - I`.
#[inline]
pub fn strain(r: &Matrix3<f64>, f: &Matrix3<f64>) -> Matrix3<f64> {
    let s = r.transpose() * f;
    (s + s.transpose()) * 0.5 - Matrix3::identity()
}

/// The linear stress `sigma = 2 mu epsilon + lambda tr(epsilon) I` in Pa.
#[inline]
pub fn stress(mu: f64, lambda: f64, eps: &Matrix3<f64>) -> Matrix3<f64> {
    eps * (2.0 * mu) + Matrix3::identity() * (lambda * eps.trace())
}
