//! Volumetric cutting after Nakao et al.: the blade sweeps a partial clipping surface C
//! between two poses; edges crossing C get new vertices, incompletely intersected tetrahedra
//! are resolved by vertex movement, crossed tetrahedra are split minimally (4 or 6 children)
//! with the split pattern that minimises `mu = max dihedral / min dihedral`, vertices on the
//! cut surface are split into one copy per side, and masses and springs are rebuilt by the
//! model's rules (`m = sum rho V / 4`, `l = d (1 - s)`), so the pre-tension opens the wound.
//!
//! A cut is a transaction: on error the simulation is unchanged.

mod cutter;
mod event;
mod fragment;
mod pattern;
mod polygon;
mod resolve;
mod separate;
mod specimen;

use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};

pub use cutter::{Cutter, CutterResume, CutterResumeError};
pub use event::{CreatedVertex, CutEvent, MovedVertex, SplitVertex};
pub use pattern::{Children, Quad, QuadKey, TetSplit, prism};
pub use polygon::{Blade, CutPolygon};
pub use specimen::Specimen;

use crate::mesh::{
    PARALLEL_MIN_TETS, TET_EDGES, TET_FACES, TetMesh, dihedral_angles, edge_key, sorted_pair,
    sorted_triple, tet_signed_volume,
};
use crate::model::ModelError;
use crate::solver::Simulation;
use crate::{MeshError, Point3, Vector3};

/// How split patterns are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PatternChoice {
    /// The paper's adaptive scheme: among the admissible patterns (conforming with the
    /// neighbours, no cyclic prism, positive children), the one with the smallest mu.
    #[default]
    MinMu,
    /// A fixed rule: every quadrilateral's diagonal runs through its smallest vertex id.
    MinVertexId,
}

/// Settings of the cutter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutOptions {
    /// How the diagonals of the quadrilaterals a cut makes are chosen.
    pub pattern: PatternChoice,
    /// Crossing parameters closer than this to an end move that vertex onto the plane.
    pub snap: f64,
    /// Vertices closer than this to the plane (m) move onto it too, and vertices of the
    /// stroke's cut this close count as on it, however short their edges: a floor under the
    /// relative `snap`, so that a blade that trembles across cut tissue does not slice it into
    /// ever thinner slivers. `None`: a [`Cutter`] derives it from the mesh it first cuts
    /// (`snap` times the median edge length) and keeps it here; [`cut`] uses the relative
    /// rule only.
    pub snap_distance_m: Option<f64>,
    /// A free piece (no held vertex) smaller than this (m^3) that a step's cut would carve
    /// out is a numerical fragment, not a specimen: the step leaves the faces around it
    /// uncut (see the `fragment` module). 0: every piece is kept as cut.
    pub fragment_volume_m3: f64,
}

/// The default [`CutOptions::fragment_volume_m3`]: 30 mm^3, a cube of about 3 mm. The slivers
/// turning strokes carved measured up to 18 mm^3; a specimen an exercise asks for (a 10 mm disc
/// of a 2 mm sheet) is 150 mm^3 and more.
pub const FRAGMENT_VOLUME_M3: f64 = 3e-8;

impl Default for CutOptions {
    fn default() -> Self {
        Self {
            pattern: PatternChoice::MinMu,
            snap: 0.15,
            snap_distance_m: None,
            fragment_volume_m3: FRAGMENT_VOLUME_M3,
        }
    }
}

