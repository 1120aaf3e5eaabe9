//! Data for a fresh database: the demo accounts, a cohort and synthetic attempts
//! ([`seed_demo`]), and the load-test population ([`seed_load`]). Synthetic attempts are
//! scored through the store (`finish_attempt`) like real ones, from metric values drawn
//! around the exercise's thresholds by a seeded generator; they have no recording.

use cutlab_assessor::AssessError;
use cutlab_assessor::store::{Cohort, Role, Store, User};
use cutlab_scoring::Better;
use cutlab_scoring::evidence::Experience;
use cutlab_scoring::metrics::{self, MetricValue};
use cutlab_scoring::proficiency::Thresholds;
use cutlab_sim::rng::Rng;
use serde::Serialize;

/// A demo login.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct DemoAccount {
    pub name: &'static str,
    pub password: &'static str,
    pub role: Role,
    /// The surgical experience recorded for the evidence report's groups.
    pub experience: Option<Experience>,
}

/// The demo accounts (also in the README).
pub const DEMO_ACCOUNTS: [DemoAccount; 4] = [
    DemoAccount {
        name: "admin",
        password: "admin-demo",
        role: Role::Admin,
        experience: None,
    },
    DemoAccount {
        name: "dr-kim",
        password: "instructor-demo",
        role: Role::Instructor,
        experience: Some(Experience::Expert),
    },
    DemoAccount {
        name: "ana",
        password: "trainee-demo",
        role: Role::Trainee,
        experience: Some(Experience::Novice),
    },
    DemoAccount {
        name: "ben",
        password: "trainee-demo",
        role: Role::Trainee,
        experience: Some(Experience::Novice),
    },
];

/// The demo cohort, led by `dr-kim`, with `ana` and `ben`.
pub const DEMO_COHORT: &str = "demo-cohort";

/// The user `a.name`, created with its role and password when missing; a password is set
/// when the account has none, its experience when none is recorded. An existing account's
/// password and experience are never changed.
async fn ensure_account(store: &Store, a: &DemoAccount) -> Result<User, AssessError> {
    let u = match store.user_by_name(a.name).await {
        Ok(u) => {
            if !u.has_password {
                store.set_password(u.id, a.password).await?;
            }
            store.get_user(u.id).await?
        }
        Err(AssessError::NotFound(_)) => {
            store.create_user(a.name, a.role, Some(a.password)).await?
        }
        Err(e) => return Err(e),
    };
    if a.experience.is_some() && store.experience(u.id).await?.is_none() {
        store.set_experience(u.id, a.experience).await?;
    }
    Ok(u)
}

async fn ensure_cohort(store: &Store, name: &str, instructor: i64) -> Result<Cohort, AssessError> {
    match store.cohort_by_name(name).await {
        Ok(c) => Ok(c),
        Err(AssessError::NotFound(_)) => store.create_cohort(name, Some(instructor)).await,
        Err(e) => Err(e),
    }
}

/// Metric values of one synthetic attempt: each thresholded metric at `mean + q (limit -
/// mean)` with `q` around `skill` (below 1 passes), plus noise.
pub fn synthetic_metrics(t: &Thresholds, skill: f64, rng: &mut Rng) -> Vec<MetricValue> {
    t.metrics
        .iter()
        .filter_map(|th| {
            let def = metrics::metric(&th.key)?;
            let q = (skill + 0.35 * (rng.uniform() - 0.5)).max(0.0);
            let value = match (th.better, th.lower, th.upper) {
                (Better::LowerIsBetter, _, Some(u)) => th.mean + q * (u - th.mean),
                (Better::HigherIsBetter, Some(l), _) => th.mean - q * (th.mean - l),
                (Better::TwoSided, _, Some(u)) => {
                    th.mean + if rng.uniform() < 0.5 { -1.0 } else { 1.0 } * q * (u - th.mean)
                }
                _ => th.mean,
            };
            let value = if th.better == Better::HigherIsBetter && def.unit == "1" {
                value.clamp(0.0, 1.0)
            } else {
                value.max(if th.better == Better::TwoSided {
                    f64::NEG_INFINITY
                } else {
                    0.0
                })
            };
            Some(MetricValue {
                key: th.key.clone(),
                value: Some(value),
                unit: def.unit.into(),
                better: th.better,
                scored: def.scored,
                missing: None,
            })
        })
        .collect()
}

