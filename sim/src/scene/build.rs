//! Building a [`Scene`] from its spec: mesh, model, held vertices.

use std::path::Path;

use super::spec::{ForceModelSpec, HeldSelection, MeshSource, SceneSpec, Target, Viewpoint};
use super::{SceneError, SpecOrigin};
use crate::fem::FemMaterial;
use crate::generate::{self, GridCells};
use crate::io::ReadNote;
use crate::model::{Material, Model};
use crate::solver::Simulation;
use crate::{Point3, TetMesh, Vector3};

const MM: f64 = 1e-3;

/// Overrides applied when building a scene.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BuildOptions {
    /// Replaces `min_tets` of a generated mesh (the resolution knob).
    pub min_tets: Option<usize>,
}

/// The simulation steps [`Scene::with_time_step`] accepts, s.
pub const TIME_STEP_RANGE_S: (f64, f64) = (1e-4, 1e-2);

/// A built scene, ready to simulate.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The spec the scene was built from.
    pub spec: SceneSpec,
    /// The particle model: mesh, materials, masses, held vertices and springs.
    pub model: Model,
    /// The spec's targets (in millimetres, as written).
    pub targets: Vec<Target>,
    /// The spec's viewpoint (in millimetres), if it gives one.
    pub viewpoint: Option<Viewpoint>,
    /// What the reader left out of the scene's mesh file (vertices no tetrahedron uses,
    /// undeclared TetGen values), for the user to hear about; empty for other meshes.
    pub read_notes: Vec<ReadNote>,
}

impl Scene {
    /// Builds a built-in scene (by name, see [`super::BUILTIN`]) or a scene file (by path,
    /// `.toml` or `.json`).
    ///
    /// ```
    /// use cutlab_sim::scene::{BuildOptions, Scene};
    ///
    /// // the chest wall at a coarse resolution (at least 1,000 tetrahedra)
    /// let scene = Scene::load("chest-wall", BuildOptions { min_tets: Some(1_000) })?;
    /// assert!(scene.model.mesh.tet_count() >= 1_000);
    /// let sim = scene.simulation();
    /// assert_eq!(sim.state.positions.len(), scene.model.vertex_count());
    /// # Ok::<(), cutlab_sim::scene::SceneError>(())
    /// ```
    pub fn load(name_or_path: &str, options: BuildOptions) -> Result<Self, SceneError> {
        let (spec, origin) = super::find_spec(name_or_path)?;
        Self::build(spec, &origin, options)
    }

    /// The same scene simulated with steps of `time_step_s` (0.1 to 10 ms) instead of its
    /// spec's: how a session trades accuracy for real time on a big mesh. The spec records
    /// the new step.
    pub fn with_time_step(mut self, time_step_s: f64) -> Result<Self, SceneError> {
        if !(TIME_STEP_RANGE_S.0..=TIME_STEP_RANGE_S.1).contains(&time_step_s) {
            return Err(SceneError::Invalid {
                scene: self.spec.name.clone(),
                message: format!(
                    "a simulation step of {} ms is outside {}-{} ms",
                    time_step_s * 1e3,
                    TIME_STEP_RANGE_S.0 * 1e3,
                    TIME_STEP_RANGE_S.1 * 1e3
                ),
            });
        }
        self.spec.solver.time_step_s = time_step_s;
        Ok(self)
    }

