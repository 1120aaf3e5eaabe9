//! Reference problems with known answers, shared by the accuracy tests
//! (`sim/tests/accuracy.rs`) and `cutlab bench accuracy`: each builds a model of the chosen
//! kind ([`Elasticity`]), solves, and returns the computed and the analytic value. No clocks
//! here: the benchmark times the calls.
//!
//! - [`patch_test`]: a box whose boundary follows the uniaxial-stress field
//!   `u = eps (x, -nu y, -nu z)`; the interior must follow it and the boundary forces must be
//!   those of the uniaxial stress `E eps` (zero on the lateral faces).
//! - [`cantilever`]: an IPC bar clamped at one end, a tip load `P`; Timoshenko:
//!   `delta = P L^3 / (3 E I) + P L / (kappa G A)`, `kappa = 5/6`.
//! - [`wound_opening`]: a thin pre-stressed sheet held at its rim with a through slit of length
//!   `2a`; linear elastic fracture mechanics (plane stress, infinite sheet):
//!   `delta(x) = (4 sigma / E) sqrt(a^2 - x^2)`.
//! - [`vibration`]: a bar fixed at one end, released from a uniform stretch;
//!   `f_1 = sqrt(E / rho) / (4 L)`.

use crate::fem::FemMaterial;
use crate::fem::quadratic::{
    QuadraticMaterial, QuadraticMesh, QuadraticSolution, QuadraticStatics,
};
use crate::generate::{GridCells, grid};
use crate::model::{Material, Model, ModelError, SpringStiffness};
use crate::solver::{Integrator, Simulation, SolverSettings, StaticSettings, StepError};
use crate::{Point3, ReadError, TetMesh, Vector3};

/// A problem with a reference computation.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    /// A mesh file of the problem could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The problem's mesh is invalid.
    #[error(transparent)]
    Mesh(#[from] crate::MeshError),
    /// The model could not be built on the mesh.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A step or a static solve failed.
    #[error(transparent)]
    Step(#[from] StepError),
    /// The computation ran but gave no answer (it did not converge, found no crossing).
    #[error("{0}")]
    Failed(String),
}

/// The force model of a reference computation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Elasticity {
    /// The paper's springs, one constant on every edge: the mean of the constants that
    /// [`Elasticity::SpringsYoungs`] gives on the same mesh (the paper's model tuned to the
    /// material as well as one constant can be).
    SpringsUniform,
    /// Springs from Young's modulus after van Gelder, `k_e = sum E V / l^2`.
    SpringsYoungs,
    /// Co-rotational linear tetrahedral finite elements.
    CorotationalFem,
    /// Quadratic (10-node) tetrahedra on the same mesh ([`crate::fem::quadratic`]): linear
    /// elasticity, static problems only (the patch test, the cantilever, the wound opening);
    /// the converged reference beside the linear elements, not a model a session runs.
    QuadraticFem,
}

impl Elasticity {
    /// The models a simulation runs (statics and dynamics).
    pub const ALL: [Elasticity; 3] = [
        Elasticity::SpringsUniform,
        Elasticity::SpringsYoungs,
        Elasticity::CorotationalFem,
    ];

    /// Every model of the static reference problems: [`Self::ALL`] and the quadratic elements.
    pub const STATIC: [Elasticity; 4] = [
        Elasticity::SpringsUniform,
        Elasticity::SpringsYoungs,
        Elasticity::CorotationalFem,
        Elasticity::QuadraticFem,
    ];

    /// The model's name in reports (kebab case).
    pub fn name(self) -> &'static str {
        match self {
            Elasticity::SpringsUniform => "springs-uniform",
            Elasticity::SpringsYoungs => "springs-youngs",
            Elasticity::CorotationalFem => "corotational-fem",
            Elasticity::QuadraticFem => "quadratic-fem",
        }
    }
}

