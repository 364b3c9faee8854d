//! Matching a run's outputs to the ground truth as both stream in, in fixed memory: each
//! output waits only until the truth has reached its stamp (or [`TruthMatcher::LAG_NS`] has
//! passed), and the truth is kept only as far back as a waiting output may need it. Truth
//! that comes more than the lag after the outputs of its time is not matched to them.

use std::collections::VecDeque;

/// Outputs (`Q`, by stamp) waiting for the truth samples (`T`, by stamp) around them.
///
/// Both streams are expected in about stamp order, as a bag's log order gives them; a truth
/// sample out of order is put in its place for the outputs still waiting. A stamp more than
/// the lag before the newest seen starts the matching afresh (a bag played again from its
/// start): what waits is settled with the truth there is, and the old truth is dropped.
#[derive(Debug, Clone)]
pub struct TruthMatcher<T, Q> {
    /// Truth samples in stamp order.
    truth: VecDeque<(i64, T)>,
    /// Outputs in arrival order, waiting to be settled.
    waiting: VecDeque<(i64, Q)>,
    /// How far before an output's stamp a truth sample can still be used.
    lookback_ns: i64,
    /// The newest stamp seen on either stream.
    newest_ns: Option<i64>,
    /// The newest output stamp settled: later outputs need no truth before it but the last.
    settled_up_to_ns: Option<i64>,
}

