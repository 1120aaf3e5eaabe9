//! The `field` kind's metrics (issue 62): what the opened wound shows of the target, wherever
//! the trainee placed the incision, what the incision cost, and the harm done. None of them
//! measures a distance to the expert's line: an incision elsewhere that shows as much for no
//! more length and no harm scores as well.
//!
//! - the field: the target's area `A` seen from the viewpoint through the deformed tissue's
//!   surface at the end of the attempt ([`super::exposure`]); `A / A_expert`, the plan's
//!   reference (what the expert's incision shows), is the scored figure; the working width
//!   and the approach angle (between `-n` and the line from the incision's middle to the seen
//!   part's centroid) are reported;
//! - the incision's length on the skin: the largest distance between two points of the cut's
//!   trace, seen along the plan's normal `n` (a cut gone over twice is not longer);
//! - the deepest cut below the surface, and whether it went through the wall (`>= wall_m`);
//! - harm: the times the blade came down on bone, and the critical harm: each structure to
//!   spare cut or touched (the lung), and the target itself touched (a pose's tip inside
//!   its ellipsoid).

use nalgebra::{Point3, Vector3};

use super::exposure::{Ellipsoid, exposure};
use super::incision::trace_point;
use super::{Better, Metric, Values, m};
use crate::geom;
use crate::input::AttemptData;
use cutlab_haptics::damage::DamageKind;

/// Samples of the target across `theta` for the field (twice as many across `phi`).
pub const TARGET_SAMPLES: usize = 60;

/// The kind's metrics, in report order.
pub const METRICS: &[Metric] = &[
    m(
        "field_of_expert",
        "1",
        Better::HigherIsBetter,
        true,
        "the target's area seen through the opening at the end, over what the expert's incision shows",
    )
    .labelled("Field (of the expert's)")
    .shown_in("%", 100.0),
    m(
        "field_area_m2",
        "m^2",
        Better::HigherIsBetter,
        false,
        "the target's area seen from the viewpoint through the opening at the end",
    )
    .labelled("Target seen"),
    m(
        "field_working_width_m",
        "m",
        Better::HigherIsBetter,
        false,
        "the widest straight instrument that reaches the seen target through the opening",
    )
    .labelled("Working width"),
    m(
        "field_approach_deg",
        "deg",
        Better::LowerIsBetter,
        false,
        "angle between straight in and the line from the incision's middle to the seen target",
    )
    .labelled("Approach angle"),
    m(
        "incision_length_m",
        "m",
        Better::LowerIsBetter,
        true,
        "the incision's length on the skin",
    )
    .labelled("Incision length"),
    m(
        "incision_space",
        "1",
        Better::TwoSided,
        false,
        "where the incision's middle lies among the landmarks beside the expert's, in spaces: \
         0 the expert's space, +1 the next in the plan's order (lower), +-0.5 on the mark between",
    )
    .labelled("Space (from the expert's)"),
    m(
        "wall_opened",
        "1",
        Better::HigherIsBetter,
        true,
        "1 when the cut went through the wall's innermost layer, else 0",
    )
    .labelled("Wall opened"),
    m(
        "deepest_cut_m",
        "m",
        Better::HigherIsBetter,
        false,
        "the deepest the blade cut below the surface",
    )
    .labelled("Deepest cut"),
    m(
        "bone_contacts",
        "1",
        Better::LowerIsBetter,
        true,
        "times the blade came down on a rib or a cartilage",
    )
    .labelled("Blade on bone"),
    m(
        "critical_damage",
        "1",
        Better::LowerIsBetter,
        true,
        "structures to spare cut (an artery) or touched (the lung), and touches of the target itself",
    )
    .labelled("Critical damage"),
];

/// What the metrics measure against.
#[derive(Debug, Clone)]
pub struct Field {
    /// The structure to expose.
    pub target: Ellipsoid,
    /// Where it is seen from (m).
    pub eye_m: Point3<f64>,
    /// The skin's outward normal (unit).
    pub normal: Vector3<f64>,
    /// The wall's thickness: a cut this deep opened it (m).
    pub wall_m: f64,
    /// What the expert's incision shows of the target (m^2).
    pub reference_area_m2: f64,
    /// The field is measured with a retractor in the wound
    /// ([`AttemptData::retracted_surface`]).
    pub retracted: bool,
    /// Structures behind the wall not to touch (the lung).
    pub spare: Vec<Ellipsoid>,
}

