//! The recording store on a folder and on a real S3-compatible server: the one
//! `$CUTLAB_TEST_S3` names (`s3://bucket`, with the `AWS_*` variables of that server; CI
//! starts one), skipped without it.

use bytes::Bytes;
use cutlab_assessor::recordings::{RecordingStore, sha256_hex};
use cutlab_assessor::store::Role;
use cutlab_assessor::{AssessError, Store};
use object_store::ObjectStore as _;

/// The variable naming the S3 bucket the tests may write to.
const TEST_S3_ENV: &str = "CUTLAB_TEST_S3";

/// A store and an attempt whose recording (`.mcap`, and an `.rrd` beside it) is in `dir`.
async fn attempt_with_recordings(dir: &std::path::Path) -> (Store, i64, Vec<u8>, Vec<u8>) {
    let store = Store::open(&dir.join("cutlab.db")).await.expect("store");
    store.ensure_builtins().await.expect("builtins");
    let exercise = store.list_exercises().await.expect("exercises")[0].id;
    let trainee = store
        .create_user("trainee", Role::Trainee, None)
        .await
        .expect("trainee");
    let mcap_bytes: Vec<u8> = (0..200_000u32)
        .flat_map(|i| (i * 7).to_le_bytes())
        .collect();
    let rrd_bytes = b"RRF2 a viewer's recording".to_vec();
    let mcap = dir.join("attempt.mcap");
    std::fs::write(&mcap, &mcap_bytes).expect("mcap");
    std::fs::write(mcap.with_extension("rrd"), &rrd_bytes).expect("rrd");
    let a = store
        .start_attempt(trainee.id, exercise, mcap.to_str(), false)
        .await
        .expect("attempt");
    (store, a.id, mcap_bytes, rrd_bytes)
}

/// What every store must do: keep an attempt's recordings under their hashes, once, serve
/// them whole and in ranges, and refuse keys that are not hashes.
async fn keeps_and_serves(recordings: &RecordingStore) {
    let dir = tempfile::tempdir().expect("folder");
    let (store, id, mcap, rrd) = attempt_with_recordings(dir.path()).await;
    let a = store.keep_recordings(id, recordings).await.expect("kept");
    let mcap_key = a.recording_sha256.expect("mcap key");
    assert_eq!(mcap_key, sha256_hex(&mcap));
    assert_eq!(a.rrd_sha256.as_deref(), Some(sha256_hex(&rrd).as_str()));
    // the keys are in the database, not only in the answer
    let again = store.get_attempt(id).await.expect("attempt");
    assert_eq!(again.recording_sha256.as_deref(), Some(mcap_key.as_str()));
    // kept twice, one object
    let a = store.keep_recordings(id, recordings).await.expect("again");
    assert_eq!(a.recording_sha256.as_deref(), Some(mcap_key.as_str()));
    assert_eq!(recordings.get(&mcap_key).await.expect("whole"), mcap);
    assert_eq!(
        recordings.size(&mcap_key).await.expect("size"),
        mcap.len() as u64
    );
    let part = recordings
        .get_range(&mcap_key, 1000..1016)
        .await
        .expect("range");
    assert_eq!(&part[..], &mcap[1000..1016]);
    assert!(matches!(
        recordings.get(&sha256_hex(b"never stored")).await,
        Err(AssessError::NotFound(_))
    ));
    assert!(matches!(
        recordings.get("../cutlab.db").await,
        Err(AssessError::InvalidInput(_))
    ));
}

#[tokio::test]
async fn recordings_in_a_folder() {
    let dir = tempfile::tempdir().expect("folder");
    let at = dir.path().join("recordings");
    let recordings = RecordingStore::connect(at.to_str().expect("utf-8"))
        .await
        .expect("store");
    keeps_and_serves(&recordings).await;
}

#[tokio::test]
async fn recordings_in_an_s3_bucket() {
    let Some(bucket_url) = std::env::var(TEST_S3_ENV).ok().filter(|v| !v.is_empty()) else {
        println!("skipped: ${TEST_S3_ENV} names no S3 bucket to test on");
        return;
    };
    // a prefix of this run's own
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("clock")
        .as_nanos();
    let prefix = format!("test-{nanos}");
    let location = format!("{}/{prefix}", bucket_url.trim_end_matches('/'));
    let recordings = RecordingStore::connect(&location).await.expect("bucket");
    keeps_and_serves(&recordings).await;

    // an object changed in the bucket behind the store's back is refused, not served
    let bucket = bucket_url
        .trim_start_matches("s3://")
        .split('/')
        .next()
        .expect("bucket");
    let raw = object_store::aws::AmazonS3Builder::from_env()
        .with_bucket_name(bucket)
        .build()
        .expect("raw client");
    let data = Bytes::from_static(b"the original recording");
    let key = recordings.put(data.clone()).await.expect("put");
    let path = object_store::path::Path::from(format!("{prefix}/sha256/{key}"));
    raw.put(&path, Bytes::from_static(b"another recording").into())
        .await
        .expect("tamper");
    let err = recordings.get(&key).await.expect_err("changed object");
    assert!(err.to_string().contains("has changed"), "{err}");

    // a bucket that does not exist is found out when the store is opened
    let missing = format!("s3://no-such-bucket-{nanos}");
    let err = RecordingStore::connect(&missing)
        .await
        .expect_err("missing bucket");
    assert!(err.to_string().contains(&missing), "{err}");
}
