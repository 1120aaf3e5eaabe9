//! Where a synthetic trainee places an incision it chooses itself (the `field` exercises): from
//! the expert's line and the landmarks on the skin ([`Spaces`]), with the mistakes a trainee
//! of its level makes in choosing: the wrong space, the line on a rib, too short, too shallow.
//! Drawn once per attempt from its own seeded stream, so the hand's own noise is the same as
//! when it follows the expert's line.

use crate::landmarks::Spaces;
use crate::{Point3, Vector3};
use cutlab_sim::rng::Rng;

/// How well a trainee chooses an incision: the chance of each mistake and the scatter of a
/// right choice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Planning {
    /// Chance of choosing a neighbouring space (either side).
    pub wrong_space: f64,
    /// Chance of placing the line on a mark (a rib) next to the right space.
    pub on_mark: f64,
    /// Chance of an incision too short; its length is then `short_fraction` of the expert's.
    pub too_short: f64,
    /// The length of a too short incision, a fraction of the expert's.
    pub short_fraction: f64,
    /// Chance of stopping short of the planned depth, at `shallow_fraction` of it.
    pub too_shallow: f64,
    /// The depth of a too shallow incision, a fraction of the expert's.
    pub shallow_fraction: f64,
    /// Scatter of the line's middle along the line (standard deviation), m.
    pub along_sd_m: f64,
    /// Scatter of the line across, within the space chosen (standard deviation), m.
    pub across_sd_m: f64,
    /// Relative scatter of the length of a right choice (standard deviation).
    pub length_sd: f64,
}

impl Planning {
    /// The expert's: the right space, the right length, placed within a few millimetres.
    pub const EXPERT: Self = Self {
        wrong_space: 0.0,
        on_mark: 0.0,
        too_short: 0.0,
        short_fraction: 0.6,
        too_shallow: 0.0,
        shallow_fraction: 0.7,
        along_sd_m: 0.004,
        across_sd_m: 0.0007,
        length_sd: 0.04,
    };
    /// The intermediate's: sometimes a space off, on a rib, short or shallow.
    pub const INTERMEDIATE: Self = Self {
        wrong_space: 0.15,
        on_mark: 0.1,
        too_short: 0.2,
        short_fraction: 0.65,
        too_shallow: 0.1,
        shallow_fraction: 0.7,
        along_sd_m: 0.006,
        across_sd_m: 0.0015,
        length_sd: 0.08,
    };
    /// The novice's: more often wrong than right.
    pub const NOVICE: Self = Self {
        wrong_space: 0.35,
        on_mark: 0.25,
        too_short: 0.45,
        short_fraction: 0.5,
        too_shallow: 0.3,
        shallow_fraction: 0.6,
        along_sd_m: 0.008,
        across_sd_m: 0.0025,
        length_sd: 0.15,
    };

    /// `a` and `b` mixed, `t` = 0 all `a`, 1 all `b`.
    pub fn mix(a: &Self, b: &Self, t: f64) -> Self {
        let m = |x: f64, y: f64| x * (1.0 - t) + y * t;
        Self {
            wrong_space: m(a.wrong_space, b.wrong_space),
            on_mark: m(a.on_mark, b.on_mark),
            too_short: m(a.too_short, b.too_short),
            short_fraction: m(a.short_fraction, b.short_fraction),
            too_shallow: m(a.too_shallow, b.too_shallow),
            shallow_fraction: m(a.shallow_fraction, b.shallow_fraction),
            along_sd_m: m(a.along_sd_m, b.along_sd_m),
            across_sd_m: m(a.across_sd_m, b.across_sd_m),
            length_sd: m(a.length_sd, b.length_sd),
        }
    }

