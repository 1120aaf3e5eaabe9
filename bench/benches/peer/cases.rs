//! The two meshes both engines run, as cutlab models (the canonical description: mesh,
//! lumped masses, held vertices, material), with the load that presses on each and the blade
//! that cuts it.

use anyhow::Context;
use cutlab_sim::fem::FemMaterial;
use cutlab_sim::model::{Material, Model, SpringStiffness};
use cutlab_sim::reference::{IPC_UNIT_M, ipc_dir, read_bar};
use cutlab_sim::scene::{BuildOptions, Scene};
use cutlab_sim::{Point3, TetMesh, Vector3};

use crate::press::Press;

/// One mesh with everything both engines need.
#[derive(Debug, Clone)]
pub struct Case {
    pub name: &'static str,
    /// Co-rotational finite elements (what Rapier's co-rotational cells are compared with).
    pub fem: Model,
    /// The paper's springs on the same mesh (cutlab only).
    pub springs: Model,
    /// The finite elements' material (Young's modulus, Poisson's ratio, Rayleigh damping).
    pub material: FemMaterial,
    /// True when cutlab settles the model before stepping (a pre-tensioned scene).
    pub settle: bool,
    /// The load during the timed steps.
    pub press: Press,
    /// The cut: a planar quadrilateral through the middle (corners in order).
    pub cut_quad: [Point3; 4],
}

impl Case {
    pub fn tets(&self) -> usize {
        self.fem.mesh.tet_count()
    }
}

/// The IPC bar `bar-2523.msh` (100 x 5 x 10 mm), clamped at its `x = min` face like the
/// cantilever, the chest-wall material without pre-tension, a 0.5 mN press sliding along its
/// top from the middle to the tip, a notch cut half its height deep at mid-length.
pub fn bar() -> anyhow::Result<Case> {
    let mesh = bar_mesh()?;
    let (lo, hi) = mesh.bounding_box();
    let held = end_face(&mesh, lo.x);
    let density = 900.0;
    let material = FemMaterial::CHEST_WALL;
    let springs_material = Material {
        density_kg_per_m3: density,
        stiffness: SpringStiffness::YoungsModulus {
            pascals: material.youngs_modulus_pa,
        },
        damping_newton_seconds_per_metre: Material::PAPER_CHEST_WALL
            .damping_newton_seconds_per_metre,
        pretension: 0.0,
    };
    let springs = Model::new(mesh, &[(0, springs_material)], &held, Vector3::zeros())
        .context("bar springs")?;
    let fem = springs
        .clone()
        .with_fem(&[(0, material)])
        .context("bar finite elements")?;
    let mid_x = 0.5 * (lo.x + hi.x);
    let press = Press::new(
        &fem,
        Point3::new(mid_x, 0.5 * (lo.y + hi.y), hi.z),
        Point3::new(hi.x, 0.5 * (lo.y + hi.y), hi.z),
        1.0,
        5e-4,
    )
    .with_radius(0.003);
    // (off the mesh's vertex layers, so that neither engine cuts along a layer of vertices)
    let x = mid_x + 0.37e-3;
    let (y0, y1, z0, z1) = (lo.y - 1e-3, hi.y + 1e-3, 0.5 * (lo.z + hi.z), hi.z + 1e-3);
    let cut_quad = [
        Point3::new(x, y0, z1),
        Point3::new(x, y1, z1),
        Point3::new(x, y1, z0),
        Point3::new(x, y0, z0),
    ];
    Ok(Case {
        name: "bar-2523",
        fem,
        springs,
        material,
        settle: false,
        press,
        cut_quad,
    })
}

/// The IPC bar with 2,523 tets, in metres.
pub fn bar_mesh() -> anyhow::Result<TetMesh> {
    let path = ipc_dir().join("bar-2523.msh");
    read_bar(&path, IPC_UNIT_M).with_context(|| format!("reading {}", path.display()))
}

/// The vertices on the `x = x_m` face (within 1e-6 of the bar's length).
pub fn end_face(mesh: &TetMesh, x_m: f64) -> Vec<u32> {
    let (lo, hi) = mesh.bounding_box();
    let tol = 1e-6 * (hi.x - lo.x);
    (0..mesh.vertex_count() as u32)
        .filter(|&i| (mesh.positions()[i as usize].x - x_m).abs() < tol)
        .collect()
}

/// The chest wall at 10k tets requested (12,768 built): `chest-wall-fem` (co-rotational finite
/// elements, 4 % pre-tension) and `chest-wall` (the paper's springs), held at the rim; the
/// 0.3 N stroke of `cutlab bench step` along the wall; a 60 x 8 mm incision across the middle.
pub fn chest_wall() -> anyhow::Result<Case> {
    let options = BuildOptions {
        min_tets: Some(10_000),
    };
    let fem_scene = Scene::load("chest-wall-fem", options).context("chest-wall-fem")?;
    let springs = Scene::load("chest-wall", options)
        .context("chest-wall")?
        .model;
    let fem = fem_scene.model;
    let material = fem_scene
        .spec
        .materials
        .first()
        .and_then(|m| m.fem)
        .unwrap_or_default();
    let top = fem
        .mesh
        .positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::NEG_INFINITY, f64::max);
    let press = Press::new(
        &fem,
        Point3::new(-0.03, 0.0, top),
        Point3::new(0.03, 0.0, top),
        1.5,
        0.3,
    );
    // (y off the grid's vertex layers; from 1 mm above the top down to 8 mm below it)
    let y = 1.3e-3;
    let (z0, z1) = (top - 8e-3, top + 1e-3);
    let cut_quad = [
        Point3::new(-0.03, y, z1),
        Point3::new(0.03, y, z1),
        Point3::new(0.03, y, z0),
        Point3::new(-0.03, y, z0),
    ];
    Ok(Case {
        name: "chest-wall",
        fem,
        springs,
        material,
        settle: true,
        press,
        cut_quad,
    })
}
