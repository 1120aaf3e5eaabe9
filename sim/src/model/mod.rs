//! The paper's particle model: particles at the mesh vertices with lumped masses, springs and
//! dampers along the tetrahedron edges, pre-tension by shortened rest lengths, held vertices
//! and gravity; optionally ([`Model::with_fem`]) co-rotational finite elements instead of the
//! springs (see [`crate::fem`]).

mod mass;
mod material;
mod springs;

pub use mass::{DONATED_SHARE, lumped_masses};
pub use material::{Material, MaterialError, SpringStiffness};
pub use springs::SpringSet;
pub(crate) use springs::sorted_by_first_end;

use crate::fem::{FemMaterial, FemMaterialError, FemModel};
use crate::{Point3, TetMesh, Vector3};
use mass::quarter_mass;

/// A problem with the model's set-up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A region's spring material is out of range.
    #[error("region {region}: {error}")]
    Material {
        /// The region id.
        region: u32,
        /// What is wrong with its material.
        error: MaterialError,
    },
    /// A region's finite-element material is out of range.
    #[error("region {region}: {error}")]
    FemMaterial {
        /// The region id.
        region: u32,
        /// What is wrong with its material.
        error: FemMaterialError,
    },
    /// A region (the id given) of the mesh has no spring material.
    #[error("no material for region {0}")]
    MissingMaterial(u32),
    /// A region (the id given) of the mesh has no finite-element material.
    #[error("no finite-element material for region {0}")]
    MissingFemMaterial(u32),
    /// A held vertex is past the end of the mesh's vertices.
    #[error("held vertex {vertex} is out of range (mesh has {vertex_count} vertices)")]
    HeldOutOfRange {
        /// The vertex.
        vertex: u32,
        /// How many vertices the mesh has.
        vertex_count: usize,
    },
    /// The gravity vector has a non-finite component.
    #[error("gravity must be finite")]
    NonFiniteGravity,
    /// A free vertex has no mass: no tetrahedron of positive volume uses it.
    #[error("vertex {vertex} has zero mass (it belongs to no tetrahedron of positive volume)")]
    ZeroMass {
        /// The vertex.
        vertex: u32,
    },
}

/// The particle model (everything but the changing state).
#[derive(Debug, Clone)]
pub struct Model {
    /// The mesh in its reference (initial, unstressed-geometry) configuration.
    pub mesh: TetMesh,
    /// Materials by region id, sorted by id.
    pub materials: Vec<(u32, Material)>,
    /// The paper's lumped mass `l_i = sum over tets k around i of rho_k V_k / 4`, in kg.
    pub lumped_mass: Vec<f64>,
    /// The mass `m_i` the solvers use, in kg: `l_i`, except where a cut left particles below
    /// [`Self::mass_floor_kg`], which receive mass from their neighbours (see
    /// the `model::mass` module; the total is conserved).
    pub mass: Vec<f64>,
    /// The lightest particle of the uncut mesh, in kg: what the regularisation lifts the
    /// particles created by cuts towards.
    pub mass_floor_kg: f64,
    /// `1 / m_i` for free vertices, 0 for held ones.
    pub inv_mass: Vec<f64>,
    /// Vertices held at their position.
    pub held: Vec<bool>,
    /// The springs and dampers on the mesh edges.
    pub springs: SpringSet,
    /// Gravitational acceleration in m/s^2 (zero when gravity is off).
    pub gravity: Vector3,
    /// The co-rotational finite elements, when the model uses them instead of the springs
    /// (see [`Model::with_fem`]); the springs are still derived (for the cutter's events), but
    /// the solvers then ignore them.
    pub fem: Option<FemModel>,
    /// The regions a scalpel does not cut (bone, cartilage), ascending: a [`crate::cut::Cutter`]
    /// stops the blade where it meets one of their tetrahedra.
    pub uncuttable_regions: Vec<u32>,
    /// The regions to spare (an artery beside the incision), ascending: cutting one of their
    /// tetrahedra is damage ([`Self::spare`]).
    pub spare_regions: Vec<u32>,
}

/// Whether `region` is in the ascending list `regions`.
fn in_regions(regions: &[u32], region: u32) -> bool {
    !regions.is_empty() && regions.binary_search(&region).is_ok()
}

