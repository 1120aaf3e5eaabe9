//! Recordings in an object store, through the `object_store` crate: a folder of the local
//! filesystem (the default), or an S3-compatible bucket by URL (`s3://bucket/prefix`, with
//! the usual `AWS_*` environment variables: `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
//! `AWS_REGION`, `AWS_ENDPOINT` for a server of one's own, `AWS_ALLOW_HTTP=true` for one
//! without TLS).
//!
//! Keys are content addresses, `PREFIX/sha256/<hex>` of the file's SHA-256, so a file stored
//! twice is one object, and every whole read is checked against its key.

use std::ops::Range;
use std::path::Path as FsPath;
use std::sync::Arc;

use bytes::Bytes;
use object_store::path::Path;
use object_store::{ObjectStore, PutPayload};
use sha2::{Digest, Sha256};

use crate::error::{AssessError, Result};

/// The environment variable naming the recording store when `--recordings` is not given.
pub const RECORDINGS_ENV: &str = "CUTLAB_RECORDINGS";

/// A content-addressed store of recordings.
#[derive(Debug, Clone)]
pub struct RecordingStore {
    store: Arc<dyn ObjectStore>,
    prefix: Path,
    /// Where, as the user gave it (for messages).
    location: String,
}

/// `bytes` in lowercase hex.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The SHA-256 of `bytes`, lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// Whether `key` is a SHA-256 in lowercase hex (64 digits): anything else is never looked up.
pub fn is_sha256_hex(key: &str) -> bool {
    key.len() == 64
        && key
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

fn store_error(location: &str) -> impl Fn(object_store::Error) -> AssessError + '_ {
    move |e| AssessError::Recordings(format!("{location}: {e}"))
}

impl RecordingStore {
    /// Opens the store at `location`: `s3://bucket[/prefix]`, or a folder (`file:///abs` or
    /// a path), created if missing.
    pub fn open(location: &str) -> Result<Self> {
        let location = location.trim();
        if location.is_empty() {
            return Err(AssessError::InvalidInput(
                "an empty recording store location".into(),
            ));
        }
        if let Some(rest) = location.strip_prefix("s3://") {
            let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
            if bucket.is_empty() {
                return Err(AssessError::InvalidInput(format!(
                    "{location}: no bucket named"
                )));
            }
            let s3 = object_store::aws::AmazonS3Builder::from_env()
                .with_bucket_name(bucket)
                .with_retry(object_store::RetryConfig {
                    // an unreachable bucket is reported in seconds, not after minutes
                    max_retries: 3,
                    retry_timeout: std::time::Duration::from_secs(15),
                    ..Default::default()
                })
                .build()
                .map_err(store_error(location))?;
            return Ok(Self {
                store: Arc::new(s3),
                prefix: Path::from(prefix.trim_matches('/')),
                location: location.to_owned(),
            });
        }
        let dir = location.strip_prefix("file://").unwrap_or(location);
        std::fs::create_dir_all(dir).map_err(|error| AssessError::Io {
            path: dir.to_owned(),
            error,
        })?;
        let fs = object_store::local::LocalFileSystem::new_with_prefix(dir)
            .map_err(store_error(location))?;
        sweep_staged(&FsPath::new(dir).join("sha256"));
        Ok(Self {
            store: Arc::new(fs),
            prefix: Path::default(),
            location: location.to_owned(),
        })
    }

    /// [`RecordingStore::open`] and [`RecordingStore::check`]: what a command does before it
    /// relies on the store.
    pub async fn connect(location: &str) -> Result<Self> {
        let store = Self::open(location)?;
        store.check().await?;
        Ok(store)
    }

    /// [`RecordingStore::connect`] when a location is given.
    pub async fn connect_if(location: Option<&str>) -> Result<Option<Self>> {
        match location {
            Some(at) => Self::connect(at).await.map(Some),
            None => Ok(None),
        }
    }

    /// Where the store is, as given.
    pub fn location(&self) -> &str {
        &self.location
    }

