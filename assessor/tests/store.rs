//! The store on a fresh database per test, each test twice: on SQLite (`name::sqlite`) and
//! on PostgreSQL (`name::postgres`, on the server `$CUTLAB_TEST_POSTGRES` names; CI starts
//! one).

use cutlab_assessor::store::CUTTING_BASICS;
use cutlab_assessor::store::{Access, AttemptStatus, BODY_WALL_EXERCISE, BUILTIN_EXERCISE};
use cutlab_assessor::store::{DbLocation, test_postgres};
use cutlab_assessor::store::{EXCISION_EXERCISE, FIELD_EXERCISE};
use cutlab_assessor::store::{NewExercise, PATTERN_EXERCISE, Role, ThresholdSource};
use cutlab_assessor::{AssessError, Store, on_db};
use cutlab_scoring::metrics::{METRICS, MetricValue};
use cutlab_scoring::proficiency::{CusumParams, Threshold, Thresholds, cusum};
use cutlab_scoring::{Better, ExercisePlan, IncisionPlan};

/// A fresh SQLite database in a temporary folder (kept alive by the returned guard).
async fn sqlite_store() -> (Store, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let store = Store::open(&dir.path().join("cutlab.db"))
        .await
        .expect("store");
    (store, dir)
}

/// A fresh database on the PostgreSQL server of `$CUTLAB_TEST_POSTGRES`; `None` (saying
/// so) without one.
async fn postgres_location() -> Option<DbLocation> {
    test_postgres("cutlab_store_test").await
}

/// `name::sqlite` and `name::postgres`: the test `name(store)` on a fresh database of each.
macro_rules! on_both {
    ($name:ident) => {
        mod $name {
            #[tokio::test]
            async fn sqlite() {
                let (store, _dir) = super::sqlite_store().await;
                super::$name(store).await;
            }

            #[tokio::test]
            async fn postgres() {
                if let Some(at) = super::postgres_location().await {
                    let store = cutlab_assessor::Store::open(&at).await.expect("store");
                    super::$name(store).await;
                }
            }
        }
    };
}

/// Metric values: every catalogue metric missing except the given ones.
/// Every metric of the catalogue, `pairs` given, the rest missing; the task done (the whole
/// line cut within the tolerance) unless `pairs` says otherwise.
fn values(pairs: &[(&str, f64)]) -> Vec<MetricValue> {
    METRICS
        .iter()
        .map(|m| {
            let done = (m.key == "fraction_cut_in_tolerance").then_some(1.0);
            let v = pairs
                .iter()
                .find(|(k, _)| *k == m.key)
                .map(|p| p.1)
                .or(done);
            MetricValue {
                key: m.key.into(),
                value: v,
                unit: m.unit.into(),
                better: m.better,
                scored: m.scored,
                missing: v.is_none().then(|| "test".into()),
            }
        })
        .collect()
}

async fn exercise_with_one_threshold(store: &Store) -> i64 {
    exercise_named(store, "one-metric", "").await
}

/// A chest-wall incision exercise called `name` with the one threshold `lateral_mean_m`.
async fn exercise_named(store: &Store, name: &str, description: &str) -> i64 {
    let plan = ExercisePlan::chest_wall().expect("plan");
    let t = [Threshold::fixed(
        "lateral_mean_m",
        Better::LowerIsBetter,
        0.0005,
        0.002,
    )];
    let new = NewExercise {
        name,
        scene: "chest-wall",
        description,
        plan: &plan,
        thresholds: &t,
        threshold_k: 2.0,
        exam_only: false,
    };
    store.create_exercise(&new).await.expect("exercise").id
}

/// A scored attempt of `trainee` at `exercise` with the one metric `lateral_mean_m`.
async fn scored_attempt(store: &Store, trainee: i64, exercise: i64, lateral: f64) {
    let a = store
        .start_attempt(trainee, exercise, None, false)
        .await
        .expect("start");
    store
        .finish_attempt(a.id, &values(&[("lateral_mean_m", lateral)]))
        .await
        .expect("finish");
}

on_both!(users_and_passwords);
async fn users_and_passwords(store: Store) {
    let alice = store
        .create_user("alice", Role::Trainee, Some("s3cret"))
        .await
        .expect("alice");
    assert_eq!(alice.role, Role::Trainee);
    assert!(alice.has_password);
    store
        .create_user("bob", Role::Instructor, None)
        .await
        .expect("bob");
    assert!(matches!(
        store.create_user("alice", Role::Admin, None).await,
        Err(AssessError::Conflict(_))
    ));
    assert_eq!(
        store
            .verify_password("alice", "s3cret")
            .await
            .expect("verify")
            .map(|u| u.id),
        Some(alice.id)
    );
    assert!(
        store
            .verify_password("alice", "wrong")
            .await
            .expect("verify")
            .is_none()
    );
    assert!(
        store
            .verify_password("bob", "")
            .await
            .expect("verify")
            .is_none(),
        "no password: cannot log in"
    );
    assert!(
        store
            .verify_password("nobody", "x")
            .await
            .expect("verify")
            .is_none()
    );
    // never the plain text
    let hash: String = on_db!(store.db(), pool => {
        sqlx::query_scalar("SELECT password_hash FROM users WHERE name = 'alice'")
            .fetch_one(pool)
            .await
    })
    .expect("hash");
    assert!(
        hash.starts_with("$argon2id$") && !hash.contains("s3cret"),
        "{hash}"
    );
    assert_eq!(
        store
            .list_users(Some(Role::Instructor))
            .await
            .expect("list")
            .len(),
        1
    );
    assert_eq!(store.list_users(None).await.expect("list").len(), 2);
    assert!(matches!(
        store.user_by_name("carol").await,
        Err(AssessError::NotFound(_))
    ));
}

