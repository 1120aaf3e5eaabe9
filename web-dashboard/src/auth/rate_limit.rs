//! Failed-login rate limiting: at most `max` failures per key in a sliding window; beyond
//! that, logins for the key are refused (429) until the oldest failure leaves the window.
//! The dashboard has two: per user name and address (low) and per address (high, for shared
//! NATs). A login takes its place as a failure before its password is checked
//! ([`RateLimiter::take`], under the same lock as the check), and gives it back when the
//! password was right: guesses sent at once count as they are checked, not after.
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

    /// Counts a failure against `key` now, unless it is over the limit (`None`): the place
    /// of a login about to be checked, given back with [`RateLimiter::give_back`] if it
    /// succeeds.
    pub fn take(&self, key: &str) -> Option<Instant> {
        let now = Instant::now();
        self.with(|map| {
            if map.len() >= MAX_KEYS {
                map.retain(|_, q| {
                    q.back()
                        .is_some_and(|t| now.duration_since(*t) < self.window)
                });
            }
            let q = map.entry(key.to_owned()).or_default();
            self.prune(q, now);
            if q.len() >= self.max {
                return None;
            }
            q.push_back(now);
            Some(now)
        })
    }

    /// Takes back the failure counted against `key` at `at` (a login that succeeded, or
    /// one another limit refused).
    pub fn give_back(&self, key: &str, at: Instant) {
        self.with(|map| {
            if let Some(q) = map.get_mut(key)
                && let Some(i) = q.iter().rposition(|t| *t == at)
            {
                q.remove(i);
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
        for _ in 0..3 {
            assert!(r.take("user:a").is_some());
        }
        assert!(r.take("user:a").is_none(), "the fourth is over the limit");
        assert!(r.take("user:b").is_some(), "another key is not");
        std::thread::sleep(Duration::from_millis(250));
        let at = r.take("user:a").expect("the window slid past the failures");
        r.give_back("user:a", at);
        r.clear("user:a");
        for _ in 0..3 {
            assert!(r.take("user:a").is_some());
        }
    }

    #[test]
    fn a_place_given_back_is_free_again() {
        let r = RateLimiter::new(2, Duration::from_secs(60));
        let first = r.take("k").unwrap();
        assert!(r.take("k").is_some());
        assert!(r.take("k").is_none());
        r.give_back("k", first);
        assert!(r.take("k").is_some(), "a success does not count");
        assert!(r.take("k").is_none());
    }

    #[test]
    fn guesses_at_once_take_no_more_than_the_limit() {
        let r = std::sync::Arc::new(RateLimiter::new(5, Duration::from_secs(60)));
        let threads: Vec<_> = (0..16)
            .map(|_| {
                let r = r.clone();
                std::thread::spawn(move || (0..10).filter(|_| r.take("k").is_some()).count())
            })
            .collect();
        let taken: usize = threads.into_iter().map(|t| t.join().unwrap()).sum();
        assert_eq!(taken, 5);
    }
}