    /// Whether the store answers, so that a misconfigured store stops a command when it
    /// starts, not when its first attempt ends: a listing of a prefix that is never
    /// written (empty, on a store that works; an error for an unreachable server, a missing
    /// bucket or refused credentials).
    pub async fn check(&self) -> Result<()> {
        use futures_util::StreamExt as _;
        let probe = self.prefix.child("probe");
        match self.store.list(Some(&probe)).next().await {
            None | Some(Ok(_)) => Ok(()),
            Some(Err(e)) => Err(store_error(&self.location)(e)),
        }
    }

    fn key(&self, sha256: &str) -> Result<Path> {
        if !is_sha256_hex(sha256) {
            return Err(AssessError::InvalidInput(format!(
                "{sha256:?} is not a SHA-256 key"
            )));
        }
        Ok(self.prefix.child("sha256").child(sha256))
    }

    /// Stores `bytes` under their SHA-256 and returns the key. An object already there is
    /// written again (the same content: a damaged one is mended).
    pub async fn put(&self, bytes: Bytes) -> Result<String> {
        let sha = sha256_hex(&bytes);
        let key = self.key(&sha)?;
        self.store
            .put(&key, PutPayload::from(bytes))
            .await
            .map_err(store_error(&self.location))?;
        Ok(sha)
    }

    /// Stores the file at `path` ([`RecordingStore::put`]).
    pub async fn put_file(&self, path: &FsPath) -> Result<String> {
        let bytes = tokio::fs::read(path)
            .await
            .map_err(|error| AssessError::Io {
                path: path.display().to_string(),
                error,
            })?;
        self.put(Bytes::from(bytes)).await
    }

    /// The size in bytes of the object `sha256`.
    pub async fn size(&self, sha256: &str) -> Result<u64> {
        let key = self.key(sha256)?;
        match self.store.head(&key).await {
            Ok(meta) => Ok(meta.size),
            Err(object_store::Error::NotFound { .. }) => {
                Err(AssessError::NotFound(format!("recording {sha256}")))
            }
            Err(e) => Err(store_error(&self.location)(e)),
        }
    }

    /// The whole object `sha256`, checked against its key: a changed object is an error,
    /// never data.
    pub async fn get(&self, sha256: &str) -> Result<Bytes> {
        let key = self.key(sha256)?;
        let bytes = match self.store.get(&key).await {
            Ok(r) => r.bytes().await.map_err(store_error(&self.location))?,
            Err(object_store::Error::NotFound { .. }) => {
                return Err(AssessError::NotFound(format!("recording {sha256}")));
            }
            Err(e) => return Err(store_error(&self.location)(e)),
        };
        let actual = sha256_hex(&bytes);
        if actual != sha256 {
            return Err(AssessError::Recordings(format!(
                "{}: the object {sha256} has changed (its content hashes to {actual})",
                self.location
            )));
        }
        Ok(bytes)
    }

    /// Bytes `range` of the object `sha256` (a part cannot be checked against the key; keep
    /// `range` within [`RecordingStore::size`]).
    pub async fn get_range(&self, sha256: &str, range: Range<u64>) -> Result<Bytes> {
        let key = self.key(sha256)?;
        self.store
            .get_range(&key, range)
            .await
            .map_err(store_error(&self.location))
    }
}

/// How old a folder store's staged file must be to be taken for one a killed process left.
const STAGED_LEFT_AFTER: std::time::Duration = std::time::Duration::from_secs(600);

/// Whether `name` is a staged file of a folder store: the object's key, `#` and a number
/// (how `object_store` writes a file before it renames it into place).
fn is_staged(name: &str) -> bool {
    name.split_once('#').is_some_and(|(key, n)| {
        is_sha256_hex(key) && !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit())
    })
}

/// Removes from the folder `objects` the staged files a process killed mid-write left
/// (older than [`STAGED_LEFT_AFTER`]): never renamed into place, and never looked at again
/// (a retry stages a file of its own). Logged; a failure to remove one is only logged.
fn sweep_staged(objects: &FsPath) {
    let Ok(entries) = std::fs::read_dir(objects) else {
        return;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let old = entry
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= STAGED_LEFT_AFTER);
        if old && name.to_str().is_some_and(is_staged) {
            match std::fs::remove_file(entry.path()) {
                Ok(()) => removed += 1,
                Err(e) => tracing::warn!("removing {}: {e}", entry.path().display()),
            }
        }
    }
    if removed > 0 {
        tracing::info!(
            "{}: removed {removed} files a killed upload left half-written",
            objects.display()
        );
    }
}