/// A cut that could not be applied (the simulation is unchanged).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CutError {
    /// The blade's pose has a non-finite number or a depth that is not positive.
    #[error("the blade pose is not finite")]
    NonFiniteBlade,
    /// The step's cut could not be resolved; nothing changed, and the next step (whose
    /// trailing window covers the same place) tries again.
    #[error("cut left tetrahedron {0} incompletely intersected; step skipped")]
    Unresolved(u32),
    /// The cut mesh failed validation (a bug in the cutter; nothing changed).
    #[error("cut produced an invalid mesh: {0}")]
    Mesh(#[from] MeshError),
    /// The model could not be rebuilt on the cut mesh (nothing changed).
    #[error("cut produced an invalid model: {0}")]
    Model(#[from] ModelError),
}

/// Tetrahedra whose bounds meet the polygon's (inflated by `margin`) and that touch or cross
/// its plane, or come within `near` times their longest edge of it (where vertices of the
/// stroke's cut that drifted off the plane still count as on it). The two halves of a large
/// mesh are scanned side by side.
fn candidates(
    mesh_tets: &[[u32; 4]],
    x: &[Point3],
    polygon: &CutPolygon,
    margin: f64,
    near: f64,
) -> Vec<u32> {
    // A tet's bounds miss the polygon's inflated bounds exactly when all four of its vertices
    // lie beyond the same side of them (the tet's least coordinate above the box's greatest,
    // or its greatest below the box's least): each vertex's sides, one bit each, are found
    // once, and a tet is passed over when its vertices' bits share one.
    let (lo, hi) = polygon.bounds();
    let beyond: Vec<u8> = x
        .iter()
        .map(|q| {
            (0..3).fold(0u8, |m, k| {
                m | (u8::from(q[k] > hi[k] + margin) << k)
                    | (u8::from(q[k] < lo[k] - margin) << (k + 3))
            })
        })
        .collect();
    let (count, half) = (mesh_tets.len(), mesh_tets.len() / 2);
    let (mut first, second) = crate::parallel::join(
        count >= PARALLEL_MIN_TETS,
        || candidates_in(mesh_tets, 0..half, x, &beyond, polygon, margin, near),
        || candidates_in(mesh_tets, half..count, x, &beyond, polygon, margin, near),
    );
    first.extend(second);
    first
}

/// [`candidates`] among the tets `range`, `beyond` the sides of the bounds each vertex lies
/// beyond.
fn candidates_in(
    mesh_tets: &[[u32; 4]],
    range: std::ops::Range<usize>,
    x: &[Point3],
    beyond: &[u8],
    polygon: &CutPolygon,
    margin: f64,
    near: f64,
) -> Vec<u32> {
    let mut out = Vec::new();
    for (t, tet) in mesh_tets
        .iter()
        .enumerate()
        .skip(range.start)
        .take(range.len())
    {
        if tet.iter().fold(u8::MAX, |m, &v| m & beyond[v as usize]) != 0 {
            continue;
        }
        let p = tet.map(|v| x[v as usize]);
        let s = p.map(|q| polygon.signed_distance(&q));
        let (smin, smax) = s
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let reach = if near > 0.0 {
            let longest = TET_EDGES
                .iter()
                .map(|&[i, j]| (p[i] - p[j]).norm_squared())
                .fold(0.0, f64::max)
                .sqrt();
            margin.max(near * longest)
        } else {
            margin
        };
        if smin <= reach && smax >= -reach {
            out.push(t as u32);
        }
    }
    out
}

/// The vertices of a stroke's cut: those moved onto the cut plane, those of the cut faces and
/// the copies of the split ones. The [`Cutter`] keeps them for one stroke, so that, drifting a
/// little across the plane as the wound opens, they are not cut again when the trailing window
/// passes over them.
#[derive(Debug, Clone, Default)]
pub struct StrokeVertices {
    member: Vec<bool>,
}

impl StrokeVertices {
    /// True when `v` belongs to the stroke's cut.
    pub fn contains(&self, v: u32) -> bool {
        self.member.get(v as usize).copied().unwrap_or(false)
    }

    fn insert(&mut self, v: u32) {
        let i = v as usize;
        if self.member.len() <= i {
            self.member.resize(i + 1, false);
        }
        self.member[i] = true;
    }

    /// True before the stroke has cut anything.
    pub fn is_empty(&self) -> bool {
        self.member.is_empty()
    }

    /// Forgets every vertex (a new stroke).
    pub fn clear(&mut self) {
        self.member.clear();
    }

    /// The members, ascending.
    pub fn members(&self) -> Vec<u32> {
        self.member
            .iter()
            .enumerate()
            .filter(|(_, m)| **m)
            .map(|(v, _)| v as u32)
            .collect()
    }

    /// The stroke whose members are `vertices`.
    pub fn from_members(vertices: &[u32]) -> Self {
        let mut me = Self::default();
        vertices.iter().for_each(|&v| me.insert(v));
        me
    }
}

/// Cuts the simulation's tissue along a planar polygon C.
///
/// A square blade path through the middle of a held 1 cm cube, from its top face to half its
/// depth:
///
/// ```
/// use cutlab_sim::cut::{CutOptions, CutPolygon, cut};
/// use cutlab_sim::generate::{GridCells, boxed};
/// use cutlab_sim::model::{Material, Model};
/// use cutlab_sim::solver::{Simulation, SolverSettings};
/// use cutlab_sim::{Point3, Vector3};
///
/// let cube = boxed(Point3::origin(), [0.01; 3], GridCells { nx: 3, ny: 3, nz: 3 })?.mesh;
/// let bottom: Vec<u32> = (0..cube.vertex_count() as u32)
///     .filter(|&v| cube.positions()[v as usize].z == 0.0)
///     .collect();
/// let model = Model::new(cube, &[(0, Material::default())], &bottom, Vector3::zeros())?;
/// let mut sim = Simulation::new(model, SolverSettings::default());
/// let tets_before = sim.model.mesh.tet_count();
/// // the plane y = 4.5 mm, from above the top (z = 12 mm) down to z = 5 mm
/// let polygon = CutPolygon::new(&[
///     Point3::new(-0.001, 0.0045, 0.012),
///     Point3::new(0.011, 0.0045, 0.012),
///     Point3::new(0.011, 0.0045, 0.005),
///     Point3::new(-0.001, 0.0045, 0.005),
/// ])
/// .expect("a planar polygon");
/// let event = cut(&mut sim, &polygon, &CutOptions::default())?;
/// assert!(!event.is_empty());
/// assert!(sim.model.mesh.tet_count() > tets_before);
/// sim.step()?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn cut(
    sim: &mut Simulation,
    polygon: &CutPolygon,
    options: &CutOptions,
) -> Result<CutEvent, CutError> {
    cut_remembering(
        sim,
        polygon,
        options,
        &mut StrokeVertices::default(),
        Vector3::zeros(),
    )
}

