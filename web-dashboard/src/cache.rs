//! In-memory caches that keep the hot paths off the database under load: the session of a
//! cookie, who may see whom, users by id, and a trainee's progress (data, page body, JSON).
//!
//! An entry is valid while the database has not changed since it was read: [`Changes`] keeps
//! a generation that the watcher ([`crate::watch`]) bumps whenever any connection, in this
//! process or another (a scored `cutlab session`, a new cohort member), commits to the
//! database, and entries carry the generation ([`Stamp`]) taken before their queries ran. So a
//! change shows within the watcher's poll ([`crate::watch::POLL`]), and a database that does
//! not change is read once. Entries also expire after [`WATCHED_TTL`] (a safety net); while
//! nothing watches (an in-memory database, the watcher's connection lost) they expire after the
//! cache's own short time to live ([`SESSION_TTL`], [`ACCESS_TTL`], [`PROGRESS_TTL`]). The
//! dashboard's own writes that change them clear them at once (log-out, threshold and exercise
//! edits), so a redirect after a form never shows the old state.

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub const SESSION_TTL: Duration = Duration::from_secs(5);
pub const ACCESS_TTL: Duration = Duration::from_secs(5);
pub const PROGRESS_TTL: Duration = Duration::from_secs(2);
/// Time to live of every entry while the watcher runs.
pub const WATCHED_TTL: Duration = Duration::from_secs(60);
/// Entries kept per cache (beyond it, expired ones go, then everything).
const CAPACITY: usize = 10_000;

/// The database's generation as the caches know it, and whether a watcher keeps it current.
#[derive(Debug, Default)]
pub struct Changes {
    generation: AtomicU64,
    watching: AtomicBool,
}

/// The generation of the database at some moment: taken before reading what gets cached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp(u64);

impl Changes {
    pub fn stamp(&self) -> Stamp {
        Stamp(self.generation.load(Ordering::Acquire))
    }

    /// The database changed: every entry read before now is stale.
    pub fn bump(&self) {
        self.generation.fetch_add(1, Ordering::AcqRel);
    }

    pub fn set_watching(&self, watching: bool) {
        self.watching.store(watching, Ordering::Release);
    }

    pub fn watching(&self) -> bool {
        self.watching.load(Ordering::Acquire)
    }
}

/// A map whose entries expire when the database changes or after a time to live.
#[derive(Debug)]
pub struct TtlCache<K, V> {
    ttl: Duration,
    changes: Arc<Changes>,
    map: Mutex<HashMap<K, Entry<V>>>,
    /// One gate per key being loaded by [`load_once`](Self::load_once).
    loading: Mutex<HashMap<K, Arc<tokio::sync::Mutex<()>>>>,
}

#[derive(Debug)]
struct Entry<V> {
    at: Instant,
    stamp: Stamp,
    value: V,
}

impl<K: Eq + Hash, V: Clone> TtlCache<K, V> {
    /// A cache whose entries live `ttl` while nothing watches the database.
    pub fn new(ttl: Duration, changes: Arc<Changes>) -> Self {
        Self {
            ttl,
            changes,
            map: Mutex::new(HashMap::new()),
            loading: Mutex::new(HashMap::new()),
        }
    }

    /// The generation to [`put`](Self::put) with what is read after this call.
    pub fn stamp(&self) -> Stamp {
        self.changes.stamp()
    }

