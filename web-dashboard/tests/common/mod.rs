//! Shared by the HTTP tests: a fresh database per test with the demo seeded, the app, and a
//! tiny client over `tower::ServiceExt::oneshot`. The database is a temporary SQLite file,
//! or with `CUTLAB_TEST_DASHBOARD_ON=postgres` a scratch database on the PostgreSQL server of
//! `$CUTLAB_TEST_POSTGRES` (CI runs the suite both ways).
#![allow(dead_code, clippy::unwrap_used)]

use axum::Router;
use axum::body::Body;
use axum::http::{Method, Request, Response, StatusCode, header};
pub use cutlab_assessor::on_db;
use cutlab_assessor::store::{DbLocation, Store, TEST_POSTGRES_ENV, scratch_postgres};
use cutlab_dashboard::{AppState, Config, app, seed_demo};
use http_body_util::BodyExt;
use tower::ServiceExt;

#[derive(Debug)]
pub struct Env {
    pub app: Router,
    pub store: Store,
    /// Where `store` is (another process may open it too).
    pub db: DbLocation,
    pub dir: tempfile::TempDir,
}

pub async fn env() -> Env {
    env_with(Config::default()).await.0
}

/// [`env`] with `config`, and the app's state.
pub async fn env_with(config: Config) -> (Env, AppState) {
    let dir = tempfile::tempdir().unwrap();
    let db = database(&dir).await;
    let store = Store::open(&db).await.unwrap();
    seed_demo(&store).await.unwrap();
    let state = AppState::new(store.clone(), config).unwrap();
    let app = app(state.clone());
    (
        Env {
            app,
            store,
            db,
            dir,
        },
        state,
    )
}

/// The environment variable that puts the suite on PostgreSQL (`postgres`).
pub const ENGINE_ENV: &str = "CUTLAB_TEST_DASHBOARD_ON";

/// A fresh database for one test: an SQLite file in `dir`, or a scratch PostgreSQL database
/// when [`ENGINE_ENV`] asks for one.
pub async fn database(dir: &tempfile::TempDir) -> DbLocation {
    match std::env::var(ENGINE_ENV).as_deref() {
        Ok("postgres") => {
            let server = std::env::var(TEST_POSTGRES_ENV)
                .unwrap_or_else(|_| panic!("{ENGINE_ENV}=postgres needs {TEST_POSTGRES_ENV}"));
            scratch_postgres(&server, "cutlab_dashboard_test")
                .await
                .unwrap()
        }
        Ok("sqlite") | Err(_) => DbLocation::Sqlite(dir.path().join("cutlab.db")),
        Ok(other) => panic!("{ENGINE_ENV}={other}: postgres or sqlite"),
    }
}

/// A logged-in browser: its cookie and the session's CSRF token.
#[derive(Debug, Clone)]
pub struct Session {
    pub cookie: String,
    pub csrf: String,
}

pub async fn send(app: &Router, req: Request<Body>) -> Response<Body> {
    app.clone().oneshot(req).await.unwrap()
}

pub async fn body_text(r: Response<Body>) -> String {
    String::from_utf8_lossy(&r.into_body().collect().await.unwrap().to_bytes()).into_owned()
}

pub fn get(path: &str, s: Option<&Session>) -> Request<Body> {
    let mut b = Request::get(path);
    if let Some(s) = s {
        b = b.header(header::COOKIE, &s.cookie);
    }
    b.body(Body::empty()).unwrap()
}

pub fn post_form(path: &str, cookie: Option<&str>, form: &[(&str, &str)]) -> Request<Body> {
    let body: String = form_urlencoded::Serializer::new(String::new())
        .extend_pairs(form)
        .finish();
    let mut b = Request::builder()
        .method(Method::POST)
        .uri(path)
        .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded");
    if let Some(c) = cookie {
        b = b.header(header::COOKIE, c);
    }
    b.body(Body::from(body)).unwrap()
}

