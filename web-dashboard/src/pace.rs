//! Request bodies that must keep coming, on every route: a body that goes
//! [`BodyPace::stall`] without a byte, or that once [`BodyPace::grace`] has passed has brought
//! fewer than [`BodyPace::min_bytes_per_s`] on average, ends in an error for whoever reads it,
//! and the request is answered 408 with the connection closed ([`pace_bodies`]). Without it a
//! client holds a connection (and so a place under the connection caps, see [`crate::serve`])
//! as long as it likes by sending a declared body ten bytes at a time.
//!
//! The deadline of a body that has brought `b` bytes since it started at `t0`, the last of
//! them at `t_last`, is
//!
//! `min(t_last + stall, t0 + max(grace, b / min_bytes_per_s))`,
//!
//! re-armed at each frame: one timer, woken only when the body is due to fail.

use std::pin::Pin;
use std::sync::{Arc, OnceLock};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::http::{HeaderValue, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use hyper::body::Frame;
use tokio::time::{Instant, Sleep};

use crate::AppState;
use crate::error::{ApiError, AppError};

/// How fast a request body must come.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyPace {
    /// The longest a body may go without a byte.
    pub stall: Duration,
    /// The slowest a body may come on average once `grace` has passed, bytes per second.
    pub min_bytes_per_s: f64,
    /// The time a body may take before its average rate counts.
    pub grace: Duration,
}

impl BodyPace {
    /// The moment a body that started at `started`, has brought `bytes` and the last of them
    /// at `last`, fails.
    fn deadline(&self, started: Instant, last: Instant, bytes: u64) -> Instant {
        let rate_s = bytes as f64 / self.min_bytes_per_s.max(f64::MIN_POSITIVE);
        let by_rate = Duration::try_from_secs_f64(rate_s).unwrap_or(Duration::MAX);
        let by_rate = started
            .checked_add(self.grace.max(by_rate))
            .unwrap_or_else(|| started + Duration::from_secs(86_400 * 365));
        (last + self.stall).min(by_rate)
    }

    /// Why a body is cut off at `now`, if it is.
    fn verdict(&self, started: Instant, last: Instant, bytes: u64, now: Instant) -> Option<String> {
        if now.duration_since(last) >= self.stall {
            return Some(format!(
                "no byte of the request's body for {:.1} s: cut off",
                self.stall.as_secs_f64()
            ));
        }
        let elapsed = now.duration_since(started);
        let slow = (bytes as f64) < self.min_bytes_per_s * elapsed.as_secs_f64();
        (elapsed >= self.grace && slow).then(|| {
            format!(
                "the request's body came slower than {:.0} KiB/s: cut off",
                self.min_bytes_per_s / 1024.0
            )
        })
    }
}

/// Why a body was cut off; the error its reader sees.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{0}")]
pub struct TooSlow(pub String);

/// A body held to a [`BodyPace`]; when cut off it says why in `tripped`.
struct PacedBody {
    inner: Body,
    pace: BodyPace,
    started: Instant,
    last: Instant,
    bytes: u64,
    timer: Pin<Box<Sleep>>,
    tripped: Arc<OnceLock<TooSlow>>,
}

impl PacedBody {
    fn new(inner: Body, pace: BodyPace, tripped: Arc<OnceLock<TooSlow>>) -> Self {
        let now = Instant::now();
        Self {
            inner,
            pace,
            started: now,
            last: now,
            bytes: 0,
            timer: Box::pin(tokio::time::sleep_until(pace.deadline(now, now, 0))),
            tripped,
        }
    }

    fn cut(&mut self, why: String) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        let e = self.tripped.get_or_init(|| TooSlow(why)).clone();
        Poll::Ready(Some(Err(axum::Error::new(e))))
    }
}

impl HttpBody for PacedBody {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Self::Error>>> {
        let this = self.get_mut();
        if let Some(why) = this.tripped.get() {
            return Poll::Ready(Some(Err(axum::Error::new(why.clone()))));
        }
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => {
                let now = Instant::now();
                if let Some(data) = frame.data_ref() {
                    this.bytes += data.len() as u64;
                    this.last = now;
                }
                let deadline = this.pace.deadline(this.started, this.last, this.bytes);
                this.timer.as_mut().reset(deadline);
                Poll::Ready(Some(Ok(frame)))
            }
            Poll::Ready(other) => Poll::Ready(other),
            Poll::Pending => loop {
                if this.timer.as_mut().poll(cx).is_pending() {
                    return Poll::Pending;
                }
                let now = Instant::now();
                if let Some(why) = this.pace.verdict(this.started, this.last, this.bytes, now) {
                    return this.cut(why);
                }
                // woken early (a rounding of the timer): wait for the rest
                let deadline = this.pace.deadline(this.started, this.last, this.bytes);
                this.timer
                    .as_mut()
                    .reset(deadline.max(now + Duration::from_millis(1)));
            },
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> hyper::body::SizeHint {
        self.inner.size_hint()
    }
}

/// The layer: every request's body held to the server's [`BodyPace`]; a request whose body
/// was cut off is answered 408 (JSON under `/api/`, a page elsewhere), whatever its handler
/// made of the error, and the connection is closed.
pub async fn pace_bodies(State(state): State<AppState>, request: Request, next: Next) -> Response {
    if request.body().is_end_stream() {
        return next.run(request).await;
    }
    let pace = state.config().limits.body;
    let api = request.uri().path().starts_with("/api/");
    let tripped = Arc::new(OnceLock::new());
    let watched = tripped.clone();
    let request = request.map(|b| Body::new(PacedBody::new(b, pace, watched)));
    let response = next.run(request).await;
    let Some(TooSlow(why)) = tripped.get().cloned() else {
        return response;
    };
    let e = AppError::TimedOut(why);
    let mut response = if api {
        ApiError(e).into_response()
    } else {
        e.into_response()
    };
    response
        .headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    const PACE: BodyPace = BodyPace {
        stall: Duration::from_secs(2),
        min_bytes_per_s: 100.0,
        grace: Duration::from_secs(5),
    };

    #[test]
    fn the_deadline_is_the_stall_or_the_rate_whichever_comes_first() {
        let t0 = Instant::now();
        let s = Duration::from_secs;
        // nothing yet: the stall
        assert_eq!(PACE.deadline(t0, t0, 0), t0 + s(2));
        // bytes coming steadily within the grace: the stall from the last byte
        assert_eq!(PACE.deadline(t0, t0 + s(4), 50), t0 + s(5));
        // 1,000 bytes pay for 10 s at 100 B/s
        assert_eq!(PACE.deadline(t0, t0 + s(9), 1000), t0 + s(10));
        assert_eq!(PACE.deadline(t0, t0 + s(9), 10_000), t0 + s(11));
    }

    #[test]
    fn a_crawl_is_cut_after_the_grace_and_a_stall_at_once() {
        let t0 = Instant::now();
        let s = Duration::from_secs;
        assert!(PACE.verdict(t0, t0 + s(4), 40, t0 + s(4)).is_none());
        let slow = PACE.verdict(t0, t0 + s(6), 60, t0 + s(6)).unwrap();
        assert!(slow.contains("slower than"), "{slow}");
        let stalled = PACE.verdict(t0, t0, 0, t0 + s(2)).unwrap();
        assert!(stalled.contains("no byte"), "{stalled}");
        assert!(PACE.verdict(t0, t0 + s(6), 600, t0 + s(6)).is_none());
    }
}
