//! Streaming activity classification, one model step per scan and state (see
//! `docs/model_contract.md`, "Windows and streaming").
//!
//! The model was trained on windows of `T` scans starting from a zero state and is right
//! after `T/2..=T` frames of history. Two states ("lanes") are stepped in parallel, each reset
//! every lane period `P` scans (`T` by default, or somewhat more: models stay right a little
//! past `T`), offset by `P/2`, and the prediction comes from the lane with the longer history.
//! So every prediction after warm-up has seen between `P/2` and `P` frames, and the state
//! never grows stale. A gap in the scans longer than `T` scan periods, or time going
//! backwards, restarts both lanes.
//!
//! The model is behind the small [`StepModel`] trait: the real one runs ONNX Runtime
//! (`lidar-har-infer`), tests use tiny deterministic ones.

use std::str::FromStr;

use glam::DVec2;
use ndarray::{Array2, ArrayView2};

use crate::activity::Activity;
use crate::representation::{Framing, Renderer, RepresentationSpec, SpecError};

/// One ConvLSTM step: consume a frame, update the state in place, return the class logits.
pub trait StepModel {
    type State;
    type Error: std::error::Error + Send + Sync + 'static;

    /// A fresh (zero) state.
    fn initial_state(&self) -> Self::State;
    /// Sets `state` back to the initial state without allocating.
    fn reset_state(&self, state: &mut Self::State);
    /// Finite logits, or an error that leaves `state` as it was: a broken model's NaN kept in
    /// the state would spoil every later step, and its logits would read as a class.
    fn step(
        &mut self,
        frame: ArrayView2<'_, f32>,
        state: &mut Self::State,
    ) -> Result<[f32; Activity::COUNT], Self::Error>;
}

/// What the streaming classifier needs to know about a model: how its input is made and
/// the window it was trained on. Carried by the model file's metadata.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSpec {
    pub representation: RepresentationSpec,
    /// Training window length `T`, scans.
    pub window: usize,
    /// The scan rate the model was trained at, Hz.
    pub scan_rate_hz: f64,
}

/// Why a stream spec (typically a model's metadata) is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StreamSpecError {
    #[error("metadata key '{0}' is missing")]
    Missing(&'static str),
    #[error("metadata key '{key}' = '{value}' is not valid: {reason}")]
    Invalid {
        key: &'static str,
        value: String,
        reason: String,
    },
    #[error(transparent)]
    Representation(#[from] SpecError),
    #[error("a lane period of {period} scans is shorter than the model's window of {window} scans")]
    LanePeriod { period: usize, window: usize },
    #[error(
        "{lanes} lanes: need at least 2 (a restarting lane has no history) and at most the lane period ({period} scans)"
    )]
    LaneCount { lanes: usize, period: usize },
    #[error(
        "{lanes} lanes with {lanes_between} more between each two make {states} states, more than the lane period's {period} scans (each restarts on a scan of its own)",
        states = .lanes * (1 + .lanes_between)
    )]
    LanesBetween {
        lanes: usize,
        lanes_between: usize,
        period: usize,
    },
}

impl StreamSpec {
    pub const KEY_REPRESENTATION: &'static str = "lidar_har.representation";
    pub const KEY_FRAMING: &'static str = "lidar_har.framing";
    pub const KEY_SIZE: &'static str = "lidar_har.size";
    pub const KEY_RESOLUTION: &'static str = "lidar_har.resolution_m";
    pub const KEY_WINDOW: &'static str = "lidar_har.window";
    /// The longest window a model may declare: minutes of scans at any Lidar's rate. A larger
    /// one is a broken file, and the lane schedule's arithmetic would overflow.
    pub const MAX_WINDOW: usize = 10_000;
    pub const KEY_SCAN_RATE: &'static str = "lidar_har.scan_rate_hz";
    /// Optional: the circle radius, metres (default [`RepresentationSpec::DEFAULT_MARK_RADIUS_M`]).
    pub const KEY_MARK_RADIUS: &'static str = "lidar_har.mark_radius_m";
    /// Optional: the ellipse semi-axes "along,across", metres.
    pub const KEY_ELLIPSE_AXES: &'static str = "lidar_har.ellipse_axes_m";

