//! The robot's motion: a path planned on an occupancy grid inflated by the robot's radius
//! (A* between the motion's waypoints, shortened by line of sight), then driven as turns on
//! the spot and straight runs at constant speed. The plan repeats with a fixed period, and
//! the pose is a closed-form function of time, so hours of motion accumulate no error.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::DVec2;
use lidar_har_core::geometry::{Pose2, normalize_angle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::scene::{Motion, RobotSpec, SceneError};
use crate::world::World;

/// Extra distance the planner keeps from obstacles beyond the robot's radius.
pub const PLANNING_MARGIN: f64 = 0.03;
const GRID_RESOLUTION: f64 = 0.05;
/// Free space the start reaches, as a share of all the robot's free space, under which a
/// coverage that finds no lane blames the start's pocket rather than the lane spacing.
const POCKET_FRACTION: f64 = 0.25;
/// The shortest straight run a `bounce` motion drives; shorter ones end the bouncing.
const MIN_BOUNCE_RUN: f64 = 0.05;
/// How far a straight move between a point inside the planning margin (a start or waypoint)
/// and its nearest free cell may come within the robot's radius: what the grid's own runs
/// allow (a free cell's centre keeps radius + 3 cm, its corners 3.5 cm from it), plus
/// sampling.
const ENTRY_TOLERANCE: f64 = 0.01;
/// Step at which a straight move into the free space is checked, metres.
const ENTRY_STEP: f64 = 0.01;

/// The robot's velocity in its own frame (base_link): forward speed and turn rate.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Twist2 {
    pub linear: f64,
    pub angular: f64,
}

#[derive(Debug, Clone, Copy)]
enum Leg {
    Turn {
        at: DVec2,
        from: f64,
        delta: f64,
    },
    Drive {
        from: DVec2,
        to: DVec2,
        heading: f64,
    },
}

#[derive(Debug, Clone, Copy)]
struct TimedLeg {
    start: f64,
    duration: f64,
    leg: Leg,
}

/// The robot's planned motion.
#[derive(Debug, Clone)]
pub struct RobotMotion {
    legs: Vec<TimedLeg>,
    period: f64,
    start: Pose2,
    speed: f64,
    turn_rate: f64,
    /// The planned path's corners, for drawing.
    pub path: Vec<DVec2>,
}

/// Free space for the robot's centre on a grid.
struct Grid {
    origin: DVec2,
    width: usize,
    height: usize,
    free: Vec<bool>,
    /// Cells whose centre leaves the robot its radius (without the planning margin): where
    /// the search for the free cell nearest a start or waypoint inside the margin may go.
    fits: Vec<bool>,
}

/// Why a point inside the planning margin (a start or a waypoint) cannot join the free
/// space.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stuck {
    /// No free cell is reached through cells that leave the robot its radius.
    NoFreeCell,
    /// The straight move between the point and its nearest free cell (centre `cell`) runs
    /// the robot into `what` (a wall: `None`).
    Touches { cell: DVec2, what: Option<usize> },
}

/// Why [`Grid::plan`] found no way.
#[derive(Debug, Clone, Copy, PartialEq)]
enum NoWay {
    Start(Stuck),
    Goal(Stuck),
    /// No way on the grid between the two.
    Between,
}

/// The first obstacle the straight move `a`-`b` runs the robot of `radius` into (within
/// [`ENTRY_TOLERANCE`]): `Some(None)` a wall, `Some(Some(i))` furniture `i`.
fn move_touches(world: &World, radius: f64, a: DVec2, b: DVec2) -> Option<Option<usize>> {
    let n = ((b - a).length() / ENTRY_STEP).ceil().max(1.0) as usize;
    (0..=n).find_map(|k| {
        let (clear, what) = world.robot_clearance(a.lerp(b, k as f64 / n as f64));
        (clear < radius - ENTRY_TOLERANCE).then_some(what)
    })
}

impl Grid {
    /// The grid for a robot of `radius`: free cells keep radius + [`PLANNING_MARGIN`].
    fn new(world: &World, radius: f64) -> Self {
        let clearance = radius + PLANNING_MARGIN;
        let (lo, hi) = world.bounds();
        let origin = lo;
        let width = (((hi.x - lo.x) / GRID_RESOLUTION).ceil() as usize).max(1);
        let height = (((hi.y - lo.y) / GRID_RESOLUTION).ceil() as usize).max(1);
        let mut free = vec![false; width * height];
        let mut fits = vec![false; width * height];
        for j in 0..height {
            for i in 0..width {
                let c = origin
                    + DVec2::new(
                        (i as f64 + 0.5) * GRID_RESOLUTION,
                        (j as f64 + 0.5) * GRID_RESOLUTION,
                    );
                let clear = world.robot_clearance(c).0;
                free[j * width + i] = clear >= clearance;
                fits[j * width + i] = clear >= radius;
            }
        }
        Self {
            origin,
            width,
            height,
            free,
            fits,
        }
    }

