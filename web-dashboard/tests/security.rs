//! The dashboard's security over HTTP (tower `oneshot`, a fresh database per test): logins,
//! sessions, CSRF, rate limiting, roles, path traversal and hostile parameters.
#![allow(clippy::unwrap_used)]

mod common;

use axum::http::{StatusCode, header};
use common::*;

#[tokio::test]
async fn unauthenticated_pages_redirect_and_api_calls_get_401() {
    let e = env().await;
    let a = first_attempt(&e.store, "ana").await;
    for path in [
        "/",
        "/cohorts",
        "/trainees/1",
        &format!("/attempts/{a}"),
        &format!("/attempts/{a}/recording.mcap"),
        &format!("/attempts/{a}/replay"),
        "/supervision",
        "/curriculum",
        "/viewer/re_viewer_bg.wasm",
    ] {
        let r = send(&e.app, get(path, None)).await;
        assert_eq!(r.status(), StatusCode::SEE_OTHER, "{path}");
        assert_eq!(r.headers()[header::LOCATION], "/login", "{path}");
    }
    for path in [
        "/api/me",
        "/api/cohorts",
        &format!("/api/attempts/{a}"),
        "/api/trainees/1/progress",
        "/api/running",
        "/api/nothing-here",
    ] {
        let r = send(&e.app, get(path, None)).await;
        let status = r.status();
        let body = body_text(r).await;
        assert!(
            status == StatusCode::UNAUTHORIZED
                || (path == "/api/nothing-here" && status == StatusCode::NOT_FOUND),
            "{path}: {status}"
        );
        assert!(
            body.starts_with('{') && body.contains("\"error\""),
            "{path}: {body}"
        );
    }
    // a made-up session cookie is no session
    let fake = Session {
        cookie: format!("cutlab_session={}", "a".repeat(64)),
        csrf: String::new(),
    };
    assert_eq!(
        send(&e.app, get("/api/me", Some(&fake))).await.status(),
        StatusCode::UNAUTHORIZED
    );
}