    /// Reads the spec from key/value metadata (the ONNX `metadata_props`).
    pub fn from_metadata(get: impl Fn(&str) -> Option<String>) -> Result<Self, StreamSpecError> {
        let mut representation = RepresentationSpec::new(
            parse_metadata(Self::KEY_REPRESENTATION, &get)?,
            parse_metadata(Self::KEY_FRAMING, &get)?,
            parse_metadata(Self::KEY_SIZE, &get)?,
            parse_metadata(Self::KEY_RESOLUTION, &get)?,
        );
        if get(Self::KEY_MARK_RADIUS).is_some() {
            representation.mark_radius_m = parse_metadata(Self::KEY_MARK_RADIUS, &get)?;
        }
        if let Some(axes) = get(Self::KEY_ELLIPSE_AXES) {
            let parsed: Vec<Result<f64, _>> =
                axes.split(',').map(|a| a.trim().parse::<f64>()).collect();
            match parsed.as_slice() {
                [Ok(a), Ok(b)] => representation.ellipse_axes_m = [*a, *b],
                _ => {
                    return Err(StreamSpecError::Invalid {
                        key: Self::KEY_ELLIPSE_AXES,
                        value: axes,
                        reason: "expected two numbers 'along,across'".into(),
                    });
                }
            }
        }
        let spec = Self {
            representation,
            window: parse_metadata(Self::KEY_WINDOW, &get)?,
            scan_rate_hz: parse_metadata(Self::KEY_SCAN_RATE, &get)?,
        };
        spec.validate()?;
        Ok(spec)
    }

    pub fn validate(&self) -> Result<(), StreamSpecError> {
        self.representation.validate()?;
        if !(2..=Self::MAX_WINDOW).contains(&self.window) {
            return Err(StreamSpecError::Invalid {
                key: Self::KEY_WINDOW,
                value: self.window.to_string(),
                reason: format!("the window must be 2..={} scans", Self::MAX_WINDOW),
            });
        }
        if !(self.scan_rate_hz.is_finite() && self.scan_rate_hz > 0.0) {
            return Err(StreamSpecError::Invalid {
                key: Self::KEY_SCAN_RATE,
                value: self.scan_rate_hz.to_string(),
                reason: "the scan rate must be finite and positive".into(),
            });
        }
        Ok(())
    }
}

/// Reads and parses metadata key `key`, naming it in the error.
pub(crate) fn parse_metadata<T: FromStr>(
    key: &'static str,
    get: &impl Fn(&str) -> Option<String>,
) -> Result<T, StreamSpecError>
where
    T::Err: std::fmt::Display,
{
    let value = get(key).ok_or(StreamSpecError::Missing(key))?;
    value
        .trim()
        .parse()
        .map_err(|e: T::Err| StreamSpecError::Invalid {
            key,
            value: value.clone(),
            reason: e.to_string(),
        })
}

/// One scan's input: the person as the localiser found them.
#[derive(Debug, Clone, Copy)]
pub struct PersonScan<'a> {
    pub stamp_s: f64,
    /// The person's points in the map frame (ignored when not visible).
    pub points: &'a [DVec2],
    /// The track's position, map frame; `None` when the person is not visible in this scan.
    pub position: Option<DVec2>,
    /// The Lidar's position in the map (orients ellipse marks).
    pub sensor: DVec2,
}

/// The classification of one scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    pub stamp_s: f64,
    pub activity: Activity,
    pub confidence: f32,
    /// Class probabilities, class order, finite and summing to 1.
    pub probabilities: [f32; Activity::COUNT],
    /// Frames of history behind this prediction (1..=the lane period).
    pub history: usize,
    /// At least `T/2` frames of history: what the model was trained for.
    pub ready: bool,
}