/// `n` scored synthetic attempts of `trainee` at `exercise_id`, skill improving from
/// `skill0` to `skill1`.
pub async fn synthetic_attempts(
    store: &Store,
    trainee: i64,
    exercise_id: i64,
    n: usize,
    skill0: f64,
    skill1: f64,
    rng: &mut Rng,
) -> Result<(), AssessError> {
    let t = store.thresholds(exercise_id).await?;
    for i in 0..n {
        let s = if n > 1 {
            skill0 + (skill1 - skill0) * i as f64 / (n - 1) as f64
        } else {
            skill1
        };
        let a = store
            .start_attempt(trainee, exercise_id, None, false)
            .await?;
        store
            .finish_attempt(a.id, &synthetic_metrics(&t, s, rng))
            .await?;
    }
    Ok(())
}

/// The built-in exercise, the [`DEMO_ACCOUNTS`] and the cohort [`DEMO_COHORT`] led by
/// `dr-kim` with the demo trainees in it; returns the accounts' users in the order of
/// [`DEMO_ACCOUNTS`]. Safe to run again.
pub async fn seed_demo_accounts(store: &Store) -> Result<Vec<User>, AssessError> {
    store.ensure_builtins().await?;
    let mut users = Vec::new();
    for a in &DEMO_ACCOUNTS {
        users.push(ensure_account(store, a).await?);
    }
    let cohort = ensure_cohort(store, DEMO_COHORT, users[1].id).await?;
    for u in users.iter().filter(|u| u.role == Role::Trainee) {
        store.join_cohort(cohort.id, u.id).await?;
    }
    Ok(users)
}

/// Makes a fresh (or any) database usable at once: [`seed_demo_accounts`] and, for a demo
/// trainee without attempts, synthetic scored attempts (ana improves to proficiency, ben is
/// still learning), and the instructor's at an expert's level. `cutlab demo` simulates its attempts instead. Safe to run again.
pub async fn seed_demo(store: &Store) -> Result<Vec<DemoAccount>, AssessError> {
    let exercise = store.ensure_builtins().await?;
    let users = seed_demo_accounts(store).await?;
    let mut rng = Rng::new(7);
    for (u, (n, s0, s1)) in users[2..].iter().zip([(8, 1.6, 0.3), (5, 1.8, 1.0)]) {
        if store.list_attempts(Some(u.id), None).await?.is_empty() {
            synthetic_attempts(store, u.id, exercise.id, n, s0, s1, &mut rng).await?;
        }
    }
    // the instructor's own attempts, at an expert's level: the evidence page's expert group
    let expert = &users[1];
    if store.list_attempts(Some(expert.id), None).await?.is_empty() {
        synthetic_attempts(store, expert.id, exercise.id, 6, 0.35, 0.2, &mut rng).await?;
    }
    Ok(DEMO_ACCOUNTS.to_vec())
}

/// The load-test instructor and password.
pub const LOAD_INSTRUCTOR: DemoAccount = DemoAccount {
    name: "load-instructor",
    password: "load-demo",
    role: Role::Instructor,
    experience: None,
};

/// `trainees` trainees (`load-0000`...) in cohort `load-cohort` led by [`LOAD_INSTRUCTOR`],
/// each with `attempts` scored synthetic attempts; returns the trainees' ids. Trainees that
/// already have attempts are kept as they are.
pub async fn seed_load(
    store: &Store,
    trainees: usize,
    attempts: usize,
) -> Result<Vec<i64>, AssessError> {
    let exercise = store.ensure_builtins().await?;
    let instructor = ensure_account(store, &LOAD_INSTRUCTOR).await?;
    let cohort = ensure_cohort(store, "load-cohort", instructor.id).await?;
    let mut rng = Rng::new(11);
    let mut ids = Vec::with_capacity(trainees);
    for i in 0..trainees {
        let name = format!("load-{i:04}");
        let u = match store.user_by_name(&name).await {
            Ok(u) => u,
            Err(AssessError::NotFound(_)) => store.create_user(&name, Role::Trainee, None).await?,
            Err(e) => return Err(e),
        };
        store.join_cohort(cohort.id, u.id).await?;
        if store.list_attempts(Some(u.id), None).await?.is_empty() {
            let start = 1.2 + 0.8 * rng.uniform();
            synthetic_attempts(
                store,
                u.id,
                exercise.id,
                attempts,
                start,
                0.3 + 0.5 * rng.uniform(),
                &mut rng,
            )
            .await?;
        }
        ids.push(u.id);
    }
    Ok(ids)
}
