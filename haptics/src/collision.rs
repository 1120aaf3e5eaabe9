//! The tissue surface as seen by the tool: a parry triangle mesh (with its BVH) over the
//! boundary triangles of the tetrahedral mesh, refitted in place as the tissue deforms and
//! rebuilt when a cut changes the surface. Queries give the closest surface point to the
//! proxy and the local contact model (plane and stiffness) the servo loop renders from.
//!
//! parry works on glam vectors (`DVec3`); the conversion happens here and nowhere else.

use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::{PointQueryWithLocation, Ray, RayCast};
use parry3d_f64::shape::{TriMesh, TriMeshFlags};

use cutlab_sim::mesh::Csr;
use cutlab_sim::solver::Simulation;

use crate::render::ContactModel;
use crate::{HapticsError, Point3, Vector3};

fn to_parry(p: &Point3) -> PVec {
    PVec::new(p.x, p.y, p.z)
}

fn from_parry(v: PVec) -> Vector3 {
    Vector3::new(v.x, v.y, v.z)
}

/// The closest surface point to a query point.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceHit {
    /// The closest point on the surface, m.
    pub point: Point3,
    /// Outward unit normal of the triangle hit.
    pub normal: Vector3,
    /// Particles (simulation vertex ids) of the triangle and the point's barycentric weights.
    pub vertices: [u32; 3],
    /// The point's barycentric weights on those particles (summing to 1).
    pub weights: [f64; 3],
    /// The distance from the query point to `point`, m.
    pub distance_m: f64,
}

impl SurfaceHit {
    /// The same material point of the surface at `positions`, which moves with the tissue:
    /// the triangle's particles weighted as at the hit, and the outward normal of the
    /// triangle as it is now (the hit's normal when the triangle has collapsed). None when a
    /// particle is not in `positions` or a coordinate is not finite.
    pub fn moved(&self, positions: &[Point3]) -> Option<(Point3, Vector3)> {
        let [a, b, c] = self.vertices.map(|v| positions.get(v as usize).copied());
        let (a, b, c) = (a?, b?, c?);
        let point = Point3::from(
            a.coords * self.weights[0] + b.coords * self.weights[1] + c.coords * self.weights[2],
        );
        let normal = (b - a)
            .cross(&(c - a))
            .try_normalize(1e-18)
            .unwrap_or(self.normal);
        (point.iter().chain(normal.iter()).all(|x| x.is_finite())).then_some((point, normal))
    }
}

/// The surface collider.
#[derive(Debug)]
pub struct SurfaceCollider {
    /// Simulation vertex id of each collider vertex.
    vertex_ids: Vec<u32>,
    /// The region of each collider vertex (see [`Self::vertex_regions`]).
    vertex_regions: Vec<u32>,
    mesh: TriMesh,
    /// Collider positions, reused by every refit.
    scratch: Vec<PVec>,
    /// Springs around each simulation vertex.
    springs_at: Csr,
    /// Rebuilds so far (one at construction, one per surface-changing cut, and the periodic
    /// ones of a recorded session, [`crate::SessionConfig::collider_rebuild_every_steps`]).
    pub rebuilds: u64,
}

impl SurfaceCollider {
    /// Builds the collider over `sim`'s current surface and positions.
    pub fn build(sim: &Simulation) -> Result<Self, HapticsError> {
        let mut me = Self {
            vertex_ids: Vec::new(),
            vertex_regions: Vec::new(),
            mesh: TriMesh::new(vec![PVec::ZERO; 3], vec![[0, 1, 2]])
                .map_err(|e| HapticsError::Surface(e.to_string()))?,
            scratch: Vec::new(),
            springs_at: Csr::default(),
            rebuilds: 0,
        };
        me.rebuild(sim)?;
        Ok(me)
    }

    /// Rebuilds the triangle mesh and its BVH from the simulation's surface (after a cut).
    pub fn rebuild(&mut self, sim: &Simulation) -> Result<(), HapticsError> {
        let mesh = &sim.model.mesh;
        let boundary = &mesh.topology().boundary;
        if boundary.is_empty() {
            return Err(HapticsError::Surface(
                "the mesh has no boundary triangles".into(),
            ));
        }
        let n = mesh.vertex_count();
        let mut local = vec![u32::MAX; n];
        self.vertex_ids.clear();
        let mut triangles = Vec::with_capacity(boundary.len());
        for tri in boundary {
            let mut t = [0u32; 3];
            for (k, &v) in tri.iter().enumerate() {
                if local[v as usize] == u32::MAX {
                    local[v as usize] = self.vertex_ids.len() as u32;
                    self.vertex_ids.push(v);
                }
                t[k] = local[v as usize];
            }
            triangles.push(t);
        }
        self.vertex_regions = self
            .vertex_ids
            .iter()
            .map(|&v| most_common_region(mesh, v))
            .collect();
        let x = &sim.state.positions;
        let vertices: Vec<PVec> = self
            .vertex_ids
            .iter()
            .map(|&v| to_parry(&x[v as usize]))
            .collect();
        self.scratch.clone_from(&vertices);
        self.mesh = TriMesh::with_flags(vertices, triangles, TriMeshFlags::DEFORMABLE)
            .map_err(|e| HapticsError::Surface(e.to_string()))?;

        // springs around each vertex, for the local stiffness
        self.springs_at = sim.model.springs.by_particle(n);
        self.rebuilds += 1;
        Ok(())
    }

