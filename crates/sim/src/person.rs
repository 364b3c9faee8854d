//! The person: a script of activities turned into a body pose at any time.
//!
//! Each activity is a parametric motion (gait cycles as functions of a phase, a fall as a
//! pitch angle growing with the square of time, like a toppling body from rest); steps are
//! joined by blending the joint parameters from the previous step's last pose, and the root
//! is re-anchored so the pelvis does not jump. Everything is a closed-form function of time:
//! no integration, no drift over hours.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::DVec2;
use lidar_har_core::activity::Activity;
use lidar_har_core::geometry::normalize_angle;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::body::{BodyDims, Capsule, PARTS, PoseParams, capsules};
use crate::scene::{FallDirection, PersonSpec, SceneError, ScriptStep, is_locomotion};
use crate::validate::describe;
use crate::world::World;

/// Per-person traits drawn once per episode.
#[derive(Debug, Clone, Copy)]
pub struct Traits {
    pub dims: BodyDims,
    pub pace: f64,
    pub stride: f64,
    pub sway: f64,
    /// Phase offsets of the slow sway oscillators.
    phases: [f64; 6],
}

/// Where the person is and what they do at one instant.
#[derive(Debug, Clone, Copy)]
pub struct PersonState {
    /// Pelvis position on the floor plane (the ground-truth position).
    pub position: DVec2,
    /// Facing direction of the root frame.
    pub yaw: f64,
    pub activity: Activity,
    pub parts: [Capsule; PARTS],
}

/// A walking route: the polyline walked there and back again, forever.
#[derive(Debug, Clone)]
struct Route {
    points: Vec<DVec2>,
    cumulative: Vec<f64>,
    /// One there-and-back period as legs `(start, end, heading)` in arc length, headings
    /// unwrapped so that each reversal is a left turn of pi (no jump of 2 pi anywhere).
    legs: Vec<(f64, f64, f64)>,
    /// Heading gained over one period (a multiple of 2 pi).
    turn_per_period: f64,
}

impl Route {
    fn new(points: Vec<DVec2>) -> Self {
        let mut cumulative = vec![0.0];
        for w in points.windows(2) {
            let last = cumulative.last().copied().unwrap_or(0.0);
            cumulative.push(last + (w[1] - w[0]).length());
        }
        let len = cumulative.last().copied().unwrap_or(0.0);
        let mut raw: Vec<(f64, f64, f64)> = Vec::new();
        if len > 1e-9 {
            for i in 0..points.len() - 1 {
                if cumulative[i + 1] - cumulative[i] > 1e-12 {
                    raw.push((
                        cumulative[i],
                        cumulative[i + 1],
                        (points[i + 1] - points[i]).to_angle(),
                    ));
                }
            }
            for i in (0..points.len() - 1).rev() {
                if cumulative[i + 1] - cumulative[i] > 1e-12 {
                    raw.push((
                        2.0 * len - cumulative[i + 1],
                        2.0 * len - cumulative[i],
                        (points[i] - points[i + 1]).to_angle(),
                    ));
                }
            }
        }
        let mut legs: Vec<(f64, f64, f64)> = Vec::with_capacity(raw.len());
        for (a, b, angle) in raw {
            let unwrapped = match legs.last() {
                Some(prev) => prev.2 + normalize_angle(angle - prev.2),
                None => angle,
            };
            legs.push((a, b, unwrapped));
        }
        let turn_per_period = match (legs.first(), legs.last()) {
            (Some(first), Some(last)) => last.2 + normalize_angle(first.2 - last.2) - first.2,
            _ => 0.0,
        };
        Self {
            points,
            cumulative,
            legs,
            turn_per_period,
        }
    }

    fn length(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// The points ahead of a walker `s` metres along (back and forth), up to the end it is
    /// heading for: walked back and forth as a route of their own from there, they keep to
    /// this route's segments.
    fn ahead(&self, s: f64) -> Vec<DVec2> {
        let len = self.length();
        if len <= 1e-9 {
            return Vec::new();
        }
        let u = s.rem_euclid(2.0 * len);
        // At an end, the walker turns back.
        let outward = if u < 1e-9 { true } else { u < len - 1e-9 };
        if outward {
            let zip = self.points.iter().zip(&self.cumulative);
            zip.filter(|&(_, &c)| c > u + 1e-9)
                .map(|(p, _)| *p)
                .collect()
        } else {
            let back = 2.0 * len - u;
            let zip = self.points.iter().zip(&self.cumulative).rev();
            zip.filter(|&(_, &c)| c < back - 1e-9)
                .map(|(p, _)| *p)
                .collect()
        }
    }

    /// Position after walking `s` metres, back and forth along the route.
    fn at(&self, s: f64) -> DVec2 {
        let len = self.length();
        if len <= 1e-9 {
            return self.points[0];
        }
        let u = s.rem_euclid(2.0 * len);
        let u = if u > len { 2.0 * len - u } else { u };
        let i = self
            .cumulative
            .partition_point(|&c| c <= u)
            .clamp(1, self.points.len() - 1);
        let (c0, c1) = (self.cumulative[i - 1], self.cumulative[i]);
        let f = if c1 > c0 { (u - c0) / (c1 - c0) } else { 0.0 };
        self.points[i - 1].lerp(self.points[i], f)
    }

    /// Mean walking direction over the arc `[s - w, s + w]`, clipped at the start and at
    /// `s_end` (where the step ends): turns at corners and reversals are spread over `2 w`
    /// metres instead of happening at once, and a step ending at a turnaround ends facing
    /// the way it arrived, not half turned.
    fn heading(&self, s: f64, w: f64, s_end: f64) -> Option<f64> {
        let period = 2.0 * self.length();
        if self.legs.is_empty() || period <= 0.0 {
            return None;
        }
        let (lo, hi) = ((s - w).max(0.0), (s + w).min(s_end));
        if hi <= lo {
            return None;
        }
        // Count whole periods apart, so the arc is walked in small numbers: kilometres in,
        // a fixed step below the spacing of floats would never move on.
        let periods_before = (lo / period).floor();
        let (lo_here, hi_here) = (lo - periods_before * period, hi - periods_before * period);
        let mut u = lo_here;
        let mut acc = 0.0;
        while u < hi_here {
            let k = (u / period).floor();
            let r = u - k * period;
            let j = self
                .legs
                .partition_point(|l| l.1 <= r)
                .min(self.legs.len() - 1);
            let (_, end, angle) = self.legs[j];
            let next = (k * period + end).min(hi_here).max(u.next_up());
            acc += (next - u) * (angle + (periods_before + k) * self.turn_per_period);
            u = next;
        }
        Some(acc / (hi_here - lo_here))
    }
}

/// One script step, resolved: timing, route, speeds and the pose it starts from.
#[derive(Debug, Clone)]
struct Plan {
    activity: Activity,
    start: f64,
    end: f64,
    route: Route,
    speed: f64,
    /// Gait cycles per second.
    freq: f64,
    /// Hip swing amplitude, radians.
    amp: f64,
    phase0: f64,
    heading0: f64,
    blend: f64,
    from: PoseParams,
    from_heading: f64,
    /// For falls, getting up and lying: which way the body lies from the feet.
    lying: FallDirection,
    /// Step duration for falls and getting up (the motion's own time scale).
    motion_time: f64,
}

/// The person of a scene, evaluated at non-decreasing times.
#[derive(Debug, Clone)]
pub struct Person {
    steps: Vec<ScriptStep>,
    repeat: bool,
    traits: Traits,
    rng: ChaCha8Rng,
    plans: Vec<Plan>,
    /// Next script step to plan, counting over repeats.
    next_step: usize,
    current: usize,
    /// The room, for finding room to fall or lie down in.
    world: World,
    /// Once the first pass is planned, steps are planned while simulating, where a refusal
    /// cannot be reported: what the first pass checked (paths, room to sit or crawl) is not
    /// checked again, and a fall with no room goes as drawn.
    first_pass_planned: bool,
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

fn rotate(v: DVec2, yaw: f64) -> DVec2 {
    DVec2::from_angle(yaw).rotate(v)
}

fn lying_vector(dir: FallDirection) -> DVec2 {
    match dir {
        FallDirection::Forward => DVec2::X,
        FallDirection::Backward => -DVec2::X,
        FallDirection::Left => DVec2::Y,
        FallDirection::Right => -DVec2::Y,
    }
}

/// Usual speed (m/s) and gait frequency (cycles/s) of a moving activity, before traits.
fn gait_defaults(a: Activity) -> (f64, f64) {
    match a {
        Activity::Walking => (1.0, 0.9),
        Activity::Running => (2.5, 1.4),
        Activity::WalkingUnsteadily => (0.5, 0.7),
        Activity::Crawling => (0.3, 0.5),
        _ => (0.0, 0.0),
    }
}

impl Traits {
    fn wave(&self, t: f64, freq: f64, k: usize) -> f64 {
        (TAU * freq * t + self.phases[k % 6]).sin()
    }

