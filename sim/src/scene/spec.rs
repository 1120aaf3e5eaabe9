//! The scene file: TOML (or JSON) describing mesh source, materials, held vertices, targets,
//! viewpoint and solver settings. See `sim/scenes/*.toml` for documented examples; the
//! built-in scenes are exactly those files.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::model::Material;
use crate::solver::SolverSettings;

/// A scene as written in a scene file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// The scene's name (a built-in scene's is how it is loaded).
    pub name: String,
    /// A sentence or two on what the scene is, for listings.
    #[serde(default)]
    pub description: String,
    /// Gravitational acceleration in m/s^2; zero (the default) turns gravity off.
    #[serde(default)]
    pub gravity_m_per_s2: [f64; 3],
    /// Where the tetrahedral mesh comes from.
    pub mesh: MeshSource,
    /// Material per region id of the mesh.
    pub materials: Vec<RegionMaterial>,
    /// Which vertices are held fixed (the union of all selections).
    #[serde(default)]
    pub held: Vec<HeldSelection>,
    /// Structures behind the tissue that an incision must expose (for the field-of-view
    /// metric).
    #[serde(default)]
    pub targets: Vec<Target>,
    /// Where the surgeon looks from.
    pub viewpoint: Option<Viewpoint>,
    /// The incision a session practises when no exercise gives a plan.
    #[serde(default)]
    pub incision: IncisionDirections,
    /// The push along the surface normal at which a scalpel's blade enters this tissue, N
    /// (the haptic renderer's cut threshold; default 1 N).
    #[serde(default = "default_cut_threshold_newtons")]
    pub cut_threshold_newtons: f64,
    /// How far an engaged blade's tip must have pressed into this tissue, from where it first
    /// touched it, to enter it when the push has stayed under `cut_threshold_newtons` (a soft
    /// or loosely held tissue yields instead of pushing back), mm (default 4 mm).
    #[serde(default = "default_cut_depth_mm")]
    pub cut_depth_mm: f64,
    /// The scalpel's cutting edge from its tip, mm (default 20 mm): a wall thicker than
    /// that (the thorax's 40 mm) needs a longer blade to be opened in one stroke.
    #[serde(default = "default_blade_length_mm")]
    pub blade_length_mm: f64,
    /// The solver settings (the `[solver]` table; defaults where absent).
    #[serde(default)]
    pub solver: SolverSettings,
    /// The force model: the paper's `springs` (default) or `corotational-fem`.
    #[serde(default)]
    pub force_model: ForceModelSpec,
}

impl SceneSpec {
    /// What the scene calls region `region` (its material's `name`), else `region N`.
    pub fn region_name(&self, region: u32) -> String {
        self.materials
            .iter()
            .find(|m| m.region == region && !m.name.is_empty())
            .map_or_else(|| format!("region {region}"), |m| m.name.clone())
    }
}

/// The force model of a scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ForceModelSpec {
    /// The paper's springs and dampers on the edges.
    #[default]
    Springs,
    /// Co-rotational linear tetrahedral finite elements.
    CorotationalFem,
}