/// What the spring solvers read of a model: lumped masses, held flags, springs and gravity.
/// [`Model::particles`] lends the whole body; the localised step
/// ([`crate::solver::localise`]) builds one of the active region, with its sleeping border
/// held.
#[derive(Debug, Clone, Copy)]
pub struct Particles<'a> {
    /// The mass of each particle in kg.
    pub mass: &'a [f64],
    /// Whether each particle is held at its position.
    pub held: &'a [bool],
    /// The springs between the particles.
    pub springs: &'a SpringSet,
    /// Gravitational acceleration in m/s^2.
    pub gravity: Vector3,
}

impl Particles<'_> {
    /// The number of particles.
    pub fn vertex_count(&self) -> usize {
        self.mass.len()
    }
}

/// Which force model a [`Model`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForceModel {
    /// The paper's springs and dampers on the edges.
    Springs,
    /// Co-rotational linear tetrahedral finite elements.
    CorotationalFem,
}

/// Positions (m) and velocities (m/s) of the particles.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct State {
    /// The position of each particle in m.
    pub positions: Vec<Point3>,
    /// The velocity of each particle in m/s.
    pub velocities: Vec<Vector3>,
}

impl State {
    /// At rest in the mesh's reference positions.
    pub fn at_rest(mesh: &TetMesh) -> Self {
        Self {
            positions: mesh.positions().to_vec(),
            velocities: vec![Vector3::zeros(); mesh.vertex_count()],
        }
    }

    /// Largest particle speed in m/s.
    pub fn max_speed(&self) -> f64 {
        self.velocities.iter().map(|v| v.norm()).fold(0.0, f64::max)
    }

    /// True when every position and velocity is finite.
    pub fn is_finite(&self) -> bool {
        self.positions
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite()))
            && self
                .velocities
                .iter()
                .all(|v| v.iter().all(|c| c.is_finite()))
    }

    /// The particles whose position or velocity is not finite, ascending.
    pub fn non_finite_particles(&self) -> Vec<u32> {
        let finite = |c: &[f64]| c.iter().all(|c| c.is_finite());
        (0..self.positions.len())
            .filter(|&i| {
                !(finite(self.positions[i].coords.as_slice())
                    && finite(self.velocities[i].as_slice()))
            })
            .map(|i| i as u32)
            .collect()
    }

    /// A hash of the exact bits of every position and velocity (FNV-1a, 64 bit): equal states
    /// give equal hashes on every platform.
    pub fn bit_hash(&self) -> u64 {
        let mut h = crate::hash::Fnv1a::default();
        let coords = self
            .positions
            .iter()
            .flat_map(|p| p.coords.iter())
            .chain(self.velocities.iter().flat_map(|v| v.iter()));
        coords.for_each(|&c| h.f64(c));
        h.finish()
    }
}

impl Model {
    /// Builds the model: materials per region (`materials`, any order), held vertices, gravity.
    pub fn new(
        mesh: TetMesh,
        materials: &[(u32, Material)],
        held_vertices: &[u32],
        gravity: Vector3,
    ) -> Result<Self, ModelError> {
        let mut materials = materials.to_vec();
        materials.sort_by_key(|(id, _)| *id);
        materials.dedup_by_key(|(id, _)| *id);
        for (region, m) in &materials {
            m.check().map_err(|error| ModelError::Material {
                region: *region,
                error,
            })?;
        }
        if !gravity.iter().all(|g| g.is_finite()) {
            return Err(ModelError::NonFiniteGravity);
        }
        let n = mesh.vertex_count();
        let mut held = vec![false; n];
        for &v in held_vertices {
            *held.get_mut(v as usize).ok_or(ModelError::HeldOutOfRange {
                vertex: v,
                vertex_count: n,
            })? = true;
        }
        let material_of_tet = material_of_tets(&materials, &mesh)?;
        let lumped = lumped_masses(&mesh, &material_of_tet);
        let floor = lumped.iter().copied().fold(f64::INFINITY, f64::min);
        let d = derive(&material_of_tet, &mesh, &held, lumped, floor)?;
        let Derived {
            lumped,
            mass,
            inv_mass,
            springs,
        } = d;
        Ok(Self {
            mesh,
            materials,
            lumped_mass: lumped,
            mass,
            mass_floor_kg: floor,
            inv_mass,
            held,
            springs,
            gravity,
            fem: None,
            uncuttable_regions: Vec::new(),
            spare_regions: Vec::new(),
        })
    }

