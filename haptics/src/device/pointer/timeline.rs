//! The samples the device has taken, on the session's clock: where the page clock is anchored,
//! where the playback cursor is, and the pose there.

use std::collections::VecDeque;

use crate::pose::BUTTON_BLADE;
use crate::{Point3, Rotation, ToolPose};

/// A usable sample as a pose at a page time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Keyed {
    pub t_ms: f64,
    pub pose: ToolPose,
}

/// What [`Timeline::advance`] did to the clock mapping this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Advance {
    /// The page clock was anchored again (not counting the first anchoring).
    pub reanchored: bool,
    /// The cursor wanted to be past the newest sample: the pose is held.
    pub held: bool,
}

/// The samples around the cursor, oldest first, and the clock mapping.
///
/// Page time `p` plays at session time `p - offset_ms + delay_ms`: the cursor at session time
/// `s` is `s + offset_ms - delay_ms` (page ms), moved only forwards and never past the newest
/// sample.
#[derive(Debug)]
pub(crate) struct Timeline {
    samples: VecDeque<Keyed>,
    /// Samples kept at most (the allocation is made up front).
    capacity: usize,
    delay_ms: f64,
    max_lag_ms: f64,
    /// Page ms minus session ms; `None` before the first sample.
    offset_ms: Option<f64>,
    cursor_ms: f64,
    /// At the last tick the cursor wanted to be past the newest sample.
    dry: bool,
}

impl Timeline {
    pub fn new(capacity: usize, delay_ms: f64, max_lag_ms: f64) -> Self {
        let capacity = capacity.max(2);
        Self {
            samples: VecDeque::with_capacity(capacity),
            capacity,
            delay_ms,
            max_lag_ms,
            offset_ms: None,
            cursor_ms: f64::NEG_INFINITY,
            dry: false,
        }
    }

    /// Forgets the samples and the clock mapping (the allocation is kept): the next sample
    /// anchors the page clock anew, as the first did. The pose stays where it was until then.
    pub fn restart(&mut self) {
        self.samples.clear();
        self.offset_ms = None;
        self.cursor_ms = f64::NEG_INFINITY;
        self.dry = false;
    }

    /// The newest sample's page time, ms.
    pub fn newest_ms(&self) -> Option<f64> {
        self.samples.back().map(|k| k.t_ms)
    }

    /// Takes a sample later than every sample taken before (the caller checks the order).
    pub fn push(&mut self, k: Keyed) {
        if self.samples.len() >= self.capacity {
            // more samples than fit between the cursor and now: the oldest go first
            self.samples.pop_front();
        }
        self.samples.push_back(k);
    }

    /// Moves the cursor to session time `time_ms` (`arrived`: samples were taken this tick).
    ///
    /// The page clock is anchored so the newest sample plays `delay_ms` from now: at the first
    /// sample; again when samples arrive after the cursor ran past the newest one (the page
    /// stalled or its clock runs slow: the pose was held, and latency is restored to the
    /// delay); and when the newest sample is more than `max_lag_ms` ahead of the cursor (the
    /// page's clock runs fast). The cursor never moves back, so an anchoring only ever holds
    /// the pose a little longer or skips forward.
    pub fn advance(&mut self, time_ms: f64, arrived: bool) -> Advance {
        let mut out = Advance {
            reanchored: false,
            held: false,
        };
        let Some(newest_ms) = self.newest_ms() else {
            return out;
        };
        let offset_ms = match self.offset_ms {
            None => newest_ms - time_ms,
            Some(offset_ms) => {
                let natural_ms = time_ms + offset_ms - self.delay_ms;
                if arrived && (self.dry || newest_ms - natural_ms > self.max_lag_ms) {
                    out.reanchored = true;
                    newest_ms - time_ms
                } else {
                    offset_ms
                }
            }
        };
        self.offset_ms = Some(offset_ms);
        let natural_ms = time_ms + offset_ms - self.delay_ms;
        self.dry = natural_ms > newest_ms;
        out.held = self.dry;
        self.cursor_ms = natural_ms.max(self.cursor_ms).min(newest_ms);
        out
    }

    /// The pose at the cursor: linear between the samples around it (tip), spherical
    /// (orientation), the buttons held in either (see [`interpolate`]); exact at a sample's
    /// time.
    pub fn pose(&mut self) -> Option<ToolPose> {
        // samples before the one at or before the cursor are never needed again
        while self.samples.len() >= 2 && self.samples[1].t_ms <= self.cursor_ms {
            self.samples.pop_front();
        }
        let a = *self.samples.front()?;
        let Some(b) = self.samples.get(1).copied() else {
            return Some(a.pose);
        };
        if self.cursor_ms <= a.t_ms {
            return Some(a.pose);
        }
        let u = (self.cursor_ms - a.t_ms) / (b.t_ms - a.t_ms);
        Some(interpolate(&a.pose, &b.pose, u))
    }
}

