//! Failed-login rate limiting: at most `max` failures per key in a sliding window; beyond
//! that, logins for the key are refused (429) until the oldest failure leaves the window.
//! The dashboard has two: per user name (low) and per IP address (high, for shared NATs).
//! In memory: a restart forgets (acceptable for a throttle).

use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Keys kept at most (beyond it, keys without a failure in the window are dropped).
const MAX_KEYS: usize = 100_000;

#[derive(Debug)]
pub struct RateLimiter {
    max: usize,
    window: Duration,
    failures: Mutex<HashMap<String, VecDeque<Instant>>>,
}

impl RateLimiter {
    pub fn new(max: usize, window: Duration) -> Self {
        Self {
            max,
            window,
            failures: Mutex::new(HashMap::new()),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut HashMap<String, VecDeque<Instant>>) -> R) -> R {
        // a poisoned lock only means another thread panicked mid-update: the data is usable
        let mut map = self
            .failures
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f(&mut map)
    }

    fn prune(&self, q: &mut VecDeque<Instant>, now: Instant) {
        while q
            .front()
            .is_some_and(|t| now.duration_since(*t) >= self.window)
        {
            q.pop_front();
        }
    }

    /// Whether any of `keys` is over the limit now.
    pub fn blocked(&self, keys: &[String]) -> bool {
        let now = Instant::now();
        self.with(|map| {
            keys.iter().any(|k| {
                map.get_mut(k).is_some_and(|q| {
                    self.prune(q, now);
                    q.len() >= self.max
                })
            })
        })
    }

    /// Counts a failure against each of `keys`.
    pub fn fail(&self, keys: &[String]) {
        let now = Instant::now();
        self.with(|map| {
            if map.len() >= MAX_KEYS {
                map.retain(|_, q| {
                    q.back()
                        .is_some_and(|t| now.duration_since(*t) < self.window)
                });
            }
            for k in keys {
                let q = map.entry(k.clone()).or_default();
                self.prune(q, now);
                q.push_back(now);
            }
        })
    }

    /// Forgets the failures of `key` (after a successful login).
    pub fn clear(&self, key: &str) {
        self.with(|map| map.remove(key));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_after_max_failures_then_recovers() {
        let r = RateLimiter::new(3, Duration::from_millis(200));
        let k = vec!["user:a".to_owned()];
        for _ in 0..3 {
            assert!(!r.blocked(&k));
            r.fail(&k);
        }
        assert!(r.blocked(&k));
        assert!(!r.blocked(&["user:b".to_owned()]));
        std::thread::sleep(Duration::from_millis(250));
        assert!(!r.blocked(&k), "the window slid past the failures");
        r.fail(&k);
        r.clear("user:a");
        assert!(!r.blocked(&k));
    }
}