/// An isotropic elastic solid.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Solid {
    /// Young's modulus `E` in Pa.
    pub youngs_modulus_pa: f64,
    /// Poisson's ratio `nu`.
    pub poisson_ratio: f64,
    /// Mass density in kg/m^3.
    pub density_kg_per_m3: f64,
}

impl Solid {
    /// The default chest wall of [`FemMaterial::CHEST_WALL`] with the paper's density.
    pub const CHEST_WALL: Self = Self {
        youngs_modulus_pa: FemMaterial::CHEST_WALL.youngs_modulus_pa,
        poisson_ratio: FemMaterial::CHEST_WALL.poisson_ratio,
        density_kg_per_m3: 900.0,
    };
}

/// Builds a model of `kind` on `mesh` (one region, id 0 assumed for all tets) with no damping.
pub fn build_model(
    mesh: TetMesh,
    kind: Elasticity,
    solid: Solid,
    pretension: f64,
    held: &[u32],
) -> Result<Model, ReferenceError> {
    let material = |stiffness| Material {
        density_kg_per_m3: solid.density_kg_per_m3,
        stiffness,
        damping_newton_seconds_per_metre: 0.0,
        pretension,
    };
    let regions = mesh.region_ids();
    let young = SpringStiffness::YoungsModulus {
        pascals: solid.youngs_modulus_pa,
    };
    let materials: Vec<(u32, Material)> = regions.iter().map(|&r| (r, material(young))).collect();
    let model = Model::new(mesh, &materials, held, Vector3::zeros())?;
    Ok(match kind {
        Elasticity::SpringsYoungs => model,
        Elasticity::SpringsUniform => {
            let k = &model.springs.stiffness;
            let mean = k.iter().sum::<f64>() / k.len().max(1) as f64;
            let uniform = SpringStiffness::Uniform {
                newtons_per_metre: mean,
            };
            let materials: Vec<(u32, Material)> =
                regions.iter().map(|&r| (r, material(uniform))).collect();
            let mesh = model.mesh;
            Model::new(mesh, &materials, held, Vector3::zeros())?
        }
        Elasticity::CorotationalFem => {
            let fem = FemMaterial {
                youngs_modulus_pa: solid.youngs_modulus_pa,
                poisson_ratio: solid.poisson_ratio,
                rayleigh_mass_per_s: 0.0,
                rayleigh_stiffness_s: 0.0,
            };
            let fems: Vec<(u32, FemMaterial)> = regions.iter().map(|&r| (r, fem)).collect();
            model.with_fem(&fems)?
        }
        Elasticity::QuadraticFem => return Err(static_only()),
    })
}

/// The error of asking the static-only quadratic elements for a dynamic run.
pub(crate) fn static_only() -> ReferenceError {
    ReferenceError::Failed(
        "the quadratic elements solve static problems only (no mass, no time steps)".into(),
    )
}

/// The quadratic elements' material for `solid` with the pre-tension `s` (pre-strain
/// `s / (1 - s)`, as the linear elements' rest shape `(1 - s) D_ref` gives).
fn quadratic_material(solid: Solid, pretension: f64) -> QuadraticMaterial {
    let fem = FemMaterial {
        youngs_modulus_pa: solid.youngs_modulus_pa,
        poisson_ratio: solid.poisson_ratio,
        ..FemMaterial::default()
    };
    let (mu_pa, lambda_pa) = fem.lame_pa();
    QuadraticMaterial {
        mu_pa,
        lambda_pa,
        pre_strain: pretension / (1.0 - pretension),
    }
}