/// [`cut`] as one step of a stroke: vertices of the stroke's cut (`stroke`) that drifted a
/// little off the plane count as on it, and `stroke` learns this step's cut vertices. A piece
/// the cut frees is moved by `lift_m` and held there (a [`Specimen`]; [`cut`] leaves it where
/// it is).
pub fn cut_remembering(
    sim: &mut Simulation,
    polygon: &CutPolygon,
    options: &CutOptions,
    stroke: &mut StrokeVertices,
    lift_m: Vector3,
) -> Result<CutEvent, CutError> {
    let mesh = &sim.model.mesh;
    let n = mesh.vertex_count();
    let margin = 1e-9 * polygon.scale;
    let near = if stroke.is_empty() {
        0.0
    } else {
        resolve::near_fraction(options.snap)
    };
    let cand = candidates(mesh.tets(), &sim.state.positions, polygon, margin, near);
    let mut event = CutEvent::default();
    if cand.is_empty() {
        return Ok(event);
    }

    // Working copies: the simulation changes only when everything succeeded.
    let mut x = sim.state.positions.clone();
    let mut x_ref = mesh.positions().to_vec();
    let mut vel = sim.state.velocities.clone();
    let mut held = sim.model.held.clone();
    // Resolve; every tetrahedron around a split edge must take part (a forced split can
    // reach beyond the first candidates), so widen the set and resolve again until it does.
    let mut cand = cand;
    let mut moved_all = Vec::new();
    let mut forced_all = 0;
    let class = loop {
        let class = resolve::Resolver {
            mesh,
            x: &mut x,
            x_ref: &mut x_ref,
            held: &held,
            plane: polygon,
            candidates: &cand,
            snap: options.snap,
            snap_distance_m: options.snap_distance_m.unwrap_or(0.0),
            inside_tolerance: 1e-9 * polygon.scale,
            stroke,
        }
        .resolve();
        moved_all.extend_from_slice(&class.moved);
        forced_all += class.forced;
        let topo = mesh.topology();
        let mut extra: BTreeSet<u32> = BTreeSet::new();
        for cr in class.crossings.values().filter(|c| c.split) {
            extra.extend(
                topo.tets_of_edge(cr.edge)
                    .filter(|t| cand.binary_search(t).is_err()),
            );
        }
        if extra.is_empty() {
            break class;
        }
        cand.extend(extra);
        cand.sort_unstable();
    };
    let class = resolve::Classification {
        moved: moved_all,
        forced: forced_all,
        ..class
    };
    event.forced_splits = class.forced;
    for &(id, from, to) in &class.moved {
        event.vertices_moved.push(MovedVertex {
            id,
            from: from.coords.into(),
            to: to.coords.into(),
        });
    }

    // New vertices on split edges.
    let mut split_id: BTreeMap<[u32; 2], u32> = BTreeMap::new();
    for cr in class.crossings.values().filter(|c| c.split) {
        let id = (n + split_id.len()) as u32;
        let [a, b] = cr.edge.map(|v| v as usize);
        x.push(x[a] + (x[b] - x[a]) * cr.t);
        x_ref.push(x_ref[a] + (x_ref[b] - x_ref[a]) * cr.t);
        vel.push(vel[a] + (vel[b] - vel[a]) * cr.t);
        held.push(false);
        split_id.insert(cr.edge, id);
        event.vertices_created.push(CreatedVertex {
            id,
            edge: cr.edge,
            t: cr.t,
        });
    }

    // Tetrahedra to split, and faces lying in the plane inside C.
    let mut splits: Vec<(u32, TetSplit)> = Vec::new();
    let mut cut_faces: BTreeSet<[u32; 3]> = BTreeSet::new();
    for &t in &cand {
        let verts = mesh.tets()[t as usize];
        let signs = verts.map(|v| class.sign[&v]);
        let mut split = [crate::mesh::NONE; 6];
        let (mut crossing, mut split_count) = (0, 0);
        for (e, &[i, j]) in TET_EDGES.iter().enumerate() {
            let key = edge_key(&verts, [i, j]);
            if let Some(cr) = class.crossings.get(&key) {
                crossing += 1;
                if cr.split {
                    split_count += 1;
                    split[e] = split_id[&key];
                }
            }
        }
        if split_count > 0 {
            if split_count != crossing {
                return Err(CutError::Unresolved(t));
            }
            splits.push((
                t,
                TetSplit {
                    verts,
                    signs,
                    split,
                },
            ));
        } else if signs.iter().filter(|&&s| s == 0).count() == 3 {
            let face: Vec<u32> = (0..4)
                .filter(|&l| signs[l] == 0)
                .map(|l| verts[l])
                .collect();
            let c = Point3::from(
                (x[face[0] as usize].coords
                    + x[face[1] as usize].coords
                    + x[face[2] as usize].coords)
                    / 3.0,
            );
            if polygon.contains_projection(&c, 1e-9 * polygon.scale) {
                cut_faces.insert(sorted_triple([face[0], face[1], face[2]]));
            }
        }
    }

    // Children with conforming diagonals.
    let children = match options.pattern {
        PatternChoice::MinMu => {
            choose_min_mu(&splits, &x, &x_ref).or_else(|| choose_fixed(&splits, &x_ref))
        }
        PatternChoice::MinVertexId => choose_fixed(&splits, &x_ref),
    };
    let Some(children) = children else {
        return Err(CutError::Unresolved(
            splits.first().map(|s| s.0).unwrap_or(0),
        ));
    };

    // (copied only when a tet is split: most steps of a stroke change no tet)
    let mut tets = Cow::Borrowed(mesh.tets());
    let mut regions = Cow::Borrowed(mesh.regions());
    for ((t, _), ch) in splits.iter().zip(&children) {
        let parent_volume = mesh.tet_volume(*t as usize);
        for (k, c) in ch.tets.iter().enumerate() {
            let [a, b, cc, d] = c.map(|v| x_ref[v as usize]);
            event.min_child_volume_fraction = event
                .min_child_volume_fraction
                .min(tet_signed_volume(&a, &b, &cc, &d) / parent_volume);
            let id = if k == 0 {
                tets.to_mut()[*t as usize] = *c;
                *t
            } else {
                tets.to_mut().push(*c);
                let region = regions[*t as usize];
                regions.to_mut().push(region);
                (tets.len() - 1) as u32
            };
            event.tets_added.push((id, *c));
        }
        event.tets_removed.push(*t);
        cut_faces.extend(ch.section.iter().copied());
    }

    // Separate the two sides: split vertices of the cut surface by star components. A cut
    // face that would only pinch the surface (an edge of it on the outer surface whose ends
    // both stay whole) is given up, and the split redone.
    let old_tet_count = mesh.tet_count();
    let topo = mesh.topology();
    let star_of = |tets: &[[u32; 4]], on_cut: &BTreeSet<u32>| -> separate::Stars {
        let mut stars: separate::Stars = BTreeMap::new();
        for &v in on_cut {
            let star = stars.entry(v).or_default();
            if (v as usize) < n {
                star.extend(
                    topo.vertex_tets
                        .row(v as usize)
                        .iter()
                        .filter(|&&t| tets[t as usize].contains(&v)),
                );
            }
        }
        for (id, c) in &event.tets_added {
            if (*id as usize) >= old_tet_count || !mesh.tets()[*id as usize].eq(c) {
                for v in c {
                    if let Some(star) = stars.get_mut(v) {
                        star.push(*id);
                    }
                }
            }
        }
        for star in stars.values_mut() {
            star.sort_unstable();
            star.dedup();
        }
        stars
    };
    let base_vertices = x.len();
    let mut splits = Vec::new();
    let mut relinked = BTreeSet::new();
    // the relinked tets as they were, to undo a round
    let mut undo: Vec<(u32, [u32; 4])> = Vec::new();
    let mut on_cut = BTreeSet::new();
    for _ in 0..64 {
        on_cut = cut_faces.iter().flatten().copied().collect();
        let stars = star_of(&tets, &on_cut);
        splits = separate::star_components(&tets, &stars, &cut_faces);
        relinked.clear();
        undo.clear();
        let mut original_of: Vec<u32> = Vec::with_capacity(splits.len());
        for (k, (v, moved_tets)) in splits.iter().enumerate() {
            let copy = (base_vertices + k) as u32;
            original_of.push(*v);
            for &t in moved_tets {
                let tet = &mut tets.to_mut()[t as usize];
                if relinked.insert(t) {
                    undo.push((t, *tet));
                }
                for w in tet {
                    if *w == *v {
                        *w = copy;
                    }
                }
            }
        }
        let original = |v: u32| {
            if (v as usize) < base_vertices {
                v
            } else {
                original_of[v as usize - base_vertices]
            }
        };
        let local: BTreeSet<u32> = stars.values().flatten().copied().collect();
        let pinched = separate::pinched_edges(&tets, &local, &|v| on_cut.contains(&original(v)));
        let before = cut_faces.len();
        let kept: BTreeSet<[u32; 3]> = if pinched.is_empty() {
            let seeds: Vec<u32> = local.iter().copied().collect();
            let fragments = fragments_of(
                &FragmentScan {
                    tets: &tets,
                    mesh,
                    old_tet_count,
                    changed: relinked
                        .iter()
                        .copied()
                        .chain(event.tets_added.iter().map(|(t, _)| *t)),
                    x_ref: &x_ref,
                    held: &held,
                    original: &original,
                    options,
                },
                &seeds,
            );
            if fragments.is_empty() {
                break;
            }
            let around: BTreeSet<[u32; 3]> = fragments
                .iter()
                .flatten()
                .flat_map(|&t| {
                    let tet = tets[t as usize].map(original);
                    TET_FACES.map(|f| sorted_triple(f.map(|k| tet[k])))
                })
                .collect();
            let kept: BTreeSet<[u32; 3]> = cut_faces.difference(&around).copied().collect();
            if kept.len() < before {
                event.fragments_reattached += fragments.len();
            }
            kept
        } else {
            let pinched: BTreeSet<[u32; 2]> = pinched
                .iter()
                .map(|e| sorted_pair(original(e[0]), original(e[1])))
                .collect();
            cut_faces
                .iter()
                .filter(|f| {
                    !pinched
                        .iter()
                        .any(|e| f.contains(&e[0]) && f.contains(&e[1]))
                })
                .copied()
                .collect()
        };
        if kept.len() == before {
            break; // not ours to fix: the invariant checks will report it
        }
        // undo this round's relabelling and try again without the pinching faces
        for &(t, tet) in &undo {
            tets.to_mut()[t as usize] = tet;
        }
        cut_faces = kept;
    }
    event.cut_faces = cut_faces.len();
    if splits.is_empty() && event.tets_removed.is_empty() && event.vertices_moved.is_empty() {
        // nothing changed (the part of the window already cut): no rebuild
        return Ok(event);
    }
    for (v, _) in &splits {
        let copy = x.len() as u32;
        x.push(x[*v as usize]);
        x_ref.push(x_ref[*v as usize]);
        vel.push(vel[*v as usize]);
        held.push(held[*v as usize]);
        event
            .vertices_split
            .push(SplitVertex { original: *v, copy });
    }
    let tets = tets.into_owned();
    event.tets_relinked = relinked
        .into_iter()
        .map(|t| (t, tets[t as usize]))
        .collect();

    // Commit: new mesh, rebuilt model, extended state.
    // only the split parents (replaced in place by a child) and the relinked tets changed
    let mut changed: Vec<u32> = event
        .tets_removed
        .iter()
        .copied()
        .chain(event.tets_relinked.iter().map(|(t, _)| *t))
        .collect();
    changed.retain(|&t| (t as usize) < old_tet_count);
    changed.sort_unstable();
    changed.dedup();
    let new_mesh = TetMesh::with_changes(mesh, x_ref, tets, regions.into_owned(), &changed)?;
    // the masses and springs to derive again: those of the changed and new tets, and of the
    // tets around the vertices moved onto the plane (their reference geometry changed)
    let mut dirty: Vec<u32> = changed
        .iter()
        .copied()
        .chain(old_tet_count as u32..new_mesh.tet_count() as u32)
        .collect();
    for &(v, _, _) in &class.moved {
        dirty.extend_from_slice(new_mesh.topology().vertex_tets.row(v as usize));
    }
    // a piece the cut freed is lifted out of the wound, aside, and held there
    if !splits.is_empty() {
        let min_volume_m3 = options.fragment_volume_m3.max(f64::MIN_POSITIVE);
        event.specimens = specimen::freed(&new_mesh, &held, min_volume_m3, lift_m);
        for s in &event.specimens {
            let moved = Vector3::from(s.lift_m);
            for &v in &s.vertices {
                held[v as usize] = true;
                x[v as usize] += moved;
                vel[v as usize] = Vector3::zeros();
            }
            dirty.extend_from_slice(&s.tets);
        }
    }
    dirty.sort_unstable();
    dirty.dedup();
    // the springs are the edges: those lost are among the changed tets' old edges, those
    // gained among the dirty tets' new ones
    let old_edges =
        (sim.model.springs.ends != mesh.topology().edges).then(|| sim.model.springs.ends.clone());
    if old_edges.is_none() {
        let (old, new) = (mesh.topology(), new_mesh.topology());
        event.springs_removed = new.lacking_edges(mesh.tets(), &changed);
        event.springs_added = old.lacking_edges(new_mesh.tets(), &dirty);
    }
    sim.model.rebuild_local(new_mesh, held, &dirty, &changed)?;
    if let Some(old_edges) = old_edges {
        let new_edges = &sim.model.mesh.topology().edges;
        event.springs_removed = sorted_difference(&old_edges, new_edges);
        event.springs_added = sorted_difference(new_edges, &old_edges);
    }
    sim.state.positions = x;
    sim.state.velocities = vel;
    sim.model_changed();
    // a localised simulation wakes everything the cut touched
    let touched: Vec<u32> = event
        .tets_added
        .iter()
        .chain(&event.tets_relinked)
        .flat_map(|(_, t)| *t)
        .chain(event.vertices_moved.iter().map(|m| m.id))
        .collect();
    sim.wake(touched);
    let copies = base_vertices as u32..(base_vertices + splits.len()) as u32;
    for v in class.moved.iter().map(|m| m.0).chain(on_cut).chain(copies) {
        stroke.insert(v);
    }
    Ok(event)
}

