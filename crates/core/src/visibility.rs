//! What a scan says about where an unseen person cannot be: the Lidar's beams pass through
//! the free space in front of their returns, so a person predicted there would have been
//! seen. A hidden person is somewhere the beams do not reach: behind an obstacle, in its
//! shadow ("negative information" in tracking).

use std::f64::consts::TAU;

use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::geometry::{Pose2, normalize_angle};
use crate::map::OccupancyMap;
use crate::scan::Scan;
use crate::sweep::Sweep;

/// How a hidden person is kept out of the space the scan saw through.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShadowConfig {
    /// Whether a hidden person predicted where the scan saw through is moved into the
    /// nearest shadow, and one predicted into a mapped obstacle stopped before it (with a map
    /// only: the map says where a body fits).
    pub enabled: bool,
    /// Half the width of a body at the scan plane (m): a person there blocks every beam
    /// within this distance of their centre, and stands this far behind what hides them.
    pub body_radius_m: f64,
    /// A beam passes a person only when it returns at least this much beyond them (m): range
    /// noise and a body's depth.
    pub pass_margin_m: f64,
    /// How far from the prediction a hidden place is looked for (m); none nearer: the
    /// prediction stands.
    pub search_m: f64,
    /// Least clearance from mapped obstacles of a hidden place, and of a hidden person's
    /// prediction: closer, the person stops where the track was a scan before (m).
    pub min_clearance_m: f64,
}

impl Default for ShadowConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            body_radius_m: 0.10,
            pass_margin_m: 0.3,
            search_m: 1.0,
            min_clearance_m: 0.1,
        }
    }
}

/// The beams of one scan, placed in the map frame, asked whether a body could hide somewhere.
pub struct ScanView<'a> {
    scan: &'a Scan,
    /// Where the Lidar was at each beam.
    sweep: Sweep,
}

impl<'a> ScanView<'a> {
    /// Every beam measured from `laser`.
    pub fn new(scan: &'a Scan, laser: Pose2) -> Self {
        Self::sweeping(scan, laser, laser)
    }

    /// Beam 0 measured from `first`, the last beam from `last`, those between from poses in
    /// between, as the localiser placed them ([`crate::sweep::BeamPoses`]).
    pub fn sweeping(scan: &'a Scan, first: Pose2, last: Pose2) -> Self {
        let sweep = Sweep::new(first, last, scan.ranges.len());
        Self { scan, sweep }
    }

    /// Whether every beam across a body centred at `p` (map frame) returned well beyond it:
    /// the scan saw through the place, so nobody stands there. A beam without a return, or
    /// a place outside the scan's field of view, says nothing.
    pub fn sees_through(&self, p: DVec2, config: &ShadowConfig) -> bool {
        self.polar(p, config.body_radius_m)
            .is_some_and(|(distance, bearing)| self.sees_through_at(distance, bearing, config))
    }

    /// [`Self::sees_through`] for a place given by its distance and bearing from the Lidar.
    fn sees_through_at(&self, distance: f64, bearing: f64, config: &ShadowConfig) -> bool {
        let half_width = (config.body_radius_m / distance).asin();
        let mut beams = self
            .beams_between(bearing - half_width, bearing + half_width)
            .peekable();
        beams.peek().is_some()
            && beams.all(|beam| {
                let range = self.scan.ranges[beam];
                self.scan.is_return(range) && f64::from(range) > distance + config.pass_margin_m
            })
    }

