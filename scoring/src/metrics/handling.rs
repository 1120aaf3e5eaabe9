//! Tissue handling: how the second hand held the tissue while the other cut (DESIGN.md
//! section 9). Measured on an attempt made with a grasper ([`GrasperSample`]: the jaws'
//! centre `j`, closed or not, and the held tissue's pull `f` on them, zero while they hold
//! nothing); an attempt without one has none of these metrics.
//!
//! Each sample stands for the time to the next one, `Δt_i = min(t_{i+1} - t_i, 50 ms)` (the
//! last for the one before it), so gaps in a recording count for no more than 50 ms.
//!
//! - grasps: holds begun, a sample holding (`f ≠ 0`) after one that did not;
//! - slips: holds that ended with the jaws still closed (the tissue pulled out of their grip
//!   past its slip force);
//! - peak traction `max |f|`; mean traction `Σ |f| Δt / Σ Δt` over the samples holding;
//! - time over the limit: `Σ Δt` over the samples with `|f|` above the plan's force limit,
//!   the tissue loaded past it by the jaws (damage by excessive grip and pull);
//! - traction alignment: over the instants the blade cuts (a pose with the blade engaged)
//!   while the jaws hold tissue drawn at least [`DRAWN_M`] from where they took hold, the
//!   time-weighted mean of `cos ∠(d, u)` between the draw `d = j - j₀` (`j₀`: the jaws when
//!   they took hold) and `u = j - b` (from the blade's tip `b` to the jaws): +1 draws the
//!   tissue straight away from the blade, 0 across, -1 slackens it towards the blade;
//! - countertraction: the share of the cutting time during which the jaws held the tissue
//!   drawn at least [`DRAWN_M`] and away from the blade (`d · u > 0`);
//! - the grasper's path: its jaws' path length from their first closing on (the hand at
//!   work; a tracked or touched grasper's place before it is not a reach it made), filtered
//!   as the blade's ([`super::path`]), over the whole attempt when the jaws never closed;
//! - bimanual balance and coordination of the blade and the jaws ([`super::motion::bimanual`]).

use nalgebra::{Point3, Vector3};

use super::path::{PathParams, path};
use super::{Better, Metric, Values, m};
use crate::geom;
use crate::input::{AttemptData, GrasperSample, PoseSample};

/// How far the jaws must have drawn the tissue from where they took hold for the hold to
/// count as traction (m): below it the grip is only held still.
pub const DRAWN_M: f64 = 0.001;

/// The longest time one sample stands for (s).
const MAX_DT_S: f64 = 0.05;

/// The tissue-handling metrics (reported, not scored), in report order.
pub const METRICS: &[Metric] = &[
    m(
        "grasps",
        "1",
        Better::LowerIsBetter,
        false,
        "times the grasper's jaws took hold of tissue",
    )
    .labelled("Grasps"),
    m(
        "grasp_slips",
        "1",
        Better::LowerIsBetter,
        false,
        "times the held tissue pulled out of the closed jaws",
    )
    .labelled("Grasp slips"),
    m(
        "peak_traction_n",
        "N",
        Better::LowerIsBetter,
        false,
        "largest pull of the held tissue on the grasper's jaws",
    )
    .labelled("Peak traction"),
    m(
        "mean_traction_n",
        "N",
        Better::LowerIsBetter,
        false,
        "mean pull of the held tissue on the jaws while they held it",
    )
    .labelled("Mean traction"),
    m(
        "time_traction_over_limit_s",
        "s",
        Better::LowerIsBetter,
        false,
        "time the jaws loaded the tissue past the plan's force limit",
    )
    .labelled("Traction over the limit"),
    m(
        "countertraction_fraction",
        "1",
        Better::HigherIsBetter,
        false,
        "share of the cutting time the other hand held the tissue drawn away from the blade",
    )
    .labelled("Countertraction")
    .shown_in("%", 100.0),
    m(
        "traction_alignment",
        "1",
        Better::HigherIsBetter,
        false,
        "mean cosine between the tissue's draw and the way from the blade to the jaws while cutting: 1 straight away from the blade, -1 towards it",
    )
    .labelled("Traction direction"),
    m(
        "grasper_path_length_m",
        "m",
        Better::LowerIsBetter,
        false,
        "distance travelled by the grasper's jaws from their first closing (filtered)",
    )
    .labelled("Grasper path length"),
];

