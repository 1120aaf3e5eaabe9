//! Incision metrics: how the cut the simulation made compares with the planned line.
//!
//! The cut's trace is where the blade crossed the tissue surface at each [`CutSample`], in
//! time order: `tip + depth_m * edge_dir` (the blade runs from its tip along `edge_dir`, and
//! the tip is `depth_m` below the surface), or the tip itself when the depth or edge direction
//! is unusable. (On a curved surface, or with a tilted blade, the tip runs beside the line the
//! trainee actually cut on the surface; the surface crossing is that line.) Everything lateral
//! is measured seen from above: points are projected along the plan's unit normal `n` onto a
//! plane, `P(x) = x - (x . n) n`, so the tip's depth below the surface does not count as
//! lateral error. The trace's segments join consecutive samples of one stroke only: a new
//! stroke starts where the blade left the tissue and entered it again, as the recorder saw
//! it ([`CutSample::stroke`]; the simulation cuts along the blade's whole sweep within a
//! stroke, however far the blade moved between two samples), or, for samples without a
//! recorded stroke, where consecutive samples are more than [`STROKE_GAP_M`] apart (blade
//! lifted and put back). Entry, exit, length and the fraction in tolerance all rest on these
//! strokes, so a cut whose ends are on the plan's is as long as the plan's unless the blade
//! left the tissue on the way.
//!
//! - entry / exit error: `|P(first trace point) - P(entry)|`, `|P(last) - P(exit)|`;
//! - length error: the incision's length minus the plan's length (signed). The length is
//!   measured along the projected planned line: each trace point gets the arc-length
//!   coordinate of its nearest point on the line (extended straight beyond both ends), each
//!   segment of a stroke spans the interval between its ends' coordinates, and the length is
//!   the measure of the union of those spans. So going back over a stretch already cut, or a
//!   tremor's zigzag across the line, does not lengthen the incision (the zigzag counts as
//!   lateral deviation); a gap between strokes is not cut;
//! - lateral deviation of sample `i`: the distance from `P(trace_i)` to the projected planned
//!   polyline; its mean, RMS and max over the samples;
//! - fraction cut within tolerance: the planned line is split into intervals of at most
//!   0.1 mm; an interval counts as cut when its midpoint is within `tolerance_m` of the
//!   projected trace; the fraction is the counted length over the plan's length;
//! - direction error: the angle between `P(last - first)` and `P(exit - entry)` (deg);
//! - depth error: the samples' mean `depth_m` (the recorder's penetration below the surface
//!   along `n`, see [`CutSample::depth_m`]) minus the planned depth (signed), and its RMS.
//! - approach error: the angle between the tip's displacement over the last 5 mm of travel
//!   before the first cut and the plan's approach direction (deg). Not measured with a device
//!   whose blade enters the tissue along an orientation the station fixes
//!   ([`device_sets_approach`]: the station page's pointer pushes the tip in along the blade
//!   it holds, so every attempt would show the same angle, the station's).

use std::ops::Range;

use nalgebra::{Point3, Vector3};

use crate::error::{Result, ScoreError};
use crate::geom;
use crate::incision_plan::IncisionPlan;
use crate::input::{CutSample, PoseSample};
use crate::metrics::Values;

/// Consecutive cut samples without a recorded stroke ([`CutSample::stroke`]) further apart
/// than this belong to different strokes (m).
pub const STROKE_GAP_M: f64 = 0.003;
/// The length of approach the approach direction is taken over (m).
pub const APPROACH_LENGTH_M: f64 = 0.005;

/// The incision metrics of one attempt (SI units, angles in degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IncisionMetrics {
    pub entry_error_m: f64,
    pub exit_error_m: f64,
    pub cut_length_m: f64,
    pub length_error_m: f64,
    pub lateral_mean_m: f64,
    pub lateral_rms_m: f64,
    pub lateral_max_m: f64,
    pub fraction_cut_in_tolerance: f64,
    pub direction_error_deg: f64,
    /// `None` when a sample's depth is not finite.
    pub depth_error_m: Option<f64>,
    pub depth_rms_error_m: Option<f64>,
}

/// Where the blade of `c` crossed the surface: `tip + depth_m * edge_dir` when the depth is
/// finite and non-negative and `edge_dir` a finite non-zero vector, else the tip.
pub fn trace_point(c: &CutSample) -> [f64; 3] {
    match geom::unit(c.edge_dir.into()) {
        Some(e) if c.depth_m.is_finite() && c.depth_m >= 0.0 => {
            (Point3::from(c.tip_m) + e * c.depth_m).into()
        }
        _ => c.tip_m,
    }
}

