//! [`StylusHand`]: a person's hand ([`crate::hand::Hand`]) on a 3D stylus (a haptic device's
//! pen or a tracked scalpel), as a device: the stylus class's human model, as
//! [`super::PointerHand`] is the pointer's (issue 63: the stylus class was judged against the
//! synthetic trainees alone, robots that press the blade on until the cut is as deep as
//! planned).
//!
//! The hand makes the same gestures as on the pointer (`stylus:steady`, `stylus:sloppy`; see
//! [`super::PointerHand`]): the reach, the stroke at a careful person's pace with tremor and
//! drift, the lift. A stylus has no set depth: the person holds the tip where they aim, the
//! plan's depth below the tissue's surface as it was at rest, and does not follow the tissue
//! as it gives way under the blade. Between gestures the tip hovers [`HOVER_M`] above the
//! surface; pressing in and lifting out take [`PLUNGE_S`] each, a minimum-jerk movement along
//! the surface's normal. The tool's +z is the normal and +x the plan's direction, as the
//! synthetic trainee holds it. The hand's 60 Hz samples are played at the servo's rate,
//! interpolated linearly between them ([`PoseTrack`]).

use super::pointer_hand::{HandSample, SurfaceFrame, gestures, hand_samples};
use super::track::PoseTrack;
use super::trainee::blade_frame;
use super::{DeviceFault, HandKind, HapticDevice};
use crate::hand::minimum_jerk;
use crate::plan::Plan;
use crate::pose::BUTTON_BLADE;
use crate::{HapticsError, ToolPose, Vector3};

/// How high above the surface the tip hovers between gestures, m.
pub const HOVER_M: f64 = 0.003;
/// How long pressing the blade in (or lifting it out) takes, s.
pub const PLUNGE_S: f64 = 0.25;
/// The hand's sampling interval, ms (60 Hz).
const FRAME_MS: f64 = 1000.0 / 60.0;

/// A person's hand on a stylus (see the module documentation).
#[derive(Debug, Clone)]
pub struct StylusHand {
    name: String,
    track: PoseTrack,
}

impl StylusHand {
    /// The `kind` of hand (steady or sloppy) cutting along `plan`, its noise seeded by `seed`.
    pub fn new(kind: HandKind, plan: &Plan, seed: u64) -> Result<Self, HapticsError> {
        if kind == HandKind::Lagging {
            return Err(HapticsError::Config(
                "a stylus hand is steady or sloppy (a lagging page is the pointer's)".into(),
            ));
        }
        let frame = SurfaceFrame::new(plan)?;
        let samples = hand_samples(&gestures(kind, plan, seed), FRAME_MS);
        let (times_s, poses) = stylus_poses(&samples, &frame);
        Ok(Self {
            name: format!("stylus:{}", kind.as_str()),
            track: PoseTrack::new(times_s, poses),
        })
    }
}

/// The stylus's poses for the hand's samples: each sample at the surface point it aims at,
/// hovering or at the plan's depth, with a plunge inserted at each press and each lift.
fn stylus_poses(samples: &[HandSample], frame: &SurfaceFrame<'_>) -> (Vec<f64>, Vec<ToolPose>) {
    let depth_m = frame.plan.depth_m;
    let height = |engaged: bool| if engaged { -depth_m } else { HOVER_M };
    let pose = |at: [f64; 2], height_m: f64, engaged: bool| {
        let (p, normal, tangent) = frame.at(at[0], at[1]);
        ToolPose {
            tip_in_world: p + normal * height_m,
            world_from_tool: blade_frame(normal, tangent),
            buttons: if engaged { BUTTON_BLADE } else { 0 },
        }
    };
    let (mut times_s, mut poses) = (Vec::new(), Vec::new());
    let (mut shift_s, mut engaged) = (0.0, false);
    for s in samples {
        let t_s = s.t_ms * 1e-3 + shift_s;
        if s.engaged != engaged {
            // press in (or lift out) where the hand is, the button already as it is now
            let (from, to) = (height(engaged), height(s.engaged));
            let steps = (PLUNGE_S * 1e3 / FRAME_MS).ceil() as usize;
            for k in 0..=steps {
                let tau = k as f64 / steps as f64;
                times_s.push(t_s + tau * PLUNGE_S);
                let h = from + (to - from) * minimum_jerk(tau);
                poses.push(pose(s.at, h, s.engaged));
            }
            shift_s += PLUNGE_S;
            engaged = s.engaged;
            continue;
        }
        if times_s.last().is_some_and(|&last| t_s <= last) {
            continue;
        }
        times_s.push(t_s);
        poses.push(pose(s.at, height(s.engaged), s.engaged));
    }
    if poses.is_empty() {
        times_s.push(0.0);
        poses.push(pose([0.0, 0.0], HOVER_M, false));
    }
    (times_s, poses)
}

