//! Planning (issue 62): a candidate incision cut in the simulation by a scripted stroke, the
//! wound left to open, and the field it gives ([`crate::metrics::exposure`]), so that a
//! surgeon compares candidates before any trainee cuts (`cutlab plan field`).
//!
//! The stroke follows the candidate's line on the skin at 1 mm steps, one simulation step
//! each; the blade stands along the scene's `up` (its incision directions) with its tip the
//! candidate's depth below the line and its edge reaching [`ABOVE_M`] above it. Tissue a
//! scalpel does not cut stops it (the bone is touched: damage); a region marked `spare` that
//! the stroke splits is damaged too.

use nalgebra::{Point3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh;
use serde::{Deserialize, Serialize};

use cutlab_haptics::damage::DamageWatch;
use cutlab_sim::cut::{self, Cutter};
use cutlab_sim::retractor::Retractor;
use cutlab_sim::scene::{Scene, SceneSpec};

use crate::error::{Result, ScoreError};
use crate::input::SurfaceMesh;
use crate::metrics::exposure::{Ellipsoid, exposure};
use crate::metrics::field::trimesh;

pub mod picture;

pub use picture::{Camera, Picture};

/// How far above the skin the blade's edge reaches, m.
pub const ABOVE_M: f64 = 0.02;
/// A candidate's points must lie this near the tissue's surface, m.
pub const ON_TISSUE_M: f64 = 0.005;
/// The stroke's step along the line, m.
pub const STEP_M: f64 = 0.001;
/// Samples of the target's surface across `theta` (twice as many across `phi`).
pub const TARGET_SAMPLES: usize = 60;

/// A candidate incision, as a file holds it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CandidateIncision {
    /// The line on the skin, m (at least two points).
    pub incision_m: Vec<[f64; 3]>,
    /// How deep the blade's tip goes below the line, m.
    pub depth_m: f64,
}

/// What the viewpoint sees of the target through the opening, at one moment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct View {
    /// The target's area seen from the viewpoint through the opening, m^2.
    pub target_visible_area_m2: f64,
    /// That over the target's area facing the viewpoint.
    pub target_visible_fraction: f64,
    /// The widest straight instrument that reaches the seen target, m.
    pub working_width_m: f64,
    /// The angle between the way into the body (`-up`) and the line from the incision's
    /// middle to the seen part of the target, degrees; none when nothing is seen.
    pub approach_angle_deg: Option<f64>,
}

/// The field a candidate gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldReport {
    /// The target the figures are of (the scene's first).
    pub target: String,
    /// The field once the wound has opened under the tissue's own tension.
    #[serde(flatten)]
    pub unretracted: View,
    /// The width a retractor spread the wound's middle to, m, when one was set.
    pub retractor_width_m: Option<f64>,
    /// The field with the retractor open.
    pub retracted: Option<View>,
    /// The incision's length on the skin, m.
    pub incision_length_m: f64,
    /// What the stroke damaged: the regions it stopped on (bone) or split though marked
    /// `spare`, and the structures behind the wall the blade's tip entered (the target,
    /// one to spare: the lung), by name.
    pub damaged: Vec<String>,
}

/// How a candidate is cut and opened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opening {
    /// How long the wound opens under the tissue's tension before the field is measured, s.
    pub open_s: f64,
    /// The width a retractor then spreads the wound's middle to, m (none: no retractor).
    pub retract_m: Option<f64>,
}

