//! The wound retractor the trainee sets at the station (issue 62): while the scalpel's
//! [`crate::pose::BUTTON_RETRACT`] is held, a soft-tissue retractor spreads the wound the
//! session's cuts made to [`RETRACTOR_WIDTH_M`] ([`cutlab_sim::retractor`]); let go, the
//! wound closes again.
//!
//! The incision it is set along is the span of the cuts on the skin: each cut's tip projected
//! onto the skin's plane where the first stroke went in (along its normal, the retractor's
//! `up`), the two projected points farthest apart kept (each new point replaces the end it
//! lies farther from when that makes the span longer). A later stroke may go in inside the
//! wound (a blade pressed again after a reload enters on a wall, deep down); its own entry
//! plane would put the span's end down there.

use cutlab_sim::retractor::{Opening, Retractor};
use cutlab_sim::solver::Simulation;

use crate::{Point3, Vector3};

/// The width the station's retractor opens the wound's middle to, m: a mini-thoracotomy's
/// soft-tissue retractor, the width scoring spreads a field exercise's wound to.
pub const RETRACTOR_WIDTH_M: f64 = 0.02;

/// An incision shorter than this is not retracted, m.
const SHORTEST_M: f64 = 0.002;

/// The incision's span on the skin so far.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Incision {
    /// The span's ends on the skin, m.
    pub ends_m: [Point3; 2],
    /// The way out of the body where the first stroke went in (unit).
    pub up: Vector3,
}

/// The retractor's state in a session: the incision it would be set along, and the opening
/// while it is set.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WoundRetraction {
    /// The incision the cuts made so far.
    pub incision: Option<Incision>,
    /// The retractor, while set.
    pub opening: Option<Opening>,
    /// The button was held at the last step (the retractor is set as it is pressed).
    pub pressed: bool,
}

impl WoundRetraction {
    /// A cut at `tip` of a stroke that went in at `entry` with the outward `normal` there
    /// (which set the skin's plane if it is the first).
    pub fn note_cut(&mut self, tip: &Point3, entry: &Point3, normal: &Vector3) {
        let Some(inc) = &mut self.incision else {
            self.incision = Some(Incision {
                ends_m: [tip - normal * (tip - entry).dot(normal); 2],
                up: *normal,
            });
            return;
        };
        let [a, b] = inc.ends_m;
        let on_skin = tip - inc.up * (tip - a).dot(&inc.up);
        let span = (b - a).norm();
        if (on_skin - a).norm() > span.max((on_skin - b).norm()) {
            inc.ends_m[1] = on_skin;
        } else if (on_skin - b).norm() > span {
            inc.ends_m[0] = on_skin;
        }
    }

    /// Before a simulation step: sets the retractor as the button is pressed (once there is an
    /// incision to set it in), carries it open, and takes it out as the button is let go.
    /// Returns whether it was set at this step.
    pub fn update(&mut self, sim: &mut Simulation, pressed: bool) -> bool {
        let was = std::mem::replace(&mut self.pressed, pressed);
        let mut set = false;
        if pressed && !was && self.opening.is_none() {
            if let Some(inc) = self
                .incision
                .filter(|i| (i.ends_m[1] - i.ends_m[0]).norm() >= SHORTEST_M)
            {
                let retractor = Retractor {
                    line_m: inc.ends_m.to_vec(),
                    up: inc.up,
                    width_m: RETRACTOR_WIDTH_M,
                };
                self.opening = Some(retractor.set(sim));
                set = true;
            }
        } else if !pressed && let Some(opening) = self.opening.take() {
            opening.release(sim);
        }
        if let Some(opening) = &mut self.opening {
            opening.carry(sim);
        }
        set
    }

    /// Whether its particles are in a mesh of `vertex_count` and its numbers finite.
    pub fn fits(&self, vertex_count: usize) -> bool {
        let finite = |p: &Point3| p.iter().all(|c| c.is_finite());
        self.incision
            .is_none_or(|i| i.ends_m.iter().all(finite) && i.up.iter().all(|c| c.is_finite()))
            && self.opening.as_ref().is_none_or(|o| o.fits(vertex_count))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_incision_is_the_span_of_the_cuts_projected_onto_the_skin() {
        let mut r = WoundRetraction::default();
        let (entry, up) = (Point3::new(0.0, 0.0, 0.01), Vector3::z());
        for x in [0.0, 0.01, 0.005, 0.03, 0.02] {
            r.note_cut(&Point3::new(x, 0.001 * x, -0.02), &entry, &up);
        }
        let inc = r.incision.expect("an incision");
        assert_eq!(inc.up, up);
        let xs = inc.ends_m.map(|p| p.x);
        assert!(
            xs.contains(&0.0) && xs.contains(&0.03),
            "the ends are the farthest apart: {:?}",
            inc.ends_m
        );
        assert!(
            inc.ends_m.iter().all(|p| (p.z - 0.01).abs() < 1e-15),
            "on the skin's plane"
        );
        // a tip behind the first end lengthens the span that way
        r.note_cut(&Point3::new(-0.01, 0.0, -0.02), &entry, &up);
        let xs = r.incision.expect("an incision").ends_m.map(|p| p.x);
        assert!(xs.contains(&-0.01) && xs.contains(&0.03), "{xs:?}");
        // a stroke that went in on a wall inside the wound, 30 mm down (its normal across the
        // wound) lengthens the span on the skin, not down there
        let wall = (Point3::new(0.03, 0.0, -0.02), Vector3::y());
        r.note_cut(&Point3::new(0.05, 0.0, -0.03), &wall.0, &wall.1);
        let inc = r.incision.expect("an incision");
        assert!(
            inc.ends_m.iter().any(|p| (p.x - 0.05).abs() < 1e-12)
                && inc.ends_m.iter().all(|p| (p.z - 0.01).abs() < 1e-15),
            "{:?}",
            inc.ends_m
        );
    }
}
