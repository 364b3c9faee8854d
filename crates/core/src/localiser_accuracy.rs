//! How well the localiser follows the person, scored scan by scan against ground truth (the
//! simulator's), so sweeps over scenes, seeds and robot motions give comparable figures.
//!
//! Definitions (docs/localiser.md repeats them beside the figures):
//! - **position error**: distance from the reported person position to the true one, over
//!   every scan in which the localiser reports a person, seen or predicted (the same set as
//!   `summary.json`'s `position_error_m`);
//! - **in sight**: at least [`AccuracyCriteria::min_person_beams`] beams of the scan returned
//!   from the person's body (default 3, the clustering's `min_points`: fewer cannot form a
//!   cluster at all);
//! - **on the person**: a person is reported within [`AccuracyCriteria::on_person_m`] of the
//!   truth (default 0.5 m: well inside the tracker's 0.8 m gate, farther than any body part
//!   from the pelvis of a standing person);
//! - **continuity**: the fraction of in-sight scans in which the track is on the person;
//! - **identity continuity**: the same with "on the person" decided by whose returns the track
//!   took, where the host knows (the simulator labels every beam): a seen track is on the
//!   person when most of the points it took for them are returns from the person's body, so
//!   a track holding the person's own legs is on them even when the truth (the pelvis of
//!   someone sitting on the floor) lies 0.5 m away, and a track on a chair leg beside them is
//!   not. A predicted track, which took no points, is judged by distance as above;
//! - **visible ratio**: the fraction of all scans in which the localiser saw the person.
//!
//! Quantiles are nearest-rank (the smallest value with at least that fraction of the values
//! at or below it), as in `summary.json`.

use glam::DVec2;
use serde::Serialize;

use crate::stats::nearest_rank;

/// Thresholds that turn ground truth into "in sight" and "on the person".
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AccuracyCriteria {
    /// Beams on the person's body for the scan to count as in sight.
    pub min_person_beams: usize,
    /// Largest distance from the truth at which the track is on the person (m).
    pub on_person_m: f64,
}

impl Default for AccuracyCriteria {
    fn default() -> Self {
        Self {
            min_person_beams: 3,
            on_person_m: 0.5,
        }
    }
}

/// What the localiser reported for the person in one scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReportedPerson {
    pub position: DVec2,
    /// Seen in this scan (false: predicted through an occlusion).
    pub visible: bool,
    /// Whose returns the points taken for the person were; `None` when the host cannot tell.
    pub points: Option<PointOwners>,
}

/// Of the points the localiser took for the person, how many came from the person's body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointOwners {
    pub from_person: usize,
    pub total: usize,
}

impl ReportedPerson {
    /// Whether the track is on the person: by the owners of its points when seen and known,
    /// else by its distance to the truth.
    fn is_on_person(&self, error_m: f64, criteria: &AccuracyCriteria) -> bool {
        match self.points {
            Some(owners) if self.visible => 2 * owners.from_person > owners.total,
            _ => error_m <= criteria.on_person_m,
        }
    }
}

/// One scan: the truth and what was reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanOutcome {
    /// The person's true position; `None` when the scene has nobody.
    pub truth: Option<DVec2>,
    /// Beams whose return came from the person's body.
    pub person_beams: usize,
    pub reported: Option<ReportedPerson>,
}

/// Counts over many scans; tallies of parts (scenes, activities) merge into a whole.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AccuracyTally {
    scans: u64,
    in_sight: u64,
    on_person_in_sight: u64,
    identity_in_sight: u64,
    visible: u64,
    reported: u64,
    errors_m: Vec<f64>,
}

impl AccuracyTally {
    pub fn add(&mut self, scan: &ScanOutcome, criteria: &AccuracyCriteria) {
        self.scans += 1;
        let in_sight = scan.truth.is_some() && scan.person_beams >= criteria.min_person_beams;
        self.in_sight += u64::from(in_sight);
        let Some(reported) = scan.reported else {
            return;
        };
        self.reported += 1;
        self.visible += u64::from(reported.visible);
        let Some(truth) = scan.truth else {
            return;
        };
        let error = reported.position.distance(truth);
        if error.is_finite() {
            self.errors_m.push(error);
        }
        self.on_person_in_sight += u64::from(in_sight && error <= criteria.on_person_m);
        self.identity_in_sight += u64::from(in_sight && reported.is_on_person(error, criteria));
    }

