//! [`PoseTrack`]: timed poses played back, interpolated between samples; what a trajectory
//! file ([`super::CsvDevice`]) and a person's hand on a stylus ([`super::StylusHand`]) play.

use crate::{Point3, ToolPose};

/// Poses at increasing times: the position interpolated linearly between samples, the
/// orientation by spherical interpolation, the buttons the earlier sample's; before the first
/// sample the first pose holds, after the last the last.
#[derive(Debug, Clone)]
pub struct PoseTrack {
    times_s: Vec<f64>,
    poses: Vec<ToolPose>,
    cursor: usize,
}

impl PoseTrack {
    /// The track of `poses` at `times_s` (as many, at least one, times strictly increasing
    /// and finite: the caller's to check).
    pub(crate) fn new(times_s: Vec<f64>, poses: Vec<ToolPose>) -> Self {
        debug_assert!(!poses.is_empty() && times_s.len() == poses.len());
        Self {
            times_s,
            poses,
            cursor: 0,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// Whether it holds no sample (never: a track has at least one).
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// Time of the last sample, s.
    pub fn duration_s(&self) -> f64 {
        self.times_s.last().copied().unwrap_or(0.0)
    }

    /// The interpolated pose at `time_s` (moves the cursor; O(1) for increasing times).
    pub fn pose_at(&mut self, time_s: f64) -> ToolPose {
        let n = self.poses.len();
        if time_s <= self.times_s[0] {
            self.cursor = 0;
            return self.poses[0];
        }
        if time_s >= self.times_s[n - 1] {
            return self.poses[n - 1];
        }
        if self.times_s[self.cursor] > time_s {
            self.cursor = 0;
        }
        while self.cursor + 1 < n && self.times_s[self.cursor + 1] <= time_s {
            self.cursor += 1;
        }
        let (a, b) = (self.poses[self.cursor], self.poses[self.cursor + 1]);
        let u = (time_s - self.times_s[self.cursor])
            / (self.times_s[self.cursor + 1] - self.times_s[self.cursor]);
        let mut tip = a.tip_in_world + (b.tip_in_world - a.tip_in_world) * u;
        if !tip.iter().all(|c| c.is_finite()) {
            // a step between two finite samples that overflows (coordinates of opposite
            // signs near f64::MAX): the convex form, else the nearer sample
            tip = Point3::from(a.tip_in_world.coords * (1.0 - u) + b.tip_in_world.coords * u);
            if !tip.iter().all(|c| c.is_finite()) {
                tip = if u < 0.5 {
                    a.tip_in_world
                } else {
                    b.tip_in_world
                };
            }
        }
        let rotation = a
            .world_from_tool
            .try_slerp(&b.world_from_tool, u, 1e-9)
            .unwrap_or(a.world_from_tool);
        ToolPose {
            tip_in_world: tip,
            world_from_tool: rotation,
            buttons: a.buttons,
        }
    }
}
