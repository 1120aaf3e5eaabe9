//! Stations and hub: each attempt has a global id (a UUID made where it was recorded), a
//! station keeps a queue of the attempts its hub has not taken yet (in its own database, so
//! it survives restarts), and a hub takes uploads from stations that hold a token of their
//! own, each attempt once however often it is sent.

use serde::{Deserialize, Serialize};

use super::attempts::{ATTEMPT_COLUMNS, Attempt, AttemptRow, AttemptStatus, attempt, score_in_tx};
use super::{BeginWrite, Role, Store, now_ns};
use crate::error::{AssessError, Result};
use crate::recordings::is_sha256_hex;
use cutlab_scoring::metrics::MetricValue;

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
    /// The station's mode (`guided` or `exam`), if recorded.
    #[serde(default)]
    pub mode: Option<String>,
    /// The device the attempt was made with, if recorded (its class picks the thresholds the
    /// hub scores it by).
    #[serde(default)]
    pub device: Option<String>,
}

/// The earliest time an attempt may have started: 2020-01-01 (cutlab did not exist).
const EARLIEST_NS: i64 = 1_577_836_800 * 1_000_000_000;
/// The longest an attempt may last.
pub const MAX_ATTEMPT_NS: i64 = 24 * 3600 * 1_000_000_000;
/// How far ahead of the hub's clock a station's may be.
pub const CLOCK_SKEW_NS: i64 = 10 * 60 * 1_000_000_000;
/// The longest device name an upload may carry, in characters.
const MAX_DEVICE_CHARS: usize = 200;

impl AttemptUpload {
    /// Refuses what a hub must never store: a malformed id or key, a running attempt, times
    /// out of order, in the future or before 2020, names that are no user's names, unknown,
    /// repeated, non-finite or physically impossible metrics ([`check_metric`]). `now_ns` is
    /// the hub's clock.
    pub fn validate(&self, now_ns: i64) -> Result<()> {
        let bad = |m: String| Err(AssessError::InvalidInput(m));
        if !is_uuid(&self.uuid) {
            return bad(format!(
                "{:?} is not an attempt id (a UUID)",
                short(&self.uuid)
            ));
        }
        if self.status == AttemptStatus::Running {
            return bad(format!("attempt {} has not ended", self.uuid));
        }
        for key in [&self.recording_sha256, &self.rrd_sha256]
            .into_iter()
            .flatten()
        {
            if !is_sha256_hex(key) {
                return bad(format!("{:?} is not a recording key (SHA-256)", short(key)));
            }
        }
        if super::names::check_name(&self.trainee)? != self.trainee {
            return bad(format!("the trainee's name {:?}", short(&self.trainee)));
        }
        if self.exercise.trim().is_empty() || self.exercise.len() > 200 {
            return bad(format!("the exercise's name {:?}", short(&self.exercise)));
        }
        if let Some(note) = &self.note {
            super::text::text("the attempt's note", note, super::text::MAX_NOTE_CHARS)?;
        }
        if self
            .mode
            .as_deref()
            .is_some_and(|m| !matches!(m, "guided" | "exam"))
        {
            return bad("the mode is guided or exam".into());
        }
        if self.device.as_deref().is_some_and(|d| {
            d.is_empty() || d.chars().count() > MAX_DEVICE_CHARS || d.chars().any(char::is_control)
        }) {
            return bad(format!(
                "the device's name: 1 to {MAX_DEVICE_CHARS} printable characters"
            ));
        }
        if self.expert {
            // an expert's reference attempt sets the exercise's thresholds: recorded on the
            // hub itself, never uploaded with a station's token
            return bad("expert reference attempts are not taken from stations".into());
        }
        self.check_times(now_ns)?;
        if self.status == AttemptStatus::Complete && self.recording_sha256.is_none() {
            return bad("a complete attempt comes with its recording (the hub scores it)".into());
        }
        if self.metrics.len() > cutlab_scoring::metrics::all().count() {
            return bad(format!(
                "{} metrics: more than there are",
                self.metrics.len()
            ));
        }
        let mut keys: Vec<&str> = self.metrics.iter().map(|m| m.key.as_str()).collect();
        keys.sort_unstable();
        if let Some(w) = keys.windows(2).find(|w| w[0] == w[1]) {
            return bad(format!("metric {:?} given twice", w[0]));
        }
        self.metrics.iter().try_for_each(check_metric)
    }

