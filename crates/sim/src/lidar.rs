//! The Lidar: exact beam intersections with walls, furniture and the body's capsules, then
//! the noise model.
//!
//! Broad phase: instead of testing every beam against every object, each object is
//! "painted" onto the beams inside its angular extent as seen from the Lidar (a z-buffer over
//! beam indices). Walls cover the circle once between them and small objects a few beams, so
//! a scan costs about one exact test per beam per overlapping object.

use std::f64::consts::{PI, TAU};
use std::ops::Range;

use glam::{DVec2, DVec3};
use lidar_har_core::geometry::Pose2;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::body::Capsule;
use crate::scene::{LidarSpec, NoiseSpec};
use crate::shapes::{SegmentFromOrigin, point_segment_dist, ray_capsule, ray_circle};
use crate::world::{BeamLabel, World};

/// Beam geometry of one rotation, as LaserScan states it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanGeometry {
    pub beams: usize,
    pub angle_min: f64,
    pub angle_increment: f64,
    pub range_min: f64,
    pub range_max: f64,
    /// Seconds per rotation.
    pub scan_time: f64,
    /// Seconds from one beam's measurement to the next's (LaserScan's `time_increment`):
    /// `-scan_time / beams` for a Lidar that sweeps (`lidar.sweep`: beam 0 is measured last,
    /// at the stamp, as by the RPLIDAR driver), 0 for a scan taken at one instant.
    pub time_increment: f64,
}

impl ScanGeometry {
    pub fn new(spec: &LidarSpec) -> Self {
        let beams = spec.beams as usize;
        Self {
            beams,
            angle_min: -PI,
            angle_increment: TAU / beams as f64,
            range_min: spec.range_min,
            range_max: spec.range_max,
            scan_time: 1.0 / spec.rate_hz,
            time_increment: if spec.sweep {
                -1.0 / (spec.rate_hz * beams as f64)
            } else {
                0.0
            },
        }
    }

    /// Unit direction of beam `i` in the map for a Lidar heading `heading`, computed exactly
    /// as the caster does (the nominal direction, without angle error).
    pub fn direction(&self, heading: f64, i: usize) -> DVec2 {
        DVec2::from_angle(heading).rotate(DVec2::from_angle(
            self.angle_min + self.angle_increment * i as f64,
        ))
    }

    /// Angle of the last beam (LaserScan's `angle_max`).
    pub fn angle_max(&self) -> f64 {
        self.angle_min + self.angle_increment * (self.beams as f64 - 1.0)
    }
}

/// Casts scans; keeps its buffers between scans.
#[derive(Debug, Clone)]
pub struct Lidar {
    pub geometry: ScanGeometry,
    pub noise: NoiseSpec,
    /// Beam directions in the Lidar's frame.
    local_dirs: Vec<DVec2>,
    /// The same bent by this scan's angle errors.
    bent_dirs: Vec<DVec2>,
    /// Beam directions in the map.
    dirs: Vec<DVec2>,
    /// The beams being cast: all of them, or one sector of a sweeping Lidar's rotation.
    window: Range<usize>,
    exact: Vec<f64>,
    hit: Vec<BeamLabel>,
    margin: i64,
    /// Segments by distance from the Lidar, nearest first (kept to reuse its allocation).
    segment_order: Vec<(f64, usize)>,
}

/// A sweeping Lidar's rotation is cast in this many sectors, each from the Lidar's pose at
/// its middle beam's time: turning at 90 degrees per second with 20 scans a second, a
/// sector's beams are then at most 1.1 mrad (3 mm at 3 m) from where the Lidar truly was.
pub const SWEEP_SECTORS: usize = 36;

/// Beam directions are bent by the angle error; drawn errors are cut at 4 sigma so that the
/// painting margin below is a strict bound.
const ANGLE_SIGMA_CUT: f64 = 4.0;

