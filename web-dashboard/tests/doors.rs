//! The server's doors, tried as a hostile client would (issue 61), through real sockets on
//! loopback: idle sockets, crawling bodies, connection caps, login races and timing, the
//! session's streams after a logout, what a trainee may read, the text policy.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::{Duration, Instant};

use axum::http::{StatusCode, header};
use common::*;
use cutlab_dashboard::Config;
use cutlab_dashboard::pace::BodyPace;
use cutlab_dashboard::serve::Limits;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Limits of seconds, so that a test sees them act.
fn quick() -> Limits {
    Limits {
        header_timeout: Duration::from_secs(1),
        body: BodyPace {
            stall: Duration::from_secs(1),
            min_bytes_per_s: 1024.0,
            grace: Duration::from_secs(2),
        },
        ..Limits::default()
    }
}

fn config(limits: Limits) -> Config {
    Config {
        limits,
        ..Config::default()
    }
}

/// Whether `s` stays open and silent for `within`.
async fn silent(s: &mut tokio::net::TcpStream, within: Duration) -> bool {
    let mut buf = [0u8; 64];
    tokio::time::timeout(within, s.read(&mut buf))
        .await
        .is_err()
}

const GET_LOGIN: &str = "GET /login HTTP/1.1\r\nHost: ward\r\n\r\n";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sockets_that_send_nothing_are_closed_by_the_header_time() {
    let (_e, _state, addr) = served(config(quick())).await;
    let t0 = Instant::now();
    let mut idle = Vec::new();
    for _ in 0..20 {
        idle.push(connect_from("127.0.0.1", addr).await);
    }
    for s in &mut idle {
        let status = answer(s, Duration::from_secs(3)).await;
        assert!(status.is_none() || status == Some(408), "{status:?}");
    }
    let took = t0.elapsed();
    assert!(took < Duration::from_secs(3), "closed after {took:?}");
    // a kept-alive connection that goes quiet after its first request: closed as well
    let mut s = connect_from("127.0.0.1", addr).await;
    s.write_all(GET_LOGIN.as_bytes()).await.unwrap();
    let mut got = Vec::new();
    let t0 = Instant::now();
    tokio::time::timeout(Duration::from_secs(3), s.read_to_end(&mut got))
        .await
        .expect("closed within 3 s")
        .unwrap();
    assert!(String::from_utf8_lossy(&got).starts_with("HTTP/1.1 200"));
    assert!(
        t0.elapsed() >= Duration::from_millis(900),
        "{:?}",
        t0.elapsed()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_few_addresses_cannot_take_every_place() {
    let limits = Limits {
        header_timeout: Duration::from_secs(5),
        max_connections: 64,
        max_connections_per_ip: 32,
        max_connections_per_ip_when_busy: 4,
        ..quick()
    };
    let (_e, _state, addr) = served(config(limits)).await;
    // one address takes its 32 places: half of all, so the server is busy
    let mut first = Vec::new();
    for _ in 0..32 {
        first.push(connect_from("127.0.0.1", addr).await);
    }
    // accepted before the next address comes (a loaded machine accepts late)
    tokio::time::sleep(Duration::from_secs(1)).await;
    for s in &mut first {
        assert!(silent(s, Duration::from_millis(20)).await, "held");
    }
    // a second gets the busy share only
    let mut second = Vec::new();
    for _ in 0..8 {
        second.push(connect_from("127.0.0.2", addr).await);
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    for (k, s) in second.iter_mut().enumerate() {
        if k < 4 {
            assert!(
                silent(s, Duration::from_millis(100)).await,
                "place {k} held"
            );
        } else {
            assert_eq!(answer(s, Duration::from_secs(1)).await, Some(503), "{k}");
        }
    }
    // and everyone else is still served
    for from in ["127.0.0.3", "127.0.0.4"] {
        let answer = exchange(
            from,
            addr,
            "GET /login HTTP/1.1\r\nHost: ward\r\nConnection: close\r\n\r\n",
        )
        .await;
        assert!(answer.starts_with("HTTP/1.1 200"), "{from}: {answer:.80}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_never_reads_its_answer_is_let_go() {
    let limits = Limits {
        write_stall: Duration::from_secs(1),
        ..quick()
    };
    let (e, _state, addr) = served(config(limits)).await;
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let r = send(&e.app, get("/viewer/re_viewer_bg.wasm", Some(&ana))).await;
    let full: usize = r.headers()[header::CONTENT_LENGTH]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    // a small window, and no read: the server's writes wait
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let mut s = socket.connect(addr).await.unwrap();
    s.write_all(
        format!(
            "GET /viewer/re_viewer_bg.wasm HTTP/1.1\r\nHost: ward\r\nCookie: {}\r\n\r\n",
            ana.cookie
        )
        .as_bytes(),
    )
    .await
    .unwrap();
    tokio::time::sleep(Duration::from_secs(3)).await;
    let mut got = Vec::new();
    let mut buf = vec![0u8; 1 << 16];
    let t0 = Instant::now();
    loop {
        match tokio::time::timeout(Duration::from_secs(5), s.read(&mut buf)).await {
            Ok(Ok(0) | Err(_)) => break,
            Ok(Ok(n)) => got.extend_from_slice(&buf[..n]),
            Err(_) => panic!(
                "still open after {:?}, {} bytes read",
                t0.elapsed(),
                got.len()
            ),
        }
    }
    assert!(got.len() < full / 2, "{} of {full} bytes: cut", got.len());
}

/// The head of a request with a `Content-Length` of 100,000 whose body is still to come.
fn announced(method_path: &str, extra: &str) -> String {
    format!(
        "{method_path} HTTP/1.1\r\nHost: ward\r\n{extra}Content-Type: application/x-www-form-urlencoded\r\nContent-Length: 100000\r\n\r\n"
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bodies_that_crawl_or_stall_are_cut_on_every_route() {
    let (e, _state, addr) = served(config(quick())).await;
    let token = e.store.create_station_token("or-crawl").await.unwrap();
    let uuid = cutlab_assessor::store::new_uuid().unwrap();
    let attempts = count(&e.store, "attempts").await;
    let requests = [
        announced("POST /login", ""),
        announced(
            &format!("PUT /api/hub/attempts/{uuid}"),
            &format!("Authorization: Bearer {token}\r\n"),
        ),
    ];
    for head in &requests {
        // ten bytes every half second: 20 B/s against 1 KiB/s after a 2 s grace
        let t0 = Instant::now();
        let mut s = connect_from("127.0.0.1", addr).await;
        s.write_all(head.as_bytes()).await.unwrap();
        let status = crawl(&mut s, 1000, 10, Duration::from_millis(500)).await;
        assert_eq!(status, Some(408), "{head:.40}");
        let took = t0.elapsed();
        assert!(
            took < Duration::from_secs(6),
            "{head:.40}: cut after {took:?}"
        );
        // a body that stops: cut after the stall
        let t0 = Instant::now();
        let mut s = connect_from("127.0.0.1", addr).await;
        s.write_all(head.as_bytes()).await.unwrap();
        assert_eq!(
            crawl(&mut s, 1, 5, Duration::from_millis(1)).await,
            Some(408)
        );
        assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
    }
    assert_eq!(
        count(&e.store, "attempts").await,
        attempts,
        "nothing stored"
    );
}

/// The login form's CSRF cookie and field, fetched over a socket.
async fn login_csrf_over(addr: std::net::SocketAddr) -> String {
    let page = exchange(
        "127.0.0.1",
        addr,
        "GET /login HTTP/1.1\r\nHost: ward\r\nConnection: close\r\n\r\n",
    )
    .await;
    let at = page.find("cutlab_login_csrf=").unwrap() + "cutlab_login_csrf=".len();
    page[at..at + 64].to_owned()
}

/// A form `fields` posted to `path` on a new connection from `from` with `cookie`: the whole
/// answer.
async fn post_over(
    from: &str,
    addr: std::net::SocketAddr,
    path: &str,
    cookie: &str,
    fields: &[(&str, &str)],
) -> String {
    let body: String = form_urlencoded::Serializer::new(String::new())
        .extend_pairs(fields)
        .finish();
    let request = format!(
        "POST {path} HTTP/1.1\r\nHost: ward\r\nConnection: close\r\nCookie: {cookie}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    exchange(from, addr, &request).await
}

/// A `GET` of `path` on a new connection with `cookie`: the whole answer.
async fn get_over(addr: std::net::SocketAddr, path: &str, cookie: &str) -> String {
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: ward\r\nConnection: close\r\nCookie: {cookie}\r\n\r\n"
    );
    exchange("127.0.0.1", addr, &request).await
}

/// The status of a whole answer.
fn status(answer: &str) -> u16 {
    answer.split(' ').nth(1).unwrap().parse().unwrap()
}

/// A login on a new connection from `from`: the whole answer.
async fn login_answer(
    from: &str,
    addr: std::net::SocketAddr,
    csrf: &str,
    user: &str,
    password: &str,
) -> String {
    let fields = [("username", user), ("password", password), ("csrf", csrf)];
    post_over(
        from,
        addr,
        "/login",
        &format!("cutlab_login_csrf={csrf}"),
        &fields,
    )
    .await
}

/// [`login_answer`]'s status.
async fn login_over(
    from: &str,
    addr: std::net::SocketAddr,
    csrf: &str,
    user: &str,
    password: &str,
) -> u16 {
    status(&login_answer(from, addr, csrf, user, password).await)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn guesses_sent_at_once_count_as_they_are_checked() {
    let (_e, _state, addr) = served(Config::default()).await;
    let csrf = login_csrf_over(addr).await;
    let mut guesses = tokio::task::JoinSet::new();
    for k in 0..30 {
        let csrf = csrf.clone();
        guesses.spawn(async move {
            login_over("127.0.0.1", addr, &csrf, "ana", &format!("guess-{k}")).await
        });
    }
    let mut statuses = Vec::new();
    while let Some(s) = guesses.join_next().await {
        statuses.push(s.unwrap());
    }
    let checked = statuses.iter().filter(|s| **s == 401).count();
    let refused = statuses.iter().filter(|s| **s == 429).count();
    assert_eq!((checked, refused), (5, 25), "{statuses:?}");
    // locked out at that address, not at her own
    assert_eq!(
        login_over("127.0.0.1", addr, &csrf, "ana", "trainee-demo").await,
        429
    );
    assert_eq!(
        login_over("127.0.0.2", addr, &csrf, "ana", "trainee-demo").await,
        303
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unknown_name_costs_the_time_of_a_known_one() {
    let (_e, _state, addr) = served(Config::default()).await;
    let csrf = login_csrf_over(addr).await;
    let (mut known, mut unknown) = (Vec::new(), Vec::new());
    for k in 0..4 {
        // one failure per name and address: no limit is near
        let user = ["ana", "ben", "dr-kim", "admin"][k];
        let t0 = Instant::now();
        assert_eq!(
            login_over("127.0.0.1", addr, &csrf, user, "wrong").await,
            401
        );
        known.push(t0.elapsed().as_secs_f64());
        let t0 = Instant::now();
        let nobody = format!("nobody-{k}");
        assert_eq!(
            login_over("127.0.0.1", addr, &csrf, &nobody, "wrong").await,
            401
        );
        unknown.push(t0.elapsed().as_secs_f64());
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[1] + v[2]) / 2.0
    };
    let (k, u) = (median(&mut known), median(&mut unknown));
    // argon2 is tens of milliseconds, a lookup alone well under one: 50x apart before; the
    // bounds leave room for a loaded machine
    assert!(
        u > k / 3.0 && u < 3.0 * k,
        "known {k:.4} s, unknown {u:.4} s"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_logout_ends_the_sessions_event_stream() {
    let (e, _state, addr) = served(Config::default()).await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let mut s = connect_from("127.0.0.1", addr).await;
    s.write_all(
        format!(
            "GET /supervision/events HTTP/1.1\r\nHost: ward\r\nCookie: {}\r\n\r\n",
            kim.cookie
        )
        .as_bytes(),
    )
    .await
    .unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while !String::from_utf8_lossy(&got).contains("event: running") {
        let n = tokio::time::timeout(Duration::from_secs(5), s.read(&mut buf))
            .await
            .expect("an event")
            .unwrap();
        assert!(n > 0, "closed before an event");
        got.extend_from_slice(&buf[..n]);
    }
    let r = send(
        &e.app,
        post_form("/logout", Some(&kim.cookie), &[("csrf", &kim.csrf)]),
    )
    .await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER);
    // the stream's last chunk within a few of its periods
    let t0 = Instant::now();
    got.clear();
    while !got.ends_with(b"0\r\n\r\n") {
        let n = tokio::time::timeout(Duration::from_secs(4), s.read(&mut buf))
            .await
            .expect("the stream ends")
            .unwrap();
        if n == 0 {
            break;
        }
        got.extend_from_slice(&buf[..n]);
    }
    assert!(t0.elapsed() < Duration::from_secs(4));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trainee_never_reads_an_exam_only_plan() {
    let (e, _state, addr) = served(Config::default()).await;
    let exercise = e
        .store
        .exercise_by_name("chest-wall-incision")
        .await
        .unwrap();
    let path = format!("/api/exercises/{}", exercise.id);
    let ana = login(&e.app, "ana", "trainee-demo").await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let plan_of = |answer: String| {
        let body = &answer[answer.find("\r\n\r\n").unwrap() + 4..];
        serde_json::from_str::<serde_json::Value>(body).unwrap()["plan"].clone()
    };
    assert!(plan_of(get_over(addr, &path, &ana.cookie).await).is_object());
    let edit = cutlab_assessor::store::ExerciseEdit {
        scene: &exercise.scene,
        description: &exercise.description,
        threshold_k: exercise.threshold_k,
        exam_only: true,
    };
    e.store
        .update_exercise(exercise.id, &edit, None)
        .await
        .unwrap();
    assert!(plan_of(get_over(addr, &path, &ana.cookie).await).is_null());
    assert!(
        plan_of(get_over(addr, &path, &kim.cookie).await).is_object(),
        "an instructor reads it"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_secure_flag_is_set_when_asked() {
    let (_e, _state, addr) = served(Config {
        secure_cookies: true,
        ..Config::default()
    })
    .await;
    let cookie_lines = |answer: &str| -> Vec<String> {
        answer
            .lines()
            .filter(|l| l.to_ascii_lowercase().starts_with("set-cookie:"))
            .map(str::to_owned)
            .collect()
    };
    let csrf = login_csrf_over(addr).await;
    let form = get_over(addr, "/login", "").await;
    let answer = login_answer("127.0.0.1", addr, &csrf, "ana", "trainee-demo").await;
    assert_eq!(status(&answer), 303);
    let cookies = [cookie_lines(&form), cookie_lines(&answer)].concat();
    assert!(
        cookies.iter().any(|c| c.contains("cutlab_session=")),
        "{cookies:?}"
    );
    for c in &cookies {
        assert!(c.trim_end().ends_with("; Secure"), "{c}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn text_with_control_or_reordering_characters_is_refused_on_every_path() {
    let (e, _state, addr) = served(Config::default()).await;
    let kim = login(&e.app, "dr-kim", "instructor-demo").await;
    let a = first_attempt(&e.store, "ana").await;
    let path = format!("/attempts/{a}/comments");
    let before = count(&e.store, "attempt_comments").await;
    for body in [
        "bell\u{7} and esc\u{1b}[2J",
        "nul\0",
        "invoice\u{202e}fdp.exe",
    ] {
        let fields = [("csrf", kim.csrf.as_str()), ("body", body)];
        let answer = post_over("127.0.0.1", addr, &path, &kim.cookie, &fields).await;
        assert_eq!(status(&answer), 400, "{body:?}");
    }
    assert_eq!(count(&e.store, "attempt_comments").await, before);
    let fields = [
        ("csrf", kim.csrf.as_str()),
        ("body", "two lines\nof advice"),
    ];
    let answer = post_over("127.0.0.1", addr, &path, &kim.cookie, &fields).await;
    assert!((300..400).contains(&status(&answer)), "{answer:.200}");
    // the store refuses what any other path (the CLI, a hub's import) would bring
    for bad in ["spring\u{1b}", "rtl\u{202e}", &"x".repeat(100_000)] {
        assert!(e.store.create_cohort(bad, None).await.is_err(), "{bad:.20}");
        assert!(
            e.store.create_curriculum(bad, "").await.is_err(),
            "{bad:.20}"
        );
    }
    let huge = "d".repeat(1 << 20);
    let err = e.store.create_curriculum("big", &huge).await.unwrap_err();
    assert!(err.to_string().contains("at most 2000"), "{err}");
}
