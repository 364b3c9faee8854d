//! Which cluster is the person, scan after scan.
//!
//! The paper keeps the cluster nearest the previous centroid inside a 0.8 m gate, and loses
//! the person for good when they are hidden for one scan. Here every cluster feeds a
//! constant-velocity Kalman filter track:
//! - the person's track predicts through short occlusions (behind furniture) and its gate
//!   grows with the person's top speed while it is unseen, so it re-acquires them where they
//!   reappear;
//! - a new cluster only becomes a confirmed track after `confirm_hits` detections, so
//!   transient clutter (multipath, a stray return) never takes over;
//! - when the person's track has been unseen for `max_coast_s`, it is dropped and the most
//!   established confirmed track becomes the person.
//!
//! The filter is separable: with the same constant-velocity model and isotropic measurement
//! noise on both axes, x and y evolve independently, so two 2-state filters are exact and
//! cheaper than one 4-state filter (the position covariance is diagonal).

use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::cluster::Cluster;

/// Tracker parameters; the gate is the paper's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerConfig {
    /// Clusters farther than this from a track's predicted position are not that track (m).
    pub gate_m: f64,
    /// While a track is unseen its gate grows at this speed (the person's top speed, m/s:
    /// 2.5, running; the paper's 1 m/s lost runners behind pillars in the simulator)...
    pub gate_growth_mps: f64,
    /// ...up to this radius (m).
    pub max_gate_m: f64,
    /// Other clusters whose centroid is this close to the person's cluster are parts of the
    /// person (an arm, the second leg) and join its points (m).
    pub part_merge_m: f64,
    /// Detections before a new track is trusted.
    pub confirm_hits: u32,
    /// A tentative track missed this many scans in a row is clutter and is dropped.
    pub tentative_max_misses: u32,
    /// A confirmed track unseen for longer than this is lost (s).
    pub max_coast_s: f64,
    /// Standard deviation of the person's acceleration, the filter's process noise (m/s^2).
    pub accel_std_mps2: f64,
    /// Standard deviation of a cluster centroid around the person's position (m): the legs
    /// swing, one hides the other, so a walking person's centroid scatters ~0.15 m (measured
    /// with the `localiser_accuracy` example; 0.05 made the velocity jitter by +-1 m/s).
    pub measurement_std_m: f64,
    /// Standard deviation of the unknown velocity of a new track (m/s).
    pub initial_velocity_std_mps: f64,
    /// Speeds above this are clamped: nobody indoors moves faster (m/s).
    pub max_speed_mps: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            gate_m: 0.8,
            gate_growth_mps: 2.5,
            max_gate_m: 2.0,
            part_merge_m: 0.6,
            confirm_hits: 3,
            tentative_max_misses: 2,
            max_coast_s: 2.0,
            accel_std_mps2: 2.0,
            measurement_std_m: 0.15,
            initial_velocity_std_mps: 1.0,
            max_speed_mps: 3.0,
        }
    }
}

/// One axis of a constant-velocity Kalman filter.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AxisFilter {
    pos: f64,
    vel: f64,
    /// Covariance of (pos, vel).
    cov: [[f64; 2]; 2],
}

impl AxisFilter {
    fn new(pos: f64, pos_var: f64, vel_var: f64) -> Self {
        Self {
            pos,
            vel: 0.0,
            cov: [[pos_var, 0.0], [0.0, vel_var]],
        }
    }

    fn predict(&mut self, dt: f64, accel_var: f64) {
        let [[p00, p01], [p10, p11]] = self.cov;
        self.pos += self.vel * dt;
        let (dt2, dt3) = (dt * dt, dt * dt * dt);
        self.cov = [
            [
                p00 + dt * (p10 + p01) + dt2 * p11 + accel_var * dt3 / 3.0,
                p01 + dt * p11 + accel_var * dt2 / 2.0,
            ],
            [p10 + dt * p11 + accel_var * dt2 / 2.0, p11 + accel_var * dt],
        ];
    }

    fn update(&mut self, z: f64, meas_var: f64) {
        let [[p00, p01], [p10, p11]] = self.cov;
        let s = p00 + meas_var;
        let (k0, k1) = (p00 / s, p10 / s);
        let innovation = z - self.pos;
        self.pos += k0 * innovation;
        self.vel += k1 * innovation;
        self.cov = [
            [(1.0 - k0) * p00, (1.0 - k0) * p01],
            [p10 - k1 * p00, p11 - k1 * p01],
        ];
    }
}