impl Lidar {
    pub fn new(spec: &LidarSpec) -> Self {
        let geometry = ScanGeometry::new(spec);
        let local_dirs: Vec<DVec2> = (0..geometry.beams)
            .map(|i| DVec2::from_angle(geometry.angle_min + geometry.angle_increment * i as f64))
            .collect();
        let noise = spec.noise;
        let angle_bound = ANGLE_SIGMA_CUT * noise.angle_deg.to_radians();
        let margin = 1 + (angle_bound / geometry.angle_increment).ceil() as i64;
        let n = geometry.beams;
        Self {
            geometry,
            noise,
            bent_dirs: local_dirs.clone(),
            local_dirs,
            dirs: vec![DVec2::X; n],
            window: 0..n,
            exact: vec![f64::INFINITY; n],
            hit: vec![BeamLabel::Nothing; n],
            margin,
            segment_order: Vec::new(),
        }
    }

    /// Exact distances of the last scan (before noise), for checks and tests.
    pub fn exact_ranges(&self) -> &[f64] {
        &self.exact
    }

    /// Paints `test` over the beams whose (unperturbed) angle lies in `[lo, hi]` relative to
    /// the Lidar's heading, widened by the margin. `near` is a lower bound of the object's
    /// distance: beams that already hit something nearer are not tested (objects are painted
    /// nearest first, so most far ones cost a comparison per beam).
    fn paint(
        &mut self,
        lo: f64,
        hi: f64,
        near: f64,
        label: BeamLabel,
        test: impl Fn(DVec2) -> Option<f64>,
    ) {
        let g = &self.geometry;
        let n = g.beams as i64;
        let k_lo = ((lo - g.angle_min) / g.angle_increment).floor() as i64 - self.margin;
        let k_hi = ((hi - g.angle_min) / g.angle_increment).ceil() as i64 + self.margin;
        let k_hi = k_hi.min(k_lo + n - 1);
        // The beam range may wrap around the scan's start: paint it as two plain ranges,
        // each kept inside the window.
        let first = k_lo.rem_euclid(n);
        let count = k_hi - k_lo + 1;
        let end = first + count;
        let (w_lo, w_hi) = (self.window.start as i64, self.window.end as i64);
        let clip =
            |lo: i64, hi: i64| lo.max(w_lo) as usize..hi.min(w_hi).max(lo.max(w_lo)) as usize;
        let (head, tail) = (clip(first, end.min(n)), clip(0, (end - n).max(0)));
        for i in head.chain(tail) {
            if self.exact[i] <= near {
                continue;
            }
            if let Some(t) = test(self.dirs[i])
                && t < self.exact[i]
            {
                self.exact[i] = t;
                self.hit[i] = label;
            }
        }
    }

    fn paint_all(&mut self, label: BeamLabel, test: impl Fn(DVec2) -> Option<f64>) {
        let (lo, hi) = (self.geometry.angle_min, self.geometry.angle_min + TAU);
        self.paint(lo, hi, 0.0, label, test);
    }

    /// Angular interval (relative to `heading`) of a circle seen from `o`, or the whole
    /// circle when `o` is inside it.
    fn paint_circle(
        &mut self,
        o: DVec2,
        heading: f64,
        c: DVec2,
        r: f64,
        label: BeamLabel,
        test: impl Fn(DVec2) -> Option<f64>,
    ) {
        let v = c - o;
        let d = v.length();
        if d <= r * 1.000_001 + 1e-12 {
            self.paint_all(label, test);
        } else {
            let mid = wrap(v.to_angle() - heading);
            let half = (r / d).asin();
            self.paint(mid - half, mid + half, d - r, label, test);
        }
    }

    /// One scan from `laser` (the Lidar's pose in the map) at height `world.lidar_height`,
    /// through the room and the body `parts`. Writes ranges (+inf: no return) and labels.
    pub fn scan(
        &mut self,
        world: &World,
        laser: Pose2,
        parts: Option<&[Capsule]>,
        rng: Option<&mut ChaCha8Rng>,
        ranges: &mut Vec<f32>,
        labels: &mut Vec<BeamLabel>,
    ) {
        self.scan_moving(world, |_| (laser, parts), rng, ranges, labels);
    }