    fn standing(&self, t: f64) -> PoseParams {
        let sway = 0.012 * self.sway;
        PoseParams {
            pelvis: DVec2::new(sway * self.wave(t, 0.21, 0), sway * self.wave(t, 0.29, 1)),
            pitch: 0.02 + 0.01 * self.wave(t, 0.17, 2),
            roll: 0.012 * self.sway * self.wave(t, 0.23, 3),
            hip_abduct: [0.05, 0.05],
            knee_flex: [0.03, 0.03],
            shoulder_flex: [0.05, 0.05],
            shoulder_abduct: [0.08, 0.08],
            elbow_flex: [0.15, 0.15],
            ..PoseParams::default()
        }
    }

    fn lying(&self, dir: FallDirection, t: f64) -> PoseParams {
        // `down`: the sign of a flexion that points a limb at the floor.
        let (pitch, roll, down) = match dir {
            FallDirection::Forward => (FRAC_PI_2, 0.0, 1.0),
            FallDirection::Backward => (-FRAC_PI_2, 0.0, -1.0),
            FallDirection::Left => (0.0, -FRAC_PI_2, 0.0),
            FallDirection::Right => (0.0, FRAC_PI_2, 0.0),
        };
        // Legs bent slightly towards the floor so they rest on it beside the thicker trunk.
        let leg = 0.08 * down;
        let breath = 0.03 * self.wave(t, 0.25, 4);
        let pelvis = lying_vector(dir) * (self.dims.leg_length() + 0.05);
        match dir {
            // On the back or front: arms out on the floor. Face down, the feet are stretched
            // along the shins (a foot at a right angle would prop the body up on its toes).
            FallDirection::Forward | FallDirection::Backward => PoseParams {
                pelvis,
                pitch,
                roll,
                hip_flex: [leg, leg],
                hip_abduct: [0.1, 0.1],
                knee_flex: [0.1, 0.15],
                ankle: if down > 0.0 { [-1.5, -1.5] } else { [0.0, 0.0] },
                shoulder_flex: [0.1 * down, 0.1 * down],
                shoulder_abduct: [0.35 + breath, 0.35 + breath],
                elbow_flex: [0.15, 0.15],
                ..PoseParams::default()
            },
            // On the side: legs stacked with the knees a little bent, arms forward in front
            // of the chest (spread arms or legs would point into the floor and lift the body).
            FallDirection::Left | FallDirection::Right => PoseParams {
                pelvis,
                pitch,
                roll,
                hip_flex: [0.3, 0.3],
                hip_abduct: [0.0, 0.0],
                knee_flex: [0.5, 0.5],
                shoulder_flex: [1.2 + breath, 1.2 + breath],
                shoulder_abduct: [0.0, 0.0],
                elbow_flex: [0.4, 0.4],
                ..PoseParams::default()
            },
        }
    }

    /// The fall at progress `w` in [0, 1]: the trunk turns from upright to flat through
    /// `w * pi/2` about the feet, with knees and hips giving way on the way down.
    fn falling(&self, dir: FallDirection, w: f64, t: f64) -> PoseParams {
        let mut p = self.standing(t).lerp(&self.lying(dir, t), w);
        let theta = w * FRAC_PI_2;
        let sign = |v: f64| if v == 0.0 { 0.0 } else { v.signum() };
        let lying = self.lying(dir, t);
        p.pitch = sign(lying.pitch) * theta;
        p.roll = sign(lying.roll) * theta;
        p.pelvis = lying_vector(dir) * (self.dims.leg_length() + 0.05) * theta.sin();
        let bump = (PI * w).sin();
        for i in 0..2 {
            p.knee_flex[i] += 0.5 * bump;
            p.hip_flex[i] += 0.3 * bump * sign(lying.pitch + 1e-9);
            p.shoulder_flex[i] += 1.0 * bump; // arms reach out
        }
        p
    }

    fn sitting(&self, t: f64) -> PoseParams {
        let pitch = -0.2 + 0.02 * self.wave(t, 0.2, 5);
        PoseParams {
            pelvis: DVec2::new(-0.3, 0.0),
            pitch,
            roll: 0.02 * self.sway * self.wave(t, 0.15, 1),
            hip_flex: [FRAC_PI_2 + pitch, FRAC_PI_2 + pitch - 0.05],
            hip_abduct: [0.15, 0.15],
            knee_flex: [0.3, 0.45],
            ankle: [0.3, 0.3],
            shoulder_flex: [-0.5, -0.5],
            shoulder_abduct: [0.25, 0.25],
            elbow_flex: [0.0, 0.0],
            ..PoseParams::default()
        }
    }

    fn crawling(&self, phase: f64, amp: f64) -> PoseParams {
        let pitch = 1.2;
        let s = [phase.sin(), (phase + PI).sin()];
        PoseParams {
            pelvis: DVec2::new(-0.25, 0.0),
            pitch,
            roll: 0.04 * self.sway * phase.sin(),
            hip_flex: [pitch + amp * s[0], pitch + amp * s[1]],
            hip_abduct: [0.08, 0.08],
            knee_flex: [FRAC_PI_2 + amp * s[0], FRAC_PI_2 + amp * s[1]],
            ankle: [-FRAC_PI_2, -FRAC_PI_2],
            // Diagonal pairs: left arm with right leg.
            shoulder_flex: [pitch + amp * s[1], pitch + amp * s[0]],
            shoulder_abduct: [0.1, 0.1],
            elbow_flex: [0.1, 0.1],
            ..PoseParams::default()
        }
    }

