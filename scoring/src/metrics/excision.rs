//! Elliptical excision metrics: an outline incised round a skin lesion, down into the fat.
//!
//! The cut's trace ([`super::incision::trace_point`]: where the blade crossed the surface) is
//! seen along the plan's unit normal `n`, in the plane's coordinates `(x, y)` about the
//! lesion's centre `c`: `x` along the plan's long axis `u` (the skin's tension lines), `y`
//! along `n × u`. With `r` the lesion's radius:
//!
//! - margin of a trace point: `|p| - r`, its distance from the lesion's edge; the smallest over
//!   the trace (negative: the cut entered the lesion);
//! - side margin: over the trace points beside the lesion (`|x| ≤ r`), the mean of
//!   `|y| - √(r² - x²)`, the distance across from the lesion's edge, where a fusiform
//!   excision's margin is narrowest by design; its error is `|side margin - planned margin|`;
//! - length to width: the trace's extent along `u` over its extent along `n × u`; its error is
//!   how far the ratio lies outside the plan's accepted range (0 inside it);
//! - apex angle: at each end of the outline (the trace's extreme points `A` along `u`), the
//!   angle between the chords from `A` to the trace on either side of the axis about a sixth
//!   of the length `q` in from `A`: `atan(s₊) + atan(s₋)`, `s` the mean slope `|y - y_A| /
//!   |x - x_A|` of the trace points within `q / 4` of that distance, exact for straight sides;
//!   the larger of the two ends;
//! - axis error: the angle between the trace's principal axis (the larger eigenvector of its
//!   2 x 2 covariance, `θ = ½ atan2(2 s_xy, s_xx - s_yy)`) and `u`, in `[0°, 90°]`;
//! - where along the outline: each trace point's arc-length coordinate `s` on the planned
//!   (closed) outline of perimeter `P`, at its closest point, and its distance from it (an
//!   elongated outline's sides run nearly radially near the apexes, so angles about `c` would
//!   not tell its stretches apart);
//! - depth: the planned outline is divided into [`SECTORS`] equal lengths; in each the trace
//!   reached, the deepest cut's depth below the surface; the fraction of those sectors whose
//!   depth lies in the fat (from the fat's top to the fascia's), the shallowest and the
//!   deepest;
//! - closed: of the trace points within [`NEAR_OUTLINE_M`] of the planned outline, the largest
//!   step between consecutive `s` round the whole outline (`P` when none is near) is the
//!   outline's widest gap; closed when it is at most [`CLOSED_GAP_M`];
//! - time: from the first cut to the last;
//! - specimen: 1 when a cut freed a piece of tissue ([`crate::input::FreedPiece`], the first
//!   such), else 0, and then its volume at rest. An incision into the fat leaves the specimen
//!   attached at its base (undermining it is not part of the exercise), so neither is scored;
//!   a freed specimen's margins at the skin are the outline's own (above).

use nalgebra::{Point3, Vector3};

use super::{Better, Metric, Values, m};
use crate::geom;
use crate::input::AttemptData;

/// The sectors of the outline the depth is measured in.
pub const SECTORS: usize = 360;

/// How far from the planned outline a trace point still counts towards closing it (m): twice
/// the usual margin, so a cut wide of the plan still closes its own outline.
pub const NEAR_OUTLINE_M: f64 = 0.004;

/// The largest gap an outline may have and still count as closed (m): about the width a
/// scalpel's cut opens, under which the skin between two cuts tears rather than holds.
pub const CLOSED_GAP_M: f64 = 0.002;

