//! The server loop: [`axum::serve`]'s, with the limits a server on a hospital network needs
//! against a client that opens connections and never finishes them ([`Limits`]). Every
//! connection has a deadline from accept: its first request's headers (the first byte
//! included) and each later one's on a kept-alive connection must arrive within
//! [`Limits::header_timeout`] (hyper's own `header_read_timeout`, which runs from the
//! connection's start and between its requests); request bodies must keep coming
//! ([`Limits::body`], on every route: [`crate::pace`]), and answers must be read
//! ([`Limits::write_stall`]). The connections held at once are
//! capped, per client address and in all; once half the places are taken an address may hold
//! only [`Limits::max_connections_per_ip_when_busy`], so a few hostile addresses cannot take
//! every place. A connection past a cap is answered at once with a 503 and closed. Why these
//! and not others: docs/decisions.md ("The hub and a hostile station", "The server's doors").

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::pin::pin;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use tower::Service;

use crate::pace::BodyPace;

/// What a served dashboard allows its clients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Time from accept to a request's last header byte, and the longest a kept-alive
    /// connection may wait for its next request.
    pub header_timeout: Duration,
    /// How fast every request body must come.
    pub body: BodyPace,
    /// The longest a write to a client may wait (a client that stops reading its answer,
    /// or an event stream, is closed then).
    pub write_stall: Duration,
    /// Connections held at once, all clients together (lowered to what the process's open
    /// file limit allows when served, see [`fit_to_open_files`]).
    pub max_connections: usize,
    /// Connections held at once from one address while fewer than half of
    /// `max_connections` are held.
    pub max_connections_per_ip: usize,
    /// Connections held at once from one address once half of `max_connections` are held.
    pub max_connections_per_ip_when_busy: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            header_timeout: Duration::from_secs(10),
            body: BodyPace {
                stall: Duration::from_secs(10),
                // a LAN sends a station's 11 MB recording in well under a second
                min_bytes_per_s: 64.0 * 1024.0,
                grace: Duration::from_secs(15),
            },
            write_stall: Duration::from_secs(30),
            max_connections: 1024,
            // a clinic's NAT: a dozen browsers of six connections each
            max_connections_per_ip: 128,
            max_connections_per_ip_when_busy: 16,
        }
    }
}

/// `limits` with `max_connections` lowered so that the connections, and the files the
/// server needs besides (its database, recordings, the viewer), fit under the process's
/// limit of open files, after raising that soft limit as far as the hard one allows.
pub fn fit_to_open_files(limits: Limits) -> Limits {
    /// Files kept for the database, recordings being written and read, and the runtime.
    const RESERVE: u64 = 128;
    let open_files = match rlimit::increase_nofile_limit(u64::MAX) {
        Ok(n) => n,
        Err(e) => {
            tracing::warn!("reading the open file limit: {e}");
            return limits;
        }
    };
    let fit = usize::try_from(open_files.saturating_sub(RESERVE).max(32)).unwrap_or(usize::MAX);
    if fit < limits.max_connections {
        tracing::warn!(
            "{open_files} open files allowed: at most {fit} connections at once (raise `ulimit -n` for more)"
        );
    }
    Limits {
        max_connections: limits.max_connections.min(fit),
        ..limits
    }
}

/// The connections held now, in all and per address.
#[derive(Debug, Default)]
struct Held {
    total: usize,
    per_ip: HashMap<IpAddr, usize>,
}

/// One connection's place in [`Held`], given back when it closes.
struct Slot {
    held: Arc<Mutex<Held>>,
    ip: IpAddr,
}

impl Slot {
    /// A place for a connection from `ip`, if neither cap is reached.
    fn take(held: &Arc<Mutex<Held>>, ip: IpAddr, limits: &Limits) -> Option<Slot> {
        let mut h = held
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let from_ip = h.per_ip.get(&ip).copied().unwrap_or(0);
        let per_ip = if 2 * h.total >= limits.max_connections {
            limits.max_connections_per_ip_when_busy
        } else {
            limits.max_connections_per_ip
        };
        if h.total >= limits.max_connections || from_ip >= per_ip {
            return None;
        }
        h.total += 1;
        h.per_ip.insert(ip, from_ip + 1);
        Some(Slot {
            held: held.clone(),
            ip,
        })
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut h = self
            .held
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        h.total = h.total.saturating_sub(1);
        if let Some(n) = h.per_ip.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                h.per_ip.remove(&self.ip);
            }
        }
    }
}

