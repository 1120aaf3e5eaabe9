//! Short-lived in-memory caches that keep the hot paths off the database under load: the
//! session of a cookie, who may see whom, and a trainee's progress (data, page body, JSON).
//! Entries live a few seconds ([`SESSION_TTL`], [`ACCESS_TTL`], [`PROGRESS_TTL`]), so what
//! other processes write (a scored `cutlab session`, a new cohort member) shows within that
//! time; the dashboard's own writes that change them clear them at once (log-out, threshold
//! and exercise edits).

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub const SESSION_TTL: Duration = Duration::from_secs(5);
pub const ACCESS_TTL: Duration = Duration::from_secs(5);
pub const PROGRESS_TTL: Duration = Duration::from_secs(2);
/// Entries kept per cache (beyond it, expired ones go, then everything).
const CAPACITY: usize = 10_000;

/// A map whose entries expire `ttl` after insertion.
#[derive(Debug)]
pub struct TtlCache<K, V> {
    ttl: Duration,
    map: Mutex<HashMap<K, (Instant, V)>>,
}

impl<K: Eq + Hash, V: Clone> TtlCache<K, V> {
    pub fn new(ttl: Duration) -> Self {
        Self { ttl, map: Mutex::new(HashMap::new()) }
    }

    fn with<R>(&self, f: impl FnOnce(&mut HashMap<K, (Instant, V)>) -> R) -> R {
        f(&mut self.map.lock().unwrap_or_else(std::sync::PoisonError::into_inner))
    }

    pub fn get(&self, k: &K) -> Option<V> {
        let now = Instant::now();
        self.with(|m| m.get(k).filter(|(at, _)| now.duration_since(*at) < self.ttl).map(|(_, v)| v.clone()))
    }

    /// The entry, fresh or not; when it has expired, the first caller gets `true` (refresh it)
    /// and the entry counts as fresh again for everyone else meanwhile (stale while
    /// revalidating: one refresh at a time, nobody waits for it).
    pub fn get_or_claim(&self, k: &K) -> Option<(V, bool)> {
        let now = Instant::now();
        self.with(|m| {
            let (at, v) = m.get_mut(k)?;
            if now.duration_since(*at) < self.ttl {
                Some((v.clone(), false))
            } else {
                *at = now;
                Some((v.clone(), true))
            }
        })
    }

    pub fn put(&self, k: K, v: V) {
        let now = Instant::now();
        self.with(|m| {
            if m.len() >= CAPACITY {
                m.retain(|_, (at, _)| now.duration_since(*at) < self.ttl);
                if m.len() >= CAPACITY {
                    m.clear();
                }
            }
            m.insert(k, (now, v));
        })
    }

    pub fn remove(&self, k: &K) {
        self.with(|m| m.remove(k));
    }

    pub fn clear(&self) {
        self.with(HashMap::clear);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_expire() {
        let c = TtlCache::new(Duration::from_millis(50));
        c.put(1, "a");
        assert_eq!(c.get(&1), Some("a"));
        std::thread::sleep(Duration::from_millis(60));
        assert_eq!(c.get(&1), None);
        c.put(3, "c");
        assert_eq!(c.get_or_claim(&3), Some(("c", false)));
        std::thread::sleep(Duration::from_millis(60));
        assert_eq!(c.get_or_claim(&3), Some(("c", true)), "the first caller refreshes");
        assert_eq!(c.get_or_claim(&3), Some(("c", false)), "the others take the old value");
        c.put(2, "b");
        c.remove(&2);
        assert_eq!(c.get(&2), None);
    }
}