/// Softmax that stays finite for any finite or saturated logits: the maximum is subtracted
/// first; non-finite logits (a broken model) give a uniform distribution rather than NaN.
pub fn softmax(logits: &[f32; Activity::COUNT]) -> [f32; Activity::COUNT] {
    let uniform = [1.0 / Activity::COUNT as f32; Activity::COUNT];
    if logits.iter().any(|l| l.is_nan()) {
        return uniform;
    }
    let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    if !max.is_finite() {
        // All -inf, or some +inf: share among the maxima.
        let winners = logits.iter().filter(|&&l| l == max).count() as f32;
        return logits.map(|l| if l == max { 1.0 / winners } else { 0.0 });
    }
    let exp = logits.map(|l| (l - max).exp());
    let sum: f32 = exp.iter().sum(); // >= 1: the maximum contributes exp(0)
    exp.map(|e| e / sum)
}

struct Lane<S> {
    state: S,
    /// Frames since the last reset.
    history: usize,
    /// Room-fixed framing: the first visible position since the reset.
    centre: Option<DVec2>,
}

/// Why classification failed: the model's step failed. The cause is in the text, not a
/// `source()`, so a printed chain says it once.
#[derive(Debug, thiserror::Error)]
#[error("model step failed: {0}")]
pub struct StepError(pub Box<dyn std::error::Error + Send + Sync>);

/// When the model's states restart: `lanes` states, each reset every `period` scans, one
/// every `period / lanes` scans. The prediction comes from the oldest, so every prediction
/// after warm-up has between `period - period / lanes` (about) and `period` scans behind it;
/// more lanes narrow that range towards `period` for one model step per lane per scan.
///
/// `lanes_between` more states restart between each two of those, stepped but never
/// predicted from: more views of the same scans for readers of the state (the pose head,
/// [`StreamingClassifier::states_with_history`]). They leave the predictions exactly as
/// without them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LaneSchedule {
    pub period: usize,
    pub lanes: usize,
    pub lanes_between: usize,
}

impl LaneSchedule {
    /// Two lanes restarting every `window` scans: every prediction has `T/2..=T` behind it,
    /// what training scored.
    pub fn for_window(window: usize) -> Self {
        Self {
            period: window,
            lanes: 2,
            lanes_between: 0,
        }
    }

    /// States stepped in all.
    pub fn states(&self) -> usize {
        self.lanes * (1 + self.lanes_between)
    }

    /// The scan (modulo `period`) at which state `k` restarts. The predicting lanes are
    /// every `1 + lanes_between`-th state, so they restart when they would without the others.
    fn offset(&self, k: usize) -> usize {
        k * self.period / self.states()
    }
}

/// Staggered lanes over one model, plus the renderer and image buffers.
pub struct StreamingClassifier<M: StepModel> {
    model: M,
    spec: StreamSpec,
    renderer: Renderer,
    lanes: Vec<Lane<M::State>>,
    /// One image per lane (room-fixed framing centres each on its lane's first position).
    images: Vec<Array2<f32>>,
    schedule: LaneSchedule,
    /// Scans since the (re)start; lane `k` resets when `scans % period` is its offset.
    scans: usize,
    last_stamp_s: Option<f64>,
}

impl<M: StepModel> StreamingClassifier<M> {
    /// Two lanes restarting every `T` scans, the window the model was trained on.
    pub fn new(model: M, spec: StreamSpec) -> Result<Self, StreamSpecError> {
        Self::with_schedule(model, spec, LaneSchedule::for_window(spec.window))
    }

