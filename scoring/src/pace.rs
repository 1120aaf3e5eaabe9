//! Whether the station kept pace with the hand: how often the hand's pose reached the
//! simulation while it moved over the task, read from the recorded poses alone.
//!
//! A device that reports at rate `f` and is played at the servo's rate by interpolation
//! (the station's pointer, a CSV trajectory) moves the tool along straight pieces between its
//! reports: the tool's velocity changes course only where a report lies. So the rate of those
//! changes, counted over the ticks where the tool moves ([`input_pace`]), is the rate the
//! hand reached the simulation: about 60 a second from a steady page, every tick from a
//! 1 kHz device. A page that a slow machine holds back reports a few times a second; the
//! person, who sees the tissue answer late, slows down and waits, and the task's time, idle
//! time, movements and smoothness measure the station, not them ([`set_aside`]).

use nalgebra::Vector3;

use crate::input::PoseSample;
use crate::metrics::{MetricValue, STATION_LAGGED};

/// Below this many reports a second while moving the station lagged (a steady page sends
/// 60; a busy one 30; the slow machine in issue 63 reached 7).
pub const MIN_INPUT_HZ: f64 = 20.0;

/// The metrics that measure the hand's pace in time, set aside when the station lagged:
/// the geometry of the cut, the path's length and the forces stay the trainee's.
pub const PACED_METRICS: [&str; 9] = [
    "time_s",
    "idle_time_s",
    "movements",
    "ldlj",
    "sparc",
    "ldlj_per_movement",
    "sparc_per_movement",
    "completion_time_s",
    "mistels_score",
];

/// The hand's pace as it reached the simulation over the task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputPace {
    /// Changes of the tool's course a second while it moved, Hz.
    pub input_hz: f64,
    /// How long the tool moved over the task, s.
    pub moving_s: f64,
}

impl InputPace {
    /// Whether the hand reached the simulation too seldom for its pace to be its own.
    pub fn lagged(&self) -> bool {
        self.input_hz < MIN_INPUT_HZ
    }

    /// What the trainee is told.
    pub fn words(&self) -> String {
        format!(
            "your hand reached the simulation {:.0} times a second while it moved (a steady \
             page: 60), so time, idle time, movements and smoothness measure the station, not \
             you, and are not scored; close other programs or tabs, or use a faster computer",
            self.input_hz
        )
    }
}

/// The hand's pace over the task of `poses` (servo ticks in order; the task's window as the
/// path metrics take it). `None` when the tool moved less than a second in it.
pub fn input_pace(poses: &[PoseSample]) -> Option<InputPace> {
    let poses = crate::metrics::path::task_window(poses);
    // the course bends at a report: over one tick's window when the report falls on a tick,
    // two when it falls between; a run of `n` bending windows is `max(1, n - 1)` reports (a
    // device that reports every tick bends at every one)
    let (mut changes, mut moving_s, mut run) = (0u32, 0.0, 0u32);
    let mut end_run = |run: &mut u32| {
        changes += (*run).saturating_sub(1).max(u32::from(*run > 0));
        *run = 0;
    };
    for w in poses.windows(3) {
        let (dt1, dt2) = (w[1].t_s - w[0].t_s, w[2].t_s - w[1].t_s);
        // only three ticks in a row (a dropped record would read as a change)
        if !(dt1 > 0.0 && (dt2 - dt1).abs() <= 1e-6 * dt1) {
            end_run(&mut run);
            continue;
        }
        let tip = |k: usize| Vector3::from(w[k].tip_m);
        let (d1, d2) = (tip(1) - tip(0), tip(2) - tip(1));
        let (n1, n2) = (d1.norm(), d2.norm());
        // still: under 0.01 mm/s at 1 kHz
        if n1.max(n2) < 1e-8 * dt1 / 1e-3 {
            end_run(&mut run);
            continue;
        }
        moving_s += dt1;
        if (d2 - d1).norm() > 1e-6 * n1.max(n2) {
            run += 1;
        } else {
            end_run(&mut run);
        }
    }
    end_run(&mut run);
    (moving_s >= 1.0).then(|| InputPace {
        input_hz: f64::from(changes) / moving_s,
        moving_s,
    })
}

/// Sets the paced metrics of `values` aside (missing, with [`STATION_LAGGED`] and `why`).
pub fn set_aside(values: &mut [MetricValue], why: &str) {
    for v in values
        .iter_mut()
        .filter(|v| PACED_METRICS.contains(&v.key.as_str()))
    {
        v.value = None;
        v.missing = Some(format!("{STATION_LAGGED}: {why}"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stroke of 60 mm in 6 s at 1 kHz whose pose comes from reports at `hz`, linear in
    /// between, after a 2 s still hold (engaged throughout).
    fn played(hz: f64) -> Vec<PoseSample> {
        // report `k`: a wavy hand, each report a little off the line
        let report = |k: f64| [0.01 * k / hz, 1e-4 * (k * 1.7).sin(), 0.0];
        (0..8000)
            .map(|tick| {
                let t = f64::from(tick) * 1e-3;
                let s = (t - 2.0).max(0.0);
                let k = (s * hz).floor();
                let (a, b) = (report(k), report(k + 1.0));
                let u = s * hz - k;
                PoseSample {
                    t_s: t,
                    tip_m: [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * u),
                    quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                    blade_engaged: true,
                }
            })
            .collect()
    }

    #[test]
    fn the_rate_the_hand_reached_the_simulation_is_read_from_the_poses() {
        for hz in [7.0, 30.0, 60.0] {
            let pace = input_pace(&played(hz)).expect("it moved");
            assert!(
                (pace.input_hz - hz).abs() < 0.05 * hz,
                "{hz} Hz read as {pace:?}"
            );
            // the still hold is not counted
            assert!((pace.moving_s - 6.0).abs() < 0.01, "{pace:?}");
            assert_eq!(pace.lagged(), hz < MIN_INPUT_HZ);
        }
        // a 1 kHz device: a change at every tick
        let device: Vec<PoseSample> = (0..3000)
            .map(|tick| {
                let t = f64::from(tick) * 1e-3;
                PoseSample {
                    t_s: t,
                    tip_m: [0.01 * t, 1e-4 * (40.0 * t).sin(), 0.0],
                    quat_wxyz: [1.0, 0.0, 0.0, 0.0],
                    blade_engaged: true,
                }
            })
            .collect();
        assert!(input_pace(&device).expect("moved").input_hz > 900.0);
        // too little movement to say
        assert_eq!(input_pace(&played(60.0)[..2500]), None);
    }

    #[test]
    fn a_lag_sets_the_paced_metrics_aside_and_keeps_the_rest() {
        let m = |key: &str| MetricValue {
            key: key.into(),
            value: Some(1.0),
            unit: "s".into(),
            better: crate::Better::LowerIsBetter,
            scored: true,
            missing: None,
        };
        let mut values = vec![m("time_s"), m("lateral_mean_m"), m("completion_time_s")];
        set_aside(&mut values, "7 Hz");
        assert!(values[0].value.is_none() && values[0].not_measured());
        assert_eq!(values[1].value, Some(1.0));
        assert!(values[2].not_measured());
    }
}