    /// Walking, running and unsteady walking: legs swing with `phase`; the stance foot moves
    /// back at the walking speed on average over a step when `amp` matches the stride (see
    /// `Plan::new`).
    fn gait(&self, a: Activity, phase: f64, amp: f64, t: f64) -> PoseParams {
        let ph = [phase, phase + PI];
        let mut p = PoseParams::default();
        let (knee_base, knee_swing, elbow, pitch) = match a {
            Activity::Running => (0.35, 1.5, 1.4, 0.15),
            Activity::WalkingUnsteadily => (0.12, 0.8, 0.3, 0.1 + 0.05 * self.wave(t, 0.37, 2)),
            _ => (0.08, 0.95, 0.25, 0.05),
        };
        let bias = if a == Activity::Running { 0.15 } else { 0.0 };
        for (i, ph) in ph.iter().enumerate() {
            let swing = ph.cos().max(0.0);
            p.hip_flex[i] = amp * ph.sin() + bias;
            p.knee_flex[i] = knee_base + knee_swing * swing * swing;
            p.shoulder_flex[i] = -0.8 * amp * ph.sin();
            p.elbow_flex[i] = elbow;
            p.hip_abduct[i] = 0.04;
            p.shoulder_abduct[i] = 0.08;
        }
        p.pitch = pitch;
        p.roll = 0.04 * self.sway * phase.sin();
        p.pelvis = DVec2::new(0.0, 0.025 * self.sway * phase.cos());
        match a {
            Activity::Running => p.lift = 0.07 * self.stride * (-(2.0 * phase).cos()).max(0.0),
            Activity::WalkingUnsteadily => {
                p.pelvis.y += 0.07 * self.sway * self.wave(t, 0.27, 1);
                p.roll += 0.12 * self.sway * self.wave(t, 0.4, 5);
                for i in 0..2 {
                    p.hip_abduct[i] = 0.12 + 0.06 * self.wave(t, 0.23 + 0.1 * i as f64, 3);
                    p.shoulder_abduct[i] = 0.35;
                }
            }
            _ => {}
        }
        p
    }
}

impl Plan {
    fn local(&self, t: f64) -> f64 {
        (t - self.start).max(0.0)
    }

    fn phase(&self, traits: &Traits, t: f64) -> f64 {
        let l = self.local(t);
        let mut phase = self.phase0 + TAU * self.freq * l;
        if self.activity == Activity::WalkingUnsteadily {
            // Irregular steps: the cadence wanders smoothly.
            phase += 0.6 * traits.wave(l, 0.31, 2) + 0.4 * traits.wave(l, 0.53, 3);
        }
        phase
    }

    /// The activity's own pose, before blending from the previous step.
    fn raw_pose(&self, traits: &Traits, t: f64) -> PoseParams {
        let l = self.local(t);
        match self.activity {
            Activity::Standing => traits.standing(l),
            Activity::LyingDown => traits.lying(self.lying, l),
            Activity::SittingOnFloor => traits.sitting(l),
            Activity::FallingDown => {
                let tau = (l / self.motion_time).min(1.0);
                traits.falling(self.lying, tau * tau, l)
            }
            Activity::GettingUp => {
                let tau = (l / self.motion_time).min(1.0);
                traits.falling(self.lying, 1.0 - smoothstep(tau), l)
            }
            Activity::Crawling => traits.crawling(self.phase(traits, t), self.amp),
            a => traits.gait(a, self.phase(traits, t), self.amp, l),
        }
    }

    fn root(&self, t: f64) -> DVec2 {
        self.route.at(self.speed * self.local(t))
    }

    fn raw_heading(&self, traits: &Traits, t: f64) -> f64 {
        if self.speed <= 0.0 {
            return self.heading0;
        }
        let walked = self.speed * (self.end - self.start);
        let mut h = self
            .route
            .heading(self.speed * self.local(t), 0.25, walked)
            .unwrap_or(self.heading0);
        if self.activity == Activity::WalkingUnsteadily {
            h += 0.15 * traits.sway * traits.wave(self.local(t), 0.19, 0);
        }
        h
    }

    fn pose(&self, traits: &Traits, t: f64) -> (PoseParams, f64) {
        let raw = self.raw_pose(traits, t);
        let heading = self.raw_heading(traits, t);
        let l = self.local(t);
        if l >= self.blend {
            return (raw, heading);
        }
        let w = smoothstep(l / self.blend);
        let h = self.from_heading + normalize_angle(heading - self.from_heading) * w;
        (self.from.lerp(&raw, w), h)
    }
}

impl Person {
    /// Builds the person of a scene; `seed` drives per-person traits and per-episode choices.
    /// Errors name the script step whose path runs through furniture.
    pub fn new(spec: &PersonSpec, world: &World, seed: u64) -> Result<Self, SceneError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let b = spec.body;
        let mut vary = |x: f64| x * (1.0 + b.variation * rng.random_range(-1.0..=1.0));
        let height = vary(b.height);
        let girth = vary(b.girth);
        let (pace, stride, sway) = (vary(b.pace), vary(b.stride), vary(b.sway));
        let mut phases = [0.0; 6];
        for p in &mut phases {
            *p = rng.random_range(0.0..TAU);
        }
        let traits = Traits {
            dims: BodyDims::new(height, girth),
            pace,
            stride,
            sway,
            phases,
        };
        let start = spec.start.to_pose();
        let mut person = Person {
            steps: spec.script.clone(),
            repeat: spec.repeat,
            traits,
            rng,
            plans: Vec::new(),
            next_step: 0,
            current: 0,
            world: world.clone(),
            first_pass_planned: false,
        };
        let first = person.make_plan(0.0, start.position(), start.theta, None)?;
        person.plans.push(first);
        // Plan the whole first pass now, so path errors surface before simulating.
        while person.next_step < person.steps.len() {
            person.extend()?;
        }
        person.first_pass_planned = true;
        Ok(person)
    }

    pub fn traits(&self) -> &Traits {
        &self.traits
    }

    /// The script step to plan next, and its index in the script for error messages.
    fn step_to_plan(&self) -> Option<(usize, ScriptStep)> {
        let n = self.steps.len();
        if self.next_step < n || self.repeat {
            let i = self.next_step % n;
            return Some((i, self.steps[i].clone()));
        }
        None
    }

