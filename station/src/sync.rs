//! A station's uploads to its hub: offline first. The station records and scores in its own
//! database; its queue is the ended attempts the hub has not taken (kept in that database,
//! so it survives restarts). [`sync`] sends each one: its recordings first
//! (`PUT /api/hub/recordings/{sha256}`), then the attempt (`PUT /api/hub/attempts/{uuid}`),
//! with the station's token. The hub takes an attempt once per id, so a retry after a lost
//! answer never makes a second attempt.
//!
//! What stops a sync, everything still queued: a refused token (401), a hub that cannot be
//! reached or answers 5xx. What leaves one attempt queued with its reason and goes on to the
//! next: the hub refusing it (a recording whose content does not match its key, an exercise
//! the hub lacks), or its recording missing on this machine.

use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use cutlab_assessor::AssessError;
use cutlab_assessor::recordings::{RecordingStore, sha256_hex};
use cutlab_assessor::store::{Attempt, Store};
use serde::Serialize;

/// The environment variable naming the hub (`--hub`).
pub const HUB_ENV: &str = "CUTLAB_HUB";
/// The environment variable holding the station's token (`--hub-token`).
pub const HUB_TOKEN_ENV: &str = "CUTLAB_HUB_TOKEN";

/// A hub and this station's token for it.
#[derive(Clone)]
pub struct Hub {
    base: String,
    token: String,
    client: reqwest::Client,
    /// One sync at a time from this process (after each attempt, and `cutlab sync`).
    busy: Arc<tokio::sync::Mutex<()>>,
}

impl std::fmt::Debug for Hub {
    // never the token
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Hub").field("url", &self.base).finish()
    }
}

/// Why a sync stopped (the queue is as it was, less what was taken).
#[derive(Debug, thiserror::Error)]
pub enum SyncError {
    #[error(
        "the hub {hub} refused this station's token (401: missing, wrong or revoked); {queued} attempt(s) stay queued"
    )]
    TokenRefused { hub: String, queued: usize },
    #[error("the hub {hub} cannot be reached ({detail}); {queued} attempt(s) stay queued")]
    Unreachable {
        hub: String,
        detail: String,
        queued: usize,
    },
    #[error("{0}")]
    Config(String),
    #[error(transparent)]
    Assess(#[from] AssessError),
}

/// What a sync did.
#[derive(Debug, Default, Clone, PartialEq, Serialize)]
pub struct SyncReport {
    /// Attempts the hub took now.
    pub uploaded: usize,
    /// Attempts the hub had already (a retry after a lost answer).
    pub already: usize,
    /// Attempts left queued, with why (the hub refused them, or a recording is missing).
    pub refused: Vec<(i64, String)>,
}

/// How one request ended, short of stopping the sync.
enum Answer {
    Taken { created: bool },
    Refused(String),
}

impl Hub {
    /// The hub at `url` (`http://` or `https://`), this station's `token`.
    pub fn new(url: &str, token: &str) -> Result<Self, SyncError> {
        let base = url.trim().trim_end_matches('/');
        if !(base.starts_with("http://") || base.starts_with("https://")) || base.len() < 10 {
            return Err(SyncError::Config(format!(
                "{url:?}: a hub is an http:// or https:// URL"
            )));
        }
        let token = token.trim();
        if token.is_empty() {
            return Err(SyncError::Config(format!(
                "no station token for the hub {base} (--hub-token or ${HUB_TOKEN_ENV})"
            )));
        }
        let client = reqwest::Client::builder()
            .connect_timeout(Duration::from_secs(5))
            .timeout(Duration::from_secs(600))
            .build()
            .map_err(|e| SyncError::Config(format!("an HTTP client: {e}")))?;
        Ok(Self {
            base: base.to_owned(),
            token: token.to_owned(),
            client,
            busy: Arc::default(),
        })
    }

    /// The hub's URL.
    pub fn url(&self) -> &str {
        &self.base
    }

    /// `PUT path` with `body`; `Err` stops the sync.
    async fn put(
        &self,
        path: &str,
        body: Bytes,
        json: bool,
        queued: usize,
    ) -> Result<Answer, SyncError> {
        let mut req = self
            .client
            .put(format!("{}{path}", self.base))
            .bearer_auth(&self.token)
            .body(body);
        if json {
            req = req.header(reqwest::header::CONTENT_TYPE, "application/json");
        }
        let unreachable = |detail: String| SyncError::Unreachable {
            hub: self.base.clone(),
            detail,
            queued,
        };
        let response = req.send().await.map_err(|e| unreachable(causes(&e)))?;
        let status = response.status();
        let text = response.text().await.unwrap_or_default();
        let message = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| v["error"].as_str().map(str::to_owned))
            .unwrap_or_else(|| text.chars().take(200).collect());
        match status.as_u16() {
            200 => Ok(Answer::Taken { created: false }),
            201 => Ok(Answer::Taken { created: true }),
            401 => Err(SyncError::TokenRefused {
                hub: self.base.clone(),
                queued,
            }),
            // the hub's trouble or a timeout (408: the upload stalled), not the attempt's
            s if s >= 500 || matches!(s, 404 | 405 | 408 | 429) => {
                Err(unreachable(format!("it answered {status}: {message}")))
            }
            _ => Ok(Answer::Refused(format!(
                "the hub answered {status}: {message}"
            ))),
        }
    }
}