impl crate::Store {
    /// Puts attempt `attempt_id`'s recording (its recorded path) and the `.rrd` beside it, if
    /// there is one, into `recordings` and records their keys. The files stay where they are.
    pub async fn keep_recordings(
        &self,
        attempt_id: i64,
        recordings: &RecordingStore,
    ) -> Result<crate::store::Attempt> {
        let a = self.get_attempt(attempt_id).await?;
        let Some((mcap, rrd)) = a.recording_files() else {
            return Err(AssessError::NotFound(format!(
                "attempt {attempt_id} has no recording"
            )));
        };
        let mcap_key = recordings.put_file(&mcap).await?;
        let rrd_key = if rrd.is_file() {
            Some(recordings.put_file(&rrd).await?)
        } else {
            None
        };
        self.set_recording_keys(attempt_id, Some(&mcap_key), rrd_key.as_deref())
            .await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_killed_writes_staged_file_goes_when_the_store_opens_again() {
        let dir = tempfile::tempdir().expect("folder");
        let at = dir.path().join("recordings");
        let objects = at.join("sha256");
        std::fs::create_dir_all(&objects).expect("objects");
        let sha = sha256_hex(b"x");
        let left = objects.join(format!("{sha}#1"));
        let fresh = objects.join(format!("{sha}#2"));
        let other = objects.join("notes.txt#1");
        for f in [&left, &fresh, &other] {
            std::fs::write(f, b"").expect("file");
        }
        let old = std::time::SystemTime::now() - 2 * STAGED_LEFT_AFTER;
        for f in [&left, &other] {
            std::fs::File::options()
                .write(true)
                .open(f)
                .and_then(|f| f.set_modified(old))
                .expect("age");
        }
        RecordingStore::open(at.to_str().expect("utf-8")).expect("store");
        assert!(!left.exists(), "the killed write's file is gone");
        assert!(fresh.exists(), "a write that may be under way stays");
        assert!(other.exists(), "what the store did not write stays");
        assert!(is_staged(&format!("{sha}#12")) && !is_staged(&format!("{sha}#")));
        assert!(!is_staged(&sha) && !is_staged(&format!("{sha}#1a")));
    }

    #[test]
    fn keys_are_sha256_hex_only() {
        let sha = sha256_hex(b"abc");
        assert_eq!(
            sha,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(is_sha256_hex(&sha));
        assert!(!is_sha256_hex(&sha.to_uppercase()));
        assert!(!is_sha256_hex("../../etc/passwd"));
        assert!(!is_sha256_hex(&sha[1..]));
    }

    #[tokio::test]
    async fn a_folder_store_keeps_checks_and_serves_ranges() {
        let dir = tempfile::tempdir().expect("folder");
        let at = dir.path().join("recordings");
        let store = RecordingStore::open(at.to_str().expect("utf-8")).expect("store");
        let data = Bytes::from_static(b"MCAP bytes of a session");
        let sha = store.put(data.clone()).await.expect("put");
        assert_eq!(sha, sha256_hex(&data));
        assert_eq!(
            store.put(data.clone()).await.expect("again"),
            sha,
            "one object"
        );
        assert_eq!(store.get(&sha).await.expect("get"), data);
        assert_eq!(store.size(&sha).await.expect("size"), data.len() as u64);
        assert_eq!(
            store.get_range(&sha, 5..10).await.expect("range"),
            Bytes::from_static(b"bytes")
        );
        // a file changed behind the store's back is refused
        let object = at.join("sha256").join(&sha);
        std::fs::write(&object, b"MCAP bytes of another one").expect("tamper");
        let err = store.get(&sha).await.expect_err("changed");
        assert!(err.to_string().contains("has changed"), "{err}");
        let missing = sha256_hex(b"nothing");
        assert!(matches!(
            store.get(&missing).await,
            Err(AssessError::NotFound(_))
        ));
        assert!(matches!(
            store.get("../secret").await,
            Err(AssessError::InvalidInput(_))
        ));
    }

    #[test]
    fn bad_locations_are_refused() {
        assert!(RecordingStore::open("  ").is_err());
        assert!(RecordingStore::open("s3:///prefix").is_err());
    }
}