on_both!(cohorts_and_curricula);
async fn cohorts_and_curricula(store: Store) {
    let teacher = store
        .create_user("dr-who", Role::Instructor, None)
        .await
        .expect("user");
    let t1 = store
        .create_user("t1", Role::Trainee, None)
        .await
        .expect("user");
    let t2 = store
        .create_user("t2", Role::Trainee, None)
        .await
        .expect("user");
    let c = store
        .create_cohort("2026-spring", Some(teacher.id))
        .await
        .expect("cohort");
    store.join_cohort(c.id, t2.id).await.expect("join");
    store.join_cohort(c.id, t1.id).await.expect("join");
    store
        .join_cohort(c.id, t1.id)
        .await
        .expect("joining twice is fine");
    let members: Vec<String> = store
        .cohort_members(c.id)
        .await
        .expect("members")
        .into_iter()
        .map(|u| u.name)
        .collect();
    assert_eq!(members, ["t1", "t2"]);
    assert_eq!(
        store
            .cohort_by_name("2026-spring")
            .await
            .expect("by name")
            .id,
        c.id
    );

    let builtin = store.ensure_builtins().await.expect("builtins");
    let other = exercise_with_one_threshold(&store).await;
    let cur = store
        .create_curriculum("basic incisions", "first steps")
        .await
        .expect("curriculum");
    store
        .add_module(cur.id, "straight lines", &[builtin.id, other])
        .await
        .expect("module");
    store
        .add_module(cur.id, "again", &[other])
        .await
        .expect("module");
    let modules = store.curriculum_modules(cur.id).await.expect("modules");
    assert_eq!(
        modules.iter().map(|m| m.position).collect::<Vec<_>>(),
        [1, 2]
    );
    assert_eq!(modules[0].exercise_ids, [builtin.id, other]);
    assert_eq!(
        store.get_curriculum(cur.id).await.expect("get").name,
        "basic incisions"
    );
    // the five built-in plans and the other exercise's
    assert_eq!(store.list_plans().await.expect("plans").len(), 6);
    assert!(store.add_module(cur.id, "bad", &[9999]).await.is_err());
}

on_both!(an_older_databases_cutting_basics_gains_the_new_exercises_once);
/// A database whose `cutting-basics` an older cutlab made, with only the incision, keeps its
/// module and its settings; the built-in exercises new to it join the end, once.
async fn an_older_databases_cutting_basics_gains_the_new_exercises_once(store: Store) {
    let incision = exercise_named(
        &store,
        BUILTIN_EXERCISE,
        "the incision as an older cutlab made it",
    )
    .await;
    let basics = store
        .create_curriculum(CUTTING_BASICS, "an older one")
        .await
        .expect("basics");
    store
        .add_module(basics.id, "Straight incision", &[incision])
        .await
        .expect("module");

    assert_eq!(
        store.ensure_builtins().await.expect("builtins").id,
        incision
    );
    let names = |modules: Vec<cutlab_assessor::store::Module>| -> Vec<String> {
        modules.into_iter().map(|m| m.name).collect()
    };
    let expected = [
        "Straight incision",
        "Pattern cutting",
        "Elliptical excision",
        "Curved incision on a patient",
        "Surgical field: mini-thoracotomy",
    ];
    let modules = store.curriculum_modules(basics.id).await.expect("modules");
    assert_eq!(modules[0].exercise_ids, [incision]);
    assert_eq!(names(modules), expected);
    store.ensure_builtins().await.expect("again: nothing added");
    let modules = store.curriculum_modules(basics.id).await.expect("modules");
    assert_eq!(names(modules), expected);
    let kept = store
        .curriculum_by_name(CUTTING_BASICS)
        .await
        .expect("basics");
    assert_eq!(
        (kept.description.as_str(), kept.progression),
        ("an older one", false)
    );
}

on_both!(progression_opens_each_exercise_after_the_one_before);
/// In a curriculum with progression an exercise opens when the one before it is proficient
/// (two passes in a row), or when an instructor opens it early (recorded); the built-in
/// `cutting-basics` orders the built-in exercises that way.
async fn progression_opens_each_exercise_after_the_one_before(store: Store) {
    let builtin = store.ensure_builtins().await.expect("builtins");
    let basics = store
        .curriculum_by_name(CUTTING_BASICS)
        .await
        .expect("basics");
    assert!(basics.progression);
    let order = store
        .curriculum_exercise_ids(basics.id)
        .await
        .expect("modules");
    let pattern = store
        .exercise_by_name(PATTERN_EXERCISE)
        .await
        .expect("pattern");
    let body_wall = store
        .exercise_by_name(BODY_WALL_EXERCISE)
        .await
        .expect("body wall");
    let excision = store
        .exercise_by_name(EXCISION_EXERCISE)
        .await
        .expect("excision");
    let field = store.exercise_by_name(FIELD_EXERCISE).await.expect("field");
    assert_eq!(
        order,
        [builtin.id, pattern.id, excision.id, body_wall.id, field.id]
    );
    store.ensure_builtins().await.expect("again: nothing added");
    assert_eq!(
        store.curriculum_modules(basics.id).await.expect("m").len(),
        5
    );

    // a course of our own: one-metric, then pattern cutting
    let first = exercise_with_one_threshold(&store).await;
    let course = store
        .create_curriculum("a-course", "")
        .await
        .expect("course");
    store
        .add_module(course.id, "one", &[first])
        .await
        .expect("module");
    store
        .add_module(course.id, "two", &[pattern.id])
        .await
        .expect("module");
    let t = store
        .create_user("t", Role::Trainee, None)
        .await
        .expect("t");
    let access = |e: i64| {
        let store = store.clone();
        async move { store.exercise_access(t.id, e).await.expect("access") }
    };
    // without progression nothing is locked but cutting-basics' second
    assert_eq!(access(first).await, Access::Open);
    assert!(!access(pattern.id).await.is_open());
    store
        .set_progression(course.id, true)
        .await
        .expect("progression");
    match access(pattern.id).await {
        Access::Locked { curriculum, after } => {
            assert_eq!(curriculum, "a-course");
            assert_eq!(after, "one-metric");
        }
        other => panic!("locked: {other:?}"),
    }
    assert_eq!(store.next_exercise(t.id).await.expect("next"), Some(first));
    // fail, pass: not yet; pass again: proficient in one-metric (cutting-basics still locks)
    for (k, lateral) in [0.005, 0.001, 0.0005].into_iter().enumerate() {
        scored_attempt(&store, t.id, first, lateral).await;
        assert!(!access(pattern.id).await.is_open(), "after attempt {k}");
    }
    match access(pattern.id).await {
        Access::Locked { curriculum, after } => {
            assert_eq!(
                (curriculum.as_str(), after.as_str()),
                (CUTTING_BASICS, BUILTIN_EXERCISE)
            );
        }
        other => panic!("still locked by cutting-basics: {other:?}"),
    }
    store.set_progression(basics.id, false).await.expect("off");
    assert_eq!(
        access(pattern.id).await,
        Access::Earned {
            after: "one-metric".into()
        }
    );
    assert_eq!(
        store.next_exercise(t.id).await.expect("next"),
        Some(pattern.id)
    );

    // another trainee: opened early by an instructor, not by a trainee
    let u = store
        .create_user("u", Role::Trainee, None)
        .await
        .expect("u");
    let kim = store
        .create_user("dr-kim", Role::Instructor, None)
        .await
        .expect("kim");
    let refused = store.open_early(u.id, pattern.id, t.id, "").await;
    assert!(
        matches!(refused, Err(AssessError::InvalidInput(_))),
        "{refused:?}"
    );
    assert!(
        !store
            .exercise_access(u.id, pattern.id)
            .await
            .expect("a")
            .is_open()
    );
    let o = store
        .open_early(u.id, pattern.id, kim.id, "repeat of last year")
        .await
        .expect("opened");
    assert_eq!(
        (o.opened_by.as_str(), o.reason.as_str()),
        ("dr-kim", "repeat of last year")
    );
    assert_eq!(
        store.exercise_access(u.id, pattern.id).await.expect("a"),
        Access::OpenedEarly(o.clone())
    );
    let again = store
        .open_early(u.id, pattern.id, kim.id, "twice")
        .await
        .expect("again");
    assert_eq!(again, o, "the first opening stays");
}