/// Where the tetrahedral mesh comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MeshSource {
    /// A slab curved about an axis parallel to y (see [`crate::generate::curved_slab`]).
    CurvedSlab {
        /// Length, width and thickness of the slab before it is bent, in mm.
        size_mm: [f64; 3],
        /// The radius of curvature of its mid-surface, in mm.
        radius_mm: f64,
        /// The fewest tetrahedra the mesh may have (the resolution).
        min_tets: usize,
    },
    /// An axis-aligned box with its minimum corner at the origin.
    Box {
        /// Its extent along x, y and z, in mm.
        size_mm: [f64; 3],
        /// The fewest tetrahedra the mesh may have (the resolution).
        min_tets: usize,
    },
    /// A block of layered tissue (skin over fat over muscle), each layer its own region,
    /// centred on the origin with its top face at z = 0 (see
    /// [`crate::generate::layered_block`]); `min_tets` does not apply (`cell_mm` sets the
    /// resolution).
    LayeredBox {
        /// Its extent along x and y, in mm.
        size_mm: [f64; 2],
        /// The cells' size across, in mm; each layer is as many cells through as its thickness
        /// holds (at least one), so interfaces lie on cell faces.
        cell_mm: f64,
        /// The layers, from the top down.
        layers: Vec<LayerSpec>,
        /// Discs set into the top (a lesion), each its own region.
        #[serde(default)]
        inclusions: Vec<InclusionSpec>,
        /// Axis-aligned bars set into the block (ribs, costal cartilage), each its own region;
        /// they take the tetrahedra whose centroids lie inside, after the discs. Faces on the
        /// grid's planes (the layers' interfaces, multiples of `cell_mm` from the sides) make
        /// clean bars.
        #[serde(default)]
        bars: Vec<BarSpec>,
    },
    /// A mesh file (.msh, .node/.ele, .vtk, .vtu); relative paths are relative to the scene
    /// file. `unit_m` is the length of one file unit in metres (0.001 for millimetres).
    File {
        /// The mesh file.
        path: PathBuf,
        /// The length of one file unit in metres (default 1).
        #[serde(default = "one")]
        unit_m: f64,
    },
    /// A NIfTI label volume meshed voxel by voxel; each kept label becomes a region.
    Segmentation {
        /// A label volume, or binary masks (one per region, see `masks`).
        #[serde(default)]
        path: Option<PathBuf>,
        /// Labels of `path` to keep.
        #[serde(default)]
        labels: Vec<u32>,
        /// Binary masks on one grid, each becoming the region given.
        #[serde(default)]
        masks: Vec<MaskFile>,
        /// Coarsen the voxel grid by this integer factor before meshing (majority vote).
        #[serde(default)]
        coarsen: Option<usize>,
    },
}

fn one() -> f64 {
    1.0
}

/// One layer of a layered box.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerSpec {
    /// What the layer is (`skin`, `fat`...), for listings.
    #[serde(default)]
    pub name: String,
    /// Its thickness, in mm.
    pub thickness_mm: f64,
    /// The region id its tetrahedra get.
    pub region: u32,
}

/// A disc set into the top of a layered box.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InclusionSpec {
    /// What it is (`lesion`), for listings.
    #[serde(default)]
    pub name: String,
    /// Its centre on the top face, `[x, y]` in mm.
    pub centre_mm: [f64; 2],
    /// Its radius, in mm.
    pub radius_mm: f64,
    /// How far below the top it reaches, in mm.
    pub depth_mm: f64,
    /// The region id its tetrahedra get.
    pub region: u32,
}

/// An axis-aligned bar set into a layered box.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BarSpec {
    /// What it is (`rib 4`, `4th costal cartilage`), for listings.
    #[serde(default)]
    pub name: String,
    /// Its corner of least x, y and z, in mm (the block's top is z = 0).
    pub min_mm: [f64; 3],
    /// Its corner of greatest x, y and z, in mm.
    pub max_mm: [f64; 3],
    /// The region id its tetrahedra get.
    pub region: u32,
}

/// A binary mask file and the region id its voxels get.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaskFile {
    /// The NIfTI mask (non-zero voxels are in it).
    pub path: PathBuf,
    /// The region id its voxels get.
    pub region: u32,
}

/// A material for one region (the fields of [`Material`] plus the region id).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionMaterial {
    /// The region id of the mesh it applies to.
    pub region: u32,
    /// What the region is (`skin`, `fat`...), for listings.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub name: String,
    /// The colour the station shows the region's surface in (linear RGB, each 0 to 1);
    /// unset, the tissue's default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour_rgb: Option<[f64; 3]>,
    /// See [`Material::density_kg_per_m3`].
    pub density_kg_per_m3: f64,
    /// See [`Material::stiffness`].
    pub stiffness: crate::model::SpringStiffness,
    /// See [`Material::damping_newton_seconds_per_metre`].
    pub damping_newton_seconds_per_metre: f64,
    /// See [`Material::pretension`].
    pub pretension: f64,
    /// Finite-element parameters, used when the scene's `force_model` is `corotational-fem`
    /// (default: [`crate::fem::FemMaterial::CHEST_WALL`]).
    #[serde(default)]
    pub fem: Option<crate::fem::FemMaterial>,
    /// Whether a scalpel cuts it (default true): bone and cartilage are not, the blade stops
    /// on them ([`crate::model::Model::uncuttable_regions`]).
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub cuttable: bool,
    /// A structure to spare (default false): cutting it is damage (an artery, a nerve).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub spare: bool,
}

