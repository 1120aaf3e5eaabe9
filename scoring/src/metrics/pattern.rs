//! Pattern cutting metrics, after the FLS/MISTELS pattern cutting task: a circle marked on a
//! sheet, cut out along the mark.
//!
//! The cut's trace ([`super::incision::trace_point`]: where the blade crossed the surface)
//! is seen along the plan's unit normal `n`: each trace point `p` becomes polar coordinates
//! `(r, θ)` about the circle's centre `c` in the plane through `c` normal to `n`.
//!
//! - deviation of a trace point: `|r - R|`, the distance from the marked circle of radius
//!   `R`; its maximum and mean over the trace ("the whole cut within 2 mm of the line");
//! - the cut's outline `r(θ)`: the trace points' mean radius in each of [`BINS`] equal
//!   sectors, a sector the trace missed interpolated (round the circle) between the nearest
//!   sectors it crossed; with no trace point in more than a quarter of the sectors the cut
//!   has no outline (the metric is missing);
//! - area deviation: the area between the outline and the circle over the circle's area,
//!   `(1/(π R²)) Σ ½ |r_k² - R²| Δθ` with `Δθ = 2π / BINS`: a cut 1 mm outside a 40 mm circle
//!   deviates by `(21² - 20²)/20² = 10.25 %`;
//! - completion time: from the start of the attempt (its first pose) to the moment the first
//!   piece was cut free ([`crate::input::FreedPiece`]); missing when none was;
//! - piece freed: 1 when a piece was cut free, else 0;
//! - the MISTELS score: `cutoff - time - 100 · area deviation` (the penalty is the percentage
//!   of the circle's area that deviates), floored at 0; 0 when no piece was cut free (the
//!   task not completed by the cutoff scores 0).

use nalgebra::Point3;

use super::{Better, Metric, Values, m};
use crate::geom;
use crate::input::AttemptData;

/// The sectors the outline is measured in.
pub const BINS: usize = 360;

/// The pattern cutting metrics, in report order.
pub const METRICS: &[Metric] = &[
    m(
        "mistels_score",
        "1",
        Better::HigherIsBetter,
        false,
        "MISTELS score: the cutoff minus the completion time (s) minus the area deviation (% of the circle); 0 when the piece is not cut free",
    )
    .labelled("Pattern score (MISTELS)"),
    m(
        "piece_freed",
        "1",
        Better::HigherIsBetter,
        true,
        "1 when the marked piece was cut free, else 0",
    )
    .labelled("Piece cut free"),
    m(
        "completion_time_s",
        "s",
        Better::LowerIsBetter,
        true,
        "from the start until the piece was cut free",
    )
    .labelled("Completion time"),
    m(
        "pattern_max_deviation_m",
        "m",
        Better::LowerIsBetter,
        true,
        "largest distance of the cut from the marked line",
    )
    .labelled("Deviation from the mark (max)")
    .distance_from_plan(),
    m(
        "pattern_mean_deviation_m",
        "m",
        Better::LowerIsBetter,
        false,
        "mean distance of the cut from the marked line",
    )
    .labelled("Deviation from the mark (mean)"),
    m(
        "area_deviation",
        "1",
        Better::LowerIsBetter,
        false,
        "area between the cut and the marked circle over the circle's area",
    )
    .labelled("Area deviation")
    .shown_in("%", 100.0),
];

/// The marked circle: its centre on the surface, unit normal and radius (m), and the cutoff
/// time (s).
#[derive(Debug, Clone, Copy)]
pub struct Circle {
    pub centre_m: [f64; 3],
    pub normal: [f64; 3],
    pub radius_m: f64,
    pub cutoff_s: f64,
}

/// `(r, θ)` of each finite trace point about the circle's centre, seen along its normal.
fn polar(circle: &Circle, data: &AttemptData) -> Vec<(f64, f64)> {
    let (u, v) = geom::plane_basis(circle.normal);
    let c = Point3::from(circle.centre_m);
    data.cuts
        .iter()
        .map(|s| Point3::from(super::incision::trace_point(s)) - c)
        .filter(|d| d.iter().all(|x| x.is_finite()))
        .map(|d| {
            let (x, y) = (d.dot(&u), d.dot(&v));
            (x.hypot(y), y.atan2(x))
        })
        .collect()
}