    /// The model with `regions` uncuttable (see [`Self::uncuttable_regions`]).
    pub fn with_uncuttable_regions(mut self, regions: &[u32]) -> Self {
        self.uncuttable_regions = regions.to_vec();
        self.uncuttable_regions.sort_unstable();
        self.uncuttable_regions.dedup();
        self
    }

    /// The model with `regions` to spare (see [`Self::spare_regions`]).
    pub fn with_spare_regions(mut self, regions: &[u32]) -> Self {
        self.spare_regions = regions.to_vec();
        self.spare_regions.sort_unstable();
        self.spare_regions.dedup();
        self
    }

    /// Whether tetrahedron `t` is of an uncuttable region.
    pub fn uncuttable(&self, t: usize) -> bool {
        in_regions(&self.uncuttable_regions, self.mesh.regions()[t])
    }

    /// Whether region `region` is to be spared.
    pub fn spare(&self, region: u32) -> bool {
        in_regions(&self.spare_regions, region)
    }

    /// Switches the model to co-rotational finite elements with the given materials per region
    /// (any order); density and pre-tension stay those of [`Self::materials`].
    pub fn with_fem(mut self, fem_materials: &[(u32, FemMaterial)]) -> Result<Self, ModelError> {
        let mut fem_materials = fem_materials.to_vec();
        fem_materials.sort_by_key(|(id, _)| *id);
        fem_materials.dedup_by_key(|(id, _)| *id);
        self.fem = Some(FemModel::build(
            &self.mesh,
            &self.materials,
            &fem_materials,
        )?);
        Ok(self)
    }

    /// The force model the solvers run.
    pub fn force_model(&self) -> ForceModel {
        if self.fem.is_some() {
            ForceModel::CorotationalFem
        } else {
            ForceModel::Springs
        }
    }

    /// The number of particles (the mesh's vertices).
    pub fn vertex_count(&self) -> usize {
        self.mass.len()
    }