impl CandidateIncision {
    /// Checks the numbers, naming the field at fault.
    pub fn check(&self) -> Result<()> {
        let bad = |m: &str| Err(ScoreError::InvalidInput(m.into()));
        if self.incision_m.len() < 2 {
            return bad("incision_m: needs at least two points");
        }
        if let Some(i) = self
            .incision_m
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return bad(&format!("incision_m[{i}]: not a finite point"));
        }
        if !(self.depth_m > 0.0 && self.depth_m.is_finite() && self.depth_m < 0.2) {
            return bad("depth_m: must be above 0 and below 0.2 m");
        }
        if self.length_m() < 1e-3 {
            return bad("incision_m: the line is shorter than 1 mm");
        }
        Ok(())
    }

    /// The line's length, m.
    pub fn length_m(&self) -> f64 {
        let line: Vec<Point3<f64>> = self.incision_m.iter().map(|&p| p.into()).collect();
        crate::geom::polyline_length(&line)
    }

    /// Points along the line every [`STEP_M`] (and its last point).
    fn stations(&self) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        for w in self.incision_m.windows(2) {
            let (a, b) = (Point3::from(w[0]), Point3::from(w[1]));
            let n = ((b - a).norm() / STEP_M).ceil().max(1.0) as usize;
            out.extend((0..n).map(|k| a + (b - a) * (k as f64 / n as f64)));
        }
        out.extend(self.incision_m.last().map(|&p| Point3::from(p)));
        out
    }
}

/// A scene's skin at rest as a map: a point on it is named by its coordinates `(a, b)` along
/// the scene's `along` and `side = up x along` (m), as a planner draws on the skin seen from
/// above, and laid on the skin along `-up`.
#[derive(Debug, Clone)]
pub struct SkinMap {
    skin: TriMesh,
    up: Vector3<f64>,
    along: Vector3<f64>,
    side: Vector3<f64>,
}

/// How far above the scene's origin a map's rays start, m.
const MAP_ABOVE_M: f64 = 1.0;

impl SkinMap {
    /// The map of `scene`'s tissue before anything touched it.
    pub fn of(scene: &Scene) -> Result<Self> {
        Self::of_simulation(&scene.spec, &scene.simulation())
    }

    /// The map of `sim`'s tissue as it is now, in `scene`'s directions.
    pub fn of_simulation(scene: &SceneSpec, sim: &cutlab_sim::solver::Simulation) -> Result<Self> {
        let (up, along) = scene
            .incision
            .unit()
            .map_err(|e| ScoreError::InvalidInput(e.to_string()))?;
        Ok(Self {
            skin: surface(sim)?,
            up,
            along,
            side: up.cross(&along),
        })
    }

    /// The skin's point over `(a_m, b_m)`; none off the tissue or for a non-finite input.
    pub fn point(&self, a_m: f64, b_m: f64) -> Option<[f64; 3]> {
        if !(a_m.is_finite() && b_m.is_finite()) {
            return None;
        }
        let from = Point3::from(self.along * a_m + self.side * b_m + self.up * MAP_ABOVE_M);
        let down = -self.up;
        let t = parry3d_f64::query::RayCast::cast_local_ray(
            &self.skin,
            &crate::metrics::exposure::ray(&from, &down),
            2.0 * MAP_ABOVE_M,
            false,
        )?;
        Some((from + down * t).into())
    }

    /// `p`'s coordinates on the map, m.
    pub fn across(&self, p: &[f64; 3]) -> [f64; 2] {
        let p = Vector3::from(*p);
        [p.dot(&self.along), p.dot(&self.side)]
    }

    /// The tissue's extent on the map: the least and the greatest `(a, b)`, m.
    pub fn extent_m(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for v in self.skin.vertices() {
            let ab = self.across(&[v.x, v.y, v.z]);
            for k in 0..2 {
                lo[k] = lo[k].min(ab[k]);
                hi[k] = hi[k].max(ab[k]);
            }
        }
        (lo, hi)
    }

