//! A cut as a transaction: [`PendingCut`] holds the working copies of the state and the mesh
//! and takes them through the cut's stages, one method each, only reading the simulation;
//! [`Commit`] owns what they built, and its [`Commit::apply`] is the one stage that writes to
//! the simulation. A stage that fails drops the working copies: the simulation is unchanged.

use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};

use super::{
    CreatedVertex, CutError, CutEvent, CutOptions, CutPolygon, FragmentScan, MovedVertex,
    PatternChoice, SplitVertex, StrokeVertices, TetSplit, candidates, choose_fixed, choose_min_mu,
    fragments_of, resolve, separate, sorted_difference, specimen,
};
use crate::mesh::{
    TET_EDGES, TET_FACES, TetMesh, anchored, edge_key, sorted_pair, sorted_triple,
    tet_signed_volume,
};
use crate::model::Model;
use crate::solver::Simulation;
use crate::{Point3, Vector3};

/// A face whose three vertices lie on the step's plane joins the cut when its centroid
/// projects within this many snapping distances of the sides of C along the blade's first and
/// last poses (besides inside C). The resolution moves vertices onto the plane up to
/// [`resolve::FORCE_REACH`] of an edge's length past C's boundary, so a face it made flat can
/// sit just outside C; left uncut where the window shortened on a turn, such faces held a
/// pattern disc to the sheet by a column of vertices (see `docs/design/cutting.md`, "Strokes
/// that turn", rule 4).
const FACE_REACH_SNAPS: f64 = 4.0;

/// A cut under way: working copies of the simulation's state and mesh, which the stages
/// change while the simulation is only read, and the event they record. Taken through
/// [`Self::resolve`], [`Self::split_edges`], [`Self::tets_to_split`], [`Self::split_tets`],
/// [`Self::separate`] and [`Self::split_vertices`], it becomes a [`Commit`].
pub(super) struct PendingCut<'a> {
    /// The simulation's mesh before the cut.
    mesh: &'a TetMesh,
    /// The cut's polygon C.
    polygon: &'a CutPolygon,
    options: &'a CutOptions,
    /// Vertices of the cut made by earlier steps of the stroke.
    stroke: &'a StrokeVertices,
    /// The simulation's model (its uncuttable tetrahedra are never split).
    model: &'a Model,
    /// The tetrahedra taking part, ascending: the candidates, widened by [`Self::resolve`].
    cand: Vec<u32>,
    /// Current positions (working copy).
    x: Vec<Point3>,
    /// Reference positions (working copy).
    x_ref: Vec<Point3>,
    /// Velocities (working copy).
    vel: Vec<Vector3>,
    /// Held flags (working copy).
    held: Vec<bool>,
    /// The vertices' sides, the crossings and the vertices moved onto the plane.
    class: resolve::Classification,
    /// The new vertex on each split edge (sorted vertex pair).
    split_id: BTreeMap<[u32; 2], u32>,
    /// The faces of the cut surface (sorted vertex ids).
    cut_faces: BTreeSet<[u32; 3]>,
    /// The tetrahedra (copied only when a tet is split: most steps of a stroke change no tet).
    tets: Cow<'a, [[u32; 4]]>,
    /// The tetrahedra's regions (copied as `tets` is).
    regions: Cow<'a, [u32]>,
    /// The vertex count before the copies of the split vertices.
    base_vertices: usize,
    /// For each split vertex, the original and the tetrahedra of its star that move to its
    /// copy.
    vertex_splits: Vec<(u32, Vec<u32>)>,
    /// The tetrahedra whose vertices the split relinked to copies.
    relinked: BTreeSet<u32>,
    /// The relinked tets as they were, to undo a round.
    undo: Vec<(u32, [u32; 4])>,
    /// The vertices of the cut faces.
    on_cut: BTreeSet<u32>,
    event: CutEvent,
}

