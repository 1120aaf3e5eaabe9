//! Where an incision lies among landmarks laid parallel to it (the ribs either side of an
//! intercostal space), counted in spaces: what a synthetic trainee chooses from and what the
//! debrief says ("one space lower than the expert's").
//!
//! Seen along the skin's normal `n`, with `t` the planned line's direction and `a = n x t`
//! across it, each parallel landmark `i` lies at an offset `c_i = (m_i - o) . a` from the
//! line's middle `o`. The marks, in the order they are listed, get the positions `k + 1/2`
//! (`k` integer) so that the planned line's space is `(-1/2, 1/2)`: position 0 is the plan's
//! space, +1 the next space in listing order (the marks of the thorax are listed head first:
//! +1 is one space lower), +1/2 on the mark between them. Between marks the position is
//! linear in the offset; beyond the outermost marks it goes on at the outermost pitch.

use crate::{Point3, Vector3};

/// A landmark counts as parallel to the line when its direction is within this cosine of it.
const PARALLEL_COS: f64 = 0.9;

/// The spaces between the landmarks parallel to a planned line.
#[derive(Debug, Clone, PartialEq)]
pub struct Spaces {
    /// The planned line's middle, m.
    origin_m: Point3,
    /// Unit vector across the line on the skin.
    across: Vector3,
    /// Unit vector along the line.
    along: Vector3,
    /// The parallel marks' offsets across, in listing order (strictly monotone), m.
    offsets_m: Vec<f64>,
    /// The position of the first mark (`k + 1/2`).
    first_position: f64,
}

impl Spaces {
    /// The spaces of `landmarks` around the planned `line` (entry first) on a skin facing
    /// `normal`; `None` when fewer than two landmarks run parallel to the line, when their
    /// offsets do not run one way in the order listed, or when the line does not lie between
    /// two of them.
    pub fn new(line: &[Point3], normal: &Vector3, landmarks: &[Vec<Point3>]) -> Option<Self> {
        let n = normal.try_normalize(1e-12)?;
        let (first, last) = (line.first()?, line.last()?);
        let flat = |v: Vector3| v - n * n.dot(&v);
        let along = flat(last - first).try_normalize(1e-12)?;
        let across = n.cross(&along);
        let origin_m = Point3::from((first.coords + last.coords) * 0.5);
        let offsets_m: Vec<f64> = landmarks
            .iter()
            .filter_map(|mark| {
                let (a, b) = (mark.first()?, mark.last()?);
                let dir = flat(b - a).try_normalize(1e-12)?;
                (dir.dot(&along).abs() >= PARALLEL_COS)
                    .then(|| (Point3::from((a.coords + b.coords) * 0.5) - origin_m).dot(&across))
            })
            .collect();
        if offsets_m.len() < 2 {
            return None;
        }
        let sign = (offsets_m[1] - offsets_m[0]).signum();
        if !offsets_m.windows(2).all(|w| (w[1] - w[0]) * sign > 0.0) {
            return None;
        }
        // the line's space: between the last mark before it and the first after, in order
        let before = offsets_m.iter().take_while(|&&c| c * sign < 0.0).count();
        if before == 0 || before == offsets_m.len() {
            return None;
        }
        Some(Self {
            origin_m,
            across,
            along,
            offsets_m,
            first_position: 0.5 - before as f64,
        })
    }

    /// Unit vectors along and across the planned line on the skin.
    pub fn axes(&self) -> (Vector3, Vector3) {
        (self.along, self.across)
    }

    /// The planned line's middle, m.
    pub fn origin_m(&self) -> Point3 {
        self.origin_m
    }

    /// The position of `point` in spaces from the plan's (0: the plan's space, +-1 the next
    /// ones, +-1/2 on the marks between).
    pub fn position(&self, point: &Point3) -> f64 {
        let c = (point - self.origin_m).dot(&self.across);
        let o = &self.offsets_m;
        // the segment of marks it falls in (the outermost ones extended)
        let sign = (o[1] - o[0]).signum();
        let i = o
            .iter()
            .take_while(|&&m| (m - c) * sign < 0.0)
            .count()
            .clamp(1, o.len() - 1);
        let u = (c - o[i - 1]) / (o[i] - o[i - 1]);
        self.first_position + (i - 1) as f64 + u
    }

