//! Path metrics from the tool poses: how the hand moved, independently of what it cut.
//!
//! They are taken over the task's window ([`task_window`]): from the first pose with the
//! blade engaged to the last one, so the reach to the entry, the hand waiting above it and
//! the lift after the cut are not counted as the task's time, path or movements (all poses
//! when the blade never engaged).
//!
//! The tip positions are resampled to a uniform `resample_hz` (linear interpolation on the
//! time column, so any input rate works, uneven ones too), each coordinate is low-pass
//! filtered with the zero-phase Butterworth of [`smoothness::lowpass_zero_phase`]
//! (`cutoff_hz`, default 6 Hz: hand motion lies below it, tremor and sensor noise above), and
//! only then differentiated (central differences) to the speed `v(t) = |dx/dt|`.
//!
//! - time: the task time, from the first to the last sample where `v` reaches
//!   `idle_speed_m_s` (still time before or after the task does not count);
//! - path length: `sum |x[k+1] - x[k]|` over the filtered samples;
//! - economy of motion: `|x_last - x_first| / path length` (1 for a straight line);
//! - idle time: total length of the intervals whose mean speed is below `idle_speed_m_s`;
//! - movements: the strokes, runs where the speed across the blade's axis
//!   `v_across = |v - (v . a) a|` (`a` the tool's z axis, resampled like the tip) exceeds
//!   `max(movement_fraction * peak v_across, min(movement_floor_m_s, mean v / 2))`, lasting at
//!   least `min_movement_s` and going at least `min_movement_m` from where they began (a dip
//!   below the threshold shorter than `min_movement_s` does not end a run). Pressing the blade
//!   in and lifting it out run along its axis and are not strokes: a pointer's press (8 mm in
//!   one 60 Hz frame) had set the peak, and a 4 mm/s stroke under its tenth counted as none.
//!   The floor gives way to a stroke slower than it (a stroke at 3 mm/s is a movement, not
//!   none); the distance keeps a hand's noise, its drift and what the filter leaves of its
//!   tremor, from counting when it holds still;
//! - angular path: `sum 2 acos |q_i . q_(i+1)|` over the raw unit quaternions (rad);
//! - smoothness: LDLJ and SPARC ([`smoothness`]) of the whole speed profile, and their mean
//!   over the movements (each movement's own speed profile).

use nalgebra::{Point3, Quaternion, UnitQuaternion, Vector3};

use crate::error::{Result, ScoreError};
use crate::geom;
use crate::input::PoseSample;
use crate::metrics::Values;
use crate::metrics::smoothness;

/// Parameters of the path metrics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathParams {
    /// Uniform rate the poses are resampled to (Hz).
    pub resample_hz: f64,
    /// Cut-off of the zero-phase low-pass filter on positions (Hz).
    pub cutoff_hz: f64,
    /// Below this speed the tool counts as idle (m/s).
    pub idle_speed_m_s: f64,
    /// Movement threshold as a fraction of the peak speed ...
    pub movement_fraction: f64,
    /// ... but at least this (m/s), or half the mean speed `path length / duration` where
    /// that is lower (a slow stroke).
    pub movement_floor_m_s: f64,
    /// Shorter runs above the threshold are not movements (s).
    pub min_movement_s: f64,
    /// Nor runs that end nearer than this to where they began (m).
    pub min_movement_m: f64,
    /// SPARC: zero padding level, cut-off (Hz), amplitude threshold.
    pub sparc_padlevel: u32,
    pub sparc_fc_hz: f64,
    pub sparc_amp_th: f64,
}

impl Default for PathParams {
    fn default() -> Self {
        Self {
            resample_hz: 100.0,
            cutoff_hz: 6.0,
            idle_speed_m_s: 0.005,
            movement_fraction: 0.1,
            movement_floor_m_s: 0.005,
            min_movement_s: 0.1,
            min_movement_m: 0.001,
            sparc_padlevel: 4,
            sparc_fc_hz: 10.0,
            sparc_amp_th: 0.05,
        }
    }
}