    pub fn merge(&mut self, other: &AccuracyTally) {
        self.scans += other.scans;
        self.in_sight += other.in_sight;
        self.on_person_in_sight += other.on_person_in_sight;
        self.identity_in_sight += other.identity_in_sight;
        self.visible += other.visible;
        self.reported += other.reported;
        self.errors_m.extend_from_slice(&other.errors_m);
    }

    /// How many scored scans were more than `limit_m` off: a p95 target of `limit_m` allows
    /// a twentieth of all scans, and this says which scans spend that allowance.
    pub fn errors_above(&self, limit_m: f64) -> usize {
        self.errors_m.iter().filter(|&&e| e > limit_m).count()
    }

    /// Scans with a reported position and a truth to score it against.
    pub fn scored(&self) -> usize {
        self.errors_m.len()
    }

    pub fn report(&self) -> AccuracyReport {
        let ratio = |n: u64, d: u64| (d > 0).then(|| n as f64 / d as f64);
        let mut errors = self.errors_m.clone();
        errors.sort_by(f64::total_cmp);
        AccuracyReport {
            scans: self.scans,
            in_sight_scans: self.in_sight,
            error_median_m: nearest_rank(&errors, 0.5),
            error_p95_m: nearest_rank(&errors, 0.95),
            error_max_m: errors.last().copied(),
            continuity: ratio(self.on_person_in_sight, self.in_sight),
            identity_continuity: ratio(self.identity_in_sight, self.in_sight),
            visible_ratio: ratio(self.visible, self.scans),
            in_sight_ratio: ratio(self.in_sight, self.scans),
            reported_ratio: ratio(self.reported, self.scans),
        }
    }
}