    /// The place nearest `p` within `config.search_m` that this scan does not see through,
    /// `body_radius_m` behind a return and at least `min_clearance_m` from mapped obstacles;
    /// `None` when `p` is not seen through or no such place is near.
    pub fn nearest_hidden(
        &self,
        p: DVec2,
        map: &OccupancyMap,
        config: &ShadowConfig,
    ) -> Option<DVec2> {
        let (distance, bearing) = self.polar(p, config.body_radius_m)?;
        if !self.sees_through_at(distance, bearing, config) {
            return None;
        }
        let half_width = (config.search_m / distance).min(1.0).asin();
        let mut best: Option<(f64, DVec2)> = None;
        for beam in self.beams_between(bearing - half_width, bearing + half_width) {
            let range = self.scan.ranges[beam];
            if !self.scan.is_return(range) {
                continue;
            }
            let sensor = self.sweep.position_at(beam as f64);
            let direction =
                DVec2::from_angle(self.scan.beam_angle(beam) + self.sweep.heading_at(beam as f64));
            // Along this beam, the point nearest `p` with a body behind the return ...
            let along = (p - sensor).dot(direction);
            let mut reach = along.max(f64::from(range) + config.body_radius_m);
            // ... and clear of what is mapped behind it (the far side of a sofa).
            let mut place = None;
            while reach - along <= config.search_m {
                let q = sensor + direction * reach;
                match map.free_clearance(q).map(f64::from) {
                    Some(c) if c >= config.min_clearance_m => {
                        place = Some(q);
                        break;
                    }
                    Some(c) => reach += (config.min_clearance_m - c).max(0.02),
                    None => reach += 0.05,
                }
            }
            let Some(q) = place else { continue };
            let off = q.distance(p);
            if off <= config.search_m
                && best.is_none_or(|(d, _)| off < d)
                && !self.sees_through(q, config)
            {
                best = Some((off, q));
            }
        }
        best.map(|(_, q)| q)
    }

    /// Distance and bearing (map frame) of `p` from the Lidar (where it was halfway through
    /// the scan); `None` within `min_distance` of it (or for a non-finite `p`), where a
    /// bearing means little.
    fn polar(&self, p: DVec2, min_distance: f64) -> Option<(f64, f64)> {
        let middle = self.scan.ranges.len().saturating_sub(1) as f64 / 2.0;
        let offset = p - self.sweep.position_at(middle);
        let distance = offset.length();
        (distance > min_distance).then(|| (distance, offset.y.atan2(offset.x)))
    }