pub fn set_cookie(r: &Response<Body>, name: &str) -> Option<String> {
    r.headers()
        .get_all(header::SET_COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .find_map(|v| {
            v.split(';')
                .next()?
                .trim()
                .strip_prefix(name)?
                .strip_prefix('=')
                .map(str::to_owned)
        })
}

/// The login form's CSRF cookie token.
pub async fn login_csrf(app: &Router) -> String {
    let r = send(app, get("/login", None)).await;
    assert_eq!(r.status(), StatusCode::OK);
    set_cookie(&r, "cutlab_login_csrf").unwrap()
}

/// Posts the login form; returns the answer. Without a client address (as `oneshot` sends
/// it), every such login counts against one address.
pub async fn try_login(app: &Router, user: &str, password: &str) -> Response<Body> {
    let csrf = login_csrf(app).await;
    send(
        app,
        post_form(
            "/login",
            Some(&format!("cutlab_login_csrf={csrf}")),
            &[("username", user), ("password", password), ("csrf", &csrf)],
        ),
    )
    .await
}

/// Posts the login form from the client address `ip` (the connection info the server's
/// `into_make_service_with_connect_info` would add).
pub async fn try_login_from(app: &Router, ip: &str, user: &str, password: &str) -> Response<Body> {
    let csrf = login_csrf(app).await;
    let mut req = post_form(
        "/login",
        Some(&format!("cutlab_login_csrf={csrf}")),
        &[("username", user), ("password", password), ("csrf", &csrf)],
    );
    let addr = std::net::SocketAddr::new(ip.parse().unwrap(), 40_000);
    req.extensions_mut()
        .insert(axum::extract::ConnectInfo(addr));
    send(app, req).await
}

/// Logs in (must succeed) and reads the session's CSRF token off a page.
pub async fn login(app: &Router, user: &str, password: &str) -> Session {
    let r = try_login(app, user, password).await;
    assert_eq!(r.status(), StatusCode::SEE_OTHER, "login of {user}");
    let token = set_cookie(&r, "cutlab_session").unwrap();
    let cookie = format!("cutlab_session={token}");
    let page = body_text(
        send(
            app,
            get(
                "/curriculum",
                Some(&Session {
                    cookie: cookie.clone(),
                    csrf: String::new(),
                }),
            ),
        )
        .await,
    )
    .await;
    let at = page.find("name=\"csrf\" value=\"").unwrap() + "name=\"csrf\" value=\"".len();
    let csrf = page[at..at + 64].to_owned();
    Session { cookie, csrf }
}

pub async fn user_id(store: &Store, name: &str) -> i64 {
    store.user_by_name(name).await.unwrap().id
}

/// The first attempt of `name`.
pub async fn first_attempt(store: &Store, name: &str) -> i64 {
    store
        .list_attempts(Some(user_id(store, name).await), None)
        .await
        .unwrap()[0]
        .id
}

pub async fn count(store: &Store, table: &str) -> i64 {
    on_db!(store.db(), pool => {
        sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT COUNT(*) FROM {table}")))
            .fetch_one(pool)
            .await
    })
    .unwrap()
}

/// `n` real, whole recordings in `dir` (`real-<k>.mcap`): the synthetic expert cutting the
/// chest wall for 0.3 s of simulated time, seeded by `k` so each is its own. What a hub
/// takes as a complete attempt's recording (it scores it).
pub async fn real_recordings(dir: &std::path::Path, n: usize) -> Vec<std::path::PathBuf> {
    let dir = dir.to_owned();
    tokio::task::spawn_blocking(move || {
        use cutlab_sim::scene::{BuildOptions, Scene};
        let scene = Scene::load("chest-wall", BuildOptions::default()).unwrap();
        (0..n)
            .map(|k| {
                let path = dir.join(format!("real-{k}.mcap"));
                cutlab_recorder::record::record_expert(
                    &scene,
                    "chest-wall",
                    0.3,
                    k as u64 + 1,
                    &path,
                )
                .unwrap();
                path
            })
            .collect()
    })
    .await
    .unwrap()
}

// ---- a client on a real socket (the server's limits act only there) ----

use std::net::SocketAddr;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// [`env_with`] `config`, served on a loopback port: the environment, the state and where.
pub async fn served(config: Config) -> (Env, AppState, SocketAddr) {
    let (e, state) = env_with(config).await;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(cutlab_dashboard::serve(
        listener,
        state.clone(),
        std::future::pending(),
    ));
    (e, state, addr)
}

/// A connection to `to` from the loopback address `from` (`127.0.0.x`: another client).
pub async fn connect_from(from: &str, to: SocketAddr) -> TcpStream {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(format!("{from}:0").parse().unwrap()).unwrap();
    socket.connect(to).await.unwrap()
}

/// The status the server answers on `stream` within `within`: `Some(code)`, `None` if it
/// closed the connection without one; panics if it is still open and silent.
pub async fn answer<R: tokio::io::AsyncRead + Unpin>(
    stream: &mut R,
    within: Duration,
) -> Option<u16> {
    let mut got = Vec::new();
    let read = tokio::time::timeout(within, async {
        let mut buf = [0u8; 1024];
        loop {
            match stream.read(&mut buf).await {
                Ok(0) | Err(_) => return,
                Ok(n) => got.extend_from_slice(&buf[..n]),
            }
            if got.windows(2).any(|w| w == b"\r\n") {
                return;
            }
        }
    })
    .await;
    assert!(read.is_ok(), "no answer and not closed within {within:?}");
    let line = String::from_utf8_lossy(&got);
    line.split(' ').nth(1).and_then(|c| c.parse().ok())
}

/// Sends `sends` chunks of `chunk` bytes on `s`, one every `every`, then nothing, until the
/// server answers (its status; `None`: closed without one) or 10 s pass (a panic).
pub async fn crawl(s: &mut TcpStream, sends: usize, chunk: usize, every: Duration) -> Option<u16> {
    let (mut read, mut write) = s.split();
    let writing = async {
        let bytes = vec![b'x'; chunk];
        for _ in 0..sends {
            if write.write_all(&bytes).await.is_err() {
                break;
            }
            tokio::time::sleep(every).await;
        }
        std::future::pending::<()>().await
    };
    tokio::select! {
        status = answer(&mut read, Duration::from_secs(10)) => status,
        () = writing => None,
    }
}

/// One whole request on a new connection from `from`, read to its end (the server closes
/// it: `Connection: close`): the answer's status line, headers and body as text.
pub async fn exchange(from: &str, to: SocketAddr, request: &str) -> String {
    let mut s = connect_from(from, to).await;
    s.write_all(request.as_bytes()).await.unwrap();
    let mut got = Vec::new();
    tokio::time::timeout(Duration::from_secs(30), s.read_to_end(&mut got))
        .await
        .expect("an answer within 30 s")
        .unwrap();
    String::from_utf8_lossy(&got).into_owned()
}