    /// Moves the collider's vertices to the simulation's positions and refits the BVH (no
    /// allocation once built); skipped when no surface particle moved (a localised
    /// simulation leaves the sleeping surface where it was). Returns whether it refitted.
    pub fn refit(&mut self, positions: &[Point3]) -> bool {
        let mut moved = false;
        for (dst, &v) in self.scratch.iter_mut().zip(&self.vertex_ids) {
            let p = to_parry(&positions[v as usize]);
            moved |= *dst != p;
            *dst = p;
        }
        if moved {
            self.mesh.set_vertices(&self.scratch);
        }
        moved
    }

    /// The simulation particles on the surface.
    pub fn vertex_ids(&self) -> &[u32] {
        &self.vertex_ids
    }

    /// The region of each surface vertex, in the order of [`Self::vertex_ids`]: the most
    /// common among its tetrahedra (the smallest id of a tie), what the station colours it by.
    pub fn vertex_regions(&self) -> &[u32] {
        &self.vertex_regions
    }

    /// The surface triangles, over [`Self::vertex_ids`] (outward by the right-hand rule).
    pub fn triangles(&self) -> &[[u32; 3]] {
        self.mesh.indices()
    }

    /// Number of surface triangles.
    pub fn triangle_count(&self) -> usize {
        self.mesh.num_triangles()
    }

    /// The closest surface point to `p`, if finite.
    pub fn closest(&self, p: &Point3) -> Option<SurfaceHit> {
        if !p.iter().all(|c| c.is_finite()) {
            return None;
        }
        let (proj, (tri, location)) = self
            .mesh
            .project_local_point_and_get_location(to_parry(p), false);
        let idx = *self.mesh.indices().get(tri as usize)?;
        let triangle = self.mesh.triangle(tri);
        let normal = from_parry(triangle.normal()?);
        let weights = location.barycentric_coordinates().unwrap_or([1.0 / 3.0; 3]);
        let point = Point3::from(from_parry(proj.point));
        Some(SurfaceHit {
            point,
            normal,
            vertices: idx.map(|i| self.vertex_ids[i as usize]),
            weights,
            distance_m: (point - p).norm(),
        })
    }

    /// Where the ray from `origin` along the unit `direction` first meets the surface, within
    /// `max_m`.
    pub fn cast(&self, origin: &Point3, direction: &Vector3, max_m: f64) -> Option<Point3> {
        let ray = Ray::new(
            to_parry(origin),
            PVec::new(direction.x, direction.y, direction.z),
        );
        let toi = self.mesh.cast_local_ray(&ray, max_m, false)?;
        Some(origin + direction * toi)
    }

    /// Local stiffness of the tissue along `normal` at a hit: the springs around the
    /// triangle's particles projected onto the normal, `sum k (n . e)^2`, weighted
    /// barycentrically (held particles are rigid: they count as the stiffest neighbour).
    pub fn stiffness_at(&self, sim: &Simulation, hit: &SurfaceHit) -> f64 {
        let springs = &sim.model.springs;
        let x = &sim.state.positions;
        let mut k = 0.0;
        for (&v, &w) in hit.vertices.iter().zip(&hit.weights) {
            let v = v as usize;
            if v >= self.springs_at.rows() {
                continue;
            }
            let mut kv = 0.0;
            for &s in self.springs_at.row(v) {
                let [a, b] = springs.ends[s as usize];
                let Some(e) = (x[b as usize] - x[a as usize]).try_normalize(1e-15) else {
                    continue;
                };
                kv += springs.stiffness[s as usize] * e.dot(&hit.normal).powi(2);
            }
            k += w * kv;
        }
        k
    }

