//! The server loop: [`axum::serve`]'s, with the limits a server on a hospital network needs
//! against a client that opens connections and never finishes them ([`Limits`]): request
//! headers must arrive within a time (also between the requests of a kept-alive connection,
//! so an idle connection is closed then), and the connections held at once are capped, per
//! client address and in all, a connection past a cap answered at once with a 503 and
//! closed. Why these and not others: docs/decisions.md ("The hub and a hostile station").

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::pin::pin;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto::Builder;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use tower::Service;

/// What a served dashboard allows its clients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Time to send a request's headers, and the longest a kept-alive connection may wait
    /// for its next request.
    pub header_timeout: Duration,
    /// Connections held at once, all clients together.
    pub max_connections: usize,
    /// Connections held at once from one address.
    pub max_connections_per_ip: usize,
    /// The longest a hub upload's body may go without a byte.
    pub upload_stall: Duration,
    /// The slowest a hub upload's body may come on average, once `upload_rate_grace` has
    /// passed, bytes per second.
    pub upload_min_bytes_per_s: f64,
    pub upload_rate_grace: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            header_timeout: Duration::from_secs(10),
            max_connections: 1024,
            max_connections_per_ip: 128,
            upload_stall: Duration::from_secs(10),
            // a LAN sends a station's 11 MB recording in well under a second
            upload_min_bytes_per_s: 64.0 * 1024.0,
            upload_rate_grace: Duration::from_secs(15),
        }
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
        if h.total >= limits.max_connections || from_ip >= limits.max_connections_per_ip {
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
        let mut builder = Builder::new(TokioExecutor::new());
        builder
            .http1()
            .timer(TokioTimer::new())
            .header_read_timeout(self.limits.header_timeout)
            .max_buf_size(64 << 10);
        builder
            .http2()
            .timer(TokioTimer::new())
            .keep_alive_interval(self.limits.header_timeout)
            .enable_connect_protocol();
        let mut conn = pin!(builder.serve_connection_with_upgrades(TokioIo::new(stream), service));
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
