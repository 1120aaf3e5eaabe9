//! Edge/plane intersections and the resolution of incomplete intersections by vertex
//! movement (the paper's section 4.1).
//!
//! An edge *crosses* C when its two vertices lie strictly on opposite sides of C's plane and
//! the crossing point lies inside C. A tetrahedron some of whose plane-crossing edges cross
//! inside C and some outside is *incompletely* intersected: C's boundary B runs through it.
//! It is resolved, for each outside crossing, by the first of:
//!
//! 1. when the crossing point lies within [`FORCE_REACH`] of the edge's length of C, the edge
//!    is split too: the cut reaches a little past B rather than a vertex being pulled across
//!    half an element (which would snap the cut to the mesh's faces, quantising its depth);
//! 2. the paper's vertex movement: a vertex of the edge (the one outside C, or the nearer)
//!    moves onto the plane by the mean of its intersecting edge vectors,
//!    `x_v += mean_e t_e (x_w - x_v)`, after which none of its edges cross;
//! 3. when neither end may move, the edge is split anyway.
//!
//! Vertices very close to the plane (crossing parameter below `snap`, or nearer than
//! `snap_distance_m`, on an edge crossing inside C or within [`FORCE_REACH`] of it) move onto
//! it too, so that no sliver is created and a layer of vertices just past B joins the cut; one nearer than
//! `snap_distance_m` that may not move counts as on the plane where it stands. A vertex moves only if every tetrahedron around it keeps at
//! least [`MIN_VOLUME_KEPT`] of its volume in both the current and the reference
//! configuration; held vertices, and surface vertices on a crease or corner, do not move. A
//! surface vertex moves within its tangent plane, and every reference-configuration step is
//! made volume-conserving (see `volume_conserving`), so that the rest volume and the masses
//! stay exact on curved surfaces too.
//!
//! Within a stroke, vertices of the cut made by earlier steps ([`super::StrokeVertices`]) that
//! drifted off the plane by less than [`near_fraction`] of their shortest edge (or the
//! snapping distance), plus [`STROKE_FLATNESS_REACH`] times the swept surface's departure from
//! the plane, count as on it, so that neither the opening wound nor the part of a turning
//! stroke already cut is cut again.

use std::collections::{BTreeMap, BTreeSet};

use super::CutPolygon;
use crate::mesh::{
    TET_EDGES, TET_FACES, TetMesh, edge_key, face_key, tet_signed_volume, tet_volume_gradients,
    triangle_normal,
};
use crate::model::Model;
use crate::{Point3, Vector3};

/// A moved vertex keeps every tetrahedron around it at no less than this fraction of its
/// volume.
pub const MIN_VOLUME_KEPT: f64 = 0.1;

/// Split points stay at least this fraction of their edge away from its ends.
pub const MIN_EDGE_FRACTION: f64 = 0.05;

/// A vertex of the stroke's cut within this fraction of its shortest edge of the plane
/// counts as on it (at least [`MIN_EDGE_FRACTION`], else the snapping fraction).
pub fn near_fraction(snap: f64) -> f64 {
    snap.max(MIN_EDGE_FRACTION)
}

/// A vertex of the stroke's cut also counts as on the plane within this many times the
/// polygon's [`CutPolygon::flatness_m`]: where the blade turns, the planes of successive steps
/// differ, and the stroke's earlier cut lies off this step's plane by a few times the swept
/// surface's departure from it (see `docs/design/cutting.md`, "Strokes that turn").
pub const STROKE_FLATNESS_REACH: f64 = 5.0;

/// An edge crossing the plane outside C but within this fraction of its length of C is split
/// (the cut reaches a little past B) instead of moving a vertex.
pub const FORCE_REACH: f64 = 0.5;

/// A plane-crossing edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// Sorted vertex ids.
    pub edge: [u32; 2],
    /// Crossing parameter from `edge[0]`.
    pub t: f64,
    /// The crossing lies inside C (or was forced).
    pub split: bool,
}

