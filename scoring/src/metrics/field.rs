//! Surgical-field metrics on the deformed tissue surface after the cut: can the target be
//! seen, and how wide is the opening (working space).
//!
//! The surface becomes a parry [`TriMesh`] (glam `DVec3` appears only in this file).
//! - visible fraction: target point `p` is visible when the segment from the viewpoint `e` to
//!   `p` meets no surface triangle before `p - eps (p - e)/|p - e|`, `eps` = [`VISIBILITY_EPS_M`]
//!   (and neither do two rays to points 20 um beside `p`, see [`visible_fraction`]); the
//!   fraction of the plan's target points that are visible. The target is what the planned
//!   incision lays open ([`IncisionPlan::target_m`]); a target deeper below the planned line
//!   than the planned depth ([`depth_below_plan`], beyond [`TARGET_DEPTH_SLACK_M`]) is behind
//!   tissue an incision as planned leaves whole, so the metric would be 0 for every attempt
//!   that keeps to the plan (the heart behind the 15 mm chest wall, under an 8 mm incision):
//!   it is missing then, with the reason, rather than a 0 that measures the plan.
//! - opening width: at [`OPENING_STATIONS`] stations along the planned line, rays are cast along
//!   `-n` (the plan's normal) from above the surface on a row across the line (perpendicular
//!   to it and to `n`, every [`OPENING_STEP_M`] up to `max(3 x corridor, 10 mm)` to each
//!   side). The row's reference height is the median depth of its hits (the intact surface);
//!   a ray is *in the opening* when it misses the tissue or first hits it more than half the
//!   planned depth below that reference (it went between the lips). The station's width is
//!   the longest run of such rays that does not reach the row's ends, times the step; the
//!   metric is the widest station (m). An unopened cut (faces touching) has width 0.
//! - opening area: the trapezoidal integral of the station widths along the line (m^2),
//!   the opening seen along `n`; approximate (the stations are ~1.5 mm apart on the 60 mm
//!   plan, ends of the wound between stations are linearly interpolated).