/// Whether the consecutive cut samples `a` then `b`, whose projected trace points are `pa`
/// and `pb`, belong to one stroke: the same recorded stroke when both have one, else no more
/// than [`STROKE_GAP_M`] apart.
pub(crate) fn same_stroke(
    a: &CutSample,
    b: &CutSample,
    pa: &Point3<f64>,
    pb: &Point3<f64>,
) -> bool {
    match (a.stroke, b.stroke) {
        (Some(x), Some(y)) => x == y,
        _ => nalgebra::distance(pa, pb) <= STROKE_GAP_M,
    }
}

/// The trace's strokes: ranges of `cuts` (in time order) and their projected trace points
/// `tips`, split between consecutive samples not of one stroke ([`same_stroke`]).
fn strokes(cuts: &[CutSample], tips: &[Point3<f64>]) -> Vec<Range<usize>> {
    let mut out: Vec<Range<usize>> = Vec::new();
    for (i, p) in tips.iter().enumerate() {
        match out.last_mut() {
            Some(s) if same_stroke(&cuts[i - 1], &cuts[i], &tips[i - 1], p) => s.end = i + 1,
            _ => out.push(i..i + 1),
        }
    }
    out
}

/// Distance from `p` to the nearest point of any stroke of `tips`.
fn distance_to_strokes(p: Point3<f64>, tips: &[Point3<f64>], strokes: &[Range<usize>]) -> f64 {
    let mut best = f64::INFINITY;
    for s in strokes.iter().map(|r| &tips[r.clone()]) {
        if s.len() == 1 {
            best = best.min(nalgebra::distance(&p, &s[0]));
        }
        for w in s.windows(2) {
            best = best.min(nalgebra::distance(
                &p,
                &geom::closest_on_segment(p, w[0], w[1]).0,
            ));
        }
    }
    best
}

/// The tip's depth below the plan's (rest) surface along the normal, `(q - tip) . n` with `q`
/// the planned line's point nearest to the tip seen from above: an approximation of
/// [`CutSample::depth_m`] for recorders without the deformed surface (exact for a line on a
/// flat surface).
pub fn depth_below_plan(plan: &IncisionPlan, tip: [f64; 3]) -> f64 {
    depth_below_line(&plan.incision_m, plan.normal, tip)
}

/// The depth of `tip` below the surface through the line `line_m` (at least one point), along
/// the unit `normal`: as [`depth_below_plan`].
pub fn depth_below_line(line_m: &[[f64; 3]], normal: [f64; 3], tip: [f64; 3]) -> f64 {
    let n = Vector3::from(normal);
    let tip = Point3::from(tip);
    let p = geom::project(tip, &n);
    let mut best = (f64::INFINITY, Point3::from(line_m[0]));
    for w in line_m.windows(2) {
        let (a, b) = (Point3::from(w[0]), Point3::from(w[1]));
        // the nearest point seen from above, then the same parameter on the 3D segment
        let (q, t) = geom::closest_on_segment(p, geom::project(a, &n), geom::project(b, &n));
        let d = nalgebra::distance(&p, &q);
        if d < best.0 {
            best = (d, a + (b - a) * t);
        }
    }
    (best.1 - tip).dot(&n)
}