on_both!(the_builtin_exercise_is_there_once);
async fn the_builtin_exercise_is_there_once(store: Store) {
    let a = store.ensure_builtins().await.expect("builtins");
    let b = store.ensure_builtins().await.expect("builtins again");
    assert_eq!(a.id, b.id);
    assert_eq!(a.name, BUILTIN_EXERCISE);
    assert_eq!(a.scene, "chest-wall");
    let plan = store.exercise_plan(a.id).await.expect("plan");
    assert_eq!(plan, ExercisePlan::chest_wall().expect("plan"));
    assert!(
        !store
            .thresholds(a.id)
            .await
            .expect("thresholds")
            .metrics
            .is_empty()
    );
    // and pattern cutting, a pattern plan with its own thresholds
    let names: Vec<String> = store
        .list_exercises()
        .await
        .expect("list")
        .into_iter()
        .map(|e| e.name)
        .collect();
    assert_eq!(
        names,
        [
            BODY_WALL_EXERCISE,
            BUILTIN_EXERCISE,
            EXCISION_EXERCISE,
            FIELD_EXERCISE,
            "pattern-cutting"
        ]
        .map(String::from)
        .to_vec()
    );
    let pattern = store
        .exercise_by_name("pattern-cutting")
        .await
        .expect("pattern");
    let plan = store.exercise_plan(pattern.id).await.expect("plan");
    assert_eq!(plan.kind(), cutlab_scoring::Kind::Pattern);
    let keys: Vec<String> = store
        .thresholds(pattern.id)
        .await
        .expect("thresholds")
        .metrics
        .into_iter()
        .map(|t| t.key)
        .collect();
    assert!(keys.contains(&"completion_time_s".to_owned()), "{keys:?}");
}

on_both!(evidence_groups_and_an_adopted_pass_mark);
async fn evidence_groups_and_an_adopted_pass_mark(store: Store) {
    use cutlab_scoring::evidence::{Experience, Finding};
    let ex = exercise_with_one_threshold(&store).await;
    let mut ids = Vec::new();
    // two experts cut 0.3-0.6 mm off the line, two novices 2-5 mm, a third person has no
    // recorded level
    for (name, level, laterals) in [
        ("e1", Some(Experience::Expert), [0.0003, 0.0004, 0.0005]),
        ("e2", Some(Experience::Expert), [0.0004, 0.0005, 0.0006]),
        ("n1", Some(Experience::Novice), [0.005, 0.004, 0.003]),
        ("n2", Some(Experience::Novice), [0.004, 0.003, 0.002]),
        ("x", None, [0.001, 0.001, 0.001]),
    ] {
        let u = store
            .create_user(name, Role::Trainee, None)
            .await
            .expect("user");
        store.set_experience(u.id, level).await.expect("level");
        assert_eq!(store.experience(u.id).await.expect("read"), level);
        for l in laterals {
            scored_attempt(&store, u.id, ex, l).await;
        }
        ids.push(u.id);
    }
    assert!(matches!(
        store.set_experience(9999, None).await,
        Err(AssessError::NotFound(_))
    ));
    let attempts = store.evidence_attempts(ex).await.expect("attempts");
    assert_eq!(attempts.len(), 15);
    assert!(
        attempts
            .iter()
            .all(|a| a.score.is_some() && !a.metrics.is_empty())
    );
    let r = store.evidence(ex, true).await.expect("report");
    assert_eq!(
        (r.higher, r.lower),
        (Some(Experience::Expert), Some(Experience::Novice))
    );
    assert_eq!((r.attempts_without_level, r.trainees_without_level), (3, 1));
    assert_eq!(r.score.finding, Finding::Discriminates, "{:?}", r.score);
    let lateral = r
        .metrics
        .iter()
        .find(|m| m.key == "lateral_mean_m")
        .expect("metric");
    assert_eq!(lateral.comparison.expect("compared").auc, 1.0);
    // adopting: recorded with who; the newest is the exercise's
    assert_eq!(store.pass_mark(ex).await.expect("none yet"), None);
    let instructor = store
        .create_user("dr", Role::Instructor, None)
        .await
        .expect("user");
    let mark = store
        .adopt_pass_mark(ex, &r.pass_mark, instructor.id)
        .await
        .expect("adopt");
    let cut = r.pass_mark.cut.expect("cut");
    assert_eq!((mark.score, mark.adopted_by.as_str()), (cut.cut, "dr"));
    assert_eq!((mark.n_higher, mark.n_lower), (6, 6));
    assert_eq!(store.pass_mark(ex).await.expect("read"), Some(mark));
    // a report without a cut cannot be adopted
    let mut none = r.pass_mark.clone();
    none.cut = None;
    none.why_not = Some("test".into());
    let e = store
        .adopt_pass_mark(ex, &none, instructor.id)
        .await
        .expect_err("no cut");
    assert!(e.to_string().contains("no pass mark to adopt"), "{e}");
}

