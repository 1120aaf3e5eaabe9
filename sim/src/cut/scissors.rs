//! Scissors (issue 66): two blades hinged at a pivot that shear the material between them as
//! they close.
//!
//! The blades turn about the hinge axis `h` in the plane normal to it; the jaws' axis `a`
//! (unit, normal to `h`) bisects them. Open by the angle `theta`, the blades stand
//! `g = L tan(theta / 2)` from the jaws' axis at their tips (`L` the blades' length). Closing,
//! the point where their edges meet runs from the pivot `P` to the tips: closed a fraction
//! `c` of the way it is at `P + c L a`, and every material point in the blades' plane within
//! `g` of the axis and behind that point has been sheared. So a closure is one stroke of a
//! [`Blade`] whose edge stands across the axis, `e = h x a`, from `-g` to `+g`, moved from the
//! pivot to the tips: the cutter's swept polygons are the sheared band. A membrane thinner than
//! `2 g` (gauze) is cut through along the blades' length in one closure.

use super::{Blade, CutError, CutEvent, Cutter};
use crate::solver::Simulation;
use crate::{Point3, Vector3};

/// A pair of scissors at one pose.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Scissors {
    /// The pivot, m.
    pub pivot_m: Point3,
    /// The jaws' axis, from the pivot towards the tips (unit).
    pub along: Vector3,
    /// The hinge axis the blades turn about (unit, normal to `along`).
    pub hinge: Vector3,
    /// The blades' length from the pivot, m.
    pub blade_length_m: f64,
    /// The opening before the closure, radians (0 to pi/2).
    pub opening_rad: f64,
}

/// Cuts between two of a closure's blade positions: about the cutter's spacing along the
/// jaws, m.
pub const CLOSURE_SPACING_M: f64 = 0.0005;

impl Scissors {
    /// Laparoscopic scissors (blades 15 mm long, opened 40 degrees) at `pivot_m`, closing
    /// along `along` with the blades turning about `hinge`.
    pub fn laparoscopic(pivot_m: Point3, along: Vector3, hinge: Vector3) -> Self {
        Self {
            pivot_m,
            along: along.normalize(),
            hinge: hinge.normalize(),
            blade_length_m: 0.015,
            opening_rad: 40f64.to_radians(),
        }
    }

    /// Whether every number is finite, the axes unit and normal to each other, the length
    /// positive and the opening within (0, pi/2].
    pub fn is_valid(&self) -> bool {
        let finite = self
            .pivot_m
            .iter()
            .chain(self.along.iter())
            .chain(self.hinge.iter())
            .all(|c| c.is_finite());
        finite
            && (self.along.norm() - 1.0).abs() < 1e-9
            && (self.hinge.norm() - 1.0).abs() < 1e-9
            && self.along.dot(&self.hinge).abs() < 1e-9
            && self.blade_length_m > 0.0
            && self.blade_length_m.is_finite()
            && self.opening_rad > 0.0
            && self.opening_rad <= std::f64::consts::FRAC_PI_2
    }

    /// How far the open blades stand from the jaws' axis at their tips, m: `L tan(theta/2)`.
    pub fn gap_m(&self) -> f64 {
        self.blade_length_m * (0.5 * self.opening_rad).tan()
    }

    /// The blade the closure shears with when closed the fraction `closed` (0 to 1) of the
    /// way: its edge across the axis through the meeting point, spanning the gap.
    pub fn blade(&self, closed: f64) -> Blade {
        let across = self.hinge.cross(&self.along).normalize();
        let meet = self.pivot_m + self.along * (closed.clamp(0.0, 1.0) * self.blade_length_m);
        let gap = self.gap_m();
        super::blade(meet - across * gap, across, 2.0 * gap)
    }

    /// One whole closure on `sim` as one stroke of `cutter`: the blade from the pivot to the
    /// tips, a cut every [`CLOSURE_SPACING_M`], `steps_per_cut` simulation steps after each.
    /// Returns the cuts' events; the stroke is ended, and a cut that fails ends the closure
    /// with its error (the simulation unchanged by that cut).
    pub fn close(
        &self,
        sim: &mut Simulation,
        cutter: &mut Cutter,
        steps_per_cut: usize,
    ) -> Result<Vec<CutEvent>, CutError> {
        if !self.is_valid() {
            return Err(CutError::NonFiniteBlade);
        }
        let n = (self.blade_length_m / CLOSURE_SPACING_M).ceil().max(1.0) as usize;
        let mut events = Vec::new();
        for k in 0..=n {
            let event = cutter.advance(sim, self.blade(k as f64 / n as f64));
            let event = match event {
                Ok(e) => e,
                Err(e) => {
                    cutter.abandon_stroke();
                    return Err(e);
                }
            };
            events.push(event);
            for _ in 0..steps_per_cut {
                // a rejected step keeps the state; the closure goes on as a hand's would
                let _ = sim.step();
            }
        }
        cutter.end_stroke();
        Ok(events)
    }
}