/// The figures of a tally; ratios and quantiles are `None` when nothing was counted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AccuracyReport {
    pub scans: u64,
    pub in_sight_scans: u64,
    pub error_median_m: Option<f64>,
    pub error_p95_m: Option<f64>,
    pub error_max_m: Option<f64>,
    /// In-sight scans with the track on the person, over in-sight scans.
    pub continuity: Option<f64>,
    /// In-sight scans with the track on the person by the owners of its points, over in-sight
    /// scans.
    pub identity_continuity: Option<f64>,
    /// Scans in which the person was seen, over all scans.
    pub visible_ratio: Option<f64>,
    /// Scans with the person in sight (ground truth), over all scans.
    pub in_sight_ratio: Option<f64>,
    /// Scans with a person reported (seen or predicted), over all scans.
    pub reported_ratio: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(truth: f64, beams: usize, reported: Option<(f64, bool)>) -> ScanOutcome {
        ScanOutcome {
            truth: Some(DVec2::new(truth, 0.0)),
            person_beams: beams,
            reported: reported.map(|(x, visible)| ReportedPerson {
                position: DVec2::new(x, 0.0),
                visible,
                points: None,
            }),
        }
    }

    fn owned_by(mut s: ScanOutcome, from_person: usize, total: usize) -> ScanOutcome {
        s.reported.as_mut().unwrap().points = Some(PointOwners { from_person, total });
        s
    }

    #[test]
    fn a_hand_made_sequence_gives_the_hand_computed_figures() {
        let criteria = AccuracyCriteria::default();
        let scans = [
            scan(0.0, 10, Some((0.1, true))),  // in sight, on, error 0.1
            scan(0.0, 10, Some((0.2, true))),  // in sight, on, error 0.2
            scan(0.0, 10, Some((0.6, true))),  // in sight, off (0.6 > 0.5)
            scan(0.0, 10, None),               // in sight, nothing reported
            scan(0.0, 2, Some((0.3, false))),  // not in sight (2 beams), predicted
            scan(1.0, 0, Some((1.05, false))), // not in sight, predicted, error 0.05
        ];
        let mut tally = AccuracyTally::default();
        for s in &scans {
            tally.add(s, &criteria);
        }
        let r = tally.report();
        assert_eq!(r.scans, 6);
        assert_eq!(r.in_sight_scans, 4);
        assert_eq!(r.continuity, Some(0.5));
        // Without point owners identity is judged by distance too.
        assert_eq!(r.identity_continuity, r.continuity);
        assert_eq!(r.visible_ratio, Some(0.5));
        assert_eq!(r.in_sight_ratio, Some(4.0 / 6.0));
        assert_eq!(r.reported_ratio, Some(5.0 / 6.0));
        // Errors sorted: 0.05, 0.1, 0.2, 0.3, 0.6 -> median is the 3rd, p95 the 5th.
        let close = |a: Option<f64>, b: f64| (a.unwrap() - b).abs() < 1e-12;
        assert!(close(r.error_median_m, 0.2), "{r:?}");
        assert!(close(r.error_p95_m, 0.6), "{r:?}");
        assert!(close(r.error_max_m, 0.6), "{r:?}");
    }

    #[test]
    fn identity_follows_the_owners_of_a_seen_tracks_points_and_distance_otherwise() {
        let criteria = AccuracyCriteria::default();
        let scans = [
            // Holding the person's own points 0.6 m from the truth (sitting: legs, not pelvis).
            owned_by(scan(0.0, 10, Some((0.6, true))), 8, 10),
            // Right beside the truth but on something else (a chair leg).
            owned_by(scan(0.0, 10, Some((0.1, true))), 2, 10),
            // Half and half is not on the person.
            owned_by(scan(0.0, 10, Some((0.0, true))), 5, 10),
            // Predicted through an occlusion: by distance, owners or not.
            owned_by(scan(0.0, 10, Some((0.3, false))), 0, 0),
            owned_by(scan(0.0, 10, Some((0.7, false))), 0, 0),
        ];
        let mut tally = AccuracyTally::default();
        for s in &scans {
            tally.add(s, &criteria);
        }
        let r = tally.report();
        assert_eq!(r.identity_continuity, Some(2.0 / 5.0), "{r:?}");
        assert_eq!(r.continuity, Some(3.0 / 5.0), "{r:?}");
    }

    #[test]
    fn merged_tallies_equal_one_tally_over_all_scans() {
        let criteria = AccuracyCriteria::default();
        let scans: Vec<ScanOutcome> = (0..20)
            .map(|i| {
                let reported = (i % 3 != 0).then_some((i as f64 * 0.07, i % 2 == 0));
                match reported {
                    Some(_) if i % 4 < 2 => owned_by(scan(0.0, i % 5, reported), i % 3, 2),
                    _ => scan(0.0, i % 5, reported),
                }
            })
            .collect();
        let (mut a, mut b, mut whole) = (
            AccuracyTally::default(),
            AccuracyTally::default(),
            AccuracyTally::default(),
        );
        for (i, s) in scans.iter().enumerate() {
            if i < 7 { &mut a } else { &mut b }.add(s, &criteria);
            whole.add(s, &criteria);
        }
        a.merge(&b);
        assert_eq!(a.report(), whole.report());
    }

    #[test]
    fn nothing_counted_gives_no_figures_and_no_person_is_never_in_sight() {
        assert_eq!(AccuracyTally::default().report().continuity, None);
        let mut tally = AccuracyTally::default();
        let empty_room = ScanOutcome {
            truth: None,
            person_beams: 50,
            reported: Some(ReportedPerson {
                position: DVec2::ZERO,
                visible: true,
                points: None,
            }),
        };
        tally.add(&empty_room, &AccuracyCriteria::default());
        let r = tally.report();
        assert_eq!((r.in_sight_scans, r.continuity), (0, None));
        assert_eq!(r.error_median_m, None);
        assert_eq!(r.visible_ratio, Some(1.0));
    }
}