/// The truth around an output's stamp when it was settled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Around<'a, T> {
    /// The latest sample stamped before the output.
    pub before: Option<(i64, &'a T)>,
    /// The first sample stamped at or after it.
    pub from: Option<(i64, &'a T)>,
}

impl<'a, T> Around<'a, T> {
    /// The latest sample stamped at or before the output.
    pub fn latest_not_after(&self, stamp_ns: i64) -> Option<(i64, &'a T)> {
        match self.from {
            Some((t, value)) if t == stamp_ns => Some((t, value)),
            _ => self.before,
        }
    }
}

impl<T, Q> TruthMatcher<T, Q> {
    /// How long (in stamps, on either stream) an output waits for the truth to reach its
    /// stamp before it is settled with what there is: truth that ended, or that comes late.
    pub const LAG_NS: i64 = 5_000_000_000;

    /// A matcher that keeps truth samples up to `lookback_ns` before the outputs waiting.
    pub fn new(lookback_ns: i64) -> Self {
        Self {
            truth: VecDeque::new(),
            waiting: VecDeque::new(),
            lookback_ns,
            newest_ns: None,
            settled_up_to_ns: None,
        }
    }

    /// Adds a truth sample and settles the outputs it completes.
    pub fn add_truth(
        &mut self,
        stamp_ns: i64,
        value: T,
        mut settle: impl FnMut(i64, Q, Around<'_, T>),
    ) {
        self.restart_if_back(stamp_ns, &mut settle);
        let at = self.truth.partition_point(|&(t, _)| t <= stamp_ns);
        self.truth.insert(at, (stamp_ns, value));
        self.saw(stamp_ns);
        self.settle_ready(settle);
    }

    /// Adds an output, settled once the truth around it is known.
    pub fn add_output(
        &mut self,
        stamp_ns: i64,
        output: Q,
        mut settle: impl FnMut(i64, Q, Around<'_, T>),
    ) {
        self.restart_if_back(stamp_ns, &mut settle);
        self.waiting.push_back((stamp_ns, output));
        self.saw(stamp_ns);
        self.settle_ready(settle);
    }

    /// Settles every output still waiting, with the truth there is: the end of the run.
    pub fn finish(&mut self, mut settle: impl FnMut(i64, Q, Around<'_, T>)) {
        while let Some((stamp_ns, output)) = self.waiting.pop_front() {
            settle(stamp_ns, output, self.around(stamp_ns));
        }
    }

    /// Truth samples held: bounded by the lag and the lookback, whatever the run's length.
    pub fn truth_held(&self) -> usize {
        self.truth.len()
    }

    /// Starts afresh when `stamp_ns` is more than the lag before the newest stamp seen: the
    /// truth held is of another stretch of time, and would be dropped as too old anyway.
    fn restart_if_back(&mut self, stamp_ns: i64, settle: impl FnMut(i64, Q, Around<'_, T>)) {
        let back = self
            .newest_ns
            .is_some_and(|newest| stamp_ns < newest.saturating_sub(Self::LAG_NS));
        if back {
            self.finish(settle);
            self.truth.clear();
            self.newest_ns = None;
            self.settled_up_to_ns = None;
        }
    }

    fn saw(&mut self, stamp_ns: i64) {
        self.newest_ns = Some(self.newest_ns.map_or(stamp_ns, |n| n.max(stamp_ns)));
    }

    fn settle_ready(&mut self, mut settle: impl FnMut(i64, Q, Around<'_, T>)) {
        let newest_ns = self.newest_ns.unwrap_or(i64::MIN);
        let newest_truth_ns = self.truth.back().map(|&(t, _)| t);
        while let Some(&(stamp_ns, _)) = self.waiting.front() {
            let truth_reached = newest_truth_ns.is_some_and(|t| t >= stamp_ns);
            if !truth_reached && newest_ns.saturating_sub(stamp_ns) <= Self::LAG_NS {
                break;
            }
            let (stamp_ns, output) = self.waiting.pop_front().expect("front seen above");
            settle(stamp_ns, output, self.around(stamp_ns));
            self.settled_up_to_ns =
                Some(self.settled_up_to_ns.map_or(stamp_ns, |s| s.max(stamp_ns)));
        }
        self.drop_old_truth();
    }

    /// Drops the truth no output can need: before the oldest one waiting (or, with none
    /// waiting, the newest settled), less the lookback, and older than the lag, keeping the
    /// last sample before that line.
    fn drop_old_truth(&mut self) {
        let needed_from = self
            .waiting
            .front()
            .map(|&(t, _)| t)
            .or(self.settled_up_to_ns)
            .unwrap_or(i64::MIN)
            .max(
                self.newest_ns
                    .unwrap_or(i64::MIN)
                    .saturating_sub(Self::LAG_NS),
            )
            .saturating_sub(self.lookback_ns);
        while self.truth.len() > 1 && self.truth[1].0 < needed_from {
            self.truth.pop_front();
        }
    }

    fn around(&self, stamp_ns: i64) -> Around<'_, T> {
        let i = self.truth.partition_point(|&(t, _)| t < stamp_ns);
        let get = |j: usize| self.truth.get(j).map(|(t, value)| (*t, value));
        Around {
            before: i.checked_sub(1).and_then(get),
            from: get(i),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    type Settled = Vec<(i64, char, Option<i64>, Option<i64>)>;

    fn record(settled: &mut Settled) -> impl FnMut(i64, char, Around<'_, i64>) + '_ {
        |stamp, output, around| {
            settled.push((
                stamp,
                output,
                around.before.map(|(_, v)| *v),
                around.from.map(|(_, v)| *v),
            ))
        }
    }

    #[test]
    fn an_output_waits_for_the_truth_to_reach_its_stamp() {
        let mut matcher = TruthMatcher::new(200 * MS);
        let mut settled = Settled::new();
        matcher.add_truth(0, 10, record(&mut settled));
        matcher.add_output(50 * MS, 'a', record(&mut settled));
        assert!(settled.is_empty(), "the truth after 50 ms is not known yet");
        matcher.add_truth(100 * MS, 11, record(&mut settled));
        assert_eq!(settled, vec![(50 * MS, 'a', Some(10), Some(11))]);
        // An output the truth has passed settles at once, its exact-stamp sample as `from`.
        matcher.add_output(100 * MS, 'b', record(&mut settled));
        assert_eq!(settled[1], (100 * MS, 'b', Some(10), Some(11)));
    }

    #[test]
    fn an_output_the_truth_never_reaches_settles_after_the_lag_or_at_the_end() {
        let lag = TruthMatcher::<i64, char>::LAG_NS;
        let mut matcher = TruthMatcher::new(200 * MS);
        let mut settled = Settled::new();
        matcher.add_truth(0, 10, record(&mut settled));
        matcher.add_output(MS, 'a', record(&mut settled));
        matcher.add_output(2 * MS, 'b', record(&mut settled));
        matcher.add_output(MS + lag, 'c', record(&mut settled));
        assert!(settled.is_empty());
        matcher.add_output(2 * MS + lag, 'd', record(&mut settled));
        assert_eq!(settled, vec![(MS, 'a', Some(10), None)]);
        matcher.finish(record(&mut settled));
        let order: String = settled.iter().map(|s| s.1).collect();
        assert_eq!(order, "abcd");
    }

    #[test]
    fn truth_out_of_order_is_put_in_its_place() {
        let mut matcher = TruthMatcher::new(200 * MS);
        let mut settled = Settled::new();
        matcher.add_output(50 * MS, 'a', record(&mut settled));
        matcher.add_truth(40 * MS, 4, record(&mut settled));
        matcher.add_truth(60 * MS, 6, record(&mut settled));
        matcher.add_truth(45 * MS, 5, record(&mut settled));
        assert_eq!(settled, vec![(50 * MS, 'a', Some(4), Some(6))]);
        matcher.add_output(55 * MS, 'b', record(&mut settled));
        assert_eq!(settled[1], (55 * MS, 'b', Some(5), Some(6)));
    }

    #[test]
    fn a_bag_played_again_from_its_start_is_matched_afresh() {
        let mut matcher = TruthMatcher::new(200 * MS);
        let mut settled = Settled::new();
        for pass in 0..2 {
            for k in 0..1000_i64 {
                matcher.add_truth(k * 10 * MS, k, record(&mut settled));
                matcher.add_output(k * 10 * MS + 5 * MS, 'a', record(&mut settled));
            }
            assert_eq!(settled.len(), 999 * (pass + 1) + pass, "pass {pass}");
        }
        matcher.finish(record(&mut settled));
        assert_eq!(settled.len(), 2000);
        // Each output of either pass between the truth of its own pass.
        assert!(settled.iter().all(
            |&(stamp, _, before, from)| before == Some(stamp / (10 * MS))
                && from.is_none_or(|f| f == stamp / (10 * MS) + 1)
        ));
    }

    #[test]
    fn the_truth_held_stays_bounded_over_a_long_run() {
        let mut matcher = TruthMatcher::new(500 * MS);
        let mut settled = 0;
        let mut count = |_: i64, _: (), _: Around<'_, ()>| settled += 1;
        // An hour of truth at 100 Hz; outputs at 10 Hz, but none for a stretch in the middle
        // (the person out of sight).
        for i in 0..360_000_i64 {
            let stamp = i * 10 * MS;
            matcher.add_truth(stamp, (), &mut count);
            let unseen = (100_000..200_000).contains(&i);
            if i % 10 == 0 && !unseen {
                matcher.add_output(stamp + MS, (), &mut count);
            }
            assert!(
                matcher.truth_held() <= 560,
                "{} held at {i}",
                matcher.truth_held()
            );
        }
        matcher.finish(&mut count);
        assert_eq!(settled, 26_000);
    }
}
