//! [`GrasperHand`]: a synthetic second hand holding a grasper (issue 66). It reaches down to a
//! point of the tissue, pauses, closes the jaws on it, draws the tissue along a traction
//! vector, holds it there while the other hand cuts, and at the end opens the jaws and lifts
//! away: what an assistant's or the trainee's own left hand does for countertraction. Its jaws
//! tremble as a hand does (physiological tremor, 8-12 Hz, a tenth of a millimetre), seeded.

use cutlab_sim::rng::Rng;

use super::{DeviceFault, HapticDevice};
use crate::pose::BUTTON_JAWS;
use crate::{Point3, ToolPose, Vector3};

/// How the grasper hand moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraspPlan {
    /// Where the jaws close, m.
    pub hold_m: Point3,
    /// How far and where the held tissue is drawn once held, m.
    pub pull_m: Vector3,
    /// The way out of the tissue (unit): the jaws come down along it and lift away along it.
    pub up: Vector3,
    /// When the jaws open, s (`None`: they hold to the session's end).
    pub release_s: Option<f64>,
}

/// How a synthetic trainee's other hand gives countertraction beside an incision: where its
/// grasper takes hold and how it draws the tissue (part of a [`Skill`](super::Skill)). An
/// expert holds close beside the line and draws the tissue away from it and up, so the
/// incision opens under the blade, for the whole cut; a novice holds far off, draws weakly
/// or towards the line, and lets go part way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Traction {
    /// How far beside the incision's middle the jaws close, m.
    pub beside_m: f64,
    /// How far the held tissue is drawn away from the incision, m (negative: towards it).
    pub away_m: f64,
    /// How far the held tissue is lifted, m.
    pub lift_m: f64,
    /// How long the jaws hold once closed, as a share of the stroke's expected time (1 or
    /// more: to the session's end).
    pub hold_share: f64,
}

impl GraspPlan {
    /// The grasp of a hand giving `traction` beside `plan`'s incision: the jaws close
    /// `beside_m` to the left of the line's middle (the surface normal crossed with the
    /// line's direction there), shifted up to 2 mm along the line by `seed`, draw the tissue
    /// `away_m` further to that side and `lift_m` along the normal, and open after
    /// `hold_share` of `stroke_s` (the stroke's expected time, s). An error names what is
    /// wrong when the line has no middle with a direction.
    pub fn countertraction(
        plan: &crate::plan::Plan,
        traction: &Traction,
        stroke_s: f64,
        seed: u64,
    ) -> Result<Self, String> {
        let (at, up, along) = halfway(plan)
            .ok_or("the plan's line has no middle with a direction to hold the tissue beside")?;
        let side = up
            .cross(&along)
            .try_normalize(1e-12)
            .ok_or("the plan's line has no direction across its normal at its middle")?;
        let mut rng = Rng::new(seed ^ 0x7472_6163_7469_6f6e);
        let shift_m = (rng.uniform() - 0.5) * 4e-3;
        Ok(Self {
            hold_m: at + along * shift_m + side * traction.beside_m,
            pull_m: side * traction.away_m + up * traction.lift_m,
            up,
            release_s: (traction.hold_share < 1.0)
                .then(|| REACH_S + PAUSE_S + traction.hold_share * stroke_s.max(0.0)),
        })
    }
}

/// The point half way along `plan`'s line, its normal there (linear between the segment's
/// ends, unit) and the segment's direction (unit); `None` for a line without length.
fn halfway(plan: &crate::plan::Plan) -> Option<(Point3, Vector3, Vector3)> {
    let line = &plan.line_m;
    let total_m: f64 = line.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let mut left_m = 0.5 * total_m;
    for (k, w) in line.windows(2).enumerate() {
        let length_m = (w[1] - w[0]).norm();
        if length_m > 1e-12 && left_m <= length_m {
            let u = left_m / length_m;
            let (a, b) = (plan.normals.get(k)?, plan.normals.get(k + 1)?);
            let up = (a * (1.0 - u) + b * u).try_normalize(1e-12)?;
            return Some((w[0] + (w[1] - w[0]) * u, up, (w[1] - w[0]) / length_m));
        }
        left_m -= length_m;
    }
    None
}

