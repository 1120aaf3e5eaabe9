//! Stations and hub: each attempt has a global id (a UUID made where it was recorded), a
//! station keeps a queue of the attempts its hub has not taken yet (in its own database, so
//! it survives restarts), and a hub takes uploads from stations that hold a token of their
//! own, each attempt once however often it is sent.

use serde::{Deserialize, Serialize};

use super::attempts::{ATTEMPT_COLUMNS, Attempt, AttemptRow, AttemptStatus, attempt};
use super::{Role, Store, now_ns};
use crate::error::{AssessError, Result};
use crate::metrics::MetricValue;
use crate::recordings::is_sha256_hex;

/// A random (version 4) UUID, lowercase hex with hyphens.
pub fn new_uuid() -> Result<String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b)
        .map_err(|e| AssessError::InvalidInput(format!("no randomness for an id: {e}")))?;
    b[6] = (b[6] & 0x0f) | 0x40;
    b[8] = (b[8] & 0x3f) | 0x80;
    let h = crate::recordings::hex(&b);
    Ok(format!(
        "{}-{}-{}-{}-{}",
        &h[0..8],
        &h[8..12],
        &h[12..16],
        &h[16..20],
        &h[20..32]
    ))
}

/// Whether `s` is a UUID as [`new_uuid`] writes them (36 characters, lowercase hex and
/// hyphens at 8, 13, 18, 23).
pub fn is_uuid(s: &str) -> bool {
    s.len() == 36
        && s.bytes().enumerate().all(|(i, c)| match i {
            8 | 13 | 18 | 23 => c == b'-',
            _ => c.is_ascii_digit() || (b'a'..=b'f').contains(&c),
        })
}

/// An ended attempt as a station sends it to its hub: who, what, when, how it ended, the
/// keys of its recordings (uploaded first) and, for a complete attempt, the metrics the
/// station measured (the hub scores them against its own thresholds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AttemptUpload {
    pub uuid: String,
    pub trainee: String,
    pub exercise: String,
    pub started_ns: i64,
    pub ended_ns: Option<i64>,
    pub status: AttemptStatus,
    pub expert: bool,
    pub note: Option<String>,
    pub recording_sha256: Option<String>,
    pub rrd_sha256: Option<String>,
    pub metrics: Vec<MetricValue>,
}

impl AttemptUpload {
    /// Refuses what a hub must never store: a malformed id or key, a running attempt.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(AssessError::InvalidInput(m));
        if !is_uuid(&self.uuid) {
            return bad(format!("{:?} is not an attempt id (a UUID)", self.uuid));
        }
        if self.status == AttemptStatus::Running {
            return bad(format!("attempt {} has not ended", self.uuid));
        }
        for key in [&self.recording_sha256, &self.rrd_sha256]
            .into_iter()
            .flatten()
        {
            if !is_sha256_hex(key) {
                return bad(format!("{key:?} is not a recording key (SHA-256)"));
            }
        }
        for (what, name) in [("trainee", &self.trainee), ("exercise", &self.exercise)] {
            if name.trim().is_empty() || name.trim() != name.as_str() {
                return bad(format!("the {what}'s name {name:?}"));
            }
        }
        if self.expert {
            // an expert's reference attempt sets the exercise's thresholds: recorded on the
            // hub itself, never uploaded with a station's token
            return bad("expert reference attempts are not taken from stations".into());
        }
        let mut keys: Vec<&str> = self.metrics.iter().map(|m| m.key.as_str()).collect();
        keys.sort_unstable();
        if let Some(w) = keys.windows(2).find(|w| w[0] == w[1]) {
            return bad(format!("metric {:?} given twice", w[0]));
        }
        Ok(())
    }
}

/// What a hub did with an upload.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Imported {
    /// The attempt as the hub has it.
    pub attempt: Attempt,
    /// `false`: the hub had it already (a retry).
    pub created: bool,
}

/// A station allowed to upload to this hub.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StationToken {
    pub id: i64,
    pub name: String,
    pub created_ns: i64,
    pub revoked_ns: Option<i64>,
    pub last_used_ns: Option<i64>,
}

type TokenRow = (i64, String, i64, Option<i64>, Option<i64>);

fn station_token(r: TokenRow) -> StationToken {
    StationToken {
        id: r.0,
        name: r.1,
        created_ns: r.2,
        revoked_ns: r.3,
        last_used_ns: r.4,
    }
}

fn token_hash(token: &str) -> String {
    crate::recordings::sha256_hex(token.as_bytes())
}