/// The incision metrics of `cuts` (at least 2, finite tips) against `plan`.
pub fn incision(plan: &IncisionPlan, cuts: &[CutSample]) -> Result<IncisionMetrics> {
    if cuts.len() < 2 {
        return Err(ScoreError::InvalidInput(format!(
            "{} cut samples: no incision to measure",
            cuts.len()
        )));
    }
    if let Some(i) = cuts
        .iter()
        .position(|c| !geom::finite(&c.tip_m) || !c.t_s.is_finite())
    {
        return Err(ScoreError::InvalidInput(format!(
            "cut sample {i}: time or tip not finite"
        )));
    }
    let mut cuts = cuts.to_vec();
    cuts.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let n = Vector3::from(plan.normal);
    let tips: Vec<Point3<f64>> = cuts
        .iter()
        .map(|c| geom::project(trace_point(c).into(), &n))
        .collect();
    let line: Vec<Point3<f64>> = plan
        .incision_m
        .iter()
        .map(|&p| geom::project(p.into(), &n))
        .collect();
    let (entry, exit) = (
        geom::project(plan.entry_m.into(), &n),
        geom::project(plan.exit_m.into(), &n),
    );
    let (first, last) = (tips[0], tips[tips.len() - 1]);
    let strokes = strokes(&cuts, &tips);
    let on_line: Vec<geom::OnLine> = tips
        .iter()
        .map(|&p| geom::closest_on_polyline(p, &line))
        .collect();
    let spans = strokes.iter().flat_map(|r| {
        on_line[r.clone()]
            .windows(2)
            .map(|w| (w[0].arc.min(w[1].arc), w[0].arc.max(w[1].arc)))
    });
    let cut_length_m = geom::union_length(spans.collect());
    let plan_length = geom::polyline_length(&line);

    let lateral: Vec<f64> = on_line.iter().map(|o| o.distance).collect();
    let (lateral_mean_m, lateral_rms_m, lateral_max_m) = geom::mean_rms_max(&lateral);

    let intervals = ((plan_length / 1e-4).ceil() as usize).max(1);
    let step = plan_length / intervals as f64;
    let covered = (0..intervals)
        .filter(|&k| {
            let (mid, _) = geom::point_at_arc(&line, (k as f64 + 0.5) * step);
            distance_to_strokes(mid, &tips, &strokes) <= plan.tolerance_m
        })
        .count();
    let fraction_cut_in_tolerance = covered as f64 / intervals as f64;

    let direction_error_deg =
        geom::angle(last - first, exit - entry).map_or(180.0, f64::to_degrees);

    let depths: Vec<f64> = cuts.iter().map(|c| c.depth_m - plan.depth_m).collect();
    let (depth_error_m, depth_rms_error_m) = if geom::finite(&depths) {
        let (mean, rms, _) = geom::mean_rms_max(&depths);
        (Some(mean), Some(rms))
    } else {
        (None, None)
    };

    Ok(IncisionMetrics {
        entry_error_m: nalgebra::distance(&first, &entry),
        exit_error_m: nalgebra::distance(&last, &exit),
        cut_length_m,
        length_error_m: cut_length_m - plan_length,
        lateral_mean_m,
        lateral_rms_m,
        lateral_max_m,
        fraction_cut_in_tolerance,
        direction_error_deg,
        depth_error_m,
        depth_rms_error_m,
    })
}

/// Whether `device` (as a recording names it; `recording of D` is D's hand played again)
/// sets how the blade enters the tissue, so the trainee cannot: the station page's pointer
/// ([`crate::DeviceClass::Pointer`]: a mouse, a pen or a touch, or the hand model on it; the
/// point under it on the tissue, pushed in along the blade the station holds pointing into
/// the tissue at the plan's entry). The approach angle of an attempt made with one is the
/// station's.
pub fn device_sets_approach(device: &str) -> bool {
    crate::DeviceClass::of(Some(device)) == crate::DeviceClass::Pointer
}

/// The angle (deg) between the tip's displacement over the last [`APPROACH_LENGTH_M`] of
/// travel up to time `t_first_cut` and the plan's approach direction; `None` without poses,
/// with non-finite ones, or if the tip barely moved.
pub fn approach_error_deg(
    plan: &IncisionPlan,
    poses: &[PoseSample],
    t_first_cut: f64,
) -> Option<f64> {
    let before: Vec<&PoseSample> = poses.iter().filter(|p| p.t_s <= t_first_cut).collect();
    let end = Point3::from(before.last()?.tip_m);
    let mut travelled = 0.0;
    let mut start = end;
    for w in before.windows(2).rev() {
        if !geom::finite(&w[0].tip_m) || !geom::finite(&w[1].tip_m) {
            return None;
        }
        let (a, b) = (Point3::from(w[0].tip_m), Point3::from(w[1].tip_m));
        travelled += nalgebra::distance(&a, &b);
        start = a;
        if travelled >= APPROACH_LENGTH_M {
            break;
        }
    }
    if travelled < 0.2 * APPROACH_LENGTH_M {
        return None;
    }
    geom::angle(end - start, plan.approach().into()).map(f64::to_degrees)
}