    /// The offset across the planned line (m) of position `position` (the inverse of
    /// [`Self::position`]).
    pub fn offset_m(&self, position: f64) -> f64 {
        let o = &self.offsets_m;
        let k = position - self.first_position;
        let i = (k.floor().max(0.0) as usize).min(o.len() - 2);
        o[i] + (k - i as f64) * (o[i + 1] - o[i])
    }
}

/// Where a position in spaces lies, as a surgeon says it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// In a space, counted from the plan's (0 the plan's, +1 the next in listing order).
    Space(i32),
    /// On the mark between space `k` and `k + 1`.
    OnMark(i32),
}

impl Placement {
    /// The placement of `position`: a space when within 0.3 of its middle (the space being
    /// the part of the pitch between the marks' own widths), else on the mark.
    pub fn of(position: f64) -> Self {
        let k = position.round();
        if (position - k).abs() <= 0.3 {
            Placement::Space(k as i32)
        } else {
            Placement::OnMark(position.floor() as i32)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ribs at y = 35, 10, -15 and -45 mm (listed head first), the sternum's edge along y,
    /// the line in the space between y = 10 and -15.
    fn thorax() -> Spaces {
        let rib = |y: f64| vec![Point3::new(-0.045, y, 0.0), Point3::new(0.048, y, 0.0)];
        let marks = vec![
            vec![
                Point3::new(-0.045, -0.048, 0.0),
                Point3::new(-0.045, 0.048, 0.0),
            ],
            rib(0.035),
            rib(0.010),
            rib(-0.015),
            rib(-0.045),
        ];
        let line = [
            Point3::new(-0.02, -0.0025, 0.0),
            Point3::new(0.03, -0.0025, 0.0),
        ];
        Spaces::new(&line, &Vector3::z(), &marks).expect("spaces")
    }

    #[test]
    fn positions_count_spaces_from_the_plans_in_the_order_listed() {
        let s = thorax();
        let at = |y: f64| s.position(&Point3::new(0.0, y, 0.0));
        assert!(at(-0.0025).abs() < 1e-12, "{}", at(-0.0025));
        assert!((at(0.010) + 0.5).abs() < 1e-12 && (at(-0.015) - 0.5).abs() < 1e-12);
        // the next space in listing order (lower) and the one before (higher)
        assert_eq!(Placement::of(at(-0.030)), Placement::Space(1));
        assert_eq!(Placement::of(at(0.0225)), Placement::Space(-1));
        assert_eq!(Placement::of(at(-0.015)), Placement::OnMark(0));
        assert_eq!(Placement::of(at(0.010)), Placement::OnMark(-1));
        // beyond the outermost mark at the outermost pitch
        assert!((at(-0.075) - 2.5).abs() < 1e-12, "{}", at(-0.075));
        for p in [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.5] {
            assert!((s.position(&(s.origin_m() + s.axes().1 * s.offset_m(p))) - p).abs() < 1e-9);
        }
    }

    #[test]
    fn marks_that_do_not_frame_the_line_give_no_spaces() {
        let rib = |y: f64| vec![Point3::new(-0.04, y, 0.0), Point3::new(0.04, y, 0.0)];
        let line = [Point3::new(-0.02, 0.0, 0.0), Point3::new(0.02, 0.0, 0.0)];
        let z = Vector3::z();
        assert!(Spaces::new(&line, &z, &[rib(0.01)]).is_none(), "one mark");
        assert!(
            Spaces::new(&line, &z, &[rib(0.02), rib(0.01)]).is_none(),
            "both above"
        );
        assert!(
            Spaces::new(&line, &z, &[rib(0.01), rib(-0.01), rib(0.02)]).is_none(),
            "out of order"
        );
        assert!(Spaces::new(&line, &z, &[rib(0.01), rib(-0.01)]).is_some());
    }
}
