//! The incision's plan: what the optimal incision looks like (SI units: metres). Parsed, and
//! the built-in plans, in [`crate::exercise::incision`].

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Result, ScoreError};
use crate::geom;

/// The plan an attempt is measured against (SI units: metres).
///
/// The incision is the polyline `incision_m` on the tissue surface from `entry_m` to `exit_m`,
/// cut `depth_m` deep along `-normal`. Lateral distances are measured "seen from above": after
/// projecting along `normal` onto a plane (see [`crate::metrics::incision`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IncisionPlan {
    /// A name for reports.
    #[serde(default)]
    pub name: String,
    /// The scene the plan is for (e.g. `chest-wall`), informative.
    #[serde(default)]
    pub scene: Option<String>,
    /// Where the incision starts, on the surface (m).
    pub entry_m: [f64; 3],
    /// Where it ends, on the surface (m).
    pub exit_m: [f64; 3],
    /// The planned line on the surface from entry to exit (m), at least 2 points. Empty means
    /// the straight segment `[entry_m, exit_m]`.
    #[serde(default)]
    pub incision_m: Vec<[f64; 3]>,
    /// The planned depth below the surface (m), > 0.
    pub depth_m: f64,
    /// The surface's outward normal at the incision (unit after normalisation; default +z).
    #[serde(default = "default_normal")]
    pub normal: [f64; 3],
    /// The direction the blade moves as it enters the tissue (default `-normal`).
    #[serde(default)]
    pub approach_dir: Option<[f64; 3]>,
    /// Points on the target that must become visible through the opening (m); may be empty
    /// (then the visibility metric is missing). What the planned incision lays open: no deeper
    /// below the planned line than `depth_m` (a target beyond it, tissue the planned cut does
    /// not reach, could only be seen after cutting deeper than planned, so the visibility
    /// metric is missing then too); [`IncisionPlan::mid_depth_targets`] are such points.
    #[serde(default)]
    pub target_m: Vec<[f64; 3]>,
    /// Where the target is seen from (m).
    pub viewpoint_m: [f64; 3],
    /// How far from the planned line still counts as on it (m), default 2 mm.
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
    /// Half the width of the corridor cuts may stay in without damage (m), default 5 mm.
    #[serde(default = "default_corridor")]
    pub corridor_half_width_m: f64,
    /// The force the tissue should not be loaded beyond (N), default 2.5 N.
    #[serde(default = "default_force_limit")]
    pub force_limit_n: f64,
}

fn default_normal() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}
fn default_tolerance() -> f64 {
    0.002
}
fn default_corridor() -> f64 {
    0.005
}
fn default_force_limit() -> f64 {
    2.5
}

impl IncisionPlan {
    /// Fills the defaults that depend on other fields (the polyline, the approach), normalises
    /// the direction vectors and checks the result.
    pub fn normalised(mut self) -> Result<Self> {
        if self.incision_m.is_empty() {
            self.incision_m = vec![self.entry_m, self.exit_m];
        }
        self.check()?;
        let normal = geom::unit(self.normal.into())
            .ok_or_else(|| ScoreError::InvalidPlan("zero normal".into()))?;
        self.normal = normal.into();
        let approach = self.approach_dir.map_or(-normal, Vector3::from);
        self.approach_dir = Some(
            geom::unit(approach)
                .ok_or_else(|| ScoreError::InvalidPlan("zero approach direction".into()))?
                .into(),
        );
        Ok(self)
    }

    /// Rejects plans that cannot be assessed against: non-finite numbers, fewer than 2 line
    /// points, a line shorter than 1 mm, a zero normal, non-positive depth, tolerance,
    /// corridor or force limit.
    pub fn check(&self) -> Result<()> {
        let bad = |m: &str| Err(ScoreError::InvalidPlan(m.into()));
        let mut numbers: Vec<f64> = Vec::new();
        for v in [self.entry_m, self.exit_m, self.normal, self.viewpoint_m]
            .iter()
            .chain(self.approach_dir.iter())
            .chain(&self.incision_m)
            .chain(&self.target_m)
        {
            numbers.extend_from_slice(v);
        }
        numbers.extend([
            self.depth_m,
            self.tolerance_m,
            self.corridor_half_width_m,
            self.force_limit_n,
        ]);
        if !geom::finite(&numbers) {
            return bad("a number is not finite (NaN or infinite)");
        }
        if self.incision_m.len() < 2 {
            return bad("the incision line needs at least 2 points");
        }
        if geom::polyline_length(&self.line()) < 1e-3 {
            return bad("the incision line is shorter than 1 mm");
        }
        if geom::unit(self.normal.into()).is_none() {
            return bad("the normal is zero");
        }
        if self
            .approach_dir
            .is_some_and(|a| geom::unit(a.into()).is_none())
        {
            return bad("the approach direction is zero");
        }
        if !(self.depth_m > 0.0) {
            return bad("depth_m must be > 0");
        }
        if !(self.tolerance_m > 0.0) {
            return bad("tolerance_m must be > 0");
        }
        if !(self.corridor_half_width_m > 0.0) {
            return bad("corridor_half_width_m must be > 0");
        }
        if !(self.force_limit_n > 0.0) {
            return bad("force_limit_n must be > 0");
        }
        Ok(())
    }

    /// The planned incision's length along its polyline (m).
    pub fn length_m(&self) -> f64 {
        geom::polyline_length(&self.line())
    }

    /// The planned line `incision_m` as points.
    pub(crate) fn line(&self) -> Vec<Point3<f64>> {
        self.incision_m.iter().map(|&p| Point3::from(p)).collect()
    }

    /// `count` points (at least 1) evenly along the middle third of the planned line, half the
    /// planned depth below it along `-normal`: what a cut of the planned depth lays open in
    /// the middle of the incision, seen from above (the built-in plans' targets).
    pub fn mid_depth_targets(&self, count: usize) -> Vec<[f64; 3]> {
        let line = self.line();
        let length = geom::polyline_length(&line);
        let down = -Vector3::from(self.normal) * (0.5 * self.depth_m);
        let count = count.max(1);
        (0..count)
            .map(|k| {
                let u = if count == 1 {
                    0.5
                } else {
                    1.0 / 3.0 + k as f64 / (3 * (count - 1)) as f64
                };
                (geom::point_at_arc(&line, u * length).0 + down).into()
            })
            .collect()
    }

    /// The approach direction (unit), `-normal` unless given.
    pub fn approach(&self) -> [f64; 3] {
        self.approach_dir
            .and_then(|a| geom::unit(a.into()))
            .unwrap_or(-Vector3::from(self.normal))
            .into()
    }
}
