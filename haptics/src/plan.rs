//! What the hand follows, planned on the tissue ([`Plan`]): the line to cut, its normals, the
//! depth, the viewpoint. One type for the synthetic trainees, the scripted hands, the pointer
//! device, the recording (`plan.json`, its serde form: points as `[x, y, z]` in metres) and
//! the station's page.

use serde::{Deserialize, Serialize};

use crate::{HapticsError, Point3, Vector3};

/// What the hand follows: the incision line on the tissue surface and how to cut it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Points of the planned line on the surface, entry first, exit last (at least two).
    pub line_m: Vec<Point3>,
    /// Outward surface normal at each point of `line_m` (unit).
    pub normals: Vec<Vector3>,
    /// Depth of the blade's tip below the surface while cutting, m.
    pub depth_m: f64,
    /// Height above the entry point where the hand starts and ends, m.
    pub approach_height_m: f64,
    /// Where the exercise views the surgical field from (the expert plan's eye), m; a review
    /// of the cut looks from there. `None` when the plan names none (and in recordings made
    /// before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viewpoint_m: Option<Point3>,
}

impl Plan {
    /// A 60 mm line along x on the plane z = 0, `depth_m` deep: the devices' tests' plan.
    #[cfg(test)]
    pub(crate) fn flat_across_x(depth_m: f64) -> Self {
        Self {
            line_m: vec![Point3::new(-0.03, 0.0, 0.0), Point3::new(0.03, 0.0, 0.0)],
            normals: vec![Vector3::z(); 2],
            depth_m,
            approach_height_m: 0.015,
            viewpoint_m: None,
        }
    }

    /// Checks the plan's numbers.
    pub fn check(&self) -> Result<(), HapticsError> {
        let bad = |m: &str| Err(HapticsError::Config(format!("plan: {m}")));
        if self.line_m.len() < 2 || self.line_m.len() != self.normals.len() {
            return bad("needs at least two line points, each with a normal");
        }
        if !self.line_m.iter().all(|p| p.iter().all(|c| c.is_finite()))
            || !self
                .normals
                .iter()
                .all(|n| n.iter().all(|c| c.is_finite()) && (n.norm() - 1.0).abs() < 1e-6)
        {
            return bad("line points must be finite and normals unit vectors");
        }
        if !(self.depth_m >= 0.0
            && self.depth_m < 0.1
            && self.approach_height_m > 0.0
            && self.approach_height_m < 1.0)
        {
            return bad("depth must be in [0, 0.1) m and approach height in (0, 1) m");
        }
        if self.length_m() < 1e-4 {
            return bad("the line is shorter than 0.1 mm");
        }
        if self
            .viewpoint_m
            .is_some_and(|v| !v.iter().all(|c| c.is_finite()))
        {
            return bad("the viewpoint must be finite");
        }
        Ok(())
    }

    /// Length of the planned line, m.
    pub fn length_m(&self) -> f64 {
        self.line_m.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The viewpoint goes through the JSON; a plan recorded before it was kept reads back
    /// without one, and the points are `[x, y, z]` arrays as the recordings have always held.
    #[test]
    fn the_plan_keeps_its_viewpoint_and_old_plans_still_read() {
        let plan = Plan {
            line_m: vec![Point3::new(-0.03, 0.0, 0.0), Point3::new(0.03, 0.0, 0.0)],
            normals: vec![Vector3::z(); 2],
            depth_m: 0.008,
            approach_height_m: 0.015,
            viewpoint_m: Some(Point3::new(0.0, 0.01, 0.15)),
        };
        let json = serde_json::to_string(&plan).expect("json");
        assert!(
            json.contains(r#""line_m":[[-0.03,0.0,0.0],[0.03,0.0,0.0]]"#),
            "{json}"
        );
        let back: Plan = serde_json::from_str(&json).expect("read back");
        assert_eq!(back, plan);
        let old = r#"{"line_m":[[0,0,0],[0.06,0,0]],"normals":[[0,0,1],[0,0,1]],
            "depth_m":0.008,"approach_height_m":0.015}"#;
        let old: Plan = serde_json::from_str(old).expect("an old plan");
        assert_eq!(old.viewpoint_m, None);
        assert_eq!(old.line_m[1], Point3::new(0.06, 0.0, 0.0));
        let unplaced = Plan {
            viewpoint_m: None,
            ..plan
        };
        assert!(
            !serde_json::to_string(&unplaced)
                .expect("json")
                .contains("viewpoint")
        );
    }
}