/// Smoothness of one movement.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Movement {
    pub start_s: f64,
    pub end_s: f64,
    pub peak_speed_m_s: f64,
    pub ldlj: Option<f64>,
    pub sparc: Option<f64>,
}

/// The path metrics of one trajectory.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PathMetrics {
    pub time_s: f64,
    pub path_length_m: f64,
    /// `None` when the tool did not move.
    pub economy_of_motion: Option<f64>,
    pub idle_time_s: f64,
    pub movements: usize,
    pub angular_path_rad: f64,
    pub ldlj: Option<f64>,
    pub sparc: Option<f64>,
    pub ldlj_per_movement: Option<f64>,
    pub sparc_per_movement: Option<f64>,
    pub per_movement: Vec<Movement>,
    pub peak_speed_m_s: f64,
}

impl PathMetrics {
    /// The metrics under their catalogue keys ([`super::METRICS`]); `None` where not
    /// measured (the tool did not move).
    pub fn keyed(&self) -> [(&'static str, Option<f64>); 10] {
        [
            ("time_s", Some(self.time_s)),
            ("path_length_m", Some(self.path_length_m)),
            ("economy_of_motion", self.economy_of_motion),
            ("idle_time_s", Some(self.idle_time_s)),
            ("movements", Some(self.movements as f64)),
            ("angular_path_rad", Some(self.angular_path_rad)),
            ("ldlj", self.ldlj),
            ("sparc", self.sparc),
            ("ldlj_per_movement", self.ldlj_per_movement),
            ("sparc_per_movement", self.sparc_per_movement),
        ]
    }
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

/// The path metrics of `poses` (at least 3 with distinct times, all finite, non-zero
/// quaternions; sorted by time here).
pub fn path(poses: &[PoseSample], p: &PathParams) -> Result<PathMetrics> {
    if let Some(i) = poses
        .iter()
        .position(|s| !s.t_s.is_finite() || !geom::finite(&s.tip_m) || !geom::finite(&s.quat_wxyz))
    {
        return Err(ScoreError::InvalidInput(format!(
            "pose {i}: a value is not finite"
        )));
    }
    if let Some(i) = poses
        .iter()
        .position(|s| s.quat_wxyz.iter().map(|c| c * c).sum::<f64>() < 1e-12)
    {
        return Err(ScoreError::InvalidInput(format!(
            "pose {i}: zero quaternion"
        )));
    }
    let mut poses = poses.to_vec();
    poses.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    poses.dedup_by(|b, a| b.t_s <= a.t_s);
    if poses.len() < 3 {
        return Err(ScoreError::InvalidInput(format!(
            "{} poses with distinct times: need at least 3",
            poses.len()
        )));
    }
    let fs = p.resample_hz;
    let dt = 1.0 / fs;
    let t: Vec<f64> = poses.iter().map(|s| s.t_s).collect();
    let coords: Vec<Vec<f64>> = (0..3)
        .map(|c| {
            let x: Vec<f64> = poses.iter().map(|s| s.tip_m[c]).collect();
            smoothness::lowpass_zero_phase(&smoothness::resample(&t, &x, fs), fs, p.cutoff_hz)
        })
        .collect();
    let n = coords[0].len();
    let pos = |k: usize| Point3::new(coords[0][k], coords[1][k], coords[2][k]);
    let vel: Vec<Vec<f64>> = coords
        .iter()
        .map(|x| smoothness::derivative(x, dt))
        .collect();
    let speed: Vec<f64> = (0..n)
        .map(|k| Vector3::new(vel[0][k], vel[1][k], vel[2][k]).norm())
        .collect();

    let path_length_m: f64 = (1..n)
        .map(|k| nalgebra::distance(&pos(k), &pos(k - 1)))
        .sum();
    let straight = nalgebra::distance(&pos(n - 1), &pos(0));
    let economy_of_motion = (path_length_m > 1e-9).then(|| (straight / path_length_m).min(1.0));
    let idle_time_s = (1..n)
        .filter(|&k| 0.5 * (speed[k] + speed[k - 1]) < p.idle_speed_m_s)
        .count() as f64
        * dt;
    // the task time: from the first to the last moment the tip moves (a recording that runs
    // on before or after the task does not count)
    let moving = |k: &usize| speed[*k] >= p.idle_speed_m_s;
    let time_s = match ((0..n).find(moving), (0..n).rev().find(moving)) {
        (Some(first), Some(last)) => (last - first) as f64 * dt,
        _ => 0.0,
    };

    let peak = speed.iter().copied().fold(0.0, f64::max);
    let across = speed_across_axis(&t, &poses, &vel, fs);
    let peak_across = across.iter().copied().fold(0.0, f64::max);
    let mean_speed = path_length_m / ((n - 1) as f64 * dt);
    let floor = p.movement_floor_m_s.min(0.5 * mean_speed);
    let threshold = floor.max(p.movement_fraction * peak_across);
    let min_len = (p.min_movement_s * fs).round() as usize;
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut start = None;
    for k in 0..=n {
        let above = k < n && across[k] > threshold;
        match (above, start) {
            (true, None) => start = Some(k),
            (false, Some(s)) => {
                // a dip shorter than a movement does not end one
                match runs.last_mut() {
                    Some(last) if s - last.1 <= min_len => last.1 = k - 1,
                    _ => runs.push((s, k - 1)),
                }
                start = None;
            }
            _ => {}
        }
    }
    let per_movement: Vec<Movement> = runs
        .into_iter()
        .filter(|&(s, e)| {
            e - s >= min_len && nalgebra::distance(&pos(s), &pos(e)) >= p.min_movement_m
        })
        .map(|(s, e)| {
            let v = &speed[s..=e];
            Movement {
                start_s: t[0] + s as f64 * dt,
                end_s: t[0] + e as f64 * dt,
                peak_speed_m_s: v.iter().copied().fold(0.0, f64::max),
                ldlj: smoothness::ldlj(v, fs),
                sparc: smoothness::sparc(v, fs, p.sparc_padlevel, p.sparc_fc_hz, p.sparc_amp_th),
            }
        })
        .collect();

    let quats: Vec<[f64; 4]> = poses
        .iter()
        .map(|s| {
            let q = s.quat_wxyz;
            let l = q.iter().map(|c| c * c).sum::<f64>().sqrt();
            [q[0] / l, q[1] / l, q[2] / l, q[3] / l]
        })
        .collect();
    let angular_path_rad = quats
        .windows(2)
        .map(|w| {
            let d: f64 = (0..4)
                .map(|i| w[0][i] * w[1][i])
                .sum::<f64>()
                .abs()
                .min(1.0);
            2.0 * d.acos()
        })
        .sum();

    Ok(PathMetrics {
        time_s,
        path_length_m,
        economy_of_motion,
        idle_time_s,
        movements: per_movement.len(),
        angular_path_rad,
        ldlj: smoothness::ldlj(&speed, fs),
        sparc: smoothness::sparc(&speed, fs, p.sparc_padlevel, p.sparc_fc_hz, p.sparc_amp_th),
        ldlj_per_movement: mean(per_movement.iter().filter_map(|m| m.ldlj)),
        sparc_per_movement: mean(per_movement.iter().filter_map(|m| m.sparc)),
        per_movement,
        peak_speed_m_s: peak,
    })
}

/// `|v - (v . a) a|` at each resampled instant: the tip's velocity `vel` (per coordinate)
/// without its part along the tool's z axis `a` (the blade's), the axis resampled at `fs`
/// from `poses`' quaternions (times `t`) like the tip.
fn speed_across_axis(t: &[f64], poses: &[PoseSample], vel: &[Vec<f64>], fs: f64) -> Vec<f64> {
    let axes: Vec<Vector3<f64>> = poses
        .iter()
        .map(|s| {
            let [w, x, y, z] = s.quat_wxyz;
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)) * Vector3::z()
        })
        .collect();
    let a: Vec<Vec<f64>> = (0..3)
        .map(|c| smoothness::resample(t, &axes.iter().map(|v| v[c]).collect::<Vec<_>>(), fs))
        .collect();
    (0..vel[0].len())
        .map(|k| {
            let v = Vector3::new(vel[0][k], vel[1][k], vel[2][k]);
            let axis = Vector3::new(a[0][k], a[1][k], a[2][k]);
            match axis.try_normalize(1e-9) {
                Some(u) => (v - u * v.dot(&u)).norm(),
                None => v.norm(),
            }
        })
        .collect()
}