/// A tracked object.
#[derive(Debug, Clone)]
struct Track {
    id: u64,
    x: AxisFilter,
    y: AxisFilter,
    stamp_ns: i64,
    last_seen_ns: i64,
    hits: u32,
    misses_in_a_row: u32,
    confirmed: bool,
    /// Points of the cluster(s) assigned in the latest scan; empty when unseen.
    points: Vec<DVec2>,
}

impl Track {
    fn position(&self) -> DVec2 {
        DVec2::new(self.x.pos, self.y.pos)
    }

    fn unseen_s(&self, stamp_ns: i64) -> f64 {
        (stamp_ns - self.last_seen_ns) as f64 * 1e-9
    }

    fn gate(&self, stamp_ns: i64, config: &TrackerConfig) -> f64 {
        (config.gate_m + config.gate_growth_mps * self.unseen_s(stamp_ns))
            .min(config.max_gate_m.max(config.gate_m))
    }
}

/// The person as the tracker sees them at one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct PersonEstimate {
    /// Stable while the same track follows the person; a new id means a re-acquisition.
    pub track_id: u64,
    pub position: DVec2,
    pub velocity: DVec2,
    /// Position covariance (m^2), row-major.
    pub covariance: [[f64; 2]; 2],
    /// Whether a cluster was assigned in this scan (false while predicting through occlusion).
    pub visible: bool,
    /// The person's points in this scan (map frame); empty when not visible.
    pub points: Vec<DVec2>,
    /// Seconds since the person was last seen (0 when visible).
    pub unseen_s: f64,
}

/// Multi-target tracker that singles out one person.
#[derive(Debug, Clone)]
pub struct Tracker {
    config: TrackerConfig,
    tracks: Vec<Track>,
    person: Option<u64>,
    next_id: u64,
    confirmed_total: u64,
    /// Scratch: which clusters are taken in the current scan.
    taken: Vec<bool>,
}

impl Tracker {
    pub fn new(config: TrackerConfig) -> Self {
        Self {
            config,
            tracks: Vec::new(),
            person: None,
            next_id: 1,
            confirmed_total: 0,
            taken: Vec::new(),
        }
    }

    /// How many tracks were ever confirmed (people, or persistent unmapped objects).
    pub fn confirmed_total(&self) -> u64 {
        self.confirmed_total
    }

    /// Tracks currently alive, tentative ones included.
    pub fn live_tracks(&self) -> usize {
        self.tracks.len()
    }

    /// Forgets everything (after a jump in time or pose that breaks continuity).
    pub fn reset(&mut self) {
        self.tracks.clear();
        self.person = None;
    }