    /// Like [`Lidar::scan`] with the Lidar and the body moving: `at(s)` gives the Lidar's
    /// pose and the body's parts `s` seconds after beam 0 was measured. A Lidar that sweeps
    /// (`time_increment` != 0) casts each of [`SWEEP_SECTORS`] sectors as they are at its
    /// middle beam's time; otherwise every beam is cast as they are at 0.
    pub fn scan_moving<B: AsRef<[Capsule]>>(
        &mut self,
        world: &World,
        mut at: impl FnMut(f64) -> (Pose2, Option<B>),
        rng: Option<&mut ChaCha8Rng>,
        ranges: &mut Vec<f32>,
        labels: &mut Vec<BeamLabel>,
    ) {
        let n = self.geometry.beams;
        let angle_sigma = self.noise.angle_deg.to_radians();
        let mut rng = rng.filter(|_| !self.noise.is_none());
        match rng.as_deref_mut() {
            Some(r) if angle_sigma > 0.0 => {
                let cut = ANGLE_SIGMA_CUT * angle_sigma;
                for (bent, local) in self.bent_dirs.iter_mut().zip(&self.local_dirs) {
                    let z: f64 = StandardNormal.sample(r);
                    let delta = (z * angle_sigma).clamp(-cut, cut);
                    *bent = small_rotation(delta).rotate(*local);
                }
            }
            _ => self.bent_dirs.copy_from_slice(&self.local_dirs),
        }
        let dt = self.geometry.time_increment;
        let sectors = if dt != 0.0 { SWEEP_SECTORS.min(n) } else { 1 };
        for sector in 0..sectors {
            let beams = sector * n / sectors..(sector + 1) * n / sectors;
            let middle = (beams.start + beams.end - 1) as f64 / 2.0;
            let (laser, parts) = at(middle * dt);
            self.cast(world, laser, parts.as_ref().map(AsRef::as_ref), beams);
        }
        self.window = 0..n;
        self.add_noise(rng, ranges, labels);
    }

    /// Casts the `beams` from `laser`: exact distances and what they hit.
    fn cast(
        &mut self,
        world: &World,
        laser: Pose2,
        parts: Option<&[Capsule]>,
        beams: Range<usize>,
    ) {
        let rot = DVec2::from_angle(laser.theta);
        for i in beams.clone() {
            self.dirs[i] = rot.rotate(self.bent_dirs[i]);
        }
        self.exact[beams.clone()].fill(f64::INFINITY);
        self.hit[beams.clone()].fill(BeamLabel::Nothing);
        self.window = beams;

        let o = laser.position();
        for c in &world.circles {
            let (center, radius) = (c.center, c.radius);
            self.paint_circle(o, laser.theta, center, radius, BeamLabel::Furniture, |d| {
                ray_circle(o, d, center, radius)
            });
        }
        if let Some(parts) = parts {
            let h = world.lidar_height;
            let o3 = o.extend(h);
            for part in parts {
                let Some((center, radius)) = part.section_bound(h) else {
                    continue;
                };
                let Capsule { a, b, radius: r } = *part;
                self.paint_circle(o, laser.theta, center, radius, BeamLabel::Person, |d| {
                    ray_capsule(o3, DVec3::new(d.x, d.y, 0.0), a, b, r)
                });
            }
        }
        let mut order = std::mem::take(&mut self.segment_order);
        order.clear();
        order.extend(
            world
                .segments
                .iter()
                .enumerate()
                .map(|(k, s)| (point_segment_dist(o, s.a, s.b), k)),
        );
        order.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
        for &(near, k) in &order {
            let s = &world.segments[k];
            let (a, b) = (s.a, s.b);
            let seg = SegmentFromOrigin::new(o, a, b);
            if near < 1e-12 {
                self.paint_all(s.label, |d| seg.hit(d));
                continue;
            }
            let ra = wrap((a - o).to_angle() - laser.theta);
            let delta = wrap((b - o).to_angle() - (a - o).to_angle());
            let (lo, hi) = if delta >= 0.0 {
                (ra, ra + delta)
            } else {
                (ra + delta, ra)
            };
            self.paint(lo, hi, near, s.label, |d| seg.hit(d));
        }
        self.segment_order = order;
    }