    /// Resolves the next script step, starting at `start` from `prev` (root, heading, pose).
    fn make_plan(
        &mut self,
        start: f64,
        root: DVec2,
        heading: f64,
        prev: Option<(&Plan, PoseParams)>,
    ) -> Result<Plan, SceneError> {
        let (index, step) = match self.step_to_plan() {
            Some(s) => s,
            None => {
                // After the script: the last activity goes on, a fall ends lying, getting up standing.
                let last = self
                    .plans
                    .last()
                    .map(|p| p.activity)
                    .unwrap_or(Activity::Standing);
                let activity = match last {
                    Activity::FallingDown => Activity::LyingDown,
                    Activity::GettingUp => Activity::Standing,
                    a => a,
                };
                let mut s = self.steps[self.steps.len() - 1].clone();
                s.activity = activity;
                s.duration = f64::INFINITY;
                s.fall = None;
                // A walk goes on over the route it was checked on, from where it is; the
                // script's path from here would cut across to its first point.
                s.path = match self.plans.last() {
                    Some(last) if is_locomotion(activity) => {
                        let walked = last.speed * last.local(last.end);
                        let ahead = last.route.ahead(walked);
                        ahead.into_iter().map(|p| [p.x, p.y]).collect()
                    }
                    _ => Vec::new(),
                };
                (self.steps.len() - 1, s)
            }
        };
        self.next_step += 1;
        let a = step.activity;
        let prev_activity = prev.map(|(p, _)| p.activity);
        // After a fall, lying or getting up the body stays on the side it fell on.
        let keeps_side = matches!(
            prev_activity,
            Some(Activity::FallingDown | Activity::LyingDown | Activity::GettingUp)
        );
        let lying = match (a, step.fall, prev) {
            (Activity::FallingDown, Some(d), _) => d,
            (Activity::FallingDown, None, _) => [
                FallDirection::Forward,
                FallDirection::Backward,
                FallDirection::Left,
                FallDirection::Right,
            ][self.rng.random_range(0..4)],
            (_, _, Some((p, _))) if keeps_side => p.lying,
            _ => [
                FallDirection::Backward,
                FallDirection::Left,
                FallDirection::Right,
            ][self.rng.random_range(0..3)],
        };
        // Lying down without a fall, or getting up without being on the floor first (a
        // script's first step), lays the body on a side drawn here: it needs the room a
        // fall's landing needs.
        // Getting up from sitting or crawling is left alone: random scripts do it all the
        // time, and checking it would draw some of them again.
        let lies_down_unchecked = !keeps_side
            && match a {
                Activity::LyingDown => true,
                Activity::GettingUp => !prev_activity.is_some_and(Activity::is_on_floor),
                _ => false,
            };
        let (base_speed, base_freq) = gait_defaults(a);
        let speed = step.speed.unwrap_or(
            base_speed * self.traits.pace * self.traits.stride * self.rng.random_range(0.9..=1.1),
        );
        let freq = base_freq * self.traits.pace;
        // Hip amplitude that makes the stance foot move back at the walking speed on average
        // over a step (it slides within the step: docs/simulator.md, "Body model"):
        // stride = speed / freq = 4 * leg * sin(amp).
        let leg = self.traits.dims.leg_length();
        let amp = if a == Activity::Crawling {
            0.22
        } else if freq > 0.0 {
            ((speed / freq) / (4.0 * leg)).clamp(0.0, 0.9).asin()
        } else {
            0.0
        };
        let blend: f64 = match (prev.map(|(p, _)| p.activity), a) {
            (None, _) => 0.0,
            (_, Activity::FallingDown) => 0.15,
            (Some(Activity::FallingDown), Activity::LyingDown) => 0.2,
            (_, Activity::LyingDown | Activity::SittingOnFloor) => 1.0,
            (_, Activity::GettingUp) => 0.5,
            _ => 0.4,
        };
        let blend = blend.min(step.duration);
        let mut plan = Plan {
            activity: a,
            start,
            end: start + step.duration,
            route: Route::new(vec![root]),
            speed: if is_locomotion(a) { speed } else { 0.0 },
            freq,
            amp,
            phase0: self.rng.random_range(0.0..TAU),
            heading0: heading,
            blend,
            from: PoseParams::default(),
            from_heading: heading,
            lying,
            motion_time: step.duration.min(15.0),
        };
        // A fall needs room on the floor: the body may twist as it goes down, or fall
        // another way, so that it lands clear of walls and furniture. Lying down without a
        // fall takes the same care; there the pelvis stays where it was and the feet go
        // where the re-anchoring below puts them.
        let mut heading = heading;
        // How far the body turns from the previous step's heading to find room.
        let mut twist = 0.0;
        if a == Activity::FallingDown || lies_down_unchecked {
            let world = &self.world;
            let (verb, key) = if a == Activity::FallingDown {
                ("fall", format!("person.script[{index}].fall"))
            } else {
                ("lie", format!("person.script[{index}]"))
            };
            let feet = |dir: FallDirection, heading: f64| match prev {
                Some((_, prev_pose)) if a != Activity::FallingDown => {
                    root + rotate(
                        prev_pose.pelvis - self.traits.lying(dir, 0.0).pelvis,
                        heading,
                    )
                }
                _ => root,
            };
            let height = self.traits.dims.height;
            match fall_direction(world, feet, heading, height, plan.lying, verb) {
                Ok((lying, turn)) => {
                    plan.lying = lying;
                    twist = turn;
                    heading += twist;
                    plan.heading0 = heading;
                }
                Err(_) if self.first_pass_planned => {}
                Err(message) => return Err(SceneError::Refused { key, message }),
            }
        }
        // Re-anchor the root so the pelvis stays where the previous step left it.
        let nominal_pelvis = plan.raw_pose(&self.traits, start).pelvis;
        let root = match prev {
            Some((_, prev_pose)) => root + rotate(prev_pose.pelvis - nominal_pelvis, heading),
            None => root,
        };
        let mut points = vec![root];
        points.extend(step.path.iter().map(|p| DVec2::new(p[0], p[1])));
        if !self.first_pass_planned {
            let world = &self.world;
            for (j, w) in points.windows(2).enumerate() {
                let blocked = world.furniture.iter().enumerate().find(|(_, f)| {
                    f.person_blocks
                        .iter()
                        .any(|s| s.crosses_segment(w[0], w[1]))
                });
                let outside = world.wall_clearance(w[1]) < 0.0
                    || crate::shapes::segments_cross_outline(w[0], w[1], &world.outline);
                if let Some((fi, _)) = blocked {
                    return Err(path_error(
                        index,
                        j,
                        format!(
                            "the walk to this point crosses {}",
                            describe(world, Some(fi))
                        ),
                    ));
                }
                if outside {
                    return Err(path_error(
                        index,
                        j,
                        "the walk to this point leaves the room".to_string(),
                    ));
                }
            }
        }
        plan.route = Route::new(points);
        // Cover the path a whole number of times (ending at its last point or back at its
        // start), so where the next step starts does not depend on the random speed.
        let len = plan.route.length();
        if plan.speed > 0.0 && step.speed.is_none() && step.duration.is_finite() && len > 1e-9 {
            let laps = (step.duration * plan.speed / len).round().max(1.0);
            let fitted = laps * len / step.duration;
            if (0.6 * plan.speed..=1.5 * plan.speed).contains(&fitted) {
                plan.speed = fitted;
                if a != Activity::Crawling && freq > 0.0 {
                    plan.amp = ((fitted / freq) / (4.0 * leg)).clamp(0.0, 0.9).asin();
                }
            }
        }
        if let Some(first) = plan.route.points.get(1) {
            let d = *first - root;
            if d.length() > 1e-9 {
                plan.heading0 = d.to_angle();
            }
        }
        if let Some((_, mut prev_pose)) = prev {
            // The blend starts from the previous heading, about the re-anchored root: seen from
            // there, the pelvis is where the previous step left it. Without a twist that is
            // `nominal_pelvis`; with one, the root moved by the pelvis offset turned by the
            // twist, and taking `nominal_pelvis` jumped the body a quarter to half a metre in
            // 1 ms when lying down (or getting up) from standing. A fall starts standing, its pelvis
            // within 5 mm of `nominal_pelvis`: a twisted one keeps it, as the datasets were
            // made (it moves no body point faster than an untwisted fall does).
            prev_pose.pelvis = if twist == 0.0 || a == Activity::FallingDown {
                nominal_pelvis
            } else {
                prev_pose.pelvis - rotate(prev_pose.pelvis - nominal_pelvis, twist)
            };
            plan.from = prev_pose;
        } else {
            plan.from = plan.raw_pose(&self.traits, start);
        }
        // A script that starts sitting is held to validation's wider circle around
        // `person.start` instead.
        let on_floor = match a {
            Activity::Crawling => Some("crawl"),
            Activity::SittingOnFloor if prev.is_some() => Some("sit"),
            _ => None,
        };
        if let Some(verb) = on_floor.filter(|_| !self.first_pass_planned) {
            check_room_on_floor(&self.world, &self.traits, &plan, index, verb)?;
        }
        Ok(plan)
    }