/// The field metrics of `data` against `field`, but the incision's space (the plan's
/// landmarks place it); returns the incision's middle on the skin, if it was cut.
pub(crate) fn assess(
    field: &Field,
    data: &AttemptData,
    values: &mut Values,
) -> Option<Point3<f64>> {
    let middle = match incision_span(field.normal, data) {
        Some((a, b, length)) => {
            values.set("incision_length_m", length);
            Some(Point3::from((a.coords + b.coords) * 0.5))
        }
        None => {
            values.set("incision_length_m", 0.0);
            None
        }
    };
    let deepest = data
        .cuts
        .iter()
        .map(|c| c.depth_m)
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max);
    values.set("deepest_cut_m", deepest);
    values.set(
        "wall_opened",
        if deepest >= field.wall_m { 1.0 } else { 0.0 },
    );
    harm(field, data, values);
    seen(field, data, middle, values);
    middle
}

/// The incision's ends on the skin and its length: the two points of the cut's trace
/// furthest apart, seen along `normal` (in the plane through the origin across it).
pub fn incision_span(
    normal: Vector3<f64>,
    data: &AttemptData,
) -> Option<(Point3<f64>, Point3<f64>, f64)> {
    let skin: Vec<Point3<f64>> = data
        .cuts
        .iter()
        .map(|c| Point3::from(trace_point(c)))
        .filter(|p| geom::finite(p.coords.as_slice()))
        .map(|p| p - normal * normal.dot(&p.coords))
        .collect();
    span(&skin)
}

/// The two points of `points` furthest apart and their distance (every point against every
/// other, at most 2,000 points: a longer trace is thinned evenly first).
fn span(points: &[Point3<f64>]) -> Option<(Point3<f64>, Point3<f64>, f64)> {
    let every = points.len().div_ceil(2000).max(1);
    let thin: Vec<&Point3<f64>> = points.iter().step_by(every).collect();
    let mut best: Option<(Point3<f64>, Point3<f64>, f64)> = None;
    for (i, a) in thin.iter().enumerate() {
        for b in &thin[i + 1..] {
            let d = nalgebra::distance(*a, *b);
            if best.is_none_or(|(_, _, m)| d > m) {
                best = Some((**a, **b, d));
            }
        }
    }
    best
}

/// The harm: bone contacts, and the critical ones (structures to spare cut, the target
/// touched).
fn harm(field: &Field, data: &AttemptData, values: &mut Values) {
    let count = |kind: DamageKind| data.damage.iter().filter(|d| d.kind == kind).count();
    values.set("bone_contacts", count(DamageKind::BladeOnBone) as f64);
    let touched = std::iter::once(&field.target)
        .chain(&field.spare)
        .filter(|e| {
            data.poses
                .iter()
                .any(|p| e.contains(&Point3::from(p.tip_m)))
        })
        .count();
    values.set(
        "critical_damage",
        (count(DamageKind::SpareCut) + touched) as f64,
    );
}

