//! xAPI (Experience API 1.0.3) statements of a trainee's attempts, as JSON values for a
//! learning record store.
//!
//! Per attempt: `attempted` (every attempt; `result.completion` says whether it ended
//! scored); then for a scored one `passed` or `failed` with `result.score.scaled` (the
//! normalised score, in `[-1, 1]`), `result.success`, `result.duration` (ISO 8601) and each
//! metric's value in `result.extensions` under `<XAPI_BASE>/metric/<key>`; and `mastered` on
//! the attempt that made the trainee proficient.

use serde_json::{Value, json};

use crate::error::Result;
use crate::store::{Attempt, AttemptStatus, Store, StoredMetric, User, iso8601};

/// The base IRI of cutlab's activities and extensions.
pub const XAPI_BASE: &str = "https://cutlab.invalid/xapi";

/// The ADL verbs used.
pub const VERB_ATTEMPTED: &str = "http://adlnet.gov/expapi/verbs/attempted";
pub const VERB_PASSED: &str = "http://adlnet.gov/expapi/verbs/passed";
pub const VERB_FAILED: &str = "http://adlnet.gov/expapi/verbs/failed";
pub const VERB_MASTERED: &str = "http://adlnet.gov/expapi/verbs/mastered";

/// ISO 8601 duration of `ns` nanoseconds, e.g. `PT1M2.5S` (hours, minutes, seconds to ms).
pub fn iso_duration(ns: i64) -> String {
    let ms = ns.max(0) / 1_000_000;
    let (h, m, s, milli) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60, ms % 1000);
    let mut out = String::from("PT");
    if h > 0 {
        out += &format!("{h}H");
    }
    if m > 0 {
        out += &format!("{m}M");
    }
    if milli > 0 {
        let frac = format!("{milli:03}");
        out += &format!("{s}.{}S", frac.trim_end_matches('0'));
    } else if s > 0 || (h == 0 && m == 0) {
        out += &format!("{s}S");
    }
    out
}

fn verb(id: &str) -> Value {
    let name = id.rsplit('/').next().unwrap_or(id);
    json!({ "id": id, "display": { "en-US": name } })
}

/// The statements of one trainee's attempts (oldest first). `exercise_name` names each
/// attempt's exercise; `metrics` are its stored results; `mastered_attempts` are the attempts
/// that made the trainee proficient.
pub fn statements(
    trainee: &User,
    attempts: &[(Attempt, String, Vec<StoredMetric>)],
    mastered_attempts: &[i64],
) -> Vec<Value> {
    let actor = json!({ "objectType": "Agent", "name": trainee.name, "account": { "homePage": XAPI_BASE, "name": trainee.name } });
    let mut out = Vec::new();
    for (a, exercise, metrics) in attempts {
        let object = json!({
            "objectType": "Activity",
            "id": format!("{XAPI_BASE}/exercise/{exercise}"),
            "definition": { "name": { "en-US": exercise }, "type": "http://adlnet.gov/expapi/activities/simulation" }
        });
        let timestamp = iso8601(a.ended_ns.unwrap_or(a.started_ns));
        let duration = a.ended_ns.map(|e| iso_duration(e - a.started_ns));
        let context = json!({ "extensions": { format!("{XAPI_BASE}/attempt"): a.id, format!("{XAPI_BASE}/status"): a.status.as_str() } });
        let mut attempted_result = json!({ "completion": a.status == AttemptStatus::Complete });
        if let Some(d) = &duration {
            attempted_result["duration"] = json!(d);
        }
        out.push(json!({ "actor": actor, "verb": verb(VERB_ATTEMPTED), "object": object, "result": attempted_result, "context": context, "timestamp": iso8601(a.started_ns) }));
        let (Some(score), Some(pass), true) = (a.score, a.passed, a.scored) else {
            continue;
        };
        let extensions: serde_json::Map<String, Value> = metrics
            .iter()
            .filter_map(|m| {
                m.value
                    .map(|v| (format!("{XAPI_BASE}/metric/{}", m.metric), json!(v)))
            })
            .collect();
        let mut result = json!({
            "score": { "scaled": score.clamp(-1.0, 1.0) },
            "success": pass,
            "completion": true,
            "extensions": extensions
        });
        if let Some(d) = &duration {
            result["duration"] = json!(d);
        }
        out.push(json!({ "actor": actor, "verb": verb(if pass { VERB_PASSED } else { VERB_FAILED }), "object": object, "result": result, "context": context, "timestamp": timestamp }));
        if mastered_attempts.contains(&a.id) {
            out.push(json!({ "actor": actor, "verb": verb(VERB_MASTERED), "object": object, "result": { "success": true, "completion": true }, "context": context, "timestamp": timestamp }));
        }
    }
    out
}