impl Store {
    /// The attempt with global id `uuid`.
    pub async fn attempt_by_uuid(&self, uuid: &str) -> Result<Attempt> {
        let row: Option<AttemptRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!("{ATTEMPT_COLUMNS} WHERE uuid = $1")))
            .bind(uuid)
            .fetch_optional(pool).await)?;
        attempt(row.ok_or_else(|| AssessError::NotFound(format!("attempt {uuid}")))?)
    }

    /// The station's queue: ended attempts its hub has not taken, oldest first.
    pub async fn sync_queue(&self) -> Result<Vec<Attempt>> {
        let rows: Vec<AttemptRow> = crate::on_db!(&self.db, pool => sqlx::query_as(sqlx::AssertSqlSafe(format!("{ATTEMPT_COLUMNS} WHERE status <> 'running' AND synced_ns IS NULL ORDER BY id")))
            .fetch_all(pool).await)?;
        rows.into_iter().map(attempt).collect()
    }

    /// Records how the upload of attempt `id` went: taken by the hub (`Ok`), or why not
    /// (it stays queued).
    pub async fn set_synced(&self, id: i64, result: std::result::Result<(), &str>) -> Result<()> {
        let (synced, error) = match result {
            Ok(()) => (Some(now_ns()), None),
            Err(e) => (None, Some(e)),
        };
        crate::on_db!(&self.db, pool => sqlx::query("UPDATE attempts SET synced_ns = $1, sync_error = $2 WHERE id = $3")
            .bind(synced)
            .bind(error)
            .bind(id)
            .execute(pool).await.map(|_| ()))?;
        Ok(())
    }

    /// What the station sends of attempt `id` (made a global id first if it has none: an
    /// attempt from before ids).
    pub async fn upload_of(&self, id: i64) -> Result<AttemptUpload> {
        crate::on_db!(&self.db, pool => sqlx::query("UPDATE attempts SET uuid = $1 WHERE id = $2 AND uuid IS NULL")
            .bind(new_uuid()?)
            .bind(id)
            .execute(pool).await.map(|_| ()))?;
        let a = self.get_attempt(id).await?;
        let trainee = self.get_user(a.trainee_id).await?.name;
        let exercise = self.get_exercise(a.exercise_id).await?.name;
        let metrics = if a.status == AttemptStatus::Complete {
            self.attempt_metric_values(id).await?
        } else {
            Vec::new()
        };
        Ok(AttemptUpload {
            uuid: a.uuid.unwrap_or_default(),
            trainee,
            exercise,
            started_ns: a.started_ns,
            ended_ns: a.ended_ns,
            status: a.status,
            expert: a.expert,
            note: a.note,
            recording_sha256: a.recording_sha256,
            rrd_sha256: a.rrd_sha256,
            metrics,
        })
    }

    /// Takes an attempt uploaded by `station`: once per global id (a second upload answers
    /// with the attempt already there), the trainee created (without a password) if the hub
    /// does not know them (a name the hub gives an instructor or administrator is refused),
    /// the exercise the hub's own (unknown: an error), a complete attempt scored against the
    /// hub's thresholds. The recordings' keys are taken as given: the caller checks they are
    /// in its recording store.
    pub async fn import_attempt(&self, up: &AttemptUpload, station: &str) -> Result<Imported> {
        up.validate()?;
        if let Ok(a) = self.attempt_by_uuid(&up.uuid).await {
            // a retry; or the first upload stopped between insert and scoring
            return Ok(Imported {
                attempt: self.end_imported(a, up).await?,
                created: false,
            });
        }
        let exercise = match self.exercise_by_name(&up.exercise).await {
            Ok(e) => e,
            Err(AssessError::NotFound(_)) => {
                return Err(AssessError::InvalidInput(format!(
                    "this hub has no exercise {:?}",
                    up.exercise
                )));
            }
            Err(e) => return Err(e),
        };
        let trainee = match self.user_by_name(&up.trainee).await {
            Ok(u) => u,
            Err(AssessError::NotFound(_)) => {
                match self.create_user(&up.trainee, Role::Trainee, None).await {
                    Ok(u) => u,
                    // made meanwhile by another upload
                    Err(AssessError::Conflict(_)) => self.user_by_name(&up.trainee).await?,
                    Err(e) => return Err(e),
                }
            }
            Err(e) => return Err(e),
        };
        if trainee.role != Role::Trainee {
            return Err(AssessError::InvalidInput(format!(
                "{:?} is not a trainee on this hub",
                up.trainee
            )));
        }
        let id: Option<i64> = crate::on_db!(&self.db, pool => sqlx::query_scalar(
            "INSERT INTO attempts (trainee_id, exercise_id, started_ns, ended_ns, status, expert, note, recording_sha256, rrd_sha256, uuid, station) \
             VALUES ($1, $2, $3, $4, 'running', $5, $6, $7, $8, $9, $10) ON CONFLICT (uuid) DO NOTHING RETURNING id")
            .bind(trainee.id)
            .bind(exercise.id)
            .bind(up.started_ns)
            .bind(up.ended_ns)
            .bind(up.expert)
            .bind(&up.note)
            .bind(&up.recording_sha256)
            .bind(&up.rrd_sha256)
            .bind(&up.uuid)
            .bind(station)
            .fetch_optional(pool).await)?;
        let a = self.attempt_by_uuid(&up.uuid).await?;
        Ok(Imported {
            created: id == Some(a.id),
            attempt: self.end_imported(a, up).await?,
        })
    }

    /// Ends an imported attempt as it ended on its station, unless that is done.
    async fn end_imported(&self, a: Attempt, up: &AttemptUpload) -> Result<Attempt> {
        if a.status != AttemptStatus::Running {
            return Ok(a);
        }
        let ended = match up.status {
            AttemptStatus::Complete => self
                .finish_attempt(a.id, &up.metrics)
                .await
                .map(|o| o.attempt),
            AttemptStatus::Incomplete => self.mark_incomplete(a.id, up.note.as_deref()).await,
            AttemptStatus::Failed | AttemptStatus::Running => {
                let reason = up.note.as_deref().unwrap_or("failed on its station");
                self.mark_failed(a.id, reason).await
            }
        };
        match ended {
            Ok(a) => Ok(a),
            Err(AssessError::Conflict(m)) => {
                // ended meanwhile by a concurrent upload of the same attempt; anything else
                // that conflicts is this upload's own error
                let now = self.get_attempt(a.id).await?;
                if now.status == AttemptStatus::Running {
                    return Err(AssessError::Conflict(m));
                }
                Ok(now)
            }
            Err(e) => Err(e),
        }
    }

    /// A new station token `name`: the token, shown once (the hub keeps its hash).
    pub async fn create_station_token(&self, name: &str) -> Result<String> {
        let name = name.trim();
        if name.is_empty() || name.len() > 100 {
            return Err(AssessError::InvalidInput(
                "a station's name: 1 to 100 characters".into(),
            ));
        }
        let mut b = [0u8; 32];
        getrandom::fill(&mut b)
            .map_err(|e| AssessError::InvalidInput(format!("no randomness for a token: {e}")))?;
        let token = format!("cutlab-station-{}", crate::recordings::hex(&b));
        crate::on_db!(&self.db, pool => sqlx::query("INSERT INTO station_tokens (name, token_hash, created_ns) VALUES ($1, $2, $3)")
            .bind(name)
            .bind(token_hash(&token))
            .bind(now_ns())
            .execute(pool).await
            .map(|_| ())
            .map_err(super::conflict(|| format!("a station named {name:?} exists"))))?;
        Ok(token)
    }

    /// Revokes station `name`'s token: its uploads get 401 from now on.
    pub async fn revoke_station_token(&self, name: &str) -> Result<()> {
        let done = crate::on_db!(&self.db, pool => sqlx::query("UPDATE station_tokens SET revoked_ns = $1 WHERE name = $2 AND revoked_ns IS NULL")
            .bind(now_ns())
            .bind(name)
            .execute(pool).await.map(|r| r.rows_affected()))?;
        if done == 0 {
            return Err(AssessError::NotFound(format!(
                "a station {name:?} with a valid token"
            )));
        }
        Ok(())
    }

    /// The stations, by name.
    pub async fn list_station_tokens(&self) -> Result<Vec<StationToken>> {
        let rows: Vec<TokenRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, created_ns, revoked_ns, last_used_ns FROM station_tokens ORDER BY name")
            .fetch_all(pool).await)?;
        Ok(rows.into_iter().map(station_token).collect())
    }

    /// The station whose valid (not revoked) token is `token`, its use recorded; `None`
    /// for any other string.
    pub async fn station_by_token(&self, token: &str) -> Result<Option<StationToken>> {
        let row: Option<TokenRow> = crate::on_db!(&self.db, pool => sqlx::query_as("UPDATE station_tokens SET last_used_ns = $1 WHERE token_hash = $2 AND revoked_ns IS NULL RETURNING id, name, created_ns, revoked_ns, last_used_ns")
            .bind(now_ns())
            .bind(token_hash(token))
            .fetch_optional(pool).await)?;
        Ok(row.map(station_token))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uuids_are_v4_and_recognised() {
        let a = new_uuid().expect("uuid");
        let b = new_uuid().expect("uuid");
        assert_ne!(a, b);
        assert!(is_uuid(&a), "{a}");
        assert_eq!(&a[14..15], "4");
        assert!(matches!(&a[19..20], "8" | "9" | "a" | "b"), "{a}");
        assert!(!is_uuid(&a.to_uppercase()));
        assert!(!is_uuid(&a[1..]));
        assert!(!is_uuid("../../../../etc/passwd-and-some-more-xx"));
    }
}
