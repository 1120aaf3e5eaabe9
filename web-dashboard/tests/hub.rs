//! Stations and hub: the hub's upload calls (through `oneshot`) and a station's sync against
//! a hub served on a real socket.
#![allow(clippy::unwrap_used)]

mod common;

use axum::body::Body;
use axum::http::{Method, Request, StatusCode, header};
use common::*;
use cutlab_assessor::recordings::{RecordingStore, sha256_hex};
use cutlab_assessor::store::{AttemptStatus, BUILTIN_EXERCISE, Role, Store};
use cutlab_dashboard::Config;
use cutlab_station::sync::{Hub, SyncError, SyncReport, sync, sync_new};

fn put(path: &str, token: Option<&str>, body: Vec<u8>) -> Request<Body> {
    let mut b = Request::builder().method(Method::PUT).uri(path);
    if let Some(t) = token {
        b = b.header(header::AUTHORIZATION, format!("Bearer {t}"));
    }
    b.body(Body::from(body)).unwrap()
}

/// An attempt upload by `ana` at the built-in exercise, ended `ended_ago_s` ago after a
/// minute, with recording `key`.
fn attempt_json(uuid: &str, status: &str, key: &str, ended_ago_s: i64) -> Vec<u8> {
    let ended = cutlab_assessor::store::now_ns() - ended_ago_s * 1_000_000_000;
    serde_json::to_vec(&serde_json::json!({
        "uuid": uuid, "trainee": "ana", "exercise": BUILTIN_EXERCISE,
        "started_ns": ended - 60_000_000_000, "ended_ns": ended,
        "status": status, "expert": false, "note": null,
        "recording_sha256": key, "rrd_sha256": null, "metrics": [],
    }))
    .unwrap()
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
    let recordings = real_recordings(dir, 2).await;
    for (id, mcap) in ids.iter_mut().zip(recordings) {
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
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let apath = format!("/api/hub/attempts/{uuid}");
    let r = send(&e.app, put(&apath, Some(&token), b"{not json".to_vec())).await;
    assert_eq!(r.status(), StatusCode::UNPROCESSABLE_ENTITY);
    let upload = |uuid: &str, key: &str| attempt_json(uuid, "incomplete", key, 0);
    let other = cutlab_assessor::store::new_uuid().unwrap();
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

// ---- a hostile station, and a crash (issue 46) ----

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use cutlab_dashboard::pace::BodyPace;
use cutlab_dashboard::serve::Limits;
use tokio::io::AsyncWriteExt;

/// [`hub_env`] with `limits`, served on a loopback port.
async fn served_hub(limits: Limits) -> (Env, SocketAddr, RecordingStore, tempfile::TempDir) {
    let store_dir = tempfile::tempdir().unwrap();
    let recordings = RecordingStore::open(store_dir.path().to_str().unwrap()).unwrap();
    let config = Config {
        recordings: Some(recordings.clone()),
        limits,
        ..Default::default()
    };
    let (e, _state, addr) = served(config).await;
    (e, addr, recordings, store_dir)
}

/// A `PUT` of a recording's headers (`Content-Length: declared`), no body yet.
fn recording_headers(key: &str, token: &str, declared: u64) -> Vec<u8> {
    format!(
        "PUT /api/hub/recordings/{key} HTTP/1.1\r\nHost: hub\r\nAuthorization: Bearer {token}\r\nContent-Length: {declared}\r\n\r\n"
    )
    .into_bytes()
}

/// An honest upload of `body` on a new connection from `from`: its status and time.
async fn honest_upload(from: &str, to: SocketAddr, token: &str, body: &[u8]) -> (u16, Duration) {
    let t0 = Instant::now();
    let mut s = connect_from(from, to).await;
    let key = sha256_hex(body);
    s.write_all(&recording_headers(&key, token, body.len() as u64))
        .await
        .unwrap();
    s.write_all(body).await.unwrap();
    let status = answer(&mut s, Duration::from_secs(30)).await.unwrap();
    (status, t0.elapsed())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_that_stall_or_crawl_are_cut_and_free_their_slots() {
    let limits = Limits {
        body: BodyPace {
            stall: Duration::from_secs(1),
            grace: Duration::from_secs(2),
            ..Limits::default().body
        },
        ..Limits::default()
    };
    let (e, addr, _recordings, _guard) = served_hub(limits).await;
    let token = e.store.create_station_token("or-slow").await.unwrap();
    let key = sha256_hex(b"never sent");

    // a declared length over the limit: 413 before a byte of the body
    let mut s = connect_from("127.0.0.1", addr).await;
    s.write_all(&recording_headers(&key, &token, 600 << 20))
        .await
        .unwrap();
    assert_eq!(answer(&mut s, Duration::from_secs(2)).await, Some(413));

    // four hostile stations upload at once: three bodies crawling at a byte every 200 ms
    // and one that stops after a byte; a station's second upload meanwhile is told to come
    // back later
    let t0 = Instant::now();
    let mut slow = tokio::task::JoinSet::new();
    let mut hostile = Vec::new();
    for k in 0..4 {
        let token = e
            .store
            .create_station_token(&format!("or-slow-{k}"))
            .await
            .unwrap();
        hostile.push(token.clone());
        let key = key.clone();
        slow.spawn(async move {
            let mut s = connect_from("127.0.0.1", addr).await;
            s.write_all(&recording_headers(&key, &token, 100 << 20))
                .await
                .unwrap();
            let sends = if k == 3 { 1 } else { 1000 };
            let status = crawl(&mut s, sends, 1, Duration::from_millis(200)).await;
            (status, t0.elapsed())
        });
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut second = connect_from("127.0.0.1", addr).await;
    second
        .write_all(&recording_headers(&key, &hostile[0], 10))
        .await
        .unwrap();
    assert_eq!(answer(&mut second, Duration::from_secs(1)).await, Some(429));
    // an honest station meanwhile: through at once (the crawling bodies hold a MiB of the
    // hub's memory each, not a turn others wait for)
    let (status, took) = honest_upload("127.0.0.1", addr, &token, b"an honest recording").await;
    assert_eq!(status, 201);
    assert!(
        took < Duration::from_secs(1),
        "the honest upload took {took:?}"
    );
    while let Some(done) = slow.join_next().await {
        let (status, at) = done.unwrap();
        assert_eq!(status, Some(408), "cut off as too slow or stalled");
        assert!(at < Duration::from_secs(6), "cut off after {at:?}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_revoked_token_frees_its_upload_at_once() {
    let (e, addr, _recordings, _guard) = served_hub(Limits::default()).await;
    let token = e.store.create_station_token("or-gone").await.unwrap();
    let mut s = connect_from("127.0.0.1", addr).await;
    s.write_all(&recording_headers(&sha256_hex(b"x"), &token, 400 << 20))
        .await
        .unwrap();
    // fast enough never to be cut as slow (160 kB/s), for ever
    let revoke = async {
        tokio::time::sleep(Duration::from_millis(500)).await;
        e.store.revoke_station_token("or-gone").await.unwrap();
        Instant::now()
    };
    let (status, revoked_at) = tokio::join!(
        crawl(&mut s, 100_000, 16 << 10, Duration::from_millis(100)),
        revoke
    );
    assert_eq!(status, Some(401));
    let after = revoked_at.elapsed();
    assert!(
        after < Duration::from_secs(4),
        "cut {after:?} after the revocation"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connections_that_never_finish_their_headers_are_capped_and_closed() {
    let limits = Limits {
        header_timeout: Duration::from_secs(1),
        max_connections: 64,
        max_connections_per_ip: 16,
        ..Limits::default()
    };
    let (_e, addr, _recordings, _guard) = served_hub(limits).await;
    let partial = b"PUT /api/hub/recordings/x HTTP/1.1\r\nHost: hub\r\nX-Slow: ";
    let t0 = Instant::now();
    let mut held = Vec::new();
    let mut refused = 0;
    for _ in 0..40 {
        let mut s = connect_from("127.0.0.1", addr).await;
        s.write_all(partial).await.unwrap();
        held.push(s);
    }
    // past the address's cap: a 503 at once
    for s in &mut held[16..] {
        if answer(s, Duration::from_secs(1)).await == Some(503) {
            refused += 1;
        }
    }
    assert_eq!(refused, 24, "the connections past the cap are refused");
    // another client is served while those 16 hold their places
    let mut other = connect_from("127.0.0.2", addr).await;
    other
        .write_all(b"GET /login HTTP/1.1\r\nHost: hub\r\n\r\n")
        .await
        .unwrap();
    assert_eq!(answer(&mut other, Duration::from_secs(1)).await, Some(200));
    // the 16 are closed once the header time is up
    for s in &mut held[..16] {
        let status = answer(s, Duration::from_secs(3)).await;
        assert!(status.is_none() || status == Some(408), "{status:?}");
    }
    assert!(t0.elapsed() < Duration::from_secs(5));
    // and the first address is served again
    let mut again = connect_from("127.0.0.1", addr).await;
    again
        .write_all(b"GET /login HTTP/1.1\r\nHost: hub\r\n\r\n")
        .await
        .unwrap();
    assert_eq!(answer(&mut again, Duration::from_secs(1)).await, Some(200));
}

/// The metrics stored for an attempt.
async fn metric_count(store: &Store, id: i64) -> usize {
    store.attempt_metrics(id).await.unwrap().len()
}

#[tokio::test]
async fn a_day_old_attempt_survives_the_hubs_restart_and_a_retry_gets_what_the_hub_holds() {
    let (e, _state, _recordings, _guard) = hub_env().await;
    let token = e.store.create_station_token("or-1").await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mcap = real_recordings(dir.path(), 1).await.remove(0);
    let bytes = std::fs::read(&mcap).unwrap();
    let key = sha256_hex(&bytes);
    let r = send(
        &e.app,
        put(&format!("/api/hub/recordings/{key}"), Some(&token), bytes),
    )
    .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    // recorded a day before it reached the hub (a day offline)
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let path = format!("/api/hub/attempts/{uuid}");
    let body = attempt_json(&uuid, "complete", &key, 86_400);
    let r = send(&e.app, put(&path, Some(&token), body.clone())).await;
    assert_eq!(r.status(), StatusCode::CREATED, "{}", body_text(r).await);
    let a = e.store.attempt_by_uuid(&uuid).await.unwrap();
    assert_eq!(a.status, AttemptStatus::Complete);
    let metrics = metric_count(&e.store, a.id).await;
    assert!(
        metrics > 10,
        "scored by the hub from its recording: {metrics}"
    );

    // the hub restarts: its sweep for attempts left running leaves imports alone
    cutlab_station::attempt::end_abandoned(&e.store, None)
        .await
        .unwrap();
    let after = e.store.attempt_by_uuid(&uuid).await.unwrap();
    assert_eq!(after, a);
    assert_eq!(metric_count(&e.store, a.id).await, metrics);
    // the retry is answered with the attempt as the hub holds it
    let r = send(&e.app, put(&path, Some(&token), body)).await;
    assert_eq!(r.status(), StatusCode::OK);
    let answer: serde_json::Value = serde_json::from_str(&body_text(r).await).unwrap();
    assert_eq!(answer["status"], "complete");
    assert_eq!(answer["id"], a.id);
    assert_eq!(answer["score"].as_f64(), a.score);

    // an older hub's import left between its insert and its scoring, a day ago: the
    // sweep leaves it, the station's retry ends it
    let legacy = cutlab_assessor::store::new_uuid().unwrap();
    let ana = e.store.user_by_name("ana").await.unwrap();
    on_db!(e.store.db(), pool => sqlx::query("INSERT INTO attempts (trainee_id, exercise_id, started_ns, status, expert, uuid, station) VALUES ($1, $2, $3, 'running', FALSE, $4, 'or-1')")
        .bind(ana.id)
        .bind(a.exercise_id)
        .bind(a.started_ns)
        .bind(&legacy)
        .execute(pool).await.map(|_| ()).unwrap());
    cutlab_station::attempt::end_abandoned(&e.store, None)
        .await
        .unwrap();
    let left = e.store.attempt_by_uuid(&legacy).await.unwrap();
    assert_eq!(left.status, AttemptStatus::Running, "not swept");
    let r = send(
        &e.app,
        put(
            &format!("/api/hub/attempts/{legacy}"),
            Some(&token),
            attempt_json(&legacy, "incomplete", &key, 86_400),
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::OK);
    let ended = e.store.attempt_by_uuid(&legacy).await.unwrap();
    assert_eq!(ended.status, AttemptStatus::Incomplete);
}

#[tokio::test]
async fn a_station_cannot_take_anothers_attempt_or_recording() {
    let (e, _state, _recordings, _guard) = hub_env().await;
    let first = e.store.create_station_token("or-1").await.unwrap();
    let second = e.store.create_station_token("or-2").await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mcap = real_recordings(dir.path(), 1).await.remove(0);
    let bytes = std::fs::read(&mcap).unwrap();
    let key = sha256_hex(&bytes);
    let r = send(
        &e.app,
        put(
            &format!("/api/hub/recordings/{key}"),
            Some(&first),
            bytes.clone(),
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let body = attempt_json(&uuid, "complete", &key, 60);
    let path = format!("/api/hub/attempts/{uuid}");
    assert_eq!(
        send(&e.app, put(&path, Some(&first), body.clone()))
            .await
            .status(),
        StatusCode::CREATED
    );
    // the same id from another station: refused, the attempt untouched
    let r = send(&e.app, put(&path, Some(&second), body)).await;
    assert_eq!(r.status(), StatusCode::CONFLICT);
    assert_eq!(
        e.store
            .attempt_by_uuid(&uuid)
            .await
            .unwrap()
            .station
            .as_deref(),
        Some("or-1")
    );
    // the first station's recording, known by its key only: the same answer as a key
    // no one sent, so existence is not told either
    let answer_for = |key: String| {
        let uuid = cutlab_assessor::store::new_uuid().unwrap();
        let path = format!("/api/hub/attempts/{uuid}");
        (path, attempt_json(&uuid, "incomplete", &key, 60))
    };
    let (p1, b1) = answer_for(key.clone());
    let (p2, b2) = answer_for(sha256_hex(b"no one sent this"));
    let theirs = send(&e.app, put(&p1, Some(&second), b1)).await;
    let nobodys = send(&e.app, put(&p2, Some(&second), b2)).await;
    assert_eq!(theirs.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(nobodys.status(), StatusCode::UNPROCESSABLE_ENTITY);
    let (t, n) = (body_text(theirs).await, body_text(nobodys).await);
    assert_eq!(
        t.replace(&key, "KEY"),
        n.replace(&sha256_hex(b"no one sent this"), "KEY")
    );
    // uploading the bytes again is 201 for a station that had not sent them
    let r = send(
        &e.app,
        put(&format!("/api/hub/recordings/{key}"), Some(&second), bytes),
    )
    .await;
    assert_eq!(r.status(), StatusCode::CREATED);
}

#[tokio::test]
async fn a_hub_scores_what_it_takes_and_refuses_forgeries() {
    let (e, _state, _recordings, _guard) = hub_env().await;
    let token = e.store.create_station_token("or-1").await.unwrap();
    let fake = b"not a recording, only its key".to_vec();
    let fake_key = sha256_hex(&fake);
    let r = send(
        &e.app,
        put(
            &format!("/api/hub/recordings/{fake_key}"),
            Some(&token),
            fake,
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let refused = |body: Vec<u8>, uuid: String| {
        let app = e.app.clone();
        let token = token.clone();
        async move {
            let r = send(
                &app,
                put(&format!("/api/hub/attempts/{uuid}"), Some(&token), body),
            )
            .await;
            (r.status(), body_text(r).await)
        }
    };
    // complete with bytes that are no recording; complete without any; times impossible
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let (status, text) = refused(attempt_json(&uuid, "complete", &fake_key, 60), uuid).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(text.contains("not a readable recording"), "{text}");
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let mut v: serde_json::Value =
        serde_json::from_slice(&attempt_json(&uuid, "complete", &fake_key, 60)).unwrap();
    v["recording_sha256"] = serde_json::Value::Null;
    let (status, text) = refused(serde_json::to_vec(&v).unwrap(), uuid.clone()).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(text.contains("with its recording"), "{text}");
    v["status"] = "failed".into();
    v["started_ns"] = i64::MAX.into();
    let (status, text) = refused(serde_json::to_vec(&v).unwrap(), uuid).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(text.contains("future"), "{text}");
    assert!(e.store.user_by_name("ana").await.is_ok());
    let ana = e.store.user_by_name("ana").await.unwrap();
    let imported = e
        .store
        .list_attempts(Some(ana.id), None)
        .await
        .unwrap()
        .into_iter()
        .filter(|a| a.station.is_some())
        .count();
    assert_eq!(imported, 0, "nothing taken");
    // a body over the attempt limit is refused before it is parsed
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let (status, _) = refused(vec![b' '; 300 << 10], uuid).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
}
