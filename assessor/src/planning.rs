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
use cutlab_sim::scene::Scene;

use crate::error::{AssessError, Result};
use crate::input::SurfaceMesh;
use crate::metrics::exposure::{Ellipsoid, exposure};
use crate::metrics::field::trimesh;

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
    /// `spare`, by name.
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
        let bad = |m: &str| Err(AssessError::InvalidInput(m.into()));
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
    candidate.check()?;
    if let Some(w) = opening.retract_m
        && !(w.is_finite() && (0.0..=0.2).contains(&w))
    {
        return Err(AssessError::InvalidInput(format!(
            "retract_m: from 0 to 0.2 m, got {w}"
        )));
    }
    let target = scene.targets.first().ok_or_else(|| {
        AssessError::InvalidInput(format!("scene {:?} has no target", scene.spec.name))
    })?;
    let view = scene.viewpoint.as_ref().ok_or_else(|| {
        AssessError::InvalidInput(format!("scene {:?} has no viewpoint", scene.spec.name))
    })?;
    let (up, _) = scene
        .spec
        .incision
        .unit()
        .map_err(|e| AssessError::InvalidInput(e.to_string()))?;
    let mut sim = scene.simulation();
    on_tissue(&surface(&sim)?, candidate)?;
    let stations = candidate.stations();
    let damaged = stroke(&mut sim, scene, &stations, candidate.depth_m, &up)?;
    let dt_s = sim.settings.time_step_s;
    let steps = |s: f64| (s.max(0.0) / dt_s).round() as usize;
    for _ in 0..steps(opening.open_s) {
        sim.step()
            .map_err(|e| AssessError::InvalidInput(format!("the opening wound: {e}")))?;
    }
    let sight = Sight {
        heart: Ellipsoid {
            centre_m: Point3::from(target.centre_mm) * 1e-3,
            radii_m: Vector3::from(target.radii_mm) * 1e-3,
        },
        eye: Point3::from(view.eye_mm) * 1e-3,
        middle: stations[stations.len() / 2],
        up,
    };
    let unretracted = sight.view(&sim)?;
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
                .map_err(|e| AssessError::InvalidInput(format!("the retracted wound: {e}")))?;
            Some(sight.view(&sim)?)
        }
    };
    Ok(FieldReport {
        target: target.name.clone(),
        unretracted,
        retractor_width_m: opening.retract_m,
        retracted,
        incision_length_m: candidate.length_m(),
        damaged,
    })
}

/// Refuses a candidate whose points are off the tissue's surface.
fn on_tissue(skin: &TriMesh, candidate: &CandidateIncision) -> Result<()> {
    for (i, p) in candidate.incision_m.iter().enumerate() {
        let at = PVec::new(p[0], p[1], p[2]);
        if skin.distance_to_local_point(at, true) > ON_TISSUE_M {
            return Err(AssessError::InvalidInput(format!(
                "incision_m[{i}]: {p:?} is more than {} mm off the tissue's surface",
                ON_TISSUE_M * 1e3
            )));
        }
    }
    Ok(())
}

/// The target, the eye, and where the approach is measured from.
struct Sight {
    heart: Ellipsoid,
    eye: Point3<f64>,
    middle: Point3<f64>,
    up: Vector3<f64>,
}

impl Sight {
    /// What the eye sees of the target through the tissue as it is now.
    fn view(&self, sim: &cutlab_sim::solver::Simulation) -> Result<View> {
        let seen = exposure(&surface(sim)?, &self.heart, &self.eye, TARGET_SAMPLES);
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
            Err(e) => return Err(AssessError::InvalidInput(format!("cutting: {e}"))),
        }
        watch.blade_stop(cutter.stop().map(|s| s.region), &mut harm);
        sim.step()
            .map_err(|e| AssessError::InvalidInput(format!("the cut tissue: {e}")))?;
    }
    let mut hit: Vec<u32> = harm.iter().map(|d| d.region).collect();
    hit.sort_unstable();
    hit.dedup();
    Ok(hit.into_iter().map(|r| scene.spec.region_name(r)).collect())
}