on_both!(attempts_scores_and_proficiency);
async fn attempts_scores_and_proficiency(store: Store) {
    let ex = exercise_with_one_threshold(&store).await;
    let t = store
        .create_user("trainee", Role::Trainee, None)
        .await
        .expect("user");
    // fail, pass, pass: proficient at the third
    let mut ids = Vec::new();
    for lateral in [0.005, 0.001, 0.0005] {
        let a = store
            .start_attempt(t.id, ex, Some("rec/a.mcap"), false)
            .await
            .expect("start");
        assert_eq!(a.status, AttemptStatus::Running);
        let out = store
            .finish_attempt(a.id, &values(&[("lateral_mean_m", lateral)]))
            .await
            .expect("finish");
        assert_eq!(out.attempt.status, AttemptStatus::Complete);
        assert!(out.attempt.ended_ns.is_some() && out.attempt.scored);
        ids.push(a.id);
    }
    let attempts = store
        .list_attempts(Some(t.id), Some(ex))
        .await
        .expect("list");
    assert_eq!(
        attempts.iter().map(|a| a.passed).collect::<Vec<_>>(),
        [Some(false), Some(true), Some(true)]
    );
    // 0.001 on a (0.0005, 0.002) threshold: (0.002 - 0.001) / 0.0015 = 2/3
    assert!((attempts[1].score.expect("score") - 2.0 / 3.0).abs() < 1e-12);
    let p = store.proficiency(t.id, ex).await.expect("proficiency");
    assert!(p.state.proficient);
    assert_eq!(p.proficient_attempt_id, Some(ids[2]));
    assert_eq!(
        (p.state.attempts, p.state.passes, p.state.consecutive_passes),
        (3, 2, 2)
    );
    let chart = store
        .cusum_chart(t.id, ex, &CusumParams::default())
        .await
        .expect("cusum");
    assert_eq!(chart.len(), 3);
    // proficient at the third: the CUSUM restarts from 0 after it, its third point ends the
    // learning phase
    assert_eq!(p.cusum, 0.0);
    let learning = cusum(&[false, true, true], &CusumParams::default()).expect("chart");
    assert!((chart[2].1.value - learning[2].value).abs() < 1e-12);
    let metrics = store.attempt_metrics(ids[0]).await.expect("metrics");
    let lat = metrics
        .iter()
        .find(|m| m.metric == "lateral_mean_m")
        .expect("stored");
    assert_eq!((lat.value, lat.passed), (Some(0.005), Some(false)));
    assert!(
        metrics
            .iter()
            .find(|m| m.metric == "time_s")
            .expect("stored")
            .value
            .is_none(),
        "missing stays missing"
    );
    assert!(
        matches!(
            store.finish_attempt(ids[0], &values(&[])).await,
            Err(AssessError::Conflict(_))
        ),
        "scored once"
    );

    // an interrupted session: incomplete, recording kept, not scored
    let a = store
        .start_attempt(t.id, ex, Some("rec/cut-short.mcap"), false)
        .await
        .expect("start");
    let a = store
        .mark_incomplete(a.id, Some("interrupted"))
        .await
        .expect("incomplete");
    assert_eq!(a.status, AttemptStatus::Incomplete);
    assert_eq!(a.recording_path.as_deref(), Some("rec/cut-short.mcap"));
    assert!(!a.scored && a.score.is_none());
    assert!(
        store.mark_incomplete(a.id, None).await.is_err(),
        "only running attempts"
    );
    assert_eq!(
        store.proficiency(t.id, ex).await.expect("p").state.attempts,
        3
    );
}

on_both!(thresholds_from_expert_attempts);
async fn thresholds_from_expert_attempts(store: Store) {
    let ex = exercise_with_one_threshold(&store).await;
    let expert = store
        .create_user("expert", Role::Instructor, None)
        .await
        .expect("user");
    assert!(
        store.thresholds_from_experts(ex).await.is_err(),
        "no experts yet"
    );
    for lateral in [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 40.0] {
        let a = store
            .start_attempt(expert.id, ex, None, true)
            .await
            .expect("start");
        store
            .finish_attempt(
                a.id,
                &values(&[("lateral_mean_m", lateral * 1e-3), ("time_s", 10.0)]),
            )
            .await
            .expect("finish");
    }
    let t: Thresholds = store.thresholds_from_experts(ex).await.expect("thresholds");
    let lat = t
        .metrics
        .iter()
        .find(|m| m.key == "lateral_mean_m")
        .expect("lateral");
    assert_eq!(lat.n_experts, 9, "the 40 mm outlier is out");
    assert!((lat.upper.expect("upper") - (5.0 + 2.0 * 7.5f64.sqrt()) * 1e-3).abs() < 1e-12);
    assert_eq!(
        t.metrics.iter().map(|m| m.key.as_str()).collect::<Vec<_>>(),
        ["lateral_mean_m", "fraction_cut_in_tolerance", "time_s"]
    );
    let stored = store.thresholds(ex).await.expect("stored");
    assert_eq!(stored.metrics.len(), 3);
    let src: String = on_db!(store.db(), pool => {
        sqlx::query_scalar("SELECT DISTINCT source FROM metric_thresholds WHERE exercise_id = $1")
            .bind(ex)
            .fetch_one(pool)
            .await
    })
    .expect("source");
    assert_eq!(src, "experts");
    store
        .set_thresholds(
            ex,
            &Thresholds {
                k: 2.0,
                metrics: vec![],
            },
            ThresholdSource::Default,
        )
        .await
        .expect("clear");
    assert!(
        store
            .thresholds(ex)
            .await
            .expect("stored")
            .metrics
            .is_empty()
    );
}