    fn extend(&mut self) -> Result<(), SceneError> {
        let Some(last) = self.plans.last().cloned() else {
            return Ok(());
        };
        let end = last.end;
        let (pose, heading) = last.pose(&self.traits, end);
        let root = last.root(end);
        let plan = self.make_plan(end, root, heading, Some((&last, pose)))?;
        self.plans.push(plan);
        Ok(())
    }

    /// The person at time `t` seconds from the scene start. Times should not go backwards
    /// by more than one script step (the simulator only moves forward).
    pub fn state_at(&mut self, t: f64) -> PersonState {
        while self.plans[self.current].end <= t {
            if self.current + 1 >= self.plans.len() && self.extend().is_err() {
                break; // cannot happen after the first pass; stay in the current step
            }
            if self.current + 1 >= self.plans.len() {
                break;
            }
            self.current += 1;
            // Keep memory bounded over hours of repeats.
            if self.current > 64 {
                self.plans.drain(..32);
                self.current -= 32;
            }
        }
        while self.current > 0 && self.plans[self.current].start > t {
            self.current -= 1;
        }
        let plan = &self.plans[self.current];
        let (pose, yaw) = plan.pose(&self.traits, t);
        let root = plan.root(t);
        let parts = capsules(&self.traits.dims, &pose, root, yaw);
        PersonState {
            position: root + rotate(pose.pelvis, yaw),
            yaw: normalize_angle(yaw),
            activity: plan.activity,
            parts,
        }
    }
}

/// Room a fallen body needs on each side of its axis, metres.
const FALLEN_BODY_HALF_WIDTH: f64 = 0.12;

/// What a body lying on the floor from `feet` along the unit vector `axis`, `length` metres
/// long, would hit: nine points along it need `half_width` from walls and furniture.
/// `Some(None)` is a wall, `Some(Some(i))` furniture `i`.
fn body_axis_blocker(
    world: &World,
    feet: DVec2,
    axis: DVec2,
    length: f64,
    half_width: f64,
) -> Option<Option<usize>> {
    (1..=9).find_map(|k| {
        let p = feet + axis * (length * k as f64 / 10.0);
        let (clearance, what) = world.person_clearance(p);
        (clearance < half_width).then_some(what)
    })
}

/// How a fall lands clear of walls and furniture: `wanted` straight on when it fits, else
/// the smallest twist of the body (up to 60 degrees either way), else another direction with
/// the smallest twist. A scripted direction is a preference: the person's random size and
/// sway decide where exactly they stand and face when they fall. `feet(direction, heading)`
/// is where the feet of the body lying that way end up; `verb` names the motion in the
/// error. Returns the direction and the twist (radians, added to the heading).
fn fall_direction(
    world: &World,
    feet: impl Fn(FallDirection, f64) -> DVec2,
    heading: f64,
    height: f64,
    wanted: FallDirection,
    verb: &str,
) -> Result<(FallDirection, f64), String> {
    let blocker = |dir: FallDirection, twist: f64| {
        let axis = rotate(lying_vector(dir), heading + twist);
        body_axis_blocker(
            world,
            feet(dir, heading + twist),
            axis,
            height,
            FALLEN_BODY_HALF_WIDTH,
        )
    };
    let order = [
        FallDirection::Forward,
        FallDirection::Backward,
        FallDirection::Left,
        FallDirection::Right,
    ];
    let first = order.iter().position(|&d| d == wanted).unwrap_or(0);
    let twists = [0.0, 15.0, -15.0, 30.0, -30.0, 45.0, -45.0, 60.0, -60.0_f64];
    let mut wanted_blocker = None;
    for k in 0..order.len() {
        let dir = order[(first + k) % order.len()];
        for twist in twists.map(f64::to_radians) {
            match blocker(dir, twist) {
                None => return Ok((dir, twist)),
                Some(what) if k == 0 && twist == 0.0 => wanted_blocker = Some(what),
                Some(_) => {}
            }
        }
    }
    Err(format!(
        "no room to {verb} here: the body would hit {}, and walls or furniture every other way",
        describe(world, wanted_blocker.flatten())
    ))
}

/// Crawling, and sitting down on the floor later in a script, put the body on the floor
/// where the step starts (a crawler's legs trail behind, a seated body's feet reach ahead
/// and its hands behind). A script that starts crawling needs a fall's room along the body
/// from its rearmost to its foremost joint. Later steps start where the script has taken
/// the person, and the shipped scenes and random scripts sit and crawl off closer to walls
/// and furniture than that: there only the body's axis must stay out of them, which still
/// refuses a body going through a wall. The step's own body is checked, not the pose it
/// blends from. `verb` names the motion in the error.
fn check_room_on_floor(
    world: &World,
    traits: &Traits,
    plan: &Plan,
    index: usize,
    verb: &str,
) -> Result<(), SceneError> {
    let pose = plan.raw_pose(traits, plan.start);
    let heading = plan.raw_heading(traits, plan.start);
    let root = plan.root(plan.start);
    let axis = DVec2::from_angle(heading);
    let (behind, ahead) = capsules(&traits.dims, &pose, root, heading)
        .iter()
        .flat_map(|c| [c.a, c.b])
        .map(|end| (end.truncate() - root).dot(axis))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    let half_width = if index == 0 {
        FALLEN_BODY_HALF_WIDTH
    } else {
        0.0
    };
    match body_axis_blocker(
        world,
        root + axis * behind,
        axis,
        ahead - behind,
        half_width,
    ) {
        Some(what) => Err(SceneError::Refused {
            key: format!("person.script[{index}]"),
            message: format!(
                "no room to {verb} here: the body would reach into {}",
                describe(world, what)
            ),
        }),
        None => Ok(()),
    }
}

fn path_error(step: usize, point: usize, message: String) -> SceneError {
    SceneError::Refused {
        key: format!("person.script[{step}].path[{point}]"),
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    fn scene(script: &str) -> Scene {
        let text = format!(
            "duration: 60\nroom: {{outline: [[0,0],[8,0],[8,6],[0,6]]}}\nrobot: {{start: {{x: 0.5, y: 0.5}}}}\nperson:\n  start: {{x: 4, y: 3}}\n  script:\n{script}"
        );
        Scene::parse(&text, "test").unwrap()
    }

    #[test]
    fn the_heading_kilometres_along_a_route_is_the_heading_at_that_phase() {
        // A runner back and forth over 4 m for hours: tens of kilometres along the route,
        // arcs spanning the turnarounds. A hang fails the test rather than stalling it.
        let (done, finished) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let route = Route::new(vec![DVec2::new(1.0, 2.0), DVec2::new(4.9137, 2.3)]);
            let period = 2.0 * route.length();
            let mut worst: f64 = 0.0;
            // Every scan of a 3.1 m/s runner at 20 Hz for two hours (after the first metre,
            // where the arc is clipped at the start).
            for k in 10..144_000 {
                let s = 0.155 * k as f64;
                let far = route.heading(s, 0.25, f64::INFINITY).unwrap();
                let near = route
                    .heading(period + s.rem_euclid(period), 0.25, f64::INFINITY)
                    .unwrap();
                worst = worst.max(normalize_angle(far - near).abs());
            }
            let _ = done.send(worst);
        });
        let worst = finished
            .recv_timeout(std::time::Duration::from_secs(20))
            .expect("heading() returns");
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn a_walk_ending_at_a_turnaround_ends_facing_the_way_it_came() {
        // Out to x = 6 and back (the walk is fitted to whole laps), then a fall forward: the
        // person arrives heading west, stands facing west and falls west.
        for seed in 0..4 {
            let s = scene(
                "    - {activity: walking, duration: 3.4, path: [[6,3]]}\n    - {activity: standing, duration: 1}\n    - {activity: falling_down, duration: 1, fall: forward}\n    - {activity: lying_down, duration: 2}\n",
            );
            let world = World::new(&s);
            let mut p = Person::new(s.person.as_ref().unwrap(), &world, seed).unwrap();
            let standing = p.state_at(3.9);
            let arrival = (p.state_at(3.4).position - p.state_at(3.0).position).to_angle();
            assert!(
                normalize_angle(standing.yaw - arrival).abs() < 0.35,
                "seed {seed}: standing at yaw {} after arriving at {arrival}",
                standing.yaw
            );
            let fall = p.state_at(7.0).position - standing.position;
            assert!(
                normalize_angle(fall.to_angle() - arrival).abs() < 0.6,
                "seed {seed}: fell towards {} after arriving at {arrival}",
                fall.to_angle()
            );
        }
    }

    fn max_jump(person: &mut Person, t0: f64, t1: f64, dt: f64) -> f64 {
        let mut prev = person.state_at(t0);
        let mut worst: f64 = 0.0;
        let mut t = t0 + dt;
        while t <= t1 {
            let s = person.state_at(t);
            for (k, (a, b)) in prev.parts.iter().zip(s.parts.iter()).enumerate() {
                let j = (a.a - b.a).length().max((a.b - b.b).length());
                assert!(j < 0.02, "part {k} jumps {j} m at t = {t} ({})", s.activity);
                worst = worst.max(j);
            }
            prev = s;
            t += dt;
        }
        worst
    }

    #[test]
    fn consecutive_activities_join_without_jumps() {
        let s = scene(
            "    - {activity: standing, duration: 1}\n    - {activity: walking, duration: 3, path: [[6,3]]}\n    - {activity: running, duration: 2, path: [[2,3]]}\n    - {activity: walking_unsteadily, duration: 2, path: [[4,4]]}\n    - {activity: falling_down, duration: 1}\n    - {activity: lying_down, duration: 2}\n    - {activity: getting_up, duration: 2}\n    - {activity: sitting_on_floor, duration: 2}\n    - {activity: crawling, duration: 3, path: [[3,3]]}\n    - {activity: standing, duration: 2}\n",
        );
        let world = World::new(&s);
        let mut p = Person::new(s.person.as_ref().unwrap(), &world, 5).unwrap();
        // At 1 kHz no body point moves more than 2 cm (20 m/s, far above running limbs).
        let jump = max_jump(&mut p, 0.0, 20.0, 0.001);
        assert!(jump < 0.02, "largest per-millisecond jump {jump} m");
    }

    #[test]
    fn fall_takes_the_body_to_the_floor() {
        let s = scene(
            "    - {activity: standing, duration: 1}\n    - {activity: falling_down, duration: 1, fall: backward}\n    - {activity: lying_down, duration: 5}\n",
        );
        let world = World::new(&s);
        let mut p = Person::new(s.person.as_ref().unwrap(), &world, 1).unwrap();
        let top = |st: &PersonState| {
            st.parts
                .iter()
                .map(|c| c.a.z.max(c.b.z) + c.radius)
                .fold(0.0, f64::max)
        };
        let before = p.state_at(0.9);
        assert!(top(&before) > 1.5);
        let after = p.state_at(2.1);
        assert_eq!(after.activity, Activity::LyingDown);
        assert!(top(&after) < 0.35, "lying body top at {}", top(&after));
        assert!(
            (after.position - before.position).length() > 0.7,
            "the pelvis ends about a leg's length away"
        );
    }

    #[test]
    fn a_body_lying_after_a_fall_rests_on_the_floor_every_way() {
        // A foot at a right angle (face down) or a spread arm (on the side) once propped the
        // body up, so that a Lidar 10 cm above the floor saw little more than the feet.
        for dir in ["forward", "backward", "left", "right"] {
            let s = scene(&format!(
                "    - {{activity: standing, duration: 1}}\n    - {{activity: falling_down, duration: 1, fall: {dir}}}\n    - {{activity: lying_down, duration: 5}}\n"
            ));
            let world = World::new(&s);
            let mut p = Person::new(s.person.as_ref().unwrap(), &world, 1).unwrap();
            let st = p.state_at(4.0);
            let low = |c: &Capsule| c.a.z.min(c.b.z) - c.radius;
            let high = |c: &Capsule| c.a.z.max(c.b.z) + c.radius;
            let cut = st
                .parts
                .iter()
                .filter(|c| low(c) < 0.10 && high(c) > 0.10)
                .count();
            let top = st.parts.iter().map(high).fold(0.0, f64::max);
            let torso = &st.parts[10];
            assert!(
                low(torso) < 0.10 && high(torso) > 0.10,
                "{dir}: the trunk misses the 0.10 m scan plane"
            );
            assert!(
                cut >= 4,
                "{dir}: only {cut} of 12 parts reach the 0.10 m scan plane"
            );
            assert!(top < 0.5, "{dir}: lying body reaches {top:.2} m");
        }
    }

    #[test]
    fn a_fall_lands_clear_of_walls_and_furniture() {
        // Standing 0.4 m from the wall at x = 0, facing +x: a backward fall would go through
        // the wall; with a box behind and beside, only forward (or a twist) is free.
        let text = "duration: 60\nroom: {outline: [[0,0],[8,0],[8,6],[0,6]]}\nfurniture: [{kind: box, center: [0.6, 1.9], size: [1.0, 1.0], height: 0.5}]\nrobot: {start: {x: 6, y: 5}}\nperson:\n  start: {x: 0.4, y: 3, yaw_deg: 0}\n  script:\n    - {activity: standing, duration: 1}\n    - {activity: falling_down, duration: 1, fall: backward}\n    - {activity: lying_down, duration: 5}\n";
        let s = Scene::parse(text, "test").unwrap();
        let world = World::new(&s);
        for seed in 0..6 {
            let mut p = Person::new(s.person.as_ref().unwrap(), &world, seed).unwrap();
            let lying = p.state_at(3.0);
            assert_eq!(lying.activity, Activity::LyingDown);
            for part in &lying.parts {
                for end in [part.a, part.b] {
                    let (clearance, what) = world.person_clearance(end.truncate());
                    assert!(
                        clearance > 0.0,
                        "seed {seed}: body part at {end} inside {what:?} (clearance {clearance})"
                    );
                }
            }
        }
        // A spot boxed in on every side has no room to fall: a clear error naming the step.
        let cramped = "duration: 60\nroom: {outline: [[0,0],[1.2,0],[1.2,1.2],[0,1.2]]}\nrobot: {start: {x: 0.2, y: 0.2}}\nperson:\n  start: {x: 0.6, y: 0.6}\n  script:\n    - {activity: standing, duration: 1}\n    - {activity: falling_down, duration: 1}\n";
        let s = Scene::parse(cramped, "test").unwrap();
        let world = World::new(&s);
        let err = Person::new(s.person.as_ref().unwrap(), &world, 1).unwrap_err();
        assert!(
            err.to_string().contains("person.script[1].fall")
                && err.to_string().contains("no room"),
            "{err}"
        );
    }

    /// The least clearance from walls and furniture of the ends of the body's parts at `t`
    /// (of the trunk alone with `trunk_only`).
    fn body_clearance(person: &mut Person, world: &World, t: f64, trunk_only: bool) -> f64 {
        let st = person.state_at(t);
        let parts = if trunk_only {
            &st.parts[10..11]
        } else {
            &st.parts[..]
        };
        parts
            .iter()
            .flat_map(|c| [c.a, c.b])
            .map(|end| world.person_clearance(end.truncate()).0)
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn lying_down_without_a_fall_lies_clear_of_the_wall() {
        // 0.11 m from the wall at y = 0, facing along it: lying backward (along the wall) or
        // on the right side (into it) put the body through the wall; such a side is drawn
        // at random for a script that starts lying or getting up, or lies down standing.
        // Like a fall's landing, the trunk lies clear; a limb may still touch the wall.
        let room = |y: f64, script: &str| {
            let text = format!(
                "duration: 30\nroom: {{outline: [[0,0],[8,0],[8,6],[0,6]]}}\nrobot: {{start: {{x: 7, y: 5}}}}\nperson:\n  start: {{x: 4, y: {y}, yaw_deg: 0}}\n  script:\n{script}"
            );
            Scene::parse(&text, "test").unwrap()
        };
        for (y, script, t) in [
            (0.11, "    - {activity: lying_down, duration: 5}\n", 1.0),
            (0.11, "    - {activity: getting_up, duration: 3}\n", 0.0),
            (
                1.2,
                "    - {activity: standing, duration: 1}\n    - {activity: lying_down, duration: 5}\n",
                3.0,
            ),
        ] {
            let s = room(y, script);
            let world = World::new(&s);
            for seed in 0..8 {
                let mut p = Person::new(s.person.as_ref().unwrap(), &world, seed).unwrap();
                let clear = body_clearance(&mut p, &world, t, true);
                assert!(
                    clear > FALLEN_BODY_HALF_WIDTH,
                    "seed {seed}, {script}: the trunk {clear} m from the wall"
                );
            }
        }
        // A spot boxed in on every side has no room to lie: an error naming the step.
        let cramped = "duration: 60\nroom: {outline: [[0,0],[1.2,0],[1.2,1.2],[0,1.2]]}\nrobot: {start: {x: 0.2, y: 0.2}}\nperson:\n  start: {x: 0.6, y: 0.6}\n  script:\n    - {activity: standing, duration: 1}\n    - {activity: lying_down, duration: 5}\n";
        let s = Scene::parse(cramped, "test").unwrap();
        let err = Person::new(s.person.as_ref().unwrap(), &World::new(&s), 1)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("person.script[1]: no room to lie here: the body would hit a wall"),
            "{err}"
        );
    }

    /// Lying down from standing where the drawn side has no room twists the body: the root
    /// was re-anchored with the new heading while the blend set off from the old one with
    /// the lying pelvis, and the whole body jumped a quarter to half a metre in 1 ms. Getting
    /// up from standing twists the same way; a twisted fall (left as it was) does not jump.
    #[test]
    fn a_body_turned_to_find_room_joins_without_jumps() {
        // Three thin posts around the spot leave room to lie only some ways.
        let posts = "furniture:\n  - {kind: cylinder, center: [2.3, 2.5], radius: 0.05, height: 0.5}\n  - {kind: cylinder, center: [3, 3.2], radius: 0.05, height: 0.5}\n  - {kind: cylinder, center: [3, 1.8], radius: 0.05, height: 0.5}\n";
        let mut twisted = 0;
        for (then, fall) in [
            ("lying_down", ""),
            ("getting_up", ""),
            ("falling_down", ", fall: backward"),
            ("falling_down", ""),
        ] {
            let text = format!(
                "duration: 8\nroom: {{outline: [[0,0],[6,0],[6,5],[0,5]]}}\n{posts}robot: {{start: {{x: 0.5, y: 0.5}}}}\nperson:\n  start: {{x: 3, y: 2.5}}\n  script:\n    - {{activity: standing, duration: 2}}\n    - {{activity: {then}, duration: 4{fall}}}\n"
            );
            let s = Scene::parse(&text, "test").unwrap();
            let world = World::new(&s);
            for seed in 0..8 {
                let mut p = Person::new(s.person.as_ref().unwrap(), &world, seed).unwrap();
                let jump = max_jump(&mut p, 1.9, 3.5, 0.001);
                assert!(jump < 0.02, "{then}, seed {seed}: {jump} m in 1 ms");
                let step = &p.plans[1];
                if normalize_angle(step.heading0 - step.from_heading).abs() > 0.1 {
                    twisted += 1;
                }
            }
        }
        assert!(twisted >= 8, "only {twisted} bodies twisted");
    }

    #[test]
    fn a_script_that_starts_crawling_needs_room_for_the_legs() {
        // Crawling away from a wall 0.3 m behind: the legs trail about 0.9 m.
        let text = |x: f64| {
            format!(
                "duration: 10\nroom: {{outline: [[0,0],[8,0],[8,6],[0,6]]}}\nrobot: {{start: {{x: 7, y: 5}}}}\nperson:\n  start: {{x: {x}, y: 3}}\n  script:\n    - {{activity: crawling, duration: 5, path: [[4, 3]]}}\n"
            )
        };
        let s = Scene::parse(&text(0.3), "test").unwrap();
        let err = Person::new(s.person.as_ref().unwrap(), &World::new(&s), 1)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(
                "person.script[0]: no room to crawl here: the body would reach into a wall"
            ),
            "{err}"
        );
        let s = Scene::parse(&text(1.2), "test").unwrap();
        let world = World::new(&s);
        let mut p = Person::new(s.person.as_ref().unwrap(), &world, 1).unwrap();
        assert!(body_clearance(&mut p, &world, 0.0, false) > 0.0);
    }

