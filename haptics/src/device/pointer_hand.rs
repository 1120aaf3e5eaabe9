//! [`PointerHand`]: a person's hand ([`crate::hand::Hand`]) on the station's pointer, as a
//! device: the samples the station page would send for the hand's gestures, pushed into a
//! [`PointerDevice`] as the session's clock reaches them, so the pose goes through the same
//! code as a person's at the station (30 ms behind, linear between 60 Hz samples, the blade
//! plunging to the set depth when the button goes down), on the virtual clock as well as the
//! live one.
//!
//! What the hand does (`pointer:steady`, `pointer:sloppy` or `pointer:lagging`, a steady hand
//! on a page a slow machine holds back to 7 samples a second), in the plan's frame on the
//! surface (millimetres along the planned line and across it): it waits at rest 15 mm before
//! the entry and 20 mm to the side, reaches for the entry (a primary movement that stops
//! short, a correction), presses, strokes along the line at a careful person's 12 mm/s (one
//! minimum-jerk submovement; the sloppy hand twice as fast),
//! each seed one person of many ([`Hand::one_of_many`]: their own pace, 9-15 mm/s for the
//! steady hand, tremor, drift and reaction time), releases, moves away and holds
//! still for 1.5 s, when the page would end the attempt. The depth is the plan's, the button
//! held only for the stroke; between gestures the page's heartbeat repeats the last point
//! every frame. The surface point is the plan's line moved across along the surface's tangent
//! plane (the page picks on the tissue itself: the two agree on and near the line).

use super::pointer::{PointerDevice, PointerFeed, PointerOptions, PointerSample};
use super::{DeviceFault, HapticDevice};
use crate::hand::{Gesture, Hand};
use crate::plan::Plan;
use crate::{HapticsError, Point3, ToolPose, Vector3};

/// A careful person's cutting pace along the line, m/s.
pub const STEADY_PACE_M_PER_S: f64 = 0.012;
/// Where the hand rests before the reach: this far before the entry along the line and
/// across it, m.
const REST_M: [f64; 2] = [-0.015, -0.020];
/// How long the page goes on after the hand lifted away, s (it ends the attempt 1.5 s after
/// the blade was lifted out of a cut).
const AFTER_S: f64 = 1.5;

/// Which hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HandKind {
    /// [`Hand::steady`] at [`STEADY_PACE_M_PER_S`].
    Steady,
    /// [`Hand::sloppy`], twice as fast.
    Sloppy,
    /// [`Hand::steady`] on a page a slow machine holds back: its samples reach the station
    /// [`LAGGING_PAGE_HZ`] times a second, and the person, who sees the tissue answer late,
    /// cuts at half the pace.
    Lagging,
}

/// How often a lagging page's samples reach the station, Hz (a slow machine's in issue 63).
pub const LAGGING_PAGE_HZ: f64 = 7.0;

impl HandKind {
    /// `steady` or `sloppy`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "steady" => Some(Self::Steady),
            "sloppy" => Some(Self::Sloppy),
            "lagging" => Some(Self::Lagging),
            _ => None,
        }
    }

    /// The name [`Self::parse`] reads.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Steady => "steady",
            Self::Sloppy => "sloppy",
            Self::Lagging => "lagging",
        }
    }
}

/// A person's hand on the station's pointer (see the module documentation).
#[derive(Debug)]
pub struct PointerHand {
    name: String,
    pointer: PointerDevice,
    feed: PointerFeed,
    samples: Vec<PointerSample>,
    next: usize,
    /// The hand is done and the page would have ended the attempt.
    done: bool,
}

impl PointerHand {
    /// The `kind` of hand cutting along `plan`, its noise seeded by `seed`.
    pub fn new(kind: HandKind, plan: &Plan, seed: u64) -> Result<Self, HapticsError> {
        let (pointer, feed) = PointerDevice::new(PointerOptions::above_entry(plan)?)?;
        let frame_ms = match kind {
            HandKind::Lagging => 1000.0 / LAGGING_PAGE_HZ,
            HandKind::Steady | HandKind::Sloppy => 1000.0 / 60.0,
        };
        let samples = page_samples(
            &gestures(kind, plan, seed),
            &SurfaceFrame::new(plan)?,
            frame_ms,
        );
        Ok(Self {
            name: format!("pointer:{}", kind.as_str()),
            pointer,
            feed,
            samples,
            next: 0,
            done: false,
        })
    }

    /// The samples the page sends, page time from 0.
    pub fn samples(&self) -> &[PointerSample] {
        &self.samples
    }

    fn end_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.t_ms * 1e-3)
    }
}