    /// The scene's viewpoint looking at the map's middle at the height of the skin's
    /// outermost point (over an opened wound too) and framing the whole map with a tenth to
    /// spare, so that every candidate on it is pictured alike (see [`Camera::of_scene`]).
    pub fn camera(&self, scene: &SceneSpec, size_px: u32) -> Option<Camera> {
        let (lo, hi) = self.extent_m();
        let top = self
            .skin
            .vertices()
            .iter()
            .map(|v| Vector3::new(v.x, v.y, v.z).dot(&self.up))
            .fold(f64::NEG_INFINITY, f64::max);
        let middle =
            self.along * 0.5 * (lo[0] + hi[0]) + self.side * 0.5 * (lo[1] + hi[1]) + self.up * top;
        let half_width_m = 0.55 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
        Camera::of_scene(scene, middle.into(), half_width_m, size_px)
    }
}

/// The tissue's surface as it is now.
fn surface(sim: &cutlab_sim::solver::Simulation) -> Result<TriMesh> {
    trimesh(&SurfaceMesh::of(sim))
}

/// Cuts `candidate` in `scene`, lets the wound open and measures the field; with a
/// retractor, spreads the wound and measures it again.
pub fn field_of(
    scene: &Scene,
    candidate: &CandidateIncision,
    opening: Opening,
) -> Result<FieldReport> {
    Ok(field_pictured(scene, candidate, opening, None)?.0)
}

/// [`field_of`], and the field as `camera` sees it at each measure (the opened wound, then
/// the retracted one when a retractor was set); no pictures without a camera.
pub fn field_pictured(
    scene: &Scene,
    candidate: &CandidateIncision,
    opening: Opening,
    camera: Option<&Camera>,
) -> Result<(FieldReport, Vec<Picture>)> {
    candidate.check()?;
    if let Some(w) = opening.retract_m
        && !(w.is_finite() && (0.0..=0.2).contains(&w))
    {
        return Err(ScoreError::InvalidInput(format!(
            "retract_m: from 0 to 0.2 m, got {w}"
        )));
    }
    let target = scene.targets.iter().find(|t| !t.spare).ok_or_else(|| {
        ScoreError::InvalidInput(format!("scene {:?} has no target", scene.spec.name))
    })?;
    let view = scene.viewpoint.as_ref().ok_or_else(|| {
        ScoreError::InvalidInput(format!("scene {:?} has no viewpoint", scene.spec.name))
    })?;
    let (up, _) = scene
        .spec
        .incision
        .unit()
        .map_err(|e| ScoreError::InvalidInput(e.to_string()))?;
    let mut sim = scene.simulation();
    on_tissue(&surface(&sim)?, candidate)?;
    let stations = candidate.stations();
    let mut damaged = stroke(&mut sim, scene, &stations, candidate.depth_m, &up)?;
    for t in &scene.targets {
        let inside = |p: &Point3<f64>| ellipsoid(t).contains(&(p - up * candidate.depth_m));
        if stations.iter().any(inside) {
            damaged.push(t.name.clone());
        }
    }
    let dt_s = sim.settings.time_step_s;
    let steps = |s: f64| (s.max(0.0) / dt_s).round() as usize;
    for _ in 0..steps(opening.open_s) {
        sim.step()
            .map_err(|e| ScoreError::InvalidInput(format!("the opening wound: {e}")))?;
    }
    let sight = Sight {
        heart: ellipsoid(target),
        spare: scene
            .targets
            .iter()
            .filter(|t| t.spare)
            .map(ellipsoid)
            .collect(),
        eye: Point3::from(view.eye_mm) * 1e-3,
        middle: stations[stations.len() / 2],
        up,
        camera: camera.copied(),
    };
    let mut pictures = Vec::new();
    let unretracted = sight.view(scene, &sim, &mut pictures)?;
    let retracted = match opening.retract_m {
        None => None,
        Some(width_m) => {
            let retractor = Retractor {
                line_m: candidate
                    .incision_m
                    .iter()
                    .map(|&p| Point3::from(p))
                    .collect(),
                up,
                width_m,
            };
            retractor
                .open(&mut sim)
                .map_err(|e| ScoreError::InvalidInput(format!("the retracted wound: {e}")))?;
            Some(sight.view(scene, &sim, &mut pictures)?)
        }
    };
    let report = FieldReport {
        target: target.name.clone(),
        unretracted,
        retractor_width_m: opening.retract_m,
        retracted,
        incision_length_m: candidate.length_m(),
        damaged,
    };
    Ok((report, pictures))
}

