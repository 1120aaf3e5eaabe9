//! Stations and hub: the hub's upload calls (through `oneshot`) and a station's sync against
//! a hub served on a real socket.
#![allow(clippy::unwrap_used)]

mod common;

use axum::body::Body;
use axum::http::{Method, Request, StatusCode, header};
use common::*;
use cutlab_dashboard::Config;
use cutlab_dashboard::assessor::recordings::{RecordingStore, sha256_hex};
use cutlab_dashboard::assessor::store::{AttemptStatus, BUILTIN_EXERCISE, Role, Store};
use cutlab_station::sync::{Hub, SyncError, SyncReport, sync, sync_new};

fn put(path: &str, token: Option<&str>, body: Vec<u8>) -> Request<Body> {
    let mut b = Request::builder().method(Method::PUT).uri(path);
    if let Some(t) = token {
        b = b.header(header::AUTHORIZATION, format!("Bearer {t}"));
    }
    b.body(Body::from(body)).unwrap()
}

/// A hub with a recording store in a folder (kept by the returned guard).
async fn hub_env() -> (
    Env,
    cutlab_dashboard::AppState,
    RecordingStore,
    tempfile::TempDir,
) {
    let store_dir = tempfile::tempdir().unwrap();
    let recordings = RecordingStore::open(store_dir.path().to_str().unwrap()).unwrap();
    let config = Config {
        recordings: Some(recordings.clone()),
        ..Default::default()
    };
    let (e, state) = env_with(config).await;
    (e, state, recordings, store_dir)
}

/// A station's own database with two ended attempts by `zoe` (unknown to the hub), each with
/// a recording file.
async fn station_with_two_attempts(dir: &std::path::Path) -> (Store, [i64; 2]) {
    let store = Store::open(&dir.join("station.db")).await.unwrap();
    let exercise = store.ensure_builtins().await.unwrap();
    let zoe = store.create_user("zoe", Role::Trainee, None).await.unwrap();
    let mut ids = [0; 2];
    for (k, id) in ids.iter_mut().enumerate() {
        let mcap = dir.join(format!("attempt-{k}.mcap"));
        std::fs::write(&mcap, format!("MCAP bytes of attempt {k}").repeat(1000)).unwrap();
        let a = store
            .start_attempt(zoe.id, exercise.id, mcap.to_str(), false)
            .await
            .unwrap();
        store.finish_attempt(a.id, &[]).await.unwrap();
        *id = a.id;
    }
    (store, ids)
}