/// Linear statics on the quadratic elements: `held` nodes at their prescribed displacements,
/// `external` nodal forces, CG to `relative_tolerance` of the right-hand side (its true
/// residual, checked; 1e-9 leaves the cantilever's deflection unchanged in its first four
/// digits against 1e-10).
fn solve_quadratic(
    quadratic: &QuadraticMesh,
    solid: Solid,
    pretension: f64,
    held: &[Option<Vector3>],
    external: &[Vector3],
    relative_tolerance: f64,
) -> Result<QuadraticSolution, ReferenceError> {
    let statics = QuadraticStatics::new(quadratic, |_| quadratic_material(solid, pretension));
    let solution = statics.solve(held, external, relative_tolerance);
    if !solution.report.converged {
        return Err(ReferenceError::Failed(format!(
            "quadratic elements: CG did not converge: {:?}",
            solution.report
        )));
    }
    Ok(solution)
}

/// The nodes of `quadratic` on the linear mesh's boundary: its boundary vertices and the
/// middles of the boundary triangles' edges.
fn quadratic_boundary(quadratic: &QuadraticMesh, mesh: &TetMesh) -> Vec<bool> {
    let mut on = vec![false; quadratic.nodes.len()];
    for tri in &mesh.topology().boundary {
        for node in quadratic.triangle(*tri).into_iter().flatten() {
            on[node as usize] = true;
        }
    }
    on
}

/// Tight static settings for the reference solutions.
/// (Relative to the largest element or external force: 1e-6 leaves the solution error far
/// below the discretisation error while staying above the round-off of the positions.)
fn tight() -> StaticSettings {
    StaticSettings {
        relative_force_tolerance: 1e-6,
        max_newton_iterations: 60,
    }
}

/// Result of the displacement patch test.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PatchResult {
    /// Tetrahedra in the mesh.
    pub tets: usize,
    /// Largest deviation of an interior vertex from the linear field, relative to `eps L`.
    pub displacement_error: f64,
    /// Largest force on a vertex of the lateral faces (only), relative to `E eps h^2`.
    pub lateral_force: f64,
    /// `|sum of x forces on the x = L face - E eps A| / (E eps A)`.
    pub axial_force_error: f64,
}

/// The displacement patch test on a box of `cells` (uniaxial stress `E eps` along x, lateral
/// contraction `-nu eps`): the boundary vertices are held on the field, the interior settles.
pub fn patch_test(
    kind: Elasticity,
    solid: Solid,
    cells: GridCells,
    strain: f64,
) -> Result<PatchResult, ReferenceError> {
    let size = [0.04, 0.02, 0.02];
    let mesh = crate::generate::boxed(Point3::origin(), size, cells)?.mesh;
    let boundary = mesh.topology().boundary_vertices();
    let rest: Vec<Point3> = mesh.positions().to_vec();
    let nu = solid.poisson_ratio;
    let field = |p: &Point3| Vector3::new(strain * p.x, -nu * strain * p.y, -nu * strain * p.z);
    let tets = mesh.tet_count();
    // per node: rest position, held, displacement, elastic force
    let (rest, held, u, f): (Vec<Point3>, Vec<bool>, Vec<Vector3>, Vec<Vector3>) =
        if kind == Elasticity::QuadraticFem {
            let quadratic = QuadraticMesh::new(&mesh);
            let held = quadratic_boundary(&quadratic, &mesh);
            let prescribed: Vec<Option<Vector3>> = quadratic
                .nodes
                .iter()
                .zip(&held)
                .map(|(p, &h)| h.then(|| field(p)))
                .collect();
            let solution = solve_quadratic(&quadratic, solid, 0.0, &prescribed, &[], 1e-13)?;
            (
                quadratic.nodes,
                held,
                solution.displacements,
                solution.internal_forces,
            )
        } else {
            let model = build_model(mesh, kind, solid, 0.0, &boundary)?;
            let mut sim = Simulation::new(model, SolverSettings::default());
            for &v in &boundary {
                sim.state.positions[v as usize] = rest[v as usize] + field(&rest[v as usize]);
            }
            // (a uniform field: the forces are large and exact, so the solve can go to round-off)
            let report = sim.settle(StaticSettings {
                relative_force_tolerance: 1e-11,
                max_newton_iterations: 60,
            });
            if !report.converged {
                return Err(ReferenceError::Failed(format!(
                    "patch test did not settle: {report:?}"
                )));
            }
            let f = sim.forces_at(&vec![Vector3::zeros(); sim.model.vertex_count()]);
            let u = sim
                .state
                .positions
                .iter()
                .zip(&rest)
                .map(|(x, p)| x - p)
                .collect();
            (rest, sim.model.held.clone(), u, f)
        };
    let mut displacement_error = 0.0f64;
    for (i, p) in rest.iter().enumerate() {
        if !held[i] {
            displacement_error =
                displacement_error.max((u[i] - field(p)).norm() / (strain * size[0]));
        }
    }
    let h = size[0] / cells.nx as f64;
    let e = solid.youngs_modulus_pa;
    let eps_tol = 1e-9 * size[0];
    let on = |x: f64, v: f64| (x - v).abs() < eps_tol;
    let mut lateral_force = 0.0f64;
    let mut axial = 0.0;
    for (i, p) in rest.iter().enumerate() {
        let end = on(p.x, 0.0) || on(p.x, size[0]);
        if on(p.x, size[0]) {
            axial += f[i].x;
        }
        let side = on(p.y, 0.0) || on(p.y, size[1]) || on(p.z, 0.0) || on(p.z, size[2]);
        if side && !end {
            lateral_force = lateral_force.max(f[i].norm() / (e * strain * h * h));
        }
    }
    // the internal force on the end face pulls back: -sigma A
    let expected = -e * strain * size[1] * size[2];
    Ok(PatchResult {
        tets,
        displacement_error,
        lateral_force,
        axial_force_error: ((axial - expected) / expected).abs(),
    })
}