    #[test]
    fn sitting_or_crawling_later_in_a_script_needs_the_room_a_first_step_needs() {
        // Standing 0.25 m from the wall at y = 0, then sitting down facing it or crawling
        // away from it: unchecked, the seated body went 0.70 m through the wall, the
        // crawler's legs 0.46 m.
        let text = |y: f64, yaw: f64, later: &str| {
            format!(
                "duration: 8\nroom: {{outline: [[0,0],[5,0],[5,4],[0,4]]}}\nrobot: {{start: {{x: 4.5, y: 3.5}}}}\nperson:\n  start: {{x: 2.5, y: {y}, yaw_deg: {yaw}}}\n  script:\n    - {{activity: standing, duration: 2}}\n    - {later}\n"
            )
        };
        let sit = "{activity: sitting_on_floor, duration: 6}";
        let crawl = "{activity: crawling, duration: 6, path: [[2.5, 2.5]]}";
        let err = |text: String| {
            let s = Scene::parse(&text, "test").unwrap();
            Person::new(s.person.as_ref().unwrap(), &World::new(&s), 1)
                .unwrap_err()
                .to_string()
        };
        let e = err(text(0.25, -90.0, sit));
        assert_eq!(
            e,
            "person.script[1]: no room to sit here: the body would reach into a wall"
        );
        let e = err(text(0.25, 90.0, crawl));
        assert_eq!(
            e,
            "person.script[1]: no room to crawl here: the body would reach into a wall"
        );
        // With room, both go ahead, clear of the wall.
        for (y, yaw, later) in [(1.5, -90.0, sit), (1.2, 90.0, crawl)] {
            let s = Scene::parse(&text(y, yaw, later), "test").unwrap();
            let world = World::new(&s);
            let mut p = Person::new(s.person.as_ref().unwrap(), &world, 1).unwrap();
            for t in [2.5, 4.0, 7.5] {
                assert!(
                    body_clearance(&mut p, &world, t, false) > 0.0,
                    "{later} at {t}"
                );
            }
        }
    }