/// Refuses a candidate whose points are off the tissue's surface.
fn on_tissue(skin: &TriMesh, candidate: &CandidateIncision) -> Result<()> {
    for (i, p) in candidate.incision_m.iter().enumerate() {
        let at = PVec::new(p[0], p[1], p[2]);
        if skin.distance_to_local_point(at, true) > ON_TISSUE_M {
            return Err(ScoreError::InvalidInput(format!(
                "incision_m[{i}]: {p:?} is more than {} mm off the tissue's surface",
                ON_TISSUE_M * 1e3
            )));
        }
    }
    Ok(())
}

/// A scene's target (in mm) as an ellipsoid in m.
fn ellipsoid(t: &cutlab_sim::scene::Target) -> Ellipsoid {
    Ellipsoid {
        centre_m: Point3::from(t.centre_mm) * 1e-3,
        radii_m: Vector3::from(t.radii_mm) * 1e-3,
    }
}

/// The target, the structures to spare beside it, the eye, and where the approach is
/// measured from.
struct Sight {
    heart: Ellipsoid,
    spare: Vec<Ellipsoid>,
    eye: Point3<f64>,
    middle: Point3<f64>,
    up: Vector3<f64>,
    camera: Option<Camera>,
}

impl Sight {
    /// What the eye sees of the target through the tissue as it is now; with a camera, its
    /// picture is added to `pictures`.
    fn view(
        &self,
        scene: &Scene,
        sim: &cutlab_sim::solver::Simulation,
        pictures: &mut Vec<Picture>,
    ) -> Result<View> {
        let tissue = surface(sim)?;
        if let Some(camera) = &self.camera {
            let shown =
                picture::Shown::new(&scene.spec, sim, &tissue, &self.heart, &self.spare, self.up);
            pictures.push(picture::render(&shown, camera));
        }
        let seen = exposure(&tissue, &self.heart, &self.eye, TARGET_SAMPLES);
        let approach_angle_deg = seen.visible_centroid_m.map(|c| {
            let to = c - self.middle;
            (to.dot(&-self.up) / to.norm())
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        });
        Ok(View {
            target_visible_area_m2: seen.visible_area_m2,
            target_visible_fraction: seen.visible_fraction,
            working_width_m: seen.working_width_m,
            approach_angle_deg,
        })
    }
}

/// The scripted stroke through `stations`, the tip `depth_m` below them; returns the names of
/// what it damaged.
fn stroke(
    sim: &mut cutlab_sim::solver::Simulation,
    scene: &Scene,
    stations: &[Point3<f64>],
    depth_m: f64,
    up: &Vector3<f64>,
) -> Result<Vec<String>> {
    let (mut watch, mut harm) = (DamageWatch::default(), Vec::new());
    let mut cutter = Cutter::default();
    for p in stations {
        let blade = cut::blade(p - up * depth_m, *up, depth_m + ABOVE_M);
        let regions = sim.model.mesh.regions().to_vec();
        match cutter.advance(sim, blade) {
            Ok(event) => watch.after_cut(&sim.model, &regions, &event, &mut harm),
            Err(cut::CutError::Unresolved(_)) => {}
            Err(e) => return Err(ScoreError::InvalidInput(format!("cutting: {e}"))),
        }
        watch.blade_stop(cutter.stop().map(|s| s.region), &mut harm);
        sim.step()
            .map_err(|e| ScoreError::InvalidInput(format!("the cut tissue: {e}")))?;
    }
    let mut hit: Vec<u32> = harm.iter().map(|d| d.region).collect();
    hit.sort_unstable();
    hit.dedup();
    Ok(hit.into_iter().map(|r| scene.spec.region_name(r)).collect())
}