/// The elliptical excision metrics, in report order.
pub const METRICS: &[Metric] = &[
    m(
        "excision_min_margin_m",
        "m",
        Better::HigherIsBetter,
        true,
        "smallest distance of the incision from the lesion's edge (negative: into the lesion)",
    )
    .labelled("Margin (smallest)"),
    m(
        "excision_side_margin_m",
        "m",
        Better::TwoSided,
        false,
        "mean distance across from the lesion's edge to the incision, beside the lesion",
    )
    .labelled("Margin beside the lesion (mean)"),
    m(
        "excision_margin_error_m",
        "m",
        Better::LowerIsBetter,
        true,
        "how far the margin beside the lesion is from the planned margin",
    )
    .labelled("Margin error")
    .distance_from_plan(),
    m(
        "length_to_width",
        "1",
        Better::TwoSided,
        false,
        "the outline's length along the skin's tension lines over its width",
    )
    .labelled("Length to width"),
    m(
        "excision_ratio_error",
        "1",
        Better::LowerIsBetter,
        true,
        "how far the length to width lies outside the accepted range (0 inside it)",
    )
    .labelled("Length to width: outside the range by"),
    m(
        "excision_apex_angle_deg",
        "deg",
        Better::LowerIsBetter,
        false,
        "the angle at the blunter end of the outline (chords over a sixth of its length)",
    )
    .labelled("Apex angle"),
    m(
        "excision_axis_error_deg",
        "deg",
        Better::LowerIsBetter,
        true,
        "angle between the outline's long axis and the skin's tension lines",
    )
    .labelled("Axis off the tension lines"),
    m(
        "excision_depth_in_fat",
        "1",
        Better::HigherIsBetter,
        true,
        "fraction of the outline cut into the fat and short of the fascia",
    )
    .labelled("Outline cut to the fat")
    .shown_in("%", 100.0),
    m(
        "excision_shallowest_m",
        "m",
        Better::HigherIsBetter,
        false,
        "the shallowest depth along the outline (its sectors' deepest cuts)",
    )
    .labelled("Depth (shallowest)"),
    m(
        "excision_deepest_m",
        "m",
        Better::LowerIsBetter,
        false,
        "the deepest cut along the outline",
    )
    .labelled("Depth (deepest)"),
    m(
        "outline_closed",
        "1",
        Better::HigherIsBetter,
        true,
        "1 when the incision goes all round the lesion with no gap wider than 2 mm, else 0",
    )
    .labelled("Outline closed"),
    m(
        "excision_outline_gap_m",
        "m",
        Better::LowerIsBetter,
        false,
        "the widest gap in the outline",
    )
    .labelled("Widest gap in the outline"),
    m(
        "excision_time_s",
        "s",
        Better::LowerIsBetter,
        false,
        "from the first cut to the last",
    )
    .labelled("Cutting time"),
    m(
        "excision_specimen_freed",
        "1",
        Better::HigherIsBetter,
        false,
        "1 when the cuts freed the specimen, else 0 (undermining is not asked for)",
    )
    .labelled("Specimen freed"),
    m(
        "excision_specimen_volume_m3",
        "m^3",
        Better::HigherIsBetter,
        false,
        "the freed specimen's volume at rest",
    )
    .labelled("Specimen volume"),
];

/// What an excision is measured against: the lesion (centre on the surface, unit normal,
/// radius), the long axis, the planned margin, the accepted length to width, the depths of
/// the fat's top and the fascia's (m) and the planned outline (closed: its last point is its
/// first).
#[derive(Debug, Clone)]
pub struct Excision {
    pub centre_m: [f64; 3],
    pub normal: [f64; 3],
    pub long_axis: [f64; 3],
    pub lesion_radius_m: f64,
    pub margin_m: f64,
    pub ratio_range: [f64; 2],
    pub fat_depth_m: f64,
    pub fascia_depth_m: f64,
    pub outline_m: Vec<[f64; 3]>,
}

impl Excision {
    /// The plane's axes `(u, n × u)`: `u` the long axis made perpendicular to `n`.
    pub fn axes(&self) -> (Vector3<f64>, Vector3<f64>) {
        plane_axes(self.normal, self.long_axis)
    }
}

/// `(u, n × u)`: `u` the long axis `axis` made perpendicular to the unit normal `normal`
/// (any direction in the plane when the axis is along the normal).
pub fn plane_axes(normal: [f64; 3], axis: [f64; 3]) -> (Vector3<f64>, Vector3<f64>) {
    let n = Vector3::from(normal);
    let a = Vector3::from(axis);
    let u = geom::unit(a - n * a.dot(&n)).unwrap_or_else(|| geom::plane_basis(normal).0);
    (u, n.cross(&u))
}

/// One trace point in the plane about the lesion's centre, with its cut's depth, and where
/// it is along the planned outline: its arc-length coordinate and distance.
#[derive(Debug, Clone, Copy)]
struct TracePoint {
    x: f64,
    y: f64,
    depth_m: f64,
    s: f64,
    off: f64,
}