impl<'a> PendingCut<'a> {
    /// The cut of `sim` along `polygon`, with working copies of its state; `None` when no
    /// tetrahedron is a candidate (nothing to cut).
    pub(super) fn begin(
        sim: &'a Simulation,
        polygon: &'a CutPolygon,
        options: &'a CutOptions,
        stroke: &'a StrokeVertices,
    ) -> Option<Self> {
        let mesh = &sim.model.mesh;
        let margin = 1e-9 * polygon.scale;
        let near = if stroke.is_empty() {
            0.0
        } else {
            resolve::near_fraction(options.snap)
        };
        let cand = candidates(mesh.tets(), &sim.state.positions, polygon, margin, near);
        if cand.is_empty() {
            return None;
        }
        // Working copies: the simulation changes only when everything succeeded.
        Some(Self {
            mesh,
            polygon,
            options,
            stroke,
            model: &sim.model,
            cand,
            x: sim.state.positions.clone(),
            x_ref: mesh.positions().to_vec(),
            vel: sim.state.velocities.clone(),
            held: sim.model.held.clone(),
            class: resolve::Classification::default(),
            split_id: BTreeMap::new(),
            cut_faces: BTreeSet::new(),
            tets: Cow::Borrowed(mesh.tets()),
            regions: Cow::Borrowed(mesh.regions()),
            base_vertices: 0,
            vertex_splits: Vec::new(),
            relinked: BTreeSet::new(),
            undo: Vec::new(),
            on_cut: BTreeSet::new(),
            event: CutEvent::default(),
        })
    }

    /// Resolve: classify the vertices by side, find the crossings and move vertices onto the
    /// plane where the intersection is incomplete. Every tetrahedron around a split edge must
    /// take part (a forced split can reach beyond the first candidates), so the set is widened
    /// and resolved again until it does.
    pub(super) fn resolve(&mut self) {
        let mesh = self.mesh;
        let mut moved_all = Vec::new();
        let mut forced_all = 0;
        let class = loop {
            let class = resolve::Resolver {
                mesh,
                x: &mut self.x,
                x_ref: &mut self.x_ref,
                held: &self.held,
                plane: self.polygon,
                candidates: &self.cand,
                snap: self.options.snap,
                snap_distance_m: self.options.snap_distance_m.unwrap_or(0.0),
                inside_tolerance: 1e-9 * self.polygon.scale,
                stroke: self.stroke,
                model: self.model,
            }
            .resolve();
            moved_all.extend_from_slice(&class.moved);
            forced_all += class.forced;
            let topo = mesh.topology();
            let mut extra: BTreeSet<u32> = BTreeSet::new();
            for cr in class.crossings.values().filter(|c| c.split) {
                extra.extend(
                    topo.tets_of_edge(cr.edge)
                        .filter(|t| self.cand.binary_search(t).is_err()),
                );
            }
            if extra.is_empty() {
                break class;
            }
            self.cand.extend(extra);
            self.cand.sort_unstable();
        };
        self.class = resolve::Classification {
            moved: moved_all,
            forced: forced_all,
            ..class
        };
        self.event.forced_splits = self.class.forced;
        for &(id, from, to) in &self.class.moved {
            self.event.vertices_moved.push(MovedVertex {
                id,
                from: from.coords.into(),
                to: to.coords.into(),
            });
        }
    }

    /// New vertices on split edges, at the crossings, their positions and velocities
    /// interpolated, not held.
    pub(super) fn split_edges(&mut self) {
        let n = self.mesh.vertex_count();
        let (x, x_ref, vel) = (&mut self.x, &mut self.x_ref, &mut self.vel);
        for cr in self.class.crossings.values().filter(|c| c.split) {
            let id = (n + self.split_id.len()) as u32;
            let [a, b] = cr.edge.map(|v| v as usize);
            x.push(x[a] + (x[b] - x[a]) * cr.t);
            x_ref.push(x_ref[a] + (x_ref[b] - x_ref[a]) * cr.t);
            vel.push(vel[a] + (vel[b] - vel[a]) * cr.t);
            self.held.push(false);
            self.split_id.insert(cr.edge, id);
            self.event.vertices_created.push(CreatedVertex {
                id,
                edge: cr.edge,
                t: cr.t,
            });
        }
    }