    /// Lanes restart as `schedule` says (a period of at least `T`). A model is usually most
    /// accurate with a little more history than it was trained on (docs/classifier.md).
    pub fn with_schedule(
        model: M,
        spec: StreamSpec,
        schedule: LaneSchedule,
    ) -> Result<Self, StreamSpecError> {
        spec.validate()?;
        let LaneSchedule {
            period,
            lanes,
            lanes_between,
        } = schedule;
        if period < spec.window {
            return Err(StreamSpecError::LanePeriod {
                period,
                window: spec.window,
            });
        }
        if !(2..=period).contains(&lanes) {
            return Err(StreamSpecError::LaneCount { lanes, period });
        }
        if schedule.states() > period {
            return Err(StreamSpecError::LanesBetween {
                lanes,
                lanes_between,
                period,
            });
        }
        let renderer = Renderer::new(spec.representation)?;
        Ok(Self {
            lanes: (0..schedule.states())
                .map(|_| Lane {
                    state: model.initial_state(),
                    history: 0,
                    centre: None,
                })
                .collect(),
            images: (0..schedule.states())
                .map(|_| spec.representation.blank_image())
                .collect(),
            model,
            spec,
            renderer,
            schedule,
            scans: 0,
            last_stamp_s: None,
        })
    }

    pub fn spec(&self) -> &StreamSpec {
        &self.spec
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    /// Gives the model back (to run it again under another schedule).
    pub fn into_model(self) -> M {
        self.model
    }

    /// The image the last prediction was made from.
    pub fn last_image(&self) -> ArrayView2<'_, f32> {
        self.images[self.predicting_lane()].view()
    }

    /// Every state with at least `min_history` frames behind it (those between the predicting
    /// lanes included), and where `position` lies in the image it was last stepped on
    /// (metres from the image's centre): what the pose head reads.
    pub fn states_with_history(
        &self,
        min_history: usize,
        position: DVec2,
    ) -> impl Iterator<Item = (&M::State, DVec2)> {
        let framing = self.spec.representation.framing;
        self.lanes
            .iter()
            .filter(move |lane| lane.history >= min_history)
            .map(move |lane| {
                let located = match framing {
                    Framing::RoomFixed => {
                        lane.centre.map_or(DVec2::ZERO, |centre| position - centre)
                    }
                    Framing::PersonCentred => DVec2::ZERO,
                };
                (&lane.state, located)
            })
    }

    /// Restarts every lane from zero state.
    pub fn reset(&mut self) {
        self.scans = 0;
        for lane in &mut self.lanes {
            self.model.reset_state(&mut lane.state);
            lane.history = 0;
            lane.centre = None;
        }
    }

    /// The predicting lane with the longest history (the first of equals).
    fn predicting_lane(&self) -> usize {
        let mut chosen = 0;
        for k in (0..self.lanes.len()).step_by(1 + self.schedule.lanes_between) {
            if self.lanes[k].history > self.lanes[chosen].history {
                chosen = k;
            }
        }
        chosen
    }