/// The cut mesh being built, as the fragment flood sees it.
struct FragmentScan<'a, C, O> {
    /// The tetrahedra after this round's splits and relinks.
    tets: &'a [[u32; 4]],
    /// The mesh before the cut.
    mesh: &'a TetMesh,
    old_tet_count: usize,
    /// The tetrahedra the round changed or added.
    changed: C,
    x_ref: &'a [Point3],
    held: &'a [bool],
    /// The vertex a copy was split from (itself for others).
    original: &'a O,
    options: &'a CutOptions,
}

/// The fragments (see the `fragment` module) among the pieces of `seeds`.
fn fragments_of<C, O>(scan: &FragmentScan<'_, C, O>, seeds: &[u32]) -> Vec<Vec<u32>>
where
    C: Iterator<Item = u32> + Clone,
    O: Fn(u32) -> u32,
{
    if scan.options.fragment_volume_m3 <= 0.0 {
        return Vec::new();
    }
    let (tets, topo) = (scan.tets, scan.mesh.topology());
    let mut added: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for t in scan.changed.clone() {
        for v in tets[t as usize] {
            added.entry(v).or_default().push(t);
        }
    }
    let n = scan.mesh.vertex_count();
    let tets_at = |v: u32| -> Vec<u32> {
        let mut out: Vec<u32> = if (v as usize) < n {
            topo.vertex_tets
                .row(v as usize)
                .iter()
                .copied()
                .filter(|&t| (t as usize) < scan.old_tet_count && tets[t as usize].contains(&v))
                .collect()
        } else {
            Vec::new()
        };
        out.extend(added.get(&v).into_iter().flatten());
        out.sort_unstable();
        out.dedup();
        out
    };
    let x_ref = scan.x_ref;
    let volume = |t: u32| {
        let [a, b, c, d] = tets[t as usize].map(|v| x_ref[(scan.original)(v) as usize]);
        tet_signed_volume(&a, &b, &c, &d).abs()
    };
    let held = |v: u32| scan.held[(scan.original)(v) as usize];
    fragment::PieceQuery {
        tets,
        tets_at: &tets_at,
        volume: &volume,
        held: &held,
        max_volume_m3: scan.options.fragment_volume_m3,
    }
    .fragments(seeds)
}

/// The entries of `a` that are not in `b`, both sorted: one merge pass (see
/// `docs/decisions.md` for the binary search it replaced).
fn sorted_difference(a: &[[u32; 2]], b: &[[u32; 2]]) -> Vec<[u32; 2]> {
    let mut out = Vec::new();
    let mut j = 0;
    for e in a {
        while j < b.len() && b[j] < *e {
            j += 1;
        }
        if b.get(j) != Some(e) {
            out.push(*e);
        }
    }
    out
}

/// Orients children positively in the reference configuration; false when one is degenerate
/// there or inverted in the current configuration.
fn orient(ch: &mut Children, x: &[Point3], x_ref: &[Point3]) -> bool {
    let vol = |c: &[u32; 4], p: &[Point3]| {
        let [a, b, cc, d] = c.map(|v| p[v as usize]);
        tet_signed_volume(&a, &b, &cc, &d)
    };
    let mut ok = true;
    for c in &mut ch.tets {
        if vol(c, x_ref) < 0.0 {
            c.swap(2, 3);
        }
        ok &= vol(c, x_ref) > 0.0 && vol(c, x) > 0.0;
    }
    ok
}

/// The paper's mu over a set of children: largest dihedral angle over smallest.
fn mu(ch: &Children, x: &[Point3]) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for c in &ch.tets {
        for a in dihedral_angles(&c.map(|v| x[v as usize])) {
            lo = lo.min(a);
            hi = hi.max(a);
        }
    }
    if lo > 0.0 { hi / lo } else { f64::INFINITY }
}

