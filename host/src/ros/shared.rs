//! The hand-off between the 1 kHz bridge thread and the DDS thread.
//!
//! ```text
//!   DDS thread                         Shared                          bridge thread (1 kHz)
//!   cmd_vel sample ── put_cmd_vel ──► latest (v, ω, received at) ── take_cmd_vel (try_lock) ──►
//!   service call  ── request ───────► requests                   ── take_requests (try_lock) ─►
//!   publishers   ◄── snapshot ─────── Snapshot                   ◄── publish (try_lock) ───────
//! ```
//!
//! The bridge thread only ever *tries* the locks: if the DDS thread holds one, the bridge skips
//! that hand-off for this cycle and tries again 1 ms later, so nothing the DDS side does (a
//! publish waiting on a full reliable window, a descheduled thread holding a lock) can delay an
//! exchange with the MCU. A cmd_vel keeps the time it was received, so a hand-off that comes a
//! cycle late does not make the command look fresher than it is: the 200 ms staleness rule of the
//! bridge counts from reception.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard, TryLockError};
use std::time::{Instant, SystemTime};

use protocol::amr::{McuInfo, MotorFeedback};

use crate::bridge::{ArmState, BridgeStats, Diagnostic};

/// Most diagnostics kept for the DDS side between two snapshots (the oldest are dropped).
pub const MAX_EVENTS: usize = 256;

/// A velocity command as received.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CmdVel {
    /// Linear velocity, m/s.
    pub v: f64,
    /// Yaw rate, rad/s.
    pub w: f64,
    /// When it was received, µs on [`Shared::now_us`]'s clock.
    pub received_us: u64,
}

/// An operator request to the bridge (from a service or a signal).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request {
    /// Start the arming sequence from Disarmed.
    Arm,
    /// Send enable = 0 from now on.
    Disarm,
    /// Explicit re-arm after the MCU braked (a request: the MCU decides).
    Rearm,
    /// true: stop every exchange (and disarm), so the MCU loses the link and brakes; false: resume.
    Estop(bool),
}

/// What the bridge thread reports after each cycle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Snapshot {
    /// Cycles run.
    pub cycles: u64,
    /// Wall-clock time of the last exchange's reply (stamps of the published messages).
    pub stamp: Option<SystemTime>,
    /// The last feedback decoded.
    pub feedback: Option<MotorFeedback>,
    /// The MCU's identity, once received.
    pub mcu_info: Option<McuInfo>,
    /// Arming state of the bridge.
    pub arm: Option<ArmState>,
    /// Wheel speeds last commanded, rad/s.
    pub output: [f64; 2],
    /// Age of the latest cmd_vel at the last cycle, µs (None before the first).
    pub cmd_vel_age_us: Option<u64>,
    /// Bridge counters.
    pub stats: BridgeStats,
    /// Exchanges that failed at the transport.
    pub transport_errors: u64,
    /// The last transport error.
    pub last_error: Option<String>,
    /// Clock sync has converged.
    pub clock_synced: bool,
    /// MCU clock minus host clock at the last cycle, µs, once synced.
    pub clock_offset_us: Option<f64>,
    /// Exchanges are stopped (ESTOP engaged).
    pub silent: bool,
    /// Pacing: periods outside 1 ms ± 0.2 ms so far.
    pub period_misses: u64,
    /// Pacing: deadlines skipped after an overrun.
    pub skipped_deadlines: u64,
    /// Diagnostics raised since the DDS side last read them (host µs, diagnostic).
    pub events: Vec<(u64, Diagnostic)>,
    /// Diagnostics dropped because the DDS side did not read them in time.
    pub events_dropped: u64,
    /// The bridge thread has ended.
    pub ended: bool,
}

/// The state both threads share.
#[derive(Debug)]
pub struct Shared {
    epoch: Instant,
    cmd_vel: Mutex<Option<CmdVel>>,
    requests: Mutex<Vec<Request>>,
    snapshot: Mutex<Snapshot>,
    stop: AtomicBool,
}

impl Default for Shared {
    fn default() -> Self {
        Self::new()
    }
}

/// The guard of `m`, or None if another thread holds it (a poisoned lock is taken anyway: the
/// data are plain values, valid whatever the panicking thread was doing).
fn try_guard<T>(m: &Mutex<T>) -> Option<MutexGuard<'_, T>> {
    match m.try_lock() {
        Ok(g) => Some(g),
        Err(TryLockError::Poisoned(p)) => Some(p.into_inner()),
        Err(TryLockError::WouldBlock) => None,
    }
}