    /// The incision this trainee chooses, drawn with `seed`, given the expert's `line` (entry
    /// first) and `depth_m` on a skin facing `normal`, and the skin's `landmarks`. Without
    /// landmarks that frame the line it keeps the expert's place and chooses the length and
    /// depth only.
    pub fn choose(
        &self,
        line: &[Point3],
        normal: &Vector3,
        depth_m: f64,
        landmarks: &[Vec<Point3>],
        seed: u64,
    ) -> Choice {
        // a stream of its own: the hand's noise does not depend on the choice
        let mut rng = Rng::new(seed ^ 0x5eed_c401_ce00_0001);
        let spaces = Spaces::new(line, normal, landmarks);
        let side = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let pick = rng.uniform();
        let position = if pick < self.wrong_space {
            side
        } else if pick < self.wrong_space + self.on_mark {
            0.5 * side
        } else {
            0.0
        };
        let short = rng.uniform() < self.too_short;
        let shallow = rng.uniform() < self.too_shallow;
        let (n_along, n_across, n_length) = (rng.normal(), rng.normal(), rng.normal());
        let length_factor = if short {
            self.short_fraction
        } else {
            1.0 + self.length_sd * n_length
        }
        .max(0.2);
        let depth_m = if shallow {
            depth_m * self.shallow_fraction
        } else {
            depth_m
        };
        // about the expert's middle: moved to the space chosen, where the landmarks frame
        // the line (else kept in place), and scaled to the length chosen
        let middle = match (line.first(), line.last()) {
            (Some(a), Some(b)) => Point3::from((a.coords + b.coords) * 0.5),
            _ => Point3::origin(), // no line: nothing to move
        };
        let (shift, position) = match spaces {
            Some(spaces) => {
                let (along, across) = spaces.axes();
                let shift = across * (spaces.offset_m(position) + self.across_sd_m * n_across)
                    + along * (self.along_sd_m * n_along);
                (shift, position)
            }
            None => (Vector3::zeros(), 0.0),
        };
        Choice {
            line_m: line
                .iter()
                .map(|p| middle + shift + (p - middle) * length_factor)
                .collect(),
            depth_m,
            position,
        }
    }
}

/// An incision a trainee chose.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The line on the skin, entry first (m).
    pub line_m: Vec<Point3>,
    /// How deep it is cut (m).
    pub depth_m: f64,
    /// The space aimed at, in spaces from the expert's ([`Spaces::position`]).
    pub position: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::landmarks::Placement;

    fn thorax() -> (Vec<Point3>, Vec<Vec<Point3>>) {
        let rib = |y: f64| vec![Point3::new(-0.045, y, 0.0), Point3::new(0.048, y, 0.0)];
        let line = vec![
            Point3::new(-0.02, -0.0025, 0.0),
            Point3::new(0.03, -0.0025, 0.0),
        ];
        (line, vec![rib(0.035), rib(0.010), rib(-0.015), rib(-0.045)])
    }

    fn choices(planning: &Planning) -> Vec<(Choice, Spaces)> {
        let (line, marks) = thorax();
        let spaces = Spaces::new(&line, &Vector3::z(), &marks).expect("spaces");
        (0..200)
            .map(|seed| {
                (
                    planning.choose(&line, &Vector3::z(), 0.045, &marks, seed),
                    spaces.clone(),
                )
            })
            .collect()
    }

    fn length(c: &Choice) -> f64 {
        (c.line_m[c.line_m.len() - 1] - c.line_m[0]).norm()
    }

    /// The expert always chooses the plan's space, its length within 15 % and its depth;
    /// the novice chooses another space, a rib, too short or too shallow most of the time.
    #[test]
    fn the_expert_chooses_the_right_space_and_the_novice_often_not() {
        for (c, spaces) in choices(&Planning::EXPERT) {
            let middle = Point3::from((c.line_m[0].coords + c.line_m[1].coords) * 0.5);
            assert_eq!(Placement::of(spaces.position(&middle)), Placement::Space(0));
            assert!((length(&c) / 0.05 - 1.0).abs() < 0.15, "{}", length(&c));
            assert_eq!(c.depth_m, 0.045);
        }
        let novices = choices(&Planning::NOVICE);
        let wrong = novices
            .iter()
            .filter(|(c, spaces)| {
                let middle = Point3::from((c.line_m[0].coords + c.line_m[1].coords) * 0.5);
                Placement::of(spaces.position(&middle)) != Placement::Space(0)
                    || length(c) < 0.04
                    || c.depth_m < 0.045
            })
            .count();
        assert!(
            wrong > 150 && wrong < 200,
            "{wrong} of 200 novices chose wrong"
        );
        let on_rib = novices
            .iter()
            .filter(|(c, _)| c.position.fract() != 0.0)
            .count();
        assert!(on_rib > 20, "{on_rib}");
    }

    #[test]
    fn a_choice_is_the_same_for_the_same_seed() {
        let (line, marks) = thorax();
        let z = Vector3::z();
        let p = Planning::INTERMEDIATE;
        assert_eq!(
            p.choose(&line, &z, 0.045, &marks, 7),
            p.choose(&line, &z, 0.045, &marks, 7)
        );
        assert_ne!(
            p.choose(&line, &z, 0.045, &marks, 7),
            p.choose(&line, &z, 0.045, &marks, 8)
        );
        // no landmarks: never a space off
        let c = Planning::NOVICE.choose(&line, &z, 0.045, &[], 3);
        assert_eq!(c.position, 0.0);
        assert!((c.line_m[0].y + 0.0025).abs() < 1e-12);
    }
}