/// The gestures, in millimetres of the plan's frame.
pub(super) fn gestures(kind: HandKind, plan: &Plan, seed: u64) -> Vec<Gesture> {
    let mut hand = match kind {
        HandKind::Steady => Hand::steady(1.0, seed),
        HandKind::Sloppy => Hand::sloppy(1.0, seed),
        HandKind::Lagging => {
            let mut h = Hand::steady(1.0, seed);
            h.rate_hz = LAGGING_PAGE_HZ;
            h
        }
    };
    let length_mm = plan.length_m() * 1e3;
    let pace = hand.one_of_many()
        * match kind {
            HandKind::Steady => STEADY_PACE_M_PER_S,
            HandKind::Sloppy => 2.0 * STEADY_PACE_M_PER_S,
            HandKind::Lagging => 0.5 * STEADY_PACE_M_PER_S,
        };
    let rest = [REST_M[0] * 1e3, REST_M[1] * 1e3];
    let line = [[0.0, 0.0], [length_mm, 0.0]];
    let mut g = hand.approach(rest, line[0]);
    g.extend(hand.stroke(&line, plan.length_m() / pace, 1.0));
    let end = g
        .iter()
        .rev()
        .find_map(|g| match *g {
            Gesture::Move { x, y, .. } => Some([x, y]),
            _ => None,
        })
        .unwrap_or(line[1]);
    g.extend(hand.withdraw(end, [6.0, -12.0], 0.5));
    g.push(Gesture::Wait {
        ms: (AFTER_S * 1e3) as u64,
    });
    g
}

/// The plan's frame on the surface: millimetres along the line and across it to the world.
pub(super) struct SurfaceFrame<'a> {
    pub(super) plan: &'a Plan,
    /// The arc length at each point of the line, m.
    arc_m: Vec<f64>,
}

impl<'a> SurfaceFrame<'a> {
    pub(super) fn new(plan: &'a Plan) -> Result<Self, HapticsError> {
        plan.check()?;
        let mut arc_m = vec![0.0];
        for w in plan.line_m.windows(2) {
            arc_m.push(arc_m[arc_m.len() - 1] + (w[1] - w[0]).norm());
        }
        Ok(Self { plan, arc_m })
    }

    /// The surface point `along_mm` along the line (extrapolated past its ends) and
    /// `across_mm` across it (to the left of the cut, seen from outside).
    pub(super) fn point(&self, along_mm: f64, across_mm: f64) -> Point3 {
        self.at(along_mm, across_mm).0
    }

    /// [`Self::point`], with the surface's normal there and the line's direction.
    pub(super) fn at(&self, along_mm: f64, across_mm: f64) -> (Point3, Vector3, Vector3) {
        let s = along_mm * 1e-3;
        let line = &self.plan.line_m;
        let i = self.arc_m[1..line.len() - 1].partition_point(|&a| a < s);
        let span = (self.arc_m[i + 1] - self.arc_m[i]).max(1e-12);
        let t = (s - self.arc_m[i]) / span;
        let tangent = (line[i + 1] - line[i]) / span;
        let u = t.clamp(0.0, 1.0);
        let normal: Vector3 = self.plan.normals[i] * (1.0 - u) + self.plan.normals[i + 1] * u;
        let across = normal
            .cross(&tangent)
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::y);
        let point = line[i] + (line[i + 1] - line[i]) * t + across * (across_mm * 1e-3);
        let normal = normal.try_normalize(1e-12).unwrap_or_else(Vector3::z);
        (point, normal, tangent)
    }
}

/// One moment of the hand: when (ms from the start), where on the surface (mm along the
/// line and across it) and whether the button is down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct HandSample {
    pub(super) t_ms: f64,
    pub(super) at: [f64; 2],
    pub(super) engaged: bool,
}

/// The hand's samples for `gestures`: one per move, one every frame (`frame_ms`) while the
/// hand holds still (the heartbeat), one at each press and release.
pub(super) fn hand_samples(gestures: &[Gesture], frame_ms: f64) -> Vec<HandSample> {
    let (mut t_ms, mut at, mut engaged) = (0.0, [0.0, 0.0], false);
    let mut out = Vec::new();
    for g in gestures {
        match *g {
            Gesture::Move { x, y, ms } => {
                t_ms += ms as f64;
                at = [x, y];
                out.push(HandSample { t_ms, at, engaged });
            }
            Gesture::Wait { ms } => {
                let end = t_ms + ms as f64;
                while t_ms + frame_ms <= end {
                    t_ms += frame_ms;
                    out.push(HandSample { t_ms, at, engaged });
                }
                t_ms = end;
            }
            Gesture::Press | Gesture::Release => {
                engaged = matches!(g, Gesture::Press);
                t_ms += 1.0;
                out.push(HandSample { t_ms, at, engaged });
            }
        }
    }
    out
}