/// Serves `router` on `listener` within `limits` until `shutdown` completes, then lets the
/// open connections finish their requests. The handlers see the client's address
/// ([`ConnectInfo<SocketAddr>`]).
pub async fn serve_with_limits(
    listener: tokio::net::TcpListener,
    router: Router,
    limits: Limits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let stop = CancellationToken::new();
    let stopping = stop.clone();
    tokio::spawn(async move {
        shutdown.await;
        stopping.cancel();
    });
    let held = Arc::new(Mutex::new(Held::default()));
    let (closed_tx, closed_rx) = watch::channel(());
    let mut said_accept_error = false;
    loop {
        let (stream, addr) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    // out of file descriptors, say: the open connections close in time
                    if !said_accept_error {
                        tracing::warn!("accepting a connection: {e}");
                        said_accept_error = true;
                    }
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = stop.cancelled() => break,
        };
        said_accept_error = false;
        let Some(slot) = Slot::take(&held, addr.ip(), &limits) else {
            tokio::spawn(refuse(stream));
            continue;
        };
        let conn = Connection {
            router: router.clone(),
            addr,
            limits,
            stop: stop.clone(),
            _closed: closed_rx.clone(),
            _slot: slot,
        };
        tokio::spawn(conn.run(stream));
    }
    drop(closed_rx);
    drop(listener);
    // every connection's task holds a receiver until it ends
    closed_tx.closed().await;
    Ok(())
}

/// A connection past a cap: a 503 that says so, then closed.
async fn refuse(mut stream: TcpStream) {
    const BODY: &str = "{\"error\":\"too many connections; try again in a moment\",\"status\":503}";
    let response = format!(
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nContent-Length: {}\r\nRetry-After: 1\r\nConnection: close\r\n\r\n{BODY}",
        BODY.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        stream.write_all(response.as_bytes()).await?;
        stream.shutdown().await
    })
    .await;
}

/// One accepted connection and what it holds until it closes.
struct Connection {
    router: Router,
    addr: SocketAddr,
    limits: Limits,
    stop: CancellationToken,
    _closed: watch::Receiver<()>,
    _slot: Slot,
}

impl Connection {
    async fn run(self, stream: TcpStream) {
        let _ = stream.set_nodelay(true);
        let (router, addr) = (self.router.clone(), self.addr);
        let service = hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
            let mut req = req.map(Body::new);
            req.extensions_mut().insert(ConnectInfo(addr));
            router.clone().call(req)
        });
        // HTTP/1 only: browsers speak HTTP/2 over TLS alone, which a proxy in front ends; and
        // the version sniffing of hyper-util's auto builder waits for a first byte with no
        // deadline (an idle socket held for ever)
        let mut builder = http1::Builder::new();
        builder
            .timer(TokioTimer::new())
            .header_read_timeout(self.limits.header_timeout)
            .max_buf_size(64 << 10);
        // a write that waits past `write_stall` fails: a client that never reads its answer
        // (nor its event stream, nor its socket's frames) holds nothing for long
        let mut io = tokio_io_timeout::TimeoutStream::new(stream);
        io.set_write_timeout(Some(self.limits.write_stall));
        let mut conn = pin!(
            builder
                .serve_connection(TokioIo::new(Box::pin(io)), service)
                .with_upgrades()
        );
        let mut stopping = false;
        loop {
            tokio::select! {
                result = conn.as_mut() => {
                    if let Err(e) = result {
                        tracing::trace!("connection from {addr}: {e}");
                    }
                    break;
                }
                () = self.stop.cancelled(), if !stopping => {
                    stopping = true;
                    conn.as_mut().graceful_shutdown();
                }
            }
        }
    }
}