    /// The measured ranges and labels: the exact distances with the noise model applied.
    fn add_noise(
        &mut self,
        rng: Option<&mut ChaCha8Rng>,
        ranges: &mut Vec<f32>,
        labels: &mut Vec<BeamLabel>,
    ) {
        let n = self.geometry.beams;
        ranges.clear();
        labels.clear();
        let g = self.geometry;
        let valid = |r: f64| r >= g.range_min && r <= g.range_max;
        let Some(rng) = rng else {
            for (&r, &hit) in self.exact.iter().zip(&self.hit) {
                ranges.push(if valid(r) { r as f32 } else { f32::INFINITY });
                labels.push(if valid(r) { hit } else { BeamLabel::Nothing });
            }
            return;
        };
        // Missing and wrong returns are rare: draw the gap to the next such beam (geometric
        // distribution) instead of a uniform number for every beam.
        let missing = self.noise.missing_pct / 100.0;
        let event = (missing + self.noise.wrong_pct / 100.0).min(1.0);
        // ln(1 - event) without rounding 1 - event: for event under about 1e-16 that is 1,
        // whose logarithm 0 made every beam an event.
        let ln_keep = (-event).ln_1p();
        let gap = |rng: &mut ChaCha8Rng| -> usize {
            if event <= 0.0 {
                return usize::MAX;
            }
            let u: f64 = rng.random();
            // Both logarithms are <= 0; `as` saturates (and maps -0 to 0).
            ((1.0 - u).ln() / ln_keep) as usize
        };
        let sigma = self.noise.distance_pct / 100.0;
        let spread = (self.noise.wrong_spread_deg.to_radians() / g.angle_increment).round() as i64;
        let mut next_event = gap(rng);
        for i in 0..n {
            let (mut r, label) = if i == next_event {
                next_event = i.saturating_add(1).saturating_add(gap(rng));
                let u: f64 = rng.random();
                if u * event < missing {
                    (f64::INFINITY, BeamLabel::Missing)
                } else {
                    // Multipath: the return of a point at another angle, reported at this one.
                    let k = if spread > 0 {
                        rng.random_range(-spread..=spread)
                    } else {
                        0
                    };
                    let j = (i as i64 + k).rem_euclid(n as i64) as usize;
                    (self.exact[j], BeamLabel::Wrong)
                }
            } else {
                (self.exact[i], self.hit[i])
            };
            if sigma > 0.0 && r.is_finite() {
                let z: f64 = StandardNormal.sample(rng);
                r += z * sigma * r;
            }
            if valid(r) {
                ranges.push(r as f32);
                labels.push(label);
            } else {
                ranges.push(f32::INFINITY);
                labels.push(if label == BeamLabel::Missing {
                    label
                } else {
                    BeamLabel::Nothing
                });
            }
        }
    }
}