fn yes() -> bool {
    true
}

fn is_true(b: &bool) -> bool {
    *b
}

impl RegionMaterial {
    /// The spring material (without the region id and the finite-element parameters).
    pub fn material(&self) -> Material {
        Material {
            density_kg_per_m3: self.density_kg_per_m3,
            stiffness: self.stiffness,
            damping_newton_seconds_per_metre: self.damping_newton_seconds_per_metre,
            pretension: self.pretension,
        }
    }
}

/// A selection of vertices to hold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum HeldSelection {
    /// The rim: for generated slabs and sheets their lateral sides; for other meshes the
    /// boundary vertices within `width_mm` of the bounding-box faces across the two longest
    /// axes (default: 2 % of the bounding-box diagonal).
    Rim {
        /// How far from the bounding-box faces a vertex may be, in mm (see above).
        #[serde(default)]
        width_mm: Option<f64>,
    },
    /// Vertices within `width_mm` of the bounding-box faces across the given axes
    /// (`axes` is a subset of "xyz"), e.g. the two cut ends of a scanned slab.
    BoundingBoxFaces {
        /// The axes whose two faces hold vertices, letters of "xyz".
        axes: String,
        /// How far from those faces a vertex may be, in mm.
        width_mm: f64,
    },
    /// Vertices inside an axis-aligned box.
    Box {
        /// The box's minimum corner, in mm.
        min_mm: [f64; 3],
        /// The box's maximum corner, in mm.
        max_mm: [f64; 3],
    },
    /// All vertices of tetrahedra of a region.
    Region {
        /// The region id.
        region: u32,
    },
}

/// An ellipsoidal target behind the tissue (e.g. the heart).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// What the target is (shown in reports).
    pub name: String,
    /// The ellipsoid's centre, in mm.
    pub centre_mm: [f64; 3],
    /// Its semi-axes along x, y and z, in mm.
    pub radii_mm: [f64; 3],
    /// A structure to spare rather than expose (the lung beside the heart): never the
    /// target a field is measured on; the blade's tip inside it is critical harm.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub spare: bool,
}

fn default_cut_threshold_newtons() -> f64 {
    1.0
}

fn default_cut_depth_mm() -> f64 {
    4.0
}

fn default_blade_length_mm() -> f64 {
    20.0
}

/// How a default incision crosses the tissue: a straight line through the middle of the
/// body along `along`, on the surface facing `up` (out of the tissue, where the tool comes
/// from). Both are directions in the mesh's frame; they need not be unit vectors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IncisionDirections {
    /// Out of the tissue, towards where the tool comes from.
    pub up: [f64; 3],
    /// The direction the incision runs in.
    pub along: [f64; 3],
}

impl Default for IncisionDirections {
    /// Along x across the top (+z).
    fn default() -> Self {
        Self {
            up: [0.0, 0.0, 1.0],
            along: [1.0, 0.0, 0.0],
        }
    }
}

impl IncisionDirections {
    /// The unit directions `(up, along)`, `along` made perpendicular to `up`; an error when
    /// either is not finite, zero, or they are parallel.
    pub fn unit(&self) -> Result<(crate::Vector3, crate::Vector3), IncisionError> {
        let up = crate::Vector3::from(self.up);
        let along = crate::Vector3::from(self.along);
        let up = up
            .try_normalize(1e-12)
            .filter(|u| u.iter().all(|c| c.is_finite()))
            .ok_or(IncisionError::Up)?;
        let along = (along - up * along.dot(&up))
            .try_normalize(1e-9 * along.norm().max(1e-300))
            .filter(|a| a.iter().all(|c| c.is_finite()))
            .ok_or(IncisionError::Along)?;
        Ok((up, along))
    }
}

/// [`IncisionDirections`] that give no frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum IncisionError {
    /// `up` is zero or not finite.
    #[error("incision.up must be a finite, non-zero direction")]
    Up,
    /// `along` is not finite, or parallel to `up`.
    #[error("incision.along must be a finite direction not parallel to incision.up")]
    Along,
}

/// The planned viewpoint: an eye position looking at a point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Viewpoint {
    /// The eye's position, in mm.
    pub eye_mm: [f64; 3],
    /// The point it looks at, in mm.
    pub look_at_mm: [f64; 3],
}
