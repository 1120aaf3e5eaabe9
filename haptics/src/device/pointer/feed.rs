//! The page's side of the pointer device: [`PointerFeed`], and what the two sides share.
//!
//! Samples go from the feed (any thread: a WebSocket reader) to the device (the servo thread)
//! through a bounded lock-free SPSC queue (rtrb). A feed may be cloned; the clones share the
//! queue's producer behind a mutex, so pushes from several threads are serialised among
//! themselves, but the servo thread's side never locks, waits or allocates. The force, the
//! fault and the per-tick echo go the other way through atomics (the force through a sequence
//! lock the servo thread writes without waiting, so a page always reads a whole vector).

use std::sync::atomic::{AtomicU8, AtomicU64, Ordering, fence};
use std::sync::{Arc, Mutex};

use super::sample::PointerSample;
use crate::Vector3;

/// Why a pointer device stopped taking samples (it stays faulted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PointerFault {
    /// No usable sample arrived for longer than the device's absence (the page went away).
    #[error("the page sent no pointer sample for longer than the absence allowed")]
    TimedOut,
    /// The feed was closed (the page went away or pressed Stop).
    #[error("the pointer feed was closed")]
    Closed,
}

impl PointerFault {
    fn code(self) -> u8 {
        match self {
            PointerFault::TimedOut => 2,
            PointerFault::Closed => 3,
        }
    }

    fn of_code(code: u8) -> Option<Self> {
        match code {
            2 => Some(PointerFault::TimedOut),
            3 => Some(PointerFault::Closed),
            _ => None,
        }
    }
}

/// Why a sample was not queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PushError {
    /// The queue is full (the servo loop is not draining it: not started yet, or far behind);
    /// the sample is dropped and counted.
    #[error("the pointer queue is full")]
    Full,
    /// The feed was closed.
    #[error("the pointer feed is closed")]
    Closed,
    /// The device is gone (its session is over).
    #[error("the pointer device is gone")]
    DeviceGone,
    /// The device faulted and takes no more samples.
    #[error("the pointer device faulted: {0}")]
    Faulted(PointerFault),
}

/// What happened to the samples, counted by both sides.
#[derive(Debug, Default)]
pub struct PointerCounters {
    /// Queued by the feed.
    pub pushed: AtomicU64,
    /// Not queued: the queue was full.
    pub dropped_full: AtomicU64,
    /// Taken by the device and used.
    pub accepted: AtomicU64,
    /// Not used: not later than the last used sample.
    pub dropped_out_of_order: AtomicU64,
    /// Not used: finite but absurd (out of range, or a jump of the page clock).
    pub dropped_invalid: AtomicU64,
    /// Samples with a NaN or an infinity (dropped).
    pub non_finite: AtomicU64,
    /// Servo ticks when the newest sample was older than the tick's time (the pose held).
    pub held_ticks: AtomicU64,
    /// Times the page clock was anchored to the session clock again (see the module docs).
    pub reanchors: AtomicU64,
    /// Servo ticks paused: no usable sample for longer than the timeout (the pose held, the
    /// force faded).
    pub paused_ticks: AtomicU64,
    /// Times samples came again after a pause.
    pub resumes: AtomicU64,
}

