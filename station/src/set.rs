//! The station sessions a server runs: at most a configured number at once, one per trainee.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};

use crate::StationError;
use crate::run::Running;

/// The running sessions, by attempt id.
#[derive(Debug)]
pub struct StationSet {
    max_sessions: usize,
    running: Mutex<BTreeMap<i64, Arc<Running>>>,
}

impl StationSet {
    /// A set that runs at most `max_sessions` sessions at once.
    pub fn new(max_sessions: usize) -> Self {
        Self {
            max_sessions,
            running: Mutex::new(BTreeMap::new()),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut BTreeMap<i64, Arc<Running>>) -> R) -> R {
        // a poisoned lock only means another thread panicked mid-update: the map is usable
        let mut map = self.running.lock().unwrap_or_else(PoisonError::into_inner);
        // sessions that ended leave the set
        map.retain(|_, r| r.ending.borrow().is_none());
        f(&mut map)
    }

    /// An error unless `trainee` may start a session now.
    pub fn check_room(&self, trainee: &str) -> Result<(), StationError> {
        self.with(|map| {
            if map.values().any(|r| r.trainee == trainee) {
                return Err(StationError::Busy(format!(
                    "{trainee} already has a station session running: finish it first"
                )));
            }
            if map.len() >= self.max_sessions {
                return Err(StationError::Busy(format!(
                    "this server runs at most {} station sessions at once; all are in use",
                    self.max_sessions
                )));
            }
            Ok(())
        })
    }

    /// Adds a started session, checked again (two starts may have raced: the one that lost
    /// is ended at once, as if its page went away).
    pub fn insert(&self, running: Running) -> Result<Arc<Running>, StationError> {
        if let Err(e) = self.check_room(&running.trainee) {
            running.control.lose();
            return Err(e);
        }
        let running = Arc::new(running);
        self.with(|map| map.insert(running.attempt, running.clone()));
        Ok(running)
    }

    /// The session of attempt `attempt`, while it runs.
    pub fn get(&self, attempt: i64) -> Option<Arc<Running>> {
        self.with(|map| map.get(&attempt).cloned())
    }

    /// The sessions running now.
    pub fn running(&self) -> Vec<Arc<Running>> {
        self.with(|map| map.values().cloned().collect())
    }
}