    /// Started after 2020 and not in the future, ended after it started, within a day.
    fn check_times(&self, now_ns: i64) -> Result<()> {
        let latest = now_ns.saturating_add(CLOCK_SKEW_NS);
        let ended = self.ended_ns.ok_or_else(|| {
            AssessError::InvalidInput(format!("attempt {} has no end time", self.uuid))
        })?;
        let why = if !(EARLIEST_NS..=latest).contains(&self.started_ns) {
            "started before 2020 or in the future"
        } else if ended < self.started_ns {
            "ended before it started"
        } else if ended > latest {
            "ended in the future"
        } else if ended - self.started_ns > MAX_ATTEMPT_NS {
            "lasted more than a day"
        } else {
            return Ok(());
        };
        Err(AssessError::InvalidInput(format!(
            "attempt {} {why} (started {}, ended {})",
            self.uuid, self.started_ns, ended
        )))
    }
}

/// At most 64 characters of `s`, for an error message about a value a client sent.
fn short(s: &str) -> String {
    s.chars().take(64).collect()
}

/// A metric a station may send: in the catalogue, in its unit, finite, and within what is
/// physically possible for its unit (lengths within 10 m, times within a day, forces within
/// 1 kN, angles within a turn; times, forces, areas and one-sided lengths not negative).
pub fn check_metric(m: &MetricValue) -> Result<()> {
    let bad = |why: &str| {
        Err(AssessError::InvalidInput(format!(
            "metric {:?}: {why}",
            short(&m.key)
        )))
    };
    let Some(def) = cutlab_scoring::metrics::metric(&m.key) else {
        return bad("not a metric of this hub");
    };
    if m.unit != def.unit {
        return bad(&format!("unit {:?}, not {:?}", short(&m.unit), def.unit));
    }
    if m.missing.as_ref().is_some_and(|w| w.len() > 500) {
        return bad("a reason longer than 500 bytes");
    }
    let Some(v) = m.value else { return Ok(()) };
    let (limit, signed) = match def.unit {
        "m" => (
            10.0,
            def.better == cutlab_scoring::metrics::Better::TwoSided,
        ),
        "s" => (86_400.0, false),
        "N" => (1_000.0, false),
        "m^2" => (100.0, false),
        "deg" => (360.0, true),
        "rad" => (1e4, false),
        _ => (1e6, true),
    };
    if !v.is_finite() || v.abs() > limit || (!signed && v < 0.0) {
        return bad(&format!("{v} {} is not possible", def.unit));
    }
    Ok(())
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
            mode: a.mode,
            device: a.device,
        })
    }

    /// The attempt with global id `uuid` if the hub holds it, as a retry of `station`'s
    /// sees it: `Ok(None)` if absent, a [`AssessError::Conflict`] if another station (or this
    /// hub itself) recorded it.
    pub async fn imported_by(&self, uuid: &str, station: &str) -> Result<Option<Attempt>> {
        match self.attempt_by_uuid(uuid).await {
            Ok(a) if a.station.as_deref() == Some(station) => Ok(Some(a)),
            Ok(_) => Err(AssessError::Conflict(format!(
                "attempt {uuid} belongs to another station"
            ))),
            Err(AssessError::NotFound(_)) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Takes an attempt uploaded by `station`, in one transaction (a crash leaves it absent
    /// or whole): once per global id (a retry answers with the attempt the hub holds; another
    /// station's id is a conflict), the trainee created (without a password) if the hub does
    /// not know them (a name the hub gives an instructor or administrator, or one that looks
    /// like another user's, is refused), the exercise the hub's own (unknown: an error). A
    /// complete attempt is scored with `metrics`, which the caller measured from the
    /// attempt's recording (the station's own are checked, [`AttemptUpload::validate`], and
    /// not used), against the hub's thresholds; its recording may score no other attempt.
    /// The recordings' keys are taken as given: the caller checks that `station` uploaded
    /// them.
    pub async fn import_attempt(
        &self,
        up: &AttemptUpload,
        station: &str,
        metrics: &[MetricValue],
    ) -> Result<Imported> {
        up.validate(now_ns())?;
        if let Some(a) = self.imported_by(&up.uuid, station).await? {
            // a retry; or a hub from before imports were one transaction stopped between
            // its insert and its scoring
            return Ok(Imported {
                attempt: self.end_imported(a, up, metrics).await?,
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
        let trainee = self.trainee_named(&up.trainee).await?;
        if trainee.role != Role::Trainee {
            return Err(AssessError::InvalidInput(format!(
                "{:?} is not a trainee on this hub",
                up.trainee
            )));
        }
        let verdict = match up.status {
            AttemptStatus::Complete => {
                let class = cutlab_scoring::DeviceClass::of(up.device.as_deref());
                Some(
                    self.thresholds_for(exercise.id, class)
                        .await?
                        .verdict(metrics),
                )
            }
            _ => None,
        };
        let id = self
            .insert_imported(
                up,
                station,
                trainee.id,
                exercise.id,
                verdict.as_ref(),
                metrics,
            )
            .await?;
        let a = self.attempt_by_uuid(&up.uuid).await?;
        if id.is_none() && a.station.as_deref() != Some(station) {
            return Err(AssessError::Conflict(format!(
                "attempt {} belongs to another station",
                up.uuid
            )));
        }
        Ok(Imported {
            created: id == Some(a.id),
            attempt: a,
        })
    }

    /// Inserts an imported attempt as it ended, scored with `verdict` when complete, in one
    /// transaction; `None` if the id was taken meanwhile (a concurrent upload).
    async fn insert_imported(
        &self,
        up: &AttemptUpload,
        station: &str,
        trainee_id: i64,
        exercise_id: i64,
        verdict: Option<&cutlab_scoring::proficiency::Verdict>,
        metrics: &[MetricValue],
    ) -> Result<Option<i64>> {
        let note = match up.status {
            AttemptStatus::Failed if up.note.is_none() => Some("failed on its station"),
            _ => up.note.as_deref(),
        };
        // complete once scored, below, in the same transaction
        let status = match up.status {
            AttemptStatus::Complete => AttemptStatus::Running,
            s => s,
        };
        let id = crate::on_db!(&self.db, pool => {
            let mut tx = pool.begin_write().await?;
            if let Some(key) = &up.recording_sha256 {
                let other: Option<String> = sqlx::query_scalar("SELECT uuid FROM attempts WHERE recording_sha256 = $1 AND uuid <> $2")
                    .bind(key)
                    .bind(&up.uuid)
                    .fetch_optional(&mut *tx)
                    .await?;
                if other.is_some() {
                    return Err(AssessError::Conflict(format!(
                        "recording {key} is another attempt's"
                    )));
                }
            }
            let id: Option<i64> = sqlx::query_scalar(
                "INSERT INTO attempts (trainee_id, exercise_id, started_ns, ended_ns, status, expert, note, recording_sha256, rrd_sha256, uuid, station, mode, device) \
                 VALUES ($1, $2, $3, $4, $5, FALSE, $6, $7, $8, $9, $10, $11, $12) ON CONFLICT (uuid) DO NOTHING RETURNING id")
                .bind(trainee_id)
                .bind(exercise_id)
                .bind(up.started_ns)
                .bind(up.ended_ns)
                .bind(status.as_str())
                .bind(note)
                .bind(&up.recording_sha256)
                .bind(&up.rrd_sha256)
                .bind(&up.uuid)
                .bind(station)
                .bind(&up.mode)
                .bind(&up.device)
                .fetch_optional(&mut *tx)
                .await?;
            if let (Some(id), Some(verdict)) = (id, verdict) {
                score_in_tx!(tx, id, trainee_id, exercise_id, verdict, metrics, None);
            }
            tx.commit().await?;
            id
        });
        Ok(id)
    }

    /// Ends an imported attempt as it ended on its station, unless that is done (an attempt
    /// a hub from before one-transaction imports left running).
    async fn end_imported(
        &self,
        a: Attempt,
        up: &AttemptUpload,
        metrics: &[MetricValue],
    ) -> Result<Attempt> {
        if a.status != AttemptStatus::Running {
            return Ok(a);
        }
        let ended = match up.status {
            AttemptStatus::Complete => self.finish_attempt(a.id, metrics).await.map(|o| o.attempt),
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

    /// Records that `station` uploaded the recording `sha256`; `false` if it had already.
    pub async fn own_recording(&self, sha256: &str, station: &str) -> Result<bool> {
        let done = crate::on_db!(&self.db, pool => sqlx::query("INSERT INTO recording_owners (sha256, station, uploaded_ns) VALUES ($1, $2, $3) ON CONFLICT (sha256, station) DO NOTHING")
            .bind(sha256)
            .bind(station)
            .bind(now_ns())
            .execute(pool).await.map(|r| r.rows_affected()))?;
        Ok(done > 0)
    }

    /// Whether `station` uploaded the recording `sha256`.
    pub async fn owns_recording(&self, sha256: &str, station: &str) -> Result<bool> {
        let n: i64 = crate::on_db!(&self.db, pool => sqlx::query_scalar("SELECT COUNT(*) FROM recording_owners WHERE sha256 = $1 AND station = $2")
            .bind(sha256)
            .bind(station)
            .fetch_one(pool).await)?;
        Ok(n > 0)
    }

    /// A new station token `name`: the token, shown once (the hub keeps its hash).
    pub async fn create_station_token(&self, name: &str) -> Result<String> {
        let name = super::text::label("a station's name", name, 100)?;
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

    /// The station whose valid (not revoked) token is `token`, its use recorded (at most
    /// once a minute: a read does not wait for the write lock); `None` for any other string.
    pub async fn station_by_token(&self, token: &str) -> Result<Option<StationToken>> {
        let row: Option<TokenRow> = crate::on_db!(&self.db, pool => sqlx::query_as("SELECT id, name, created_ns, revoked_ns, last_used_ns FROM station_tokens WHERE token_hash = $1 AND revoked_ns IS NULL")
            .bind(token_hash(token))
            .fetch_optional(pool).await)?;
        let Some(mut station) = row.map(station_token) else {
            return Ok(None);
        };
        let now = now_ns();
        if station
            .last_used_ns
            .is_none_or(|t| now.saturating_sub(t) > LAST_USED_EVERY_NS)
        {
            crate::on_db!(&self.db, pool => sqlx::query("UPDATE station_tokens SET last_used_ns = $1 WHERE id = $2")
                .bind(now)
                .bind(station.id)
                .execute(pool).await.map(|_| ()))?;
            station.last_used_ns = Some(now);
        }
        Ok(Some(station))
    }

    /// Whether station `id`'s token is still valid (not revoked since it was checked).
    pub async fn station_token_valid(&self, id: i64) -> Result<bool> {
        let row: Option<i64> = crate::on_db!(&self.db, pool => sqlx::query_scalar("SELECT id FROM station_tokens WHERE id = $1 AND revoked_ns IS NULL")
            .bind(id)
            .fetch_optional(pool).await)?;
        Ok(row.is_some())
    }
}

/// How often a token's `last_used_ns` is written.
const LAST_USED_EVERY_NS: i64 = 60 * 1_000_000_000;

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