/// Reads an IPC bar (`unit_m` metres per file unit).
pub fn read_bar(path: &std::path::Path, unit_m: f64) -> Result<TetMesh, ReferenceError> {
    let mut mesh = crate::io::read_mesh(path)?;
    for p in mesh.positions_mut() {
        *p = Point3::from(p.coords * unit_m);
    }
    Ok(mesh)
}

/// Result of a cantilever computation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CantileverResult {
    /// Tetrahedra in the mesh.
    pub tets: usize,
    /// The bar's length, m.
    pub length_m: f64,
    /// Mean deflection of the tip face along the load, m.
    pub deflection_m: f64,
    /// Timoshenko's deflection, m.
    pub analytic_m: f64,
    /// `|deflection - analytic| / analytic`.
    pub relative_error: f64,
}

/// A bar clamped at its `x = min` face (all vertices held) with the tip load `P` spread over
/// the `x = max` face by area, along the bar's largest cross dimension. `P` is chosen small
/// (`delta / L` = 1e-3), so that linear beam theory applies.
///
/// Linear elements get a third of each tip triangle's share on its corners and report the
/// mean deflection of the tip vertices; quadratic elements get the consistent load of a
/// uniform traction (a third of the triangle's share on each edge middle, none on the
/// corners) and report the deflection averaged over the tip face's area (the same weights).
pub fn cantilever(
    mesh: TetMesh,
    kind: Elasticity,
    solid: Solid,
) -> Result<CantileverResult, ReferenceError> {
    let (lo, hi) = mesh.bounding_box();
    let ext = hi - lo;
    let length = ext.x;
    // the load along the larger cross dimension (height h), width b the other
    let (axis, h, b) = if ext.z >= ext.y {
        (2, ext.z, ext.y)
    } else {
        (1, ext.y, ext.z)
    };
    let tol = 1e-6 * length;
    let pos = mesh.positions().to_vec();
    let clamped: Vec<u32> = (0..pos.len() as u32)
        .filter(|&i| pos[i as usize].x < lo.x + tol)
        .collect();
    // the tip face's triangles, each with a third of its area
    let tip_triangles: Vec<([u32; 3], f64)> = mesh
        .topology()
        .boundary
        .iter()
        .filter(|tri| tri.iter().all(|&v| pos[v as usize].x > hi.x - tol))
        .map(|tri| {
            let [a, bb, c] = tri.map(|v| pos[v as usize]);
            (*tri, 0.5 * (bb - a).cross(&(c - a)).norm() / 3.0)
        })
        .collect();
    let area: f64 = 3.0 * tip_triangles.iter().map(|(_, share)| share).sum::<f64>();
    let e = solid.youngs_modulus_pa;
    let g = e / (2.0 * (1.0 + solid.poisson_ratio));
    let inertia = b * h.powi(3) / 12.0;
    let kappa = 5.0 / 6.0;
    let unit = length.powi(3) / (3.0 * e * inertia) + length / (kappa * g * b * h);
    let load = 1e-3 * length / unit;
    let analytic = load * unit;
    let tets = mesh.tet_count();
    let deflection = if kind == Elasticity::QuadraticFem {
        let quadratic = QuadraticMesh::new(&mesh);
        let mut weight = vec![0.0; quadratic.nodes.len()];
        for &(tri, share) in &tip_triangles {
            let nodes = quadratic
                .triangle(tri)
                .ok_or_else(|| ReferenceError::Failed("a tip triangle's edge is missing".into()))?;
            for &m in &nodes[3..] {
                weight[m as usize] += share;
            }
        }
        let held: Vec<Option<Vector3>> = quadratic
            .nodes
            .iter()
            .map(|p| (p.x < lo.x + tol).then(Vector3::zeros))
            .collect();
        let mut external = vec![Vector3::zeros(); quadratic.nodes.len()];
        for (f, w) in external.iter_mut().zip(&weight) {
            f[axis] = load * w / area;
        }
        // (the true residual of the coarsest bar's system, computed in f64, stays near
        // 5e-10 of the right-hand side however long CG runs: 1e-10 is out of reach there)
        let solution = solve_quadratic(&quadratic, solid, 0.0, &held, &external, 1e-9)?;
        solution
            .displacements
            .iter()
            .zip(&weight)
            .map(|(u, w)| u[axis] * w)
            .sum::<f64>()
            / area
    } else {
        let mut tip_weight = vec![0.0; pos.len()];
        for &(tri, share) in &tip_triangles {
            for v in tri {
                tip_weight[v as usize] += share;
            }
        }
        let model = build_model(mesh, kind, solid, 0.0, &clamped)?;
        let mut sim = Simulation::new(model, SolverSettings::default());
        let tip: Vec<usize> = (0..pos.len()).filter(|&i| tip_weight[i] > 0.0).collect();
        for &i in &tip {
            sim.external_forces_mut()[i][axis] = load * tip_weight[i] / area;
        }
        let report = sim.settle_loaded(tight());
        if !report.converged {
            return Err(ReferenceError::Failed(format!(
                "cantilever did not settle: {report:?}"
            )));
        }
        tip.iter()
            .map(|&i| sim.state.positions[i][axis] - pos[i][axis])
            .sum::<f64>()
            / tip.len() as f64
    };
    Ok(CantileverResult {
        tets,
        length_m: length,
        deflection_m: deflection,
        analytic_m: analytic,
        relative_error: (deflection - analytic).abs() / analytic,
    })
}