fn choose_min_mu(
    splits: &[(u32, TetSplit)],
    x: &[Point3],
    x_ref: &[Point3],
) -> Option<Vec<Children>> {
    let mut fixed: BTreeMap<QuadKey, [u32; 2]> = BTreeMap::new();
    let mut out = Vec::with_capacity(splits.len());
    for (_, s) in splits {
        let quads = s.quads();
        let mut free: Vec<QuadKey> = quads
            .iter()
            .filter(|q| !fixed.contains_key(&q.key))
            .map(|q| q.key)
            .collect();
        free.sort_unstable();
        free.dedup();
        let mut best: Option<(f64, Children, u32)> = None;
        for mask in 0..(1u32 << free.len()) {
            let choice = |q: &Quad| -> [u32; 2] {
                if let Some(d) = fixed.get(&q.key) {
                    return *d;
                }
                let bit = free.iter().position(|k| *k == q.key).unwrap_or(0);
                q.diagonals()[((mask >> bit) & 1) as usize]
            };
            let Some(mut ch) = s.children(&choice) else {
                continue;
            };
            if !orient(&mut ch, x, x_ref) {
                continue;
            }
            let m = mu(&ch, x);
            if best.as_ref().is_none_or(|(bm, _, _)| m < *bm) {
                best = Some((m, ch, mask));
            }
        }
        let (_, ch, mask) = best?;
        for q in &quads {
            if let (QuadKey::Face(_), None) = (q.key, fixed.get(&q.key)) {
                let bit = free.iter().position(|k| *k == q.key).unwrap_or(0);
                fixed.insert(q.key, q.diagonals()[((mask >> bit) & 1) as usize]);
            }
        }
        out.push(ch);
    }
    Some(out)
}

