//! cutlab-dashboard: the instructors' and trainees' window on the assessment data, an axum
//! application over the assessor's SQLite store.
//!
//! [`app`] builds the router (no `main` here: `cutlab serve` runs it). One router per area:
//! [`auth`] (log in / log out), [`pages`] (cohort overview, trainee progress, attempt detail,
//! supervision, curriculum), [`api`] (the same data as JSON), [`recordings`] (downloads and
//! the rerun web viewer). Errors are [`error::AppError`], turned into responses in one place.
//!
//! Security: argon2id passwords (the store's); a session cookie `cutlab_session` (HttpOnly,
//! SameSite=Strict, a random 256-bit token of which the database keeps the SHA-256, 12 h);
//! a per-session CSRF token checked on every state-changing request before any handler;
//! login rate-limited (5 failures a minute per user name and address, 100 per address, then
//! 429, each guess counted before its password is checked: one address behind a clinic's NAT
//! does not lock every user out, and a stranger cannot lock a user out from everywhere; an
//! unknown name costs the time of a known one);
//! roles on every route: a trainee sees only their own data, an instructor the members of
//! the cohorts they lead, an administrator everything; anything else is a 404, so ids leak
//! nothing. See [`api`] for the JSON API.

pub mod access;
pub mod api;
pub mod auth;
pub mod cache;
pub mod charts;
pub mod data;
pub mod error;
pub mod extract;
pub mod hub;
pub mod origin;
pub mod pace;
pub mod pages;
pub mod recordings;
pub mod seed;
pub mod serve;
pub mod watch;

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use cutlab_assessor::store::Store;

pub use error::AppError;
pub use origin::PublicUrl;
pub use seed::{DEMO_ACCOUNTS, DEMO_COHORT, DemoAccount, seed_demo, seed_demo_accounts};

/// Settings of a dashboard.
#[derive(Debug, Clone)]
pub struct Config {
    /// Mark cookies `Secure` (when served over HTTPS, e.g. behind a proxy).
    pub secure_cookies: bool,
    /// Where people reach the dashboard, for the links it hands out ([`origin`]); else each
    /// request's own address.
    pub public_url: Option<PublicUrl>,
    /// Failed logins per user name from one address within `login_window`; beyond, that
    /// user waits at that address (429).
    pub login_failures: usize,
    /// Failed logins per client IP address (any user names) within `login_window`; beyond,
    /// that address waits. Much higher than `login_failures`: a clinic's users share one
    /// address behind its NAT, and one of them guessing must not lock the others out.
    pub login_failures_per_ip: usize,
    pub login_window: Duration,
    /// How the trainee station runs its sessions (where their recordings go, their time limit).
    pub station: cutlab_station::StationSettings,
    /// Station sessions the server runs at once (each takes a servo, a simulation and a
    /// recorder thread: about one core).
    pub max_station_sessions: usize,
    /// The recording store (object store) recordings are served from when an attempt has
    /// keys there; else from the path the attempt recorded.
    pub recordings: Option<cutlab_assessor::recordings::RecordingStore>,
    /// What the server allows its clients: header time, connections held.
    pub limits: serve::Limits,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            secure_cookies: false,
            public_url: None,
            login_failures: 5,
            login_failures_per_ip: 100,
            login_window: Duration::from_secs(60),
            station: cutlab_station::StationSettings::new("station-attempts"),
            max_station_sessions: 2,
            recordings: None,
            limits: serve::Limits::default(),
        }
    }
}

/// What every handler shares: the store, the login limiter, the trace cache, the viewer.
#[derive(Debug, Clone)]
pub struct AppState(Arc<Inner>);

#[derive(Debug)]
struct Inner {
    store: Store,
    config: Config,
    /// Failed logins per user name and address.
    limiter: auth::rate_limit::RateLimiter,
    /// Failed logins per client IP address.
    ip_limiter: auth::rate_limit::RateLimiter,
    traces: data::trace::TraceCache,
    viewer: recordings::Viewer,
    grants: auth::grants::GrantKey,
    caches: Caches,
    station: cutlab_station::StationSet,
    kiosk: auth::kiosk::KioskTicket,
    /// The hub's recording uploads under way.
    uploads: hub::Uploads,
    /// The planning page's comparisons and the attempts' field pictures (one at a time).
    planner: pages::planning::Planner,
    /// The attempts' field pictures (PNG).
    field_pictures: data::trace::RecordingCache<bytes::Bytes>,
}