    /// A repeating script's later falls find room as the first pass's do: the person may
    /// stand elsewhere by then, and a fall drawn at random went through the corridor's wall.
    #[test]
    fn falls_of_a_repeating_script_land_clear_of_the_walls_in_every_pass() {
        let text = "duration: 60\nroom: {outline: [[0,0],[8,0],[8,1.4],[0,1.4]]}\nrobot: {start: {x: 7.5, y: 0.7}}\nperson:\n  start: {x: 4, y: 0.7, yaw_deg: 0}\n  repeat: true\n  script:\n    - {activity: standing, duration: 2}\n    - {activity: falling_down, duration: 1}\n    - {activity: lying_down, duration: 3}\n    - {activity: getting_up, duration: 2}\n";
        let s = Scene::parse(text, "test").unwrap();
        let world = World::new(&s);
        for seed in 0..20 {
            let mut p = Person::new(s.person.as_ref().unwrap(), &world, seed).unwrap();
            for pass in 0..3 {
                let t = 5.0 + 8.0 * pass as f64;
                let clearance = body_clearance(&mut p, &world, t, true);
                assert!(
                    clearance > 0.0,
                    "seed {seed}, pass {pass}: trunk {clearance:.2} m"
                );
            }
        }
    }

    /// After a script that ends walking, the walk goes on over its own route: it used to go
    /// from the last point straight back to the first, here through the box in the middle.
    #[test]
    fn a_walk_that_goes_on_after_the_script_keeps_to_its_route() {
        let text = "duration: 40\nroom: {outline: [[0,0],[6,0],[6,6],[0,6]]}\nfurniture: [{kind: box, center: [3, 3], size: [2, 2], height: 0.5}]\nrobot: {start: {x: 0.4, y: 5.6}}\nperson:\n  start: {x: 1, y: 1, yaw_deg: 90}\n  script:\n    - {activity: walking, duration: 12, path: [[1,5],[5,5],[5,1]]}\n";
        // Fitted to end at the last point; at a given speed, on the way (8.4 m of 12).
        let at_speed = text.replace("[5,1]]}", "[5,1]], speed: 0.7}");
        for (text, seed) in [(text, 0), (text, 1), (text, 2), (at_speed.as_str(), 3)] {
            let s = Scene::parse(text, "test").unwrap();
            let world = World::new(&s);
            let mut p = Person::new(s.person.as_ref().unwrap(), &world, seed).unwrap();
            for step in 0..400 {
                let t = 0.1 * step as f64;
                let state = p.state_at(t);
                assert_eq!(state.activity, Activity::Walking);
                let (clearance, what) = world.person_clearance(state.position);
                assert!(clearance > 0.0, "seed {seed}, {t:.1} s: in {what:?}");
            }
        }
    }

