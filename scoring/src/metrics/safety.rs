//! Safety metrics: forces on the tissue and tissue cut where it should not be.
//!
//! With `|F_k|` the force magnitude of sample `k` and `dt_k = t_(k+1) - t_k`:
//! - peak force: `max |F_k|` over all samples; mean force: the mean of `|F_k|` over the
//!   samples that touch the tissue (0 when none does);
//! - time above the limit: `sum dt_k` over the samples with `|F_k| > limit` (each sample holds
//!   until the next), limit = the plan's `force_limit_n`;
//! - excessive-force events: upward crossings of the limit (a first sample above counts);
//! - cut outside the corridor: the cut trace (surface crossings, projected along the plan's
//!   normal and split into strokes as in [`crate::metrics::incision`]) is divided into pieces of at most 0.1 mm; a
//!   piece whose midpoint lies further than `corridor_half_width_m` from the projected planned
//!   line is outside. The metric is the total length outside (m); the area outside (m^2) is
//!   the sum of each outside piece's length times the mean recorded depth of its segment's
//!   two cut samples (the cut face's area).

use nalgebra::{Point3, Vector3};

use crate::error::{Result, ScoreError};
use crate::geom;
use crate::incision_plan::IncisionPlan;
use crate::input::{CutSample, ForceSample};
use crate::metrics::Values;
use crate::metrics::incision::{same_stroke, trace_point};

/// The force metrics of one attempt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceMetrics {
    pub peak_force_n: f64,
    pub mean_force_n: f64,
    pub time_above_limit_s: f64,
    pub excessive_force_events: usize,
}

/// Force metrics of `forces` (at least 1, finite, sorted by time here) against `limit_n`.
pub fn forces(forces: &[ForceSample], limit_n: f64) -> Result<ForceMetrics> {
    if forces.is_empty() {
        return Err(ScoreError::InvalidInput("no force samples".into()));
    }
    if let Some(i) = forces
        .iter()
        .position(|f| !f.t_s.is_finite() || !geom::finite(&f.force_newtons))
    {
        return Err(ScoreError::InvalidInput(format!(
            "force sample {i}: a value is not finite"
        )));
    }
    let mut f = forces.to_vec();
    f.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let mag: Vec<f64> = f
        .iter()
        .map(|s| Vector3::from(s.force_newtons).norm())
        .collect();
    let touching: Vec<f64> = f
        .iter()
        .zip(&mag)
        .filter(|(s, _)| s.touching)
        .map(|(_, m)| *m)
        .collect();
    let mean_force_n = if touching.is_empty() {
        0.0
    } else {
        touching.iter().sum::<f64>() / touching.len() as f64
    };
    let time_above_limit_s = (0..f.len() - 1)
        .filter(|&k| mag[k] > limit_n)
        .map(|k| f[k + 1].t_s - f[k].t_s)
        .sum();
    let excessive_force_events = (0..f.len())
        .filter(|&k| mag[k] > limit_n && (k == 0 || mag[k - 1] <= limit_n))
        .count();
    Ok(ForceMetrics {
        peak_force_n: mag.iter().copied().fold(0.0, f64::max),
        mean_force_n,
        time_above_limit_s,
        excessive_force_events,
    })
}

/// The cut outside the plan's corridor: `(length m, area m^2)`; the area is `None` when a
/// depth is not finite. No cuts: nothing outside.
pub fn outside_corridor(plan: &IncisionPlan, cuts: &[CutSample]) -> Result<(f64, Option<f64>)> {
    if let Some(i) = cuts
        .iter()
        .position(|c| !c.t_s.is_finite() || !geom::finite(&c.tip_m))
    {
        return Err(ScoreError::InvalidInput(format!(
            "cut sample {i}: time or tip not finite"
        )));
    }
    let mut cuts = cuts.to_vec();
    cuts.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let n = Vector3::from(plan.normal);
    let line: Vec<Point3<f64>> = plan
        .incision_m
        .iter()
        .map(|&p| geom::project(p.into(), &n))
        .collect();
    let (mut length, mut area, mut area_ok) = (0.0, 0.0, true);
    for w in cuts.windows(2) {
        let (a, b) = (
            geom::project(trace_point(&w[0]).into(), &n),
            geom::project(trace_point(&w[1]).into(), &n),
        );
        if !same_stroke(&w[0], &w[1], &a, &b) {
            continue;
        }
        let len = nalgebra::distance(&a, &b);
        let pieces = (len / 1e-4).ceil().max(1.0) as usize;
        let piece = len / pieces as f64;
        let out = (0..pieces)
            .filter(|&k| {
                let mid = a + (b - a) * ((k as f64 + 0.5) / pieces as f64);
                geom::closest_on_polyline(mid, &line).distance > plan.corridor_half_width_m
            })
            .count() as f64
            * piece;
        if out > 0.0 {
            length += out;
            let depth = 0.5 * (w[0].depth_m + w[1].depth_m);
            if depth.is_finite() {
                area += out * depth.max(0.0);
            } else {
                area_ok = false;
            }
        }
    }
    Ok((length, area_ok.then_some(area)))
}