on_both!(thresholds_are_kept_per_device_class);
async fn thresholds_are_kept_per_device_class(store: Store) {
    use cutlab_scoring::DeviceClass;
    let ex = exercise_with_one_threshold(&store).await;
    let expert = store
        .create_user("expert", Role::Instructor, None)
        .await
        .expect("user");
    let trainee = store
        .create_user("trainee", Role::Trainee, None)
        .await
        .expect("user");
    let attempt = |who: i64, expert: bool, device: Option<&'static str>, lateral_mm: f64| {
        let store = &store;
        async move {
            let a = store
                .start_attempt(who, ex, None, expert)
                .await
                .expect("start");
            if let Some(d) = device {
                store
                    .set_attempt_setup(a.id, Some("guided"), d)
                    .await
                    .expect("setup");
            }
            let metrics = values(&[
                ("lateral_mean_m", lateral_mm * 1e-3),
                ("fraction_cut_in_tolerance", 1.0),
            ]);
            store.finish_attempt(a.id, &metrics).await.expect("finish")
        }
    };
    // experts with a stylus (an unrecorded device is one) keep within 1-2 mm of the line,
    // experts at the pointer within 3-4 mm
    for (k, lateral) in [1.0, 1.5, 2.0, 1.2].into_iter().enumerate() {
        attempt(expert.id, true, [None, Some("igtl:18944")][k % 2], lateral).await;
    }
    for lateral in [3.0, 3.5, 4.0, 3.2] {
        attempt(expert.id, true, Some("pointer:steady"), lateral).await;
    }
    let pooled = store.thresholds_from_experts(ex).await.expect("thresholds");
    let upper = |t: &Thresholds| {
        let m = t.metrics.iter().find(|m| m.key == "lateral_mean_m");
        (
            m.expect("lateral").upper.expect("upper"),
            m.expect("lateral").n_experts,
        )
    };
    let pointer = store
        .thresholds_for(ex, DeviceClass::Pointer)
        .await
        .expect("pointer");
    let stylus = store
        .thresholds_for(ex, DeviceClass::Stylus)
        .await
        .expect("stylus");
    assert_eq!(
        (upper(&pooled).1, upper(&pointer).1, upper(&stylus).1),
        (8, 4, 4)
    );
    assert!(
        upper(&stylus).0 < 3.0e-3 && upper(&pointer).0 > 4.0e-3,
        "{stylus:?} {pointer:?}"
    );
    assert_eq!(
        upper(&store.thresholds(ex).await.expect("pooled")),
        upper(&pooled)
    );
    // the same 3.5 mm passes at the pointer and fails with a stylus
    let at_pointer = attempt(trainee.id, false, Some("pointer"), 3.5).await;
    let with_stylus = attempt(trainee.id, false, Some("igtl:18944"), 3.5).await;
    assert!(at_pointer.verdict.pass && !with_stylus.verdict.pass);
    // thresholds set by hand are every class's
    store
        .set_thresholds(ex, &stylus, ThresholdSource::Default)
        .await
        .expect("by hand");
    for class in DeviceClass::ALL {
        let t = store.thresholds_for(ex, class).await.expect("stored");
        assert_eq!(upper(&t), upper(&stylus), "{class:?}");
    }
}

on_both!(xapi_of_a_trainee);
async fn xapi_of_a_trainee(store: Store) {
    let ex = exercise_with_one_threshold(&store).await;
    let t = store
        .create_user("trainee", Role::Trainee, None)
        .await
        .expect("user");
    for lateral in [0.001, 0.001] {
        scored_attempt(&store, t.id, ex, lateral).await;
    }
    let s = store.xapi_statements("trainee").await.expect("xapi");
    let verbs: Vec<&str> = s
        .iter()
        .map(|v| v["verb"]["display"]["en-US"].as_str().expect("verb"))
        .collect();
    assert_eq!(
        verbs,
        ["attempted", "passed", "attempted", "passed", "mastered"]
    );
    assert!(
        s[1]["result"]["duration"]
            .as_str()
            .expect("duration")
            .starts_with("PT")
    );
    assert!(matches!(
        store.xapi_statements("nobody").await,
        Err(AssessError::NotFound(_))
    ));
}

/// Two stores (two stations) on one database write attempts at the same time: nothing is
/// lost.
async fn concurrent_writers(at: &DbLocation) {
    let a = Store::open(at).await.expect("store a");
    let b = Store::open(at).await.expect("store b");
    let ex = a.ensure_builtins().await.expect("builtins").id;
    assert_eq!(b.ensure_builtins().await.expect("builtins").id, ex);
    let ua = a
        .create_user("station-a", Role::Trainee, None)
        .await
        .expect("user")
        .id;
    let ub = b
        .create_user("station-b", Role::Trainee, None)
        .await
        .expect("user")
        .id;
    let run = |store: Store, user: i64| async move {
        let mut tasks = Vec::new();
        for i in 0..10 {
            let store = store.clone();
            tasks.push(tokio::spawn(async move {
                let at = store
                    .start_attempt(user, ex, Some(&format!("rec/{user}-{i}.mcap")), false)
                    .await
                    .expect("start");
                store
                    .finish_attempt(
                        at.id,
                        &values(&[("lateral_mean_m", 0.001), ("time_s", 9.0)]),
                    )
                    .await
                    .expect("finish");
            }));
        }
        for t in tasks {
            t.await.expect("task");
        }
    };
    let (ra, rb) = tokio::join!(
        tokio::spawn(run(a.clone(), ua)),
        tokio::spawn(run(b.clone(), ub))
    );
    ra.expect("a");
    rb.expect("b");
    let all = a.list_attempts(None, None).await.expect("list");
    assert_eq!(all.len(), 20);
    assert!(all.iter().all(|x| x.status == AttemptStatus::Complete));
    let results: i64 = on_db!(b.db(), pool => {
        sqlx::query_scalar("SELECT COUNT(*) FROM metric_results")
            .fetch_one(pool)
            .await
    })
    .expect("count");
    assert_eq!(results, 20 * METRICS.len() as i64);
    assert_eq!(a.proficiency(ua, ex).await.expect("p").state.attempts, 10);
    assert_eq!(b.proficiency(ub, ex).await.expect("p").state.attempts, 10);
}