pub(crate) fn assess(
    plan: &IncisionPlan,
    cuts: &[CutSample],
    poses: &[PoseSample],
    device: Option<&str>,
    values: &mut Values,
) {
    const KEYS: [&str; 10] = [
        "entry_error_m",
        "exit_error_m",
        "length_error_m",
        "lateral_mean_m",
        "lateral_rms_m",
        "lateral_max_m",
        "fraction_cut_in_tolerance",
        "direction_error_deg",
        "depth_error_m",
        "depth_rms_error_m",
    ];
    match incision(plan, cuts) {
        Ok(m) => {
            values.set("entry_error_m", m.entry_error_m);
            values.set("exit_error_m", m.exit_error_m);
            values.set("length_error_m", m.length_error_m);
            values.set("lateral_mean_m", m.lateral_mean_m);
            values.set("lateral_rms_m", m.lateral_rms_m);
            values.set("lateral_max_m", m.lateral_max_m);
            values.set("fraction_cut_in_tolerance", m.fraction_cut_in_tolerance);
            values.set("direction_error_deg", m.direction_error_deg);
            match (m.depth_error_m, m.depth_rms_error_m) {
                (Some(d), Some(r)) => {
                    values.set("depth_error_m", d);
                    values.set("depth_rms_error_m", r);
                }
                _ => values.missing(
                    &["depth_error_m", "depth_rms_error_m"],
                    "a cut depth is not finite",
                ),
            }
        }
        Err(e) => values.missing(&KEYS, &e.to_string()),
    }
    if let Some(d) = device.filter(|d| device_sets_approach(d)) {
        values.not_measured(
            &["approach_error_deg"],
            &format!(
                "the {d} pushes the blade in along the orientation the station fixes, so the \
                 approach is the station's, not the trainee's"
            ),
        );
        return;
    }
    let first_cut = cuts
        .iter()
        .map(|c| c.t_s)
        .filter(|t| t.is_finite())
        .fold(f64::INFINITY, f64::min);
    match approach_error_deg(plan, poses, first_cut).filter(|_| first_cut.is_finite()) {
        Some(a) => values.set("approach_error_deg", a),
        None => values.missing(&["approach_error_deg"], "no approach before a first cut"),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A 60 mm plan along x on flat tissue (the surface z = 0), 8 mm deep.
    pub(crate) fn straight_plan() -> IncisionPlan {
        IncisionPlan::from_json(
            r#"{"entry_m":[0,0,0],"exit_m":[0.06,0,0],"depth_m":0.008,"viewpoint_m":[0,0,0.1]}"#,
        )
        .unwrap()
    }

    /// Cuts every 1 mm along y = `y` from x = `x0` to `x1` (mm), 8 mm deep.
    fn cuts(x0: i32, x1: i32, y: f64, depth: f64) -> Vec<CutSample> {
        (x0..=x1)
            .map(|x| CutSample {
                t_s: x as f64 * 0.01,
                tip_m: [x as f64 * 1e-3, y, -depth],
                edge_dir: [0.0, 0.0, 1.0],
                depth_m: depth,
                stroke: None,
            })
            .collect()
    }

    #[test]
    fn a_parallel_offset_cut_by_hand() {
        // cut from x = 5 to 55 mm, 1 mm to the side of the planned 0..60 mm line
        let m = incision(&straight_plan(), &cuts(5, 55, 0.001, 0.008)).unwrap();
        let e = (26.0f64).sqrt() * 1e-3; // sqrt(5^2 + 1^2) mm
        assert!((m.entry_error_m - e).abs() < 1e-12);
        assert!((m.exit_error_m - e).abs() < 1e-12);
        assert!((m.length_error_m + 0.010).abs() < 1e-12);
        assert!((m.lateral_mean_m - 0.001).abs() < 1e-12);
        assert!((m.lateral_rms_m - 0.001).abs() < 1e-12);
        assert!((m.lateral_max_m - 0.001).abs() < 1e-12);
        // covered: x in [5 - sqrt(3), 55 + sqrt(3)] mm of 60 mm
        let expected = (50.0 + 2.0 * 3f64.sqrt()) / 60.0;
        assert!(
            (m.fraction_cut_in_tolerance - expected).abs() < 2e-3,
            "{}",
            m.fraction_cut_in_tolerance
        );
        assert!(m.direction_error_deg.abs() < 1e-9);
        assert!(m.depth_error_m.unwrap().abs() < 1e-15);
    }

    #[test]
    fn direction_depth_and_lateral_max_by_hand() {
        // a straight cut rotated 10 degrees about the entry, 6 mm deep
        let tan = 10f64.to_radians().tan();
        let c: Vec<CutSample> = (0..=50)
            .map(|i| {
                let x = i as f64 * 1e-3;
                CutSample {
                    t_s: i as f64,
                    tip_m: [x, x * tan, -0.006],
                    edge_dir: [0.0, 0.0, 1.0],
                    depth_m: 0.006,
                    stroke: None,
                }
            })
            .collect();
        let m = incision(&straight_plan(), &c).unwrap();
        assert!((m.direction_error_deg - 10.0).abs() < 1e-9);
        assert!((m.depth_error_m.unwrap() + 0.002).abs() < 1e-12);
        assert!((m.depth_rms_error_m.unwrap() - 0.002).abs() < 1e-12);
        assert!((m.lateral_max_m - 0.05 * tan).abs() < 1e-12);
        assert!(m.entry_error_m < 1e-15);
    }

    #[test]
    fn a_lifted_blade_makes_two_strokes_and_the_gap_is_not_cut() {
        let mut c = cuts(0, 20, 0.0, 0.008);
        c.extend(cuts(40, 60, 0.0, 0.008));
        let m = incision(&straight_plan(), &c).unwrap();
        assert!((m.cut_length_m - 0.040).abs() < 1e-12);
        // covered: [0, 22] and [38, 60] mm
        assert!(
            (m.fraction_cut_in_tolerance - 44.0 / 60.0).abs() < 2e-3,
            "{}",
            m.fraction_cut_in_tolerance
        );
    }

    #[test]
    fn going_back_over_the_cut_or_zigzagging_does_not_lengthen_the_incision() {
        // 0 -> 40 -> 10 -> 40 mm in one stroke: 40 mm long (the blade travelled 100 mm)
        let mut c = cuts(0, 40, 0.0, 0.008);
        c.extend(cuts(10, 39, 0.0, 0.008).into_iter().rev());
        c.extend(cuts(10, 40, 0.0, 0.008));
        for (i, s) in c.iter_mut().enumerate() {
            s.t_s = i as f64 * 0.01;
        }
        let m = incision(&straight_plan(), &c).unwrap();
        assert!((m.cut_length_m - 0.040).abs() < 1e-12, "{}", m.cut_length_m);
        // a tremor of +-1 mm across the line every 1 mm: 60 mm long, 1 mm lateral
        let mut z = cuts(0, 60, 0.0, 0.008);
        for (i, s) in z.iter_mut().enumerate() {
            s.tip_m[1] = if i % 2 == 0 { 0.001 } else { -0.001 };
        }
        let m = incision(&straight_plan(), &z).unwrap();
        assert!(m.length_error_m.abs() < 1e-12, "{}", m.length_error_m);
        assert!((m.lateral_mean_m - 0.001).abs() < 1e-12);
        // 5 mm past either end: 70 mm
        let m = incision(&straight_plan(), &cuts(-5, 65, 0.0, 0.008)).unwrap();
        assert!(
            (m.length_error_m - 0.010).abs() < 1e-12,
            "{}",
            m.length_error_m
        );
    }

    #[test]
    fn a_cut_whose_ends_are_on_the_plans_is_as_long_as_the_plan_unless_the_blade_left() {
        // from 0.3 mm past the entry to 0.4 mm short of the exit, every 1 mm, but the hand
        // skips 5 mm after 27 mm (a pointer whose clock was anchored again after a stalled page):
        // the blade stayed in the tissue, one stroke, and the simulation cut the skipped stretch
        let mut c: Vec<CutSample> = cuts(0, 60, 0.0, 0.008)
            .into_iter()
            .filter(|s| !(0.0275..0.0315).contains(&s.tip_m[0]))
            .collect();
        c[0].tip_m[0] = 0.0003;
        c.last_mut().unwrap().tip_m[0] = 0.0596;
        for s in &mut c {
            s.stroke = Some(0);
        }
        let m = incision(&straight_plan(), &c).unwrap();
        assert!(m.entry_error_m < 5e-4 && m.exit_error_m < 5e-4, "{m:?}");
        assert!(m.length_error_m.abs() <= 1e-3, "{}", m.length_error_m);
        assert!(m.fraction_cut_in_tolerance > 0.99, "{m:?}");
        // the same samples without their strokes: the 5 mm skip reads as a lifted blade, the
        // length 5 mm short although the ends are on the plan's (what the recorder gave before
        // it recorded strokes)
        let mut unknown = c.clone();
        for s in &mut unknown {
            s.stroke = None;
        }
        let m = incision(&straight_plan(), &unknown).unwrap();
        assert!(m.length_error_m < -4e-3, "{}", m.length_error_m);
        // the blade did leave the tissue there: two strokes, the gap not cut
        let mut lifted = c.clone();
        for s in &mut lifted {
            s.stroke = Some(u32::from(s.tip_m[0] > 0.03));
        }
        let m = incision(&straight_plan(), &lifted).unwrap();
        let short = 0.005 + 0.0003 + 0.0004;
        assert!(
            (m.length_error_m + short).abs() < 1e-9,
            "{}",
            m.length_error_m
        );
        // a stroke recorded as one is one even where consecutive samples are far apart, and
        // a recorded change of stroke splits samples however close
        let mut close = cuts(0, 60, 0.0, 0.008);
        for s in &mut close {
            s.stroke = Some(u32::from(s.tip_m[0] > 0.0295));
        }
        let m = incision(&straight_plan(), &close).unwrap();
        assert!(
            (m.length_error_m + 0.001).abs() < 1e-12,
            "{}",
            m.length_error_m
        );
    }

    #[test]
    fn the_trace_is_where_a_tilted_blade_crosses_the_surface() {
        // tip 8 mm deep, blade tilted 45 degrees in y: it crosses the surface 8 mm beside the tip
        let e = [
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
        ];
        let c: Vec<CutSample> = (0..=60)
            .map(|i| CutSample {
                t_s: i as f64,
                tip_m: [i as f64 * 1e-3, -0.008 * e[1], -0.008 * e[2]],
                edge_dir: e,
                depth_m: 0.008,
                stroke: None,
            })
            .collect();
        let m = incision(&straight_plan(), &c).unwrap();
        assert!(m.lateral_max_m < 1e-12, "{}", m.lateral_max_m);
        let mut unusable = c.clone();
        for s in &mut unusable {
            s.edge_dir = [0.0; 3];
        }
        let m = incision(&straight_plan(), &unusable).unwrap();
        assert!(
            (m.lateral_mean_m - 0.008 * e[1]).abs() < 1e-12,
            "falls back to the tip"
        );
    }

    #[test]
    fn depth_below_the_planned_line() {
        let plan = straight_plan();
        assert!((depth_below_plan(&plan, [0.02, 0.003, -0.008]) - 0.008).abs() < 1e-15);
        let curved = IncisionPlan::chest_wall().unwrap();
        // at x = 30 mm the surface is 3.031 mm below the apex
        assert!((depth_below_plan(&curved, [0.03, 0.0, -0.011031]) - 0.008).abs() < 1e-9);
        assert!((depth_below_plan(&curved, [0.0, 0.001, -0.008]) - 0.008).abs() < 1e-12);
    }

    #[test]
    fn too_few_or_nan_cuts_are_input_errors() {
        assert!(incision(&straight_plan(), &cuts(0, 0, 0.0, 0.008)).is_err());
        let mut c = cuts(0, 10, 0.0, 0.008);
        c[3].tip_m[1] = f64::NAN;
        assert!(
            incision(&straight_plan(), &c)
                .unwrap_err()
                .to_string()
                .contains("cut sample 3")
        );
        let mut c = cuts(0, 10, 0.0, 0.008);
        c[3].depth_m = f64::NAN;
        assert!(
            incision(&straight_plan(), &c)
                .unwrap()
                .depth_error_m
                .is_none()
        );
    }

    #[test]
    fn approach_straight_down_and_at_45_degrees() {
        let plan = straight_plan();
        let down: Vec<PoseSample> = (0..=20)
            .map(|i| PoseSample {
                t_s: i as f64,
                tip_m: [0.0, 0.0, 0.01 - i as f64 * 1e-3],
                quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                blade_engaged: false,
            })
            .collect();
        assert!(approach_error_deg(&plan, &down, 20.0).unwrap() < 1e-9);
        let slanted: Vec<PoseSample> = (0..=20)
            .map(|i| PoseSample {
                t_s: i as f64,
                tip_m: [i as f64 * 1e-3, 0.0, -(i as f64) * 1e-3],
                quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                blade_engaged: false,
            })
            .collect();
        assert!((approach_error_deg(&plan, &slanted, 20.0).unwrap() - 45.0).abs() < 1e-9);
        assert!(approach_error_deg(&plan, &[], 1.0).is_none());
    }
}