fn choose_fixed(splits: &[(u32, TetSplit)], x_ref: &[Point3]) -> Option<Vec<Children>> {
    splits
        .iter()
        .map(|(_, s)| {
            // positive at rest (required); in the current configuration, as the springs
            // allow, a child may start inverted where no pattern avoids it
            let mut ch = s.children(&|q: &Quad| q.min_vertex_diagonal())?;
            orient(&mut ch, x_ref, x_ref).then_some(ch)
        })
        .collect()
}

/// The wound's opening: for each split vertex (a pair of coincident rest positions, its two
/// copies), the rest position and the distance between the copies now, m.
pub fn wound_gaps(sim: &Simulation) -> Vec<(Point3, f64)> {
    let (rest, x) = (sim.model.mesh.positions(), &sim.state.positions);
    sim.model
        .mesh
        .coincident_vertices(1e-12)
        .into_iter()
        .map(|[a, b]| (rest[a as usize], (x[a as usize] - x[b as usize]).norm()))
        .collect()
}

/// A vector helper for callers building blades.
pub fn blade(tip: Point3, edge_direction: Vector3, depth_m: f64) -> Blade {
    Blade {
        tip,
        edge_direction: edge_direction.normalize(),
        depth_m,
    }
}

#[cfg(test)]
mod tests {
    use super::sorted_difference;

    #[test]
    fn sorted_difference_is_the_set_difference() {
        let a: Vec<[u32; 2]> = (0..200u32)
            .filter(|i| i % 3 != 0)
            .map(|i| [i / 7, i])
            .collect();
        let b: Vec<[u32; 2]> = (0..200u32)
            .filter(|i| i % 2 == 0)
            .map(|i| [i / 7, i])
            .chain([[99, 999]])
            .collect();
        let naive = |a: &[[u32; 2]], b: &[[u32; 2]]| -> Vec<[u32; 2]> {
            a.iter().filter(|e| !b.contains(e)).copied().collect()
        };
        assert_eq!(sorted_difference(&a, &b), naive(&a, &b));
        assert_eq!(sorted_difference(&b, &a), naive(&b, &a));
        assert_eq!(sorted_difference(&a, &[]), a);
        assert!(sorted_difference(&[], &a).is_empty());
        assert!(sorted_difference(&a, &a).is_empty());
    }
}
