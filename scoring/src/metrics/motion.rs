//! Motion measures the field uses beyond the path metrics, for kinematics recorded anywhere:
//! one tool's depth path and the regularity of its speed (approximate entropy), and how two
//! tools move together (bimanual balance and coordination). Reported by
//! `cutlab import kinematics`; definitions in docs/guide/evidence.md.

use super::smoothness::{derivative, resample};
use super::{Better, Metric, m};
use crate::input::PoseSample;

/// The rate the speeds are resampled at (Hz): below the hand's tremor, above its movements.
pub const SPEED_HZ: f64 = 10.0;

/// The measures' catalogue (not scored by any exercise).
pub const METRICS: &[Metric] = &[
    m(
        "depth_path_m",
        "m",
        Better::LowerIsBetter,
        false,
        "the tool tip's path along the data's z axis (the camera's viewing axis when the poses are in its frame): depth perception",
    )
    .labelled("Depth path"),
    m(
        "speed_apen",
        "1",
        Better::LowerIsBetter,
        false,
        "approximate entropy (m = 2, r = 0.2 SD) of the tip's speed at 10 Hz: lower is more regular",
    )
    .labelled("Speed entropy (ApEn)"),
    m(
        "bimanual_path_ratio",
        "1",
        Better::HigherIsBetter,
        false,
        "the shorter of two tools' paths over the longer: 1 when both hands work as much",
    )
    .labelled("Bimanual balance"),
    m(
        "bimanual_speed_correlation",
        "1",
        Better::HigherIsBetter,
        false,
        "Pearson correlation of two tools' speeds at 10 Hz over their common time: how the hands move together",
    )
    .labelled("Bimanual coordination"),
];

/// The tip's speed at [`SPEED_HZ`] from `t0` (the poses' first time unless later), as the
/// derivative of the resampled positions.
fn speed(poses: &[PoseSample], t0: f64, t1: f64) -> Vec<f64> {
    let inside: Vec<&PoseSample> = poses
        .iter()
        .filter(|p| p.t_s >= t0 && p.t_s <= t1)
        .collect();
    if inside.len() < 3 {
        return Vec::new();
    }
    let t: Vec<f64> = inside.iter().map(|p| p.t_s).collect();
    let axes: Vec<Vec<f64>> = (0..3)
        .map(|k| {
            let x: Vec<f64> = inside.iter().map(|p| p.tip_m[k]).collect();
            derivative(&resample(&t, &x, SPEED_HZ), 1.0 / SPEED_HZ)
        })
        .collect();
    (0..axes[0].len())
        .map(|i| (axes[0][i].powi(2) + axes[1][i].powi(2) + axes[2][i].powi(2)).sqrt())
        .collect()
}

/// The path along z: `Σ |z_{i+1} - z_i|`.
pub fn depth_path_m(poses: &[PoseSample]) -> f64 {
    poses
        .windows(2)
        .map(|w| (w[1].tip_m[2] - w[0].tip_m[2]).abs())
        .sum()
}

/// Approximate entropy (Pincus 1991) of `x`: `ApEn = Φ_m(r) - Φ_{m+1}(r)`, `Φ_m(r) =
/// mean_i ln C_i^m(r)`, `C_i^m(r)` the share of the `N - m + 1` windows of length `m` within
/// `r` of window `i` (the largest difference; each window counts itself). `None` below
/// `m + 2` values or for `r <= 0`.
pub fn approximate_entropy(x: &[f64], m: usize, r: f64) -> Option<f64> {
    if x.len() < m + 2 || !(r > 0.0) {
        return None;
    }
    let phi = |m: usize| {
        let n = x.len() - m + 1;
        let close = |i: usize, j: usize| (0..m).all(|k| (x[i + k] - x[j + k]).abs() <= r);
        (0..n)
            .map(|i| ((0..n).filter(|&j| close(i, j)).count() as f64 / n as f64).ln())
            .sum::<f64>()
            / n as f64
    };
    Some(phi(m) - phi(m + 1))
}

/// [`approximate_entropy`] of the tip's speed at [`SPEED_HZ`], `m = 2`, `r = 0.2 SD`.
pub fn speed_apen(poses: &[PoseSample]) -> Option<f64> {
    let (t0, t1) = (poses.first()?.t_s, poses.last()?.t_s);
    let v = speed(poses, t0, t1);
    let (_, sd) = crate::stats::mean_sd(&v)?;
    approximate_entropy(&v, 2, 0.2 * sd)
}