    /// Builds a scene from its spec.
    pub fn build(
        spec: SceneSpec,
        origin: &SpecOrigin,
        options: BuildOptions,
    ) -> Result<Self, SceneError> {
        let invalid = |message: String| SceneError::Invalid {
            scene: spec.name.clone(),
            message,
        };
        spec.solver.check().map_err(|error| SceneError::Solver {
            scene: spec.name.clone(),
            error,
        })?;
        spec.incision.unit().map_err(|error| SceneError::Incision {
            scene: spec.name.clone(),
            error,
        })?;
        if !(spec.cut_threshold_newtons > 0.0 && spec.cut_threshold_newtons.is_finite()) {
            return Err(invalid(format!(
                "cut_threshold_newtons must be positive, got {}",
                spec.cut_threshold_newtons
            )));
        }
        for (name, value) in [
            ("cut_depth_mm", spec.cut_depth_mm),
            ("blade_length_mm", spec.blade_length_mm),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(invalid(format!("{name} must be positive, got {value}")));
            }
        }
        let base_dir = match origin {
            SpecOrigin::File(p) => p.parent().map(Path::to_path_buf).unwrap_or_default(),
            // Built-in scenes refer to the repository's data relative to `sim/scenes/`.
            SpecOrigin::BuiltIn => {
                std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes"))
            }
        };
        let mut read_notes = Vec::new();
        let (mesh, generated_rim) = build_mesh(&spec, &base_dir, options, &mut read_notes)?;
        let held = held_vertices(&spec, &mesh, generated_rim.as_deref()).map_err(|error| {
            SceneError::Held {
                scene: spec.name.clone(),
                error,
            }
        })?;
        let mut materials: Vec<(u32, Material)> = spec
            .materials
            .iter()
            .map(|m| (m.region, m.material()))
            .collect();
        if materials.is_empty() {
            // no materials given (a bare mesh file): the default material on every region
            materials = mesh
                .region_ids()
                .into_iter()
                .map(|r| (r, Material::default()))
                .collect();
        }
        let gravity = Vector3::from(spec.gravity_m_per_s2);
        let model_error = |source| SceneError::Model {
            scene: spec.name.clone(),
            source,
        };
        let uncuttable: Vec<u32> = spec
            .materials
            .iter()
            .filter(|m| !m.cuttable)
            .map(|m| m.region)
            .collect();
        let spare: Vec<u32> = spec
            .materials
            .iter()
            .filter(|m| m.spare)
            .map(|m| m.region)
            .collect();
        let mut model = Model::new(mesh, &materials, &held, gravity)
            .map_err(model_error)?
            .with_uncuttable_regions(&uncuttable)
            .with_spare_regions(&spare);
        if spec.force_model == ForceModelSpec::CorotationalFem {
            let fem: Vec<(u32, FemMaterial)> = if spec.materials.is_empty() {
                materials
                    .iter()
                    .map(|(r, _)| (*r, FemMaterial::default()))
                    .collect()
            } else {
                spec.materials
                    .iter()
                    .map(|m| (m.region, m.fem.unwrap_or_default()))
                    .collect()
            };
            model = model.with_fem(&fem).map_err(model_error)?;
        }
        Ok(Self {
            targets: spec.targets.clone(),
            viewpoint: spec.viewpoint.clone(),
            read_notes,
            model,
            spec,
        })
    }

    /// A simulation of this scene, at rest in the reference positions (not yet settled).
    pub fn simulation(&self) -> Simulation {
        Simulation::new(self.model.clone(), self.spec.solver)
    }
}