    fn cell(&self, p: DVec2) -> Option<(usize, usize)> {
        let q = (p - self.origin) / GRID_RESOLUTION;
        (q.x >= 0.0 && q.y >= 0.0 && (q.x as usize) < self.width && (q.y as usize) < self.height)
            .then_some((q.x as usize, q.y as usize))
    }

    fn center(&self, (i, j): (usize, usize)) -> DVec2 {
        self.origin
            + DVec2::new(
                (i as f64 + 0.5) * GRID_RESOLUTION,
                (j as f64 + 0.5) * GRID_RESOLUTION,
            )
    }

    /// Square metres of free cells.
    fn free_area(&self) -> f64 {
        self.free.iter().filter(|&&f| f).count() as f64 * GRID_RESOLUTION * GRID_RESOLUTION
    }

    fn is_free(&self, p: DVec2) -> bool {
        self.cell(p)
            .is_some_and(|(i, j)| self.free[j * self.width + i])
    }

    /// Is the straight run `a`-`b` free (sampled at a fifth of a cell)?
    fn line_free(&self, a: DVec2, b: DVec2) -> bool {
        let n = ((b - a).length() / (GRID_RESOLUTION * 0.2)).ceil().max(1.0) as usize;
        (0..=n).all(|k| self.is_free(a.lerp(b, k as f64 / n as f64)))
    }

