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
mod scissors;
mod separate;
mod specimen;
mod stop;
mod transaction;

use std::collections::BTreeMap;

pub use cutter::{Cutter, CutterResume, CutterResumeError, EndedStroke};
pub use event::{CreatedVertex, CutEvent, MadeFrom, MovedVertex, SplitVertex};
pub use pattern::{Children, Quad, QuadKey, TetSplit, prism};
pub use polygon::{Blade, CutPolygon};
pub use scissors::{CLOSURE_SPACING_M, Scissors};
pub use specimen::Specimen;
pub use stop::{BladeStop, STOP_MARGIN_M, stop_on_uncuttable};

use crate::mesh::{PARALLEL_MIN_TETS, TET_EDGES, TetMesh, dihedral_angles, tet_signed_volume};
use crate::model::ModelError;
use crate::solver::Simulation;
use crate::{MeshError, Point3, Vector3};
use transaction::PendingCut;

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

/// The default [`CutOptions::fragment_volume_m3`]: 60 mm^3, a cube of about 4 mm. The slivers
/// turning strokes carved measured up to 41 mm^3 (an S-curve 9 mm into the chest wall); a
/// specimen an exercise asks for (a 10 mm disc of a 2 mm sheet) is 150 mm^3 and more.
pub const FRAGMENT_VOLUME_M3: f64 = 6e-8;

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
        &[],
    )
}

/// [`cut`] as one step of a stroke: vertices of the stroke's cut (`stroke`) that drifted a
/// little off the plane count as on it, and `stroke` learns this step's cut vertices. A piece
/// the cut frees is moved by `lift_m` and held there (a [`Specimen`]; [`cut`] leaves it where
/// it is), unless a grasper's jaws hold it: the particles `in_jaws` (ascending) anchor
/// nothing, and a piece they hold stays in them.
pub fn cut_remembering(
    sim: &mut Simulation,
    polygon: &CutPolygon,
    options: &CutOptions,
    stroke: &mut StrokeVertices,
    lift_m: Vector3,
    in_jaws: &[u32],
) -> Result<CutEvent, CutError> {
    let Some(mut pending) = PendingCut::begin(sim, polygon, options, stroke) else {
        return Ok(CutEvent::default());
    };
    pending.resolve();
    pending.split_edges();
    let splits = pending.tets_to_split()?;
    pending.split_tets(&splits)?;
    pending.separate();
    if pending.changes_nothing() {
        // nothing changed (the part of the window already cut): no rebuild
        return Ok(pending.into_event());
    }
    pending.split_vertices();
    pending.into_commit(lift_m, in_jaws)?.apply(sim, stroke)
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
