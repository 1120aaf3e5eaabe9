//! The load figure of `cutlab bench dashboard`: a seeded population (see
//! [`cutlab_dashboard::seed::seed_load`]), the dashboard on a loopback port, and `clients`
//! concurrent HTTP/1.1 keep-alive clients (hyper) requesting pages for `duration`; requests
//! per second and latency percentiles per target.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use anyhow::Context;
use cutlab_sim::stats::percentile;
use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper::{Method, Request, StatusCode};
use hyper_util::client::legacy::Client;
use hyper_util::client::legacy::connect::HttpConnector;
use hyper_util::rt::TokioExecutor;
use serde::Serialize;

/// What one load run measured.
#[derive(Debug, Clone, Serialize)]
pub struct LoadReport {
    pub target: String,
    pub clients: usize,
    pub duration_s: f64,
    pub requests: u64,
    /// Answers other than 200, and transport errors.
    pub errors: u64,
    pub requests_per_s: f64,
    /// Latency percentiles (`cutlab_sim::stats::percentile`, nearest rank) and maximum.
    pub p50_ms: f64,
    pub p90_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub mean_bytes: f64,
}

type HttpClient = Client<HttpConnector, Full<Bytes>>;

fn client(max_idle: usize) -> HttpClient {
    let mut c = HttpConnector::new();
    c.set_nodelay(true);
    Client::builder(TokioExecutor::new())
        .pool_max_idle_per_host(max_idle)
        .build(c)
}

/// Logs in at `addr` as `user` and returns the `Cookie` header value of the session.
pub async fn login(addr: SocketAddr, user: &str, password: &str) -> anyhow::Result<String> {
    let c = client(1);
    let get = Request::get(format!("http://{addr}/login")).body(Full::new(Bytes::new()))?;
    let r = c.request(get).await.context("GET /login")?;
    let csrf = set_cookie(r.headers(), cutlab_dashboard::auth::LOGIN_CSRF_COOKIE)
        .context("no login CSRF cookie")?;
    let form: String = form_urlencoded::Serializer::new(String::new())
        .append_pair("username", user)
        .append_pair("password", password)
        .append_pair("csrf", &csrf)
        .finish();
    let post = Request::builder()
        .method(Method::POST)
        .uri(format!("http://{addr}/login"))
        .header("content-type", "application/x-www-form-urlencoded")
        .header(
            "cookie",
            format!("{}={csrf}", cutlab_dashboard::auth::LOGIN_CSRF_COOKIE),
        )
        .body(Full::new(Bytes::from(form)))?;
    let r = c.request(post).await.context("POST /login")?;
    let token = set_cookie(r.headers(), cutlab_dashboard::auth::SESSION_COOKIE)
        .filter(|t| !t.is_empty())
        .with_context(|| format!("login refused ({})", r.status()))?;
    Ok(format!(
        "{}={token}",
        cutlab_dashboard::auth::SESSION_COOKIE
    ))
}

fn set_cookie(h: &hyper::HeaderMap, name: &str) -> Option<String> {
    h.get_all(hyper::header::SET_COOKIE)
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

/// `clients` concurrent clients GET `paths` (each client walks them from its own offset)
/// for `duration`, with `cookie`; `target` names the run.
pub async fn run(
    addr: SocketAddr,
    target: &str,
    paths: &[String],
    cookie: &str,
    clients: usize,
    duration: Duration,
) -> LoadReport {
    let http = client(clients);
    let deadline = Instant::now() + duration;
    let started = Instant::now();
    let mut tasks = Vec::with_capacity(clients);
    for k in 0..clients {
        let (http, paths, cookie) = (http.clone(), paths.to_vec(), cookie.to_owned());
        tasks.push(tokio::spawn(async move {
            let mut lat = Vec::new();
            let (mut errors, mut bytes) = (0u64, 0u64);
            let mut i = k * 7919;
            while Instant::now() < deadline && !paths.is_empty() {
                let path = &paths[i % paths.len()];
                i += 1;
                let Ok(req) = Request::get(format!("http://{addr}{path}"))
                    .header("cookie", &cookie)
                    .body(Full::new(Bytes::new()))
                else {
                    errors += 1;
                    continue;
                };
                let t0 = Instant::now();
                match http.request(req).await {
                    Ok(r) => {
                        let ok = r.status() == StatusCode::OK;
                        match r.into_body().collect().await {
                            Ok(b) if ok => {
                                bytes += b.to_bytes().len() as u64;
                                lat.push(t0.elapsed());
                            }
                            _ => errors += 1,
                        }
                    }
                    Err(_) => errors += 1,
                }
            }
            (lat, errors, bytes)
        }));
    }
    let (mut lat, mut errors, mut bytes) = (Vec::new(), 0, 0);
    for t in tasks {
        if let Ok((l, e, b)) = t.await {
            lat.extend(l);
            errors += e;
            bytes += b;
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    let mut ms: Vec<f64> = lat.iter().map(|d| d.as_secs_f64() * 1e3).collect();
    ms.sort_by(f64::total_cmp);
    let requests = ms.len() as u64;
    LoadReport {
        target: target.to_owned(),
        clients,
        duration_s: elapsed,
        requests,
        errors,
        requests_per_s: requests as f64 / elapsed,
        p50_ms: percentile(&ms, 0.50),
        p90_ms: percentile(&ms, 0.90),
        p99_ms: percentile(&ms, 0.99),
        max_ms: ms.last().copied().unwrap_or(f64::NAN),
        mean_bytes: if requests > 0 {
            bytes as f64 / requests as f64
        } else {
            0.0
        },
    }
}