/// From above the hold point down to it, s.
const REACH_S: f64 = 1.0;
/// The pause before the jaws close, s.
const PAUSE_S: f64 = 0.2;
/// Drawing the tissue to the full traction, s.
const PULL_S: f64 = 1.0;
/// Lifting away after the jaws open, s.
const LIFT_S: f64 = 0.5;
/// How far above the tissue the hand starts and ends, m.
const ABOVE_M: f64 = 0.015;
/// The tremor's amplitude, m.
const TREMOR_M: f64 = 1e-4;

/// A synthetic hand on a grasper.
#[derive(Debug, Clone)]
pub struct GrasperHand {
    name: String,
    plan: GraspPlan,
    /// The tremor's three components: frequency (Hz) and phase each.
    tremor: [(f64, f64); 3],
    force_newtons: Vector3,
}

impl GrasperHand {
    /// The hand following `plan`, its tremor seeded by `seed`; an error naming what is wrong
    /// when the plan is not finite or its up vector not a direction.
    pub fn new(plan: GraspPlan, seed: u64) -> Result<Self, String> {
        let finite = plan
            .hold_m
            .iter()
            .chain(plan.pull_m.iter())
            .chain(plan.up.iter())
            .all(|c| c.is_finite());
        if !finite || plan.up.norm() < 1e-9 {
            return Err("the grasp's point, traction and up direction must be finite".into());
        }
        if plan.release_s.is_some_and(|t| !(t.is_finite() && t > 0.0)) {
            return Err("the grasp's release time must be positive".into());
        }
        let mut rng = Rng::new(seed ^ 0x0067_7261_7370_6572);
        let tremor = std::array::from_fn(|_| {
            (
                8.0 + 4.0 * rng.uniform(),
                std::f64::consts::TAU * rng.uniform(),
            )
        });
        let plan = GraspPlan {
            up: plan.up.normalize(),
            ..plan
        };
        Ok(Self {
            name: "grasper".into(),
            plan,
            tremor,
            force_newtons: Vector3::zeros(),
        })
    }

    /// When the jaws close, s.
    pub fn closes_at_s(&self) -> f64 {
        REACH_S + PAUSE_S
    }

    /// The last force written to the hand, N.
    pub fn force_newtons(&self) -> Vector3 {
        self.force_newtons
    }

    /// The jaws' centre and whether they are closed at `time_s`, without tremor.
    fn path(&self, time_s: f64) -> (Point3, bool) {
        let p = &self.plan;
        let above = p.hold_m + p.up * ABOVE_M;
        let close = self.closes_at_s();
        let smooth = |s: f64| {
            let s = s.clamp(0.0, 1.0);
            s * s * (3.0 - 2.0 * s)
        };
        let held = p.hold_m + p.pull_m * smooth((time_s - close) / PULL_S);
        match p.release_s {
            Some(release) if time_s >= release => {
                let from = p.hold_m + p.pull_m * smooth((release - close) / PULL_S);
                let lift = smooth((time_s - release) / LIFT_S);
                (from + p.up * (ABOVE_M * lift), false)
            }
            _ if time_s < REACH_S => (above + (p.hold_m - above) * smooth(time_s / REACH_S), false),
            _ if time_s < close => (p.hold_m, false),
            _ => (held, true),
        }
    }
}

impl HapticDevice for GrasperHand {
    fn name(&self) -> &str {
        &self.name
    }

    fn read(&mut self, _tick: u64, time_s: f64) -> Result<ToolPose, DeviceFault> {
        let (centre, closed) = self.path(time_s);
        let mut shake = Vector3::zeros();
        for (axis, &(hz, phase)) in self.tremor.iter().enumerate() {
            shake[axis] = TREMOR_M * (std::f64::consts::TAU * hz * time_s + phase).sin();
        }
        Ok(ToolPose {
            tip_in_world: centre + shake,
            buttons: if closed { BUTTON_JAWS } else { 0 },
            ..ToolPose::default()
        })
    }