pub(crate) fn assess(
    plan: &IncisionPlan,
    f: &[ForceSample],
    cuts: &[CutSample],
    values: &mut Values,
) {
    match forces(f, plan.force_limit_n) {
        Ok(m) => {
            values.set("peak_force_n", m.peak_force_n);
            values.set("mean_force_n", m.mean_force_n);
            values.set("time_above_force_limit_s", m.time_above_limit_s);
            values.set("excessive_force_events", m.excessive_force_events as f64);
        }
        Err(e) => values.missing(
            &[
                "peak_force_n",
                "mean_force_n",
                "time_above_force_limit_s",
                "excessive_force_events",
            ],
            &e.to_string(),
        ),
    }
    match outside_corridor(plan, cuts) {
        Ok((length, area)) => {
            values.set("cut_outside_corridor_m", length);
            match area {
                Some(a) => values.set("cut_area_outside_corridor_m2", a),
                None => values.missing(
                    &["cut_area_outside_corridor_m2"],
                    "a cut depth is not finite",
                ),
            }
        }
        Err(e) => values.missing(
            &["cut_outside_corridor_m", "cut_area_outside_corridor_m2"],
            &e.to_string(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight_plan() -> IncisionPlan {
        IncisionPlan::from_json(r#"{"entry_m":[0,0,0],"exit_m":[0.06,0,0],"depth_m":0.008,"viewpoint_m":[0,0,0.1],"force_limit_n":2.5,"corridor_half_width_m":0.005}"#).unwrap()
    }

    #[test]
    fn force_metrics_by_hand() {
        let mags = [0.0, 1.0, 3.0, 3.0, 1.0, 0.0, 3.0, 1.0, 0.0, 0.0];
        let samples: Vec<ForceSample> = mags
            .iter()
            .enumerate()
            // split each magnitude over two axes: |(0.6 m, 0.8 m, 0)| = m
            .map(|(i, m)| ForceSample { t_s: i as f64 * 0.1, force_newtons: [0.6 * m, 0.8 * m, 0.0], touching: *m > 0.0, cutting: false })
            .collect();
        let m = forces(&samples, 2.5).unwrap();
        assert!((m.peak_force_n - 3.0).abs() < 1e-12);
        assert!(
            (m.mean_force_n - 12.0 / 6.0).abs() < 1e-12,
            "mean over the 6 touching samples"
        );
        assert!((m.time_above_limit_s - 0.3).abs() < 1e-12);
        assert_eq!(m.excessive_force_events, 2);
        assert!(forces(&[], 2.5).is_err());
    }

    #[test]
    fn cut_outside_the_corridor_by_hand() {
        let at = |x_mm: i32, y_mm: f64, t: f64| CutSample {
            t_s: t,
            tip_m: [x_mm as f64 * 1e-3, y_mm * 1e-3, -0.008],
            edge_dir: [0.0, 0.0, 1.0],
            depth_m: 0.008,
            stroke: None,
        };
        // 10 mm at y = 7 mm (outside the 5 mm corridor), then 20 mm on the line
        let mut cuts: Vec<CutSample> = (10..=20).map(|x| at(x, 7.0, x as f64)).collect();
        cuts.extend((30..=50).map(|x| at(x, 0.0, x as f64)));
        let (length, area) = outside_corridor(&straight_plan(), &cuts).unwrap();
        assert!((length - 0.010).abs() < 1e-9, "{length}");
        assert!((area.unwrap() - 0.010 * 0.008).abs() < 1e-12);
        let inside: Vec<CutSample> = (0..=60).map(|x| at(x, 4.0, x as f64)).collect();
        assert_eq!(outside_corridor(&straight_plan(), &inside).unwrap().0, 0.0);
    }
}