#[tokio::test]
async fn a_station_sends_its_queue_once_and_keeps_what_is_refused() {
    let (e, state, hub_recordings, _guard) = hub_env().await;
    let token = e.store.create_station_token("or-1").await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (station, [first, second]) = station_with_two_attempts(dir.path()).await;
    let queued = || async { station.sync_queue().await.unwrap().len() };

    // the hub is down: nothing lost, both queued
    let down = Hub::new("http://127.0.0.1:1", &token).unwrap();
    let err = sync(&station, &down, None).await.unwrap_err();
    assert!(
        matches!(err, SyncError::Unreachable { queued: 2, .. }),
        "{err}"
    );
    assert_eq!(queued().await, 2);

    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    tokio::spawn(cutlab_dashboard::serve(
        listener,
        state,
        std::future::pending(),
    ));

    // a wrong token: 401, both queued
    let wrong = Hub::new(&url, "cutlab-station-not-a-token").unwrap();
    let err = sync(&station, &wrong, None).await.unwrap_err();
    assert!(
        matches!(err, SyncError::TokenRefused { queued: 2, .. }),
        "{err}"
    );
    assert_eq!(queued().await, 2);

    // the first attempt's recording changed on disk since its key was taken: refused by
    // the hub, kept queued with why; the second goes
    let recorded_key = sha256_hex(b"what the station recorded");
    station
        .set_recording_keys(first, Some(&recorded_key), None)
        .await
        .unwrap();
    let hub = Hub::new(&url, &token).unwrap();
    let report = sync(&station, &hub, None).await.unwrap();
    assert_eq!((report.uploaded, report.already), (1, 0));
    assert_eq!(report.refused.len(), 1);
    assert_eq!(report.refused[0].0, first);
    assert!(report.refused[0].1.contains("422"), "{:?}", report.refused);
    let left = station.sync_queue().await.unwrap();
    assert_eq!(left.len(), 1);
    assert!(left[0].sync_error.as_deref().unwrap().contains("hashes to"));
    // the automatic syncs do not send it again and again; `cutlab sync` does
    let report = sync_new(&station, &hub, None).await.unwrap();
    assert_eq!(report, SyncReport::default());
    assert_eq!(queued().await, 1);
    let report = sync(&station, &hub, None).await.unwrap();
    assert_eq!(report.refused.len(), 1);

    // the key put right (the file is the recording): it goes
    let bytes = std::fs::read(left[0].recording_path.as_deref().unwrap()).unwrap();
    station
        .set_recording_keys(first, Some(&sha256_hex(&bytes)), None)
        .await
        .unwrap();
    let report = sync(&station, &hub, None).await.unwrap();
    assert_eq!((report.uploaded, report.refused.len()), (1, 0));
    assert_eq!(queued().await, 0);

    // the hub's answer lost: the retry is the same attempt, not a second
    station
        .set_synced(second, Err("answer lost"))
        .await
        .unwrap();
    let report = sync(&station, &hub, None).await.unwrap();
    assert_eq!((report.uploaded, report.already), (0, 1));

    // on the hub: each attempt once, scored, its recording there and intact
    let zoe = e.store.user_by_name("zoe").await.unwrap();
    let on_hub = e.store.list_attempts(Some(zoe.id), None).await.unwrap();
    assert_eq!(on_hub.len(), 2);
    for id in [first, second] {
        let a = station.get_attempt(id).await.unwrap();
        let h = e
            .store
            .attempt_by_uuid(a.uuid.as_deref().unwrap())
            .await
            .unwrap();
        assert_eq!(h.status, AttemptStatus::Complete);
        assert_eq!(h.started_ns, a.started_ns);
        let key = h.recording_sha256.unwrap();
        let kept = hub_recordings.get(&key).await.unwrap();
        assert_eq!(kept, std::fs::read(a.recording_path.unwrap()).unwrap());
    }
    let p = e
        .store
        .proficiency(zoe.id, on_hub[0].exercise_id)
        .await
        .unwrap();
    assert_eq!(p.state.attempts, 2, "each counted once");

    // revoked: 401 from now on, the queue kept
    e.store.revoke_station_token("or-1").await.unwrap();
    station.set_synced(second, Err("again")).await.unwrap();
    let err = sync(&station, &hub, None).await.unwrap_err();
    assert!(
        matches!(err, SyncError::TokenRefused { queued: 1, .. }),
        "{err}"
    );
    assert_eq!(queued().await, 1);
}