    /// The contact model around the surface point nearest the tool: of the closest surface
    /// points to `probes` (the proxy, the blade's heel), the one the tool is deepest below or
    /// nearest above (signed distance along the surface's normal, the first on a tie), among
    /// those within `reach_m`; valid when there is one. Returns the model and the hit with the
    /// index of its probe.
    ///
    /// `pressed`: the contact the tool is pressing on, if it is. A contact follows the surface
    /// the tool came through: a closest point on a surface facing away from it with the probe
    /// behind it, inside the tissue (the far side of a thin wall dented by the press), is not
    /// taken; the pressed contact, moved with the tissue ([`SurfaceHit::moved`]), stays
    /// instead. A probe in front of such a surface is outside the tissue (in a wound, between
    /// its walls): that surface is taken.
    pub fn contact_model(
        &self,
        sim: &Simulation,
        probes: &[Point3],
        reach_m: f64,
        source_tick: u64,
        pressed: Option<&SurfaceHit>,
    ) -> (ContactModel, Option<(usize, SurfaceHit)>) {
        let signed = |p: &Point3, h: &SurfaceHit| (p - h.point).dot(&h.normal);
        let kept = pressed.and_then(|h| Some((h, h.moved(&sim.state.positions)?)));
        let mut best: Option<(f64, usize, SurfaceHit)> = None;
        for (i, p) in probes.iter().enumerate() {
            if let Some(mut h) = self.closest(p) {
                if let Some((was, (point, normal))) = kept
                    && h.normal.dot(&normal) < 0.0
                    && signed(p, &h) < 0.0
                {
                    h = SurfaceHit {
                        point,
                        normal,
                        distance_m: (point - p).norm(),
                        ..*was
                    };
                }
                // (a probe out of reach touches nothing: its signed distance to the plane of
                // a far surface says nothing of the tool, and it must not hide a near one)
                if h.distance_m > reach_m {
                    continue;
                }
                let d = signed(p, &h);
                if best.as_ref().is_none_or(|(b, _, _)| d < *b) {
                    best = Some((d, i, h));
                }
            }
        }
        let hit = best.map(|(_, i, h)| (i, h));
        let model = match hit.as_ref().map(|(_, h)| h) {
            Some(h) => ContactModel {
                published: true,
                source_tick,
                at_heel: false,
                valid: true,
                plane_point: h.point,
                plane_normal: h.normal,
                stiffness_newtons_per_m: self.stiffness_at(sim, h),
                ..ContactModel::default()
            },
            _ => ContactModel {
                published: true,
                source_tick,
                ..ContactModel::default()
            },
        };
        (model, hit)
    }
}