/// Wraps into [-pi, pi).
fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// Rotation by a small angle without a trigonometric call (error below 2e-15 for the angle
/// errors used here, which stay below 0.01 rad). Multiplies by the reciprocal
/// factorials: divisions by constants are not turned into multiplications by the compiler,
/// and three divisions per beam cost as much as casting it.
fn small_rotation(delta: f64) -> DVec2 {
    const INV_2: f64 = 1.0 / 2.0;
    const INV_6: f64 = 1.0 / 6.0;
    const INV_24: f64 = 1.0 / 24.0;
    const INV_120: f64 = 1.0 / 120.0;
    if delta.abs() < 0.01 {
        let d2 = delta * delta;
        DVec2::new(
            1.0 - d2 * INV_2 + d2 * d2 * INV_24,
            delta * (1.0 - d2 * INV_6 + d2 * d2 * INV_120),
        )
    } else {
        DVec2::from_angle(delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use crate::shapes::ray_segment;
    use rand::SeedableRng;
    use std::f64::consts::FRAC_PI_2;

    fn world(extra: &str) -> (Scene, World) {
        let text = format!(
            "duration: 1\nroom: {{outline: [[-5,-5],[5,-5],[5,5],[-5,5]]}}\n{extra}robot: {{start: {{x: 0, y: 0}}}}\n"
        );
        let s = Scene::parse(&text, "t").unwrap();
        let w = World::new(&s);
        (s, w)
    }

    /// Brute force: every beam against every object, no painting.
    fn brute(w: &World, laser: Pose2, g: &ScanGeometry, parts: &[Capsule]) -> Vec<f64> {
        (0..g.beams)
            .map(|i| {
                let d = g.direction(laser.theta, i);
                let o = laser.position();
                let mut best = f64::INFINITY;
                for s in &w.segments {
                    best = best.min(ray_segment(o, d, s.a, s.b).unwrap_or(f64::INFINITY));
                }
                for c in &w.circles {
                    best = best.min(ray_circle(o, d, c.center, c.radius).unwrap_or(f64::INFINITY));
                }
                for p in parts {
                    best = best.min(
                        ray_capsule(o.extend(w.lidar_height), d.extend(0.0), p.a, p.b, p.radius)
                            .unwrap_or(f64::INFINITY),
                    );
                }
                best
            })
            .collect()
    }

    #[test]
    fn painting_matches_brute_force() {
        let (s, w) = world(
            "furniture: [{kind: box, center: [2, 1], size: [1, 0.5], yaw_deg: 30, height: 1}, {kind: table, center: [-2, 2], size: [1.2, 0.8], height: 0.75}, {kind: cylinder, center: [0, -3], radius: 0.3, height: 1}]\n",
        );
        let mut lidar = Lidar::new(&LidarSpec {
            noise: NoiseSpec::NONE,
            ..s.lidar.clone()
        });
        let parts = [Capsule {
            a: DVec3::new(1.0, -1.0, 0.1),
            b: DVec3::new(2.0, -1.5, 0.1),
            radius: 0.12,
        }];
        let (mut r, mut l) = (Vec::new(), Vec::new());
        for theta in [0.0, 0.3, -2.9, PI] {
            let laser = Pose2::new(0.1, -0.2, theta);
            lidar.scan(&w, laser, Some(&parts), None, &mut r, &mut l);
            let expect = brute(&w, laser, &lidar.geometry, &parts);
            for (i, (got, want)) in lidar.exact_ranges().iter().zip(&expect).enumerate() {
                assert_eq!(got, want, "beam {i} at heading {theta}");
            }
        }
        assert!(
            l.contains(&BeamLabel::Person)
                && l.contains(&BeamLabel::Furniture)
                && l.contains(&BeamLabel::Wall)
        );
    }

    #[test]
    fn a_sweeping_lidar_casts_each_sector_from_where_it_then_is() {
        let (s, w) = world(
            "furniture: [{kind: box, center: [2, 1], size: [1, 0.5], yaw_deg: 30, height: 1}]\n",
        );
        let spec = LidarSpec {
            noise: NoiseSpec::NONE,
            sweep: true,
            ..s.lidar.clone()
        };
        let mut lidar = Lidar::new(&spec);
        let g = lidar.geometry;
        assert_eq!(g.time_increment, -1.0 / (spec.rate_hz * g.beams as f64));
        let parts = [Capsule {
            a: DVec3::new(1.0, -1.0, 0.1),
            b: DVec3::new(2.0, -1.5, 0.1),
            radius: 0.12,
        }];
        // Driving and turning at 90 degrees per second; beam 0 is measured last.
        let laser_at = |s: f64| Pose2::new(0.1 + 0.3 * s, -0.2, 0.3 + FRAC_PI_2 * s);
        // The body walks at 1 m/s along +y.
        let body_at = |s: f64| {
            parts.map(|c| Capsule {
                a: c.a + DVec3::Y * s,
                b: c.b + DVec3::Y * s,
                ..c
            })
        };
        let (mut r, mut l) = (Vec::new(), Vec::new());
        let at = |s: f64| (laser_at(s), Some(body_at(s)));
        lidar.scan_moving(&w, at, None, &mut r, &mut l);
        let n = g.beams;
        for sector in 0..SWEEP_SECTORS {
            let beams = sector * n / SWEEP_SECTORS..(sector + 1) * n / SWEEP_SECTORS;
            let middle = (beams.start + beams.end - 1) as f64 / 2.0;
            let s = middle * g.time_increment;
            let expect = brute(&w, laser_at(s), &g, &body_at(s));
            for i in beams {
                assert_eq!(lidar.exact_ranges()[i], expect[i], "beam {i}");
            }
        }
        // From one pose the scan differs.
        let swept = lidar.exact_ranges().to_vec();
        lidar.scan(&w, laser_at(0.0), Some(&parts), None, &mut r, &mut l);
        let moved = swept
            .iter()
            .zip(lidar.exact_ranges())
            .filter(|(a, b)| a != b);
        assert!(moved.count() > n / 2);
    }

    #[test]
    fn empty_square_room_ranges_are_exact() {
        let (s, w) = world("");
        let mut lidar = Lidar::new(&LidarSpec {
            noise: NoiseSpec::NONE,
            ..s.lidar.clone()
        });
        let (mut r, mut l) = (Vec::new(), Vec::new());
        lidar.scan(&w, Pose2::IDENTITY, None, None, &mut r, &mut l);
        // Beam 360 looks along +x (angle 0), beam 0 along -x: both 5 m.
        assert_eq!(r[360], 5.0);
        assert_eq!(r[0], 5.0);
        assert!(l.iter().all(|x| *x == BeamLabel::Wall));
    }

    #[test]
    fn lidar_at_a_wall_or_inside_an_obstacle_gives_valid_ranges() {
        let (s, w) =
            world("furniture: [{kind: cylinder, center: [2, 0], radius: 0.5, height: 1}]\n");
        let mut lidar = Lidar::new(&s.lidar);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        for pose in [
            Pose2::new(5.0, 0.0, 0.0),
            Pose2::new(2.0, 0.0, 1.0),
            Pose2::new(1.5, 0.0, 0.0),
            Pose2::new(-5.0, -5.0, 0.3),
        ] {
            lidar.scan(&w, pose, None, Some(&mut rng), &mut r, &mut l);
            assert!(
                r.iter()
                    .all(|x| x.is_infinite() && *x > 0.0 || (0.15..=12.0).contains(x)),
                "{pose:?}"
            );
        }
        // Inside the cylinder everything is closer than range_min: no return at all.
        lidar.scan(&w, Pose2::new(2.0, 0.0, 1.0), None, None, &mut r, &mut l);
        assert!(r.iter().all(|x| *x == f32::INFINITY));
    }

    #[test]
    fn zero_width_gap_between_boxes_is_closed() {
        let (s, w) = world(
            "furniture: [{kind: box, center: [3, -0.5], size: [1, 1], height: 1}, {kind: box, center: [3, 0.5], size: [1, 1], height: 1}]\n",
        );
        let spec = LidarSpec {
            beams: 3600,
            noise: NoiseSpec::NONE,
            ..s.lidar.clone()
        };
        let mut lidar = Lidar::new(&spec);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        // The beam along +x goes exactly through the shared edge's line y = 0.
        lidar.scan(&w, Pose2::IDENTITY, None, None, &mut r, &mut l);
        let along = spec.beams as usize / 2;
        assert_eq!(r[along], 2.5);
        for (i, range) in r.iter().enumerate().take(along + 40).skip(along - 40) {
            assert!(*range < 2.6, "beam {i} leaked through the gap: {range}");
        }
    }

    #[test]
    fn far_ranges_become_infinite_past_range_max() {
        let text = "duration: 1\nroom: {outline: [[-50,-1],[50,-1],[50,1],[-50,1]]}\nrobot: {start: {x: 0, y: 0}}\nlidar: {range_max: 30, noise: {distance_pct: 0, missing_pct: 0, wrong_pct: 0, angle_deg: 0}}\n";
        let s = Scene::parse(text, "t").unwrap();
        let w = World::new(&s);
        let mut lidar = Lidar::new(&s.lidar);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        lidar.scan(&w, Pose2::IDENTITY, None, None, &mut r, &mut l);
        assert_eq!(r[360], f32::INFINITY, "50 m wall past a 30 m range");
        assert!((r[540] - 1.0).abs() < 1e-6);
        assert!((lidar.exact_ranges()[360] - 50.0).abs() < 1e-9);
    }

    #[test]
    fn small_rotation_matches_the_trigonometric_one() {
        for delta in [0.0, 1e-9, -3e-4, 7e-4, 2.8e-3, -0.0099, 0.05] {
            let err = (small_rotation(delta) - DVec2::from_angle(delta)).length();
            assert!(err < 2e-15, "delta {delta}: error {err}");
        }
    }

    #[test]
    fn extreme_missing_and_wrong_rates_are_exact() {
        let (s, w) = world("");
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        let count = |labels: &[BeamLabel], which| labels.iter().filter(|&&x| x == which).count();
        for (missing, wrong) in [(100.0, 0.0), (0.0, 100.0), (0.0, 0.0), (60.0, 40.0)] {
            let mut spec = s.lidar.clone();
            spec.noise.missing_pct = missing;
            spec.noise.wrong_pct = wrong;
            let mut lidar = Lidar::new(&spec);
            lidar.scan(&w, Pose2::IDENTITY, None, Some(&mut rng), &mut r, &mut l);
            let n = l.len();
            let (m, wr) = (count(&l, BeamLabel::Missing), count(&l, BeamLabel::Wrong));
            match (missing, wrong) {
                (100.0, _) => assert_eq!(m, n),
                (_, 100.0) => assert_eq!(wr, n),
                (0.0, 0.0) => assert_eq!(m + wr, 0),
                _ => {
                    assert_eq!(m + wr, n, "every beam is an event at 100 % in all");
                    assert!(
                        (m as f64 / n as f64 - 0.6).abs() < 0.08,
                        "missing share {m}/{n}"
                    );
                }
            }
        }
    }

    /// ln(1 - event) rounded 1 - event to 1 for event under about 1e-16, and a log of 0
    /// made every beam an event: `missing_pct: 1e-15` dropped every return.
    #[test]
    fn tiny_missing_and_wrong_rates_drop_almost_nothing() {
        let (s, w) = world("");
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        for (missing, wrong) in [(1e-12, 0.0), (1e-15, 0.0), (1e-20, 0.0), (0.0, 1e-300)] {
            let mut spec = s.lidar.clone();
            spec.noise.missing_pct = missing;
            spec.noise.wrong_pct = wrong;
            let mut lidar = Lidar::new(&spec);
            for _ in 0..10 {
                lidar.scan(&w, Pose2::IDENTITY, None, Some(&mut rng), &mut r, &mut l);
                let events = l
                    .iter()
                    .filter(|x| matches!(x, BeamLabel::Missing | BeamLabel::Wrong))
                    .count();
                assert_eq!(events, 0, "missing {missing} %, wrong {wrong} %");
            }
        }
    }

    #[test]
    fn missing_returns_are_independent_between_neighbouring_beams() {
        let (s, w) = world("");
        let mut spec = s.lidar.clone();
        spec.noise.missing_pct = 20.0;
        spec.noise.wrong_pct = 0.0;
        let mut lidar = Lidar::new(&spec);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        let (mut pairs, mut both) = (0usize, 0usize);
        for _ in 0..100 {
            lidar.scan(&w, Pose2::IDENTITY, None, Some(&mut rng), &mut r, &mut l);
            for k in l.windows(2) {
                pairs += 1;
                both += usize::from(k[0] == BeamLabel::Missing && k[1] == BeamLabel::Missing);
            }
        }
        let p_both = both as f64 / pairs as f64;
        assert!(
            (p_both - 0.04).abs() < 0.005,
            "P(two missing in a row) {p_both}"
        );
    }

    #[test]
    fn noise_rates_match_the_spec() {
        let (s, w) = world("");
        let mut lidar = Lidar::new(&s.lidar);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut r, mut l) = (Vec::new(), Vec::new());
        let (mut missing, mut wrong, mut total) = (0usize, 0usize, 0usize);
        let mut rel_sq = 0.0;
        let mut rel_n = 0usize;
        for _ in 0..200 {
            lidar.scan(&w, Pose2::IDENTITY, None, Some(&mut rng), &mut r, &mut l);
            for i in 0..r.len() {
                total += 1;
                match l[i] {
                    BeamLabel::Missing => missing += 1,
                    BeamLabel::Wrong => wrong += 1,
                    BeamLabel::Wall => {
                        let e = (r[i] as f64 - lidar.exact_ranges()[i]) / lidar.exact_ranges()[i];
                        rel_sq += e * e;
                        rel_n += 1;
                    }
                    _ => {}
                }
            }
        }
        let pct = |k: usize| 100.0 * k as f64 / total as f64;
        assert!((pct(missing) - 4.0).abs() < 0.3, "missing {}", pct(missing));
        assert!((pct(wrong) - 2.0).abs() < 0.25, "wrong {}", pct(wrong));
        // Relative error's standard deviation: 2 % (the angle error adds a little at corners).
        let sd = (rel_sq / rel_n as f64).sqrt();
        assert!((sd - 0.02).abs() < 0.001, "distance sd {sd}");
    }
}