#[tokio::test]
async fn concurrent_writers_on_one_sqlite_file() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let at = DbLocation::Sqlite(dir.path().join("cutlab.db"));
    concurrent_writers(&at).await;
    let store = Store::open(&at).await.expect("store");
    let mode: String = on_db!(store.db(), pool => {
        sqlx::query_scalar("PRAGMA journal_mode").fetch_one(pool).await
    })
    .expect("pragma");
    assert_eq!(mode, "wal");
}

/// Stores opening one fresh SQLite file at the same moment: each opens it, none is told the
/// database is locked. (Two `cutlab session` processes of the validity test were, once, on a
/// loaded machine, when the second connected while the first switched the new file to WAL;
/// in one process it has not been seen, so this guards the retry rather than reproducing it.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn many_open_one_fresh_sqlite_file_at_once() {
    for round in 0..5 {
        let dir = tempfile::tempdir().expect("temporary folder");
        let at = DbLocation::Sqlite(dir.path().join("fresh.db"));
        let opens: Vec<_> = (0..6)
            .map(|_| {
                let at = at.clone();
                tokio::spawn(async move { Store::open(&at).await.map(|_| ()) })
            })
            .collect();
        for o in opens {
            let opened = o.await.expect("task");
            assert!(opened.is_ok(), "round {round}: {opened:?}");
        }
    }
}

#[tokio::test]
async fn concurrent_writers_on_one_postgres_database() {
    if let Some(at) = postgres_location().await {
        concurrent_writers(&at).await;
    }
}

#[tokio::test]
async fn open_creates_and_migrates_a_file() {
    let dir = std::env::temp_dir().join(format!("cutlab-store-{}", std::process::id()));
    let path = dir.join("sub").join("test.db");
    let store = Store::open(&path).await.expect("open");
    store.ensure_builtins().await.expect("builtins");
    store.close().await;
    let again = Store::open(&path).await.expect("reopen");
    assert_eq!(again.list_exercises().await.expect("list").len(), 5);
    again.close().await;
    std::fs::remove_dir_all(&dir).ok();
}

/// A scripted attempt on the built-in plan: approach 20 mm straight down at the entry, cut
/// along the line `offset` to the side at `depth` below the curved surface, withdraw.
fn scripted(offset: f64, depth: f64, force: f64) -> cutlab_scoring::AttemptData {
    use cutlab_scoring::{AttemptData, CutSample, ForceSample, PoseSample};
    let surface = |x: f64| (0.15f64 * 0.15 - x * x).sqrt() - 0.15;
    let mut d = AttemptData::default();
    let hz = 200.0;
    let tip = |t: f64| -> [f64; 3] {
        let ease = |u: f64| {
            let u = u.clamp(0.0, 1.0);
            10.0 * u.powi(3) - 15.0 * u.powi(4) + 6.0 * u.powi(5)
        };
        if t < 1.0 {
            [
                -0.03,
                offset,
                surface(-0.03) + 0.02 - (0.02 + depth) * ease(t),
            ]
        } else if t < 7.0 {
            let x = -0.03 + 0.06 * ease((t - 1.0) / 6.0);
            [x, offset, surface(x) - depth]
        } else {
            [
                0.03,
                offset,
                surface(0.03) - depth + (0.02 + depth) * ease(t - 7.0),
            ]
        }
    };
    for i in 0..=(8.0 * hz) as usize {
        let t = i as f64 / hz;
        let p = tip(t);
        let cutting = (1.0..7.0).contains(&t);
        d.poses.push(PoseSample {
            t_s: t,
            tip_m: p,
            quat_wxyz: [1.0, 0.0, 0.0, 0.0],
            blade_engaged: cutting,
        });
        d.forces.push(ForceSample {
            t_s: t,
            force_newtons: [0.0, 0.0, if cutting { force } else { 0.0 }],
            touching: cutting,
            cutting,
        });
        if cutting
            && d.cuts
                .last()
                .is_none_or(|c: &CutSample| (p[0] - c.tip_m[0]).abs() >= 0.0005)
        {
            d.cuts.push(CutSample {
                t_s: t,
                tip_m: p,
                edge_dir: [0.0, 0.0, 1.0],
                depth_m: depth,
                stroke: None,
            });
        }
    }
    d
}

on_both!(score_attempts_on_the_builtin_exercise);
async fn score_attempts_on_the_builtin_exercise(store: Store) {
    let ex = store.ensure_builtins().await.expect("builtins").id;
    let t = store
        .create_user("t", Role::Trainee, None)
        .await
        .expect("user");
    let good = store
        .start_attempt(t.id, ex, None, false)
        .await
        .expect("start");
    let good = store
        .score_attempt(good.id, &scripted(0.0002, 0.008, 1.0))
        .await
        .expect("score");
    let failed: Vec<_> = good.verdict.metrics.iter().filter(|m| !m.pass).collect();
    assert!(good.verdict.pass, "{failed:?}");
    assert!(
        good.verdict.score > 0.5,
        "{} {:?}",
        good.verdict.score,
        good.verdict.metrics
    );
    let bad = store
        .start_attempt(t.id, ex, None, false)
        .await
        .expect("start");
    let bad = store
        .score_attempt(bad.id, &scripted(0.004, 0.003, 3.2))
        .await
        .expect("score");
    assert!(!bad.verdict.pass);
    assert!(
        bad.verdict.score < good.verdict.score - 0.4,
        "{} vs {}",
        bad.verdict.score,
        good.verdict.score
    );
    for key in ["lateral_mean_m", "depth_error_m", "peak_force_n"] {
        assert!(
            !bad.verdict
                .metrics
                .iter()
                .find(|m| m.key == key)
                .expect(key)
                .pass,
            "{key}"
        );
    }
}

