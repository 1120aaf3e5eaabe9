//! The pages and the API with the demo data: what an instructor and a trainee see.
#![allow(clippy::unwrap_used)]

mod common;

use axum::http::{StatusCode, header};
use common::*;
use cutlab_assessor::store::Store;

#[tokio::test]
async fn the_instructor_sees_the_cohort_grid_progress_charts_and_attempts() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let grid = body_text(send(&e.app, get("/cohorts", Some(&kim))).await).await;
    assert!(
        grid.contains("demo-cohort") && grid.contains("ana") && grid.contains("ben"),
        "{grid}"
    );
    assert!(
        grid.contains("proficient after"),
        "ana's trials to proficiency: {grid}"
    );
    let ana = user_id(&e.store, "ana").await;
    let r = send(&e.app, get(&format!("/trainees/{ana}"), Some(&kim))).await;
    assert_eq!(r.status(), StatusCode::OK);
    let page = body_text(r).await;
    let curves = &page[page.find("learning-curves").unwrap()..];
    assert!(
        curves.matches("<svg").count() >= 10,
        "a chart per thresholded metric"
    );
    assert!(page.contains("CUSUM of failures") && page.contains("Normalised score"));
    assert!(
        page.contains("class=\"limit\"") && page.contains("class=\"mean\""),
        "pass lines and the expert reference"
    );
    let a = first_attempt(&e.store, "ana").await;
    let page = body_text(send(&e.app, get(&format!("/attempts/{a}"), Some(&kim))).await).await;
    assert!(page.contains("Pass limits"));
    // the metrics by name, in display units; no SI keys in the table
    let table = &page[page.find("class=\"metrics\"").unwrap()..];
    let table = &table[..table.find("</table>").unwrap()];
    let row = |name: &str| {
        let at = table
            .find(&format!("<td>{name}"))
            .unwrap_or_else(|| panic!("{name} in {table}"));
        let row = &table[at..];
        row[..row.find("</tr>").unwrap()].to_owned()
    };
    assert!(
        row("Entry error").contains("<td>mm</td>"),
        "{}",
        row("Entry error")
    );
    assert!(row("Lateral deviation (mean)").contains("<td>mm</td>"));
    assert!(row("Peak force").contains("<td>N</td>"));
    assert!(row("Task time").contains("<td>s</td>"));
    assert!(row("Cut within tolerance").contains("<td>%</td>"));
    for key in ["entry_error_m", "lateral_mean_m", "peak_force_n", "time_s"] {
        assert!(!table.contains(key), "{key} in the table");
    }
    // the JSON API keeps the keys (SI values)
    let api = body_text(send(&e.app, get(&format!("/api/attempts/{a}"), Some(&kim))).await).await;
    assert!(
        api.contains("\"entry_error_m\"") && !api.contains("Entry error"),
        "{api}"
    );
    assert!(
        page.contains("no .mcap"),
        "synthetic attempts have no recording"
    );
    // debriefing: comment, sign off, the trainee reads it
    let r = send(
        &e.app,
        post_form(
            &format!("/attempts/{a}/comments"),
            Some(&kim.cookie),
            &[
                ("body", "Keep the blade perpendicular."),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    // a review note pinned to a moment, as the viewer shows it; from the replay page, the
    // answer is the replay at that moment
    let r = send(
        &e.app,
        post_form(
            &format!("/attempts/{a}/comments"),
            Some(&kim.cookie),
            &[
                ("body", "Here the blade tilts."),
                ("at", "+1.700s"),
                ("next", "replay"),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(
        r.headers()["location"],
        format!("/attempts/{a}/replay?at=1.7").as_str()
    );
    for bad in ["NaN", "-1", "1:75", "1e9"] {
        let r = send(
            &e.app,
            post_form(
                &format!("/attempts/{a}/comments"),
                Some(&kim.cookie),
                &[("body", "never kept"), ("at", bad), ("csrf", &kim.csrf)],
            ),
        )
        .await;
        assert_eq!(r.status(), StatusCode::BAD_REQUEST, "{bad}");
    }
    let r = send(
        &e.app,
        get(&format!("/attempts/{a}/replay?at=soon"), Some(&kim)),
    )
    .await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    let r = send(
        &e.app,
        post_form(
            &format!("/attempts/{a}/signoff"),
            Some(&kim.cookie),
            &[("csrf", &kim.csrf)],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let r = send(
        &e.app,
        post_form(
            &format!("/attempts/{a}/signoff"),
            Some(&kim.cookie),
            &[("csrf", &kim.csrf)],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::CONFLICT, "signed off once");
    let trainee = login(&e.app, "ana", "trainee-demo").await;
    let page = body_text(send(&e.app, get(&format!("/attempts/{a}"), Some(&trainee))).await).await;
    assert!(
        page.contains("Keep the blade perpendicular.") && page.contains("Signed off by dr-kim")
    );
    assert!(
        !page.contains("Add comment"),
        "trainees read, they do not comment"
    );
    assert!(
        page.contains("Here the blade tilts.") && page.contains("at 0:01.700"),
        "the trainee reads the pinned note with its moment"
    );
    assert!(!page.contains("never kept"));
    let json: serde_json::Value = serde_json::from_str(
        &body_text(send(&e.app, get(&format!("/api/attempts/{a}"), Some(&trainee))).await).await,
    )
    .unwrap();
    assert_eq!(json["comments"][0]["body"], "Keep the blade perpendicular.");
    assert_eq!(json["comments"][0]["at_ns"], serde_json::Value::Null);
    assert_eq!(json["comments"][1]["at_ns"], 1_700_000_000_i64);
    assert_eq!(json["comments"].as_array().map(Vec::len), Some(2));
    assert_eq!(json["signoff"]["instructor"]["name"], "dr-kim");
}

#[tokio::test]
async fn the_api_carries_the_same_data() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let grid: serde_json::Value =
        serde_json::from_str(&body_text(send(&e.app, get("/api/cohorts", Some(&kim))).await).await)
            .unwrap();
    let rows = grid[0]["trainees"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    let ana = rows.iter().find(|r| r["trainee"]["name"] == "ana").unwrap();
    let column = grid[0]["exercises"]
        .as_array()
        .unwrap()
        .iter()
        .position(|x| x["name"] == cutlab_assessor::store::BUILTIN_EXERCISE)
        .unwrap();
    assert_eq!(ana["cells"][column]["attempts"], 8);
    assert_eq!(
        ana["cells"][column]["proficiency"]["standing"],
        "proficient"
    );
    let id = ana["trainee"]["id"].as_i64().unwrap();
    let p: serde_json::Value = serde_json::from_str(
        &body_text(
            send(
                &e.app,
                get(&format!("/api/trainees/{id}/progress"), Some(&kim)),
            )
            .await,
        )
        .await,
    )
    .unwrap();
    let ex = &p["exercises"][0];
    assert_eq!(ex["attempts"].as_array().unwrap().len(), 8);
    assert_eq!(ex["cusum"]["points"].as_array().unwrap().len(), 8);
    assert!(ex["cusum"]["h1"].as_f64().unwrap() > 0.0);
    let m = &ex["metrics"][0];
    assert!(
        m["band"]["upper_limit"].is_number() || m["band"]["lower_limit"].is_number(),
        "{m}"
    );
    assert_eq!(m["points"].as_array().unwrap().len(), 8);
    let ex: serde_json::Value = serde_json::from_str(
        &body_text(send(&e.app, get("/api/exercises", Some(&kim))).await).await,
    )
    .unwrap();
    let incision = ex
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["name"] == "chest-wall-incision")
        .unwrap();
    assert!(incision["thresholds"]["metrics"].as_array().unwrap().len() >= 10);
    let r = send(&e.app, get("/api/running", Some(&kim))).await;
    assert_eq!(r.headers()[header::CONTENT_TYPE], "application/json");
    assert_eq!(body_text(r).await, "[]");
}

#[tokio::test]
async fn supervision_shows_running_attempts_live() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let ana = user_id(&e.store, "ana").await;
    let ex = e.store.list_exercises().await.unwrap()[0].id;
    let running = e.store.start_attempt(ana, ex, None, false).await.unwrap();
    let page = body_text(send(&e.app, get("/supervision", Some(&kim))).await).await;
    assert!(
        page.contains(&format!("attempt {}", running.id))
            && page.contains("/static/supervision.js")
    );
    let list: serde_json::Value =
        serde_json::from_str(&body_text(send(&e.app, get("/api/running", Some(&kim))).await).await)
            .unwrap();
    assert_eq!(list[0]["id"], running.id);
    assert!(list[0]["elapsed_s"].as_f64().unwrap() >= 0.0);
    // the event stream's first event carries the list
    let r = send(&e.app, get("/supervision/events", Some(&kim))).await;
    assert_eq!(r.headers()[header::CONTENT_TYPE], "text/event-stream");
    let mut body = r.into_body();
    let frame = tokio::time::timeout(
        std::time::Duration::from_secs(5),
        http_body_util::BodyExt::frame(&mut body),
    )
    .await
    .unwrap()
    .unwrap()
    .unwrap();
    let text = String::from_utf8_lossy(frame.data_ref().unwrap()).into_owned();
    assert!(
        text.starts_with("event: running") && text.contains(&format!("\"id\":{}", running.id)),
        "{text}"
    );
    // another instructor's supervision does not list it
    e.store
        .create_user(
            "dr-other",
            cutlab_assessor::store::Role::Instructor,
            Some("pw"),
        )
        .await
        .unwrap();
    let other = login(&e.app, "dr-other", "pw").await;
    assert_eq!(
        body_text(send(&e.app, get("/api/running", Some(&other))).await).await,
        "[]"
    );
}

#[tokio::test]
async fn instructors_create_and_edit_exercises_and_curricula() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let plan = cutlab_scoring::exercise::CHEST_WALL_PLAN_TOML;
    let r = send(
        &e.app,
        post_form(
            "/exercises",
            Some(&kim.cookie),
            &[
                ("name", "deep-cut"),
                ("scene", "chest-wall"),
                ("threshold_k", "2.5"),
                ("description", "deeper"),
                ("exam_only", "on"),
                ("plan", plan),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let e2 = e.store.exercise_by_name("deep-cut").await.unwrap();
    assert!((e2.threshold_k - 2.5).abs() < 1e-12);
    assert!(e2.exam_only, "the exam-only box was ticked");
    let r = send(
        &e.app,
        post_form(
            &format!("/exercises/{}", e2.id),
            Some(&kim.cookie),
            &[
                ("scene", "body-wall"),
                ("threshold_k", "3"),
                ("description", "edited"),
                ("plan", ""),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let e3 = e.store.get_exercise(e2.id).await.unwrap();
    assert_eq!(
        (e3.scene.as_str(), e3.description.as_str(), e3.plan_id),
        ("body-wall", "edited", e2.plan_id)
    );
    assert!(!e3.exam_only, "an unticked box clears it");
    let r = send(
        &e.app,
        post_form(
            &format!("/exercises/{}/thresholds", e2.id),
            Some(&kim.cookie),
            &[
                ("key_0", "time_s"),
                ("better_0", "lower-is-better"),
                ("mean_0", "8"),
                ("sd_0", "1"),
                ("upper_0", "10"),
                ("key_1", ""),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let t = e.store.thresholds(e2.id).await.unwrap();
    assert_eq!(t.metrics.len(), 1);
    assert_eq!(t.metrics[0].upper, Some(10.0));
    let r = send(
        &e.app,
        post_form(
            "/curricula",
            Some(&kim.cookie),
            &[
                ("name", "basics"),
                ("description", "first steps"),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let c = e.store.curriculum_by_name("basics").await.unwrap();
    let id = e2.id.to_string();
    let r = send(
        &e.app,
        post_form(
            &format!("/curricula/{}/modules", c.id),
            Some(&kim.cookie),
            &[
                ("name", "module one"),
                ("exercise_id", &id),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(
        e.store.curriculum_modules(c.id).await.unwrap()[0].exercise_ids,
        vec![e2.id]
    );
    let ana = user_id(&e.store, "ana").await;
    let page = body_text(send(&e.app, get(&format!("/trainees/{ana}"), Some(&kim))).await).await;
    assert!(
        page.contains("module one") && page.contains("deep-cut (not started)"),
        "module state on the progress page"
    );
}

#[tokio::test]
async fn the_replay_viewer_is_served_by_the_dashboard() {
    let e = env().await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let r = send(&e.app, get("/viewer/re_viewer_bg.wasm", Some(&ana))).await;
    assert_eq!(r.status(), StatusCode::OK);
    assert_eq!(r.headers()[header::CONTENT_TYPE], "application/wasm");
    assert!(r.headers().get(header::CONTENT_ENCODING).is_none());
    // a browser that takes gzip gets the wasm compressed (issue 63: 42 MB to a remote reviewer)
    let mut req = get("/viewer/re_viewer_bg.wasm", Some(&ana));
    req.headers_mut().insert(
        header::ACCEPT_ENCODING,
        "gzip, deflate, br".parse().unwrap(),
    );
    let r = send(&e.app, req).await;
    assert_eq!(r.status(), StatusCode::OK);
    assert_eq!(r.headers()[header::CONTENT_ENCODING], "gzip");
    assert_eq!(r.headers()[header::VARY], "accept-encoding");
    let gz = axum::body::to_bytes(r.into_body(), usize::MAX)
        .await
        .unwrap();
    assert!(
        gz.starts_with(&[0x1f, 0x8b]) && gz.len() < 30_000_000,
        "{}",
        gz.len()
    );
    let r = send(&e.app, get("/viewer/", Some(&ana))).await;
    let index = body_text(r).await;
    assert!(index.contains("re_viewer.js") && !index.contains("googleapis"));
    let a = first_attempt(&e.store, "ana").await;
    let dir = e.dir.path().join("rec");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("session.mcap"), b"x").unwrap();
    std::fs::write(dir.join("session.rrd"), b"RRF2").unwrap();
    on_db!(e.store.db(), pool => sqlx::query("UPDATE attempts SET recording_path = $1 WHERE id = $2")
        .bind(dir.join("session.mcap").display().to_string())
        .bind(a).execute(pool).await.map(|_| ()))
        .unwrap();
    let mut req = get(&format!("/attempts/{a}/replay"), Some(&ana));
    req.headers_mut()
        .insert(header::HOST, "127.0.0.1:8080".parse().unwrap());
    let page = body_text(send(&e.app, req).await).await;
    let prefix = format!("/viewer/?url=http%3A%2F%2F127.0.0.1%3A8080%2Fattempts%2F{a}%2Fgrant%2F");
    let at = page.find(&prefix).unwrap() + prefix.len();
    let grant = &page[at..at + page[at..].find("%2F").unwrap()];
    // the viewer fetches without cookies, through the grant; a wrong or foreign grant is 404
    let no_cookie = |path: String| get(&path, None);
    assert_eq!(
        body_text(
            send(
                &e.app,
                no_cookie(format!("/attempts/{a}/grant/{grant}/recording.rrd"))
            )
            .await
        )
        .await,
        "RRF2"
    );
    let ben = first_attempt(&e.store, "ben").await;
    assert_eq!(
        send(
            &e.app,
            no_cookie(format!("/attempts/{ben}/grant/{grant}/recording.rrd"))
        )
        .await
        .status(),
        StatusCode::NOT_FOUND
    );
    // the grant with its last digit changed (to another digit: a random grant may end in 0)
    let last = if grant.ends_with('0') { '1' } else { '0' };
    let forged = format!("{}{last}", &grant[..grant.len() - 1]);
    assert_eq!(
        send(
            &e.app,
            no_cookie(format!("/attempts/{a}/grant/{forged}/recording.rrd"))
        )
        .await
        .status(),
        StatusCode::NOT_FOUND
    );
    assert_eq!(
        send(
            &e.app,
            no_cookie(format!(
                "/attempts/{a}/grant/1-99999999999-00/recording.rrd"
            ))
        )
        .await
        .status(),
        StatusCode::NOT_FOUND
    );
    let page = body_text(send(&e.app, get(&format!("/attempts/{a}"), Some(&ana))).await).await;
    assert!(page.contains("Review replay") && page.contains("Download .mcap"));
    assert_eq!(
        body_text(
            send(
                &e.app,
                get(&format!("/attempts/{a}/recording.rrd"), Some(&ana))
            )
            .await
        )
        .await,
        "RRF2"
    );
    // the grant ends with the login it was issued in (issue 61): logged out, it is a 404
    let mut logout = post_form("/logout", Some(&ana.cookie), &[("csrf", &ana.csrf)]);
    logout
        .headers_mut()
        .insert(header::HOST, "127.0.0.1:8080".parse().unwrap());
    assert_eq!(send(&e.app, logout).await.status(), StatusCode::SEE_OTHER);
    assert_eq!(
        send(
            &e.app,
            no_cookie(format!("/attempts/{a}/grant/{grant}/recording.rrd"))
        )
        .await
        .status(),
        StatusCode::NOT_FOUND,
        "the replay link of a logged-out session"
    );
}

#[tokio::test]
async fn an_attempt_written_by_another_process_shows_without_waiting_for_the_caches_to_expire() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let ana = common::user_id(&e.store, "ana").await;
    let attempts =
        |p: serde_json::Value| p["exercises"][0]["attempts"].as_array().map_or(0, Vec::len);
    let url = format!("/api/trainees/{ana}/progress");
    let progress = || async {
        serde_json::from_str::<serde_json::Value>(
            &body_text(send(&e.app, get(&url, Some(&kim))).await).await,
        )
        .unwrap()
    };
    assert_eq!(attempts(progress().await), 8);
    assert_eq!(attempts(progress().await), 8, "cached");
    // another process (its own connections) starts an attempt for ana and gives up on it
    let other = Store::open(&e.db).await.unwrap();
    let exercise = other.exercise_by_name("chest-wall-incision").await.unwrap();
    let a = other
        .start_attempt(ana, exercise.id, None, false)
        .await
        .unwrap();
    other
        .mark_incomplete(a.id, Some("interrupted"))
        .await
        .unwrap();
    // once the watcher has polled (every 0.1 s), the very next view shows it: not the
    // state of the viewer's previous visit while a refresh runs behind it
    tokio::time::sleep(5 * cutlab_dashboard::watch::POLL).await;
    assert_eq!(
        attempts(progress().await),
        9,
        "the first view after the change"
    );
}

/// The answer is our error page (HTML, the layout), not axum's plain text.
async fn assert_styled_error(
    r: axum::http::Response<axum::body::Body>,
    status: StatusCode,
    says: &str,
) {
    assert_eq!(r.status(), status);
    let ct = r.headers()[header::CONTENT_TYPE]
        .to_str()
        .unwrap()
        .to_owned();
    assert!(ct.starts_with("text/html"), "{ct}");
    let page = body_text(r).await;
    assert!(
        page.starts_with("<!DOCTYPE html>")
            && page.contains("/static/style.css")
            && page.contains("Back to the dashboard"),
        "{page}"
    );
    assert!(page.contains(says), "{says:?} in {page}");
}

#[tokio::test]
async fn malformed_forms_and_paths_get_the_styled_error_page() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let comments_before = count(&e.store, "attempt_comments").await;
    // a form missing a field
    for (path, form, field) in [
        (
            format!("/attempts/{a}/comments"),
            vec![("csrf", kim.csrf.as_str())],
            "body",
        ),
        (
            "/exercises".to_owned(),
            vec![("name", "x"), ("threshold_k", "2"), ("csrf", &kim.csrf)],
            "scene",
        ),
        (
            "/curricula".to_owned(),
            vec![("csrf", kim.csrf.as_str())],
            "name",
        ),
    ] {
        let r = send(&e.app, post_form(&path, Some(&kim.cookie), &form)).await;
        assert_styled_error(
            r,
            StatusCode::UNPROCESSABLE_ENTITY,
            &format!("missing field `{field}`"),
        )
        .await;
    }
    assert_eq!(count(&e.store, "attempt_comments").await, comments_before);
    // not a form at all (the CSRF token in its header)
    let r = send(
        &e.app,
        axum::http::Request::post(format!("/attempts/{a}/comments"))
            .header(header::COOKIE, &kim.cookie)
            .header("x-csrf-token", &kim.csrf)
            .header(header::CONTENT_TYPE, "application/json")
            .body(axum::body::Body::from(r#"{"body":"x"}"#))
            .unwrap(),
    )
    .await;
    assert_styled_error(
        r,
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "x-www-form-urlencoded",
    )
    .await;
    // the login form too
    let r = send(
        &e.app,
        axum::http::Request::post("/login")
            .header(header::CONTENT_TYPE, "text/plain")
            .body(axum::body::Body::from("username=ana"))
            .unwrap(),
    )
    .await;
    assert_styled_error(
        r,
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "x-www-form-urlencoded",
    )
    .await;
    // malformed ids in the path
    let r = send(&e.app, get("/attempts/abc", Some(&kim))).await;
    assert_styled_error(r, StatusCode::BAD_REQUEST, "not a number").await;
    let r = send(
        &e.app,
        post_form(
            "/attempts/1.5/comments",
            Some(&kim.cookie),
            &[("body", "x"), ("csrf", &kim.csrf)],
        ),
    )
    .await;
    assert_styled_error(r, StatusCode::BAD_REQUEST, "not a number").await;
    let r = send(&e.app, get("/attempts/abc/grant/xyz/recording.rrd", None)).await;
    assert_styled_error(r, StatusCode::BAD_REQUEST, "could not be read").await;
    // the API still answers JSON
    let r = send(&e.app, get("/api/attempts/abc", Some(&kim))).await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    assert!(
        r.headers()[header::CONTENT_TYPE]
            .to_str()
            .unwrap()
            .starts_with("application/json")
    );
}

/// The `peak_force_limits_n` of `/api/attempts/{a}`.
async fn peak_force_limits(app: &axum::Router, s: &Session, a: i64) -> serde_json::Value {
    let json: serde_json::Value = serde_json::from_str(
        &body_text(send(app, get(&format!("/api/attempts/{a}"), Some(s))).await).await,
    )
    .unwrap();
    json["peak_force_limits_n"].clone()
}

#[tokio::test]
async fn the_force_limit_shown_is_the_exercises_peak_force_threshold() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let ex = e.store.get_attempt(a).await.unwrap().exercise_id;
    // the built-in thresholds: peak force at most the plan's force limit, 2.5 N
    assert_eq!(
        peak_force_limits(&e.app, &kim, a).await,
        serde_json::json!({"lower": null, "upper": 2.5})
    );
    for (key, mean, upper, expected) in [
        (
            "peak_force_n",
            "0.5",
            "0.9",
            serde_json::json!({"lower": null, "upper": 0.9}),
        ),
        // an exercise scored without a peak-force threshold: no limit
        ("time_s", "8", "20", serde_json::Value::Null),
    ] {
        let r = send(
            &e.app,
            post_form(
                &format!("/exercises/{ex}/thresholds"),
                Some(&kim.cookie),
                &[
                    ("key_0", key),
                    ("better_0", "lower-is-better"),
                    ("mean_0", mean),
                    ("upper_0", upper),
                    ("csrf", &kim.csrf),
                ],
            ),
        )
        .await;
        assert_eq!(r.status(), StatusCode::SEE_OTHER);
        assert_eq!(peak_force_limits(&e.app, &kim, a).await, expected, "{key}");
    }
}

/// The x tick labels (`text-anchor="middle"`) of the charts in `html`.
fn x_ticks(html: &str) -> Vec<String> {
    html.split("<text class=\"tick\" ")
        .skip(1)
        .filter(|t| t[..t.find('>').unwrap()].contains("text-anchor=\"middle\""))
        .map(|t| t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].to_owned())
        .collect()
}

#[tokio::test]
async fn the_progress_page_starts_with_a_summary_and_charts_on_demand() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let ana = user_id(&e.store, "ana").await;
    let page = body_text(send(&e.app, get(&format!("/trainees/{ana}"), Some(&kim))).await).await;
    let main = &page[page.find("<main>").unwrap()..];
    // the exercise's heading, the standing, then the table before any chart
    let (table, details, svg) = (
        main.find("<table class=\"summary\">").unwrap(),
        main.find("<details").unwrap(),
        main.find("<svg").unwrap(),
    );
    assert!(table < details && details < svg, "{main}");
    assert!(!main[..table].contains("<svg") && !main[..table].contains("<table"));
    // every chart is inside a collapsed <details>
    assert!(!main.contains("<details open"));
    let charts_outside: usize = main
        .split("<details")
        .map(|part| part.find("</details>").map_or(part, |end| &part[end..]))
        .map(|rest| rest.matches("<svg").count())
        .sum();
    assert_eq!(charts_outside, 0, "{main}");
    // the summary: per metric by name, latest / best / mean, limits and the pass rate
    let summary = &main[table..];
    let summary = &summary[..summary.find("</table>").unwrap()];
    for h in ["Latest", "Best", "Mean", "Pass limits", "Passed"] {
        assert!(summary.contains(&format!("<th>{h}</th>")), "{h}");
    }
    let row = &summary[summary.find("<td>Entry error</td>").unwrap()..];
    let row = &row[..row.find("</tr>").unwrap()];
    assert!(
        row.contains("<td>mm</td>") && row.contains("≤ 4.000") && row.contains(" of 8 ("),
        "{row}"
    );
    // the CUSUM chart explained: its lines and what they mean for proficiency
    assert!(
        main.contains("green line −h0") && main.contains("red line h1"),
        "the CUSUM's lines explained"
    );
    assert!(main.contains("proficient by CUSUM") && main.contains("CUSUM after attempt 8"));
}

#[tokio::test]
async fn attempt_axes_tick_at_whole_attempts() {
    let e = env().await;
    // a trainee with 2 scored attempts: the axis spans 0.95 .. 2.05
    let ids = cutlab_dashboard::seed::seed_load(&e.store, 1, 2)
        .await
        .unwrap();
    let s = login(&e.app, "load-instructor", "load-demo").await;
    let page = body_text(send(&e.app, get(&format!("/trainees/{}", ids[0]), Some(&s))).await).await;
    let ticks = x_ticks(&page);
    assert!(ticks.len() >= 10, "{ticks:?}");
    for t in &ticks {
        assert!(t.parse::<u32>().is_ok(), "attempt tick {t:?}");
    }
    assert!(ticks.iter().any(|t| t == "1") && ticks.iter().any(|t| t == "2"));
}

/// The value of the attribute `name` in the tag text `tag`.
fn attr(tag: &str, name: &str) -> Option<String> {
    let at = tag.find(&format!(" {name}=\""))? + name.len() + 3;
    Some(tag[at..at + tag[at..].find('"')?].to_owned())
}

/// The tags `<input`, `<select`, `<textarea` of `html` (their opening tag's text), hidden
/// inputs left out.
fn controls(html: &str) -> Vec<&str> {
    let mut out = Vec::new();
    for kind in ["<input", "<select", "<textarea"] {
        for part in html.split(kind).skip(1) {
            let tag = &part[..part.find('>').unwrap()];
            if attr(tag, "type").as_deref() != Some("hidden") {
                out.push(tag);
            }
        }
    }
    out
}

/// The `(name, value)` of the inputs of the form posting to `action` (text areas empty).
fn form_values(html: &str, action: &str) -> Vec<(String, String)> {
    let form = &html[html.find(&format!("action=\"{action}\"")).unwrap()..];
    let form = &form[..form.find("</form>").unwrap()];
    let mut out: Vec<(String, String)> = form
        .split("<input")
        .skip(1)
        .map(|p| &p[..p.find('>').unwrap()])
        .filter_map(|t| Some((attr(t, "name")?, attr(t, "value").unwrap_or_default())))
        .collect();
    out.extend(
        form.split("<textarea")
            .skip(1)
            .filter_map(|p| Some((attr(&p[..p.find('>').unwrap()], "name")?, String::new()))),
    );
    out
}

#[tokio::test]
async fn curriculum_forms_are_labelled_and_the_plan_has_fields() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let ex = e.store.list_exercises().await.unwrap()[0].id;
    e.store.create_curriculum("basics", "").await.unwrap();
    for path in ["/curriculum".to_owned(), format!("/exercises/{ex}")] {
        let page = body_text(send(&e.app, get(&path, Some(&kim))).await).await;
        let controls = controls(&page);
        assert!(controls.len() >= 15, "{path}: {controls:?}");
        for c in controls {
            let id = attr(c, "id").unwrap_or_else(|| panic!("{path}: no id on {c}"));
            assert_eq!(
                page.matches(&format!(" for=\"{id}\"")).count(),
                1,
                "{path}: one label for {id}"
            );
            assert_eq!(
                page.matches(&format!(" id=\"{id}\"")).count(),
                1,
                "{path}: id {id} once"
            );
        }
        // the plan: labelled fields, its documentation on the page, no source-tree path
        for key in ["depth_mm", "force_limit_n", "entry_x_mm", "viewpoint_z_mm"] {
            assert!(page.contains(&format!("name=\"{key}\"")), "{path}: {key}");
        }
        assert!(
            page.contains("<code>corridor_half_width_m</code>")
                && page.contains("href=\"/plans/example.toml\"")
        );
        assert!(!page.contains("scoring/examples"), "{path}");
    }
    let r = send(&e.app, get("/plans/example.toml", Some(&kim))).await;
    assert_eq!(r.status(), StatusCode::OK);
    assert!(body_text(r).await.contains("corridor_half_width_m = 0.005"));
    let r = send(&e.app, get("/static/plan.js", None)).await;
    assert_eq!(r.status(), StatusCode::OK);

    // a new exercise from the fields, as the page shows them with two changed
    let page = body_text(send(&e.app, get("/curriculum", Some(&kim))).await).await;
    let mut form = form_values(&page, "/exercises");
    for (k, v) in form.iter_mut() {
        match k.as_str() {
            "name" => *v = "shallow-cut".into(),
            "depth_mm" => *v = "5".into(),
            "force_limit_n" => *v = "0.9".into(),
            _ => {}
        }
    }
    let pairs: Vec<(&str, &str)> = form.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let r = send(&e.app, post_form("/exercises", Some(&kim.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER, "{}", body_text(r).await);
    let new = e.store.exercise_by_name("shallow-cut").await.unwrap();
    let plan = e
        .store
        .get_plan(new.plan_id)
        .await
        .unwrap()
        .into_incision()
        .unwrap();
    let builtin = cutlab_scoring::IncisionPlan::chest_wall().unwrap();
    assert_eq!((plan.depth_m, plan.force_limit_n), (0.005, 0.9));
    assert_eq!(
        (plan.entry_m, plan.incision_m.len(), plan.tolerance_m),
        (
            builtin.entry_m,
            builtin.incision_m.len(),
            builtin.tolerance_m
        )
    );
    // nothing about the plan: refused, nothing created
    let before = count(&e.store, "exercises").await;
    let r = send(
        &e.app,
        post_form(
            "/exercises",
            Some(&kim.cookie),
            &[
                ("name", "no-plan"),
                ("scene", "chest-wall"),
                ("threshold_k", "2"),
                ("csrf", &kim.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    assert_eq!(count(&e.store, "exercises").await, before);

    // editing: the form posted back as shown keeps the plan; a changed field changes it
    let edit = format!("/exercises/{}", new.id);
    let page = body_text(send(&e.app, get(&edit, Some(&kim))).await).await;
    let form = form_values(&page, &edit);
    let pairs: Vec<(&str, &str)> = form.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let r = send(&e.app, post_form(&edit, Some(&kim.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(
        e.store.get_exercise(new.id).await.unwrap().plan_id,
        new.plan_id
    );
    let pairs: Vec<(&str, &str)> = form
        .iter()
        .map(|(k, v)| (k.as_str(), if k == "exit_x_mm" { "45" } else { v.as_str() }))
        .collect();
    let r = send(&e.app, post_form(&edit, Some(&kim.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let edited = e.store.get_exercise(new.id).await.unwrap();
    assert_ne!(edited.plan_id, new.plan_id);
    let plan = e
        .store
        .get_plan(edited.plan_id)
        .await
        .unwrap()
        .into_incision()
        .unwrap();
    assert_eq!(plan.exit_m[0], 0.045);
    assert_eq!(
        plan.incision_m,
        vec![plan.entry_m, plan.exit_m],
        "a straight line now"
    );
    assert_eq!(plan.depth_m, 0.005, "the rest kept");
    // a bad number: 400 as a page, the plan unchanged
    let pairs: Vec<(&str, &str)> = form
        .iter()
        .map(|(k, v)| {
            (
                k.as_str(),
                if k == "depth_mm" { "deep" } else { v.as_str() },
            )
        })
        .collect();
    let r = send(&e.app, post_form(&edit, Some(&kim.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    assert_eq!(
        e.store.get_exercise(new.id).await.unwrap().plan_id,
        edited.plan_id
    );
}

#[tokio::test]
async fn a_kiosk_link_logs_its_trainee_in_once() {
    use cutlab_dashboard::auth::kiosk;
    let (e, state) = env_with(cutlab_dashboard::Config::default()).await;
    // a staff member gets no kiosk
    assert!(kiosk::issue(&state, "dr-kim").await.is_err());
    assert!(kiosk::issue(&state, "nobody").await.is_err());
    let link = kiosk::issue(&state, "ana").await.unwrap();
    // someone else's guess neither works nor spends the link
    let wrong = format!("/kiosk/{}", "0".repeat(64));
    assert_eq!(
        send(&e.app, get(&wrong, None)).await.status(),
        StatusCode::FORBIDDEN
    );
    let r = send(&e.app, get(&link, None)).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(r.headers()[header::LOCATION], "/station");
    let token = set_cookie(&r, "cutlab_session").expect("a session cookie");
    let ana = Session {
        cookie: format!("cutlab_session={token}"),
        csrf: String::new(),
    };
    let page = body_text(send(&e.app, get("/station", Some(&ana))).await).await;
    assert!(
        page.contains("ana") && page.contains("id=\"start\""),
        "{page}"
    );
    // once only
    let again = send(&e.app, get(&link, None)).await;
    assert_eq!(again.status(), StatusCode::FORBIDDEN);
    assert!(set_cookie(&again, "cutlab_session").is_none());
}

#[tokio::test]
async fn the_station_offers_its_devices_and_refuses_others() {
    let mut config = cutlab_dashboard::Config::default();
    config.station.devices = vec!["expert".parse().unwrap(), "igtl:18944".parse().unwrap()];
    let (e, state) = env_with(config).await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let page = body_text(send(&e.app, get("/station", Some(&ana))).await).await;
    for option in [
        "value=\"pointer\"",
        "value=\"expert\"",
        "value=\"igtl:18944\"",
    ] {
        assert!(page.contains(option), "{option}: {page}");
    }
    let r = send(
        &e.app,
        post_form(
            "/station/start",
            Some(&ana.cookie),
            &[
                ("exercise", cutlab_assessor::store::BUILTIN_EXERCISE),
                ("mode", "guided"),
                ("device", "igtl:1"),
                ("csrf", &ana.csrf),
            ],
        ),
    )
    .await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    let text = body_text(r).await;
    assert!(
        text.contains("no device") && text.contains("igtl:1"),
        "{text}"
    );
    assert!(state.station().running().is_empty(), "nothing started");
}

/// cutting-basics with progression: pattern cutting is locked to ben (not proficient in the
/// incision) at the station's picker and its start (403, saying why) until dr-kim opens it
/// early, which his progress page records; ana, proficient, is offered it next.
#[tokio::test]
async fn a_locked_exercise_opens_by_proficiency_or_an_instructor() {
    use cutlab_assessor::store::{BUILTIN_EXERCISE, PATTERN_EXERCISE};
    let e = env().await;
    let (ben, ana) = (
        login(&e.app, "ben", "trainee-demo").await,
        login(&e.app, "ana", "trainee-demo").await,
    );
    let option = |page: &str| {
        let at = page
            .find("<option value=\"pattern-cutting\"")
            .expect("offered");
        page[at..at + page[at..].find("</option>").expect("closed")].to_owned()
    };
    let picker = body_text(send(&e.app, get("/station", Some(&ben))).await).await;
    assert!(option(&picker).contains("disabled") && option(&picker).contains("(locked)"));
    assert!(
        picker.contains(&format!("{BUILTIN_EXERCISE} (next)")),
        "{picker}"
    );
    let start = |s: &Session| {
        post_form(
            "/station/start",
            Some(&s.cookie),
            &[
                ("exercise", PATTERN_EXERCISE),
                ("mode", "exam"),
                ("csrf", &s.csrf),
            ],
        )
    };
    let r = send(&e.app, start(&ben)).await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    let why = body_text(r).await;
    assert!(
        why.contains("locked") && why.contains(BUILTIN_EXERCISE),
        "{why}"
    );
    let picker = body_text(send(&e.app, get("/station", Some(&ana))).await).await;
    assert!(option(&picker).contains("(next)"), "{picker}");
    assert!(!option(&picker).contains("disabled"));

    let ben_id = user_id(&e.store, "ben").await;
    let progress = format!("/trainees/{ben_id}");
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let page = body_text(send(&e.app, get(&progress, Some(&kim))).await).await;
    assert!(
        page.contains("locked until proficient in chest-wall-incision"),
        "{page}"
    );
    assert!(page.contains("id=\"open-early\""), "{page}");
    let open = |s: &Session| {
        post_form(
            &format!("{progress}/open"),
            Some(&s.cookie),
            &[
                ("exercise", PATTERN_EXERCISE),
                ("reason", "repeats the year"),
                ("csrf", &s.csrf),
            ],
        )
    };
    assert_eq!(
        send(&e.app, open(&ben)).await.status(),
        StatusCode::FORBIDDEN
    );
    assert!(send(&e.app, open(&kim)).await.status().is_redirection());
    let page = body_text(send(&e.app, get(&progress, Some(&ben))).await).await;
    assert!(
        page.contains("opened early by dr-kim") && page.contains("repeats the year"),
        "{page}"
    );
    assert!(
        !page.contains("id=\"open-early\""),
        "no form for the trainee"
    );
    let picker = body_text(send(&e.app, get("/station", Some(&ben))).await).await;
    assert!(!option(&picker).contains("disabled"), "{picker}");
}

#[tokio::test]
async fn a_lapse_after_proficiency_reads_as_a_lapse_beside_the_cusum() {
    use cutlab_assessor::store::Role;
    use cutlab_scoring::proficiency::{Course, CusumParams, ProficiencyStatus};
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let ex = e.store.ensure_builtins().await.unwrap();
    let t = e.store.thresholds(ex.id).await.unwrap();
    let cara = e
        .store
        .create_user("cara", Role::Trainee, None)
        .await
        .unwrap();
    let cohort = e
        .store
        .cohort_by_name(cutlab_dashboard::DEMO_COHORT)
        .await
        .unwrap();
    e.store.join_cohort(cohort.id, cara.id).await.unwrap();
    // two passes (proficient), then failures until the CUSUM after them is unacceptable
    let p = CusumParams::default();
    let mut outcomes = vec![true, true];
    while !matches!(
        Course::of(&outcomes, &p).unwrap().status,
        ProficiencyStatus::Lapsed { .. }
    ) {
        outcomes.push(false);
        assert!(outcomes.len() < 20);
    }
    let mut rng = cutlab_sim::rng::Rng::new(5);
    for &pass in &outcomes {
        let skill = if pass { 0.3 } else { 1.8 };
        let metrics = cutlab_dashboard::seed::synthetic_metrics(&t, skill, &mut rng);
        let a = e
            .store
            .start_attempt(cara.id, ex.id, None, false)
            .await
            .unwrap();
        let out = e.store.finish_attempt(a.id, &metrics).await.unwrap();
        assert_eq!(out.verdict.pass, pass);
    }
    let lapse = outcomes.len();
    // the store's standing, which the curriculum's progression reads, agrees
    let record = e.store.proficiency(cara.id, ex.id).await.unwrap();
    assert!(!record.state.proficient && record.lapsed(), "{record:?}");
    let page =
        body_text(send(&e.app, get(&format!("/trainees/{}", cara.id), Some(&kim))).await).await;
    let main = &page[page.find("<main>").unwrap()..];
    assert!(
        main.contains(&format!(
            "proficiency lapsed: unacceptable failure rate since attempt {lapse} — retrain"
        )),
        "{main}"
    );
    assert!(!main.contains("proficient since"), "{main}");
    // the CUSUM counts afresh after the lapse: its line does not contradict the standing
    assert!(
        main.contains(&format!("CUSUM after attempt {lapse}: 0.00"))
            && main.contains(&format!("counted afresh from 0 after attempt {lapse}")),
        "{main}"
    );
    let grid = body_text(send(&e.app, get("/cohorts", Some(&kim))).await).await;
    assert!(
        grid.contains(&format!(
            "unacceptable failure rate since attempt {lapse}: retrain"
        )),
        "{grid}"
    );
}

/// The pattern cutting exercise's page offers its kind's fields (the circle, not an
/// incision's entry and exit) and documents its keys; a changed radius is saved.
#[tokio::test]
async fn a_pattern_exercise_is_edited_through_its_own_fields() {
    let e = env().await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let ex = e
        .store
        .exercise_by_name(cutlab_assessor::store::PATTERN_EXERCISE)
        .await
        .unwrap();
    let path = format!("/exercises/{}", ex.id);
    let page = body_text(send(&e.app, get(&path, Some(&kim))).await).await;
    for key in ["centre_x_mm", "radius_mm", "cutoff_s", "viewpoint_z_mm"] {
        assert!(page.contains(&format!("name=\"{key}\"")), "{key}");
    }
    assert!(!page.contains("name=\"entry_x_mm\""));
    assert!(page.contains("<code>radius_m</code>") && page.contains("Expert plan (pattern)"));
    for c in controls(&page) {
        let id = attr(c, "id").unwrap_or_else(|| panic!("no id on {c}"));
        assert_eq!(
            page.matches(&format!(" for=\"{id}\"")).count(),
            1,
            "one label for {id}"
        );
    }
    let form = form_values(&page, &path);
    let pairs: Vec<(&str, &str)> = form
        .iter()
        .map(|(k, v)| (k.as_str(), if k == "radius_mm" { "25" } else { v.as_str() }))
        .collect();
    let r = send(&e.app, post_form(&path, Some(&kim.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER, "{}", body_text(r).await);
    let edited = e.store.get_exercise(ex.id).await.unwrap();
    let cutlab_scoring::ExercisePlan::Pattern(plan) =
        e.store.get_plan(edited.plan_id).await.unwrap()
    else {
        panic!("still a pattern plan");
    };
    assert_eq!(plan.radius_m, 0.025);
    assert_eq!(plan.centre_m, [0.05, 0.05, 0.002], "the rest kept");
}

#[tokio::test]
async fn the_evidence_page_compares_groups_and_an_instructor_adopts_its_pass_mark() {
    let e = env().await;
    let exercise = e
        .store
        .exercise_by_name(cutlab_assessor::store::BUILTIN_EXERCISE)
        .await
        .unwrap()
        .id;
    let path = format!("/exercises/{exercise}/evidence");
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let r = send(&e.app, get(&path, Some(&kim))).await;
    assert_eq!(r.status(), StatusCode::OK);
    let page = body_text(r).await;
    // the demo: dr-kim's attempts at an expert's level, ana's and ben's as novices
    assert!(
        page.contains("<strong>expert</strong>: 1 person, 6 attempts"),
        "{page}"
    );
    assert!(
        page.contains("<strong>novice</strong>: 2 people, 13 attempts"),
        "{page}"
    );
    assert!(
        page.contains("id=\"contrasting-cut\"") && page.contains("AUC"),
        "{page}"
    );
    assert!(page.matches("<svg").count() >= 3, "score, metrics, curves");
    // the learning curves say whose they are, coloured and named by experience (issue 63)
    let curves = &page[page.find("Overall score by attempt").unwrap()..];
    let curves = &curves[..curves.find("</svg>").unwrap()];
    for name in ["ana", "ben"] {
        assert!(
            curves.contains("class=\"end-label\"") && curves.contains(&format!(">{name}<")),
            "{name} named: {curves}"
        );
    }
    assert!(
        curves.contains("lc-novice") && curves.contains(">novice<"),
        "a legend by level"
    );
    assert!(page.contains("the interval decides"), "the rule is said");
    assert!(page.contains("id=\"reliability\"") && page.contains("ICC(2,1)"));
    assert!(page.contains("No pass mark adopted"));
    // the exercise page links it for staff
    let ex_page =
        body_text(send(&e.app, get(&format!("/exercises/{exercise}"), Some(&kim))).await).await;
    assert!(ex_page.contains("id=\"evidence-link\""));
    // a trainee: as if it did not exist, to read or to adopt
    let ana = login(&e.app, "ana", "trainee-demo").await;
    assert_eq!(
        send(&e.app, get(&path, Some(&ana))).await.status(),
        StatusCode::NOT_FOUND
    );
    let adopt = format!("{path}/adopt");
    let r = send(
        &e.app,
        post_form(&adopt, Some(&ana.cookie), &[("csrf", &ana.csrf)]),
    )
    .await;
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    let ana_ex =
        body_text(send(&e.app, get(&format!("/exercises/{exercise}"), Some(&ana))).await).await;
    assert!(!ana_ex.contains("evidence-link"));
    assert_eq!(e.store.pass_mark(exercise).await.unwrap(), None);
    // the instructor adopts it: recorded with who
    let r = send(
        &e.app,
        post_form(&adopt, Some(&kim.cookie), &[("csrf", &kim.csrf)]),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let mark = e.store.pass_mark(exercise).await.unwrap().unwrap();
    assert_eq!(mark.adopted_by, "dr-kim");
    let report = e.store.evidence(exercise, true).await.unwrap();
    assert_eq!(Some(mark.score), report.pass_mark.cut.map(|c| c.cut));
    let page = body_text(send(&e.app, get(&path, Some(&kim))).await).await;
    assert!(page.contains("id=\"adopted-pass-mark\"") && page.contains("by dr-kim"));
    // without the CSRF token: refused, nothing recorded
    let before = count(&e.store, "pass_marks").await;
    let r = send(&e.app, post_form(&adopt, Some(&kim.cookie), &[])).await;
    assert_ne!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(count(&e.store, "pass_marks").await, before);
    // the same as JSON for staff; 404 for a trainee
    let api = format!("/api/exercises/{exercise}/evidence");
    let json: serde_json::Value =
        serde_json::from_str(&body_text(send(&e.app, get(&api, Some(&kim))).await).await).unwrap();
    assert_eq!(json["report"]["higher"], "expert");
    assert_eq!(json["pass_mark"]["adopted_by"], "dr-kim");
    assert_eq!(
        send(&e.app, get(&api, Some(&ana))).await.status(),
        StatusCode::NOT_FOUND
    );
    // the reference attempts left out: the page says so
    let page = body_text(
        send(
            &e.app,
            get(&format!("{path}?reference=exclude"), Some(&kim)),
        )
        .await,
    )
    .await;
    assert!(page.contains("Reference attempts are left out"));
}

#[tokio::test]
async fn an_administrator_records_a_trainees_experience() {
    use cutlab_scoring::evidence::Experience;
    let e = env().await;
    let ben = user_id(&e.store, "ben").await;
    let path = format!("/trainees/{ben}/experience");
    let record = |who: &Session, level: &str| {
        post_form(
            &path,
            Some(&who.cookie),
            &[("csrf", &who.csrf), ("level", level)],
        )
    };
    let admin = login(&e.app, "admin", "admin-demo").await;
    let page = body_text(send(&e.app, get(&format!("/trainees/{ben}"), Some(&admin))).await).await;
    assert!(page.contains("id=\"set-experience\""), "{page}");
    let r = send(&e.app, record(&admin, "intermediate")).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    let intermediate = Some(Experience::Intermediate);
    assert_eq!(e.store.experience(ben).await.unwrap(), intermediate);
    // a bad level: 400, unchanged
    let r = send(&e.app, record(&admin, "surgeon")).await;
    assert_eq!(r.status(), StatusCode::BAD_REQUEST);
    assert_eq!(e.store.experience(ben).await.unwrap(), intermediate);
    // an instructor sees the level but does not set it
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let page = body_text(send(&e.app, get(&format!("/trainees/{ben}"), Some(&kim))).await).await;
    assert!(page.contains("Experience: intermediate") && !page.contains("set-experience"));
    let r = send(&e.app, record(&kim, "expert")).await;
    assert_eq!(r.status(), StatusCode::FORBIDDEN);
    assert_eq!(e.store.experience(ben).await.unwrap(), intermediate);
    // none clears it
    let r = send(&e.app, record(&admin, "none")).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    assert_eq!(e.store.experience(ben).await.unwrap(), None);
}

#[tokio::test]
async fn an_attempt_that_never_touched_the_tissue_is_shown_unscored_with_what_to_do() {
    let e = env().await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let ana_id = common::user_id(&e.store, "ana").await;
    let exercise = e
        .store
        .exercise_by_name("chest-wall-incision")
        .await
        .unwrap();
    let a = e
        .store
        .start_attempt(ana_id, exercise.id, None, false)
        .await
        .unwrap();
    e.store
        .mark_incomplete(a.id, Some(cutlab_scoring::UNTOUCHED_NOTE))
        .await
        .unwrap();
    let page = body_text(send(&e.app, get(&format!("/attempts/{}", a.id), Some(&ana))).await).await;
    assert!(page.contains("id=\"fix-next\""), "what to do next is said");
    assert!(page.contains("never touched the tissue"));
    assert!(
        !page.contains("Within every limit"),
        "no praise for nothing"
    );
}

/// The candidates' fields of a planning form: `(letter, [x0, y0, x1, y1, depth])` in mm.
fn planning_form<'a>(
    csrf: &'a str,
    rows: &[(char, [&'a str; 5])],
    more: &[(&'a str, &'a str)],
) -> Vec<(String, String)> {
    let mut form = vec![("csrf".to_owned(), csrf.to_owned())];
    for (letter, values) in rows {
        let l = letter.to_ascii_lowercase();
        for (key, v) in ["from_x", "from_y", "to_x", "to_y", "depth"]
            .iter()
            .zip(values)
        {
            form.push((format!("{l}_{key}"), (*v).to_owned()));
        }
    }
    form.extend(more.iter().map(|(k, v)| ((*k).to_owned(), (*v).to_owned())));
    form
}

/// The planning page (issue 62): an instructor draws candidates on a field exercise and
/// compares what each exposes beside the expert's plan; a trainee, and an exercise of another
/// kind, get 404; a candidate that is not an incision is refused, named.
#[tokio::test]
async fn an_instructor_compares_candidate_incisions_by_their_fields() {
    let e = env().await;
    let field = e
        .store
        .exercise_by_name("mini-thoracotomy")
        .await
        .unwrap()
        .id;
    let other = e
        .store
        .exercise_by_name(cutlab_assessor::store::BUILTIN_EXERCISE)
        .await
        .unwrap()
        .id;
    let path = format!("/exercises/{field}/planning");
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let page = body_text(send(&e.app, get(&path, Some(&kim))).await).await;
    assert!(page.contains("id=\"skin-map\""), "{page}");
    assert_eq!(
        page.matches("class=\"landmark\"").count(),
        5,
        "the sternum's edge and four ribs"
    );
    assert!(
        page.contains("class=\"expert\"") && page.contains("value=\"20.0\""),
        "the retractor's 20 mm"
    );
    let ex_page =
        body_text(send(&e.app, get(&format!("/exercises/{field}"), Some(&kim))).await).await;
    assert!(ex_page.contains("id=\"planning-link\""));
    let other_page =
        body_text(send(&e.app, get(&format!("/exercises/{other}"), Some(&kim))).await).await;
    assert!(!other_page.contains("planning-link"));
    let r = send(
        &e.app,
        get(&format!("/exercises/{other}/planning"), Some(&kim)),
    )
    .await;
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    let ana = login(&e.app, "ana", "trainee-demo").await;
    assert_eq!(
        send(&e.app, get(&path, Some(&ana))).await.status(),
        StatusCode::NOT_FOUND
    );
    let space = ('A', ["-20", "-2.5", "30", "-2.5", "45"]);
    let form = planning_form(&ana.csrf, &[space], &[]);
    let pairs: Vec<(&str, &str)> = form.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let r = send(&e.app, post_form(&path, Some(&ana.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::NOT_FOUND);

    // the 4th space against the 4th rib, retracted to 20 mm
    let rib = ('B', ["-20", "11.5", "30", "11.5", "45"]);
    let form = planning_form(&kim.csrf, &[space, rib], &[("retract_mm", "20")]);
    let pairs: Vec<(&str, &str)> = form.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let r = send(&e.app, post_form(&path, Some(&kim.cookie), &pairs)).await;
    assert_eq!(r.status(), StatusCode::OK);
    let page = body_text(r).await;
    let column = |id: &str| {
        let at = page
            .find(&format!("id=\"field-{id}\""))
            .unwrap_or_else(|| panic!("{id}: {page}"));
        page[at..page[at..]
            .find("</section>")
            .map_or(page.len(), |end| at + end)]
            .to_owned()
    };
    let (expert, a, b) = (
        column("expert-s-plan"),
        column("candidate-a"),
        column("candidate-b"),
    );
    assert_eq!(
        page.matches("src=\"data:image/png;base64,").count(),
        6,
        "opened and retracted, three columns"
    );
    assert!(
        a.contains("class=\"damaged\">nothing") && expert.contains("class=\"damaged\">nothing"),
        "{a}"
    );
    assert!(b.contains("<strong>rib</strong>"), "{b}");
    assert!(
        b.contains("class=\"seen\">0 mm²"),
        "nothing through the rib: {b}"
    );
    assert!(a.contains("% of the expert's"), "{a}");
    assert!(
        page.contains("id=\"planning-best\">Candidate A exposes the most"),
        "{page}"
    );
    assert!(
        page.contains("value=\"11.5\""),
        "the form keeps what was sent"
    );
    // two comparisons at once: one is made, the other is told to come back (503), not queued
    let form = planning_form(&kim.csrf, &[space], &[]);
    let pairs: Vec<(&str, &str)> = form.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let (r1, r2) = tokio::join!(
        send(&e.app, post_form(&path, Some(&kim.cookie), &pairs)),
        send(&e.app, post_form(&path, Some(&kim.cookie), &pairs))
    );
    let mut statuses = [r1.status(), r2.status()];
    statuses.sort();
    assert_eq!(statuses, [StatusCode::OK, StatusCode::SERVICE_UNAVAILABLE]);

    // what is not an incision: 400 and the field named
    for (rows, more, says) in [
        (vec![], vec![], "at least one candidate"),
        (
            vec![('A', ["NaN", "0", "10", "0", "45"])],
            vec![],
            "Candidate A, start x",
        ),
        (
            vec![('C', ["0", "0", "", "0", "45"])],
            vec![],
            "Candidate C: give its start, its end and its depth",
        ),
        (
            vec![('A', ["500", "0", "10", "0", "45"])],
            vec![],
            "off the tissue",
        ),
        (
            vec![('D', ["0", "-2.5", "20", "-2.5", "0"])],
            vec![],
            "depth_m",
        ),
        (
            vec![space],
            vec![("retract_mm", "-5")],
            "The retractor's width",
        ),
    ] {
        let form = planning_form(&kim.csrf, &rows, &more);
        let pairs: Vec<(&str, &str)> = form.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        let r = send(&e.app, post_form(&path, Some(&kim.cookie), &pairs)).await;
        assert_eq!(r.status(), StatusCode::BAD_REQUEST, "{says}");
        let text = body_text(r).await;
        assert!(text.contains(says), "{says}: {text}");
    }
}