    /// Free cell nearest to `p`, breadth-first over the cells that leave the robot its
    /// radius (a search through blocked cells found free cells beyond thin furniture).
    fn nearest_free(&self, p: DVec2) -> Option<(usize, usize)> {
        let start = self.cell(p)?;
        let mut seen = vec![false; self.free.len()];
        let mut queue = std::collections::VecDeque::from([start]);
        seen[start.1 * self.width + start.0] = true;
        while let Some((i, j)) = queue.pop_front() {
            if self.free[j * self.width + i] {
                return Some((i, j));
            }
            for (di, dj) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                let (ni, nj) = (i as i64 + di, j as i64 + dj);
                if ni >= 0 && nj >= 0 && (ni as usize) < self.width && (nj as usize) < self.height {
                    let k = nj as usize * self.width + ni as usize;
                    if !seen[k] && self.fits[k] {
                        seen[k] = true;
                        queue.push_back((ni as usize, nj as usize));
                    }
                }
            }
        }
        None
    }

    /// Where the robot at `p` joins the free space: `p`'s own cell when it is free, else the
    /// nearest free cell, which the robot drives to (or from) in a straight line, so that
    /// move must not run it into a wall or furniture.
    fn entry(&self, p: DVec2, world: &World, radius: f64) -> Result<(usize, usize), Stuck> {
        let cell = self.nearest_free(p).ok_or(Stuck::NoFreeCell)?;
        let c = self.center(cell);
        match move_touches(world, radius, p, c) {
            None => Ok(cell),
            Some(what) => Err(Stuck::Touches { cell: c, what }),
        }
    }

    /// A* (8-connected) from `a` to `b`, then shortened by line of sight. Ends inside the
    /// planning margin join the grid at their [`Grid::entry`].
    fn plan(&self, a: DVec2, b: DVec2, world: &World, radius: f64) -> Result<Vec<DVec2>, NoWay> {
        if self.line_free(a, b) {
            return Ok(vec![a, b]);
        }
        let s = self.entry(a, world, radius).map_err(NoWay::Start)?;
        let g = self.entry(b, world, radius).map_err(NoWay::Goal)?;
        let idx = |(i, j): (usize, usize)| j * self.width + i;
        let h = |(i, j): (usize, usize)| {
            let (dx, dy) = ((i as f64 - g.0 as f64).abs(), (j as f64 - g.1 as f64).abs());
            dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)
        };
        let mut cost = vec![f64::INFINITY; self.free.len()];
        let mut parent = vec![usize::MAX; self.free.len()];
        let mut open = BinaryHeap::new();
        cost[idx(s)] = 0.0;
        open.push(Node { f: h(s), cell: s });
        while let Some(Node { cell, .. }) = open.pop() {
            if cell == g {
                break;
            }
            let c = cost[idx(cell)];
            for (n, step) in self.moves(cell) {
                if c + step < cost[idx(n)] {
                    cost[idx(n)] = c + step;
                    parent[idx(n)] = idx(cell);
                    open.push(Node {
                        f: c + step + h(n),
                        cell: n,
                    });
                }
            }
        }
        if !cost[idx(g)].is_finite() {
            return Err(NoWay::Between);
        }
        let mut cells = vec![g];
        let mut k = idx(g);
        while k != idx(s) {
            k = parent[k];
            cells.push((k % self.width, k / self.width));
        }
        cells.reverse();
        let mut raw: Vec<DVec2> = vec![a];
        raw.extend(cells.iter().map(|c| self.center(*c)));
        raw.push(b);
        // Line-of-sight shortening.
        let mut out = vec![a];
        let mut i = 0;
        while i + 1 < raw.len() {
            let mut j = raw.len() - 1;
            while j > i + 1 && !self.line_free(raw[i], raw[j]) {
                j -= 1;
            }
            out.push(raw[j]);
            i = j;
        }
        Ok(out)
    }

    /// The free cells one planner step from `cell`, with the step's length in cells: the
    /// eight neighbours, a diagonal step cutting no blocked corner.
    fn moves(&self, cell: (usize, usize)) -> impl Iterator<Item = ((usize, usize), f64)> + '_ {
        let idx = |(i, j): (usize, usize)| j * self.width + i;
        [
            (1i64, 0i64),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
        ]
        .into_iter()
        .filter_map(move |(di, dj)| {
            let (ni, nj) = (cell.0 as i64 + di, cell.1 as i64 + dj);
            if ni < 0 || nj < 0 || ni as usize >= self.width || nj as usize >= self.height {
                return None;
            }
            let n = (ni as usize, nj as usize);
            let open =
                self.free[idx(n)] && self.free[idx((n.0, cell.1))] && self.free[idx((cell.0, n.1))];
            let step = if di != 0 && dj != 0 {
                std::f64::consts::SQRT_2
            } else {
                1.0
            };
            open.then_some((n, step))
        })
    }

    /// This grid with only the free cells the planner reaches from `p` (from the nearest
    /// free cell, as [`Grid::plan`] sets off): a free pocket walled off by furniture is no
    /// place to drive to.
    fn reachable_from(&self, p: DVec2) -> Grid {
        let mut free = vec![false; self.free.len()];
        if let Some(start) = self.nearest_free(p) {
            free[start.1 * self.width + start.0] = true;
            let mut queue = std::collections::VecDeque::from([start]);
            while let Some(cell) = queue.pop_front() {
                for (n, _) in self.moves(cell) {
                    let k = n.1 * self.width + n.0;
                    if !free[k] {
                        free[k] = true;
                        queue.push_back(n);
                    }
                }
            }
        }
        Grid {
            free,
            fits: self.fits.clone(),
            ..*self
        }
    }

    /// The longest of up to 32 runs from `p` in random directions, stopping at the first
    /// longer than half a metre: `(length, direction)`.
    fn longest_free_run(&self, p: DVec2, rng: &mut ChaCha8Rng) -> Option<(f64, DVec2)> {
        let mut best: Option<(f64, DVec2)> = None;
        for _ in 0..32 {
            let dir =
                DVec2::from_angle(rng.random_range(-std::f64::consts::PI..std::f64::consts::PI));
            let d = self.free_run(p, dir);
            if best.is_none_or(|(bd, _)| d > bd) {
                best = Some((d, dir));
            }
            if d > 0.5 {
                break;
            }
        }
        best
    }

    /// How far the robot can drive from `p` along `dir` before leaving free space.
    fn free_run(&self, p: DVec2, dir: DVec2) -> f64 {
        let step = GRID_RESOLUTION * 0.2;
        let mut d = 0.0;
        while self.is_free(p + dir * (d + step)) && d < 100.0 {
            d += step;
        }
        d
    }
}