/// The trace points and the planned outline's perimeter, both seen along the normal.
fn trace(e: &Excision, data: &AttemptData) -> (Vec<TracePoint>, f64) {
    let (u, v) = e.axes();
    let n = Vector3::from(e.normal);
    let c = Point3::from(e.centre_m);
    let flat = |p: Point3<f64>| geom::project(p, &n);
    let outline: Vec<Point3<f64>> = e.outline_m.iter().map(|&p| flat(p.into())).collect();
    let perimeter = geom::polyline_length(&outline);
    let points = data
        .cuts
        .iter()
        .map(|s| (Point3::from(super::incision::trace_point(s)), s.depth_m))
        .filter(|(p, _)| p.iter().all(|x| x.is_finite()))
        .map(|(p, depth_m)| {
            let d = p - c;
            let on = if outline.len() >= 2 {
                geom::closest_on_polyline(flat(p), &outline)
            } else {
                geom::OnLine {
                    distance: f64::INFINITY,
                    arc: 0.0,
                }
            };
            TracePoint {
                x: d.dot(&u),
                y: d.dot(&v),
                depth_m,
                s: on.arc.clamp(0.0, perimeter),
                off: on.distance,
            }
        })
        .collect();
    (points, perimeter)
}

/// The elliptical excision metrics of `data` against `e`.
pub(crate) fn assess(e: &Excision, data: &AttemptData, values: &mut Values) {
    let (points, perimeter) = trace(e, data);
    specimen(data, values);
    let finite_t: Vec<f64> = data
        .cuts
        .iter()
        .map(|c| c.t_s)
        .filter(|t| t.is_finite())
        .collect();
    match (finite_t.first(), finite_t.last()) {
        (Some(a), Some(b)) => values.set("excision_time_s", b - a),
        _ => values.missing(&["excision_time_s"], "no cut"),
    }
    if points.is_empty() {
        values.missing(
            &[
                "excision_min_margin_m",
                "excision_side_margin_m",
                "excision_margin_error_m",
                "length_to_width",
                "excision_ratio_error",
                "excision_apex_angle_deg",
                "excision_axis_error_deg",
                "excision_depth_in_fat",
                "excision_shallowest_m",
                "excision_deepest_m",
                "excision_outline_gap_m",
            ],
            "no cut",
        );
        values.set("outline_closed", 0.0);
        return;
    }
    margins(e, &points, values);
    shape(e, &points, values);
    depths(e, &points, perimeter, values);
    let gap = largest_gap(&points, perimeter);
    values.set("excision_outline_gap_m", gap);
    values.set(
        "outline_closed",
        if gap <= CLOSED_GAP_M { 1.0 } else { 0.0 },
    );
}

/// Whether a cut freed the specimen, and its volume.
fn specimen(data: &AttemptData, values: &mut Values) {
    let freed = data.freed.first();
    values.set(
        "excision_specimen_freed",
        if freed.is_some() { 1.0 } else { 0.0 },
    );
    match freed {
        Some(p) => values.set("excision_specimen_volume_m3", p.volume_m3),
        None => values.missing(&["excision_specimen_volume_m3"], "no specimen was freed"),
    }
}

fn margins(e: &Excision, points: &[TracePoint], values: &mut Values) {
    let r = e.lesion_radius_m;
    let min = points
        .iter()
        .map(|p| p.x.hypot(p.y) - r)
        .fold(f64::INFINITY, f64::min);
    values.set("excision_min_margin_m", min);
    let beside: Vec<f64> = points
        .iter()
        .filter(|p| p.x.abs() <= r)
        .map(|p| p.y.abs() - (r * r - p.x * p.x).sqrt())
        .collect();
    if beside.is_empty() {
        let keys = ["excision_side_margin_m", "excision_margin_error_m"];
        values.missing(&keys, "the cut does not pass beside the lesion");
    } else {
        let side = beside.iter().sum::<f64>() / beside.len() as f64;
        values.set("excision_side_margin_m", side);
        values.set("excision_margin_error_m", (side - e.margin_m).abs());
    }
}

fn shape(e: &Excision, points: &[TracePoint], values: &mut Values) {
    let extent = |f: fn(&TracePoint) -> f64| {
        let (lo, hi) = points
            .iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        hi - lo
    };
    let (length, width) = (extent(|p| p.x), extent(|p| p.y));
    if width > 0.0 {
        let ratio = length / width;
        values.set("length_to_width", ratio);
        let [lo, hi] = e.ratio_range;
        values.set(
            "excision_ratio_error",
            (lo - ratio).max(ratio - hi).max(0.0),
        );
    } else {
        values.missing(
            &["length_to_width", "excision_ratio_error"],
            "the cut has no width",
        );
    }
    match apex_angle(points, length) {
        Some(a) => values.set("excision_apex_angle_deg", a),
        None => values.missing(
            &["excision_apex_angle_deg"],
            "the outline has no two sides at an end",
        ),
    }
    match principal_axis_deg(points) {
        Some(a) => values.set("excision_axis_error_deg", a),
        None => values.missing(&["excision_axis_error_deg"], "the cut has no long axis"),
    }
}