impl HapticDevice for StylusHand {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        Ok(self.track.pose_at(time_s))
    }

    fn write_force(&mut self, _force_newtons: Vector3) -> Result<(), DeviceFault> {
        Ok(())
    }

    fn finished(&self, time_s: f64) -> bool {
        time_s > self.track.duration_s()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> Plan {
        Plan::flat_across_x(0.006)
    }

    fn play(kind: HandKind, seed: u64) -> Vec<ToolPose> {
        let mut hand = StylusHand::new(kind, &plan(), seed).expect("hand");
        let mut poses = Vec::new();
        for tick in 0u64.. {
            let t = tick as f64 * 1e-3;
            if hand.finished(t) {
                return poses;
            }
            poses.push(hand.read(tick, t).expect("pose"));
        }
        poses
    }

    #[test]
    fn a_steady_hand_presses_in_strokes_at_the_plans_depth_and_lifts_out() {
        let poses = play(HandKind::Steady, 3);
        let cutting: Vec<&ToolPose> = poses.iter().filter(|p| p.blade_engaged()).collect();
        let at_depth: Vec<&&ToolPose> = cutting
            .iter()
            .filter(|p| (p.tip_in_world.z + 0.006).abs() < 1e-9)
            .collect();
        let (first, last) = (
            at_depth[0].tip_in_world,
            at_depth[at_depth.len() - 1].tip_in_world,
        );
        assert!((first.x + 0.03).abs() < 1e-3, "entry {first}");
        assert!((last.x - 0.03).abs() < 1e-3, "exit {last}");
        let lateral = at_depth
            .iter()
            .map(|p| p.tip_in_world.y.abs())
            .fold(0.0, f64::max);
        assert!(
            lateral < 1e-3 && lateral > 2e-5,
            "a person's hand: {lateral}"
        );
        // pressing in takes a quarter second, not a frame (at most 0.1 m/s), and the tip is
        // never below the plan's depth; it lifts out with the button up, as it went in down
        let descent: Vec<f64> = cutting.iter().map(|p| p.tip_in_world.z).collect();
        let fastest = descent
            .windows(2)
            .map(|w| (w[1] - w[0]).abs() / 1e-3)
            .fold(0.0, f64::max);
        assert!(fastest < 0.1, "{fastest} m/s");
        assert!(poses.iter().all(|p| p.tip_in_world.z >= -0.006 - 1e-12));
        assert!(poses.iter().all(|p| p.tip_in_world.z <= HOVER_M + 1e-12));
        let pressing = cutting.len() - at_depth.len();
        assert!(
            (200..=300).contains(&pressing),
            "pressing in: {pressing} ms"
        );
        // the tip's axis is the surface's normal, the blade along the cut
        let q = cutting[cutting.len() / 2].world_from_tool;
        assert!((q * Vector3::z() - Vector3::z()).norm() < 1e-9);
        assert!((q * Vector3::x() - Vector3::x()).norm() < 1e-9);
        assert!(!poses[0].blade_engaged() && !poses[poses.len() - 1].blade_engaged());
    }

    #[test]
    fn the_same_seed_is_the_same_hand_and_a_lagging_stylus_is_refused() {
        assert_eq!(play(HandKind::Steady, 5), play(HandKind::Steady, 5));
        assert_ne!(play(HandKind::Steady, 5), play(HandKind::Sloppy, 5));
        assert!(StylusHand::new(HandKind::Lagging, &plan(), 1).is_err());
    }
}