#[derive(PartialEq)]
struct Node {
    f: f64,
    cell: (usize, usize),
}
impl Eq for Node {}
impl Ord for Node {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .f
            .total_cmp(&self.f)
            .then_with(|| self.cell.cmp(&other.cell))
    }
}
impl PartialOrd for Node {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Why the robot cannot set off from, or arrive at, `p` (`what`: "the start", "the point")
/// inside the planning margin.
fn stuck_message(world: &World, radius: f64, what: &str, p: DVec2, stuck: Stuck) -> String {
    let describe = |i| crate::validate::describe(world, i);
    let near = describe(world.robot_clearance(p).1);
    let why = match stuck {
        Stuck::NoFreeCell => "no free space can be reached from it".to_string(),
        Stuck::Touches { cell, what } => format!(
            "the straight move between it and the nearest free space, at ({:.3}, {:.3}), \
             runs the robot into {}",
            cell.x,
            cell.y,
            describe(what)
        ),
    };
    format!(
        "{what} ({}, {}) lies within the planner's margin (the robot's radius, {radius} m, \
         plus {PLANNING_MARGIN} m) of {near}, and {why}",
        p.x, p.y
    )
}

fn motion_error(key: &str, message: String) -> SceneError {
    SceneError::Refused {
        key: key.to_string(),
        message,
    }
}

impl RobotMotion {
    /// Plans the robot's motion in `world`; `seed` drives random bounce headings.
    pub fn new(spec: &RobotSpec, world: &World, seed: u64) -> Result<Self, SceneError> {
        let start = spec.start.to_pose();
        let mut motion = RobotMotion {
            legs: Vec::new(),
            period: 0.0,
            start,
            speed: spec.speed,
            turn_rate: spec.turn_rate_deg.to_radians(),
            path: vec![start.position()],
        };
        if matches!(spec.motion, Motion::Static) {
            return Ok(motion);
        }
        let grid = Grid::new(world, spec.radius);
        let s = start.position();
        // A start inside the planning margin drives straight to the nearest free cell first
        // (every plan from it does): that move must keep the robot clear too.
        if let Err(stuck) = grid.entry(s, world, spec.radius) {
            return Err(motion_error(
                "robot.start",
                stuck_message(world, spec.radius, "the start", s, stuck),
            ));
        }
        let mut stops: Vec<DVec2> = Vec::new();
        let mut repeat = true;
        match &spec.motion {
            Motion::Static => {}
            Motion::Waypoints { points, repeat: r } => {
                stops.extend(points.iter().map(|p| DVec2::new(p[0], p[1])));
                repeat = *r;
            }
            Motion::Coverage { spacing, along_y } => {
                let reachable = grid.reachable_from(s);
                let (lo, hi) = world.bounds();
                let (axis_lo, axis_hi, cross_lo, cross_hi) = if *along_y {
                    (lo.y, hi.y, lo.x, hi.x)
                } else {
                    (lo.x, hi.x, lo.y, hi.y)
                };
                let point = |along: f64, across: f64| {
                    if *along_y {
                        DVec2::new(across, along)
                    } else {
                        DVec2::new(along, across)
                    }
                };
                // Free stretches of the lane at `across`.
                let runs_at = |across: f64| {
                    let mut runs: Vec<(f64, f64)> = Vec::new();
                    let mut run_start: Option<f64> = None;
                    let step = GRID_RESOLUTION * 0.5;
                    let mut along = axis_lo;
                    while along <= axis_hi {
                        let free = reachable.is_free(point(along, across));
                        match (free, run_start) {
                            (true, None) => run_start = Some(along),
                            (false, Some(a0)) => {
                                runs.push((a0, along - step));
                                run_start = None;
                            }
                            _ => {}
                        }
                        along += step;
                    }
                    if let Some(a0) = run_start {
                        runs.push((a0, along - step));
                    }
                    runs.retain(|(a, b)| b - a > 0.1);
                    runs
                };
                let mut lane = 0usize;
                let mut across = cross_lo + spacing / 2.0;
                while across < cross_hi {
                    let mut runs = runs_at(across);
                    if lane % 2 == 1 {
                        runs.reverse();
                        for r in &mut runs {
                            *r = (r.1, r.0);
                        }
                    }
                    for (a, b) in runs {
                        stops.push(point(a, across));
                        stops.push(point(b, across));
                    }
                    lane += 1;
                    across += spacing;
                }
                if stops.is_empty() {
                    // A lane on any row of the grid: whether a finer spacing would find one.
                    let rows = ((cross_hi - cross_lo) / GRID_RESOLUTION).ceil() as usize;
                    let any_lane = (0..rows).any(|k| {
                        !runs_at(cross_lo + (k as f64 + 0.5) * GRID_RESOLUTION).is_empty()
                    });
                    let (reached_m2, free_m2) = (reachable.free_area(), grid.free_area());
                    if any_lane && reached_m2 >= free_m2 * POCKET_FRACTION {
                        let size = hi - lo;
                        return Err(motion_error(
                            "robot.motion.spacing",
                            format!(
                                "coverage found no free lane for the robot: lanes {spacing} m \
                                 apart, the first {} m in from the room's side, in a room of \
                                 {:.2} m x {:.2} m",
                                spacing / 2.0,
                                size.x,
                                size.y
                            ),
                        ));
                    }
                    let why = if any_lane {
                        format!("lanes {spacing} m apart cross none of it")
                    } else {
                        "too little for a lane at any spacing".to_string()
                    };
                    return Err(motion_error(
                        "robot.start",
                        format!(
                            "coverage found no free lane for the robot: its start ({}, {}) is \
                             walled in, reaching {reached_m2:.2} m² of the {free_m2:.2} m² free \
                             for it in the room ({why})",
                            s.x, s.y
                        ),
                    ));
                }
            }
            Motion::Bounce { runs } => {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let mut p = s;
                for run in 0..*runs {
                    let mut best = grid.longest_free_run(p, &mut rng);
                    // A start within the planning margin of a wall lies outside the grid's
                    // free space, where no run begins: set off from the nearest free cell
                    // instead (the first leg drives there). Robots that found a first run
                    // keep their plan.
                    if run == 0
                        && best.is_none_or(|(d, _)| d <= MIN_BOUNCE_RUN)
                        && let Ok(cell) = grid.entry(s, world, spec.radius)
                    {
                        p = grid.center(cell);
                        best = grid.longest_free_run(p, &mut rng);
                    }
                    match best {
                        Some((d, dir)) if d > MIN_BOUNCE_RUN => {
                            p += dir * d;
                            stops.push(p);
                        }
                        _ => break,
                    }
                }
            }
        }
        if repeat {
            stops.push(s);
        }
        let mut at = s;
        let mut path = vec![s];
        for (k, stop) in stops.iter().enumerate() {
            let leg = match grid.plan(at, *stop, world, spec.radius) {
                Ok(leg) => leg,
                Err(why) => {
                    let key = match spec.motion {
                        Motion::Waypoints { .. } if k < stops.len() - usize::from(repeat) => {
                            format!("robot.motion.points[{k}]")
                        }
                        _ => "robot.motion".to_string(),
                    };
                    let message = match why {
                        NoWay::Start(stuck) | NoWay::Goal(stuck) => {
                            let p = if matches!(why, NoWay::Start(_)) {
                                at
                            } else {
                                *stop
                            };
                            let what = if p == s { "the start" } else { "the point" };
                            stuck_message(world, spec.radius, what, p, stuck)
                        }
                        NoWay::Between => format!(
                            "no collision-free way for the robot to ({:.2}, {:.2})",
                            stop.x, stop.y
                        ),
                    };
                    return Err(motion_error(&key, message));
                }
            };
            path.extend(leg.into_iter().skip(1));
            at = *stop;
        }
        path.dedup_by(|a, b| (*a - *b).length() < 1e-9);
        motion.build_legs(&path, repeat);
        motion.path = path;
        Ok(motion)
    }

