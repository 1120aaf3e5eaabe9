//! The samples the device has taken, on the session's clock: where the page clock is anchored,
//! where the playback cursor is, and the pose there.

use std::collections::VecDeque;

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
    /// The session time of the last tick, ms.
    last_time_ms: Option<f64>,
    /// The session time of the last tick samples arrived at, ms.
    last_arrival_ms: Option<f64>,
    /// How much the cursor keeps buffered: the delay, or the last gap between arrivals and
    /// the delay when that is more (a page that sends seldom or in bursts), shrinking back
    /// at [`CATCH_UP`] per ms, ms.
    target_ms: f64,
    /// Latency beyond the target at the last arrival, still to drain, ms.
    excess_ms: f64,
}

/// How much faster than the page the cursor plays while it drains latency beyond the
/// buffer's target (grown when the buffer ran dry and play went on from the held pose), and
/// how fast the target shrinks back to the delay: 0.05 drains 50 ms a second, and moves the
/// blade 5 % faster than the hand meanwhile.
pub(crate) const CATCH_UP: f64 = 0.05;
/// Latency beyond the buffer's target that starts a drain, ms.
const DRAIN_FROM_MS: f64 = 10.0;

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
            last_time_ms: None,
            last_arrival_ms: None,
            target_ms: delay_ms,
            excess_ms: 0.0,
        }
    }

    /// Forgets the samples and the clock mapping (the allocation is kept): the next sample
    /// anchors the page clock anew, as the first did. The pose stays where it was until then.
    pub fn restart(&mut self) {
        self.samples.clear();
        self.offset_ms = None;
        self.cursor_ms = f64::NEG_INFINITY;
        self.dry = false;
        self.last_time_ms = None;
        self.last_arrival_ms = None;
        self.target_ms = self.delay_ms;
        self.excess_ms = 0.0;
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
    /// The page clock is anchored so the newest sample plays `delay_ms` from now at the first
    /// sample, and again when the newest sample is more than `max_lag_ms` ahead of the cursor
    /// (the page's clock runs fast, or it sent a long stall's worth at once): the cursor
    /// skips forward. Otherwise play is continuous: the cursor keeps a buffer of the delay, or
    /// of the last gap between arrivals and the delay when that is more (a page that sends
    /// seldom or in bursts), so it does not run dry between arrivals; when it does run dry
    /// (a longer gap than the last), play goes on from the held pose when samples come again,
    /// the latency grown by the gap; and while more than the buffer's target is buffered the
    /// cursor plays [`CATCH_UP`] faster than the page. (Skipping forward at each burst moved
    /// the blade a burst's way in one tick, and the cutting resistance, a function of its
    /// speed, flipped between 0 and its full value.) The cursor never moves back.
    pub fn advance(&mut self, time_ms: f64, arrived: bool) -> Advance {
        let mut out = Advance {
            reanchored: false,
            held: false,
        };
        let Some(newest_ms) = self.newest_ms() else {
            return out;
        };
        let dt_ms = self.last_time_ms.map_or(0.0, |l| (time_ms - l).max(0.0));
        self.last_time_ms = Some(time_ms);
        self.target_ms = (self.target_ms - CATCH_UP * dt_ms).max(self.delay_ms);
        if arrived {
            if let Some(last) = self.last_arrival_ms {
                self.target_ms = self.target_ms.max(time_ms - last + self.delay_ms);
            }
            self.last_arrival_ms = Some(time_ms);
        }
        let offset_ms = match self.offset_ms {
            None => newest_ms - time_ms,
            Some(offset_ms) => {
                let natural_ms = time_ms + offset_ms - self.delay_ms;
                let buffered_ms = newest_ms - natural_ms;
                if arrived && buffered_ms > self.max_lag_ms {
                    out.reanchored = true;
                    self.skip_to_ms(newest_ms) - time_ms + self.delay_ms
                } else if arrived && self.dry {
                    out.reanchored = true;
                    self.cursor_ms - time_ms + self.delay_ms
                } else {
                    // more than the target buffered when samples came: a little faster until
                    // that much is drained (measured at arrivals only, so the rate changes
                    // once a drain, not at every arrival)
                    if arrived {
                        let excess_ms = buffered_ms - self.target_ms;
                        // a drain starts only past a few ms (a page's jitter is not one)
                        self.excess_ms = if excess_ms > DRAIN_FROM_MS {
                            excess_ms
                        } else {
                            self.excess_ms.min(excess_ms.max(0.0))
                        };
                    }
                    let step_ms = (CATCH_UP * dt_ms).min(self.excess_ms);
                    self.excess_ms -= step_ms;
                    offset_ms + step_ms
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

    /// Where a forward skip takes the cursor (page ms): `delay_ms` behind the newest sample,
    /// or the first sample ahead of the cursor whose buttons differ from those at the cursor
    /// when that comes sooner. A skip never passes a press or a release: the tick plays the
    /// sample that changed them, exactly (a grasper closes where its hand closed it, a blade
    /// engages where it was pressed), and the next arrival skips on from there.
    fn skip_to_ms(&self, newest_ms: f64) -> f64 {
        let to_ms = newest_ms - self.delay_ms;
        let mut held = None;
        for k in &self.samples {
            if k.t_ms <= self.cursor_ms {
                held = Some(k.pose.buttons);
            } else if k.t_ms >= to_ms {
                break;
            } else if held.is_some_and(|b| b != k.pose.buttons) {
                return k.t_ms;
            } else {
                held = Some(k.pose.buttons);
            }
        }
        to_ms
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vector3;
    use crate::pose::BUTTON_BLADE;

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
        // a late sample re-anchors; play goes on from the held pose, not skipping forward
        line.push(at(1020.0, 2.0));
        let a = line.advance(46.0, true);
        assert!(a.reanchored && !a.held);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(1.0));
        // 5 ms later, 5 ms on (less than the delay buffered: no catch-up)
        line.advance(51.0, false);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(1.5));
    }

    /// A page stalled for 600 ms sends what it took meanwhile at once, a press among it: the
    /// cursor skips forward, but only as far as the press, which it plays exactly (where the
    /// hand pressed, pressed); the next arrival skips on to the newest.
    #[test]
    fn a_skip_forward_stops_at_a_press() {
        let mut line = Timeline::new(256, 30.0, 300.0);
        line.push(at(1000.0, 0.0));
        line.advance(0.0, true);
        for (k, tick) in (1..=30).zip(1u32..) {
            line.advance(f64::from(tick), false);
            assert_eq!(line.pose().map(|p| p.buttons), Some(0), "tick {k}");
        }
        // the burst: pressed from 1205 ms on
        for t in (1010..=1600).step_by(5) {
            let mut k = at(f64::from(t), f64::from(t - 1000));
            k.pose.buttons = if t >= 1205 { BUTTON_BLADE } else { 0 };
            line.push(k);
        }
        let a = line.advance(31.0, true);
        assert!(a.reanchored);
        let pose = line.pose().expect("a pose");
        assert_eq!((pose.tip_in_world.x, pose.buttons), (205.0, BUTTON_BLADE));
        // a tick without samples plays on from the press
        line.advance(32.0, false);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(206.0));
        // the next arrival, still more than the largest lag ahead, skips on to the delay
        // behind the newest
        line.push(at(1605.0, 605.0));
        line.advance(33.0, true);
        assert_eq!(line.pose().map(|p| p.tip_in_world.x), Some(575.0));
    }

    /// A page a slow machine holds back to 7 samples a second: once settled, the cursor plays
    /// at the page's own pace at every tick, never held and never hurried (each hold or
    /// catch-up would bend the tool's course between the hand's samples).
    #[test]
    fn a_seldom_page_plays_at_one_pace() {
        let mut line = Timeline::new(64, 30.0, 300.0);
        let gap = 1000.0 / 7.0;
        let (mut next, mut last) = (0.0f64, None::<f64>);
        let mut steps = Vec::new();
        for tick in 0..10_000u32 {
            let now = f64::from(tick);
            let arrived = next <= now;
            if arrived {
                line.push(at(1000.0 + next, next));
                next += gap;
            }
            line.advance(now, arrived);
            if let Some(l) = last
                && tick > 3000
            {
                steps.push(line.cursor_ms - l);
            }
            last = Some(line.cursor_ms);
        }
        let (lo, hi) = steps
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), s| (a.min(*s), b.max(*s)));
        assert!(hi - lo < 1e-9, "the cursor's step per tick: {lo}..{hi} ms");
    }

    /// A page whose samples (every 16 ms) arrive in bursts of six every 96 ms: the blade moves
    /// on at every tick without jumps, and the latency settles under the burst's length.
    #[test]
    fn samples_in_bursts_play_smoothly() {
        let mut line = Timeline::new(64, 30.0, 300.0);
        let (mut last_x, mut biggest_step) = (None::<f64>, 0.0f64);
        let speed = 0.01; // per ms: 10 m/s in x units of the test
        for tick in 0..3000u32 {
            let now = f64::from(tick);
            // a burst at every 96 ms holds the samples the page took since the last one
            let arrived = tick % 96 == 0;
            if arrived {
                let from = (now - 96.0).max(0.0);
                let mut t = (from / 16.0).ceil() * 16.0;
                while t <= now {
                    if line.newest_ms().is_none_or(|n| 1000.0 + t > n) {
                        line.push(at(1000.0 + t, speed * t));
                    }
                    t += 16.0;
                }
            }
            line.advance(now, arrived);
            let x = line.pose().map_or(0.0, |p| p.tip_in_world.x);
            if let Some(l) = last_x
                && tick > 200
            {
                biggest_step = biggest_step.max(x - l);
            }
            last_x = Some(x);
        }
        // one tick's step at the page's speed, 5 % faster while catching up: never a skip
        assert!(
            biggest_step <= speed * (1.0 + CATCH_UP) + 1e-9,
            "the largest step in a tick: {biggest_step}"
        );
        let lag_ms = 1000.0 + 2999.0 - line.cursor_ms;
        assert!(lag_ms < 96.0 + 30.0 + 16.0, "the latency: {lag_ms} ms");
    }
}