#[tokio::test]
async fn login_logout_happy_path() {
    let e = env().await;
    let r = try_login(&e.app, "dr-kim", "instructor-demo").await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let set = r.headers()[header::SET_COOKIE].to_str().unwrap().to_owned();
    assert!(
        set.contains("HttpOnly") && set.contains("SameSite=Strict"),
        "{set}"
    );
    // the database keeps a hash of the token, never the token
    let token = set_cookie(&r, "cutlab_session").unwrap();
    let stored: String = on_db!(e.store.db(), pool => sqlx::query_scalar("SELECT token_sha256 FROM login_sessions").fetch_one(pool).await)
        .unwrap();
    assert_ne!(stored, token);
    let s = login(&e.app, "dr-kim", "instructor-demo").await;
    let me = body_text(send(&e.app, get("/api/me", Some(&s))).await).await;
    assert!(
        me.contains("\"name\":\"dr-kim\"") && me.contains("\"role\":\"instructor\""),
        "{me}"
    );
    assert!(!me.contains("argon2"), "no hash in the API");
    let r = send(&e.app, get("/", Some(&s))).await;
    assert_eq!(r.headers()[header::LOCATION], "/cohorts");
    let r = send(
        &e.app,
        post_form("/logout", Some(&s.cookie), &[("csrf", &s.csrf)]),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert!(
        r.headers()[header::SET_COOKIE]
            .to_str()
            .unwrap()
            .contains("Max-Age=0")
    );
    assert_eq!(
        send(&e.app, get("/api/me", Some(&s))).await.status(),
        StatusCode::UNAUTHORIZED,
        "the session is gone"
    );
}

#[tokio::test]
async fn wrong_passwords_are_refused_then_rate_limited() {
    let e = env().await;
    let r = try_login(&e.app, "ana", "wrong").await;
    assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    assert!(set_cookie(&r, "cutlab_session").is_none());
    assert_eq!(
        try_login(&e.app, "nobody", "x").await.status(),
        StatusCode::UNAUTHORIZED
    );
    assert_eq!(
        try_login(&e.app, "", "").await.status(),
        StatusCode::UNAUTHORIZED
    );
    assert_eq!(
        try_login(&e.app, &"x".repeat(10_000), "y").await.status(),
        StatusCode::UNAUTHORIZED
    );
    for _ in 0..4 {
        assert_eq!(
            try_login(&e.app, "ana", "wrong again").await.status(),
            StatusCode::UNAUTHORIZED
        );
    }
    // 5 failures for ana within the minute: even the right password waits
    let r = try_login(&e.app, "ana", "trainee-demo").await;
    assert_eq!(r.status(), StatusCode::TOO_MANY_REQUESTS);
    assert!(set_cookie(&r, "cutlab_session").is_none());
    assert_eq!(
        try_login(&e.app, "ANA ", "trainee-demo").await.status(),
        StatusCode::TOO_MANY_REQUESTS,
        "the user key ignores case and spaces"
    );
    // ... but ben, from the same address (8 failures from it so far), is not locked out
    assert_eq!(
        try_login(&e.app, "ben", "trainee-demo").await.status(),
        StatusCode::SEE_OTHER,
        "one user's failures do not lock out the others behind the same address"
    );
}

#[tokio::test]
async fn a_shared_address_is_not_locked_by_failures_under_its_own_limit() {
    let e = env().await;
    // the default: a clinic's NAT with 30 failed logins (6 users, 5 each) within the minute
    for u in 0..6 {
        for _ in 0..5 {
            assert_eq!(
                try_login_from(&e.app, "10.0.0.1", &format!("user{u}"), "x")
                    .await
                    .status(),
                StatusCode::UNAUTHORIZED
            );
        }
        assert_eq!(
            try_login_from(&e.app, "10.0.0.1", &format!("user{u}"), "x")
                .await
                .status(),
            StatusCode::TOO_MANY_REQUESTS,
            "user{u} locked after 5"
        );
    }
    assert_eq!(
        try_login_from(&e.app, "10.0.0.1", "ana", "trainee-demo")
            .await
            .status(),
        StatusCode::SEE_OTHER
    );
}

#[tokio::test]
async fn one_address_is_blocked_at_the_per_ip_limit() {
    let e = env().await;
    let app = cutlab_dashboard::app(
        cutlab_dashboard::AppState::new(
            e.store.clone(),
            cutlab_dashboard::Config {
                login_failures_per_ip: 12,
                ..Default::default()
            },
        )
        .unwrap(),
    );
    // one failure each for 12 user names: no user key is near its limit of 5
    for u in 0..12 {
        assert_eq!(
            try_login_from(&app, "192.0.2.7", &format!("guess{u}"), "x")
                .await
                .status(),
            StatusCode::UNAUTHORIZED,
            "failure {u}"
        );
    }
    let r = try_login_from(&app, "192.0.2.7", "ana", "trainee-demo").await;
    assert_eq!(
        r.status(),
        StatusCode::TOO_MANY_REQUESTS,
        "the address is blocked, even for a right password"
    );
    assert!(set_cookie(&r, "cutlab_session").is_none());
    assert_eq!(
        try_login_from(&app, "2001:db8::1", "ana", "trainee-demo")
            .await
            .status(),
        StatusCode::SEE_OTHER,
        "another address is not"
    );
}

#[tokio::test]
async fn a_stranger_cannot_lock_a_user_out_from_everywhere() {
    let e = env().await;
    let state = cutlab_dashboard::AppState::new(
        e.store.clone(),
        cutlab_dashboard::Config {
            login_failures: 3,
            ..Default::default()
        },
    )
    .unwrap();
    let app = cutlab_dashboard::app(state);
    for _ in 0..3 {
        assert_eq!(
            try_login_from(&app, "10.0.0.1", "ben", "nope")
                .await
                .status(),
            StatusCode::UNAUTHORIZED
        );
    }
    assert_eq!(
        try_login_from(&app, "10.0.0.1", "ben", "trainee-demo")
            .await
            .status(),
        StatusCode::TOO_MANY_REQUESTS,
        "3 failures for ben from one address: ben waits there"
    );
    assert_eq!(
        try_login_from(&app, "10.0.0.2", "ben", "trainee-demo")
            .await
            .status(),
        StatusCode::SEE_OTHER,
        "the real ben, at his own address, is not locked out by a stranger's guesses"
    );
    for ip in ["10.0.0.3", "10.0.0.4"] {
        assert_eq!(
            try_login_from(&app, ip, "ana", "nope").await.status(),
            StatusCode::UNAUTHORIZED
        );
    }
    assert_eq!(
        try_login_from(&app, "10.0.0.5", "ana", "trainee-demo")
            .await
            .status(),
        StatusCode::SEE_OTHER,
        "failures from other addresses do not add up against ana here"
    );
}

#[tokio::test]
async fn forms_without_the_csrf_token_are_refused() {
    let e = env().await;
    let s = login(&e.app, "dr-kim", "instructor-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let path = format!("/attempts/{a}/comments");
    let before = count(&e.store, "attempt_comments").await;
    for form in [
        vec![("body", "hi")],
        vec![("body", "hi"), ("csrf", "0000")],
        vec![("body", "hi"), ("csrf", &"f".repeat(64))],
    ] {
        let r = send(&e.app, post_form(&path, Some(&s.cookie), &form)).await;
        assert_eq!(r.status(), StatusCode::FORBIDDEN, "{form:?}");
    }
    let r = send(
        &e.app,
        post_form(&format!("/attempts/{a}/signoff"), Some(&s.cookie), &[]),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    let r = send(&e.app, post_form("/logout", Some(&s.cookie), &[])).await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    assert_eq!(
        send(&e.app, get("/api/me", Some(&s))).await.status(),
        StatusCode::OK,
        "still logged in"
    );
    assert_eq!(count(&e.store, "attempt_comments").await, before);
    assert_eq!(count(&e.store, "attempt_signoffs").await, 0);
    // another session's token is not this session's
    let other = login(&e.app, "admin", "admin-demo").await;
    let r = send(
        &e.app,
        post_form(
            &path,
            Some(&s.cookie),
            &[("body", "hi"), ("csrf", &other.csrf)],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    // the right token works
    let r = send(
        &e.app,
        post_form(&path, Some(&s.cookie), &[("body", "hi"), ("csrf", &s.csrf)]),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(count(&e.store, "attempt_comments").await, before + 1);
    // the login form: no cookie, or a field that does not match it
    let csrf = login_csrf(&e.app).await;
    let r = send(
        &e.app,
        post_form(
            "/login",
            None,
            &[
                ("username", "ana"),
                ("password", "trainee-demo"),
                ("csrf", &csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    let r = send(
        &e.app,
        post_form(
            "/login",
            Some(&format!("cutlab_login_csrf={csrf}")),
            &[
                ("username", "ana"),
                ("password", "trainee-demo"),
                ("csrf", &"0".repeat(64)),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
}

#[tokio::test]
async fn a_trainee_sees_only_their_own_data() {
    let e = env().await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let (ana_id, ben_id) = (
        user_id(&e.store, "ana").await,
        user_id(&e.store, "ben").await,
    );
    let (mine, bens) = (
        first_attempt(&e.store, "ana").await,
        first_attempt(&e.store, "ben").await,
    );
    let dir = e.dir.path().join("ben");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("session.mcap"), b"ben's recording").unwrap();
    std::fs::write(dir.join("session.rrd"), b"ben's rrd").unwrap();
    on_db!(e.store.db(), pool => sqlx::query("UPDATE attempts SET recording_path = $1 WHERE id = $2")
        .bind(dir.join("session.mcap").display().to_string())
        .bind(bens).execute(pool).await.map(|_| ()))
        .unwrap();
    for path in [
        format!("/attempts/{bens}"),
        format!("/api/attempts/{bens}"),
        format!("/api/attempts/{bens}/trace"),
        format!("/attempts/{bens}/recording.mcap"),
        format!("/attempts/{bens}/recording.rrd"),
        format!("/attempts/{bens}/replay"),
        format!("/trainees/{ben_id}"),
        format!("/api/trainees/{ben_id}/progress"),
    ] {
        let r = send(&e.app, get(&path, Some(&ana))).await;
        assert_eq!(r.status(), StatusCode::NOT_FOUND, "{path}");
        let body = body_text(r).await;
        assert!(!body.contains("ben"), "{path} leaks: {body}");
    }
    let r = send(&e.app, get("/api/cohorts", Some(&ana))).await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    assert_eq!(
        send(&e.app, get("/cohorts", Some(&ana))).await.status(),
        StatusCode::FORBIDDEN
    );
    let list = body_text(send(&e.app, get("/api/trainees", Some(&ana))).await).await;
    assert!(
        list.contains("\"ana\"") && !list.contains("\"ben\""),
        "{list}"
    );
    // her own data is there
    assert_eq!(
        send(&e.app, get(&format!("/attempts/{mine}"), Some(&ana)))
            .await
            .status(),
        StatusCode::OK
    );
    let p = body_text(
        send(
            &e.app,
            get(&format!("/api/trainees/{ana_id}/progress"), Some(&ana)),
        )
        .await,
    )
    .await;
    assert!(p.contains("\"trials_to_proficiency\""), "{p}");
    // a trainee cannot comment, sign off or edit exercises
    let r = send(
        &e.app,
        post_form(
            &format!("/attempts/{mine}/comments"),
            Some(&ana.cookie),
            &[("body", "self praise"), ("csrf", &ana.csrf)],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    let curricula = count(&e.store, "curricula").await;
    let r = send(
        &e.app,
        post_form(
            "/curricula",
            Some(&ana.cookie),
            &[("name", "mine"), ("csrf", &ana.csrf)],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    assert_eq!(count(&e.store, "curricula").await, curricula, "none made");
}

#[tokio::test]
async fn an_instructor_sees_only_their_cohorts() {
    let e = env().await;
    e.store
        .create_user(
            "dr-other",
            cutlab_assessor::store::Role::Instructor,
            Some("pw-other"),
        )
        .await
        .unwrap();
    let other = login(&e.app, "dr-other", "pw-other").await;
    let ana_id = user_id(&e.store, "ana").await;
    let a = first_attempt(&e.store, "ana").await;
    assert_eq!(
        send(&e.app, get(&format!("/trainees/{ana_id}"), Some(&other)))
            .await
            .status(),
        StatusCode::NOT_FOUND
    );
    assert_eq!(
        send(&e.app, get(&format!("/api/attempts/{a}"), Some(&other)))
            .await
            .status(),
        StatusCode::NOT_FOUND
    );
    let grid = body_text(send(&e.app, get("/api/cohorts", Some(&other))).await).await;
    assert_eq!(grid, "[]");
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    assert_eq!(
        send(&e.app, get(&format!("/trainees/{ana_id}"), Some(&kim)))
            .await
            .status(),
        StatusCode::OK
    );
    let admin = login(&e.app, "admin", "admin-demo").await;
    assert_eq!(
        send(&e.app, get(&format!("/api/attempts/{a}"), Some(&admin)))
            .await
            .status(),
        StatusCode::OK
    );
}

#[tokio::test]
async fn downloads_serve_only_the_stored_recording() {
    let e = env().await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let dir = e.dir.path().join("rec");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("session.mcap"), b"MCAP bytes").unwrap();
    std::fs::write(e.dir.path().join("secret.txt"), b"secret").unwrap();
    on_db!(e.store.db(), pool => sqlx::query("UPDATE attempts SET recording_path = $1 WHERE id = $2")
        .bind(dir.join("session.mcap").display().to_string())
        .bind(a).execute(pool).await.map(|_| ()))
        .unwrap();
    let r = send(
        &e.app,
        get(
            &format!("/attempts/{a}/recording.mcap?path=../secret.txt&file=/etc/passwd"),
            Some(&ana),
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::OK);
    assert!(
        r.headers()[header::CONTENT_DISPOSITION]
            .to_str()
            .unwrap()
            .contains(&format!("attempt-{a}.mcap"))
    );
    assert_eq!(body_text(r).await, "MCAP bytes");
    assert_eq!(
        send(
            &e.app,
            get(&format!("/attempts/{a}/recording.rrd"), Some(&ana))
        )
        .await
        .status(),
        StatusCode::NOT_FOUND,
        "no .rrd beside it"
    );
    for path in [
        format!("/attempts/{a}/../../secret.txt"),
        format!("/attempts/{a}/recording.mcap/../../secret.txt"),
        "/attempts/..%2f..%2fsecret.txt/recording.mcap".to_owned(),
        format!("/attempts/{a}/%2e%2e%2fsecret.txt"),
        "/viewer/..%2f..%2fCargo.toml".to_owned(),
        "/viewer/%2e%2e/secret.txt".to_owned(),
        "/static/..%2fstyle.css".to_owned(),
        format!("/attempts/{a}/recording.txt"),
    ] {
        let r = send(&e.app, get(&path, Some(&ana))).await;
        assert!(r.status().is_client_error(), "{path}: {}", r.status());
        let body = body_text(r).await;
        assert!(
            !body.contains("secret") && !body.contains("[workspace]"),
            "{path}"
        );
    }
    // a stored path that is a directory is not served
    on_db!(e.store.db(), pool => sqlx::query("UPDATE attempts SET recording_path = $1 WHERE id = $2")
        .bind(dir.display().to_string())
        .bind(a).execute(pool).await.map(|_| ()))
        .unwrap();
    assert_eq!(
        send(
            &e.app,
            get(&format!("/attempts/{a}/recording.mcap"), Some(&ana))
        )
        .await
        .status(),
        StatusCode::NOT_FOUND
    );
}

/// With a recording store, an attempt's recording is served from there (whole, checked
/// against its key, or in the ranges rerun's viewer asks for), even when the station's
/// file is gone; a changed object is refused.
#[tokio::test]
async fn recordings_are_served_from_the_store_in_ranges_and_checked() {
    use cutlab_assessor::recordings::RecordingStore;
    let dir = tempfile::tempdir().unwrap();
    let store_dir = dir.path().join("store");
    let recordings = RecordingStore::open(store_dir.to_str().unwrap()).unwrap();
    let config = cutlab_dashboard::Config {
        recordings: Some(recordings.clone()),
        ..Default::default()
    };
    let (e, _state) = env_with(config).await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let rec = e.dir.path().join("rec");
    std::fs::create_dir_all(&rec).unwrap();
    let mcap = rec.join("session.mcap");
    std::fs::write(&mcap, b"0123456789 MCAP bytes").unwrap();
    on_db!(e.store.db(), pool => {
        sqlx::query("UPDATE attempts SET recording_path = $1 WHERE id = $2")
            .bind(mcap.display().to_string())
            .bind(a)
            .execute(pool)
            .await
            .map(|_| ())
    })
    .unwrap();
    let kept = e.store.keep_recordings(a, &recordings).await.unwrap();
    let key = kept.recording_sha256.clone().unwrap();
    assert_eq!(kept.rrd_sha256, None, "no .rrd beside it");
    // the station's copy is gone: the store serves
    std::fs::remove_file(&mcap).unwrap();
    let url = format!("/attempts/{a}/recording.mcap");
    let r = send(&e.app, get(&url, Some(&ana))).await;
    assert_eq!(r.status(), StatusCode::OK);
    assert_eq!(r.headers()[header::ACCEPT_RANGES], "bytes");
    assert_eq!(body_text(r).await, "0123456789 MCAP bytes");
    let ranged = |range: &'static str| {
        let mut req = get(&url, Some(&ana));
        req.headers_mut()
            .insert(header::RANGE, header::HeaderValue::from_static(range));
        req
    };
    let r = send(&e.app, ranged("bytes=2-5")).await;
    assert_eq!(r.status(), StatusCode::PARTIAL_CONTENT);
    assert_eq!(r.headers()[header::CONTENT_RANGE], "bytes 2-5/21");
    assert_eq!(r.headers()[header::CONTENT_LENGTH], "4");
    assert_eq!(body_text(r).await, "2345");
    let r = send(&e.app, ranged("bytes=-5")).await;
    assert_eq!(r.status(), StatusCode::PARTIAL_CONTENT);
    assert_eq!(body_text(r).await, "bytes");
    let r = send(&e.app, ranged("bytes=21-")).await;
    assert_eq!(r.status(), StatusCode::RANGE_NOT_SATISFIABLE);
    assert_eq!(r.headers()[header::CONTENT_RANGE], "bytes */21");
    // an object changed in the store is refused, never served
    std::fs::write(
        store_dir.join("sha256").join(&key),
        b"0123456789 other bytes",
    )
    .unwrap();
    let r = send(&e.app, get(&url, Some(&ana))).await;
    assert!(r.status().is_server_error(), "{}", r.status());
    assert!(!body_text(r).await.contains("other bytes"));
    // another trainee sees nothing of it
    let ben = login(&e.app, "ben", "trainee-demo").await;
    assert_eq!(
        send(&e.app, get(&url, Some(&ben))).await.status(),
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn hostile_parameters_get_4xx_and_change_nothing() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let tables = [
        "users",
        "attempts",
        "metric_results",
        "attempt_comments",
        "exercises",
        "metric_thresholds",
        "curricula",
        "modules",
    ];
    let mut before = Vec::new();
    for t in tables {
        before.push(count(&e.store, t).await);
    }
    let long = "9".repeat(5000);
    for id in [
        "abc",
        "1'%20OR%20'1'='1",
        "1;DROP%20TABLE%20users",
        "99999999999999999999999",
        "-1",
        "0",
        "1.5",
        "%00",
        long.as_str(),
        "9223372036854775807",
    ] {
        for path in [
            format!("/attempts/{id}"),
            format!("/api/attempts/{id}"),
            format!("/trainees/{id}"),
            format!("/api/trainees/{id}/progress"),
            format!("/attempts/{id}/recording.mcap"),
            format!("/exercises/{id}"),
            format!("/api/exercises/{id}"),
        ] {
            let r = send(&e.app, get(&path, Some(&kim))).await;
            assert!(r.status().is_client_error(), "{path}: {}", r.status());
        }
    }
    let a = first_attempt(&e.store, "ana").await;
    let ex = e.store.list_exercises().await.unwrap()[0].id;
    let c = &kim.csrf;
    let huge = "x".repeat(5000);
    let posts: Vec<(String, Vec<(&str, &str)>)> = vec![
        (
            format!("/attempts/{a}/comments"),
            vec![("body", huge.as_str()), ("csrf", c)],
        ),
        (
            format!("/attempts/{a}/comments"),
            vec![("body", "   "), ("csrf", c)],
        ),
        (format!("/attempts/{a}/comments"), vec![("csrf", c)]),
        (
            "/attempts/abc/comments".into(),
            vec![("body", "x"), ("csrf", c)],
        ),
        (
            "/attempts/99999999999/comments".into(),
            vec![("body", "x"), ("csrf", c)],
        ),
        (
            "/exercises".into(),
            vec![
                ("name", "x'); DROP TABLE exercises;--"),
                ("scene", "chest-wall"),
                ("threshold_k", "NaN"),
                ("plan", "entry_m = [0,0,0]"),
                ("csrf", c),
            ],
        ),
        (
            "/exercises".into(),
            vec![
                ("name", "ok-name"),
                ("scene", "chest-wall"),
                ("threshold_k", "2"),
                ("plan", "not = [valid"),
                ("csrf", c),
            ],
        ),
        (
            "/exercises".into(),
            vec![
                ("name", huge.as_str()),
                ("scene", "chest-wall"),
                ("threshold_k", "2"),
                ("plan", ""),
                ("csrf", c),
            ],
        ),
        (
            format!("/exercises/{ex}"),
            vec![("scene", ""), ("threshold_k", "2"), ("csrf", c)],
        ),
        (
            format!("/exercises/{ex}"),
            vec![("scene", "chest-wall"), ("threshold_k", "-1"), ("csrf", c)],
        ),
        (
            format!("/exercises/{ex}/thresholds"),
            vec![
                ("key_0", "time_s"),
                ("better_0", "lower-is-better"),
                ("mean_0", "1e999"),
                ("upper_0", "3"),
                ("csrf", c),
            ],
        ),
        (
            format!("/exercises/{ex}/thresholds"),
            vec![
                ("key_0", "'; DELETE FROM users;--"),
                ("better_0", "lower-is-better"),
                ("mean_0", "1"),
                ("upper_0", "3"),
                ("csrf", c),
            ],
        ),
        (
            format!("/exercises/{ex}/thresholds"),
            vec![
                ("key_0", "time_s"),
                ("better_0", "sideways"),
                ("mean_0", "1"),
                ("upper_0", "3"),
                ("csrf", c),
            ],
        ),
        (
            format!("/exercises/{ex}/thresholds"),
            vec![
                ("key_0", "time_s"),
                ("better_0", "two-sided"),
                ("mean_0", "1"),
                ("lower_0", "5"),
                ("upper_0", "3"),
                ("csrf", c),
            ],
        ),
        ("/curricula".into(), vec![("name", ""), ("csrf", c)]),
        (
            "/curricula/1/modules".into(),
            vec![("name", "m"), ("exercise_id", "1 OR 1=1"), ("csrf", c)],
        ),
        (
            "/curricula/424242/modules".into(),
            vec![("name", "m"), ("exercise_id", "1"), ("csrf", c)],
        ),
    ];
    for (path, form) in &posts {
        let r = send(&e.app, post_form(path, Some(&kim.cookie), form)).await;
        assert!(
            r.status().is_client_error(),
            "{path} {form:?}: {}",
            r.status()
        );
    }
    for (t, n) in tables.iter().zip(before) {
        assert_eq!(count(&e.store, t).await, n, "{t} changed");
    }
}

#[tokio::test]
async fn user_text_is_escaped() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let evil = "<script>alert('x')</script>\"><img src=x onerror=alert(1)>";
    let r = send(
        &e.app,
        post_form(
            &format!("/attempts/{a}/comments"),
            Some(&kim.cookie),
            &[("body", evil), ("csrf", &kim.csrf)],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let r = send(&e.app, get(&format!("/attempts/{a}"), Some(&ana))).await;
    assert!(
        r.headers()[header::CONTENT_SECURITY_POLICY]
            .to_str()
            .unwrap()
            .contains("script-src 'self'")
    );
    let page = body_text(r).await;
    assert!(
        !page.contains("<script>alert") && !page.contains("<img src=x"),
        "unescaped"
    );
    assert!(
        page.contains("&lt;script&gt;alert("),
        "the trainee sees the comment"
    );
}