/// The outline's radius in each of [`BINS`] sectors, or `None` when more than a quarter of
/// them hold no trace point.
pub fn outline(points: &[(f64, f64)]) -> Option<Vec<f64>> {
    let mut sum = vec![(0.0, 0usize); BINS];
    for &(r, theta) in points {
        let k = ((theta + std::f64::consts::PI) / std::f64::consts::TAU * BINS as f64) as usize;
        let bin = &mut sum[k.min(BINS - 1)];
        *bin = (bin.0 + r, bin.1 + 1);
    }
    let filled: Vec<usize> = (0..BINS).filter(|&k| sum[k].1 > 0).collect();
    if filled.len() * 4 < BINS * 3 {
        return None;
    }
    let mean = |k: usize| sum[k].0 / sum[k].1 as f64;
    let (first, last) = (filled[0], filled[filled.len() - 1]);
    Some(
        (0..BINS)
            .map(|k| {
                if sum[k].1 > 0 {
                    return mean(k);
                }
                // the nearest crossed sectors before and after, round the circle
                let a = filled
                    .iter()
                    .rev()
                    .find(|&&j| j < k)
                    .copied()
                    .unwrap_or(last);
                let b = filled.iter().find(|&&j| j > k).copied().unwrap_or(first);
                let (da, db) = ((k + BINS - a) % BINS, (b + BINS - k) % BINS);
                mean(a) + (mean(b) - mean(a)) * da as f64 / (da + db) as f64
            })
            .collect(),
    )
}

/// The area between `outline` and the circle of radius `r_m`, over the circle's area.
pub fn area_deviation(outline: &[f64], r_m: f64) -> f64 {
    let d_theta = std::f64::consts::TAU / outline.len() as f64;
    let between: f64 = outline
        .iter()
        .map(|r| 0.5 * (r * r - r_m * r_m).abs() * d_theta)
        .sum();
    between / (std::f64::consts::PI * r_m * r_m)
}