impl Store {
    /// The xAPI statements of the trainee named `trainee` (all exercises, oldest first).
    pub async fn xapi_statements(&self, trainee: &str) -> Result<Vec<Value>> {
        let user = self.user_by_name(trainee).await?;
        let mut rows = Vec::new();
        let mut mastered = Vec::new();
        for a in self.list_attempts(Some(user.id), None).await? {
            let exercise = self.get_exercise(a.exercise_id).await?.name;
            let p = self.proficiency(user.id, a.exercise_id).await?;
            if p.proficient_attempt_id == Some(a.id) {
                mastered.push(a.id);
            }
            let metrics = self.attempt_metrics(a.id).await?;
            rows.push((a, exercise, metrics));
        }
        Ok(statements(&user, &rows, &mastered))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::Role;

    #[test]
    fn durations() {
        assert_eq!(iso_duration(0), "PT0S");
        assert_eq!(iso_duration(12_345_000_000), "PT12.345S");
        assert_eq!(iso_duration(62_500_000_000), "PT1M2.5S");
        assert_eq!(iso_duration(3_600_000_000_000), "PT1H");
    }

    #[test]
    fn attempted_passed_failed_mastered() {
        let user = User {
            id: 7,
            name: "alice".into(),
            role: Role::Trainee,
            has_password: false,
            created_ns: 0,
        };
        let a = |id: i64, passed: Option<bool>, status: AttemptStatus| Attempt {
            id,
            trainee_id: 7,
            exercise_id: 1,
            recording_path: None,
            recording_sha256: None,
            rrd_sha256: None,
            uuid: None,
            synced_ns: None,
            sync_error: None,
            station: None,
            mode: None,
            device: None,
            started_ns: id * 100_000_000_000,
            ended_ns: Some(id * 100_000_000_000 + 10_500_000_000),
            status,
            expert: false,
            scored: passed.is_some(),
            score: passed.map(|p| if p { 0.7 } else { -1.5 }),
            passed,
            note: None,
        };
        let m = vec![StoredMetric {
            metric: "lateral_mean_m".into(),
            value: Some(0.001),
            unit: "m".into(),
            passed: Some(true),
            missing: None,
        }];
        let rows = vec![
            (
                a(1, Some(false), AttemptStatus::Complete),
                "chest-wall-incision".to_owned(),
                m.clone(),
            ),
            (
                a(2, None, AttemptStatus::Incomplete),
                "chest-wall-incision".to_owned(),
                vec![],
            ),
            (
                a(3, Some(true), AttemptStatus::Complete),
                "chest-wall-incision".to_owned(),
                m.clone(),
            ),
            (
                a(4, Some(true), AttemptStatus::Complete),
                "chest-wall-incision".to_owned(),
                m,
            ),
        ];
        let s = statements(&user, &rows, &[4]);
        let verbs: Vec<&str> = s
            .iter()
            .map(|v| v["verb"]["display"]["en-US"].as_str().unwrap())
            .collect();
        assert_eq!(
            verbs,
            [
                "attempted",
                "failed",
                "attempted",
                "attempted",
                "passed",
                "attempted",
                "passed",
                "mastered"
            ]
        );
        assert_eq!(s[1]["verb"]["id"], VERB_FAILED);
        assert_eq!(
            s[1]["result"]["score"]["scaled"], -1.0,
            "clamped to [-1, 1]"
        );
        assert_eq!(s[1]["result"]["duration"], "PT10.5S");
        assert_eq!(
            s[1]["result"]["extensions"][format!("{XAPI_BASE}/metric/lateral_mean_m")],
            0.001
        );
        assert_eq!(s[2]["result"]["completion"], false);
        assert_eq!(s[4]["result"]["score"]["scaled"], 0.7);
        assert_eq!(s[0]["actor"]["account"]["name"], "alice");
        assert_eq!(s[0]["timestamp"], "1970-01-01T00:01:40.000Z");
        for st in &s {
            let scaled = st["result"]["score"]["scaled"].as_f64().unwrap_or(0.0);
            assert!((-1.0..=1.0).contains(&scaled));
        }
    }
}
