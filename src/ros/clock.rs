//! The node's clock: the system clock, or, with the `use_sim_time` parameter,
//! the latest `/clock` message (`rosgraph_msgs/msg/Clock`), as published by a
//! bag player. It stamps diagnostics, model-swap announcements and the log
//! times of recordings; predictions keep their input's stamp either way.

use std::sync::atomic::{AtomicI64, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::data::msg::{Header, Time};

use super::wire::ClockMsg;

/// Wall or simulated time, in nanoseconds since the epoch.
#[derive(Debug)]
pub struct Clock {
    /// `Some` with the latest `/clock` time when simulated.
    sim: Option<AtomicI64>,
}

impl Clock {
    /// The system clock, or simulated time (0 until the first `/clock`).
    pub fn new(use_sim_time: bool) -> Self {
        Clock {
            sim: use_sim_time.then(|| AtomicI64::new(0)),
        }
    }

    /// Takes a `/clock` message (ignored by a system clock).
    pub fn set(&self, msg: &ClockMsg) {
        if let Some(s) = &self.sim {
            s.store(msg.clock.as_nanos(), Ordering::Relaxed);
        }
    }

    /// Now, in nanoseconds since the epoch.
    pub fn now_ns(&self) -> i64 {
        match &self.sim {
            Some(s) => s.load(Ordering::Relaxed),
            None => SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
                .unwrap_or(0),
        }
    }

    /// Now as a log time for recordings (0 before the epoch).
    pub fn now_log_ns(&self) -> u64 {
        u64::try_from(self.now_ns()).unwrap_or(0)
    }

    /// A header stamped now, with no frame.
    pub fn header(&self) -> Header {
        Header {
            stamp: Time::from_nanos(self.now_ns()),
            frame_id: String::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simulated_time_follows_clock_messages_and_wall_time_ignores_them() {
        let sim = Clock::new(true);
        assert_eq!(sim.now_ns(), 0);
        let msg = ClockMsg {
            clock: Time {
                sec: 42,
                nanosec: 5,
            },
        };
        sim.set(&msg);
        assert_eq!(sim.now_ns(), 42_000_000_005);
        assert_eq!(sim.header().stamp, msg.clock);
        let wall = Clock::new(false);
        wall.set(&msg);
        assert!(wall.now_ns() > 1_700_000_000_000_000_000);
    }
}