    /// Classifies one scan. Scans must come in time order; a gap over `T` scan periods or a
    /// stamp going backwards restarts the lanes. A failed step is this scan's error: the
    /// lanes stepped before it keep the scan, the failing lane and those after it do not
    /// (their history says so), and the next scan goes on from there.
    pub fn classify(&mut self, scan: &PersonScan<'_>) -> Result<Prediction, StepError> {
        let window = self.spec.window;
        let max_gap = window as f64 / self.spec.scan_rate_hz;
        if let Some(last) = self.last_stamp_s {
            let gap = scan.stamp_s - last;
            if !(0.0..=max_gap).contains(&gap) {
                self.reset();
            }
        }
        if scan.stamp_s.is_finite() {
            self.last_stamp_s = Some(scan.stamp_s);
        }

        let phase = self.scans % self.schedule.period;
        for (k, lane) in self.lanes.iter_mut().enumerate() {
            if phase == self.schedule.offset(k) {
                self.model.reset_state(&mut lane.state);
                lane.history = 0;
                lane.centre = None;
            }
        }
        self.scans += 1;

        let position = scan.position.filter(|p| p.is_finite());
        match (position, self.spec.representation.framing) {
            (None, _) => {
                for image in &mut self.images {
                    image.fill(0.0);
                }
            }
            (Some(p), Framing::PersonCentred) => {
                let (first, rest) = self.images.split_at_mut(1);
                self.renderer.render(
                    scan.points.iter().copied(),
                    p,
                    scan.sensor,
                    first[0].view_mut(),
                );
                for image in rest {
                    image.assign(&first[0]);
                }
            }
            (Some(p), Framing::RoomFixed) => {
                for (lane, image) in self.lanes.iter_mut().zip(&mut self.images) {
                    let centre = *lane.centre.get_or_insert(p);
                    self.renderer.render(
                        scan.points.iter().copied(),
                        centre,
                        scan.sensor,
                        image.view_mut(),
                    );
                }
            }
        }

        // Every lane steps once, so the oldest now is the oldest after the step.
        let chosen = self.predicting_lane();
        let mut chosen_logits = [0.0; Activity::COUNT];
        for (k, (lane, image)) in self.lanes.iter_mut().zip(&self.images).enumerate() {
            let logits = self
                .model
                .step(image.view(), &mut lane.state)
                .map_err(|e| StepError(Box::new(e)))?;
            lane.history += 1;
            if k == chosen {
                chosen_logits = logits;
            }
        }
        let probabilities = softmax(&chosen_logits);
        let (activity, confidence) = Activity::most_likely(&probabilities);
        let history = self.lanes[chosen].history;
        Ok(Prediction {
            stamp_s: scan.stamp_s,
            activity,
            confidence,
            probabilities,
            history,
            ready: history >= window / 2,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::representation::RepresentationKind;

    /// A deterministic stand-in for the ConvLSTM: the state counts frames and accumulates the
    /// lit pixels; the logits favour class `(frames seen) % 9` and record the lit count, so
    /// tests can see which state and image produced a prediction.
    #[derive(Default)]
    struct CountingModel {
        steps: usize,
        images: Vec<Array2<f32>>,
        /// The step (counted from 1) that fails, leaving the state as it was.
        fails_at_step: Option<usize>,
    }

    #[derive(Debug, Clone, PartialEq)]
    struct CountState {
        frames: usize,
        lit: f32,
    }

    impl StepModel for CountingModel {
        type State = CountState;
        type Error = std::io::Error;
        fn initial_state(&self) -> CountState {
            CountState {
                frames: 0,
                lit: 0.0,
            }
        }
        fn reset_state(&self, state: &mut CountState) {
            *state = self.initial_state();
        }
        fn step(
            &mut self,
            frame: ArrayView2<'_, f32>,
            state: &mut CountState,
        ) -> Result<[f32; 9], std::io::Error> {
            self.steps += 1;
            if self.fails_at_step == Some(self.steps) {
                return Err(std::io::Error::other("a broken step"));
            }
            self.images.push(frame.to_owned());
            state.frames += 1;
            state.lit += frame.sum();
            let mut logits = [0.0; 9];
            logits[state.frames % 9] = 10.0;
            Ok(logits)
        }
    }

    fn spec(framing: Framing, window: usize) -> StreamSpec {
        StreamSpec {
            representation: RepresentationSpec::new(
                RepresentationKind::BooleanGrid,
                framing,
                16,
                0.1,
            ),
            window,
            scan_rate_hz: 20.0,
        }
    }

    fn scan(t: f64, position: Option<DVec2>, points: &[DVec2]) -> PersonScan<'_> {
        PersonScan {
            stamp_s: t,
            points,
            position,
            sensor: DVec2::ZERO,
        }
    }

    #[test]
    fn lanes_are_staggered_and_history_stays_between_half_and_full_window() {
        let mut c =
            StreamingClassifier::new(CountingModel::default(), spec(Framing::PersonCentred, 8))
                .unwrap();
        let mut histories = vec![];
        for k in 0..40 {
            let p = c.classify(&scan(k as f64 * 0.05, None, &[])).unwrap();
            histories.push(p.history);
            // The winning class follows the chosen lane's frame count.
            assert_eq!(p.activity.index(), p.history % 9);
            assert_eq!(p.ready, p.history >= 4);
        }
        assert_eq!(&histories[..8], &[1, 2, 3, 4, 5, 6, 7, 8]);
        assert!(
            histories[8..].iter().all(|&h| (4..=8).contains(&h)),
            "{histories:?}"
        );
        // Two steps per scan.
        assert_eq!(c.model().steps, 80);
    }

    fn histories(schedule: LaneSchedule, scans: usize) -> (Vec<usize>, usize) {
        let spec = spec(Framing::PersonCentred, 8);
        let mut c =
            StreamingClassifier::with_schedule(CountingModel::default(), spec, schedule).unwrap();
        let histories = (0..scans)
            .map(|k| {
                c.classify(&scan(k as f64 * 0.05, None, &[]))
                    .unwrap()
                    .history
            })
            .collect();
        (histories, c.model().steps)
    }

    #[test]
    fn a_longer_lane_period_gives_every_prediction_more_history() {
        let (h, steps) = histories(
            LaneSchedule {
                period: 12,
                lanes: 2,
                lanes_between: 0,
            },
            48,
        );
        assert_eq!(&h[..12], &(1..=12).collect::<Vec<_>>()[..]);
        assert!(h[12..].iter().all(|&h| (7..=12).contains(&h)), "{h:?}");
        assert_eq!(steps, 96);
    }

    #[test]
    fn more_lanes_narrow_the_history_towards_the_period_for_a_step_each() {
        let schedule = LaneSchedule {
            period: 12,
            lanes: 3,
            lanes_between: 0,
        };
        let (h, steps) = histories(schedule, 48);
        assert_eq!(&h[..12], &(1..=12).collect::<Vec<_>>()[..]);
        // Restarts every 4 scans: the oldest lane always has 9..=12 behind it.
        assert!(h[12..].iter().all(|&h| (9..=12).contains(&h)), "{h:?}");
        assert_eq!(h[12..16], [9, 10, 11, 12]);
        assert_eq!(steps, 3 * 48);
    }

    #[test]
    fn lanes_between_leave_predictions_alone_and_offer_more_states_to_read() {
        let with = |lanes_between| LaneSchedule {
            period: 12,
            lanes: 2,
            lanes_between,
        };
        let (plain, plain_steps) = histories(with(0), 48);
        let (between, steps) = histories(with(1), 48);
        assert_eq!(between, plain, "the predicting lanes restart as before");
        assert_eq!((plain_steps, steps), (2 * 48, 4 * 48));

        // States restart every 3 scans: two or three of the four have 6..=12 behind them.
        let mut c = StreamingClassifier::with_schedule(
            CountingModel::default(),
            spec(Framing::PersonCentred, 8),
            with(1),
        )
        .unwrap();
        for k in 0..48 {
            let p = c.classify(&scan(k as f64 * 0.05, None, &[])).unwrap();
            let mut frames: Vec<usize> = c
                .states_with_history(6, DVec2::ZERO)
                .map(|(state, _)| state.frames)
                .collect();
            frames.sort_unstable();
            assert!(frames.iter().all(|f| (6..=12).contains(f)), "scan {k}");
            if p.history >= 6 {
                assert!(
                    frames.contains(&p.history),
                    "the predicting lane is read too"
                );
            }
            if k >= 12 {
                assert!((2..=3).contains(&frames.len()), "scan {k}: {frames:?}");
                assert!(frames.windows(2).all(|w| w[1] - w[0] == 3), "{frames:?}");
            }
        }
    }

    #[test]
    fn impossible_schedules_are_refused() {
        let spec = spec(Framing::PersonCentred, 8);
        let refused_between = |period, lanes, lanes_between| {
            StreamingClassifier::with_schedule(
                CountingModel::default(),
                spec,
                LaneSchedule {
                    period,
                    lanes,
                    lanes_between,
                },
            )
            .err()
        };
        let refused = |period, lanes| refused_between(period, lanes, 0);
        assert!(matches!(
            refused(7, 2),
            Some(StreamSpecError::LanePeriod {
                period: 7,
                window: 8
            })
        ));
        assert!(matches!(
            refused(8, 1),
            Some(StreamSpecError::LaneCount { lanes: 1, .. })
        ));
        assert!(matches!(
            refused(8, 9),
            Some(StreamSpecError::LaneCount { lanes: 9, .. })
        ));
        assert!(refused(8, 8).is_none());
        assert!(matches!(
            refused_between(8, 2, 4),
            Some(StreamSpecError::LanesBetween {
                lanes: 2,
                lanes_between: 4,
                period: 8
            })
        ));
        let message = refused_between(8, 2, 4).unwrap().to_string();
        assert!(message.contains("make 10 states"), "{message}");
        assert!(refused_between(8, 2, 3).is_none());
    }

    #[test]
    fn a_failed_step_is_the_scans_error_and_the_next_scan_goes_on() {
        let model = CountingModel {
            fails_at_step: Some(12),
            ..CountingModel::default()
        };
        let mut c = StreamingClassifier::new(model, spec(Framing::PersonCentred, 8)).unwrap();
        let frames = |c: &StreamingClassifier<CountingModel>| -> Vec<usize> {
            c.states_with_history(0, DVec2::ZERO)
                .map(|(state, _)| state.frames)
                .collect()
        };
        for k in 0..5 {
            c.classify(&scan(k as f64 * 0.05, None, &[])).unwrap();
        }
        // Step 12 is lane 1's on scan 5 (it restarted on scan 4): lane 0 keeps the scan.
        let e = c.classify(&scan(0.25, None, &[])).unwrap_err();
        assert!(e.to_string().contains("a broken step"), "{e}");
        assert_eq!(frames(&c), [6, 1]);
        let p = c.classify(&scan(0.3, None, &[])).unwrap();
        assert_eq!(p.history, 7);
        assert_eq!(frames(&c), [7, 2]);
        assert_eq!(
            c.lanes[1].history, 2,
            "the history counts the frames stepped"
        );
    }

    #[test]
    fn long_gap_and_backwards_time_restart_both_lanes() {
        let mut c =
            StreamingClassifier::new(CountingModel::default(), spec(Framing::PersonCentred, 8))
                .unwrap();
        for k in 0..20 {
            c.classify(&scan(k as f64 * 0.05, None, &[])).unwrap();
        }
        // 8 scans at 20 Hz = 0.4 s; a 0.5 s gap restarts.
        let p = c.classify(&scan(0.95 + 0.5, None, &[])).unwrap();
        assert_eq!(p.history, 1);
        assert!(!p.ready);
        let p = c.classify(&scan(1.5, None, &[])).unwrap();
        assert_eq!(p.history, 2);
        let p = c.classify(&scan(0.2, None, &[])).unwrap();
        assert_eq!(p.history, 1, "time going backwards restarts");
        // A short gap does not.
        let p = c.classify(&scan(0.5, None, &[])).unwrap();
        assert_eq!(p.history, 2);
    }

    #[test]
    fn hidden_person_gives_empty_frames_and_valid_probabilities() {
        let mut c = StreamingClassifier::new(CountingModel::default(), spec(Framing::RoomFixed, 8))
            .unwrap();
        let points = [DVec2::new(1.0, 1.0)];
        for k in 0..30 {
            let p = c.classify(&scan(k as f64 * 0.05, None, &points)).unwrap();
            assert!((p.probabilities.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        }
        assert!(c.model().images.iter().all(|img| img.sum() == 0.0));
    }

    #[test]
    fn room_fixed_keeps_each_lanes_first_position_person_centred_follows() {
        // Person moving 0.31 m per scan along x; one point 5 cm off the position (mid-pixel).
        let walk = |framing| {
            let mut c =
                StreamingClassifier::new(CountingModel::default(), spec(framing, 4)).unwrap();
            for k in 0..4 {
                let p = DVec2::new(0.31 * k as f64, 0.0);
                c.classify(&scan(k as f64 * 0.05, Some(p), &[p + DVec2::splat(0.05)]))
                    .unwrap();
            }
            c.model().images.clone()
        };
        let fixed = walk(Framing::RoomFixed);
        let lit = |img: &Array2<f32>| img.indexed_iter().find(|(_, v)| **v == 1.0).map(|(i, _)| i);
        // Lane 0 (even entries): centred at x=0, the point moves 3 pixels per scan; lane 1
        // restarts at scan 2 (T/2) and is centred there.
        assert_eq!(lit(&fixed[0]), Some((8, 8)));
        assert_eq!(lit(&fixed[2]), Some((8, 11)));
        assert_eq!(lit(&fixed[4]), Some((8, 14)));
        assert_eq!(lit(&fixed[5]), Some((8, 8)));
        assert_eq!(
            lit(&fixed[6]),
            None,
            "x = 0.98 is outside the 1.6 m image of lane 0"
        );
        let centred = walk(Framing::PersonCentred);
        assert!(centred.iter().all(|img| lit(img) == Some((8, 8))));
    }

    #[test]
    fn softmax_is_finite_and_normalised_at_the_extremes() {
        let cases: [[f32; 9]; 6] = [
            [0.0; 9],
            [1e30, -1e30, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [f32::MAX, f32::MAX, f32::MIN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [f32::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [f32::NEG_INFINITY; 9],
            [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ];
        for logits in cases {
            let p = softmax(&logits);
            assert!(
                p.iter().all(|v| v.is_finite() && *v >= 0.0),
                "{logits:?} -> {p:?}"
            );
            assert!(
                (p.iter().sum::<f32>() - 1.0).abs() < 1e-5,
                "{logits:?} -> {p:?}"
            );
        }
        let p = softmax(&[1e30, -1e30, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(p[0], 1.0);
        let p = softmax(&[f32::MAX, f32::MAX, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!((p[0], p[1]), (0.5, 0.5));
    }

    #[test]
    fn metadata_is_parsed_and_errors_name_the_key() {
        let meta = |extra: &[(&str, &str)]| {
            let mut m: Vec<(String, String)> = [
                ("lidar_har.representation", "ellipses"),
                ("lidar_har.framing", "room_fixed"),
                ("lidar_har.size", "64"),
                ("lidar_har.resolution_m", "0.05"),
                ("lidar_har.window", "40"),
                ("lidar_har.scan_rate_hz", "20"),
            ]
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
            for (k, v) in extra {
                m.retain(|(key, _)| key != k);
                if !v.is_empty() {
                    m.push((k.to_string(), v.to_string()));
                }
            }
            move |key: &str| m.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone())
        };
        let spec =
            StreamSpec::from_metadata(meta(&[("lidar_har.ellipse_axes_m", "0.1, 0.02")])).unwrap();
        assert_eq!(spec.window, 40);
        assert_eq!(spec.representation.kind, RepresentationKind::Ellipses);
        assert_eq!(spec.representation.ellipse_axes_m, [0.1, 0.02]);
        let e = StreamSpec::from_metadata(meta(&[("lidar_har.window", "")])).unwrap_err();
        assert_eq!(e, StreamSpecError::Missing("lidar_har.window"));
        let e = StreamSpec::from_metadata(meta(&[("lidar_har.size", "big")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("lidar_har.size") && e.contains("big"), "{e}");
        let e = StreamSpec::from_metadata(meta(&[("lidar_har.framing", "sideways")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sideways") && e.contains("room_fixed"), "{e}");
        assert!(StreamSpec::from_metadata(meta(&[("lidar_har.window", "1")])).is_err());
        let e = StreamSpec::from_metadata(meta(&[("lidar_har.window", "100000000000000000")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("2..=10000"), "{e}");
        assert!(StreamSpec::from_metadata(meta(&[("lidar_har.scan_rate_hz", "NaN")])).is_err());
    }
}