    /// The beams pointing between `from` and `to` (radians, map frame, `from <= to`) that
    /// the scan has, across its seam where it wraps around; empty when none.
    fn beams_between(&self, from: f64, to: f64) -> impl Iterator<Item = usize> {
        // Beam `k` points at `first_direction + k * spacing` in the map: the beam spacing plus
        // the Lidar's own turn from one beam to the next.
        let increment = f64::from(self.scan.angle_increment);
        let spacing = increment + self.sweep.turn_per_beam();
        let heading = self.sweep.first().theta;
        let first_direction = heading + self.scan.beam_angle(0);
        let beams = self.scan.ranges.len() as i64;
        let usable = spacing.is_finite() && spacing != 0.0 && beams > 0 && from <= to;
        // Beam indices per turn of the map. A scan taken while turning does not close on
        // itself: past its last beam its seam leaves a gap (indices with no beam) or
        // overlaps its first beams.
        let per_turn = if usable {
            (TAU / spacing.abs()).round().max(1.0) as i64
        } else {
            1
        };
        // Walk from whichever end of the interval the beams' order starts at.
        let start = if spacing > 0.0 { from } else { to };
        let relative = normalize_angle(start - heading - self.scan.beam_angle(0));
        let first = (relative / spacing).round() as i64;
        let count = if usable {
            (((to - from) / spacing.abs()).round() as i64)
                .saturating_add(1)
                .min(per_turn)
        } else {
            0
        };
        // A beam across the seam of a turning scan may point elsewhere: keep those that
        // point into the interval (widened by a beam).
        let (middle, reach) = ((from + to) / 2.0, (to - from) / 2.0 + spacing.abs());
        let points_into = move |b: i64| {
            normalize_angle(first_direction + b as f64 * spacing - middle).abs() <= reach
        };
        (0..count)
            .map(move |k| first.saturating_add(k).rem_euclid(per_turn))
            .filter(move |&b| b < beams && points_into(b))
            .map(|b| b as usize)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::map::MapGeometry;

    /// A 10 m x 10 m room at 5 cm, origin (0, 0), walls on its border and a sofa filling
    /// x 3.0-3.5, y 4.0-6.0.
    fn room_with_sofa() -> OccupancyMap {
        let n = 200;
        let occupied = (0..n * n)
            .map(|i| {
                let (col, row) = (i % n, i / n);
                let border = col == 0 || col == n - 1 || row == 0 || row == n - 1;
                let sofa = (60..70).contains(&col) && (80..120).contains(&row);
                border || sofa
            })
            .collect();
        let geometry = MapGeometry {
            resolution: 0.05,
            origin: Pose2::IDENTITY,
            width: n,
            height: n,
        };
        OccupancyMap::new(geometry, occupied).unwrap()
    }

    /// A 720-beam scan of `map` from `laser`, first beam at `angle_min`, with a round person
    /// (centre, radius) in it: each beam's range is where it first enters an occupied cell or
    /// the person.
    pub(crate) fn cast(
        map: &OccupancyMap,
        laser: Pose2,
        angle_min: f32,
        person: Option<(DVec2, f64)>,
    ) -> Scan {
        cast_sweeping(map, laser, laser, angle_min, person)
    }

    /// [`cast`] from a Lidar that moves from `first` at beam 0 to `last` at the last beam.
    fn cast_sweeping(
        map: &OccupancyMap,
        first: Pose2,
        last: Pose2,
        angle_min: f32,
        person: Option<(DVec2, f64)>,
    ) -> Scan {
        let n = 720;
        let increment = std::f64::consts::TAU / n as f64;
        let ranges = (0..n)
            .map(|i| {
                let laser = first.lerp(&last, i as f64 / (n - 1) as f64);
                let angle = laser.theta + f64::from(angle_min) + i as f64 * increment;
                let direction = DVec2::from_angle(angle);
                let mut range = 0.0;
                // Sphere tracing: a step as long as the clearance cannot cross an obstacle.
                while let Some(clearance) = map.free_clearance(laser.position() + direction * range)
                {
                    range += (f64::from(clearance) - 0.05).max(0.01);
                }
                if let Some((centre, radius)) = person {
                    let to_centre = centre - laser.position();
                    let along = to_centre.dot(direction);
                    let miss2 = to_centre.length_squared() - along * along;
                    if along > 0.0 && miss2 <= radius * radius {
                        range = range.min(along - (radius * radius - miss2).sqrt());
                    }
                }
                range as f32
            })
            .collect();
        Scan {
            stamp_ns: 0,
            angle_min,
            angle_increment: increment as f32,
            time_increment: 0.0,
            range_min: 0.05,
            range_max: 12.0,
            ranges,
        }
    }

    const LASER: Pose2 = Pose2::new(1.0, 5.0, 0.4);

    #[test]
    fn open_floor_in_view_is_seen_through_and_the_space_behind_furniture_is_not() {
        let map = room_with_sofa();
        let config = ShadowConfig::default();
        for angle_min in [-std::f32::consts::PI, 0.0] {
            let scan = cast(&map, LASER, angle_min, None);
            let view = ScanView::new(&scan, LASER);
            assert!(view.sees_through(DVec2::new(5.0, 8.0), &config));
            assert!(view.sees_through(DVec2::new(2.0, 2.0), &config));
            // Behind the sofa, just in front of it (the sofa returns within pass_margin_m of it), beside the
            // wall; farther in front of it, the open floor.
            assert!(!view.sees_through(DVec2::new(5.0, 5.0), &config));
            assert!(!view.sees_through(DVec2::new(2.8, 5.0), &config));
            assert!(view.sees_through(DVec2::new(2.4, 5.0), &config));
            assert!(!view.sees_through(DVec2::new(9.8, 5.0), &config));
        }
    }

    #[test]
    fn a_seen_through_prediction_moves_to_the_nearest_place_behind_the_sofa() {
        let map = room_with_sofa();
        let config = ShadowConfig::default();
        let scan = cast(&map, LASER, -std::f32::consts::PI, None);
        let view = ScanView::new(&scan, LASER);
        // The shadow's upper edge is the ray through the sofa's corner (3, 6): slope 1/2.
        let predicted = DVec2::new(5.0, 7.3);
        let hidden = view.nearest_hidden(predicted, &map, &config).unwrap();
        assert!(!view.sees_through(hidden, &config), "{hidden}");
        assert!(hidden.x > 3.5 && hidden.y < 7.3, "{hidden}");
        let beyond_edge = (hidden.y - 5.0) - 0.5 * (hidden.x - 1.0);
        assert!(beyond_edge < 0.0, "not in the shadow: {hidden}");
        assert!(hidden.distance(predicted) < 0.6, "{hidden}");
        // Hidden already: nothing to move; no shadow within reach: the prediction stands.
        assert_eq!(
            view.nearest_hidden(DVec2::new(5.0, 5.0), &map, &config),
            None
        );
        assert_eq!(
            view.nearest_hidden(DVec2::new(5.0, 1.5), &map, &config),
            None
        );
    }

    #[test]
    fn a_sweeping_scan_is_read_from_where_each_beam_was_measured() {
        let map = room_with_sofa();
        let config = ShadowConfig::default();
        // A 5 Hz rotation while turning on the spot at 90 degrees per second.
        let last = Pose2::new(LASER.x, LASER.y, LASER.theta + 0.31);
        let places: Vec<DVec2> = (1..40)
            .flat_map(|i| (1..40).map(move |j| DVec2::new(i as f64, j as f64) * 0.25))
            .collect();
        for angle_min in [-std::f32::consts::PI, 0.0] {
            let still = cast(&map, LASER, angle_min, None);
            let truth = ScanView::new(&still, LASER);
            let swept = cast_sweeping(&map, LASER, last, angle_min, None);
            let differ = |view: &ScanView| {
                places
                    .iter()
                    .filter(|&&p| view.sees_through(p, &config) != truth.sees_through(p, &config))
                    .count()
            };
            // Only places at the edges of the shadows differ: the turn spreads the beams apart.
            let read_as_swept = differ(&ScanView::sweeping(&swept, LASER, last));
            assert!(read_as_swept <= 30, "{read_as_swept} of {}", places.len());
            let read_from_beam_zero = differ(&ScanView::new(&swept, LASER));
            assert!(read_from_beam_zero > 150, "{read_from_beam_zero}");
            let hidden = ScanView::sweeping(&swept, LASER, last)
                .nearest_hidden(DVec2::new(5.0, 7.3), &map, &config)
                .unwrap();
            assert!(!truth.sees_through(hidden, &config), "{hidden}");
        }
    }

    #[test]
    fn the_gap_a_turn_leaves_at_the_seam_says_nothing() {
        let map = room_with_sofa();
        let config = ShadowConfig::default();
        // Turning clockwise at 3 rad/s through a 5 Hz rotation while the beams go
        // anticlockwise: the last beam (2.93 rad) stops 0.6 rad short of the first, which
        // points at 0.4 - pi (-2.74 rad).
        let last = Pose2::new(LASER.x, LASER.y, LASER.theta - 0.6);
        let swept = cast_sweeping(&map, LASER, last, -std::f32::consts::PI, None);
        let view = ScanView::sweeping(&swept, LASER, last);
        let still = cast(&map, LASER, -std::f32::consts::PI, None);
        let truth = ScanView::new(&still, LASER);
        let at = |bearing: f64| LASER.position() + DVec2::from_angle(bearing) * 0.6;
        for bearing in [-3.04, -2.6, 2.7] {
            assert!(truth.sees_through(at(bearing), &config), "{bearing}");
        }
        // Open floor in the gap: nobody looked there. Either side of it, the beams did.
        assert!(!view.sees_through(at(-3.04), &config));
        assert!(view.sees_through(at(-2.6), &config));
        assert!(view.sees_through(at(2.7), &config));
    }

    #[test]
    fn beams_without_returns_and_unseen_directions_say_nothing() {
        let map = room_with_sofa();
        let config = ShadowConfig::default();
        let mut scan = cast(&map, LASER, -std::f32::consts::PI, None);
        let open = DVec2::new(5.0, 8.0);
        for range in scan.ranges.iter_mut() {
            *range = f32::NAN;
        }
        assert!(!ScanView::new(&scan, LASER).sees_through(open, &config));
        // A 90-degree scan looking away from the place.
        let mut narrow = cast(&map, LASER, -std::f32::consts::PI, None);
        narrow.ranges.truncate(180);
        assert!(!ScanView::new(&narrow, LASER).sees_through(open, &config));
        assert!(!ScanView::new(&Scan::default(), LASER).sees_through(open, &config));
    }
}