    fn write_force(&mut self, force_newtons: Vector3) -> Result<(), DeviceFault> {
        self.force_newtons = force_newtons;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Beside the line's middle to its left, drawn further left and up; the expert holds to
    /// the end, a hand that lets go does so after its share of the stroke; a line without a
    /// direction is refused.
    #[test]
    fn countertraction_holds_beside_the_line_and_draws_away() {
        let line = crate::plan::Plan::flat_across_x(0.004);
        let traction = Traction {
            beside_m: 0.01,
            away_m: 0.004,
            lift_m: 0.002,
            hold_share: 0.5,
        };
        let g = GraspPlan::countertraction(&line, &traction, 6.0, 3).expect("a grasp");
        // the line runs along +x with +z up: its left is +y
        assert!((g.hold_m.y - 0.01).abs() < 1e-12 && g.hold_m.x.abs() <= 2e-3);
        assert!((g.pull_m - Vector3::new(0.0, 0.004, 0.002)).norm() < 1e-12);
        assert_eq!(g.release_s, Some(REACH_S + PAUSE_S + 3.0));
        let to_the_end = Traction {
            hold_share: 1.0,
            ..traction
        };
        let g = GraspPlan::countertraction(&line, &to_the_end, 6.0, 3).expect("a grasp");
        assert_eq!(g.release_s, None);
        let mut point = line.clone();
        point.line_m = vec![Point3::origin(); 2];
        assert!(GraspPlan::countertraction(&point, &traction, 6.0, 3).is_err());
    }

    fn plan() -> GraspPlan {
        GraspPlan {
            hold_m: Point3::new(0.05, 0.05, 0.0008),
            pull_m: Vector3::new(0.0, 0.0, 0.005),
            up: Vector3::z(),
            release_s: Some(6.0),
        }
    }

    #[test]
    fn the_hand_reaches_closes_pulls_holds_and_lets_go() {
        let mut hand = GrasperHand::new(plan(), 3).expect("a valid plan");
        let at = |hand: &mut GrasperHand, t: f64| hand.read(0, t).expect("a pose");
        let start = at(&mut hand, 0.0);
        assert!(!start.jaws_closed() && start.tip_in_world.z > 0.015);
        let reached = at(&mut hand, 1.1);
        assert!(!reached.jaws_closed() && (reached.tip_in_world - plan().hold_m).norm() < 5e-4);
        assert!(at(&mut hand, 1.25).jaws_closed());
        let pulled = at(&mut hand, 3.0);
        assert!(pulled.jaws_closed());
        assert!((pulled.tip_in_world.z - (0.0008 + 0.005)).abs() < 5e-4);
        let gone = at(&mut hand, 7.0);
        assert!(!gone.jaws_closed() && gone.tip_in_world.z > 0.015);
        // seeded: the same seed the same bits, another seed another tremor
        let again = at(&mut GrasperHand::new(plan(), 3).expect("valid"), 3.0);
        assert_eq!(again, pulled);
        let other = at(&mut GrasperHand::new(plan(), 4).expect("valid"), 3.0);
        assert_ne!(other.tip_in_world, pulled.tip_in_world);
    }

    #[test]
    fn a_plan_at_no_place_is_refused() {
        let nan = GraspPlan {
            hold_m: Point3::new(f64::NAN, 0.0, 0.0),
            ..plan()
        };
        assert!(GrasperHand::new(nan, 1).is_err());
        let flat = GraspPlan {
            up: Vector3::zeros(),
            ..plan()
        };
        assert!(GrasperHand::new(flat, 1).is_err());
        let never = GraspPlan {
            release_s: Some(-1.0),
            ..plan()
        };
        assert!(GrasperHand::new(never, 1).is_err());
    }
}