/// The most common region among the tetrahedra of vertex `v` (the smallest id of a tie; 0
/// for a vertex of none).
fn most_common_region(mesh: &cutlab_sim::TetMesh, v: u32) -> u32 {
    let regions = mesh.regions();
    let mut counts: Vec<(u32, u32)> = Vec::new();
    for &t in mesh.topology().tets_of_vertex(v) {
        let r = regions[t as usize];
        match counts.iter_mut().find(|(id, _)| *id == r) {
            Some((_, n)) => *n += 1,
            None => counts.push((r, 1)),
        }
    }
    counts
        .into_iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
        .map_or(0, |(id, _)| id)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cutlab_sim::scene::{BuildOptions, Scene};

    #[test]
    fn closest_point_normal_and_refit_on_the_sheet() {
        let scene = Scene::load(
            "sheet",
            BuildOptions {
                min_tets: Some(600),
            },
        )
        .expect("sheet");
        let mut sim = scene.simulation();
        let mut c = SurfaceCollider::build(&sim).expect("collider");
        assert!(c.triangle_count() > 100);
        // the sheet spans 0..100 mm x 0..100 mm x 0..2 mm
        let hit = c.closest(&Point3::new(0.05, 0.05, 0.01)).expect("hit");
        assert!((hit.point.z - 0.002).abs() < 1e-12, "{hit:?}");
        assert!((hit.normal - Vector3::z()).norm() < 1e-9);
        assert!((hit.distance_m - 0.008).abs() < 1e-12);
        assert!((hit.weights.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        let k = c.stiffness_at(&sim, &hit);
        assert!(k > 10.0 && k < 5000.0, "{k}");
        // deform: lift everything 1 mm, refit, the surface follows
        for p in sim.state.positions.iter_mut() {
            p.z += 0.001;
        }
        assert!(c.refit(&sim.state.positions), "moved: refitted");
        assert!(!c.refit(&sim.state.positions), "nothing moved: skipped");
        let hit = c.closest(&Point3::new(0.05, 0.05, 0.01)).expect("hit");
        assert!((hit.point.z - 0.003).abs() < 1e-12, "{hit:?}");
        assert!(c.closest(&Point3::new(f64::NAN, 0.0, 0.0)).is_none());
        let (far, _) = c.contact_model(&sim, &[Point3::new(0.05, 0.05, 1.0)], 0.05, 7, None);
        assert!(far.published && !far.valid && far.source_tick == 7);
        // the tip 1 mm above the surface (z = 3 mm), the blade's heel 0.5 mm into it: the
        // contact is under the heel; with the heel higher, under the tip
        let tip = Point3::new(0.03, 0.05, 0.004);
        let heel = Point3::new(0.05, 0.05, 0.0025);
        let (m, hit) = c.contact_model(&sim, &[tip, heel], 0.005, 8, None);
        let (probe, hit) = hit.expect("hit");
        assert!(
            m.valid && probe == 1 && (hit.point - Point3::new(0.05, 0.05, 0.003)).norm() < 1e-12,
            "{hit:?}"
        );
        let (m, hit) = c.contact_model(
            &sim,
            &[tip, heel + Vector3::new(0.0, 0.0, 0.01)],
            0.005,
            8,
            None,
        );
        let (probe, hit) = hit.expect("hit");
        assert!(
            m.valid && probe == 0 && (hit.point - Point3::new(0.03, 0.05, 0.003)).norm() < 1e-12
        );
        // pressed deep into the sheet (now 1..3 mm), the tip is nearer the bottom face: the
        // contact stays on the top, where the tool came in, and moves with the tissue
        let (_, top) = c.contact_model(&sim, &[Point3::new(0.05, 0.05, 0.0035)], 0.005, 9, None);
        let (_, top) = top.expect("hit");
        assert!(top.normal.z > 0.99, "{top:?}");
        let deep = Point3::new(0.05, 0.05, 0.0013);
        let (m, hit) = c.contact_model(&sim, &[deep], 0.005, 10, None);
        assert!(
            m.valid && m.plane_normal.z < -0.99,
            "unpressed, the nearest face is the bottom: {m:?} {hit:?}"
        );
        for p in sim.state.positions.iter_mut() {
            p.z -= 0.0005;
        }
        let (m, hit) = c.contact_model(&sim, &[deep], 0.005, 11, Some(&top));
        assert!(
            m.valid && m.plane_normal.z > 0.99 && (m.plane_point.z - 0.0025).abs() < 1e-12,
            "pressed, the top, moved: {m:?} {hit:?}"
        );
        assert_eq!(hit.expect("hit").1.vertices, top.vertices);
    }

    /// A long blade pressed into the mouth of its wound: the tip between the wound's walls, the
    /// heel far above the tissue. The heel's closest surface point is on a wall's top edge far
    /// away, and its signed distance along that wall's normal is a small sideways offset that
    /// may be below the tip's; it must not be taken for the contact (before, it was, and being
    /// out of reach it left the blade in "free space": the re-pressed blade did not cut).
    #[test]
    fn a_probe_out_of_reach_does_not_hide_the_tips_contact_in_a_wound() {
        let scene = Scene::load(
            concat!(env!("CARGO_MANIFEST_DIR"), "/tests/block.toml"),
            BuildOptions {
                min_tets: Some(1500),
            },
        )
        .expect("block");
        let mut sim = scene.simulation();
        let (lo, hi) = sim.model.mesh.bounding_box();
        let (cy, top) = (0.5 * (lo.y + hi.y) + 0.0003, hi.z);
        let mut cutter = cutlab_sim::cut::Cutter::new(cutlab_sim::cut::CutOptions::default());
        for k in 0..=80 {
            let x = lo.x + 0.015 + 0.03 * f64::from(k) / 80.0;
            let blade = cutlab_sim::cut::blade(Point3::new(x, cy, top - 0.008), Vector3::z(), 0.06);
            match cutter.advance(&mut sim, blade) {
                Ok(_) | Err(cutlab_sim::cut::CutError::Unresolved(_)) => {}
                Err(e) => panic!("step {k}: {e}"),
            }
            sim.step().expect("step");
        }
        cutter.end_stroke();
        for _ in 0..300 {
            sim.step().expect("settling");
        }
        let c = SurfaceCollider::build(&sim).expect("collider");
        let reach_m = 0.02;
        let signed = |p: &Point3, h: &SurfaceHit| (p - h.point).dot(&h.normal);
        let mut heel_below_tip = 0;
        for i in 0..40 {
            for (depth_mm, lean_mm) in [(1.0, -0.5), (2.0, -0.25), (3.0, 0.25), (4.0, 0.5)] {
                let x = lo.x + 0.02 + 0.02 * f64::from(i) / 40.0;
                let tip = Point3::new(x, cy, top - depth_mm * 1e-3);
                let heel = tip + Vector3::new(0.0, lean_mm * 1e-3, 0.06);
                let (Some(t), Some(h)) = (c.closest(&tip), c.closest(&heel)) else {
                    panic!("no surface near {tip:?} or {heel:?}");
                };
                heel_below_tip += usize::from(signed(&heel, &h) < signed(&tip, &t));
                let (m, hit) = c.contact_model(&sim, &[tip, heel], reach_m, 1, None);
                assert!(
                    m.valid && hit.is_some_and(|(probe, _)| probe == 0),
                    "tip {tip:?} ({t:?}) heel {heel:?} ({h:?}): {m:?}"
                );
            }
        }
        assert!(heel_below_tip > 0, "the case never arose");
    }
}