/// What [`assess`] sets: [`METRICS`], then the bimanual measures of [`super::motion::METRICS`].
pub fn metrics() -> Vec<Metric> {
    let bimanual = super::motion::METRICS
        .iter()
        .filter(|m| m.key.starts_with("bimanual_"));
    METRICS.iter().chain(bimanual).copied().collect()
}

/// How the jaws held the tissue over one attempt.
#[derive(Debug, Clone, PartialEq)]
pub struct Handling {
    pub grasps: usize,
    pub slips: usize,
    pub peak_traction_n: f64,
    /// `None` when the jaws never held.
    pub mean_traction_n: Option<f64>,
    pub time_over_limit_s: f64,
    /// `None` when the blade never cut while the jaws held the tissue drawn.
    pub traction_alignment: Option<f64>,
    /// `None` when the blade never cut.
    pub countertraction_fraction: Option<f64>,
}

/// The time each of `t` (sorted) stands for: to the next, at most [`MAX_DT_S`].
fn intervals(t: &[f64]) -> Vec<f64> {
    let mut dt: Vec<f64> = t.windows(2).map(|w| (w[1] - w[0]).min(MAX_DT_S)).collect();
    if let Some(&last) = dt.last() {
        dt.push(last);
    } else if !t.is_empty() {
        dt.push(0.0);
    }
    dt
}

/// For each sample, where the jaws were when they took hold of what they hold (`None` while
/// they hold nothing).
fn hold_starts(g: &[GrasperSample]) -> Vec<Option<Point3<f64>>> {
    let mut start = None;
    g.iter()
        .map(|s| {
            start = s.holds().then(|| start.unwrap_or(Point3::from(s.jaws_m)));
            start
        })
        .collect()
}

/// The handling of `grasper` (finite, in time order) while `poses` cut, against a force
/// limit of `limit_n`.
pub fn handling(grasper: &[GrasperSample], poses: &[PoseSample], limit_n: f64) -> Handling {
    let t: Vec<f64> = grasper.iter().map(|s| s.t_s).collect();
    let dt = intervals(&t);
    let pull = |s: &GrasperSample| Vector3::from(s.pull_newtons).norm();
    let held = || grasper.iter().zip(&dt).filter(|(s, _)| s.holds());
    let grasps = grasper
        .iter()
        .enumerate()
        .filter(|(i, s)| s.holds() && (*i == 0 || !grasper[i - 1].holds()))
        .count();
    let slips = grasper
        .windows(2)
        .filter(|w| w[0].holds() && !w[1].holds() && w[1].closed)
        .count();
    let held_s = held().fold(0.0, |sum, (_, dt)| sum + dt);
    let mean_traction_n =
        (held_s > 0.0).then(|| held().map(|(s, dt)| pull(s) * dt).sum::<f64>() / held_s);
    let (alignment, countertraction) = traction_while_cutting(grasper, poses);
    Handling {
        grasps,
        slips,
        peak_traction_n: grasper.iter().map(pull).fold(0.0, f64::max),
        mean_traction_n,
        time_over_limit_s: held()
            .filter(|(s, _)| pull(s) > limit_n)
            .fold(0.0, |sum, (_, dt)| sum + dt),
        traction_alignment: alignment,
        countertraction_fraction: countertraction,
    }
}

/// The traction alignment and the countertraction share of the cutting time (see the
/// module's notes): each cutting pose takes the grasper's latest sample at most
/// [`MAX_DT_S`] before it.
fn traction_while_cutting(
    grasper: &[GrasperSample],
    poses: &[PoseSample],
) -> (Option<f64>, Option<f64>) {
    let starts = hold_starts(grasper);
    let t: Vec<f64> = poses.iter().map(|p| p.t_s).collect();
    let dt = intervals(&t);
    let (mut cutting_s, mut drawn_s, mut cos_s, mut away_s) = (0.0, 0.0, 0.0, 0.0);
    for (p, &dt) in poses.iter().zip(&dt).filter(|(p, _)| p.blade_engaged) {
        cutting_s += dt;
        let i = grasper.partition_point(|g| g.t_s <= p.t_s);
        let Some(k) = i
            .checked_sub(1)
            .filter(|&k| p.t_s - grasper[k].t_s <= MAX_DT_S)
        else {
            continue;
        };
        let Some(start) = starts[k] else {
            continue;
        };
        let jaws = Point3::from(grasper[k].jaws_m);
        let (draw, from_blade) = (jaws - start, jaws - Point3::from(p.tip_m));
        if draw.norm() < DRAWN_M || from_blade.norm() == 0.0 {
            continue;
        }
        let cos = draw.normalize().dot(&from_blade.normalize());
        drawn_s += dt;
        cos_s += cos * dt;
        if cos > 0.0 {
            away_s += dt;
        }
    }
    (
        (drawn_s > 0.0).then(|| cos_s / drawn_s),
        (cutting_s > 0.0).then(|| away_s / cutting_s),
    )
}