/// The pattern cutting metrics of `data` against `circle`.
pub(crate) fn assess(circle: &Circle, data: &AttemptData, values: &mut Values) {
    let points = polar(circle, data);
    let freed_at = data.freed.first().map(|p| p.t_s);
    values.set("piece_freed", if freed_at.is_some() { 1.0 } else { 0.0 });
    let start_s = data.poses.first().map_or(0.0, |p| p.t_s);
    match freed_at {
        Some(t) => values.set("completion_time_s", t - start_s),
        None => values.missing(&["completion_time_s"], "no piece was cut free"),
    }
    if points.is_empty() {
        values.missing(
            &["pattern_max_deviation_m", "pattern_mean_deviation_m"],
            "no cut",
        );
    } else {
        let dev: Vec<f64> = points
            .iter()
            .map(|(r, _)| (r - circle.radius_m).abs())
            .collect();
        values.set(
            "pattern_max_deviation_m",
            dev.iter().fold(0.0, |a, &b| a.max(b)),
        );
        values.set(
            "pattern_mean_deviation_m",
            dev.iter().sum::<f64>() / dev.len() as f64,
        );
    }
    let area = outline(&points).map(|o| area_deviation(&o, circle.radius_m));
    match area {
        Some(a) => values.set("area_deviation", a),
        None => values.missing(&["area_deviation"], "the cut does not go round the mark"),
    }
    let score = match (freed_at, area) {
        (Some(t), Some(a)) => (circle.cutoff_s - (t - start_s) - 100.0 * a).max(0.0),
        _ => 0.0,
    };
    values.set("mistels_score", score);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::{CutSample, FreedPiece, PoseSample};

    const R: f64 = 0.02;

    fn circle() -> Circle {
        Circle {
            centre_m: [0.05, 0.05, 0.002],
            normal: [0.0, 0.0, 1.0],
            radius_m: R,
            cutoff_s: 300.0,
        }
    }

    /// A cut at radius `r_of(θ)` about the mark's centre over `turns` turns, `n` samples,
    /// the piece freed at `freed_s`.
    fn cut(r_of: impl Fn(f64) -> f64, turns: f64, freed_s: Option<f64>) -> AttemptData {
        let n = 2000;
        let c = circle().centre_m;
        let cuts = (0..n)
            .map(|i| {
                let theta = turns * std::f64::consts::TAU * i as f64 / n as f64;
                let r = r_of(theta);
                CutSample {
                    t_s: 1.0 + 0.02 * i as f64,
                    tip_m: [c[0] + r * theta.cos(), c[1] + r * theta.sin(), -0.002],
                    edge_dir: [0.0, 0.0, 1.0],
                    depth_m: 0.004,
                    stroke: Some(0),
                }
            })
            .collect();
        let pose = PoseSample {
            t_s: 0.0,
            tip_m: [0.0; 3],
            quat_wxyz: [1.0, 0.0, 0.0, 0.0],
            blade_engaged: false,
        };
        AttemptData {
            poses: vec![pose],
            cuts,
            freed: freed_s
                .map(|t_s| FreedPiece {
                    t_s,
                    volume_m3: 2.5e-6,
                    surface_m2: 3e-3,
                })
                .into_iter()
                .collect(),
            ..Default::default()
        }
    }

    fn run(data: &AttemptData) -> Vec<(&'static str, Option<f64>)> {
        let mut values = Values::default();
        assess(&circle(), data, &mut values);
        values.0.iter().map(|(k, v, _)| (*k, *v)).collect()
    }

    fn get(out: &[(&'static str, Option<f64>)], key: &str) -> Option<f64> {
        out.iter().find(|(k, _)| *k == key).and_then(|(_, v)| *v)
    }

    /// Worked by hand: a cut 1 mm outside the 40 mm circle deviates by
    /// `(21² - 20²) / 20² = 10.25 %` of its area; freed at 80 s, MISTELS gives
    /// `300 - 80 - 10.25 = 209.75`.
    #[test]
    fn a_cut_offset_by_1_mm_costs_the_area_between() {
        let out = run(&cut(|_| R + 0.001, 1.05, Some(80.0)));
        let area = get(&out, "area_deviation").unwrap();
        assert!((area - 0.1025).abs() < 1e-9, "{area}");
        let score = get(&out, "mistels_score").unwrap();
        assert!((score - 209.75).abs() < 1e-6, "{score}");
        assert!((get(&out, "pattern_max_deviation_m").unwrap() - 0.001).abs() < 1e-12);
        assert_eq!(get(&out, "completion_time_s"), Some(80.0));
        assert_eq!(get(&out, "piece_freed"), Some(1.0));
    }

    /// On the line: no deviation, the score is the cutoff minus the time; half the circle
    /// inside by 1 mm and half outside: the areas add, they do not cancel.
    #[test]
    fn on_the_line_scores_the_time_and_deviations_do_not_cancel() {
        let on = run(&cut(|_| R, 1.0, Some(60.0)));
        assert!(get(&on, "area_deviation").unwrap() < 1e-12);
        assert!((get(&on, "mistels_score").unwrap() - 240.0).abs() < 1e-9);
        let wavy = run(&cut(
            |t| if t.sin() >= 0.0 { R + 0.001 } else { R - 0.001 },
            1.0,
            Some(60.0),
        ));
        let expected = 0.5 * ((21.0f64.powi(2) - 400.0) + (400.0 - 19.0f64.powi(2))) / 400.0;
        let area = get(&wavy, "area_deviation").unwrap();
        assert!((area - expected).abs() < 2e-3, "{area} vs {expected}");
    }

    /// A piece not cut free scores 0 and has no completion time; half a circle has no
    /// outline; no cut at all is missing, not an error.
    #[test]
    fn an_unfinished_cut_scores_zero() {
        let open = run(&cut(|_| R, 0.95, None));
        assert_eq!(get(&open, "mistels_score"), Some(0.0));
        assert_eq!(get(&open, "piece_freed"), Some(0.0));
        assert_eq!(get(&open, "completion_time_s"), None);
        assert!(
            get(&open, "area_deviation").is_some(),
            "a gap of 5 % is bridged"
        );
        let half = run(&cut(|_| R, 0.5, None));
        assert_eq!(get(&half, "area_deviation"), None);
        let none = run(&AttemptData::default());
        assert_eq!(get(&none, "pattern_max_deviation_m"), None);
        assert_eq!(get(&none, "mistels_score"), Some(0.0));
    }
}