/// The page's samples for `gestures` ([`hand_samples`] on the surface, the blade at the
/// plan's depth while the button is down).
fn page_samples(
    gestures: &[Gesture],
    frame: &SurfaceFrame<'_>,
    frame_ms: f64,
) -> Vec<PointerSample> {
    hand_samples(gestures, frame_ms)
        .into_iter()
        .map(|s| {
            let p = frame.point(s.at[0], s.at[1]);
            let depth = if s.engaged { frame.plan.depth_m } else { 0.0 };
            PointerSample::new(s.t_ms, [p.x, p.y, p.z], depth, s.engaged)
        })
        .collect()
}

impl HapticDevice for PointerHand {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        while let Some(s) = self.samples.get(self.next)
            && s.t_ms * 1e-3 <= time_s
        {
            // the queue holds far more than a tick's samples; a refusal is the pointer's
            // fault, which its `read` reports
            let _ = self.feed.push(*s);
            self.next += 1;
        }
        self.done = self.next == self.samples.len() && time_s >= self.end_s();
        self.pointer.read(tick, time_s)
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.pointer.write_force(force_newtons)
    }

    fn finished(&self, time_s: f64) -> bool {
        (self.next == self.samples.len() && time_s >= self.end_s()) || self.pointer.finished(time_s)
    }

    /// Once the hand is done: the page ends the attempt 1.5 s after the blade was lifted out.
    fn ends_session(&self) -> bool {
        self.done || self.pointer.ends_session()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> Plan {
        Plan::flat_across_x(0.006)
    }

    fn play(kind: HandKind, seed: u64) -> Vec<ToolPose> {
        let mut hand = PointerHand::new(kind, &plan(), seed).expect("hand");
        let mut poses = Vec::new();
        for tick in 0..20_000u64 {
            let t = tick as f64 * 1e-3;
            if hand.finished(t) {
                break;
            }
            // the device never pauses: the page's heartbeat comes every frame
            poses.push(hand.read(tick, t).expect("pose"));
            assert!(!hand.ends_session() || hand.finished(t), "ends when done");
        }
        poses
    }

    #[test]
    fn a_steady_hand_reaches_presses_strokes_the_line_at_depth_and_lifts() {
        let poses = play(HandKind::Steady, 3);
        let cutting: Vec<&ToolPose> = poses.iter().filter(|p| p.blade_engaged()).collect();
        let (first, last) = (
            cutting[0].tip_in_world,
            cutting[cutting.len() - 1].tip_in_world,
        );
        assert!((first.x + 0.03).abs() < 1e-3, "entry {first}");
        assert!((last.x - 0.03).abs() < 1e-3, "exit {last}");
        let lateral = cutting
            .iter()
            .map(|p| p.tip_in_world.y.abs())
            .fold(0.0, f64::max);
        assert!(
            lateral < 1e-3 && lateral > 2e-5,
            "a person's hand, not a robot's: {lateral}"
        );
        // at the set depth, but while the page's release sample is interpolated towards
        assert!(
            cutting
                .iter()
                .all(|p| (-0.006 - 1e-9..=1e-9).contains(&p.tip_in_world.z))
        );
        let at_depth = cutting
            .iter()
            .filter(|p| (p.tip_in_world.z + 0.006).abs() < 1e-9);
        assert!(at_depth.count() as f64 > 0.97 * cutting.len() as f64);
        // a careful pace: 60 mm at 9-15 mm/s, and the reach, the pauses and the lift around it
        let stroke_s = cutting.len() as f64 * 1e-3;
        assert!((4.0..7.5).contains(&stroke_s), "stroke {stroke_s} s");
        let total_s = poses.len() as f64 * 1e-3;
        assert!((7.0..12.0).contains(&total_s), "attempt {total_s} s");
        // the hand starts at rest to the side and ends lifted away, the blade out
        assert!(!poses[0].blade_engaged() && !poses[poses.len() - 1].blade_engaged());
    }

    #[test]
    fn the_same_seed_is_the_same_hand_and_a_sloppy_one_strays_further() {
        assert_eq!(play(HandKind::Steady, 5), play(HandKind::Steady, 5));
        assert_ne!(play(HandKind::Steady, 5), play(HandKind::Steady, 6));
        let spread = |poses: Vec<ToolPose>| {
            let y: Vec<f64> = poses
                .iter()
                .filter(|p| p.blade_engaged())
                .map(|p| p.tip_in_world.y)
                .collect();
            (y.iter().map(|y| y * y).sum::<f64>() / y.len() as f64).sqrt()
        };
        let (steady, sloppy) = (
            spread(play(HandKind::Steady, 5)),
            spread(play(HandKind::Sloppy, 5)),
        );
        assert!(sloppy > 2.0 * steady, "{sloppy} against {steady}");
    }
}