on_both!(a_station_queues_and_a_hub_takes_each_attempt_once);
async fn a_station_queues_and_a_hub_takes_each_attempt_once(hub: Store) {
    // the station: an SQLite file of its own, as in a simulation centre
    let (station, _dir) = sqlite_store().await;
    exercise_with_one_threshold(&hub).await;
    let ex = exercise_with_one_threshold(&station).await;
    let t = station
        .create_user("sam", Role::Trainee, None)
        .await
        .expect("trainee");
    let running = station
        .start_attempt(t.id, ex, Some("rec/b.mcap"), false)
        .await
        .expect("running");
    let done = station
        .start_attempt(t.id, ex, Some("rec/a.mcap"), false)
        .await
        .expect("start");
    assert!(cutlab_assessor::store::is_uuid(
        done.uuid.as_deref().expect("id")
    ));
    station
        .finish_attempt(done.id, &values(&[("lateral_mean_m", 0.001)]))
        .await
        .expect("scored");
    // only ended attempts are queued, and they stay queued until taken
    let queue = station.sync_queue().await.expect("queue");
    assert_eq!(queue.iter().map(|a| a.id).collect::<Vec<_>>(), [done.id]);
    assert!(queue.iter().all(|a| a.id != running.id));
    station
        .set_synced(done.id, Err("hub down"))
        .await
        .expect("failed upload");
    let queue = station.sync_queue().await.expect("queue");
    assert_eq!(queue[0].sync_error.as_deref(), Some("hub down"));

    let mut up = station.upload_of(done.id).await.expect("upload");
    assert_eq!(
        (up.trainee.as_str(), up.exercise.as_str()),
        ("sam", "one-metric")
    );
    // a complete attempt comes with its recording, which the hub measures (here: the
    // station's values, as the hub's own measure would give)
    assert!(hub.import_attempt(&up, "or-1", &up.metrics).await.is_err());
    up.recording_sha256 = Some(cutlab_assessor::recordings::sha256_hex(b"a.mcap"));
    let first = hub
        .import_attempt(&up, "or-1", &up.metrics)
        .await
        .expect("import");
    assert!(first.created);
    assert_eq!(first.attempt.status, AttemptStatus::Complete);
    assert_eq!(first.attempt.passed, Some(true), "scored on the hub");
    assert_eq!(first.attempt.started_ns, done.started_ns);
    assert_eq!(first.attempt.station.as_deref(), Some("or-1"));
    // a retry is the same attempt, not a second one
    let again = hub
        .import_attempt(&up, "or-1", &up.metrics)
        .await
        .expect("retry");
    assert!(!again.created);
    assert_eq!(again.attempt.id, first.attempt.id);
    let sam = hub.user_by_name("sam").await.expect("made on the hub");
    assert_eq!(
        hub.list_attempts(Some(sam.id), None)
            .await
            .expect("list")
            .len(),
        1
    );
    let p = hub
        .proficiency(sam.id, first.attempt.exercise_id)
        .await
        .expect("proficiency");
    assert_eq!(p.state.attempts, 1, "counted once");
    station.set_synced(done.id, Ok(())).await.expect("taken");
    assert!(station.sync_queue().await.expect("queue").is_empty());

    // what a hub refuses
    let mut bad = up.clone();
    bad.uuid = "1; DROP TABLE attempts".into();
    assert!(matches!(
        hub.import_attempt(&bad, "or-1", &[]).await,
        Err(AssessError::InvalidInput(_))
    ));
    let mut bad = up.clone();
    bad.uuid = cutlab_assessor::store::new_uuid().expect("id");
    bad.exercise = "not-on-this-hub".into();
    let err = hub
        .import_attempt(&bad, "or-1", &[])
        .await
        .expect_err("unknown exercise");
    assert!(err.to_string().contains("not-on-this-hub"), "{err}");
    bad.exercise = up.exercise.clone();
    bad.status = AttemptStatus::Running;
    assert!(hub.import_attempt(&bad, "or-1", &[]).await.is_err());
    // a station token never sets thresholds, never writes as an instructor, never scores a
    // metric twice, and a name is the name
    let refused = |change: fn(&mut cutlab_assessor::store::AttemptUpload)| {
        let mut u = up.clone();
        u.uuid = cutlab_assessor::store::new_uuid().expect("id");
        change(&mut u);
        u
    };
    hub.create_user("dr-x", Role::Instructor, None)
        .await
        .expect("instructor");
    for u in [
        refused(|u| u.expert = true),
        refused(|u| u.trainee = "dr-x".into()),
        refused(|u| u.trainee = " sam".into()),
        refused(|u| {
            let m = u.metrics[0].clone();
            u.metrics.push(m);
        }),
    ] {
        assert!(
            matches!(
                hub.import_attempt(&u, "or-1", &u.metrics).await,
                Err(AssessError::InvalidInput(_))
            ),
            "{u:?}"
        );
    }
    assert_eq!(hub.list_attempts(None, None).await.expect("list").len(), 1);

    // station tokens: shown once, revoked, never another's
    let token = hub.create_station_token("or-2").await.expect("token");
    assert!(matches!(
        hub.create_station_token("or-2").await,
        Err(AssessError::Conflict(_))
    ));
    let s = hub.station_by_token(&token).await.expect("lookup");
    assert_eq!(s.expect("valid").name, "or-2");
    assert_eq!(
        hub.station_by_token("cutlab-station-guess")
            .await
            .expect("lookup"),
        None
    );
    hub.revoke_station_token("or-2").await.expect("revoke");
    assert_eq!(hub.station_by_token(&token).await.expect("lookup"), None);
    let listed = hub.list_station_tokens().await.expect("list");
    assert!(listed[0].revoked_ns.is_some() && listed[0].last_used_ns.is_some());
}