/// The caches of the hot paths, valid until the database changes (see [`cache`]).
#[derive(Debug)]
pub(crate) struct Caches {
    pub changes: Arc<cache::Changes>,
    pub sessions: cache::TtlCache<String, auth::AuthSession>,
    pub access: cache::TtlCache<(i64, i64), bool>,
    pub users: cache::TtlCache<i64, cutlab_assessor::store::User>,
    pub progress: cache::TtlCache<i64, Arc<data::progress::Cached>>,
}

impl Caches {
    fn new() -> Self {
        let changes = Arc::new(cache::Changes::default());
        Self {
            sessions: cache::TtlCache::new(cache::SESSION_TTL, changes.clone()),
            access: cache::TtlCache::new(cache::ACCESS_TTL, changes.clone()),
            users: cache::TtlCache::new(cache::ACCESS_TTL, changes.clone()),
            progress: cache::TtlCache::new(cache::PROGRESS_TTL, changes.clone()),
            changes,
        }
    }
}

impl AppState {
    /// A state over an open store (its migrations, including the dashboard's tables, are
    /// applied by [`Store::open`]). Inside a Tokio runtime, it starts watching the database
    /// for changes ([`watch`]); the watcher ends with the state.
    pub fn new(store: Store, config: Config) -> Result<Self, AppError> {
        let limiter =
            auth::rate_limit::RateLimiter::new(config.login_failures, config.login_window);
        let ip_limiter =
            auth::rate_limit::RateLimiter::new(config.login_failures_per_ip, config.login_window);
        let grants = auth::grants::GrantKey::random()?;
        let caches = Caches::new();
        watch::spawn(store.db(), &caches.changes);
        let station = cutlab_station::StationSet::new(config.max_station_sessions);
        Ok(Self(Arc::new(Inner {
            store,
            limiter,
            ip_limiter,
            config,
            traces: Default::default(),
            viewer: recordings::Viewer::load(),
            grants,
            caches,
            station,
            kiosk: Default::default(),
            uploads: Default::default(),
            planner: Default::default(),
            field_pictures: Default::default(),
        })))
    }
    pub fn store(&self) -> &Store {
        &self.0.store
    }
    pub fn config(&self) -> &Config {
        &self.0.config
    }
    pub(crate) fn limiter(&self) -> &auth::rate_limit::RateLimiter {
        &self.0.limiter
    }
    pub(crate) fn ip_limiter(&self) -> &auth::rate_limit::RateLimiter {
        &self.0.ip_limiter
    }
    pub(crate) fn traces(&self) -> &data::trace::TraceCache {
        &self.0.traces
    }
    pub(crate) fn viewer(&self) -> &recordings::Viewer {
        &self.0.viewer
    }
    pub(crate) fn caches(&self) -> &Caches {
        &self.0.caches
    }
    pub(crate) fn grants(&self) -> &auth::grants::GrantKey {
        &self.0.grants
    }
    /// The station sessions running now.
    pub fn station(&self) -> &cutlab_station::StationSet {
        &self.0.station
    }
    pub(crate) fn kiosk(&self) -> &auth::kiosk::KioskTicket {
        &self.0.kiosk
    }
    pub(crate) fn uploads(&self) -> &hub::Uploads {
        &self.0.uploads
    }
    pub(crate) fn planner(&self) -> &pages::planning::Planner {
        &self.0.planner
    }
    pub(crate) fn field_pictures(&self) -> &data::trace::RecordingCache<bytes::Bytes> {
        &self.0.field_pictures
    }
    pub(crate) fn station_settings(&self) -> &cutlab_station::StationSettings {
        &self.0.config.station
    }
}

/// The dashboard's router: every area's routes behind the session layer.
pub fn app(state: AppState) -> Router {
    Router::new()
        .merge(auth::routes::router())
        .merge(auth::kiosk::router())
        .merge(pages::router())
        .merge(recordings::router())
        .nest("/api/hub", hub::router())
        .nest("/api", api::router())
        .fallback(|| async { AppError::NotFound })
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            auth::session_layer,
        ))
        // outermost: the session layer's own read of a form is held to the pace too
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            pace::pace_bodies,
        ))
        .with_state(state)
}

/// Serves the dashboard on `listener` until the future `shutdown` completes, within the
/// configured [`serve::Limits`] (fitted to the process's open-file limit).
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let limits = serve::fit_to_open_files(state.config().limits);
    serve::serve_with_limits(listener, app(state), limits, shutdown).await
}
