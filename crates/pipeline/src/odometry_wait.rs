//! Scans waiting for the odometry at their stamp. A scan newer than the newest odometry
//! would be placed by extrapolation, and skipped beyond `odometry.max_extrapolation_s`: with
//! odometry delivered 150 ms late, every scan was. As a tf2 message filter holds a message
//! until its transform is available, such a scan waits, up to `odometry.max_wait_s` in
//! receive time (a bag's log time, a node's clock, so that both behave the same), for a
//! sample at or after its stamp. Scans leave in the order they came, never reordered.

use std::collections::VecDeque;

/// Scans held at most: 0.5 s of a 20 Hz Lidar. Beyond it the oldest leaves without waiting
/// longer, so a long `max_wait_s` or a stopped odometry cannot pile scans up.
pub const MAX_WAITING_SCANS: usize = 10;

/// The scans (`T`) waiting for odometry, oldest first.
#[derive(Debug)]
pub struct OdometryWait<T> {
    max_wait_ns: i64,
    waiting: VecDeque<Waiting<T>>,
}

#[derive(Debug)]
struct Waiting<T> {
    stamp_ns: i64,
    received_ns: i64,
    scan: T,
}

impl<T> OdometryWait<T> {
    /// `max_wait_s` 0: every scan leaves as soon as it comes.
    pub fn new(max_wait_s: f64) -> Self {
        Self {
            max_wait_ns: (max_wait_s * 1e9) as i64,
            waiting: VecDeque::new(),
        }
    }

    /// A scan stamped `stamp_ns`, received at `received_ns`, joins the end of the queue.
    pub fn push(&mut self, stamp_ns: i64, received_ns: i64, scan: T) {
        self.waiting.push_back(Waiting {
            stamp_ns,
            received_ns,
            scan,
        });
    }

    /// The oldest scan, when it need wait no longer: the newest odometry (`latest_odometry_ns`)
    /// has reached its stamp, its wait is over at `now_ns`, or too many wait behind it.
    pub fn pop_ready(&mut self, latest_odometry_ns: Option<i64>, now_ns: i64) -> Option<T> {
        let oldest = self.waiting.front()?;
        let odometry_reached = latest_odometry_ns.is_some_and(|t| t >= oldest.stamp_ns);
        if odometry_reached || self.wait_over(oldest, now_ns) {
            self.pop_any()
        } else {
            None
        }
    }

    /// The oldest scan, when its wait is over at `now_ns` whatever the odometry.
    pub fn pop_expired(&mut self, now_ns: i64) -> Option<T> {
        let oldest = self.waiting.front()?;
        if self.wait_over(oldest, now_ns) {
            self.pop_any()
        } else {
            None
        }
    }

    /// The oldest scan, ready or not (the input has ended).
    pub fn pop_any(&mut self) -> Option<T> {
        self.waiting.pop_front().map(|w| w.scan)
    }

    /// When the oldest scan's wait is over (receive time), if a scan waits.
    pub fn deadline_ns(&self) -> Option<i64> {
        self.waiting
            .front()
            .map(|w| w.received_ns.saturating_add(self.max_wait_ns))
    }

    fn wait_over(&self, oldest: &Waiting<T>, now_ns: i64) -> bool {
        now_ns.saturating_sub(oldest.received_ns) >= self.max_wait_ns
            || self.waiting.len() > MAX_WAITING_SCANS
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    /// Scans every 50 ms from 0, each received when stamped.
    fn wait_with_scans(count: i64) -> OdometryWait<i64> {
        let mut wait = OdometryWait::new(0.5);
        for k in 0..count {
            wait.push(k * 50 * MS, k * 50 * MS, k);
        }
        wait
    }

    #[test]
    fn a_scan_waits_for_odometry_at_its_stamp_and_scans_leave_in_order() {
        let mut wait = wait_with_scans(3);
        let now = 100 * MS;
        assert_eq!(wait.pop_ready(None, now), None, "no odometry yet");
        assert_eq!(
            wait.pop_ready(Some(-MS), now),
            None,
            "odometry before the scan"
        );
        // Odometry 150 ms late reaches the first two scans' stamps.
        assert_eq!(wait.pop_ready(Some(60 * MS), now), Some(0));
        assert_eq!(wait.pop_ready(Some(60 * MS), now), Some(1));
        assert_eq!(wait.pop_ready(Some(60 * MS), now), None);
        assert_eq!(wait.deadline_ns(), Some(600 * MS));
        assert_eq!(wait.pop_ready(Some(100 * MS), now), Some(2));
        assert_eq!(wait.deadline_ns(), None);
    }

    #[test]
    fn a_scan_waits_no_longer_than_max_wait_in_receive_time() {
        let mut wait = wait_with_scans(2);
        assert_eq!(wait.pop_expired(499 * MS), None);
        assert_eq!(wait.pop_ready(None, 499 * MS), None);
        assert_eq!(wait.pop_expired(500 * MS), Some(0));
        assert_eq!(
            wait.pop_expired(500 * MS),
            None,
            "the second came 50 ms later"
        );
        assert_eq!(wait.pop_ready(None, 550 * MS), Some(1));
    }

    #[test]
    fn without_a_wait_every_scan_leaves_at_once() {
        let mut wait = OdometryWait::new(0.0);
        wait.push(10 * MS, 0, 'a');
        assert_eq!(wait.pop_ready(None, 0), Some('a'));
    }

    #[test]
    fn the_oldest_leaves_when_too_many_wait() {
        let count = MAX_WAITING_SCANS as i64;
        let mut wait = wait_with_scans(count);
        assert_eq!(wait.pop_ready(None, 0), None);
        wait.push(count * 50 * MS, count * 50 * MS, count);
        assert_eq!(wait.pop_ready(None, 0), Some(0));
        assert_eq!(wait.pop_ready(None, 0), None);
    }

    #[test]
    fn scans_still_waiting_when_the_input_ends_are_all_given_back() {
        let mut wait = wait_with_scans(3);
        let left: Vec<_> = std::iter::from_fn(|| wait.pop_any()).collect();
        assert_eq!(left, [0, 1, 2]);
    }
}