    /// What the spring solvers read of the whole body.
    pub fn particles(&self) -> Particles<'_> {
        Particles {
            mass: &self.mass,
            held: &self.held,
            springs: &self.springs,
            gravity: self.gravity,
        }
    }

    /// Replaces the mesh after a topology change (a cut): masses, springs and held flags are
    /// rebuilt by the same rules as at the start (`l = sum rho V / 4` and its regularisation
    /// with the floor of the uncut mesh, rest lengths `d (1 - s)` with `d` from the reference
    /// positions).
    /// With finite elements, the elements are rebuilt too: new tetrahedra get their rest shapes
    /// by the same pre-strain rule (`D_m = (1 - s) D_ref`).
    pub fn rebuild(&mut self, mesh: TetMesh, held: Vec<bool>) -> Result<(), ModelError> {
        let material_of_tet = material_of_tets(&self.materials, &mesh)?;
        let lumped = lumped_masses(&mesh, &material_of_tet);
        let d = derive(&material_of_tet, &mesh, &held, lumped, self.mass_floor_kg)?;
        if let Some(fem) = &mut self.fem {
            *fem = FemModel::build(&mesh, &self.materials, &fem.materials)?;
        }
        self.install(mesh, held, d);
        Ok(())
    }

    /// [`Self::rebuild`] after a local change (a cut), by the same rules and with the same
    /// bits, recomputing only what the change reached: `dirty` lists (ascending) the tets of
    /// `mesh` whose vertices or reference geometry changed or that are new (ids past the old
    /// tet count), and `changed` those of them that existed before with other vertices. The
    /// lumped masses of the vertices of those tets (before and after), the masses of these
    /// vertices and their neighbours, and the springs on their edges are derived again;
    /// everything else is carried over. Finite elements are rebuilt whole.
    pub fn rebuild_local(
        &mut self,
        mesh: TetMesh,
        held: Vec<bool>,
        dirty: &[u32],
        changed: &[u32],
    ) -> Result<(), ModelError> {
        // (finite elements, or held flags not one per vertex: the whole rebuild, which checks)
        if self.fem.is_some() || held.len() != mesh.vertex_count() {
            return self.rebuild(mesh, held);
        }
        let old_mesh = &self.mesh;
        let material = |t: usize| material_of_region(&self.materials, mesh.regions()[t]);
        let topo = mesh.topology();
        let n = mesh.vertex_count();

        // lumped masses: l_i summed over the tets around i in ascending order, as
        // lumped_masses does
        let mut touched: Vec<u32> = dirty
            .iter()
            .flat_map(|&t| mesh.tets()[t as usize])
            .collect();
        touched.extend(
            changed
                .iter()
                .filter_map(|&t| old_mesh.tets().get(t as usize))
                .flatten(),
        );
        touched.sort_unstable();
        touched.dedup();
        let mut lumped = self.lumped_mass.clone();
        lumped.resize(n, 0.0);
        for &v in &touched {
            let mut m = 0.0;
            for &t in topo.vertex_tets.row(v as usize) {
                m += quarter_mass(&mesh, t as usize, &material(t as usize)?);
            }
            if !(m > 0.0) {
                return Err(ModelError::ZeroMass { vertex: v });
            }
            lumped[v as usize] = m;
        }
        // masses: a particle's depends on its neighbours' lumped masses and degrees, so those
        // of the touched particles and their neighbours are derived again
        let mut scratch = mass::MassScratch::default();
        let mut reached = touched.clone();
        let mut ring = Vec::new();
        for &v in &touched {
            mass::neighbours(&mesh, v, &mut ring);
            reached.extend_from_slice(&ring);
        }
        reached.sort_unstable();
        reached.dedup();
        let mut mass = self.mass.clone();
        mass.resize(n, 0.0);
        for &v in &reached {
            mass[v as usize] =
                mass::regularised_mass(&mesh, &lumped, self.mass_floor_kg, v, &mut scratch);
        }
        let mut inv_mass = self.inv_mass.clone();
        inv_mass.resize(n, 0.0);
        // derived again where the mass or the held flag may have changed, and for new particles
        let old_n = self.held.len().min(n);
        let held_changed = (0..old_n).filter(|&v| held[v] != self.held[v]);
        for v in reached
            .iter()
            .map(|&v| v as usize)
            .chain(held_changed)
            .chain(old_n..n)
        {
            inv_mass[v] = if held[v] { 0.0 } else { 1.0 / mass[v] };
        }

        // springs: derived again on the edges of the dirty tets and on the old edges that lost
        // a changed tet; between them the old and new edges are the same run (an edge only
        // appears with a dirty tet and only disappears with its last changed one), copied whole
        let mut dirty_edges: Vec<u32> = dirty
            .iter()
            .flat_map(|&t| topo.tet_edge_ids(&mesh.tets()[t as usize]))
            .collect();
        dirty_edges.sort_unstable();
        dirty_edges.dedup();
        let (old, old_topo) = (&self.springs, old_mesh.topology());
        let mut lost: Vec<u32> = if old.ends == old_topo.edges {
            changed
                .iter()
                .filter_map(|&t| old_mesh.tets().get(t as usize))
                .flat_map(|tet| old_topo.tet_edge_ids(tet))
                .collect()
        } else {
            (0..old.len() as u32).collect() // springs not of these edges: every one derived again
        };
        lost.sort_unstable();
        lost.dedup();
        let mut springs = SpringSet::with_capacity(topo.edges.len());
        let (mut next_dirty, mut next_lost) =
            (dirty_edges.iter().peekable(), lost.iter().peekable());
        let (mut e, mut j) = (0, 0);
        while e < topo.edges.len() {
            while next_dirty.next_if(|&&d| (d as usize) < e).is_some() {}
            while next_lost.next_if(|&&l| (l as usize) < j).is_some() {}
            let run = (next_dirty.peek().map_or(topo.edges.len(), |&&d| d as usize) - e)
                .min(next_lost.peek().map_or(old.len(), |&&l| l as usize) - j);
            if run > 0 && topo.edges[e..e + run] == old.ends[j..j + run] {
                springs.extend_from(old, j..j + run);
                (e, j) = (e + run, j + run);
                continue;
            }
            let ends = topo.edges[e];
            while j < old.len() && old.ends[j] < ends {
                j += 1;
            }
            let old_match = (j < old.len() && old.ends[j] == ends).then_some(j);
            let dirty_edge = dirty_edges.binary_search(&(e as u32)).is_ok();
            match old_match {
                Some(m) if !dirty_edge && lost.binary_search(&(m as u32)).is_err() => {
                    springs.extend_from(old, m..m + 1);
                }
                _ => {
                    // (every tet's material was found above, with the masses: the default
                    // is never used)
                    let params = SpringSet::edge_parameters(&mesh, e, &|t| {
                        material(t).unwrap_or(Material::PAPER_CHEST_WALL)
                    });
                    springs.push(ends, params);
                }
            }
            j += usize::from(old_match.is_some());
            e += 1;
        }
        self.install(
            mesh,
            held,
            Derived {
                lumped,
                mass,
                inv_mass,
                springs,
            },
        );
        Ok(())
    }

    fn install(&mut self, mesh: TetMesh, held: Vec<bool>, d: Derived) {
        self.lumped_mass = d.lumped;
        self.mass = d.mass;
        self.inv_mass = d.inv_mass;
        self.springs = d.springs;
        self.held = held;
        self.mesh = mesh;
    }

    /// The tissue's mass in kg, `sum l_i` (the lumped masses, `rho V` summed; the solvers'
    /// masses add to this what chips cut free were lifted by).
    pub fn total_mass(&self) -> f64 {
        self.lumped_mass.iter().sum()
    }

    /// Number of held vertices.
    pub fn held_count(&self) -> usize {
        self.held.iter().filter(|&&h| h).count()
    }

    /// The median of the springs' rest lengths (the mesh's edges), m: the upper middle of an
    /// even count (`stats::percentile(sorted, 0.5)`, by selection); `None` without springs.
    pub fn median_edge_length(&self) -> Option<f64> {
        let mut lengths = self.springs.rest_length.clone();
        let mid = lengths.len() / 2;
        (!lengths.is_empty()).then(|| *lengths.select_nth_unstable_by(mid, f64::total_cmp).1)
    }
}

