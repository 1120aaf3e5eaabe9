//! The incision's plan read from TOML or JSON, and the built-in ones ([`IncisionPlan`] itself
//! is [`crate::incision_plan`]: the metrics read it, below the exercise kinds).

use crate::error::Result;
use crate::exercise::ExercisePlan;
use crate::incision_plan::IncisionPlan;

/// The built-in `chest-wall-incision` plan (TOML, embedded).
pub const CHEST_WALL_PLAN_TOML: &str = include_str!("../../../examples/plan.toml");

/// The built-in `body-wall-incision` plan (TOML, embedded): a curved 100 mm incision on the
/// CT's body wall.
pub const BODY_WALL_PLAN_TOML: &str = include_str!("../../../examples/body-wall-plan.toml");

impl IncisionPlan {
    /// Parses TOML (an untagged plan or one of kind `incision`).
    pub fn from_toml(text: &str) -> Result<Self> {
        ExercisePlan::from_toml(text)?.into_incision()
    }

    /// Parses JSON (an untagged plan or one of kind `incision`).
    pub fn from_json(text: &str) -> Result<Self> {
        ExercisePlan::from_json(text)?.into_incision()
    }

    /// The built-in plan of `chest-wall-incision`.
    pub fn chest_wall() -> Result<Self> {
        Self::from_toml(CHEST_WALL_PLAN_TOML)
    }

    /// The built-in plan of `body-wall-incision`.
    pub fn body_wall() -> Result<Self> {
        Self::from_toml(BODY_WALL_PLAN_TOML)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;

    use super::*;
    use crate::error::ScoreError;

    #[test]
    fn the_builtin_plan_parses_and_is_60_mm_long() {
        let plan = IncisionPlan::chest_wall().unwrap();
        assert!(
            (plan.length_m() - 0.060).abs() < 1e-3,
            "{}",
            plan.length_m()
        );
        assert!((plan.depth_m - 0.008).abs() < 1e-12);
        assert!((plan.tolerance_m - 0.002).abs() < 1e-12);
        assert!(!plan.target_m.is_empty());
        assert_eq!(plan.approach(), [0.0, 0.0, -1.0]);
    }

    #[test]
    fn the_builtin_target_is_what_its_incision_lays_open() {
        // the points in plan.toml are the rule's: the middle third, half the depth down
        let plan = IncisionPlan::chest_wall().unwrap();
        let rule = plan.mid_depth_targets(plan.target_m.len());
        assert_eq!(rule.len(), plan.target_m.len());
        for (a, b) in plan.target_m.iter().zip(&rule) {
            assert!(
                (Point3::from(*a) - Point3::from(*b)).norm() < 1e-6,
                "{a:?} vs {b:?}"
            );
        }
        for t in &plan.target_m {
            let depth = crate::metrics::incision::depth_below_plan(&plan, *t);
            assert!(depth > 0.0 && depth <= plan.depth_m, "{depth}");
        }
    }

    #[test]
    fn json_round_trip_and_defaults() {
        let text =
            r#"{"entry_m":[0,0,0],"exit_m":[0.05,0,0],"depth_m":0.005,"viewpoint_m":[0,0,0.1]}"#;
        let plan = IncisionPlan::from_json(text).unwrap();
        assert_eq!(plan.incision_m.len(), 2);
        assert!((plan.tolerance_m - 0.002).abs() < 1e-15);
        let back = IncisionPlan::from_json(&serde_json::to_string(&plan).unwrap()).unwrap();
        assert_eq!(back, plan);
    }

    #[test]
    fn degenerate_and_nan_plans_are_rejected_with_a_reason() {
        let ok =
            r#"{"entry_m":[0,0,0],"exit_m":[0.05,0,0],"depth_m":0.005,"viewpoint_m":[0,0,0.1]}"#;
        assert!(IncisionPlan::from_json(ok).is_ok());
        let short = ok.replace("0.05,0,0", "0.0001,0,0");
        assert!(
            IncisionPlan::from_json(&short)
                .unwrap_err()
                .to_string()
                .contains("shorter than 1 mm")
        );
        let no_depth = ok.replace("\"depth_m\":0.005", "\"depth_m\":0");
        assert!(
            IncisionPlan::from_json(&no_depth)
                .unwrap_err()
                .to_string()
                .contains("depth_m")
        );
        let mut plan = IncisionPlan::from_json(ok).unwrap();
        plan.exit_m[1] = f64::NAN;
        assert!(plan.check().unwrap_err().to_string().contains("not finite"));
        let typo = ok.replace("depth_m", "depht_m");
        assert!(matches!(
            IncisionPlan::from_json(&typo),
            Err(ScoreError::Parse { .. })
        ));
    }
}