    /// Advances every track to `stamp_ns` (not earlier than the previous call) and assigns
    /// this scan's clusters; returns the person's estimate, if a person is tracked.
    pub fn update(&mut self, stamp_ns: i64, clusters: &[Cluster]) -> Option<PersonEstimate> {
        let accel_var = self.config.accel_std_mps2.powi(2);
        for track in &mut self.tracks {
            let dt = (stamp_ns - track.stamp_ns) as f64 * 1e-9;
            if dt > 0.0 {
                track.x.predict(dt, accel_var);
                track.y.predict(dt, accel_var);
                track.stamp_ns = stamp_ns;
            }
            track.points.clear();
        }
        self.taken.clear();
        self.taken.resize(clusters.len(), false);

        // The person first, then confirmed tracks by seniority, then tentative ones.
        let mut order: Vec<usize> = (0..self.tracks.len()).collect();
        let person = self.person;
        order.sort_by_key(|&i| {
            let t = &self.tracks[i];
            (
                Some(t.id) != person,
                !t.confirmed,
                std::cmp::Reverse(t.hits),
                t.id,
            )
        });
        let mut assigned: Vec<Option<DVec2>> = vec![None; self.tracks.len()];
        for &i in &order {
            let track = &self.tracks[i];
            let predicted = track.position();
            let gate = track.gate(stamp_ns, &self.config);
            let nearest = clusters
                .iter()
                .enumerate()
                .filter(|(c, _)| !self.taken[*c])
                .map(|(c, cl)| (c, cl.centroid.distance(predicted)))
                .filter(|&(_, d)| d <= gate)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let Some((c, _)) = nearest else { continue };
            self.taken[c] = true;
            let mut points = clusters[c].points.clone();
            // Cluster centroids, weighted by their points, keep the localiser's centroid
            // offset (the points themselves are where the Lidar saw them).
            let mut weighted = clusters[c].centroid * clusters[c].points.len() as f64;
            if Some(track.id) == person {
                for (other, cl) in clusters.iter().enumerate() {
                    if !self.taken[other]
                        && cl.centroid.distance(clusters[c].centroid) <= self.config.part_merge_m
                    {
                        self.taken[other] = true;
                        points.extend_from_slice(&cl.points);
                        weighted += cl.centroid * cl.points.len() as f64;
                    }
                }
            }
            assigned[i] = Some(weighted / points.len().max(1) as f64);
            self.tracks[i].points = points;
        }

        let meas_var = self.config.measurement_std_m.powi(2);
        let max_speed = self.config.max_speed_mps;
        for (track, z) in self.tracks.iter_mut().zip(&assigned) {
            match z {
                Some(z) => {
                    track.x.update(z.x, meas_var);
                    track.y.update(z.y, meas_var);
                    let v = DVec2::new(track.x.vel, track.y.vel);
                    if v.length() > max_speed {
                        let v = v.normalize() * max_speed;
                        (track.x.vel, track.y.vel) = (v.x, v.y);
                    }
                    track.hits += 1;
                    track.misses_in_a_row = 0;
                    track.last_seen_ns = stamp_ns;
                    if !track.confirmed && track.hits >= self.config.confirm_hits {
                        track.confirmed = true;
                        self.confirmed_total += 1;
                    }
                }
                None => track.misses_in_a_row += 1,
            }
        }
        let config = &self.config;
        self.tracks.retain(|t| {
            if t.confirmed {
                t.unseen_s(stamp_ns) <= config.max_coast_s
            } else {
                t.misses_in_a_row <= config.tentative_max_misses
            }
        });

        // Unassigned clusters start tentative tracks, except pieces near the person.
        let person_pos = self.person_track().map(|t| t.position());
        let pos_var = meas_var;
        let vel_var = self.config.initial_velocity_std_mps.powi(2);
        for (c, cl) in clusters.iter().enumerate() {
            if self.taken[c]
                || person_pos.is_some_and(|p| p.distance(cl.centroid) <= self.config.gate_m)
            {
                continue;
            }
            let id = self.next_id;
            self.next_id += 1;
            self.tracks.push(Track {
                id,
                x: AxisFilter::new(cl.centroid.x, pos_var, vel_var),
                y: AxisFilter::new(cl.centroid.y, pos_var, vel_var),
                stamp_ns,
                last_seen_ns: stamp_ns,
                hits: 1,
                misses_in_a_row: 0,
                confirmed: self.config.confirm_hits <= 1,
                points: cl.points.clone(),
            });
            if self.config.confirm_hits <= 1 {
                self.confirmed_total += 1;
            }
        }

        if self.person_track().is_none() {
            self.person = self
                .tracks
                .iter()
                .filter(|t| t.confirmed && t.last_seen_ns == stamp_ns)
                .max_by_key(|t| (t.hits, std::cmp::Reverse(t.id)))
                .map(|t| t.id);
        }
        // Tracks that sit on the person are pieces of them, not someone else.
        if let Some(p) = self.person_track().map(|t| t.position()) {
            let (person, merge) = (self.person, self.config.part_merge_m);
            self.tracks
                .retain(|t| Some(t.id) == person || t.position().distance(p) > merge);
        }
        self.person_track().map(|t| PersonEstimate {
            track_id: t.id,
            position: t.position(),
            velocity: DVec2::new(t.x.vel, t.y.vel),
            covariance: [[t.x.cov[0][0], 0.0], [0.0, t.y.cov[0][0]]],
            visible: t.last_seen_ns == stamp_ns,
            points: t.points.clone(),
            unseen_s: t.unseen_s(stamp_ns),
        })
    }

    /// Where the person's track expects them at `stamp_ns` (not before its last update), and
    /// the radius of its gate there; `None` when no person is tracked.
    pub fn person_prediction(&self, stamp_ns: i64) -> Option<(DVec2, f64)> {
        let track = self.person_track()?;
        let dt = ((stamp_ns - track.stamp_ns) as f64 * 1e-9).max(0.0);
        let velocity = DVec2::new(track.x.vel, track.y.vel);
        Some((
            track.position() + velocity * dt,
            track.gate(stamp_ns, &self.config),
        ))
    }