on_both!(a_hub_refuses_forged_and_impossible_attempts);
async fn a_hub_refuses_forged_and_impossible_attempts(hub: Store) {
    use cutlab_assessor::store::{AttemptUpload, new_uuid, now_ns};
    exercise_with_one_threshold(&hub).await;
    let second = 1_000_000_000;
    let good = |key: &[u8]| AttemptUpload {
        uuid: new_uuid().expect("id"),
        trainee: "sam".into(),
        exercise: "one-metric".into(),
        started_ns: now_ns() - 60 * second,
        ended_ns: Some(now_ns() - 30 * second),
        status: AttemptStatus::Complete,
        expert: false,
        note: None,
        recording_sha256: Some(cutlab_assessor::recordings::sha256_hex(key)),
        rrd_sha256: None,
        metrics: values(&[("lateral_mean_m", 0.001)]),
        mode: Some("exam".into()),
        device: Some("pointer".into()),
    };
    let up = good(b"one");
    let taken = hub
        .import_attempt(&up, "or-1", &up.metrics)
        .await
        .expect("taken");
    assert!(taken.created);
    // how it was made comes with it
    let kept = hub.attempt_by_uuid(&up.uuid).await.expect("kept");
    assert_eq!(
        (kept.mode.as_deref(), kept.device.as_deref()),
        (Some("exam"), Some("pointer"))
    );
    // another station claiming the id; a second attempt scored by the same recording
    assert!(matches!(
        hub.import_attempt(&up, "or-2", &up.metrics).await,
        Err(AssessError::Conflict(_))
    ));
    let mut copy = good(b"one");
    copy.uuid = new_uuid().expect("id");
    assert!(matches!(
        hub.import_attempt(&copy, "or-1", &copy.metrics).await,
        Err(AssessError::Conflict(_))
    ));
    // times out of order, in the future, lasting for ever, before 2020; impossible or
    // unknown metrics; names that are no one's
    type Change = fn(&mut AttemptUpload);
    let cases: Vec<(&str, Change)> = vec![
        ("ended before it started", |u| {
            u.ended_ns = Some(u.started_ns - 1)
        }),
        ("started at i64::MAX", |u| {
            u.started_ns = i64::MAX;
            u.ended_ns = Some(i64::MAX);
        }),
        ("lasted two days", |u| {
            u.started_ns -= 2 * 86_400 * 1_000_000_000;
        }),
        ("started in 1970", |u| u.started_ns = 0),
        ("no end", |u| u.ended_ns = None),
        ("1e308 m", |u| u.metrics[0].value = Some(1e308)),
        ("a negative time", |u| {
            let t = u
                .metrics
                .iter_mut()
                .find(|m| m.key == "time_s")
                .expect("time");
            t.value = Some(-5.0);
        }),
        ("an unknown metric", |u| {
            let mut m = u.metrics[0].clone();
            m.key = "made_up_m".into();
            u.metrics.push(m);
        }),
        ("a wrong unit", |u| u.metrics[0].unit = "mm".into()),
        ("a control character", |u| u.trainee = "sam\u{1b}[2J".into()),
        ("a long name", |u| u.trainee = "x".repeat(2_000_000)),
        ("a long note", |u| u.note = Some("n".repeat(10_000))),
        ("an unknown mode", |u| u.mode = Some("kiosk".into())),
        ("a device with a control character", |u| {
            u.device = Some("pointer\u{0}".into())
        }),
        ("a long device name", |u| {
            u.device = Some("d".repeat(10_000))
        }),
    ];
    for (what, change) in cases {
        let mut u = good(what.as_bytes());
        change(&mut u);
        let err = hub
            .import_attempt(&u, "or-1", &u.metrics)
            .await
            .expect_err(what);
        assert!(matches!(err, AssessError::InvalidInput(_)), "{what}: {err}");
        assert!(err.to_string().len() < 600, "{what}: a bounded message");
    }
    // a look-alike of a staff name is not made a trainee
    hub.create_user("dr-kim", Role::Instructor, None)
        .await
        .expect("instructor");
    let mut u = good(b"look-alike");
    u.trainee = "DR-KIM".into();
    let err = hub
        .import_attempt(&u, "or-1", &u.metrics)
        .await
        .expect_err("a look-alike");
    assert!(
        matches!(err, AssessError::InvalidInput(_)),
        "422 on the hub: {err}"
    );
    assert!(hub.user_by_name("DR-KIM").await.is_err());
    assert_eq!(hub.list_attempts(None, None).await.expect("list").len(), 1);
}

on_both!(a_peak_force_band_from_experts_gives_way_to_the_plans_limit);
async fn a_peak_force_band_from_experts_gives_way_to_the_plans_limit(store: Store) {
    let ex = exercise_with_one_threshold(&store).await;
    let expert = store
        .create_user("expert", Role::Instructor, None)
        .await
        .expect("user");
    // scripted experts, all pressing about 0.8 N: a band near 0.9 N
    for force in [0.78, 0.8, 0.82, 0.8] {
        let a = store
            .start_attempt(expert.id, ex, None, true)
            .await
            .expect("start");
        store
            .finish_attempt(a.id, &values(&[("peak_force_n", force)]))
            .await
            .expect("finish");
    }
    store.thresholds_from_experts(ex).await.expect("thresholds");
    let limit = |t: &Thresholds| {
        t.metrics
            .iter()
            .find(|m| m.key == "peak_force_n")
            .and_then(|m| m.upper)
    };
    let plan_limit = IncisionPlan::chest_wall().expect("plan").force_limit_n;
    let t = store.thresholds(ex).await.expect("stored");
    assert_eq!(limit(&t), Some(plan_limit), "the plan's safety limit");
    // one set by hand stays
    let hand = Thresholds {
        k: 2.0,
        metrics: vec![Threshold::fixed(
            "peak_force_n",
            Better::LowerIsBetter,
            0.5,
            0.9,
        )],
    };
    store
        .set_thresholds(ex, &hand, ThresholdSource::Default)
        .await
        .expect("set");
    assert_eq!(
        limit(&store.thresholds(ex).await.expect("stored")),
        Some(0.9)
    );
}