/// Sets [`metrics`] from `data`'s grasper (nothing when it has none) against a force limit
/// of `limit_n`; a non-finite sample leaves them missing.
pub(crate) fn assess(data: &AttemptData, limit_n: f64, values: &mut Values) {
    let keys: Vec<&'static str> = metrics().iter().map(|m| m.key).collect();
    if data.grasper.is_empty() {
        values.missing(&keys, "the attempt was made without a grasper");
        return;
    }
    let finite = |s: &GrasperSample| {
        s.t_s.is_finite() && geom::finite(&s.jaws_m) && geom::finite(&s.pull_newtons)
    };
    if let Some(i) = data.grasper.iter().position(|s| !finite(s)) {
        values.missing(&keys, &format!("grasper sample {i}: a value is not finite"));
        return;
    }
    let mut grasper = data.grasper.clone();
    grasper.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let h = handling(&grasper, &data.poses, limit_n);
    values.set("grasps", h.grasps as f64);
    values.set("grasp_slips", h.slips as f64);
    values.set("peak_traction_n", h.peak_traction_n);
    values.set("time_traction_over_limit_s", h.time_over_limit_s);
    let never = |v: Option<f64>, key: &'static str, why: &str, values: &mut Values| match v {
        Some(v) => values.set(key, v),
        None => values.missing(&[key], why),
    };
    never(
        h.mean_traction_n,
        "mean_traction_n",
        "the jaws never held tissue",
        values,
    );
    never(
        h.traction_alignment,
        "traction_alignment",
        "the blade never cut while the jaws held the tissue drawn",
        values,
    );
    never(
        h.countertraction_fraction,
        "countertraction_fraction",
        "the blade never cut",
        values,
    );
    let at_work = grasper.iter().position(|s| s.closed).unwrap_or(0);
    let jaws: Vec<PoseSample> = grasper[at_work..]
        .iter()
        .map(|s| PoseSample {
            t_s: s.t_s,
            tip_m: s.jaws_m,
            quat_wxyz: [1.0, 0.0, 0.0, 0.0],
            blade_engaged: false,
        })
        .collect();
    match path(&jaws, &PathParams::default()) {
        Ok(p) => values.set("grasper_path_length_m", p.path_length_m),
        Err(e) => values.missing(&["grasper_path_length_m"], &e.to_string()),
    }
    let (ratio, correlation) = super::motion::bimanual(&data.poses, &jaws);
    let why = "a hand did not move, or the two never moved together";
    never(ratio, "bimanual_path_ratio", why, values);
    never(correlation, "bimanual_speed_correlation", why, values);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grasper holding from 1 s, drawing the tissue `draw` over the next second, letting
    /// go at 4 s (`slip`: the tissue slips out with the jaws still closed), pulling
    /// `pull_n` along `-draw` while it holds; 1 ms samples to 5 s.
    fn grasper(draw: Vector3<f64>, pull_n: f64, slip: bool) -> Vec<GrasperSample> {
        let at = Point3::new(0.05, 0.06, 0.001);
        (0..=5000)
            .map(|i| {
                let t = f64::from(i) * 1e-3;
                let jaws = at + draw * (t - 1.0).clamp(0.0, 1.0);
                let closed = (1.0..4.0).contains(&t) || (slip && t >= 4.0);
                let holds = (1.0..4.0).contains(&t);
                let pull = if holds {
                    -draw.normalize() * pull_n
                } else {
                    Vector3::zeros()
                };
                GrasperSample {
                    t_s: t,
                    jaws_m: jaws.into(),
                    closed,
                    pull_newtons: pull.into(),
                }
            })
            .collect()
    }

    /// The blade cutting along x at y = 0.05 from 2 s to 3 s, at rest before and after.
    fn blade() -> Vec<PoseSample> {
        (0..=5000)
            .map(|i| {
                let t = f64::from(i) * 1e-3;
                PoseSample {
                    t_s: t,
                    tip_m: [0.04 + 0.02 * (t - 2.0).clamp(0.0, 1.0), 0.05, 0.0],
                    quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                    blade_engaged: (2.0..3.0).contains(&t),
                }
            })
            .collect()
    }

    #[test]
    fn drawing_the_tissue_away_from_the_blade_is_countertraction() {
        // the jaws 10 mm beside the cut draw 5 mm further away from it (+y) and up
        let away = handling(
            &grasper(Vector3::new(0.0, 0.005, 0.005), 1.0, false),
            &blade(),
            2.0,
        );
        assert_eq!((away.grasps, away.slips), (1, 0));
        assert!(
            (away.countertraction_fraction.unwrap() - 1.0).abs() < 1e-3,
            "{away:?}"
        );
        assert!(away.traction_alignment.unwrap() > 0.6, "{away:?}");
        assert!((away.peak_traction_n - 1.0).abs() < 1e-12);
        assert!((away.mean_traction_n.unwrap() - 1.0).abs() < 1e-12);
        assert!(
            away.time_over_limit_s.to_bits() == 0,
            "{away:?}: +0, not -0"
        );
        // drawn towards the blade: slack, no countertraction
        let towards = handling(
            &grasper(Vector3::new(0.0, -0.005, 0.0), 1.0, false),
            &blade(),
            2.0,
        );
        assert_eq!(towards.countertraction_fraction, Some(0.0), "{towards:?}");
        assert!(towards.traction_alignment.unwrap() < -0.5, "{towards:?}");
    }

    #[test]
    fn a_pull_past_the_limit_is_timed_and_a_slip_counted() {
        let h = handling(
            &grasper(Vector3::new(0.0, 0.005, 0.0), 3.0, true),
            &blade(),
            2.0,
        );
        // held from 1 s to 4 s at 3 N, past the 2 N limit all along
        assert!((h.time_over_limit_s - 3.0).abs() < 2e-3, "{h:?}");
        assert_eq!((h.grasps, h.slips), (1, 1));
        // opened rather than slipped: no slip
        let opened = handling(
            &grasper(Vector3::new(0.0, 0.005, 0.0), 3.0, false),
            &blade(),
            2.0,
        );
        assert_eq!(opened.slips, 0);
    }

    #[test]
    fn a_grip_held_still_draws_nothing_and_no_cut_measures_no_traction() {
        let still = handling(
            &grasper(Vector3::new(0.0, 0.0005, 0.0), 0.5, false),
            &blade(),
            2.0,
        );
        assert_eq!(still.traction_alignment, None);
        assert_eq!(still.countertraction_fraction, Some(0.0));
        let no_cut: Vec<PoseSample> = blade()
            .into_iter()
            .map(|p| PoseSample {
                blade_engaged: false,
                ..p
            })
            .collect();
        let h = handling(
            &grasper(Vector3::new(0.0, 0.005, 0.0), 0.5, false),
            &no_cut,
            2.0,
        );
        assert_eq!(
            (h.traction_alignment, h.countertraction_fraction),
            (None, None)
        );
    }

    #[test]
    fn the_group_is_missing_without_a_grasper_or_with_a_nan_sample() {
        let set = |data: &AttemptData| {
            let mut v = Values::default();
            assess(data, 2.0, &mut v);
            v.collect(&metrics())
        };
        let none = set(&AttemptData::default());
        assert!(none.iter().all(|v| v.value.is_none()), "{none:?}");
        let mut data = AttemptData {
            poses: blade(),
            grasper: grasper(Vector3::new(0.0, 0.005, 0.005), 1.0, false),
            ..AttemptData::default()
        };
        let all = set(&data);
        assert!(all.iter().all(|v| v.value.is_some()), "{all:?}");
        let path = super::super::value_of(&all, "grasper_path_length_m").unwrap();
        // 7.07 mm drawn; the filter may round the corners off a little
        assert!((path - 0.00707).abs() < 3e-4, "{path}");
        data.grasper[10].pull_newtons[1] = f64::NAN;
        let nan = set(&data);
        assert!(
            nan.iter().all(|v| v
                .missing
                .as_deref()
                .is_some_and(|m| m.contains("not finite"))),
            "{nan:?}"
        );
    }
}