/// The poses from the first with the blade engaged to the last (all of them when fewer than
/// two are engaged): the task, without the reach before it and the lift after it.
pub fn task_window(poses: &[PoseSample]) -> &[PoseSample] {
    let first = poses.iter().position(|p| p.blade_engaged);
    let last = poses.iter().rposition(|p| p.blade_engaged);
    match (first, last) {
        (Some(a), Some(b)) if b > a => &poses[a..=b],
        _ => poses,
    }
}

pub(crate) fn assess(poses: &[PoseSample], p: &PathParams, values: &mut Values) {
    let poses = task_window(poses);
    const KEYS: [&str; 10] = [
        "time_s",
        "path_length_m",
        "economy_of_motion",
        "idle_time_s",
        "movements",
        "angular_path_rad",
        "ldlj",
        "sparc",
        "ldlj_per_movement",
        "sparc_per_movement",
    ];
    match path(poses, p) {
        Ok(m) => {
            for (key, v) in m.keyed() {
                match v {
                    Some(v) => values.set(key, v),
                    None => values.missing(&[key], "no movement"),
                }
            }
        }
        Err(e) => values.missing(&KEYS, &e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(t: f64, x: [f64; 3], angle_z: f64) -> PoseSample {
        let h = 0.5 * angle_z;
        PoseSample {
            t_s: t,
            tip_m: x,
            quat_wxyz: [h.cos(), 0.0, 0.0, h.sin()],
            blade_engaged: false,
        }
    }

    /// Minimum-jerk displacement from 0 to `d` over [0, 1].
    fn min_jerk(tau: f64, d: f64) -> f64 {
        let tau = tau.clamp(0.0, 1.0);
        d * (10.0 * tau.powi(3) - 15.0 * tau.powi(4) + 6.0 * tau.powi(5))
    }

    #[test]
    fn a_straight_constant_speed_line_with_a_quarter_turn() {
        let poses: Vec<PoseSample> = (0..=1000)
            .map(|i| i as f64 * 1e-3)
            .map(|t| pose(t, [0.1 * t, 0.0, 0.0], t * std::f64::consts::FRAC_PI_2))
            .collect();
        let m = path(&poses, &PathParams::default()).unwrap();
        assert!((m.time_s - 1.0).abs() < 1e-12);
        assert!((m.path_length_m - 0.1).abs() < 1e-6, "{}", m.path_length_m);
        assert!((m.economy_of_motion.unwrap() - 1.0).abs() < 1e-6);
        assert!(m.idle_time_s < 1e-12);
        assert_eq!(m.movements, 1);
        assert!(
            (m.angular_path_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-6,
            "{}",
            m.angular_path_rad
        );
    }

    #[test]
    fn minimum_jerk_reach_has_the_analytic_ldlj() {
        // DJ of a minimum-jerk speed profile: -720 / 1.875^2 = -204.8, LDLJ = -ln 204.8
        let poses: Vec<PoseSample> = (0..=1000)
            .map(|i| i as f64 * 1e-3)
            .map(|t| pose(t, [min_jerk(t, 0.1), 0.0, 0.0], 0.0))
            .collect();
        let m = path(&poses, &PathParams::default()).unwrap();
        let expected = -(204.8f64).ln();
        assert!(
            (m.ldlj.unwrap() - expected).abs() < 0.03 * expected.abs(),
            "{:?} vs {expected}",
            m.ldlj
        );
        assert!(
            m.sparc.unwrap() > -1.8 && m.sparc.unwrap() < -1.3,
            "{:?}",
            m.sparc
        );
        assert!((m.path_length_m - 0.1).abs() < 1e-4);
    }

    #[test]
    fn rest_move_rest_move_rest_counts_two_movements_and_the_idle_time() {
        // rest 1 s, reach 1 s, rest 1 s, reach back 1 s, rest 1 s, sampled unevenly near 60 Hz
        let x = |t: f64| min_jerk(t - 1.0, 0.1) - min_jerk(t - 3.0, 0.1);
        let mut t = 0.0;
        let mut poses = Vec::new();
        let mut k = 0u32;
        while t <= 5.0 {
            poses.push(pose(t, [x(t), 0.0, 0.0], 0.0));
            k += 1;
            t += if k.is_multiple_of(2) { 0.012 } else { 0.021 };
        }
        let m = path(&poses, &PathParams::default()).unwrap();
        assert_eq!(m.movements, 2, "{:?}", m.per_movement);
        assert!((m.path_length_m - 0.2).abs() < 0.002, "{}", m.path_length_m);
        assert!(m.economy_of_motion.unwrap() < 0.01);
        // idle: the 3 rests plus the slow starts and ends of each reach (speed < 5 mm/s)
        assert!(
            m.idle_time_s > 3.0 && m.idle_time_s < 3.4,
            "{}",
            m.idle_time_s
        );
        // the task time: from the start of the first reach to the end of the second (t = 1 to
        // 4 s, less their slow starts and ends), not the 5 s recorded
        assert!(m.time_s > 2.6 && m.time_s < 3.0, "{}", m.time_s);
        assert!(
            m.ldlj_per_movement.unwrap() > m.ldlj.unwrap(),
            "each reach is smoother than the whole"
        );
        assert!(m.per_movement[0].start_s > 1.0 && m.per_movement[0].end_s < 2.0);
    }

    /// The poses of `gestures` of a hand at 1 px to the millimetre.
    fn hand_poses(gestures: &[cutlab_haptics::hand::Gesture]) -> Vec<PoseSample> {
        use cutlab_haptics::hand::Gesture;
        let (mut t_ms, mut out) = (0u64, Vec::new());
        for g in gestures {
            match *g {
                Gesture::Move { x, y, ms } => {
                    t_ms += ms;
                    out.push(pose(t_ms as f64 * 1e-3, [x * 1e-3, y * 1e-3, 0.0], 0.0));
                }
                Gesture::Wait { ms } => t_ms += ms,
                Gesture::Press | Gesture::Release => {}
            }
        }
        out
    }

    #[test]
    fn a_slow_stroke_is_one_movement_and_a_still_hand_none() {
        use cutlab_haptics::hand::Hand;
        // 60 mm in 30 s (2 mm/s on average, 3.75 mm/s at most: below the 5 mm/s floor) by a
        // steady hand, its tremor and drift on it
        for seed in 0..5 {
            let slow = Hand::steady(1.0, seed).stroke(&[[0.0, 0.0], [60.0, 0.0]], 30.0, 1.0);
            let m = path(&hand_poses(&slow), &PathParams::default()).expect("path");
            assert_eq!(m.movements, 1, "seed {seed}: {:?}", m.per_movement);
        }
        // a hand that holds still for 5 s (a stroke of 0.01 mm), steady or shaky: no movement
        for seed in 0..5 {
            for mut hand in [Hand::steady(1.0, seed), Hand::sloppy(1.0, seed)] {
                let still = hand.stroke(&[[0.0, 0.0], [0.01, 0.0]], 5.0, 1.0);
                let m = path(&hand_poses(&still), &PathParams::default()).expect("path");
                assert_eq!(m.movements, 0, "seed {seed}: {:?}", m.per_movement);
            }
        }
    }

    #[test]
    fn a_pointers_press_and_lift_along_the_blade_are_not_strokes() {
        // a pointer's stroke: the blade pressed 8 mm in along its axis in one 60 Hz frame, 60
        // mm at 4 mm/s in 0.2 mm pixels every 50 ms, lifted out in one frame; engaged throughout
        let frame = 1.0 / 60.0;
        let mut poses = Vec::new();
        let mut push = |t: f64, x: f64, z: f64| {
            let mut p = pose(t, [x, 0.0, z], 0.0);
            p.blade_engaged = true;
            poses.push(p);
        };
        push(0.0, 0.0, 0.0);
        push(frame, 0.0, -0.008);
        let stroke_s = 15.0;
        let frames = (stroke_s / frame) as usize;
        for i in 1..=frames {
            let t = i as f64 * frame;
            push(frame + t, 0.0002 * (t / 0.05).floor(), -0.008);
        }
        let end = frame + frames as f64 * frame;
        let x_end = 0.0002 * ((frames as f64 * frame) / 0.05).floor();
        push(end + frame, x_end, 0.0);
        push(end + 2.0 * frame, x_end, 0.0);
        let m = path(&poses, &PathParams::default()).expect("path");
        assert_eq!(m.movements, 1, "{:?}", m.per_movement);
        assert!(
            m.peak_speed_m_s > 0.1,
            "the press is in the speed: {}",
            m.peak_speed_m_s
        );
    }

    #[test]
    fn a_reach_and_a_lift_around_the_cut_are_not_the_task() {
        // a reach of 50 mm in 0.6 s, a still 0.4 s, the stroke of 60 mm in 4 s with the blade
        // engaged, a still 0.4 s, a lift of 50 mm in 0.6 s; minimum-jerk each
        let mut poses = Vec::new();
        let mut t0 = 0.0;
        let mut x = 0.0;
        for (duration, d, engaged) in [
            (0.6, 0.05, false),
            (0.4, 0.0, false),
            (4.0, 0.06, true),
            (0.4, 0.0, false),
            (0.6, 0.05, false),
        ] {
            let n = (duration * 1000.0) as usize;
            for i in 1..=n {
                let tau = i as f64 / n as f64;
                let mut p = pose(t0 + tau * duration, [x + min_jerk(tau, d), 0.0, 0.0], 0.0);
                p.blade_engaged = engaged;
                poses.push(p);
            }
            t0 += duration;
            x += d;
        }
        let mut values = Values::default();
        assess(&poses, &PathParams::default(), &mut values);
        let get = |k: &str| {
            values
                .0
                .iter()
                .find(|(key, _, _)| *key == k)
                .and_then(|(_, v, _)| *v)
                .expect(k)
        };
        assert_eq!(get("movements"), 1.0, "the stroke alone");
        assert!(
            (get("path_length_m") - 0.06).abs() < 1e-3,
            "{}",
            get("path_length_m")
        );
        assert!(get("time_s") <= 4.0 + 1e-9, "{}", get("time_s"));
        // the whole of it has three movements
        assert_eq!(
            path(&poses, &PathParams::default())
                .expect("path")
                .movements,
            3
        );
    }

    #[test]
    fn bad_poses_are_errors_not_panics() {
        let good: Vec<PoseSample> = (0..10)
            .map(|i| pose(i as f64 * 0.01, [0.0; 3], 0.0))
            .collect();
        assert!(path(&good, &PathParams::default()).is_ok());
        assert!(path(&good[..2], &PathParams::default()).is_err());
        let mut bad = good.clone();
        bad[4].tip_m[2] = f64::INFINITY;
        assert!(
            path(&bad, &PathParams::default())
                .unwrap_err()
                .to_string()
                .contains("pose 4")
        );
        let mut zero = good.clone();
        zero[1].quat_wxyz = [0.0; 4];
        assert!(path(&zero, &PathParams::default()).is_err());
        let still = path(&good, &PathParams::default()).unwrap();
        assert_eq!(still.movements, 0);
        assert!(still.economy_of_motion.is_none() && still.ldlj.is_none());
    }
}