#[tokio::test]
async fn the_upload_calls_refuse_what_they_must() {
    let (e, _state, _recordings, _guard) = hub_env().await;
    let token = e.store.create_station_token("or-2").await.unwrap();
    let body = b"MCAP of the station".to_vec();
    let key = sha256_hex(&body);
    let path = format!("/api/hub/recordings/{key}");

    // no token, a wrong one: 401 with a Bearer challenge, nothing stored
    for t in [None, Some("nope")] {
        let r = send(&e.app, put(&path, t, body.clone())).await;
        assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
        assert_eq!(r.headers()[header::WWW_AUTHENTICATE], "Bearer");
    }
    // a station token opens nothing else
    let mut me = get("/api/me", None);
    me.headers_mut().insert(
        header::AUTHORIZATION,
        format!("Bearer {token}").parse().unwrap(),
    );
    assert_eq!(send(&e.app, me).await.status(), StatusCode::UNAUTHORIZED);
    // content that is not its key: 422, nothing stored
    let wrong = sha256_hex(b"something else");
    let r = send(
        &e.app,
        put(
            &format!("/api/hub/recordings/{wrong}"),
            Some(&token),
            body.clone(),
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert!(body_text(r).await.contains("hashes to"));
    // a key that is no key
    let r = send(
        &e.app,
        put(
            "/api/hub/recordings/..%2F..%2Fetc",
            Some(&token),
            body.clone(),
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    // stored once: 201, then 200
    let r = send(&e.app, put(&path, Some(&token), body.clone())).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let r = send(&e.app, put(&path, Some(&token), body.clone())).await;
    assert_eq!(r.status(), StatusCode::OK);

    // attempts: malformed JSON, an id not the path's, a recording the hub lacks
    let uuid = cutlab_dashboard::assessor::store::new_uuid().unwrap();
    let apath = format!("/api/hub/attempts/{uuid}");
    let r = send(&e.app, put(&apath, Some(&token), b"{not json".to_vec())).await;
    assert_eq!(r.status(), StatusCode::UNPROCESSABLE_ENTITY);
    let upload = |uuid: &str, key: &str| {
        serde_json::to_vec(&serde_json::json!({
            "uuid": uuid, "trainee": "ana", "exercise": BUILTIN_EXERCISE,
            "started_ns": 1_800_000_000_000_000_000_i64, "ended_ns": 1_800_000_060_000_000_000_i64,
            "status": "complete", "expert": false, "note": null,
            "recording_sha256": key, "rrd_sha256": null, "metrics": [],
        }))
        .unwrap()
    };
    let other = cutlab_dashboard::assessor::store::new_uuid().unwrap();
    let r = send(&e.app, put(&apath, Some(&token), upload(&other, &key))).await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    let r = send(&e.app, put(&apath, Some(&token), upload(&uuid, &wrong))).await;
    assert_eq!(r.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert!(body_text(r).await.contains("upload it first"));
    // taken once
    let r = send(&e.app, put(&apath, Some(&token), upload(&uuid, &key))).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let r = send(&e.app, put(&apath, Some(&token), upload(&uuid, &key))).await;
    assert_eq!(r.status(), StatusCode::OK);
    let taken = e.store.attempt_by_uuid(&uuid).await.unwrap();
    assert_eq!(taken.recording_sha256, Some(key.clone()));
    // the instructor's page of it says where it came from
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let page =
        body_text(send(&e.app, get(&format!("/attempts/{}", taken.id), Some(&kim))).await).await;
    assert!(page.contains("uploaded by station or-2"), "{page}");

    // a hub without a recording store says so
    let (bare, _) = env_with(Config::default()).await;
    let token = bare.store.create_station_token("or-3").await.unwrap();
    let r = send(&bare.app, put(&path, Some(&token), body)).await;
    assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
    assert!(body_text(r).await.contains("--recordings"));
}

#[tokio::test]
async fn a_station_server_sends_its_queue_once_the_hub_is_back() {
    let (e, state, _recordings, _guard) = hub_env().await;
    let token = e.store.create_station_token("or-4").await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (station, _) = station_with_two_attempts(dir.path()).await;
    // a port where the hub will be, nothing listening yet
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let hub = Hub::new(&format!("http://127.0.0.1:{port}"), &token).unwrap();
    let retrying = tokio::spawn(cutlab_station::sync::keep_syncing(
        station.clone(),
        hub,
        None,
        std::time::Duration::from_millis(100),
    ));
    tokio::time::sleep(std::time::Duration::from_millis(400)).await;
    assert_eq!(station.sync_queue().await.unwrap().len(), 2, "hub down");
    let listener = tokio::net::TcpListener::bind(("127.0.0.1", port))
        .await
        .unwrap();
    tokio::spawn(cutlab_dashboard::serve(
        listener,
        state,
        std::future::pending(),
    ));
    let t0 = std::time::Instant::now();
    while !station.sync_queue().await.unwrap().is_empty() {
        assert!(t0.elapsed().as_secs() < 30, "the queue was not sent");
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    retrying.abort();
    let zoe = e.store.user_by_name("zoe").await.unwrap();
    assert_eq!(
        e.store
            .list_attempts(Some(zoe.id), None)
            .await
            .unwrap()
            .len(),
        2
    );
}