    #[test]
    fn walking_path_is_followed_back_and_forth() {
        let s = scene("    - {activity: walking, duration: 100, path: [[6,3]], speed: 1.0}\n");
        let world = World::new(&s);
        let mut p = Person::new(s.person.as_ref().unwrap(), &world, 1).unwrap();
        // 2 m each way at 1 m/s: at t = 2 s at (6,3), at t = 4 s back at (4,3).
        assert!((p.state_at(2.0).position - DVec2::new(6.0, 3.0)).length() < 0.1);
        assert!((p.state_at(4.0).position - DVec2::new(4.0, 3.0)).length() < 0.1);
        // And the script's last step goes on: still walking after 10 minutes.
        assert_eq!(p.state_at(600.0).activity, Activity::Walking);
    }

    #[test]
    fn a_path_through_furniture_is_rejected_with_its_step() {
        let text = "duration: 10\nroom: {outline: [[0,0],[8,0],[8,6],[0,6]]}\nfurniture: [{kind: box, name: sofa, center: [5, 3], size: [1, 2], height: 0.8}]\nrobot: {start: {x: 0.5, y: 0.5}}\nperson:\n  start: {x: 3, y: 3}\n  script:\n    - {activity: standing, duration: 1}\n    - {activity: walking, duration: 5, path: [[7,3]]}\n";
        let s = Scene::parse(text, "t").unwrap();
        let err = Person::new(s.person.as_ref().unwrap(), &World::new(&s), 0)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("person.script[1].path[0]") && err.contains("sofa"),
            "{err}"
        );
        // Unnamed, the piece is named by its index alone; the error names no scene: the
        // caller, which holds the scene, does.
        let s = Scene::parse(&text.replace("name: sofa, ", ""), "t").unwrap();
        let err = Person::new(s.person.as_ref().unwrap(), &World::new(&s), 0).unwrap_err();
        assert_eq!(
            err.to_string(),
            "person.script[1].path[0]: the walk to this point crosses furniture[0]"
        );
    }
}