    /// Tetrahedra to split (those with a split edge, in ascending order), and faces lying in
    /// the plane inside C, which join the cut faces. A tet with a crossing edge that was not
    /// split is left incompletely intersected: an error.
    pub(super) fn tets_to_split(&mut self) -> Result<Vec<(u32, TetSplit)>, CutError> {
        let (mesh, class, x) = (self.mesh, &self.class, &self.x);
        let mut splits: Vec<(u32, TetSplit)> = Vec::new();
        for &t in &self.cand {
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
                        split[e] = self.split_id[&key];
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
                if self.on_cut_face(&c) {
                    self.cut_faces
                        .insert(sorted_triple([face[0], face[1], face[2]]));
                }
            }
        }
        Ok(splits)
    }

    /// True when a face on the plane with centroid `c` is a cut face: its centroid projects
    /// inside C, or within [`FACE_REACH_SNAPS`] snapping distances of the side along the
    /// blade's first or last pose (a cutter's polygon lists the tips, then the heels
    /// backwards, so those are the side from the last tip to the last heel and the one from
    /// the first heel to the first tip).
    fn on_cut_face(&self, c: &Point3) -> bool {
        let p = self.polygon;
        let reach_m = self.options.snap_distance_m.unwrap_or(0.0) * FACE_REACH_SNAPS;
        let n = p.corners.len();
        p.contains_projection(c, 1e-9 * p.scale)
            || p.near_side(c, n / 2 - 1, reach_m)
            || p.near_side(c, n - 1, reach_m)
    }

    /// Children with conforming diagonals (chosen as [`CutOptions::pattern`] says): each split
    /// tet is replaced in place by its first child, the others appended with its region, and
    /// the section faces inside it join the cut faces. No admissible pattern: an error.
    pub(super) fn split_tets(&mut self, splits: &[(u32, TetSplit)]) -> Result<(), CutError> {
        let children = match self.options.pattern {
            PatternChoice::MinMu => choose_min_mu(splits, &self.x, &self.x_ref)
                .or_else(|| choose_fixed(splits, &self.x_ref)),
            PatternChoice::MinVertexId => choose_fixed(splits, &self.x_ref),
        };
        let Some(children) = children else {
            return Err(CutError::Unresolved(
                splits.first().map(|s| s.0).unwrap_or(0),
            ));
        };

        let mesh = self.mesh;
        let (tets, regions, event) = (&mut self.tets, &mut self.regions, &mut self.event);
        for ((t, _), ch) in splits.iter().zip(&children) {
            let parent_volume = mesh.tet_volume(*t as usize);
            for (k, c) in ch.tets.iter().enumerate() {
                let [a, b, cc, d] = c.map(|v| self.x_ref[v as usize]);
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
            self.cut_faces.extend(ch.section.iter().copied());
        }
        Ok(())
    }

    /// Separate the two sides: split vertices of the cut surface by star components. A cut
    /// face that would only pinch the surface (an edge of it on the outer surface whose ends
    /// both stay whole) is given up, and the split redone; so are the cut faces on one side of
    /// a fragment the split would carve out (see the `fragment` module).
    pub(super) fn separate(&mut self) {
        self.base_vertices = self.x.len();
        for _ in 0..64 {
            let Some(kept) = self.separation_round() else {
                break;
            };
            // undo this round's relabelling and try again without the pinching faces
            for &(t, tet) in &self.undo {
                self.tets.to_mut()[t as usize] = tet;
            }
            self.cut_faces = kept;
        }
        self.event.cut_faces = self.cut_faces.len();
    }

    /// One round of [`Self::separate`]: the vertices of the cut faces split by star
    /// components and their copies relinked; the cut faces to keep when some pinch the
    /// surface or fence a fragment, or `None` when the round's split stands.
    fn separation_round(&mut self) -> Option<BTreeSet<[u32; 3]>> {
        self.on_cut = self.cut_faces.iter().flatten().copied().collect();
        let stars = self.stars();
        self.vertex_splits = separate::star_components(&self.tets, &stars, &self.cut_faces);
        let original_of = self.relink();
        let base_vertices = self.base_vertices;
        let original = |v: u32| {
            if (v as usize) < base_vertices {
                v
            } else {
                original_of[v as usize - base_vertices]
            }
        };
        let local: BTreeSet<u32> = stars.values().flatten().copied().collect();
        let on_cut = &self.on_cut;
        let pinched =
            separate::pinched_edges(&self.tets, &local, &|v| on_cut.contains(&original(v)));
        let before = self.cut_faces.len();
        let kept = if pinched.is_empty() {
            self.without_fragments(&local, &original)?
        } else {
            self.without_pinching(&pinched, &original)
        };
        if kept.len() == before {
            return None; // not ours to fix: the invariant checks will report it
        }
        Some(kept)
    }

    /// The stars of the vertices of the cut faces in the tets as they are now: the old tets
    /// around each (that still hold it) and the split's children that hold it.
    fn stars(&self) -> separate::Stars {
        let (mesh, tets) = (self.mesh, &self.tets);
        let (n, old_tet_count, topo) = (mesh.vertex_count(), mesh.tet_count(), mesh.topology());
        let mut stars: separate::Stars = BTreeMap::new();
        for &v in &self.on_cut {
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
        for (id, c) in &self.event.tets_added {
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
    }

    /// Relinks the tets of the round's vertex splits to the copies (numbered from
    /// `base_vertices` in split order), remembering the tets as they were; returns the
    /// original of each copy.
    fn relink(&mut self) -> Vec<u32> {
        self.relinked.clear();
        self.undo.clear();
        let mut original_of: Vec<u32> = Vec::with_capacity(self.vertex_splits.len());
        for (k, (v, moved_tets)) in self.vertex_splits.iter().enumerate() {
            let copy = (self.base_vertices + k) as u32;
            original_of.push(*v);
            for &t in moved_tets {
                let tet = &mut self.tets.to_mut()[t as usize];
                if self.relinked.insert(t) {
                    self.undo.push((t, *tet));
                }
                for w in tet {
                    if *w == *v {
                        *w = copy;
                    }
                }
            }
        }
        original_of
    }

    /// The cut faces without those on one side of each fragment the round's split would carve
    /// out (the pieces of the tets around `local`; see [`Self::faces_to_one_side`]), or `None`
    /// when it carves out none.
    fn without_fragments(
        &mut self,
        local: &BTreeSet<u32>,
        original: &impl Fn(u32) -> u32,
    ) -> Option<BTreeSet<[u32; 3]>> {
        let seeds: Vec<u32> = local.iter().copied().collect();
        let tets = &self.tets;
        let fragments = fragments_of(
            &FragmentScan {
                tets,
                mesh: self.mesh,
                old_tet_count: self.mesh.tet_count(),
                changed: self
                    .relinked
                    .iter()
                    .copied()
                    .chain(self.event.tets_added.iter().map(|(t, _)| *t)),
                x_ref: &self.x_ref,
                held: &self.held,
                original,
                options: self.options,
            },
            &seeds,
        );
        if fragments.is_empty() {
            return None;
        }
        let around: BTreeSet<[u32; 3]> = fragments
            .iter()
            .flat_map(|piece| self.faces_to_one_side(piece, original))
            .collect();
        let kept: BTreeSet<[u32; 3]> = self.cut_faces.difference(&around).copied().collect();
        if kept.len() < self.cut_faces.len() {
            self.event.fragments_reattached += fragments.len();
        }
        Some(kept)
    }

    /// The cut faces round a fragment that face one side of the cut's plane: those whose
    /// outward normals point along `n`, or those pointing against it, whichever have the
    /// larger area projected on the plane. Left uncut, they join the fragment to the tissue
    /// on that side only; the cut faces facing the other side (the stroke's earlier wound,
    /// counted as on the plane) still separate it from there. Leaving every face round it
    /// uncut would join the two sides through it: a bridge across the wound.
    fn faces_to_one_side(&self, piece: &[u32], original: &impl Fn(u32) -> u32) -> Vec<[u32; 3]> {
        let n = self.polygon.normal;
        let (mut along, mut against) = (Vec::new(), Vec::new());
        let (mut area_along, mut area_against) = (0.0, 0.0);
        for &t in piece {
            let tet = self.tets[t as usize].map(original);
            for (k, f) in TET_FACES.iter().enumerate() {
                let face = sorted_triple(f.map(|i| tet[i]));
                if !self.cut_faces.contains(&face) {
                    continue;
                }
                let [a, b, c] = f.map(|i| self.x[tet[i] as usize]);
                let mut normal = (b - a).cross(&(c - a));
                if normal.dot(&(self.x[tet[k] as usize] - a)) > 0.0 {
                    normal = -normal; // outward: away from the tet's fourth vertex
                }
                let projected = normal.dot(&n);
                if projected >= 0.0 {
                    area_along += projected;
                    along.push(face);
                } else {
                    area_against -= projected;
                    against.push(face);
                }
            }
        }
        if area_along >= area_against {
            along
        } else {
            against
        }
    }

    /// The cut faces without those holding one of the `pinched` edges (between copies or
    /// originals, named by their originals).
    fn without_pinching(
        &self,
        pinched: &[[u32; 2]],
        original: &impl Fn(u32) -> u32,
    ) -> BTreeSet<[u32; 3]> {
        let pinched: BTreeSet<[u32; 2]> = pinched
            .iter()
            .map(|e| sorted_pair(original(e[0]), original(e[1])))
            .collect();
        self.cut_faces
            .iter()
            .filter(|f| {
                !pinched
                    .iter()
                    .any(|e| f.contains(&e[0]) && f.contains(&e[1]))
            })
            .copied()
            .collect()
    }

    /// True when the cut changes nothing (the part of the window already cut): no vertex
    /// split or moved, no tet split.
    pub(super) fn changes_nothing(&self) -> bool {
        self.vertex_splits.is_empty()
            && self.event.tets_removed.is_empty()
            && self.event.vertices_moved.is_empty()
    }

    /// The event so far (a cut that changes nothing ends with it).
    pub(super) fn into_event(self) -> CutEvent {
        self.event
    }

    /// The copies of the split vertices, appended in split order: each starts where its
    /// original is, as fast, and held if it is.
    pub(super) fn split_vertices(&mut self) {
        let (x, x_ref, vel, held) = (&mut self.x, &mut self.x_ref, &mut self.vel, &mut self.held);
        for (v, _) in &self.vertex_splits {
            let copy = x.len() as u32;
            x.push(x[*v as usize]);
            x_ref.push(x_ref[*v as usize]);
            vel.push(vel[*v as usize]);
            held.push(held[*v as usize]);
            self.event
                .vertices_split
                .push(SplitVertex { original: *v, copy });
        }
    }

    /// The new mesh, and the tets whose masses and springs the commit derives again; a piece
    /// the cut freed is lifted by `lift_m` (see [`Commit::lift_specimens`]). The simulation is
    /// no longer borrowed: the [`Commit`] owns everything.
    pub(super) fn into_commit(self, lift_m: Vector3, in_jaws: &[u32]) -> Result<Commit, CutError> {
        let mesh = self.mesh;
        let old_tet_count = mesh.tet_count();
        let mut event = self.event;
        let tets = self.tets.into_owned();
        event.tets_relinked = self
            .relinked
            .into_iter()
            .map(|t| (t, tets[t as usize]))
            .collect();
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
        let new_mesh =
            TetMesh::with_changes(mesh, self.x_ref, tets, self.regions.into_owned(), &changed)?;
        // the masses and springs to derive again: those of the changed and new tets, and of the
        // tets around the vertices moved onto the plane (their reference geometry changed)
        let mut dirty: Vec<u32> = changed
            .iter()
            .copied()
            .chain(old_tet_count as u32..new_mesh.tet_count() as u32)
            .collect();
        for &(v, _, _) in &self.class.moved {
            dirty.extend_from_slice(new_mesh.topology().vertex_tets.row(v as usize));
        }
        let copies =
            self.base_vertices as u32..(self.base_vertices + self.vertex_splits.len()) as u32;
        let stroke_vertices = self
            .class
            .moved
            .iter()
            .map(|m| m.0)
            .chain(self.on_cut)
            .chain(copies)
            .collect();
        let mut commit = Commit {
            mesh: new_mesh,
            x: self.x,
            vel: self.vel,
            held: self.held,
            changed,
            dirty,
            stroke_vertices,
            event,
        };
        if !self.vertex_splits.is_empty() {
            let min_volume_m3 = self.options.fragment_volume_m3.max(f64::MIN_POSITIVE);
            commit.lift_specimens(min_volume_m3, lift_m, in_jaws, mesh);
        }
        commit.dirty.sort_unstable();
        commit.dirty.dedup();
        Ok(commit)
    }
}

/// A cut ready to commit: the new mesh and the extended state, owned, and what the model's
/// rebuild and the stroke need. [`Self::apply`] writes it to the simulation.
pub(super) struct Commit {
    /// The cut mesh.
    mesh: TetMesh,
    /// Current positions, one per vertex of the cut mesh.
    x: Vec<Point3>,
    /// Velocities.
    vel: Vec<Vector3>,
    /// Held flags.
    held: Vec<bool>,
    /// The tets that existed before with other vertices, ascending.
    changed: Vec<u32>,
    /// The tets whose masses and springs are derived again (ascending once complete).
    dirty: Vec<u32>,
    /// This step's cut vertices: those moved onto the plane, those of the cut faces and the
    /// copies of the split ones.
    stroke_vertices: Vec<u32>,
    event: CutEvent,
}

impl Commit {
    /// A piece the cut freed (of at least `min_volume_m3`) is lifted out of the wound by
    /// `lift_m`, aside, and held there, at rest; its tets' masses and springs are derived
    /// again. The particles in a grasper's jaws (`in_jaws`, ascending, and what this cut
    /// made of them: [`CutEvent::made_from`]) anchor nothing: a piece held only by the jaws
    /// is freed too, and stays in them. A piece that was apart from the held tissue in the
    /// mesh `before` this cut (freed by an earlier one, in the jaws or let go of since) is
    /// not freed again.
    fn lift_specimens(
        &mut self,
        min_volume_m3: f64,
        lift_m: Vector3,
        in_jaws: &[u32],
        before: &TetMesh,
    ) {
        let mut jaws = in_jaws.to_vec();
        jaws.extend(self.event.made_from(in_jaws).into_iter().map(|(v, _)| v));
        jaws.sort_unstable();
        let mut anchors = std::borrow::Cow::Borrowed(&self.held[..]);
        if !jaws.is_empty() {
            let a = anchors.to_mut();
            for &v in &jaws {
                if let Some(h) = a.get_mut(v as usize) {
                    *h = false;
                }
            }
        }
        let mut specimens = specimen::freed(&self.mesh, &anchors, min_volume_m3, lift_m);
        if !specimens.is_empty() {
            let n = before.vertex_count();
            let was_anchored = anchored(before, &anchors[..n.min(anchors.len())]);
            specimens.retain(|s| {
                let mut old = s.vertices.iter().filter(|&&v| (v as usize) < n).peekable();
                old.peek().is_none() || old.any(|&v| was_anchored[v as usize])
            });
        }
        for s in &mut specimens {
            if s.vertices.iter().any(|v| jaws.binary_search(v).is_ok()) {
                s.in_jaws = true;
                s.lift_m = [0.0; 3];
            }
        }
        self.event.specimens = specimens;
        for s in self.event.specimens.iter().filter(|s| !s.in_jaws) {
            let moved = Vector3::from(s.lift_m);
            for &v in &s.vertices {
                self.held[v as usize] = true;
                self.x[v as usize] += moved;
                self.vel[v as usize] = Vector3::zeros();
            }
            self.dirty.extend_from_slice(&s.tets);
        }
    }

    /// Commit: the new mesh, the rebuilt model (its masses and springs derived again where
    /// the cut reached), the extended state, the springs removed and added in the event, a
    /// localised simulation woken where the cut touched, and `stroke` taught this step's cut
    /// vertices. The only stage that writes to `sim`.
    pub(super) fn apply(
        self,
        sim: &mut Simulation,
        stroke: &mut StrokeVertices,
    ) -> Result<CutEvent, CutError> {
        let mut event = self.event;
        let (mesh, new_mesh) = (&sim.model.mesh, self.mesh);
        // the springs are the edges: those lost are among the changed tets' old edges, those
        // gained among the dirty tets' new ones
        let old_edges = (sim.model.springs.ends != mesh.topology().edges)
            .then(|| sim.model.springs.ends.clone());
        if old_edges.is_none() {
            let (old, new) = (mesh.topology(), new_mesh.topology());
            event.springs_removed = new.lacking_edges(mesh.tets(), &self.changed);
            event.springs_added = old.lacking_edges(new_mesh.tets(), &self.dirty);
        }
        sim.model
            .rebuild_local(new_mesh, self.held, &self.dirty, &self.changed)?;
        if let Some(old_edges) = old_edges {
            let new_edges = &sim.model.mesh.topology().edges;
            event.springs_removed = sorted_difference(&old_edges, new_edges);
            event.springs_added = sorted_difference(new_edges, &old_edges);
        }
        sim.state.positions = self.x;
        sim.state.velocities = self.vel;
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
        for v in self.stroke_vertices {
            stroke.insert(v);
        }
        Ok(event)
    }
}