/// An error and its causes, on one line.
fn causes(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let text = s.to_string();
        if !out.contains(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
        source = s.source();
    }
    out
}

/// One of the attempt's recordings: from the recording store by its key when this station
/// has one, else the file; `Ok(None)`: the attempt has none.
async fn recording(
    a: &Attempt,
    rrd: bool,
    recordings: Option<&RecordingStore>,
) -> Result<Option<(String, Bytes)>, String> {
    let key = if rrd {
        a.rrd_sha256.as_deref()
    } else {
        a.recording_sha256.as_deref()
    };
    if let (Some(key), Some(store)) = (key, recordings)
        && let Ok(bytes) = store.get(key).await
    {
        return Ok(Some((key.to_owned(), bytes)));
    }
    let Some((mcap, rrd_path)) = a.recording_files() else {
        return Ok(None);
    };
    let path = if rrd { rrd_path } else { mcap };
    match tokio::fs::read(&path).await {
        // the key on record if there is one: a file changed since is refused by the hub
        Ok(bytes) => Ok(Some((
            key.map_or_else(|| sha256_hex(&bytes), str::to_owned),
            Bytes::from(bytes),
        ))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound && (rrd || key.is_none()) => {
            // no .rrd recorded; or a session that failed before it wrote a file
            Ok(None)
        }
        Err(e) => Err(format!("its recording {}: {e}", path.display())),
    }
}

/// Sends the station's whole queue to `hub`, oldest first, the attempts the hub refused
/// before too (`cutlab sync`: after the hub's administrator has put right why); see the
/// module's documentation.
pub async fn sync(
    store: &Store,
    hub: &Hub,
    recordings: Option<&RecordingStore>,
) -> Result<SyncReport, SyncError> {
    send(store, hub, recordings, true).await
}

/// [`sync`] without the attempts the hub refused before: what runs after each attempt and
/// every [`RETRY_EVERY`], so that a refused recording is not sent again and again.
pub async fn sync_new(
    store: &Store,
    hub: &Hub,
    recordings: Option<&RecordingStore>,
) -> Result<SyncReport, SyncError> {
    send(store, hub, recordings, false).await
}

/// How often a station server tries its queue while it runs ([`keep_syncing`]).
pub const RETRY_EVERY: Duration = Duration::from_secs(60);

/// [`sync_new`] now and every `every`, for as long as the server runs: a hub that was down
/// gets the queue once it is back, without a new attempt or a hand on the station.
pub async fn keep_syncing(
    store: Store,
    hub: Hub,
    recordings: Option<RecordingStore>,
    every: Duration,
) {
    let mut tick = tokio::time::interval(every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_error = String::new();
    loop {
        tick.tick().await;
        match sync_new(&store, &hub, recordings.as_ref()).await {
            Ok(r) => {
                if r.uploaded + r.already > 0 {
                    tracing::info!("sent to the hub {}: {r:?}", hub.url());
                }
                last_error.clear();
            }
            Err(e) => {
                // said once while it lasts, not every minute
                let e = e.to_string();
                if e != last_error {
                    tracing::warn!("{e}");
                    last_error = e;
                }
            }
        }
    }
}

async fn send(
    store: &Store,
    hub: &Hub,
    recordings: Option<&RecordingStore>,
    refused_too: bool,
) -> Result<SyncReport, SyncError> {
    let _one_at_a_time = hub.busy.lock().await;
    // an attempt whose station died mid-session is ended first, so that it is sent too
    crate::attempt::end_abandoned_and_say(store, recordings).await;
    let mut queue = store.sync_queue().await?;
    if !refused_too {
        queue.retain(|a| a.sync_error.is_none());
    }
    let mut report = SyncReport::default();
    for (i, a) in queue.iter().enumerate() {
        let left = queue.len() - i;
        let mut up = store.upload_of(a.id).await?;
        let mut refused = None;
        for rrd in [false, true] {
            match recording(a, rrd, recordings).await {
                Ok(Some((key, bytes))) => {
                    let path = format!("/api/hub/recordings/{key}");
                    match hub.put(&path, bytes, false, left).await? {
                        Answer::Taken { .. } => {}
                        Answer::Refused(why) => {
                            refused = Some(why);
                            break;
                        }
                    }
                    if rrd {
                        up.rrd_sha256 = Some(key);
                    } else {
                        up.recording_sha256 = Some(key);
                    }
                }
                Ok(None) => {}
                Err(why) => {
                    refused = Some(why);
                    break;
                }
            }
        }
        if refused.is_none() {
            let body = serde_json::to_vec(&up).map_err(|e| SyncError::Config(e.to_string()))?;
            let path = format!("/api/hub/attempts/{}", up.uuid);
            match hub.put(&path, Bytes::from(body), true, left).await? {
                Answer::Taken { created } => {
                    store.set_synced(a.id, Ok(())).await?;
                    if created {
                        report.uploaded += 1;
                    } else {
                        report.already += 1;
                    }
                }
                Answer::Refused(why) => refused = Some(why),
            }
        }
        if let Some(why) = refused {
            tracing::warn!("attempt {} stays queued for {}: {why}", a.id, hub.url());
            store.set_synced(a.id, Err(&why)).await?;
            report.refused.push((a.id, why));
        }
    }
    Ok(report)
}
