//! Tissue handling measured on really held gauze: the synthetic expert cuts 40 mm across the
//! pad while a second hand's grasper holds it beside the line and draws it, away from the
//! line and up, or towards the line. The session is recorded, read back and assessed as any
//! attempt is; the handling metrics say which hand gave countertraction.

use cutlab_haptics::device::{GraspPlan, GrasperHand, Skill, SyntheticTrainee};
use cutlab_haptics::stepper::StepperStats;
use cutlab_haptics::{Hands, Session, SessionConfig, Vector3};
use cutlab_recorder::Recording;
use cutlab_recorder::record::{self, Provenance, RecordSettings};
use cutlab_scoring::metrics::value_of;
use cutlab_scoring::{AttemptData, ExercisePlan, MetricSet, attempt_data};
use cutlab_sim::scene::{BuildOptions, Scene};

/// The expert across the gauze with a grasper taking hold `beside_m` from the line's middle
/// (+y) and drawing it by `pull_m`, recorded and assessed against an incision plan along the
/// line: the stats, the attempt's data and its metrics, and the plan.
fn two_hands(
    beside_m: f64,
    pull_m: Vector3,
) -> (StepperStats, AttemptData, MetricSet, ExercisePlan) {
    let scene = Scene::load("gauze", BuildOptions::default()).expect("scene");
    let session = Session::new(&scene).expect("session");
    let plan = session.plan_across_top(0.04, 0.0015).expect("plan");
    let preset = Skill::preset("expert").expect("preset");
    let scalpel = Box::new(SyntheticTrainee::new("expert", plan.clone(), preset, 3).expect("hand"));
    let middle = plan.line_m[plan.line_m.len() / 2];
    let grasp = GraspPlan {
        hold_m: middle + Vector3::new(0.0, beside_m, 0.0),
        pull_m,
        up: Vector3::z(),
        release_s: Some(4.6),
    };
    let grasper = Box::new(GrasperHand::new(grasp, 3).expect("grasper"));
    let config = SessionConfig {
        duration_s: 5.0,
        ..SessionConfig::default()
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("session.mcap");
    let provenance = Provenance {
        scene: "gauze".into(),
        min_tets: None,
        seed: 3,
        trainee: "t".into(),
        exercise: "e".into(),
        device: "expert".into(),
    };
    let r = record::run_recorded(
        session,
        Hands {
            scalpel,
            grasper: Some(grasper),
        },
        &config,
        &provenance,
        Some(&plan),
        &scene.spec,
        &path,
        RecordSettings::default(),
        None,
    )
    .expect("recorded session");
    let stats = r.report.expect("session ran").stats;
    let (first, last) = (plan.line_m[0], plan.line_m[plan.line_m.len() - 1]);
    let toml = format!(
        "entry_m = [{}, {}, {}]\nexit_m = [{}, {}, {}]\ndepth_m = 0.0015\nviewpoint_m = [0.05, 0.05, 0.15]\n",
        first.x, first.y, first.z, last.x, last.y, last.z
    );
    let exercise = ExercisePlan::from_toml(&toml).expect("plan");
    let rec = Recording::open(&path).expect("readable");
    let data = attempt_data(&rec, &exercise).expect("attempt data");
    let metrics = exercise.assess(&data).expect("assessed");
    (stats, data, metrics, exercise)
}

#[test]
fn countertraction_is_told_apart_from_slack_on_a_held_gauze() {
    // 8 mm beside the line, drawn 4 mm further away and 4 mm up
    let (stats, data, away, exercise) = two_hands(0.008, Vector3::new(0.0, 0.004, 0.004));
    let get = |m: &MetricSet, k: &str| value_of(m, k).unwrap_or_else(|| panic!("{k}: {m:?}"));
    assert_eq!(stats.grasps, 1, "{stats:?}");
    assert_eq!(get(&away, "grasps"), 1.0);
    assert_eq!(get(&away, "grasp_slips"), 0.0);
    // the recorded pull is the one the simulation felt
    let peak = get(&away, "peak_traction_n");
    assert!(
        (peak - stats.max_grasp_pull_newtons).abs() <= 0.02 * stats.max_grasp_pull_newtons,
        "{peak} N recorded, {} N simulated",
        stats.max_grasp_pull_newtons
    );
    assert!(get(&away, "mean_traction_n") > 0.0 && get(&away, "mean_traction_n") <= peak);
    // the expert starts cutting while the grasper is still drawing (1.2-2.2 s): two thirds
    // of the cutting time with the tissue drawn at least 1 mm
    assert!(get(&away, "countertraction_fraction") > 0.5, "{away:?}");
    assert!(get(&away, "traction_alignment") > 0.5, "{away:?}");
    // from its closing: it drew the pad 5.7 mm, held, and lifted away
    assert!(get(&away, "grasper_path_length_m") > 0.005, "{away:?}");
    assert!(value_of(&away, "bimanual_path_ratio").is_some(), "{away:?}");
    // the same attempt without its second hand has no handling metrics
    let one_hand = exercise
        .assess(&AttemptData {
            grasper: Vec::new(),
            ..data
        })
        .expect("assessed");
    assert!(one_hand.iter().all(|m| m.key != "grasps"), "{one_hand:?}");

    // 12 mm beside the line, drawn 4 mm towards it: slack where the blade cuts
    let (_, _, towards, _) = two_hands(0.012, Vector3::new(0.0, -0.004, 0.0));
    println!(
        "countertraction {:.2} / {:.2}, direction {:.2} / {:.2} (away / towards)",
        get(&away, "countertraction_fraction"),
        get(&towards, "countertraction_fraction"),
        get(&away, "traction_alignment"),
        get(&towards, "traction_alignment")
    );
    assert!(
        get(&towards, "countertraction_fraction") < 0.2,
        "{towards:?}"
    );
    assert!(get(&towards, "traction_alignment") < -0.3, "{towards:?}");
}