/// Result of a wound-opening computation.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WoundResult {
    /// Tetrahedra in the mesh.
    pub tets: usize,
    /// Half the slit's length `a`, m.
    pub half_length_m: f64,
    /// Gap across the slit at its middle, m.
    pub centre_gap_m: f64,
    /// `4 sigma a / E`, m.
    pub analytic_centre_gap_m: f64,
    /// `|centre gap - analytic| / analytic`.
    pub centre_error: f64,
    /// Largest `|delta - delta_analytic|` along the slit over `4 sigma a / E`.
    pub profile_error: f64,
    /// `(x, gap, analytic gap)` along the slit, m.
    pub profile: Vec<(f64, f64, f64)>,
}

/// Grid coordinates on `[-outer, outer]`: spacing `h` on `[-inner, inner]` (which must be a
/// multiple of `h`), growing by `growth` per cell outside.
fn graded(inner: f64, outer: f64, h: f64, growth: f64) -> Vec<f64> {
    let m = (inner / h).round() as usize;
    let mut right: Vec<f64> = (0..=m).map(|i| i as f64 * h).collect();
    let mut step = h;
    while *right.last().unwrap_or(&0.0) < outer - 1e-12 {
        step = (step * growth).min(8.0 * h);
        let last = *right.last().unwrap_or(&0.0);
        right.push((last + step).min(outer));
    }
    // avoid a sliver cell at the end
    let k = right.len();
    if k >= 3 && right[k - 1] - right[k - 2] < 0.5 * (right[k - 2] - right[k - 3]) {
        right.remove(k - 2);
    }
    let mut all: Vec<f64> = right.iter().skip(1).rev().map(|x| -x).collect();
    all.extend(right);
    all
}