/// What the eye sees of the target through the tissue's surface at the end.
fn seen(field: &Field, data: &AttemptData, middle: Option<Point3<f64>>, values: &mut Values) {
    let keys = [
        "field_of_expert",
        "field_area_m2",
        "field_working_width_m",
        "field_approach_deg",
    ];
    let (surface, why) = if field.retracted {
        (
            data.retracted_surface.as_ref(),
            "the wound could not be retracted",
        )
    } else {
        (data.surface.as_ref(), "no tissue surface recorded")
    };
    let Some(surface) = surface else {
        values.missing(&keys, why);
        return;
    };
    let tissue = match super::field::trimesh(surface) {
        Ok(t) => t,
        Err(e) => return values.missing(&keys, &e.to_string()),
    };
    let shown = exposure(&tissue, &field.target, &field.eye_m, TARGET_SAMPLES);
    values.set("field_area_m2", shown.visible_area_m2);
    values.set(
        "field_of_expert",
        shown.visible_area_m2 / field.reference_area_m2,
    );
    values.set("field_working_width_m", shown.working_width_m);
    match (shown.visible_centroid_m, middle) {
        (Some(c), Some(from)) => {
            let to = c - from;
            let cos = (to.dot(&-field.normal) / to.norm()).clamp(-1.0, 1.0);
            values.set("field_approach_deg", cos.acos().to_degrees());
        }
        _ => values.missing(&["field_approach_deg"], "nothing of the target is seen"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::{CutSample, DamageEvent, PoseSample, SurfaceMesh};

    fn field() -> Field {
        Field {
            target: Ellipsoid {
                centre_m: Point3::new(0.0, 0.0, -0.08),
                radii_m: Vector3::new(0.03, 0.03, 0.03),
            },
            eye_m: Point3::new(0.0, 0.0, 0.2),
            normal: Vector3::z(),
            wall_m: 0.04,
            reference_area_m2: 1e-4,
            retracted: false,
            spare: vec![Ellipsoid {
                centre_m: Point3::new(0.05, 0.0, -0.07),
                radii_m: Vector3::new(0.02, 0.02, 0.02),
            }],
        }
    }

    fn cut(x: f64, y: f64, depth_m: f64, t_s: f64) -> CutSample {
        CutSample {
            t_s,
            tip_m: [x, y, -depth_m],
            edge_dir: [0.0, 0.0, 1.0],
            depth_m,
            stroke: Some(0),
        }
    }

    /// A square plate at `z` with a `w` x `h` hole round the origin, as a closed surface's
    /// top (enough for the sight lines, which only meet it from above).
    fn plate_with_hole(z: f64, w: f64, h: f64) -> SurfaceMesh {
        let (a, hw, hh) = (0.2, w / 2.0, h / 2.0);
        // outer and inner rectangles, each counter-clockwise
        let outer = [[-a, -a], [a, -a], [a, a], [-a, a]];
        let inner = [[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]];
        let mut vertices_m: Vec<[f64; 3]> = outer.iter().map(|p| [p[0], p[1], z]).collect();
        vertices_m.extend(inner.iter().map(|p| [p[0], p[1], z]));
        let mut triangles = Vec::new();
        for k in 0..4u32 {
            let (o0, o1, i0, i1) = (k, (k + 1) % 4, 4 + k, 4 + (k + 1) % 4);
            triangles.push([o0, o1, i1]);
            triangles.push([o0, i1, i0]);
        }
        SurfaceMesh {
            vertices_m,
            triangles,
        }
    }

    fn assessed(data: &AttemptData) -> Vec<(&'static str, Option<f64>)> {
        let mut values = Values::default();
        assess(&field(), data, &mut values);
        values.0.iter().map(|(k, v, _)| (*k, *v)).collect()
    }

    fn value(v: &[(&'static str, Option<f64>)], key: &str) -> Option<f64> {
        v.iter().find(|(k, _)| *k == key).and_then(|(_, x)| *x)
    }

    /// The same opening anywhere over the target shows the same; a wider one more; the
    /// incision's length is its span on the skin, however often it was gone over; a cut
    /// short of the wall did not open it.
    #[test]
    fn the_field_is_what_the_opening_shows_wherever_it_is() {
        let line = |x0: f64, depth: f64| -> Vec<CutSample> {
            // there and back again over the same 40 mm
            (0..=80)
                .map(|k| {
                    let s = if k <= 40 { k } else { 80 - k };
                    cut(x0 + 0.001 * f64::from(s), 0.0, depth, f64::from(k) * 0.1)
                })
                .collect()
        };
        let data = |w: f64, x0: f64, depth: f64| AttemptData {
            cuts: line(x0, depth),
            surface: Some(plate_with_hole(0.0, 0.04, w)),
            ..AttemptData::default()
        };
        let narrow = assessed(&data(0.005, -0.02, 0.045));
        let wide = assessed(&data(0.015, -0.02, 0.045));
        let area = |v: &[(&'static str, Option<f64>)]| value(v, "field_area_m2").unwrap();
        assert!(area(&narrow) > 0.0 && area(&wide) > 2.0 * area(&narrow));
        let length = value(&narrow, "incision_length_m").unwrap();
        assert!((length - 0.04).abs() < 1e-9, "{length}");
        assert_eq!(value(&narrow, "wall_opened"), Some(1.0));
        let shallow = assessed(&data(0.005, -0.02, 0.02));
        assert_eq!(value(&shallow, "wall_opened"), Some(0.0));
        let ratio = value(&narrow, "field_of_expert").unwrap();
        assert!((ratio - area(&narrow) / 1e-4).abs() < 1e-12);
        assert!(value(&narrow, "field_approach_deg").unwrap() < 5.0);
    }

    /// Each bone contact counts; a structure to spare cut, one to spare touched (the lung)
    /// and the target touched are critical.
    #[test]
    fn harm_is_counted_by_kind() {
        let event = |kind| DamageEvent {
            t_s: 1.0,
            kind,
            structure: "x".into(),
        };
        let pose = |z: f64| PoseSample {
            t_s: 0.0,
            tip_m: [0.0, 0.0, z],
            quat_wxyz: [1.0, 0.0, 0.0, 0.0],
            blade_engaged: true,
        };
        let mut data = AttemptData {
            damage: vec![
                event(DamageKind::BladeOnBone),
                event(DamageKind::BladeOnBone),
                event(DamageKind::SpareCut),
            ],
            poses: vec![pose(-0.02)],
            ..AttemptData::default()
        };
        let v = assessed(&data);
        assert_eq!(value(&v, "bone_contacts"), Some(2.0));
        assert_eq!(value(&v, "critical_damage"), Some(1.0));
        assert_eq!(value(&v, "field_area_m2"), None, "no surface: missing");
        data.poses.push(pose(-0.06));
        assert_eq!(value(&assessed(&data), "critical_damage"), Some(2.0));
        // the lung beside it, touched twice: once more
        let mut lung = pose(-0.06);
        lung.tip_m[0] = 0.05;
        data.poses.extend([lung, lung]);
        assert_eq!(value(&assessed(&data), "critical_damage"), Some(3.0));
    }
}