/// The larger of the two ends' apex angles (degrees), or `None` when an end has no trace
/// point on one side of the axis a sixth of the length in.
fn apex_angle(points: &[TracePoint], length: f64) -> Option<f64> {
    let q = length / 6.0;
    let band = (q / 4.0).max(5e-4);
    let at_end = |sign: f64| -> Option<f64> {
        let apex = points
            .iter()
            .max_by(|a, b| (sign * a.x).total_cmp(&(sign * b.x)))?;
        // the mean slope of the chords from the apex on one side of the axis
        let slope = |above: bool| {
            let slopes: Vec<f64> = points
                .iter()
                .filter(|p| (sign * (apex.x - p.x) - q).abs() <= band && (p.y > apex.y) == above)
                .map(|p| (p.y - apex.y).abs() / (sign * (apex.x - p.x)))
                .collect();
            (!slopes.is_empty()).then(|| slopes.iter().sum::<f64>() / slopes.len() as f64)
        };
        Some(slope(true)?.atan() + slope(false)?.atan())
    };
    let (a, b) = (at_end(1.0)?, at_end(-1.0)?);
    Some(a.max(b).to_degrees())
}

/// The angle (degrees, in `[0, 90]`) between the points' principal axis and `x`.
fn principal_axis_deg(points: &[TracePoint]) -> Option<f64> {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.x / n, b + p.y / n));
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in points {
        let (dx, dy) = (p.x - mx, p.y - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    if !(sxx + syy > 0.0) {
        return None;
    }
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Some(theta.to_degrees().abs())
}

fn depths(e: &Excision, points: &[TracePoint], perimeter: f64, values: &mut Values) {
    let mut deepest = vec![f64::NEG_INFINITY; SECTORS];
    for p in points.iter().filter(|p| p.depth_m.is_finite()) {
        let k = ((p.s / perimeter * SECTORS as f64) as usize).min(SECTORS - 1);
        deepest[k] = deepest[k].max(p.depth_m);
    }
    let crossed: Vec<f64> = deepest.into_iter().filter(|d| d.is_finite()).collect();
    if crossed.is_empty() {
        let keys = [
            "excision_depth_in_fat",
            "excision_shallowest_m",
            "excision_deepest_m",
        ];
        values.missing(&keys, "no cut has a finite depth");
        return;
    }
    let in_fat = crossed
        .iter()
        .filter(|&&d| d >= e.fat_depth_m && d < e.fascia_depth_m)
        .count();
    values.set(
        "excision_depth_in_fat",
        in_fat as f64 / crossed.len() as f64,
    );
    let (lo, hi) = crossed
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &d| {
            (a.min(d), b.max(d))
        });
    values.set("excision_shallowest_m", lo);
    values.set("excision_deepest_m", hi);
}