fn build_mesh(
    spec: &SceneSpec,
    base_dir: &Path,
    options: BuildOptions,
    read_notes: &mut Vec<ReadNote>,
) -> Result<(TetMesh, Option<Vec<u32>>), SceneError> {
    let mesh_err = |source| SceneError::Mesh {
        scene: spec.name.clone(),
        source,
    };
    let invalid = |message: String| SceneError::Invalid {
        scene: spec.name.clone(),
        message,
    };
    let check_size = |size_mm: &[f64; 3], min_tets: usize| -> Result<(), SceneError> {
        if !size_mm.iter().all(|s| *s > 0.0 && s.is_finite()) {
            return Err(invalid(format!(
                "mesh size must be positive, got {size_mm:?} mm"
            )));
        }
        if !(1..=50_000_000).contains(&min_tets) {
            return Err(invalid(format!(
                "min_tets must be between 1 and 50,000,000, got {min_tets}"
            )));
        }
        Ok(())
    };
    match &spec.mesh {
        MeshSource::CurvedSlab {
            size_mm,
            radius_mm,
            min_tets,
        } => {
            let min_tets = options.min_tets.unwrap_or(*min_tets);
            check_size(size_mm, min_tets)?;
            if !(*radius_mm > size_mm[2]) || size_mm[0] / radius_mm > std::f64::consts::PI {
                return Err(invalid(format!(
                    "radius_mm must exceed the thickness and the arc must span less than half a turn, got {radius_mm}"
                )));
            }
            let size = size_mm.map(|s| s * MM);
            let cells = GridCells::for_tet_count(size, min_tets);
            let g = generate::curved_slab(size, radius_mm * MM, cells).map_err(mesh_err)?;
            Ok((g.mesh, Some(g.rim)))
        }
        MeshSource::Box { size_mm, min_tets } => {
            let min_tets = options.min_tets.unwrap_or(*min_tets);
            check_size(size_mm, min_tets)?;
            let size = size_mm.map(|s| s * MM);
            let cells = GridCells::for_tet_count(size, min_tets);
            let g = generate::boxed(Point3::origin(), size, cells).map_err(mesh_err)?;
            Ok((g.mesh, Some(g.rim)))
        }
        MeshSource::LayeredBox {
            size_mm,
            cell_mm,
            layers,
            inclusions,
            bars,
        } => layered_box(size_mm, *cell_mm, layers, inclusions, bars)
            .map_err(invalid)?
            .map_err(mesh_err)
            .map(|g| (g.mesh, Some(g.rim))),
        MeshSource::File { path, unit_m } => {
            let path = base_dir.join(path);
            if !(*unit_m > 0.0 && unit_m.is_finite()) {
                return Err(invalid(format!("unit_m must be positive, got {unit_m}")));
            }
            let read = crate::io::read_mesh_noting(&path)?;
            read_notes.extend(read.notes);
            let mut mesh = read.mesh;
            for p in mesh.positions_mut() {
                *p *= *unit_m;
            }
            Ok((mesh, None))
        }
        MeshSource::Segmentation {
            path,
            labels,
            masks,
            coarsen,
        } => {
            use crate::segmentation::{
                LabelVolume, MeshingOptions, NonManifold, Resample, mesh_labels,
            };
            let seg_err = |source: crate::SegmentationError| SceneError::Segmentation {
                scene: spec.name.clone(),
                source,
            };
            let (volume, labels) = match (path, masks.is_empty()) {
                (Some(p), true) => (LabelVolume::read(base_dir.join(p))?, labels.clone()),
                (None, false) => {
                    let files: Vec<_> = masks
                        .iter()
                        .map(|m| (base_dir.join(&m.path), m.region))
                        .collect();
                    (
                        LabelVolume::from_mask_files(&files).map_err(seg_err)?,
                        masks.iter().map(|m| m.region).collect(),
                    )
                }
                _ => {
                    return Err(invalid(
                        "a segmentation mesh needs either `path` (with `labels`) or `masks`".into(),
                    ));
                }
            };
            let mut opts = MeshingOptions::new(labels);
            opts.resample = coarsen.map(Resample::Factor);
            opts.keep_largest_component = true;
            opts.non_manifold = NonManifold::Fill;
            Ok((mesh_labels(&volume, &opts).map_err(seg_err)?, None))
        }
    }
}

/// The layered box of a scene, or what is wrong with its numbers.
fn layered_box(
    size_mm: &[f64; 2],
    cell_mm: f64,
    layers: &[super::spec::LayerSpec],
    inclusions: &[super::spec::InclusionSpec],
    bars: &[super::spec::BarSpec],
) -> Result<Result<generate::GeneratedMesh, crate::MeshError>, String> {
    let positive = |v: f64| v > 0.0 && v.is_finite();
    if !size_mm.iter().all(|&s| positive(s)) || !positive(cell_mm) {
        return Err(format!(
            "size_mm and cell_mm must be positive, got {size_mm:?} and {cell_mm} mm"
        ));
    }
    if layers.is_empty() {
        return Err("a layered box needs at least one layer".into());
    }
    if let Some(l) = layers.iter().find(|l| !positive(l.thickness_mm)) {
        return Err(format!(
            "layer {:?}: thickness_mm must be positive, got {}",
            l.name, l.thickness_mm
        ));
    }
    if let Some(d) = inclusions.iter().find(|d| {
        !d.centre_mm.iter().all(|c| c.is_finite())
            || !positive(d.radius_mm)
            || !positive(d.depth_mm)
    }) {
        return Err(format!(
            "inclusion {:?}: needs a finite centre_mm and positive radius_mm and depth_mm",
            d.name
        ));
    }
    let layers: Vec<generate::Layer> = layers
        .iter()
        .map(|l| generate::Layer {
            thickness: l.thickness_mm * MM,
            region: l.region,
        })
        .collect();
    let cell = cell_mm * MM;
    let through: usize = generate::layer_cells(&layers, cell).iter().sum();
    let across = size_mm.map(|s| (s / cell_mm).round().max(1.0));
    if 6.0 * across[0] * across[1] * through as f64 > 50e6 {
        return Err(format!(
            "cell_mm {cell_mm} makes more than 50,000,000 tetrahedra"
        ));
    }
    let discs: Vec<generate::Inclusion> = inclusions
        .iter()
        .map(|d| generate::Inclusion {
            centre: d.centre_mm.map(|c| c * MM),
            radius: d.radius_mm * MM,
            depth: d.depth_mm * MM,
            region: d.region,
        })
        .collect();
    if let Some(b) = bars.iter().find(|b| {
        !(0..3).all(|i| {
            b.min_mm[i].is_finite() && b.max_mm[i].is_finite() && b.min_mm[i] < b.max_mm[i]
        })
    }) {
        return Err(format!(
            "bar {:?}: min_mm must be below max_mm on every axis, all finite",
            b.name
        ));
    }
    let bars: Vec<generate::Bar> = bars
        .iter()
        .map(|b| generate::Bar {
            min: b.min_mm.map(|c| c * MM),
            max: b.max_mm.map(|c| c * MM),
            region: b.region,
        })
        .collect();
    Ok(generate::layered_block(
        size_mm.map(|s| s * MM),
        cell,
        &layers,
        &discs,
        &bars,
    ))
}