/// The guard of `m`, waiting for it (DDS side only).
fn guard<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Shared {
    /// Empty state; its clock starts now.
    pub fn new() -> Self {
        Self {
            epoch: Instant::now(),
            cmd_vel: Mutex::new(None),
            requests: Mutex::new(Vec::new()),
            snapshot: Mutex::new(Snapshot::default()),
            stop: AtomicBool::new(false),
        }
    }

    /// µs since this was created (the clock of [`CmdVel::received_us`]).
    pub fn now_us(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
    }

    // --- DDS side -------------------------------------------------------------------------

    /// A cmd_vel arrived now (it replaces any not yet taken).
    pub fn put_cmd_vel(&self, v: f64, w: f64) {
        let c = CmdVel {
            v,
            w,
            received_us: self.now_us(),
        };
        *guard(&self.cmd_vel) = Some(c);
    }

    /// Queues a request for the bridge thread.
    pub fn request(&self, r: Request) {
        guard(&self.requests).push(r);
    }

    /// The latest snapshot; its events are moved out (each event is read once).
    pub fn snapshot(&self) -> Snapshot {
        let mut g = guard(&self.snapshot);
        let s = g.clone();
        g.events.clear();
        s
    }

    /// Asks both threads to end.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// True once [`Shared::stop`] was called.
    pub fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    // --- bridge side (never blocks) -------------------------------------------------------

    /// The cmd_vel received since the last call, if any and if the lock is free.
    pub fn take_cmd_vel(&self) -> Option<CmdVel> {
        try_guard(&self.cmd_vel).and_then(|mut g| g.take())
    }

    /// The requests queued since the last call (none if the lock is busy: they wait a cycle).
    pub fn take_requests(&self) -> Vec<Request> {
        try_guard(&self.requests).map_or_else(Vec::new, |mut g| core::mem::take(&mut *g))
    }

    /// Updates the snapshot with `update` and appends `events` (moved out of it) if the lock is
    /// free; returns false, leaving `events` for the next cycle, if it is not.
    pub fn publish(
        &self,
        events: &mut Vec<(u64, Diagnostic)>,
        update: impl FnOnce(&mut Snapshot),
    ) -> bool {
        let Some(mut g) = try_guard(&self.snapshot) else {
            return false;
        };
        update(&mut g);
        g.events.append(events);
        let excess = g.events.len().saturating_sub(MAX_EVENTS);
        if excess > 0 {
            g.events.drain(..excess);
            g.events_dropped = g
                .events_dropped
                .saturating_add(u64::try_from(excess).unwrap_or(u64::MAX));
        }
        true
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn a_cmd_vel_is_taken_once_with_its_reception_time() {
        let s = Shared::new();
        assert_eq!(s.take_cmd_vel(), None);
        let before = s.now_us();
        s.put_cmd_vel(0.5, -0.25);
        let after = s.now_us();
        let c = s.take_cmd_vel().unwrap();
        assert_eq!((c.v, c.w), (0.5, -0.25));
        assert!(before <= c.received_us && c.received_us <= after);
        assert_eq!(s.take_cmd_vel(), None, "taken once");
    }

    #[test]
    fn the_newest_cmd_vel_replaces_an_untaken_one() {
        let s = Shared::new();
        s.put_cmd_vel(0.1, 0.0);
        s.put_cmd_vel(0.2, 0.0);
        assert_eq!(s.take_cmd_vel().unwrap().v, 0.2);
    }

    /// While the DDS side holds a lock, the bridge side gets nothing instead of waiting, and gets
    /// it all on the next try.
    #[test]
    fn the_bridge_side_never_waits_for_a_held_lock() {
        let s = Shared::new();
        s.put_cmd_vel(0.3, 0.0);
        s.request(Request::Arm);
        {
            let _held = s.cmd_vel.lock().unwrap();
            let _held_r = s.requests.lock().unwrap();
            let _held_s = s.snapshot.lock().unwrap();
            assert_eq!(s.take_cmd_vel(), None);
            assert!(s.take_requests().is_empty());
            let mut ev = vec![(5, Diagnostic::CmdVelStale)];
            assert!(!s.publish(&mut ev, |snap| snap.cycles = 9));
            assert_eq!(ev.len(), 1, "kept for the next cycle");
        }
        assert_eq!(s.take_cmd_vel().unwrap().v, 0.3);
        assert_eq!(s.take_requests(), vec![Request::Arm]);
        let mut ev = vec![(5, Diagnostic::CmdVelStale)];
        assert!(s.publish(&mut ev, |snap| snap.cycles = 9));
        assert!(ev.is_empty());
        let snap = s.snapshot();
        assert_eq!(snap.cycles, 9);
        assert_eq!(snap.events, vec![(5, Diagnostic::CmdVelStale)]);
        assert!(s.snapshot().events.is_empty(), "each event is read once");
    }

    #[test]
    fn requests_keep_their_order() {
        let s = Shared::new();
        s.request(Request::Estop(true));
        s.request(Request::Estop(false));
        s.request(Request::Rearm);
        assert_eq!(
            s.take_requests(),
            vec![Request::Estop(true), Request::Estop(false), Request::Rearm]
        );
    }

    #[test]
    fn unread_events_are_bounded_and_counted() {
        let s = Shared::new();
        let n = MAX_EVENTS + 10;
        let mut ev: Vec<_> = (0..n as u64)
            .map(|t| (t, Diagnostic::ClockSynced))
            .collect();
        assert!(s.publish(&mut ev, |_| {}));
        let snap = s.snapshot();
        assert_eq!(snap.events.len(), MAX_EVENTS);
        assert_eq!(snap.events_dropped, 10);
        // The newest are kept.
        assert_eq!(snap.events.last().unwrap().0, n as u64 - 1);
    }

    #[test]
    fn stop_is_seen_by_both_sides() {
        let s = std::sync::Arc::new(Shared::new());
        let t = {
            let s = s.clone();
            std::thread::spawn(move || {
                while !s.stopping() {
                    std::thread::yield_now();
                }
                true
            })
        };
        s.stop();
        assert!(t.join().unwrap());
    }
}