/// Result of classification.
#[derive(Debug, Clone, Default)]
pub struct Classification {
    /// Side of each vertex of the candidate tetrahedra: +1, -1, or 0 on the plane.
    pub sign: BTreeMap<u32, i8>,
    /// Crossing edges by sorted vertex pair.
    pub crossings: BTreeMap<[u32; 2], Crossing>,
    /// Vertices moved: (id, current from, current to, reference from, reference to).
    pub moved: Vec<(u32, Point3, Point3)>,
    pub forced: usize,
}

/// What [`Resolver::resolve`] has done so far: the vertices on the plane, the edges forced to
/// split, the vertices moved and those pushed off the plane.
#[derive(Default)]
struct Progress {
    on_plane: BTreeSet<u32>,
    forced: BTreeSet<[u32; 2]>,
    moved: Vec<(u32, Point3, Point3)>,
    pushed: BTreeSet<u32>,
}

pub struct Resolver<'a> {
    pub mesh: &'a TetMesh,
    pub x: &'a mut [Point3],
    pub x_ref: &'a mut [Point3],
    pub held: &'a [bool],
    pub plane: &'a CutPolygon,
    pub candidates: &'a [u32],
    /// Crossing parameters below this (or above 1 - this) move the near vertex onto the plane.
    pub snap: f64,
    /// Vertices nearer the plane than this (m) move onto it, and stroke vertices this near
    /// count as on it (see [`super::CutOptions::snap_distance_m`]; 0: relative rules only).
    pub snap_distance_m: f64,
    /// Distance tolerance for "inside C".
    pub inside_tolerance: f64,
    /// Vertices of the cut made by earlier steps of the stroke.
    pub stroke: &'a super::StrokeVertices,
    /// The model, for its uncuttable tetrahedra ([`Model::uncuttable`]): an edge of one is
    /// never split beyond the blade (the [`super::Cutter`] stops the blade itself above them).
    pub model: &'a Model,
}