    fn build_legs(&mut self, path: &[DVec2], repeat: bool) {
        let mut t = 0.0;
        let mut heading = self.start.theta;
        for w in path.windows(2) {
            let d = w[1] - w[0];
            let target = d.to_angle();
            let delta = normalize_angle(target - heading);
            if delta.abs() > 1e-9 {
                let duration = delta.abs() / self.turn_rate;
                self.legs.push(TimedLeg {
                    start: t,
                    duration,
                    leg: Leg::Turn {
                        at: w[0],
                        from: heading,
                        delta,
                    },
                });
                t += duration;
            }
            let duration = d.length() / self.speed;
            self.legs.push(TimedLeg {
                start: t,
                duration,
                leg: Leg::Drive {
                    from: w[0],
                    to: w[1],
                    heading: target,
                },
            });
            t += duration;
            heading = target;
        }
        if repeat {
            let delta = normalize_angle(self.start.theta - heading);
            if delta.abs() > 1e-9 {
                let at = path.last().copied().unwrap_or(self.start.position());
                let duration = delta.abs() / self.turn_rate;
                self.legs.push(TimedLeg {
                    start: t,
                    duration,
                    leg: Leg::Turn {
                        at,
                        from: heading,
                        delta,
                    },
                });
                t += duration;
            }
            self.period = t;
        } else {
            self.period = f64::INFINITY;
        }
    }