/// A square sheet of side `2 b = 16 a` and thickness `a / cells_per_half_length`, held at its
/// rim, pre-stressed by the pre-tension `s` (in-plane strain `e = s / (1 - s)`, thickness
/// free: plane stress `sigma = E e / (1 - nu)`), with a through slit `|x| < a, y = 0` made
/// geometrically (the vertices on the slit are duplicated, the tets above it use the copies).
/// The sheet is 8 slit lengths wide, so the finite-width effect (of a held rim, which makes the
/// sheet stiffer) is below 1 %; no correction is applied. `cells_per_half_length` cells of
/// size `h = a / cells_per_half_length` resolve the slit, growing by 15 % per cell away from
/// it up to `8 h`.
pub fn wound_opening(
    kind: Elasticity,
    solid: Solid,
    pretension: f64,
    cells_per_half_length: usize,
) -> Result<WoundResult, ReferenceError> {
    let a = 0.01;
    let b = 8.0 * a;
    let h = a / cells_per_half_length.max(1) as f64;
    let xs = graded(1.5 * a, b, h, 1.15);
    let ys = graded(0.5 * a, b, h, 1.15);
    let zs = [0.0, h];
    let cells = GridCells {
        nx: xs.len() - 1,
        ny: ys.len() - 1,
        nz: 1,
    };
    let idx = |u: f64, n: usize| ((u * n as f64).round() as usize).min(n);
    let generated = grid(cells, |u, v, w| {
        Point3::new(xs[idx(u, cells.nx)], ys[idx(v, cells.ny)], zs[idx(w, 1)])
    })?;
    let mesh = generated.mesh;
    let pos = mesh.positions().to_vec();
    let tol = 1e-9 * a;
    // the slit: vertices with y = 0 and |x| < a (not the tips)
    let on_slit = |p: &Point3| p.y.abs() < tol && p.x.abs() < a - tol;
    let mut copy_of = vec![u32::MAX; pos.len()];
    let mut positions = pos.clone();
    for (i, p) in pos.iter().enumerate() {
        if on_slit(p) {
            copy_of[i] = positions.len() as u32;
            positions.push(*p);
        }
    }
    let mut tets = mesh.tets().to_vec();
    for tet in &mut tets {
        let centroid_y: f64 = tet.iter().map(|&v| pos[v as usize].y).sum::<f64>() / 4.0;
        if centroid_y > 0.0 {
            for v in tet.iter_mut() {
                if copy_of[*v as usize] != u32::MAX {
                    *v = copy_of[*v as usize];
                }
            }
        }
    }
    let regions = mesh.regions().to_vec();
    let slit_mesh = TetMesh::new(positions, tets, regions)?;
    let rim: Vec<u32> = generated.rim.clone();
    let tet_count = slit_mesh.tet_count();
    // the vertices' positions at rest
    let deformed: Vec<Point3> = if kind == Elasticity::QuadraticFem {
        // the rim's vertices and the middles of the edges between them are held
        let quadratic = QuadraticMesh::new(&slit_mesh);
        let mut held = vec![None; quadratic.nodes.len()];
        for &v in &rim {
            held[v as usize] = Some(Vector3::zeros());
        }
        for (e, &[a, b]) in quadratic.edges.iter().enumerate() {
            if held[a as usize].is_some() && held[b as usize].is_some() {
                held[quadratic.vertex_count + e] = Some(Vector3::zeros());
            }
        }
        let solution = solve_quadratic(&quadratic, solid, pretension, &held, &[], 1e-10)?;
        slit_mesh
            .positions()
            .iter()
            .zip(&solution.displacements)
            .map(|(p, u)| p + u)
            .collect()
    } else {
        let model = build_model(slit_mesh, kind, solid, pretension, &rim)?;
        let mut sim = Simulation::new(model, SolverSettings::default());
        let report = sim.settle(tight());
        if !report.converged {
            return Err(ReferenceError::Failed(format!(
                "wound opening did not settle: {report:?}"
            )));
        }
        sim.state.positions
    };
    let e = pretension / (1.0 - pretension);
    let sigma = solid.youngs_modulus_pa * e / (1.0 - solid.poisson_ratio);
    let analytic = |x: f64| 4.0 * sigma / solid.youngs_modulus_pa * (a * a - x * x).max(0.0).sqrt();
    // gap per x: mean over the through-thickness vertices
    let mut by_x: Vec<(f64, f64, usize)> = Vec::new();
    for (i, p) in pos.iter().enumerate() {
        let c = copy_of[i];
        if c == u32::MAX {
            continue;
        }
        let gap = deformed[c as usize].y - deformed[i].y;
        match by_x.iter_mut().find(|(x, _, _)| (x - p.x).abs() < tol) {
            Some(entry) => {
                entry.1 += gap;
                entry.2 += 1;
            }
            None => by_x.push((p.x, gap, 1)),
        }
    }
    by_x.sort_by(|l, r| l.0.total_cmp(&r.0));
    let profile: Vec<(f64, f64, f64)> = by_x
        .iter()
        .map(|&(x, g, k)| (x, g / k as f64, analytic(x)))
        .collect();
    let centre = profile
        .iter()
        .min_by(|l, r| l.0.abs().total_cmp(&r.0.abs()))
        .copied()
        .unwrap_or((0.0, 0.0, 0.0));
    let scale = analytic(0.0);
    let profile_error = profile
        .iter()
        .map(|&(_, g, an)| (g - an).abs() / scale)
        .fold(0.0, f64::max);
    Ok(WoundResult {
        tets: tet_count,
        half_length_m: a,
        centre_gap_m: centre.1,
        analytic_centre_gap_m: scale,
        centre_error: (centre.1 - scale).abs() / scale,
        profile_error,
        profile,
    })
}