/// The material of `region` in `materials` (sorted by region id).
fn material_of_region(materials: &[(u32, Material)], region: u32) -> Result<Material, ModelError> {
    materials
        .binary_search_by_key(&region, |(id, _)| *id)
        .map(|i| materials[i].1)
        .map_err(|_| ModelError::MissingMaterial(region))
}

/// Material of each tetrahedron from `materials` (sorted by region id).
fn material_of_tets(
    materials: &[(u32, Material)],
    mesh: &TetMesh,
) -> Result<Vec<Material>, ModelError> {
    mesh.regions()
        .iter()
        .map(|&r| material_of_region(materials, r))
        .collect()
}

/// What the model derives from mesh, materials and held flags.
struct Derived {
    lumped: Vec<f64>,
    mass: Vec<f64>,
    /// Zero where held.
    inv_mass: Vec<f64>,
    springs: SpringSet,
}

/// The masses (from the lumped masses `lumped` and the floor), inverse masses and springs.
fn derive(
    material_of_tet: &[Material],
    mesh: &TetMesh,
    held: &[bool],
    lumped: Vec<f64>,
    floor_kg: f64,
) -> Result<Derived, ModelError> {
    if let Some(v) = lumped.iter().position(|&m| !(m > 0.0)) {
        return Err(ModelError::ZeroMass { vertex: v as u32 });
    }
    let mass = mass::regularised_masses(mesh, &lumped, floor_kg);
    let inv_mass = mass
        .iter()
        .zip(held)
        .map(|(&m, &h)| if h { 0.0 } else { 1.0 / m })
        .collect();
    Ok(Derived {
        lumped,
        mass,
        inv_mass,
        springs: SpringSet::from_mesh(mesh, material_of_tet),
    })
}