/// The longest stretch of the planned outline (of length `perimeter`) between the
/// arc-length coordinates of consecutive trace points near it, round the whole outline.
fn largest_gap(points: &[TracePoint], perimeter: f64) -> f64 {
    let mut s: Vec<f64> = points
        .iter()
        .filter(|p| p.off <= NEAR_OUTLINE_M)
        .map(|p| p.s)
        .collect();
    s.sort_by(f64::total_cmp);
    match (s.first(), s.last()) {
        (Some(&first), Some(&last)) => s
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(perimeter - last + first, f64::max),
        _ => perimeter,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::CutSample;

    const R: f64 = 0.004;

    /// The built-in's lesion and targets, with the closed outline `corners` (m, z = 0).
    fn excision(corners: &[[f64; 2]]) -> Excision {
        let mut outline_m: Vec<[f64; 3]> = corners.iter().map(|c| [c[0], c[1], 0.0]).collect();
        outline_m.push(outline_m[0]);
        Excision {
            centre_m: [0.0, 0.0, 0.0],
            normal: [0.0, 0.0, 1.0],
            long_axis: [1.0, 0.0, 0.0],
            lesion_radius_m: R,
            margin_m: 0.002,
            ratio_range: [3.0, 4.0],
            fat_depth_m: 0.002,
            fascia_depth_m: 0.011,
            outline_m,
        }
    }

    /// Cut samples along the closed polygon `corners` (m, in the plane z = 0), one every
    /// 0.25 mm, at `depth_of(x, y)`, rotated by `turn` radians about the lesion's centre.
    fn cut_round(
        corners: &[[f64; 2]],
        turn: f64,
        depth_of: impl Fn(f64, f64) -> f64,
    ) -> AttemptData {
        let mut closed = corners.to_vec();
        closed.push(corners[0]);
        cut_along(&closed, turn, depth_of)
    }

    /// [`cut_round`] along the open polyline `corners`.
    fn cut_along(
        corners: &[[f64; 2]],
        turn: f64,
        depth_of: impl Fn(f64, f64) -> f64,
    ) -> AttemptData {
        let mut cuts = Vec::new();
        let (s, c) = turn.sin_cos();
        for (a, b) in corners.iter().zip(&corners[1..]) {
            let n = (((b[0] - a[0]).hypot(b[1] - a[1])) / 2.5e-4).ceil() as usize;
            for j in 0..n {
                let f = j as f64 / n as f64;
                let (x, y) = (a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f);
                let depth_m = depth_of(x, y);
                cuts.push(CutSample {
                    t_s: cuts.len() as f64 * 0.01,
                    tip_m: [c * x - s * y, s * x + c * y, -depth_m],
                    edge_dir: [0.0, 0.0, 1.0],
                    depth_m,
                    stroke: Some(0),
                });
            }
        }
        AttemptData {
            cuts,
            ..Default::default()
        }
    }

    /// A circle 2 mm outside the lesion's edge, one point a degree.
    fn circle_2_mm_out() -> Vec<[f64; 2]> {
        (0..360)
            .map(|k| {
                let a = (k as f64).to_radians();
                [(R + 0.002) * a.cos(), (R + 0.002) * a.sin()]
            })
            .collect()
    }

    fn run(outline: &[[f64; 2]], data: &AttemptData) -> Vec<(&'static str, Option<f64>)> {
        let mut values = Values::default();
        assess(&excision(outline), data, &mut values);
        values.0.iter().map(|(k, v, _)| (*k, *v)).collect()
    }

    fn get(out: &[(&'static str, Option<f64>)], key: &str) -> f64 {
        out.iter()
            .find(|(k, _)| *k == key)
            .and_then(|(_, v)| *v)
            .unwrap_or_else(|| panic!("{key} missing"))
    }

    /// A rhombus (straight sides) 36 mm long and 11 mm wide round the lesion, its sides
    /// tangent to a circle 1.5 mm outside the lesion's edge: worked by hand, the smallest
    /// margin is 1.5 mm, the apex angle `2 atan(5.5 / 18) = 34.0°`, length to width 3.27
    /// (inside 3 to 4), the axis on the tension lines, cut 5 mm deep all round: in the fat.
    #[test]
    fn a_rhombus_drawn_1_5_mm_from_the_lesion() {
        let (half_l, half_w) = (0.018f64, 0.0055);
        // the sides' distance from the centre: L W / sqrt(L² + W²)
        let d = half_l * half_w / half_l.hypot(half_w);
        let scale = (R + 0.0015) / d;
        let (l, w) = (half_l * scale, half_w * scale);
        let rhombus = [[-l, 0.0], [0.0, -w], [l, 0.0], [0.0, w]];
        let out = run(&rhombus, &cut_round(&rhombus, 0.0, |_, _| 0.005));
        assert!((get(&out, "excision_min_margin_m") - 0.0015).abs() < 1e-6);
        let apex = get(&out, "excision_apex_angle_deg");
        assert!(
            (apex - 2.0 * (w / l).atan().to_degrees()).abs() < 0.05,
            "{apex}"
        );
        assert!((get(&out, "length_to_width") - l / w).abs() < 1e-3);
        assert_eq!(get(&out, "excision_ratio_error"), 0.0);
        assert!(get(&out, "excision_axis_error_deg") < 1e-6);
        assert_eq!(get(&out, "excision_depth_in_fat"), 1.0);
        assert_eq!(get(&out, "outline_closed"), 1.0);
        assert!(get(&out, "excision_outline_gap_m") < 5e-4);
        // beside the lesion the sides run at |y| = w (1 - |x| / l): the mean of
        // w (1 - |x| / l) - sqrt(r² - x²) over |x| <= r is w (1 - r / 2l) - π r / 4
        let side = get(&out, "excision_side_margin_m");
        let expected = w * (1.0 - R / (2.0 * l)) - std::f64::consts::PI * R / 4.0;
        assert!((side - expected).abs() < 1e-4, "{side} vs {expected}");
    }

    /// Worked by hand: a circle 2 mm outside the lesion (ratio 1) misses the range by 2; turned
    /// 20° off the tension lines, a long outline's axis error is 20°; a cut through the fascia
    /// on one side counts those sectors out of the fat; an outline a quarter short is open.
    #[test]
    fn shape_depth_and_closure_fail_where_they_should() {
        let circle = circle_2_mm_out();
        let round = run(&circle, &cut_round(&circle, 0.0, |_, _| 0.005));
        assert!((get(&round, "length_to_width") - 1.0).abs() < 1e-3);
        assert!((get(&round, "excision_ratio_error") - 2.0).abs() < 1e-3);
        // across from the lesion's edge, a circle is 2 mm out only at the sides
        let side = get(&round, "excision_side_margin_m");
        assert!(side > 0.002 && side < 0.003, "{side}");
        assert!((get(&round, "excision_margin_error_m") - (side - 0.002)).abs() < 1e-15);
        let rhombus = [[-0.021, 0.0], [0.0, -0.006], [0.021, 0.0], [0.0, 0.006]];
        let turned = run(
            &rhombus,
            &cut_round(&rhombus, 20f64.to_radians(), |_, _| 0.005),
        );
        assert!((get(&turned, "excision_axis_error_deg") - 20.0).abs() < 1e-6);
        let deep = run(
            &rhombus,
            &cut_round(&rhombus, 0.0, |_, y| if y > 0.0 { 0.012 } else { 0.005 }),
        );
        let in_fat = get(&deep, "excision_depth_in_fat");
        assert!((in_fat - 0.5).abs() < 0.02, "{in_fat}");
        assert!((get(&deep, "excision_deepest_m") - 0.012).abs() < 1e-12);
        let open = run(&circle, &cut_along(&circle[..=270], 0.0, |_, _| 0.005));
        assert_eq!(get(&open, "outline_closed"), 0.0);
        // the missing quarter of the outline
        let gap = get(&open, "excision_outline_gap_m");
        assert!(
            (gap - std::f64::consts::FRAC_PI_2 * (R + 0.002)).abs() < 3e-4,
            "{gap}"
        );
        // a closed cut 3 mm wide of the plan still closes; 5.4 mm wide it is not near it
        let wide: Vec<[f64; 2]> = circle.iter().map(|c| [c[0] * 1.5, c[1] * 1.5]).collect();
        let near = run(&circle, &cut_round(&wide, 0.0, |_, _| 0.005));
        assert_eq!(get(&near, "outline_closed"), 1.0);
        let far: Vec<[f64; 2]> = circle.iter().map(|c| [c[0] * 1.9, c[1] * 1.9]).collect();
        let far = run(&circle, &cut_round(&far, 0.0, |_, _| 0.005));
        assert_eq!(get(&far, "outline_closed"), 0.0);
        let none = run(&circle, &AttemptData::default());
        assert_eq!(get(&none, "outline_closed"), 0.0);
    }

    /// The specimen: not freed by an incision alone (its volume missing, not zero); freed, its
    /// volume is the first freed piece's.
    #[test]
    fn the_specimen_is_reported_when_a_cut_frees_it() {
        let circle = circle_2_mm_out();
        let mut data = cut_round(&circle, 0.0, |_, _| 0.005);
        let attached = run(&circle, &data);
        assert_eq!(get(&attached, "excision_specimen_freed"), 0.0);
        assert!(
            attached
                .iter()
                .any(|(k, v)| *k == "excision_specimen_volume_m3" && v.is_none())
        );
        data.freed.push(crate::input::FreedPiece {
            t_s: 3.0,
            volume_m3: 1.2e-6,
            surface_m2: 6e-4,
        });
        let freed = run(&circle, &data);
        assert_eq!(get(&freed, "excision_specimen_freed"), 1.0);
        assert_eq!(get(&freed, "excision_specimen_volume_m3"), 1.2e-6);
    }
}