/// Result of a free-vibration computation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct VibrationResult {
    /// Tetrahedra in the mesh.
    pub tets: usize,
    /// Steps simulated.
    pub steps: u64,
    /// The first frequency measured from the simulated motion, Hz.
    pub frequency_hz: f64,
    /// The beam theory's first frequency, Hz.
    pub analytic_hz: f64,
    /// `|frequency - analytic| / analytic`.
    pub relative_error: f64,
}

/// A bar fixed at its `x = min` face, released at rest from the uniform stretch `u_x = e x`
/// (`e` = 1e-4): the mean axial displacement of the tip face oscillates in the odd
/// longitudinal modes, whose common zeros lie a half period apart. The first frequency is
/// measured from the first and the third zero crossing, and compared with
/// `f_1 = sqrt(E / rho) / (4 L)`. No damping.
pub fn vibration(
    mesh: TetMesh,
    kind: Elasticity,
    solid: Solid,
    integrator: Integrator,
    time_step_s: f64,
) -> Result<VibrationResult, ReferenceError> {
    if !(time_step_s > 0.0 && time_step_s.is_finite()) {
        return Err(ReferenceError::Failed(format!(
            "time step must be positive, got {time_step_s} s"
        )));
    }
    if kind == Elasticity::QuadraticFem {
        return Err(static_only());
    }
    let (lo, hi) = mesh.bounding_box();
    let length = hi.x - lo.x;
    let tol = 1e-6 * length;
    let pos = mesh.positions().to_vec();
    let clamped: Vec<u32> = (0..pos.len() as u32)
        .filter(|&i| pos[i as usize].x < lo.x + tol)
        .collect();
    let tip: Vec<usize> = (0..pos.len()).filter(|&i| pos[i].x > hi.x - tol).collect();
    let tets = mesh.tet_count();
    let model = build_model(mesh, kind, solid, 0.0, &clamped)?;
    let settings = SolverSettings {
        integrator,
        time_step_s,
        cg_relative_tolerance: 1e-8,
        ..SolverSettings::default()
    };
    let mut sim = Simulation::new(model, settings);
    let stretch = 1e-4;
    for (p, x) in sim.state.positions.iter_mut().zip(&pos) {
        p.x = x.x + stretch * (x.x - lo.x);
    }
    let analytic = (solid.youngs_modulus_pa / solid.density_kg_per_m3).sqrt() / (4.0 * length);
    let tip_u = |sim: &Simulation| {
        tip.iter()
            .map(|&i| sim.state.positions[i].x - pos[i].x)
            .sum::<f64>()
            / tip.len() as f64
    };
    let max_steps = (3.0 / analytic / time_step_s).ceil() as u64;
    let mut crossings: Vec<f64> = Vec::new();
    let mut previous = tip_u(&sim);
    while crossings.len() < 3 && sim.step_index() < max_steps {
        sim.step()?;
        let u = tip_u(&sim);
        if (previous > 0.0) != (u > 0.0) {
            // linear interpolation of the crossing time
            let t1 = sim.time_s();
            crossings.push(t1 - time_step_s * u / (u - previous));
        }
        previous = u;
    }
    if crossings.len() < 3 {
        return Err(ReferenceError::Failed(format!(
            "vibration: {} zero crossings in {max_steps} steps",
            crossings.len()
        )));
    }
    let frequency = 1.0 / (crossings[2] - crossings[0]);
    Ok(VibrationResult {
        tets,
        steps: sim.step_index(),
        frequency_hz: frequency,
        analytic_hz: analytic,
        relative_error: (frequency - analytic).abs() / analytic,
    })
}

/// The IPC bars shipped in `data/ipc` (186, 651 and 2523 tets), 10 x 0.5 x 1 file units; read
/// with 0.01 m per unit (a 100 x 5 x 10 mm bar).
pub const IPC_BARS: [&str; 3] = ["bar-186.msh", "bar-651.msh", "bar-2523.msh"];

/// Metres per file unit of the IPC bars as used here.
pub const IPC_UNIT_M: f64 = 0.01;

/// The repository's `data/ipc` directory.
pub fn ipc_dir() -> std::path::PathBuf {
    std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../data/ipc"))
}

/// Richardson extrapolation of two cantilever results on meshes of similar shape, assuming an
/// error proportional to `h^2` with the element size `h ~ tets^(-1/3)`:
/// `delta = delta_2 + (delta_2 - delta_1) / (r^2 - 1)`, `r = (tets_2 / tets_1)^(1/3)`.
pub fn richardson(coarse: &CantileverResult, fine: &CantileverResult) -> f64 {
    let r2 = (fine.tets as f64 / coarse.tets as f64).powf(2.0 / 3.0);
    fine.deflection_m + (fine.deflection_m - coarse.deflection_m) / (r2 - 1.0)
}