/// `a` to `b` at `u` in [0, 1): tip linear, orientation spherical (the shorter way), the
/// buttons held in either. A press moves the tip from the surface to the set depth between
/// the last sample before it and the first after: the blade is engaged all the way down, so
/// the tissue it presses is counted as pressed by the blade from where it first touched (with
/// the earlier sample's buttons the tip sank into a thin sheet disengaged, and the engaged
/// blade's press was counted from the sagging surface: it never went in). A release likewise
/// keeps the blade engaged until the tip is out.
pub(crate) fn interpolate(a: &ToolPose, b: &ToolPose, u: f64) -> ToolPose {
    let tip: Point3 = a.tip_in_world + (b.tip_in_world - a.tip_in_world) * u;
    let rotation = if u == 0.0 || a.world_from_tool == b.world_from_tool {
        a.world_from_tool
    } else {
        a.world_from_tool
            .try_slerp(&b.world_from_tool, u, 1e-12)
            .unwrap_or_else(|| nlerp(&a.world_from_tool, &b.world_from_tool, u))
    };
    ToolPose {
        tip_in_world: tip,
        world_from_tool: rotation,
        buttons: if u == 0.0 {
            a.buttons
        } else {
            a.buttons | b.buttons
        },
    }
}

/// Normalised linear interpolation of quaternions (the fallback of a degenerate slerp).
fn nlerp(a: &Rotation, b: &Rotation, u: f64) -> Rotation {
    let b = if a.coords.dot(&b.coords) < 0.0 {
        -b.into_inner()
    } else {
        b.into_inner()
    };
    let q = a.into_inner() * (1.0 - u) + b * u;
    Rotation::try_new(q, 1e-12).unwrap_or(*a)
}

/// The blade button's bits for `engaged`.
pub(crate) fn buttons(engaged: bool) -> u32 {
    if engaged { BUTTON_BLADE } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vector3;

    fn at(t_ms: f64, x: f64) -> Keyed {
        Keyed {
            t_ms,
            pose: ToolPose {
                tip_in_world: Point3::new(x, 0.0, 0.0),
                ..ToolPose::default()
            },
        }
    }

    #[test]
    fn slerp_takes_the_short_way_and_a_held_button_holds() {
        let a = ToolPose {
            buttons: BUTTON_BLADE,
            ..ToolPose::default()
        };
        let quarter = Rotation::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        // the same rotation with the quaternion's sign flipped: still the short way
        let b = ToolPose {
            world_from_tool: Rotation::new_unchecked(-quarter.into_inner()),
            tip_in_world: Point3::new(1.0, 0.0, 0.0),
            buttons: 0,
        };
        let mid = interpolate(&a, &b, 0.5);
        assert!((mid.world_from_tool.angle() - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(mid.tip_in_world, Point3::new(0.5, 0.0, 0.0));
        assert_eq!(mid.buttons, BUTTON_BLADE);
        assert_eq!(interpolate(&a, &b, 0.0), a);
        // pressed: engaged on the way down from the sample before the press
        let down = interpolate(&b, &a, 0.25);
        assert_eq!(down.buttons, BUTTON_BLADE);
        assert_eq!(interpolate(&b, &a, 0.0).buttons, 0);
    }

    #[test]
    fn the_cursor_never_moves_back_and_holds_at_the_newest() {
        let mut line = Timeline::new(8, 30.0, 100.0);
        line.push(at(1000.0, 0.0));
        line.push(at(1010.0, 1.0));
        // anchored at the newest: 30 ms behind it
        assert_eq!(
            line.advance(0.0, true),
            Advance {
                reanchored: false,
                held: false
            }
        );
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(0.0));
        line.advance(25.0, false);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(0.5));
        // past the newest: held there
        let a = line.advance(45.0, false);
        assert!(a.held);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(1.0));
        // a late sample re-anchors; the cursor does not go back to before 1010
        line.push(at(1020.0, 2.0));
        let a = line.advance(46.0, true);
        assert!(a.reanchored && !a.held);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(1.0));
        // then plays on 30 ms behind the newest
        line.advance(46.0 + 25.0, false);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(1.5));
    }
}