    fn person_track(&self) -> Option<&Track> {
        self.person
            .and_then(|id| self.tracks.iter().find(|t| t.id == id))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD_NS: i64 = 50_000_000;

    fn blob(center: DVec2) -> Cluster {
        let points: Vec<DVec2> = (0..6)
            .map(|i| center + 0.1 * DVec2::from_angle(i as f64))
            .collect();
        let centroid = points.iter().copied().sum::<DVec2>() / 6.0;
        Cluster {
            centroid,
            points,
            extent_m: 0.2,
        }
    }

    #[test]
    fn a_walking_person_is_confirmed_and_followed_with_their_velocity() {
        let mut tracker = Tracker::new(TrackerConfig::default());
        let mut last = None;
        for k in 0..40 {
            let p = DVec2::new(0.05 * k as f64, 1.0); // 1 m/s along x
            last = tracker.update(k * PERIOD_NS, &[blob(p)]);
            if k < 2 {
                assert!(last.is_none(), "not confirmed before 3 hits");
            }
        }
        let est = last.expect("tracked");
        assert!(est.visible);
        assert!(
            (est.velocity - DVec2::new(1.0, 0.0)).length() < 0.1,
            "{:?}",
            est.velocity
        );
        assert!(est.covariance[0][0] > 0.0 && est.covariance[0][0] < 0.01);
        assert_eq!(est.points.len(), 6);
    }

    #[test]
    fn an_occlusion_is_bridged_by_prediction_and_the_person_reacquired() {
        let mut tracker = Tracker::new(TrackerConfig::default());
        let pos = |k: i64| DVec2::new(0.05 * k as f64, 0.0);
        let mut id = None;
        for k in 0..20 {
            id = tracker
                .update(k * PERIOD_NS, &[blob(pos(k))])
                .map(|e| e.track_id);
        }
        // Hidden for 1 s (20 scans) while walking on.
        for k in 20..40 {
            let est = tracker.update(k * PERIOD_NS, &[]).expect("coasting");
            assert!(!est.visible);
            assert!(est.points.is_empty());
            assert!(
                (est.position - pos(k)).length() < 0.3,
                "prediction drifted: {:?} vs {:?}",
                est.position,
                pos(k)
            );
        }
        let est = tracker
            .update(40 * PERIOD_NS, &[blob(pos(40))])
            .expect("reacquired");
        assert!(est.visible);
        assert_eq!(Some(est.track_id), id, "same track after the occlusion");
    }

    #[test]
    fn transient_clutter_never_becomes_the_person() {
        let mut tracker = Tracker::new(TrackerConfig::default());
        let person = DVec2::new(1.0, 1.0);
        for k in 0..30 {
            // A stray blob at a different random-ish place every second scan.
            let mut clusters = vec![blob(person)];
            if k % 2 == 0 {
                clusters.push(blob(DVec2::new(-8.0 + 1.1 * k as f64, -1.5)));
            }
            let est = tracker.update(k * PERIOD_NS, &clusters);
            if let Some(est) = est {
                assert!((est.position - person).length() < 0.1);
            }
        }
        assert_eq!(tracker.confirmed_total(), 1);
    }

    #[test]
    fn a_lost_person_is_replaced_by_a_new_confirmed_track() {
        let config = TrackerConfig::default();
        let mut tracker = Tracker::new(config.clone());
        for k in 0..10 {
            tracker.update(k * PERIOD_NS, &[blob(DVec2::ZERO)]);
        }
        let first = tracker
            .update(10 * PERIOD_NS, &[blob(DVec2::ZERO)])
            .unwrap()
            .track_id;
        // Gone for longer than max_coast_s, then someone appears far away.
        let far = DVec2::new(5.0, 5.0);
        let mut last = None;
        let start = 11 + (config.max_coast_s * 20.0) as i64 + 1;
        for k in 11..start + 5 {
            let clusters = if k >= start { vec![blob(far)] } else { vec![] };
            last = tracker.update(k * PERIOD_NS, &clusters);
        }
        let est = last.expect("new person");
        assert_ne!(est.track_id, first);
        assert!((est.position - far).length() < 0.1);
    }

    #[test]
    fn a_second_part_of_the_person_joins_their_points() {
        let mut tracker = Tracker::new(TrackerConfig::default());
        let mut est = None;
        for k in 0..5 {
            est = tracker.update(
                k * PERIOD_NS,
                &[blob(DVec2::ZERO), blob(DVec2::new(0.45, 0.0))],
            );
        }
        let est = est.unwrap();
        assert_eq!(est.points.len(), 12);
        assert_eq!(
            tracker.live_tracks(),
            1,
            "no ghost track from the second part"
        );
    }
}