impl Resolver<'_> {
    fn side(&self, s: f64, zero: f64) -> i8 {
        if s > zero {
            1
        } else if s < -zero {
            -1
        } else {
            0
        }
    }

    fn classify(&self, on_plane: &BTreeSet<u32>, forced: &BTreeSet<[u32; 2]>) -> Classification {
        let zero = 1e-12 * self.plane.scale;
        let mut c = Classification::default();
        let mut dist = BTreeMap::new();
        for &t in self.candidates {
            for &v in &self.mesh.tets()[t as usize] {
                dist.entry(v).or_insert_with(|| {
                    if on_plane.contains(&v) {
                        0.0
                    } else {
                        self.plane.signed_distance(&self.x[v as usize])
                    }
                });
            }
        }
        for (&v, &s) in &dist {
            c.sign.insert(v, self.side(s, zero));
        }
        for &t in self.candidates {
            let tet = self.mesh.tets()[t as usize];
            for [i, j] in TET_EDGES {
                let [a, b] = edge_key(&tet, [i, j]);
                if c.crossings.contains_key(&[a, b]) || c.sign[&a] * c.sign[&b] >= 0 {
                    continue;
                }
                let (sa, sb) = (dist[&a], dist[&b]);
                // Crossing parameter, kept off the ends: a split point closer than
                // `MIN_EDGE_FRACTION` to a vertex (where that vertex could neither move onto
                // the plane nor away from it) sits at that fraction instead, a little off the
                // plane, so that no child is a sliver.
                let tt = (sa / (sa - sb)).clamp(MIN_EDGE_FRACTION, 1.0 - MIN_EDGE_FRACTION);
                let p = self.x[a as usize] + (self.x[b as usize] - self.x[a as usize]) * tt;
                let split = forced.contains(&[a, b])
                    || self.plane.contains_projection(&p, self.inside_tolerance);
                c.crossings.insert(
                    [a, b],
                    Crossing {
                        edge: [a, b],
                        t: tt,
                        split,
                    },
                );
            }
        }
        c
    }

    /// True when the crossing point of `cr` lies within [`FORCE_REACH`] of its edge's length
    /// of C.
    fn within_reach(&self, cr: &Crossing) -> bool {
        let [a, b] = cr.edge.map(|v| self.x[v as usize]);
        let p = a + (b - a) * cr.t;
        self.plane
            .contains_projection(&p, FORCE_REACH * (b - a).norm())
    }

    /// Whether edge `e` may be split beyond the blade: no tetrahedron around it is of an
    /// uncuttable region.
    fn splittable(&self, e: [u32; 2]) -> bool {
        self.model.uncuttable_regions.is_empty()
            || !self
                .mesh
                .topology()
                .tets_of_edge(e)
                .any(|t| self.model.uncuttable(t as usize))
    }

    /// True when `v` lies nearer the plane than the snapping distance.
    fn near_plane(&self, v: u32) -> bool {
        self.plane.signed_distance(&self.x[v as usize]).abs() < self.snap_distance_m
    }

    /// Length of the shortest edge at `v` in the current configuration.
    fn shortest_edge(&self, v: u32) -> f64 {
        let topo = self.mesh.topology();
        let mut shortest = f64::INFINITY;
        for &t in topo.vertex_tets.row(v as usize) {
            for &w in &self.mesh.tets()[t as usize] {
                if w != v {
                    shortest = shortest.min((self.x[w as usize] - self.x[v as usize]).norm());
                }
            }
        }
        shortest
    }

    /// Where `v` would move: onto the plane by the mean of its intersecting edge vectors
    /// (tangentially for a vertex on a nearly flat surface). None when it may not move.
    fn movement(&self, v: u32, c: &Classification) -> Option<(Vector3, Vector3)> {
        if self.held[v as usize] {
            return None;
        }
        let (mut dx, mut dref, mut k) = (Vector3::zeros(), Vector3::zeros(), 0.0);
        for cr in c.crossings.values() {
            let (w, t) = if cr.edge[0] == v {
                (cr.edge[1], cr.t)
            } else if cr.edge[1] == v {
                (cr.edge[0], 1.0 - cr.t)
            } else {
                continue;
            };
            dx += (self.x[w as usize] - self.x[v as usize]) * t;
            dref += (self.x_ref[w as usize] - self.x_ref[v as usize]) * t;
            k += 1.0;
        }
        if k == 0.0 {
            return None;
        }
        let (mut dx, mut dref) = (dx / k, dref / k);
        if let Some(n_s) = self.surface_normal(v)? {
            // stay on the (nearly flat) surface: move within its tangent plane onto C's plane,
            // and by the same step in the reference configuration (made volume-conserving)
            let n_c = self.plane.normal;
            let dir = n_c - n_s * n_c.dot(&n_s);
            let along = dir.dot(&n_c);
            if along < 0.1 {
                return None; // the cut plane is nearly parallel to the surface here
            }
            let s = self.plane.signed_distance(&self.x[v as usize]);
            dx = dir * (-s / along);
            dref = dx;
        }
        Some((dx, self.volume_conserving(v, dref)))
    }

    /// Moves `v` away from the plane, along the plane normal (within the surface's tangent
    /// plane for a surface vertex), until each of its crossing edges has parameter at least
    /// `snap` from it. None when it may not move.
    fn push_away(&self, v: u32, c: &Classification) -> Option<(Vector3, Vector3)> {
        if self.held[v as usize] {
            return None;
        }
        let s_v = self.plane.signed_distance(&self.x[v as usize]);
        let mut need = 0.0f64;
        for cr in c.crossings.values() {
            let w = if cr.edge[0] == v {
                cr.edge[1]
            } else if cr.edge[1] == v {
                cr.edge[0]
            } else {
                continue;
            };
            let s_w = self.plane.signed_distance(&self.x[w as usize]).abs();
            need = need.max(self.snap / (1.0 - self.snap) * s_w * 1.01);
        }
        if !(need > s_v.abs()) {
            return None;
        }
        let target = need * s_v.signum();
        let dir = match self.surface_normal(v)? {
            None => self.plane.normal,
            Some(n_s) => {
                let d = self.plane.normal - n_s * self.plane.normal.dot(&n_s);
                let along = d.dot(&self.plane.normal);
                if along < 0.1 {
                    return None;
                }
                d / along
            }
        };
        let dx = dir * (target - s_v);
        Some((dx, self.volume_conserving(v, dx)))
    }

    /// The reference-configuration step `d` of `v`, made to keep the rest volume of every
    /// region around `v`. A region's volume is linear in one vertex,
    /// `V_r(x_v + d) = V_r(x_v) + g_r . d` with `g_r = sum_(t in r) dV_t / dx_v`, so `d` loses
    /// its components along the `g_r` (orthonormalised). For an interior vertex of one region
    /// `g_r = 0` and `d` is unchanged; on a flat surface `g_r` is the surface normal, so the
    /// vertex slides within the surface; on a curved one it slides across it by the second-order
    /// amount that keeps the volume. Region volumes kept, the masses `m = rho V / 4` sum to the
    /// same total whatever the densities.
    fn volume_conserving(&self, v: u32, d: Vector3) -> Vector3 {
        let topo = self.mesh.topology();
        let regions = self.mesh.regions();
        // (region, gradient, sum of the gradients' norms as the scale of round-off)
        let mut gradients: Vec<(u32, Vector3, f64)> = Vec::new();
        for &t in topo.vertex_tets.row(v as usize) {
            let tet = self.mesh.tets()[t as usize];
            let Some(l) = tet.iter().position(|&w| w == v) else {
                continue;
            };
            let g = tet_volume_gradients(&tet.map(|w| self.x_ref[w as usize]))[l];
            let r = regions[t as usize];
            match gradients.iter_mut().find(|e| e.0 == r) {
                Some(e) => {
                    e.1 += g;
                    e.2 += g.norm();
                }
                None => gradients.push((r, g, g.norm())),
            }
        }
        let mut basis: Vec<Vector3> = Vec::with_capacity(3);
        for (_, g, scale) in gradients {
            let u = basis.iter().fold(g, |u, b| u - b * b.dot(&u));
            let norm = u.norm();
            if norm > 1e-9 * scale {
                basis.push(u / norm);
            }
        }
        basis.iter().fold(d, |d, b| d - b * b.dot(&d))
    }

    /// Outward normal of the surface at `v` in configuration `x`: `Some(None)` for an interior
    /// vertex, `Some(Some(n))` on a nearly flat surface, `None` on a crease or corner.
    fn surface_normal(&self, v: u32) -> Option<Option<Vector3>> {
        let x = &*self.x;
        let topo = self.mesh.topology();
        let mut normals = Vec::new();
        for &t in topo.vertex_tets.row(v as usize) {
            let tet = self.mesh.tets()[t as usize];
            for (l, f) in TET_FACES.iter().enumerate() {
                if !f.iter().any(|&k| tet[k] == v)
                    || topo.tets_of_face(face_key(&tet, l)).nth(1).is_some()
                {
                    continue;
                }
                let p = f.map(|k| x[tet[k] as usize]);
                let n = triangle_normal(&p[0], &p[1], &p[2]);
                if n.norm() > 0.0 {
                    normals.push(n.normalize());
                }
            }
        }
        if normals.is_empty() {
            return Some(None);
        }
        let mean = normals.iter().sum::<Vector3>().normalize();
        // nearly flat: a crease or corner keeps its shape
        if normals.iter().all(|n| n.dot(&mean) > 0.98) {
            Some(Some(mean))
        } else {
            None
        }
    }

    /// True when moving `v` by (dx, dref) keeps every tetrahedron around it healthy.
    fn movement_ok(&self, v: u32, dx: &Vector3, dref: &Vector3) -> bool {
        let topo = self.mesh.topology();
        for &t in topo.vertex_tets.row(v as usize) {
            let tet = self.mesh.tets()[t as usize];
            for (pos, d) in [(&*self.x, dx), (&*self.x_ref, dref)] {
                let before = tet.map(|w| pos[w as usize]);
                let after = tet.map(|w| {
                    if w == v {
                        pos[w as usize] + d
                    } else {
                        pos[w as usize]
                    }
                });
                let v0 = tet_signed_volume(&before[0], &before[1], &before[2], &before[3]);
                let v1 = tet_signed_volume(&after[0], &after[1], &after[2], &after[3]);
                if !(v1 >= MIN_VOLUME_KEPT * v0.abs()) || v0 <= 0.0 {
                    return false;
                }
            }
        }
        true
    }

    /// Moves `v` by `delta` if that keeps its tetrahedra healthy; records the move.
    fn apply(
        &mut self,
        v: u32,
        delta: Option<(Vector3, Vector3)>,
        moved: &mut Vec<(u32, Point3, Point3)>,
    ) -> bool {
        match delta {
            Some((dx, dref)) if self.movement_ok(v, &dx, &dref) => {
                let from = self.x[v as usize];
                self.x[v as usize] += dx;
                self.x_ref[v as usize] += dref;
                moved.push((v, from, self.x[v as usize]));
                true
            }
            _ => false,
        }
    }

    /// Classifies, then moves vertices and forces splits until every candidate tetrahedron
    /// is either fully cut or not cut.
    pub fn resolve(&mut self) -> Classification {
        let mut p = Progress {
            on_plane: self.stroke_vertices_on_plane(),
            ..Progress::default()
        };
        let max_rounds = 4 * self.candidates.len() + 16;
        for _ in 0..max_rounds {
            let c = self.classify(&p.on_plane, &p.forced);
            let wanted = self.wanted_moves(&c);
            if wanted.is_empty() || !self.apply_round(&c, wanted, &mut p) {
                return Classification {
                    moved: p.moved,
                    forced: p.forced.len(),
                    ..c
                };
            }
        }
        let c = self.classify(&p.on_plane, &p.forced);
        Classification {
            moved: p.moved,
            forced: p.forced.len(),
            ..c
        }
    }

    /// Vertices of this stroke's cut that drifted a little off the plane (as the wound opens)
    /// count as on it, so that the open wound is not cut again.
    fn stroke_vertices_on_plane(&self) -> BTreeSet<u32> {
        let mut on_plane: BTreeSet<u32> = BTreeSet::new();
        for &t in self.candidates {
            for &v in &self.mesh.tets()[t as usize] {
                if self.stroke.contains(v)
                    && !on_plane.contains(&v)
                    && self.plane.signed_distance(&self.x[v as usize]).abs()
                        <= (near_fraction(self.snap) * self.shortest_edge(v))
                            .max(self.snap_distance_m)
                            + STROKE_FLATNESS_REACH * self.plane.flatness_m
                {
                    on_plane.insert(v);
                }
            }
        }
        on_plane
    }

    /// The moves classification `c` wants, in order: slivers first (a vertex, `None`), then
    /// incomplete intersections (a vertex of a crossing edge that should not be split, with
    /// the edge).
    fn wanted_moves(&self, c: &Classification) -> Vec<(u32, Option<[u32; 2]>)> {
        let mut wanted: Vec<(u32, Option<[u32; 2]>)> = Vec::new();
        // (a crossing just past B counts too: the vertex beside it joins the cut, as in 1.
        // below, or a layer of vertices just beyond the blade's tip would stay off the
        // plane, no face of that layer would lie on it, and the cut would never separate)
        for cr in c
            .crossings
            .values()
            .filter(|cr| cr.split || self.within_reach(cr))
        {
            if cr.t < self.snap || (cr.t <= 0.5 && self.near_plane(cr.edge[0])) {
                wanted.push((cr.edge[0], None));
            } else if cr.t > 1.0 - self.snap || self.near_plane(cr.edge[1]) {
                wanted.push((cr.edge[1], None));
            }
        }
        for &t in self.candidates {
            let tet = self.mesh.tets()[t as usize];
            let edges: Vec<&Crossing> = TET_EDGES
                .iter()
                .filter_map(|&l| c.crossings.get(&edge_key(&tet, l)))
                .collect();
            let splits = edges.iter().filter(|e| e.split).count();
            if splits == 0 || splits == edges.len() {
                continue;
            }
            for e in edges.iter().filter(|e| !e.split) {
                // the paper moves the vertex outside C; when both (or neither) project
                // outside, the one nearer the plane
                let out = e
                    .edge
                    .map(|v| !self.plane.contains_projection(&self.x[v as usize], 0.0));
                let near = match out {
                    [true, false] => e.edge[0],
                    [false, true] => e.edge[1],
                    _ if e.t < 0.5 => e.edge[0],
                    _ => e.edge[1],
                };
                wanted.push((near, Some(e.edge)));
            }
        }
        wanted
    }

    /// Applies every `wanted` move whose tetrahedra no other move of this round touched (so
    /// the moves are independent); whether anything changed.
    fn apply_round(
        &mut self,
        c: &Classification,
        wanted: Vec<(u32, Option<[u32; 2]>)>,
        p: &mut Progress,
    ) -> bool {
        let mut changed = false;
        let mut done = BTreeSet::new();
        let mut touched: BTreeSet<u32> = BTreeSet::new();
        let topo = self.mesh.topology();
        for (v, edge) in wanted {
            if p.on_plane.contains(&v) || !done.insert((v, edge)) {
                continue;
            }
            let free = |w: u32, touched: &BTreeSet<u32>| {
                topo.vertex_tets
                    .row(w as usize)
                    .iter()
                    .all(|t| !touched.contains(t))
            };
            if edge.is_some_and(|e| !free(e[0], &touched) || !free(e[1], &touched))
                || !free(v, &touched)
            {
                continue;
            }
            if let Some(e) =
                edge.filter(|e| self.within_reach(&c.crossings[e]) && self.splittable(*e))
            {
                // the crossing lies just past B: split it (the cut reaches a little
                // further) rather than pull a vertex across half an element
                if p.forced.insert(e) {
                    touched.extend(topo.vertex_tets.row(e[0] as usize));
                    touched.extend(topo.vertex_tets.row(e[1] as usize));
                    changed = true;
                }
                continue;
            }
            if self.apply(v, self.movement(v, c), &mut p.moved) {
                p.on_plane.insert(v);
                touched.extend(topo.vertex_tets.row(v as usize));
                changed = true;
                continue;
            }
            if edge.is_none() && self.near_plane(v) {
                // within the snapping distance but not free to move (held, on a crease,
                // or its tetrahedra would flatten): the cut passes through it as it
                // stands, off the plane by less than the snapping distance
                p.on_plane.insert(v);
                touched.extend(topo.vertex_tets.row(v as usize));
                changed = true;
                continue;
            }
            if edge.is_none()
                && !p.pushed.contains(&v)
                && self.apply(v, self.push_away(v, c), &mut p.moved)
            {
                // a sliver whose vertex cannot move onto the plane: pushed off instead
                p.pushed.insert(v);
                touched.extend(topo.vertex_tets.row(v as usize));
                changed = true;
                continue;
            }
            if let Some(e) = edge {
                let other = if e[0] == v { e[1] } else { e[0] };
                if p.on_plane.contains(&other) {
                    continue;
                }
                if self.apply(other, self.movement(other, c), &mut p.moved) {
                    p.on_plane.insert(other);
                    touched.extend(topo.vertex_tets.row(other as usize));
                    changed = true;
                    continue;
                }
                if self.splittable(e) && p.forced.insert(e) {
                    touched.extend(topo.vertex_tets.row(e[0] as usize));
                    touched.extend(topo.vertex_tets.row(e[1] as usize));
                    changed = true;
                }
            }
        }
        changed
    }
}