use cutlab_sim::stats::percentile;
use nalgebra::{Point3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::TriMesh;

use crate::error::{Result, ScoreError};
use crate::geom;
use crate::incision_plan::IncisionPlan;
use crate::input::SurfaceMesh;
use crate::metrics::Values;
use crate::metrics::incision::depth_below_plan;

/// A target point closer than this to the first hit counts as visible (m).
pub const VISIBILITY_EPS_M: f64 = 1e-4;
/// The sideways offset of the two extra rays per target (m).
pub const VISIBILITY_JITTER_M: f64 = 2e-5;
/// How far below the planned depth a target may lie and still count as laid open by the
/// planned incision (m).
pub const TARGET_DEPTH_SLACK_M: f64 = 1e-4;
/// Stations along the planned line for the opening width.
pub const OPENING_STATIONS: usize = 41;
/// Spacing of the rays across the line (m).
pub const OPENING_STEP_M: f64 = 1e-4;

fn to_parry(v: Vector3<f64>) -> PVec {
    PVec::new(v.x, v.y, v.z)
}

/// The surface as a parry triangle mesh; errors on an empty mesh, non-finite vertices or
/// indices out of range.
pub fn trimesh(surface: &SurfaceMesh) -> Result<TriMesh> {
    if surface.triangles.is_empty() {
        return Err(ScoreError::InvalidInput(
            "the surface has no triangles".into(),
        ));
    }
    if let Some(i) = surface.vertices_m.iter().position(|v| !geom::finite(v)) {
        return Err(ScoreError::InvalidInput(format!(
            "surface vertex {i} is not finite"
        )));
    }
    let n = surface.vertices_m.len();
    if let Some(i) = surface
        .triangles
        .iter()
        .position(|t| t.iter().any(|&v| v as usize >= n))
    {
        return Err(ScoreError::InvalidInput(format!(
            "surface triangle {i} refers to a missing vertex"
        )));
    }
    let vertices: Vec<PVec> = surface
        .vertices_m
        .iter()
        .map(|&v| PVec::from_array(v))
        .collect();
    TriMesh::new(vertices, surface.triangles.clone())
        .map_err(|e| ScoreError::InvalidInput(format!("surface: {e}")))
}

/// Whether the segment from `eye` to `p` passes `mesh` (stopping [`VISIBILITY_EPS_M`] short
/// of `p`).
pub fn seen(mesh: &TriMesh, eye: &Point3<f64>, p: &Point3<f64>) -> bool {
    let d = p - eye;
    let len = d.norm();
    len <= VISIBILITY_EPS_M
        || mesh
            .cast_local_ray(
                &Ray::new(to_parry(eye.coords), to_parry(d)),
                1.0 - VISIBILITY_EPS_M / len,
                false,
            )
            .is_none()
}

/// The fraction of `targets` visible from `eye` past `mesh`; `None` without targets.
///
/// A ray that runs exactly along mesh edges (targets and viewpoint on a grid plane of the
/// mesh) can slip between two triangles. So each target is tested with three rays, to the
/// point itself and to two points [`VISIBILITY_JITTER_M`] away from it across the ray, and is
/// visible only when none of them hits: real openings are much wider than the jitter.
pub fn visible_fraction(mesh: &TriMesh, eye: [f64; 3], targets: &[[f64; 3]]) -> Option<f64> {
    if targets.is_empty() {
        return None;
    }
    let eye = Point3::from(eye);
    let clear = |p: Point3<f64>| seen(mesh, &eye, &p);
    let visible = targets
        .iter()
        .map(|&p| Point3::from(p))
        .filter(|&p| {
            let d = p - eye;
            let helper = if d.x.abs() < 0.9 * d.norm() {
                Vector3::x()
            } else {
                Vector3::y()
            };
            let (Some(u), Some(v)) = (
                geom::unit(d.cross(&helper)),
                geom::unit(d.cross(&d.cross(&helper))),
            ) else {
                return clear(p);
            };
            clear(p) && clear(p + u * VISIBILITY_JITTER_M) && clear(p + v * VISIBILITY_JITTER_M)
        })
        .count();
    Some(visible as f64 / targets.len() as f64)
}

/// The opening's width (widest station, m), area (m^2) and the per-station widths
/// `(arc length along the plan, width)`.
pub fn opening(plan: &IncisionPlan, mesh: &TriMesh) -> (f64, f64, Vec<(f64, f64)>) {
    let n = Vector3::from(plan.normal);
    let line = plan.line();
    let length = geom::polyline_length(&line);
    let half_row = (3.0 * plan.corridor_half_width_m).max(0.01);
    let rays = (half_row / OPENING_STEP_M).round() as i64;
    let above = 0.05 + plan.depth_m;
    let max_toi = above + 0.5;
    let mut widths = Vec::with_capacity(OPENING_STATIONS);
    for k in 0..OPENING_STATIONS {
        let s = length * k as f64 / (OPENING_STATIONS - 1) as f64;
        let (q, tangent) = geom::point_at_arc(&line, s);
        let Some(lateral) = geom::unit(n.cross(&tangent)) else {
            widths.push((s, 0.0));
            continue;
        };
        let hits: Vec<Option<f64>> = (-rays..=rays)
            .map(|i| {
                let origin = q + lateral * (i as f64 * OPENING_STEP_M) + n * above;
                let ray = Ray::new(to_parry(origin.coords), to_parry(-n));
                mesh.cast_local_ray(&ray, max_toi, false)
                    .map(|toi| toi - above)
            })
            .collect();
        let mut depths: Vec<f64> = hits.iter().flatten().copied().collect();
        if depths.is_empty() {
            widths.push((s, 0.0));
            continue;
        }
        depths.sort_by(f64::total_cmp);
        let reference = percentile(&depths, 0.5);
        let open: Vec<bool> = hits
            .iter()
            .map(|h| h.is_none_or(|d| d > reference + 0.5 * plan.depth_m))
            .collect();
        let (mut best, mut run) = (0usize, 0usize);
        for (i, &o) in open.iter().enumerate() {
            if o {
                run += 1;
            } else {
                // a run from the row's start (i == run) is not between two lips
                if run > 0 && i > run {
                    best = best.max(run);
                }
                run = 0;
            }
        }
        widths.push((s, best as f64 * OPENING_STEP_M));
    }
    let width = widths.iter().map(|w| w.1).fold(0.0, f64::max);
    let area = widths
        .windows(2)
        .map(|w| 0.5 * (w[0].1 + w[1].1) * (w[1].0 - w[0].0))
        .sum();
    (width, area, widths)
}

pub(crate) fn assess(plan: &IncisionPlan, surface: Option<&SurfaceMesh>, values: &mut Values) {
    const KEYS: [&str; 3] = [
        "target_visible_fraction",
        "opening_width_m",
        "opening_area_m2",
    ];
    let Some(surface) = surface else {
        values.missing(&KEYS, "no surface recorded");
        return;
    };
    match trimesh(surface) {
        Ok(mesh) => {
            let deepest_m = plan
                .target_m
                .iter()
                .map(|&t| depth_below_plan(plan, t))
                .fold(f64::NEG_INFINITY, f64::max);
            if deepest_m > plan.depth_m + TARGET_DEPTH_SLACK_M {
                values.missing(
                    &["target_visible_fraction"],
                    &format!(
                        "the plan's target lies {:.1} mm below its line, beyond its {:.1} mm \
                         incision: an incision as planned cannot lay it open",
                        deepest_m * 1e3,
                        plan.depth_m * 1e3
                    ),
                );
            } else {
                match visible_fraction(&mesh, plan.viewpoint_m, &plan.target_m) {
                    Some(f) => values.set("target_visible_fraction", f),
                    None => values.missing(
                        &["target_visible_fraction"],
                        "the plan has no target points",
                    ),
                }
            }
            let (width, area, _) = opening(plan, &mesh);
            values.set("opening_width_m", width);
            values.set("opening_area_m2", area);
        }
        Err(e) => values.missing(&KEYS, &e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat top surface at z = 0 over x in [-10, 70] mm, y in [-20, 20] mm with a slot
    /// |y| < 2 mm open for x in [10, 50] mm; optionally a floor at z = -15 mm.
    fn slotted(floor: bool) -> SurfaceMesh {
        let mut s = SurfaceMesh::default();
        let mut rect = |x0: f64, x1: f64, y0: f64, y1: f64, z: f64| {
            let b = s.vertices_m.len() as u32;
            for (x, y) in [(x0, y0), (x1, y0), (x1, y1), (x0, y1)] {
                s.vertices_m.push([x * 1e-3, y * 1e-3, z * 1e-3]);
            }
            s.triangles.push([b, b + 1, b + 2]);
            s.triangles.push([b, b + 2, b + 3]);
        };
        rect(-10.0, 70.0, -20.0, -2.0, 0.0);
        rect(-10.0, 70.0, 2.0, 20.0, 0.0);
        rect(-10.0, 10.0, -2.0, 2.0, 0.0);
        rect(50.0, 70.0, -2.0, 2.0, 0.0);
        if floor {
            rect(-10.0, 70.0, -20.0, 20.0, -15.0);
        }
        s
    }

    fn plan() -> IncisionPlan {
        IncisionPlan::from_json(
            r#"{"entry_m":[0,0,0],"exit_m":[0.06,0,0],"depth_m":0.008,"viewpoint_m":[0.03,0,0.1],
                "target_m":[[0.03,0,-0.025],[0.04,0,-0.025],[0.0,0,-0.025],[0.06,0,-0.025]]}"#,
        )
        .unwrap()
    }

    #[test]
    fn targets_under_the_slot_are_visible_the_others_hidden() {
        let mesh = trimesh(&slotted(false)).unwrap();
        let p = plan();
        assert_eq!(
            visible_fraction(&mesh, p.viewpoint_m, &p.target_m),
            Some(0.5)
        );
        assert_eq!(visible_fraction(&mesh, p.viewpoint_m, &[]), None);
        // through the floor nothing is visible
        let closed = trimesh(&slotted(true)).unwrap();
        assert_eq!(
            visible_fraction(&closed, p.viewpoint_m, &p.target_m),
            Some(0.0)
        );
    }

    /// [`plan`] with its targets moved to `depth_mm` below the surface.
    fn plan_with_targets_at(depth_mm: f64) -> IncisionPlan {
        let mut p = plan();
        for t in &mut p.target_m {
            t[2] = -depth_mm * 1e-3;
        }
        p
    }

    fn visibility(plan: &IncisionPlan, surface: SurfaceMesh) -> crate::metrics::MetricValue {
        let data = crate::input::AttemptData {
            surface: Some(surface),
            ..Default::default()
        };
        let values = crate::ExerciseKind::assess(plan, &data).unwrap();
        values
            .into_iter()
            .find(|v| v.key == "target_visible_fraction")
            .unwrap()
    }

    #[test]
    fn a_cut_lays_its_target_open_and_a_target_beyond_its_depth_is_not_measured() {
        // the target 4 mm down, within the planned 8 mm: seen through the slot (half of its
        // points lie under it), hidden under the intact surface
        let within = plan_with_targets_at(4.0);
        let cut = visibility(&within, slotted(true));
        assert!(cut.value.is_some_and(|v| v > 0.0), "{cut:?}");
        let mut uncut = slotted(true);
        let b = uncut.vertices_m.len() as u32;
        uncut.vertices_m.extend([
            [0.0, -0.003, 0.0],
            [0.07, -0.003, 0.0],
            [0.07, 0.003, 0.0],
            [0.0, 0.003, 0.0],
        ]);
        uncut
            .triangles
            .extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        assert_eq!(visibility(&within, uncut).value, Some(0.0));
        // 25 mm down, behind tissue an 8 mm incision leaves whole: 0 for every attempt that
        // keeps to the plan, so not a measure of the attempt: missing, with the reason
        let beyond = visibility(&plan_with_targets_at(25.0), slotted(true));
        assert!(beyond.value.is_none(), "{beyond:?}");
        assert!(
            beyond
                .missing
                .as_deref()
                .unwrap()
                .contains("beyond its 8.0 mm incision"),
            "{beyond:?}"
        );
    }

    #[test]
    fn the_slot_is_4_mm_wide_and_40_mm_long() {
        for floor in [false, true] {
            let mesh = trimesh(&slotted(floor)).unwrap();
            let (width, area, widths) = opening(&plan(), &mesh);
            assert!((width - 0.004).abs() < 2.5e-4, "{width} {widths:?}");
            assert!((area - 0.004 * 0.040).abs() < 0.1 * 0.004 * 0.040, "{area}");
            assert!(widths[0].1 == 0.0 && widths[20].1 > 0.0035, "{widths:?}");
        }
    }

    #[test]
    fn a_closed_surface_has_no_opening_and_bad_meshes_are_errors() {
        let mut closed = slotted(false);
        let b = closed.vertices_m.len() as u32;
        closed.vertices_m.extend([
            [0.0, -0.003, 0.0],
            [0.07, -0.003, 0.0],
            [0.07, 0.003, 0.0],
            [0.0, 0.003, 0.0],
        ]);
        closed
            .triangles
            .extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        let (width, area, _) = opening(&plan(), &trimesh(&closed).unwrap());
        assert_eq!((width, area), (0.0, 0.0));
        assert!(trimesh(&SurfaceMesh::default()).is_err());
        let mut nan = slotted(false);
        nan.vertices_m[2][0] = f64::NAN;
        assert!(trimesh(&nan).unwrap_err().to_string().contains("vertex 2"));
        let mut out = slotted(false);
        out.triangles.push([0, 1, 999]);
        assert!(trimesh(&out).is_err());
    }
}