/// How two tools move together: the path ratio (shorter over longer) and the correlation of
/// their speeds over their common time. `None` for what cannot be measured (a tool that did
/// not move, no common time, no speed spread).
pub fn bimanual(a: &[PoseSample], b: &[PoseSample]) -> (Option<f64>, Option<f64>) {
    let path = |p: &[PoseSample]| {
        let tips: Vec<nalgebra::Point3<f64>> = p.iter().map(|s| s.tip_m.into()).collect();
        crate::geom::polyline_length(&tips)
    };
    let (pa, pb) = (path(a), path(b));
    let ratio = (pa.max(pb) > 0.0).then(|| pa.min(pb) / pa.max(pb));
    let (Some(fa), Some(fb), Some(la), Some(lb)) = (a.first(), b.first(), a.last(), b.last())
    else {
        return (ratio, None);
    };
    let (t0, t1) = (fa.t_s.max(fb.t_s), la.t_s.min(lb.t_s));
    let (va, vb) = (speed(a, t0, t1), speed(b, t0, t1));
    let n = va.len().min(vb.len());
    (ratio, crate::stats::pearson(&va[..n], &vb[..n]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(t: f64, x: f64, z: f64) -> PoseSample {
        PoseSample {
            t_s: t,
            tip_m: [x, 0.0, z],
            quat_wxyz: [1.0, 0.0, 0.0, 0.0],
            blade_engaged: false,
        }
    }

    #[test]
    fn approximate_entropy_by_hand_and_of_regular_and_random_series() {
        // 1 2 1 2 1, m = 1, r = 0.5: windows of 1: {1,2,1,2,1}: C = 3/5 for the 1s, 2/5 for
        // the 2s; Φ1 = (3 ln .6 + 2 ln .4) / 5; windows of 2: 12 21 12 21: C = 1/2 each,
        // Φ2 = ln .5
        let want = (3.0 * 0.6f64.ln() + 2.0 * 0.4f64.ln()) / 5.0 - 0.5f64.ln();
        let got = approximate_entropy(&[1.0, 2.0, 1.0, 2.0, 1.0], 1, 0.5).unwrap();
        assert!((got - want).abs() < 1e-12, "{got} {want}");
        // a periodic series is regular; a scrambled one is not
        let periodic: Vec<f64> = (0..200).map(|i| (i % 4) as f64).collect();
        let mut rng = cutlab_sim::rng::Rng::new(3);
        let noise: Vec<f64> = (0..200).map(|_| rng.uniform()).collect();
        let (p, n) = (
            approximate_entropy(&periodic, 2, 0.2).unwrap(),
            approximate_entropy(&noise, 2, 0.2 * 0.29).unwrap(),
        );
        assert!(p < 0.05 && n > 0.5, "{p} {n}");
        assert!(approximate_entropy(&[1.0, 2.0], 2, 0.1).is_none());
    }

    #[test]
    fn depth_path_and_two_hands() {
        let a: Vec<PoseSample> = (0..=20)
            .map(|i| {
                pose(
                    0.1 * i as f64,
                    0.01 * i as f64,
                    if i % 2 == 0 { 0.0 } else { 0.001 },
                )
            })
            .collect();
        assert!((depth_path_m(&a) - 0.02).abs() < 1e-12);
        // the second hand moves half as far, in step: balance 0.5, coordination 1
        let b: Vec<PoseSample> = (0..=20)
            .map(|i| pose(0.1 * i as f64, 0.005 * (i as f64).powi(2) / 20.0, 0.0))
            .collect();
        let c: Vec<PoseSample> = b
            .iter()
            .map(|p| pose(p.t_s, 2.0 * p.tip_m[0], 0.0))
            .collect();
        let (ratio, corr) = bimanual(&b, &c);
        assert!(
            (ratio.unwrap() - 0.5).abs() < 1e-9 && (corr.unwrap() - 1.0).abs() < 1e-9,
            "{ratio:?} {corr:?}"
        );
        // a hand at rest: balance 0, no coordination to measure
        let still: Vec<PoseSample> = (0..=20).map(|i| pose(0.1 * i as f64, 0.0, 0.0)).collect();
        assert_eq!(bimanual(&b, &still), (Some(0.0), None));
    }
}