impl PointerCounters {
    pub(crate) fn add(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// A vector one thread writes and others read whole, without the writer ever waiting: a
/// sequence lock over atomics.
#[derive(Debug, Default)]
struct ForceCell {
    sequence: AtomicU64,
    xyz_bits: [AtomicU64; 3],
}

impl ForceCell {
    /// One writer only (the device, through `&mut`).
    fn write(&self, force_newtons: &Vector3) {
        let s = self.sequence.load(Ordering::Relaxed);
        self.sequence.store(s.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (cell, v) in self.xyz_bits.iter().zip(force_newtons.iter()) {
            cell.store(v.to_bits(), Ordering::Relaxed);
        }
        self.sequence.store(s.wrapping_add(2), Ordering::Release);
    }

    fn read(&self) -> Vector3 {
        loop {
            let before = self.sequence.load(Ordering::Acquire);
            let v =
                Vector3::from_fn(|k, _| f64::from_bits(self.xyz_bits[k].load(Ordering::Relaxed)));
            fence(Ordering::Acquire);
            let after = self.sequence.load(Ordering::Relaxed);
            if before == after && before.is_multiple_of(2) {
                return v;
            }
            std::hint::spin_loop();
        }
    }
}

/// Entries of the echo ring: a few seconds of ticks that consumed samples.
const ECHO_ENTRIES: usize = 4096;

/// For each servo tick that took new samples, the page time of the newest: a ring the device
/// writes without waiting and readers search by tick (a reader that the writer laps gets
/// `None`, never a torn entry).
#[derive(Debug)]
struct EchoRing {
    /// Entries begun, and entries finished, by the writer.
    begun: AtomicU64,
    done: AtomicU64,
    ticks: Box<[AtomicU64]>,
    t_ms_bits: Box<[AtomicU64]>,
}

impl EchoRing {
    fn new() -> Self {
        let zeros = || (0..ECHO_ENTRIES).map(|_| AtomicU64::new(0)).collect();
        Self {
            begun: AtomicU64::new(0),
            done: AtomicU64::new(0),
            ticks: zeros(),
            t_ms_bits: zeros(),
        }
    }

    fn write(&self, tick: u64, t_ms: f64) {
        let k = self.done.load(Ordering::Relaxed);
        self.begun.store(k + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let i = (k % ECHO_ENTRIES as u64) as usize;
        self.ticks[i].store(tick, Ordering::Relaxed);
        self.t_ms_bits[i].store(t_ms.to_bits(), Ordering::Relaxed);
        self.done.store(k + 1, Ordering::Release);
    }

    fn at_or_before(&self, tick: u64) -> Option<f64> {
        let done = self.done.load(Ordering::Acquire);
        let oldest = done.saturating_sub(ECHO_ENTRIES as u64);
        for k in (oldest..done).rev() {
            let i = (k % ECHO_ENTRIES as u64) as usize;
            let entry_tick = self.ticks[i].load(Ordering::Relaxed);
            let t_ms = f64::from_bits(self.t_ms_bits[i].load(Ordering::Relaxed));
            fence(Ordering::Acquire);
            if self.begun.load(Ordering::Relaxed) > k + ECHO_ENTRIES as u64 {
                return None; // overwritten while read: older than the ring holds
            }
            if entry_tick <= tick {
                return Some(t_ms);
            }
        }
        None
    }
}

/// What the device and every feed share.
#[derive(Debug)]
pub(crate) struct Shared {
    pub counters: PointerCounters,
    force: ForceCell,
    fault: AtomicU8,
    echo: EchoRing,
}

impl Shared {
    pub fn new() -> Self {
        Self {
            counters: PointerCounters::default(),
            force: ForceCell::default(),
            fault: AtomicU8::new(0),
            echo: EchoRing::new(),
        }
    }

    pub fn write_force(&self, force_newtons: &Vector3) {
        self.force.write(force_newtons);
    }

    pub fn force(&self) -> Vector3 {
        self.force.read()
    }

    pub fn set_fault(&self, fault: PointerFault) {
        self.fault.store(fault.code(), Ordering::Release);
    }

    pub fn fault(&self) -> Option<PointerFault> {
        PointerFault::of_code(self.fault.load(Ordering::Acquire))
    }

    pub fn echo(&self, tick: u64, t_ms: f64) {
        self.echo.write(tick, t_ms);
    }
}

/// The producer of the queue, shared by a feed's clones (`None` once closed).
type SharedProducer = Arc<Mutex<Option<rtrb::Producer<PointerSample>>>>;

/// The page's handle on a [`super::PointerDevice`]: push samples, read the force back.
/// `Clone + Send + Sync`; the device sees the feed closed once [`Self::close`] is called or
/// every clone is dropped.
#[derive(Clone)]
pub struct PointerFeed {
    producer: SharedProducer,
    shared: Arc<Shared>,
    capacity: usize,
}

impl std::fmt::Debug for PointerFeed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointerFeed")
            .field("capacity", &self.capacity)
            .field("fault", &self.shared.fault())
            .finish_non_exhaustive()
    }
}

impl PointerFeed {
    pub(crate) fn new(
        producer: rtrb::Producer<PointerSample>,
        shared: Arc<Shared>,
        capacity: usize,
    ) -> Self {
        Self {
            producer: Arc::new(Mutex::new(Some(producer))),
            shared,
            capacity,
        }
    }

    /// Queues a sample for the servo loop; never waits for it. Checks of the sample happen on
    /// the device's side (so they are counted in the order the servo loop sees them).
    pub fn push(&self, sample: PointerSample) -> Result<(), PushError> {
        if let Some(fault) = self.shared.fault() {
            return Err(PushError::Faulted(fault));
        }
        // a poisoned lock only means another pusher panicked; the producer is still whole
        let mut guard = self.producer.lock().unwrap_or_else(|e| e.into_inner());
        let Some(producer) = guard.as_mut() else {
            return Err(PushError::Closed);
        };
        if producer.is_abandoned() {
            return Err(PushError::DeviceGone);
        }
        match producer.push(sample) {
            Ok(()) => {
                PointerCounters::add(&self.shared.counters.pushed);
                Ok(())
            }
            Err(_) => {
                PointerCounters::add(&self.shared.counters.dropped_full);
                Err(PushError::Full)
            }
        }
    }

    /// Closes the feed for every clone (the page went away, or the trainee pressed Stop): the
    /// device faults ([`PointerFault::Closed`]) at its next tick.
    pub fn close(&self) {
        let mut guard = self.producer.lock().unwrap_or_else(|e| e.into_inner());
        *guard = None;
    }

    /// The latest force the servo loop rendered, N, world frame (for the page's force bar).
    pub fn latest_force_newtons(&self) -> Vector3 {
        self.shared.force()
    }

    /// Why the device stopped, if it did.
    pub fn fault(&self) -> Option<PointerFault> {
        self.shared.fault()
    }

    /// The page time stamp of the newest sample the device had taken by servo tick `tick`, ms
    /// (`None`: none yet, or older than the last few seconds of ticks that took samples). The
    /// page measures its input-to-screen latency with it.
    pub fn echo_ms(&self, tick: u64) -> Option<f64> {
        self.shared.echo.at_or_before(tick)
    }

    /// The feed's counters (shared with its device).
    pub fn counters(&self) -> &PointerCounters {
        &self.shared.counters
    }

    /// Samples the queue holds at most.
    pub fn capacity(&self) -> usize {
        self.capacity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_force_is_read_whole_while_written() {
        let shared = Arc::new(Shared::new());
        let writer = {
            let shared = shared.clone();
            std::thread::spawn(move || {
                for k in 0..200_000u32 {
                    let x = f64::from(k);
                    shared.write_force(&Vector3::new(x, 2.0 * x, -x));
                }
            })
        };
        let mut reads = 0u64;
        while !writer.is_finished() || reads == 0 {
            let f = shared.force.read();
            assert_eq!((f.y, f.z), (2.0 * f.x, -f.x), "a torn force {f:?}");
            reads += 1;
        }
        writer.join().expect("writer");
        assert_eq!(
            shared.force.read(),
            Vector3::new(199_999.0, 399_998.0, -199_999.0)
        );
    }

    #[test]
    fn echo_finds_the_newest_sample_by_tick_and_forgets_old_ticks() {
        let ring = EchoRing::new();
        assert_eq!(ring.at_or_before(5), None);
        ring.write(3, 100.0);
        ring.write(7, 116.5);
        assert_eq!(ring.at_or_before(2), None);
        assert_eq!(ring.at_or_before(3), Some(100.0));
        assert_eq!(ring.at_or_before(6), Some(100.0));
        assert_eq!(ring.at_or_before(70), Some(116.5));
        for k in 0..ECHO_ENTRIES as u64 {
            ring.write(10 + k, 200.0 + k as f64);
        }
        assert_eq!(ring.at_or_before(7), None, "lapped");
        assert_eq!(ring.at_or_before(10), Some(200.0));
    }
}