    /// Pose and velocity at `t` seconds from the start.
    pub fn at(&self, t: f64) -> (Pose2, Twist2) {
        let Some(last) = self.legs.last() else {
            return (self.start, Twist2::default());
        };
        let t = if self.period.is_finite() && self.period > 0.0 {
            t.rem_euclid(self.period)
        } else {
            t.max(0.0)
        };
        let i = self
            .legs
            .partition_point(|l| l.start <= t)
            .saturating_sub(1);
        let l = &self.legs[i];
        let f = if l.duration > 0.0 {
            ((t - l.start) / l.duration).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let moving = t < last.start + last.duration;
        match l.leg {
            Leg::Turn { at, from, delta } => {
                let w = if moving {
                    delta.signum() * self.turn_rate
                } else {
                    0.0
                };
                (
                    Pose2::new(at.x, at.y, normalize_angle(from + delta * f)),
                    Twist2 {
                        linear: 0.0,
                        angular: w,
                    },
                )
            }
            Leg::Drive { from, to, heading } => {
                let p = from.lerp(to, f);
                let v = if moving { self.speed } else { 0.0 };
                (
                    Pose2::new(p.x, p.y, heading),
                    Twist2 {
                        linear: v,
                        angular: 0.0,
                    },
                )
            }
        }
    }

    /// Seconds after which the motion repeats (infinite when it stops at its last point).
    pub fn period(&self) -> f64 {
        self.period
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    fn scene(motion: &str) -> Scene {
        let text = format!(
            "duration: 10\nroom: {{outline: [[0,0],[6,0],[6,4],[0,4]]}}\nfurniture: [{{kind: box, center: [3, 2], size: [1, 2.4], height: 0.8}}]\nrobot: {{start: {{x: 0.5, y: 2}}, motion: {motion}}}\n"
        );
        Scene::parse(&text, "t").unwrap()
    }

    fn check_clear(s: &Scene, m: &RobotMotion) {
        let world = World::new(s);
        let mut t = 0.0;
        while t < m.period().min(2000.0) {
            let (pose, _) = m.at(t);
            let clear = world.robot_clearance(pose.position()).0;
            assert!(
                clear >= s.robot.radius - 1e-9,
                "robot at {pose:?} (t = {t}) only {clear} m from an obstacle"
            );
            t += 0.25;
        }
    }

    #[test]
    fn waypoints_are_reached_around_furniture() {
        let s = scene("{kind: waypoints, points: [[5.5, 2]]}");
        let m = RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap();
        assert!(
            m.path.len() > 2,
            "the box is in the way: the path must bend"
        );
        check_clear(&s, &m);
        // Reaches the waypoint and comes back: periodic.
        assert!(
            m.path
                .iter()
                .any(|p| (*p - DVec2::new(5.5, 2.0)).length() < 1e-9)
        );
        let (p0, _) = m.at(0.0);
        let (p1, _) = m.at(m.period());
        assert!((p0.position() - p1.position()).length() < 1e-9);
    }

    #[test]
    fn coverage_and_bounce_stay_clear() {
        for motion in [
            "{kind: coverage, spacing: 0.4}",
            "{kind: coverage, along_y: true}",
            "{kind: bounce, runs: 20}",
        ] {
            let s = scene(motion);
            let m = RobotMotion::new(&s.robot, &World::new(&s), 3).unwrap();
            assert!(m.period() > 10.0, "{motion}");
            check_clear(&s, &m);
        }
    }

    #[test]
    fn coverage_leaves_out_a_pocket_the_robot_cannot_reach() {
        // A sofa and a cabinet 10 cm apart wall off the strip along y = 0 left of x = 2.1:
        // free on the grid, out of reach. Its lanes made the plan fail.
        let text = "duration: 5\nroom: {outline: [[0,0],[5,0],[5,4],[0,4]]}\nfurniture:\n  - {kind: box, name: sofa, center: [1.0, 1.2], size: [2.0, 0.8], height: 0.85}\n  - {kind: box, name: cabinet, center: [2.3, 0.4], size: [0.4, 0.8], height: 0.9}\nrobot: {start: {x: 3.5, y: 2.5}, motion: {kind: coverage}}\n";
        let s = Scene::parse(text, "t").unwrap();
        let m = RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap();
        assert!(
            m.path.iter().all(|p| !(p.x < 2.1 && p.y < 0.8)),
            "{:?}",
            m.path
        );
        assert!(
            m.path.iter().any(|p| p.x < 1.0 && p.y > 3.0),
            "the rest is covered"
        );
        check_clear(&s, &m);
    }

    #[test]
    fn coverage_with_lanes_wider_than_the_room_names_the_spacing() {
        let s = scene("{kind: coverage, spacing: 100}");
        let err = RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap_err();
        assert_eq!(
            err.to_string(),
            "robot.motion.spacing: coverage found no free lane for the robot: lanes 100 m \
             apart, the first 50 m in from the room's side, in a room of 6.00 m x 4.00 m"
        );
    }

    /// A start walled in by furniture left coverage no lane too, and the error named the
    /// spacing and the room's size, neither of which was the cause.
    #[test]
    fn coverage_from_a_walled_in_start_names_the_start() {
        // Two boxes close off the corner x < `width`, y < 0.5 (1 cm from the walls), the
        // robot starting in it.
        let error = |width: f64| {
            let text = format!(
                "duration: 5\nroom: {{outline: [[0,0],[6,0],[6,4],[0,4]]}}\nfurniture:\n  - \
                 {{kind: box, center: [{}, 0.31], size: [0.1, 0.6], height: 0.9}}\n  - \
                 {{kind: box, center: [{}, 0.55], size: [{}, 0.1], height: 0.9}}\nrobot: \
                 {{start: {{x: 0.25, y: 0.25}}, motion: {{kind: coverage}}}}\n",
                width + 0.05,
                (width + 0.1) / 2.0,
                width + 0.08,
            );
            let s = Scene::parse(&text, "t").unwrap();
            RobotMotion::new(&s.robot, &World::new(&s), 0)
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            error(0.5),
            "robot.start: coverage found no free lane for the robot: its start (0.25, 0.25) is \
             walled in, reaching 0.01 m² of the 19.82 m² free for it in the room (too little \
             for a lane at any spacing)"
        );
        // A corridor a finer spacing would have lanes in, but a pocket all the same.
        assert_eq!(
            error(3.0),
            "robot.start: coverage found no free lane for the robot: its start (0.25, 0.25) is \
             walled in, reaching 0.26 m² of the 18.57 m² free for it in the room (lanes 0.35 m \
             apart cross none of it)"
        );
    }

    #[test]
    fn a_bounce_started_near_a_wall_sets_off() {
        // The start is 2 cm beyond the robot's radius from the wall at x = 0, inside the
        // planning margin: no run starts there, and the robot once shuttled 5 cm for ever.
        for seed in 0..4 {
            let text = "duration: 10\nroom: {outline: [[0,0],[6,0],[6,4],[0,4]]}\nrobot: {start: {x: 0.19, y: 2}, motion: {kind: bounce, runs: 10}}\n";
            let s = Scene::parse(text, "t").unwrap();
            let m = RobotMotion::new(&s.robot, &World::new(&s), seed).unwrap();
            let driven: f64 = m.path.windows(2).map(|w| (w[1] - w[0]).length()).sum();
            assert!(
                driven > 2.0,
                "seed {seed}: drove {driven} m, path {:?}",
                m.path
            );
            check_clear(&s, &m);
        }
    }

    /// A start 0.18 m from a wall, in a 0.36 m corridor beside a 5 cm partition: inside the
    /// planning margin, and the nearest free cell lies across the partition. The planner
    /// found that cell through blocked ones and the robot drove through the partition. Now
    /// the search keeps to the corridor, and the straight move to the free space at its end
    /// would cut the partition's corner: refused.
    #[test]
    fn a_start_inside_the_margin_does_not_cross_thin_furniture() {
        let room = "duration: 60\nroom: {outline: [[0,0],[6,0],[6,4],[0,4]]}\nfurniture: [{kind: box, name: partition, center: [3, 0.385], size: [4, 0.05], height: 1}]\n";
        for motion in [
            "{kind: waypoints, points: [[3, 2.5]]}",
            "{kind: coverage}",
            "{kind: bounce, runs: 10}",
        ] {
            let text = format!("{room}robot: {{start: {{x: 3, y: 0.18}}, motion: {motion}}}\n");
            let s = Scene::parse(&text, "t").unwrap();
            let err = RobotMotion::new(&s.robot, &World::new(&s), 0)
                .map(|m| m.path)
                .unwrap_err()
                .to_string();
            assert_eq!(
                err,
                "robot.start: the start (3, 0.18) lies within the planner's margin (the \
                 robot's radius, 0.17 m, plus 0.03 m) of a wall, and the straight move between \
                 it and the nearest free space, at (5.175, 0.225), runs the robot into \
                 furniture[0] 'partition'",
                "{motion}"
            );
        }
        // The same spot as a waypoint.
        let text = format!(
            "{room}robot: {{start: {{x: 3, y: 2.5}}, motion: {{kind: waypoints, points: [[3, 0.18]]}}}}\n"
        );
        let s = Scene::parse(&text, "t").unwrap();
        let err = RobotMotion::new(&s.robot, &World::new(&s), 0)
            .map(|m| m.path)
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("robot.motion.points[0]: the point (3, 0.18) lies within")
                && err.ends_with("runs the robot into furniture[0] 'partition'"),
            "{err}"
        );
        // Beyond the partition's end the corridor opens: a start there sets off clear.
        let text = format!(
            "{room}robot: {{start: {{x: 0.9, y: 0.18}}, motion: {{kind: waypoints, points: [[3, 2.5]]}}}}\n"
        );
        let s = Scene::parse(&text, "t").unwrap();
        check_clear(&s, &RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap());
    }

    /// A table whose top is no higher than the Lidar is no table to drive under: the robot
    /// drove straight under a 0.35 m top with its Lidar at 0.45 m.
    #[test]
    fn a_table_lower_than_the_lidar_is_driven_round() {
        let scene = |lidar_height: f64| {
            let text = format!(
                "duration: 40\nroom: {{outline: [[0,0],[6,0],[6,4],[0,4]]}}\nfurniture: [{{kind: table, name: low table, center: [3, 2], size: [1.2, 3.0], height: 0.35}}]\nrobot: {{lidar_height: {lidar_height}, start: {{x: 1, y: 2}}, motion: {{kind: waypoints, points: [[5, 2]]}}}}\n"
            );
            Scene::parse(&text, "t").unwrap()
        };
        let s = scene(0.45);
        let world = World::new(&s);
        let m = RobotMotion::new(&s.robot, &world, 0).unwrap();
        let top = &world.furniture[0].person_blocks[0];
        let mut t = 0.0;
        while t < m.period() {
            let p = m.at(t).0.position();
            assert!(
                top.signed_distance(p) >= s.robot.radius - 1e-9,
                "t = {t}: the robot at {p} is under the top (path {:?})",
                m.path
            );
            t += 0.05;
        }
        check_clear(&s, &m);
        // A top as high as the Lidar is as low; one above it is driven under, legs avoided.
        assert!(
            World::new(&scene(0.35))
                .robot_clearance(DVec2::new(3.0, 2.0))
                .0
                < 0.0
        );
        let s = scene(0.3);
        let m = RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap();
        assert_eq!(
            m.path,
            [
                DVec2::new(1.0, 2.0),
                DVec2::new(5.0, 2.0),
                DVec2::new(1.0, 2.0)
            ]
        );
        // Starting under the low top is refused like starting inside any other furniture.
        let text = "duration: 40\nroom: {outline: [[0,0],[6,0],[6,4],[0,4]]}\nfurniture: [{kind: table, name: low table, center: [3, 2], size: [1.2, 3.0], height: 0.35}]\nrobot: {lidar_height: 0.45, start: {x: 3, y: 2}}\n";
        assert_eq!(
            Scene::parse(text, "t").unwrap_err().to_string(),
            "t: robot.start: the robot (radius 0.17 m) starts inside furniture[0] 'low table'"
        );
    }

    #[test]
    fn speed_and_turn_rate_are_respected() {
        let s = scene("{kind: coverage}");
        let m = RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap();
        let dt = 0.01;
        let mut prev = m.at(0.0).0;
        for k in 1..5000 {
            let p = m.at(k as f64 * dt).0;
            assert!((p.position() - prev.position()).length() <= 0.2 * dt + 1e-9);
            assert!(
                normalize_angle(p.theta - prev.theta).abs()
                    <= std::f64::consts::FRAC_PI_2 * dt + 1e-9
            );
            prev = p;
        }
    }

    #[test]
    fn pose_after_hours_repeats_exactly() {
        let s = scene("{kind: waypoints, points: [[5.5, 2], [5.5, 0.5]]}");
        let m = RobotMotion::new(&s.robot, &World::new(&s), 0).unwrap();
        let t = 1.234;
        let (a, _) = m.at(t);
        let (b, _) = m.at(t + 500.0 * m.period());
        assert!(
            (a.position() - b.position()).length() < 1e-6
                && normalize_angle(a.theta - b.theta).abs() < 1e-6
        );
    }

    #[test]
    fn unreachable_waypoint_is_an_error() {
        let text = "duration: 10\nroom: {outline: [[0,0],[6,0],[6,4],[0,4]]}\nfurniture: [{kind: box, center: [3, 2], size: [0.3, 4], height: 0.8}]\nrobot: {start: {x: 0.5, y: 2}, motion: {kind: waypoints, points: [[5.5, 2]]}}\n";
        let s = Scene::parse(text, "t").unwrap();
        let err = RobotMotion::new(&s.robot, &World::new(&s), 0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("robot.motion.points[0]"), "{err}");
    }
}