    fn with<R>(&self, f: impl FnOnce(&mut HashMap<K, Entry<V>>) -> R) -> R {
        f(&mut self
            .map
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner))
    }

    fn fresh(&self, e: &Entry<V>, now: Instant, current: Stamp) -> bool {
        let ttl = if self.changes.watching() {
            WATCHED_TTL
        } else {
            self.ttl
        };
        e.stamp == current && now.duration_since(e.at) < ttl
    }

    pub fn get(&self, k: &K) -> Option<V> {
        let (now, current) = (Instant::now(), self.stamp());
        self.with(|m| {
            m.get(k)
                .filter(|e| self.fresh(e, now, current))
                .map(|e| e.value.clone())
        })
    }

    /// The fresh entry, or one only old: when a watched entry has outlived [`WATCHED_TTL`]
    /// with no change of the database seen, the first caller gets `true` (refresh it) and
    /// the entry counts as fresh again for everyone else meanwhile (stale while revalidating:
    /// one refresh at a time, nobody waits for it). An entry the database changed under, or
    /// one nothing vouches for (unwatched, past its short time to live), is `None`: load it.
    /// Serving those "stale while revalidating" showed each viewer the state of their own
    /// previous visit, however long ago (a curriculum read "not started" 1.5 min after two
    /// passes).
    pub fn get_or_claim(&self, k: &K) -> Option<(V, bool)> {
        let (now, current) = (Instant::now(), self.stamp());
        self.with(|m| {
            let e = m.get_mut(k)?;
            if self.fresh(e, now, current) {
                Some((e.value.clone(), false))
            } else if e.stamp == current && self.changes.watching() {
                e.at = now;
                Some((e.value.clone(), true))
            } else {
                None
            }
        })
    }

    /// Keeps `v`, read after `stamp` was taken: if the database changed meanwhile, the entry
    /// is born stale.
    pub fn put(&self, k: K, v: V, stamp: Stamp) {
        let now = Instant::now();
        let current = self.stamp();
        self.with(|m| {
            if m.len() >= CAPACITY {
                m.retain(|_, e| self.fresh(e, now, current));
                if m.len() >= CAPACITY {
                    m.clear();
                }
            }
            m.insert(
                k,
                Entry {
                    at: now,
                    stamp,
                    value: v,
                },
            );
        })
    }

    /// The fresh entry of `k`, or `load`'s value, kept: callers that miss the same key at
    /// the same time wait for one load instead of each running it (a cold cache under load
    /// would otherwise run it once per waiting request).
    pub async fn load_once<E, F: Future<Output = Result<V, E>>>(
        &self,
        k: K,
        load: impl FnOnce() -> F,
    ) -> Result<V, E>
    where
        K: Clone,
    {
        let gate = self
            .loading
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .entry(k.clone())
            .or_default()
            .clone();
        let out = {
            let _turn = gate.lock().await;
            match self.get(&k) {
                Some(v) => Ok(v),
                None => {
                    let stamp = self.stamp();
                    let v = load().await?;
                    self.put(k.clone(), v.clone(), stamp);
                    Ok(v)
                }
            }
        };
        let mut loading = self
            .loading
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        // the map's and ours: nobody else waits
        if Arc::strong_count(&gate) <= 2 {
            loading.remove(&k);
        }
        out
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
        let c = TtlCache::new(Duration::from_millis(50), Arc::default());
        c.put(1, "a", c.stamp());
        assert_eq!(c.get(&1), Some("a"));
        std::thread::sleep(Duration::from_millis(60));
        assert_eq!(c.get(&1), None);
        c.put(3, "c", c.stamp());
        assert_eq!(c.get_or_claim(&3), Some(("c", false)));
        std::thread::sleep(Duration::from_millis(60));
        assert_eq!(
            c.get_or_claim(&3),
            None,
            "unwatched: nothing vouches for an expired entry"
        );
        c.put(2, "b", c.stamp());
        c.remove(&2);
        assert_eq!(c.get(&2), None);
    }

    #[tokio::test]
    async fn concurrent_misses_of_a_key_load_it_once() {
        let c = Arc::new(TtlCache::new(Duration::from_secs(5), Arc::default()));
        let loads = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let tasks: Vec<_> = (0..8)
            .map(|_| {
                let (c, loads) = (c.clone(), loads.clone());
                tokio::spawn(async move {
                    c.load_once(7, || async {
                        loads.fetch_add(1, Ordering::SeqCst);
                        tokio::time::sleep(Duration::from_millis(20)).await;
                        Ok::<_, ()>("v")
                    })
                    .await
                })
            })
            .collect();
        for t in tasks {
            assert_eq!(t.await.expect("task"), Ok("v"));
        }
        assert_eq!(loads.load(Ordering::SeqCst), 1);
        assert!(
            c.loading.lock().expect("lock").is_empty(),
            "the gates go with the load"
        );
        // an error is not kept: the next caller loads again
        assert_eq!(
            c.load_once(8, || async { Err::<&str, _>("failed") }).await,
            Err("failed")
        );
        assert_eq!(c.load_once(8, || async { Ok::<_, ()>("w") }).await, Ok("w"));
    }

    #[test]
    fn a_change_of_the_database_makes_entries_stale_and_a_watched_one_lives_long() {
        let changes = Arc::new(Changes::default());
        let c = TtlCache::new(Duration::from_millis(20), changes.clone());
        changes.set_watching(true);
        c.put(1, "a", c.stamp());
        std::thread::sleep(Duration::from_millis(30));
        assert_eq!(
            c.get(&1),
            Some("a"),
            "watched: lives past the short time to live"
        );
        changes.bump();
        assert_eq!(c.get(&1), None, "stale after a change");
        assert_eq!(
            c.get_or_claim(&1),
            None,
            "a changed entry is never served: loaded again"
        );
        c.put(1, "a2", c.stamp());
        assert_eq!(c.get_or_claim(&1), Some(("a2", false)));
        // read before a change, kept after it: born stale
        let before = c.stamp();
        changes.bump();
        c.put(2, "b", before);
        assert_eq!(c.get(&2), None);
        changes.set_watching(false);
        c.put(3, "c", c.stamp());
        std::thread::sleep(Duration::from_millis(30));
        assert_eq!(c.get(&3), None, "unwatched: the short time to live");
    }
}