/// A `[[held]]` selection that selects nothing sensible.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeldError {
    /// The axes (given) are not letters of `xyz`.
    #[error("axes must be letters of \"xyz\", got {0:?}")]
    Axes(String),
    /// The width (given) is negative or not a number.
    #[error("width_mm must be non-negative, got {0}")]
    Width(f64),
    /// The region (given) has no tetrahedra to hold.
    #[error("held region {0} has no tetrahedra")]
    EmptyRegion(u32),
}

fn held_vertices(
    spec: &SceneSpec,
    mesh: &TetMesh,
    generated_rim: Option<&[u32]>,
) -> Result<Vec<u32>, HeldError> {
    let mut held = Vec::new();
    for sel in &spec.held {
        match sel {
            HeldSelection::Rim { width_mm } => match (generated_rim, width_mm) {
                (Some(rim), None) => held.extend_from_slice(rim),
                _ => held.extend(bounding_box_rim(mesh, width_mm.map(|w| w * MM))),
            },
            HeldSelection::BoundingBoxFaces { axes, width_mm } => {
                let axes: Vec<usize> = axes
                    .chars()
                    .map(|c| "xyz".find(c).ok_or_else(|| HeldError::Axes(axes.clone())))
                    .collect::<Result<_, _>>()?;
                if !(*width_mm >= 0.0) {
                    return Err(HeldError::Width(*width_mm));
                }
                held.extend(near_box_faces(mesh, &axes, width_mm * MM));
            }
            HeldSelection::Box { min_mm, max_mm } => {
                let lo = Point3::from(min_mm.map(|v| v * MM));
                let hi = Point3::from(max_mm.map(|v| v * MM));
                held.extend(
                    mesh.positions()
                        .iter()
                        .enumerate()
                        .filter(|(_, p)| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
                        .map(|(i, _)| i as u32),
                );
            }
            HeldSelection::Region { region } => {
                let before = held.len();
                for (t, tet) in mesh.tets().iter().enumerate() {
                    if mesh.regions()[t] == *region {
                        held.extend_from_slice(tet);
                    }
                }
                if held.len() == before {
                    return Err(HeldError::EmptyRegion(*region));
                }
            }
        }
    }
    held.sort_unstable();
    held.dedup();
    Ok(held)
}

/// Boundary vertices within `width` (default 2 % of the diagonal) of the bounding-box faces
/// across the two longest axes.
fn bounding_box_rim(mesh: &TetMesh, width: Option<f64>) -> Vec<u32> {
    let (lo, hi) = mesh.bounding_box();
    let extent = hi - lo;
    let width = width.unwrap_or(0.02 * extent.norm());
    let mut axes = [0usize, 1, 2];
    axes.sort_by(|&a, &b| extent[b].total_cmp(&extent[a]));
    near_box_faces(mesh, &axes[..2], width)
}

/// Boundary vertices within `width` of the bounding-box faces across `axes`.
fn near_box_faces(mesh: &TetMesh, axes: &[usize], width: f64) -> Vec<u32> {
    let (lo, hi) = mesh.bounding_box();
    let pos = mesh.positions();
    mesh.topology()
        .boundary_vertices()
        .into_iter()
        .filter(|&v| {
            let p = pos[v as usize];
            axes.iter()
                .any(|&k| p[k] - lo[k] <= width || hi[k] - p[k] <= width)
        })
        .collect()
}
