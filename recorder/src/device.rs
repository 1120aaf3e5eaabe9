//! [`RecordedHand`]: a haptic device that plays a recording's tool poses back, tick by tick,
//! so that a recorded hand (a trainee's, or a real device's through OpenIGTLink) drives a new
//! session: on another scene or resolution, with localisation, or on the same scene to get the
//! same session again.
//!
//! The device plays the pose of the recorded tick at the same time since the session started
//! (the nearest tick at or before it when the periods differ or a tick was not recorded), with
//! its buttons. A tick at which the recorded device had failed (lost or stale) fails the same
//! way. The rendered force is ignored: the recorded hand moved as it did whatever it feels now.
//! Finished after the last recorded tick.

use std::collections::BTreeMap;

use cutlab_haptics::render::fault;
use cutlab_haptics::servo::ServoSample;
use cutlab_haptics::{DeviceFault, HapticDevice, ToolPose, Vector3};

use crate::{RecorderError, Recording};

/// The recorded device's state at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Recorded {
    Pose(ToolPose),
    Failed(DeviceFault),
}

/// A recording's hand as a haptic device.
#[derive(Debug, Clone)]
pub struct RecordedHand {
    name: String,
    /// Recorded ticks in increasing order and what the device gave at each.
    ticks: Vec<(u64, Recorded)>,
    period_s: f64,
    /// Index into `ticks` of the last tick played (reads come in increasing time).
    cursor: usize,
}

impl RecordedHand {
    /// The hand of `recording`; an error when it has no session metadata or no tool poses.
    pub fn new(recording: &Recording) -> Result<Self, RecorderError> {
        let meta = recording.meta()?;
        Self::from_samples(
            format!("recording of {}", meta.provenance.device),
            &recording.samples(),
            meta.period_nanos,
        )
    }

    /// The hand of recorded servo samples (by tick) at a servo period of `period_nanos`.
    pub fn from_samples(
        name: String,
        samples: &BTreeMap<u64, ServoSample>,
        period_nanos: u64,
    ) -> Result<Self, RecorderError> {
        let ticks: Vec<(u64, Recorded)> = samples
            .iter()
            .map(|(&tick, s)| {
                let recorded = if s.render.faults & fault::DEVICE_LOST != 0 {
                    Recorded::Failed(DeviceFault::Disconnected)
                } else if s.render.faults & fault::DEVICE_STALE != 0 {
                    Recorded::Failed(DeviceFault::Stale {
                        age_nanos: period_nanos,
                    })
                } else {
                    Recorded::Pose(s.pose)
                };
                (tick, recorded)
            })
            .collect();
        if ticks.is_empty() || period_nanos == 0 {
            return Err(RecorderError::Malformed(
                "the recording has no tool poses to play".into(),
            ));
        }
        Ok(Self {
            name,
            ticks,
            period_s: period_nanos as f64 * 1e-9,
            cursor: 0,
        })
    }

    /// Seconds from the session's start to the last recorded tick.
    pub fn duration_s(&self) -> f64 {
        self.ticks[self.ticks.len() - 1].0 as f64 * self.period_s
    }
}

impl HapticDevice for RecordedHand {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        // the recorded tick at this time (half a period of slack for rounding)
        let tick = ((time_s / self.period_s) + 0.5).floor().max(0.0) as u64;
        while self.cursor + 1 < self.ticks.len() && self.ticks[self.cursor + 1].0 <= tick {
            self.cursor += 1;
        }
        match self.ticks[self.cursor] {
            (t, _) if t > tick => Err(DeviceFault::Disconnected),
            (_, Recorded::Pose(pose)) => Ok(pose),
            (_, Recorded::Failed(fault)) => Err(fault),
        }
    }

    fn write_force(&mut self, _force_newtons: Vector3) -> Result<(), DeviceFault> {
        Ok(())
    }

    fn finished(&self, time_s: f64) -> bool {
        time_s > self.duration_s()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cutlab_haptics::Point3;
    use cutlab_haptics::render::RenderOutput;

    fn sample(tick: u64, faults: u8) -> (u64, ServoSample) {
        let pose = ToolPose {
            tip_in_world: Point3::new(tick as f64, 0.0, 0.0),
            ..ToolPose::default()
        };
        (
            tick,
            ServoSample {
                tick,
                pose,
                render: RenderOutput {
                    faults,
                    ..RenderOutput::default()
                },
                grasper: None,
            },
        )
    }

    #[test]
    fn plays_each_recorded_tick_at_its_time_with_its_faults() {
        // ticks 2..=6 recorded at 1 ms, tick 4 missing, the device lost at 5
        let samples: BTreeMap<u64, ServoSample> = [
            sample(2, 0),
            sample(3, fault::SIM_STALLED),
            sample(5, fault::DEVICE_LOST),
            sample(6, 0),
        ]
        .into();
        let mut hand = RecordedHand::from_samples("r".into(), &samples, 1_000_000).expect("hand");
        let x = |r: Result<ToolPose, DeviceFault>| r.map(|p| p.tip_in_world.x);
        assert_eq!(
            x(hand.read(0, 0.0)),
            Err(DeviceFault::Disconnected),
            "before the first recorded tick"
        );
        assert_eq!(x(hand.read(2, 0.002)), Ok(2.0));
        assert_eq!(
            x(hand.read(3, 0.003)),
            Ok(3.0),
            "a fault that is not the device's plays the pose"
        );
        assert_eq!(
            x(hand.read(4, 0.004)),
            Ok(3.0),
            "a missing tick holds the last pose"
        );
        assert_eq!(x(hand.read(5, 0.005)), Err(DeviceFault::Disconnected));
        assert!(!hand.finished(0.006));
        assert_eq!(x(hand.read(6, 0.006)), Ok(6.0));
        assert!(hand.finished(0.007));
        // a session at another period plays by time: tick 3 at 0.5 ms is recorded tick 2
        let mut half = RecordedHand::from_samples("r".into(), &samples, 1_000_000).expect("hand");
        assert_eq!(x(half.read(3, 0.0015)), Ok(2.0));
        assert!(RecordedHand::from_samples("r".into(), &BTreeMap::new(), 1_000_000).is_err());
    }
}
