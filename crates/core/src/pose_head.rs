//! The pelvis placed from the activity model's state: the pose head (docs/localiser.md,
//! session 23; docs/model_contract.md, "Pose head").
//!
//! The localiser reports the centre of the person's returns, which for someone sitting on the
//! floor or getting up lies a third of a metre from the pelvis. The activity model's ConvLSTM
//! state holds what one scan does not (how the legs swing, where the hands and feet lie), and
//! a small model fitted on it predicts the pelvis's offset from the localiser's position. It
//! runs after each classification on every state with at least `min_history` frames behind
//! it (the predicting lanes' and those restarted between them), and combines what it reads
//! from each, weighed by the error it expects of each (docs/localiser.md, session 25); and
//! only where it was fitted and found to help: the person seen, an activity in `activities`,
//! the head expecting an error of at most `max_sigma_m` (a state it doubts beyond that counts
//! for nothing); and, for a short hold, at the last seen offset from the track while the
//! person is hidden. A person on the floor stays put while the robot moves round them, so
//! their pelvis is fused over the scans that read them there (docs/localiser.md, session 37).
//! The head's expected error is published with the pelvis, so a consumer can weigh it.

use glam::DVec2;

use crate::activity::Activity;
use crate::classifier::{
    Prediction, StepError, StepModel, StreamSpecError, StreamingClassifier, parse_metadata,
};

/// What a pose head reads from one state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadEstimate {
    /// The pelvis's offset from the localiser's position, metres in map axes.
    pub offset: DVec2,
    /// The error the head expects of it: deviation per axis of a circular Gaussian, metres.
    pub sigma_m: f64,
}

/// The model behind the pose head (ONNX Runtime in production, small stand-ins in tests).
pub trait PoseHead<S> {
    type Error: std::error::Error + Send + Sync + 'static;

    /// The estimate from the state and where the localiser's position lies in the image the
    /// state was last stepped on (metres from the image's centre).
    fn estimate(&mut self, state: &S, located: DVec2) -> Result<HeadEstimate, Self::Error>;
}

/// Where the localiser has the person on a scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PersonAt {
    /// The centroid of their returns on this scan.
    Seen(DVec2),
    /// The track's prediction: the person is hidden.
    Predicted(DVec2),
}

/// The pelvis a pose head placed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedPelvis {
    pub position: DVec2,
    /// The head's expected error, metres per axis (added to the track's covariance).
    pub sigma_m: f64,
}

/// The head of a classifier that has none: there is no value of this type, so a
/// `PelvisPlacer<NoPoseHead>` is never made and places nothing.
#[derive(Debug)]
pub enum NoPoseHead {}

impl<S> PoseHead<S> for NoPoseHead {
    type Error = std::convert::Infallible;

    fn estimate(&mut self, _: &S, _: DVec2) -> Result<HeadEstimate, Self::Error> {
        match *self {}
    }
}

/// Where a pose head may be used; carried by its model file's metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseHeadSpec {
    /// Fewest frames behind the state: the head was fitted on no shorter histories.
    pub min_history: usize,
    /// The activities (as the classifier reads them) on which the head places the pelvis
    /// better than the localiser; on the others the localiser's position stands.
    pub activities: Vec<Activity>,
    /// Above this expected error (metres per axis) the localiser's position stands: where
    /// the head doubts itself it did worse than the localiser on the data it was gated on.
    /// Infinite: never.
    pub max_sigma_m: f64,
}

impl PoseHeadSpec {
    pub const KEY_MIN_HISTORY: &'static str = "lidar_har.pose_head.min_history";
    pub const KEY_ACTIVITIES: &'static str = "lidar_har.pose_head.activities";
    pub const KEY_MAX_SIGMA: &'static str = "lidar_har.pose_head.max_sigma_m";

    /// Reads the spec from key/value metadata (the ONNX `metadata_props`).
    pub fn from_metadata(get: impl Fn(&str) -> Option<String>) -> Result<Self, StreamSpecError> {
        let labels: String = parse_metadata(Self::KEY_ACTIVITIES, &get)?;
        let activities = labels
            .split(',')
            .map(str::trim)
            .filter(|label| !label.is_empty())
            .map(|label| {
                Activity::from_label(label).ok_or_else(|| StreamSpecError::Invalid {
                    key: Self::KEY_ACTIVITIES,
                    value: labels.clone(),
                    reason: format!("'{label}' is not an activity"),
                })
            })
            .collect::<Result<_, _>>()?;
        let max_sigma_m: f64 = parse_metadata(Self::KEY_MAX_SIGMA, &get)?;
        if max_sigma_m.is_nan() || max_sigma_m <= 0.0 {
            return Err(StreamSpecError::Invalid {
                key: Self::KEY_MAX_SIGMA,
                value: max_sigma_m.to_string(),
                reason: "must be positive ('inf': no limit)".into(),
            });
        }
        Ok(Self {
            min_history: parse_metadata(Self::KEY_MIN_HISTORY, &get)?,
            activities,
            max_sigma_m,
        })
    }
}

/// A pose head with the rules of its use.
#[derive(Debug)]
pub struct PelvisPlacer<H> {
    head: H,
    spec: PoseHeadSpec,
    hold_s: f64,
    /// The last seen scan's estimate, when the pelvis was placed on it: (stamp, estimate).
    last_placed: Option<(f64, HeadEstimate)>,
    floor: FloorFusion,
}

impl<H> PelvisPlacer<H> {
    pub fn new(spec: PoseHeadSpec, head: H) -> Self {
        Self {
            head,
            spec,
            hold_s: 0.0,
            last_placed: None,
            floor: FloorFusion::default(),
        }
    }

    /// Keeps placing the pelvis at the last seen offset from the track's prediction for up to
    /// `hold_s` after the person was last seen (0: off): someone who sits down behind a chair
    /// keeps their pose, and the pelvis where it was relative to the body is a better guess
    /// than the track's centroid of returns no longer there.
    pub fn holding_for(mut self, hold_s: f64) -> Self {
        self.hold_s = hold_s;
        self
    }

    /// Publishes, for a person read lying or sitting on the floor, the pelvis combined over
    /// every scan since they were read there, for as long as each scan's own pelvis lies
    /// within `radius_m` of that combination (0: off). Such a person stays put while the
    /// robot moves round them, and the views differ: end-on or in part, a single scan's
    /// pelvis can be most of a metre off, where the combination of the views is not. Someone
    /// read as anything else (getting up, crawling off) for `gap_s` or more starts a new
    /// combination; shorter readings (the model's reading of a body on the floor flickers)
    /// get their own pelvis and leave the combination as it was.
    pub fn fusing_on_floor_within(mut self, radius_m: f64, gap_s: f64) -> Self {
        self.floor = FloorFusion {
            radius_m,
            gap_s,
            ..FloorFusion::default()
        };
        self
    }

    /// Forgets the last placement: the track is another person's.
    pub fn reset(&mut self) {
        self.last_placed = None;
        self.floor.forget();
    }

    pub fn spec(&self) -> &PoseHeadSpec {
        &self.spec
    }

    /// The pelvis after `classifier` made `prediction` from a scan where the localiser had the
    /// person at `person`; `None` where the head is not to be used, gave no finite estimate
    /// it does not doubt beyond `max_sigma_m` from any state, and where a hidden person was
    /// last placed longer than the hold ago.
    pub fn place<M>(
        &mut self,
        classifier: &StreamingClassifier<M>,
        person: PersonAt,
        prediction: &Prediction,
    ) -> Result<Option<PlacedPelvis>, StepError>
    where
        M: StepModel,
        H: PoseHead<M::State>,
    {
        let wanted = prediction.history >= self.spec.min_history
            && self.spec.activities.contains(&prediction.activity);
        let position = match person {
            PersonAt::Predicted(position) => {
                return Ok(self
                    .last_placed
                    .filter(|(stamp_s, _)| {
                        let since = prediction.stamp_s - stamp_s;
                        wanted && position.is_finite() && (0.0..=self.hold_s).contains(&since)
                    })
                    .map(|(_, held)| PlacedPelvis {
                        position: position + held.offset,
                        sigma_m: held.sigma_m,
                    }));
            }
            PersonAt::Seen(position) => position,
        };
        self.last_placed = None;
        if !wanted || !position.is_finite() {
            return Ok(None);
        }
        // A person outside a state's image (a runner long after its lane's first position) is
        // not in that state.
        let representation = classifier.spec().representation;
        let half_extent = representation.size as f64 * representation.resolution_m / 2.0;
        let mut combined = Combination::default();
        for (state, located) in classifier.states_with_history(self.spec.min_history, position) {
            if located.abs().max_element() >= half_extent {
                continue;
            }
            let estimate = self
                .head
                .estimate(state, located)
                .map_err(|e| StepError(Box::new(e)))?;
            let HeadEstimate { offset, sigma_m } = estimate;
            // Non-finite estimates are left out by the combination, even without a limit
            // (`max_sigma_m` inf).
            if sigma_m <= self.spec.max_sigma_m {
                combined.add(offset, sigma_m);
            }
        }
        let Some((offset, sigma_m)) = combined.mean() else {
            return Ok(None);
        };
        self.last_placed = Some((prediction.stamp_s, HeadEstimate { offset, sigma_m }));
        Ok(Some(self.floor.place(
            prediction.stamp_s,
            prediction.activity,
            position + offset,
            sigma_m,
        )))
    }
}

/// The pelvis of a person on the floor, combined over the scans that read them there
/// ([`PelvisPlacer::fusing_on_floor_within`]).
#[derive(Debug, Default)]
struct FloorFusion {
    /// 0: off.
    radius_m: f64,
    gap_s: f64,
    /// The pelvises placed since the person was last read on the floor afresh.
    spell: Option<Combination>,
    /// Since when the person, in a spell on the floor, has been read as something else.
    off_floor_since_s: Option<f64>,
}

impl FloorFusion {
    /// The pelvis to publish for a scan read as `activity` whose own is `pelvis`.
    fn place(
        &mut self,
        stamp_s: f64,
        activity: Activity,
        pelvis: DVec2,
        sigma_m: f64,
    ) -> PlacedPelvis {
        let own = PlacedPelvis {
            position: pelvis,
            sigma_m,
        };
        if self.radius_m <= 0.0 {
            return own;
        }
        if !matches!(activity, Activity::LyingDown | Activity::SittingOnFloor) {
            let since = *self.off_floor_since_s.get_or_insert(stamp_s);
            if stamp_s - since >= self.gap_s {
                self.spell = None;
            }
            return own;
        }
        self.off_floor_since_s = None;
        let radius = self.radius_m;
        let spell = self.spell.get_or_insert_default();
        if spell
            .mean()
            .is_some_and(|(mean, _)| mean.distance(pelvis) > radius)
        {
            *spell = Combination::default();
        }
        spell.add(pelvis, sigma_m);
        let (position, sigma_m) = spell.mean().unwrap_or((pelvis, sigma_m));
        PlacedPelvis { position, sigma_m }
    }

    fn forget(&mut self) {
        self.spell = None;
        self.off_floor_since_s = None;
    }
}

/// Estimates of one place by the head (from several states of the same scans, or over the
/// scans of a person on the floor), each weighed by the inverse of its expected variance.
/// They are far from independent (one head, one person), so the expected error is their
/// weighted mean rather than the smaller one independent estimates would give.
#[derive(Debug, Default)]
struct Combination {
    weights: f64,
    sum: DVec2,
    sigma_sum: f64,
}

impl Combination {
    /// Below this the weight stops growing: a head sure to the millimetre is no surer.
    const SIGMA_FLOOR_M: f64 = 1e-3;

    /// Adds an estimate; one without a finite place and a finite, non-negative expected
    /// error counts for nothing (docs/model_contract.md): an infinite error (a head's exp()
    /// overflowing on an older state) weighed 0 but made the mean error 0 x inf = NaN, and a
    /// NaN one weighed as much as a millimetre's (NaN.max(floor)).
    fn add(&mut self, estimate: DVec2, sigma_m: f64) {
        if !(estimate.is_finite() && sigma_m.is_finite() && sigma_m >= 0.0) {
            return;
        }
        let weight = sigma_m.max(Self::SIGMA_FLOOR_M).powi(-2);
        self.weights += weight;
        self.sum += weight * estimate;
        self.sigma_sum += weight * sigma_m;
    }

    /// The weighted mean and its expected error.
    fn mean(&self) -> Option<(DVec2, f64)> {
        (self.weights > 0.0).then(|| (self.sum / self.weights, self.sigma_sum / self.weights))
    }
}

#[cfg(test)]
mod tests {
    use ndarray::ArrayView2;

    use super::*;
    use crate::classifier::{LaneSchedule, PersonScan, StreamSpec};
    use crate::representation::{Framing, RepresentationKind, RepresentationSpec};

    /// State: frames seen. Logits: sitting on the floor from the third frame on.
    struct FrameCounter;

    impl StepModel for FrameCounter {
        type State = usize;
        type Error = std::io::Error;
        fn initial_state(&self) -> usize {
            0
        }
        fn reset_state(&self, state: &mut usize) {
            *state = 0;
        }
        fn step(
            &mut self,
            _: ArrayView2<'_, f32>,
            state: &mut usize,
        ) -> Result<[f32; 9], Self::Error> {
            *state += 1;
            let mut logits = [0.0; 9];
            let class = if *state >= 3 {
                Activity::SittingOnFloor
            } else {
                Activity::Standing
            };
            logits[class.index()] = 5.0;
            Ok(logits)
        }
    }

    /// Offset: (frames seen / 10, 0) minus where the person lies in the image; expected
    /// error: frames seen / 100 m; NaN when asked.
    struct LinearHead {
        nan: bool,
        seen: Vec<(usize, DVec2)>,
    }

    impl PoseHead<usize> for LinearHead {
        type Error = std::io::Error;
        fn estimate(
            &mut self,
            frames: &usize,
            located: DVec2,
        ) -> Result<HeadEstimate, Self::Error> {
            self.seen.push((*frames, located));
            let offset = if self.nan {
                DVec2::new(f64::NAN, 0.0)
            } else {
                DVec2::new(*frames as f64 / 10.0, 0.0) - located
            };
            Ok(HeadEstimate {
                offset,
                sigma_m: *frames as f64 / 100.0,
            })
        }
    }

    fn classifier(framing: Framing) -> StreamingClassifier<FrameCounter> {
        classifier_with_lanes_between(framing, 0)
    }

    /// Two predicting lanes restarting every 8 scans, `lanes_between` more between them.
    fn classifier_with_lanes_between(
        framing: Framing,
        lanes_between: usize,
    ) -> StreamingClassifier<FrameCounter> {
        let spec = StreamSpec {
            representation: RepresentationSpec::new(
                RepresentationKind::BooleanGrid,
                framing,
                16,
                0.1,
            ),
            window: 8,
            scan_rate_hz: 20.0,
        };
        let schedule = LaneSchedule {
            period: 8,
            lanes: 2,
            lanes_between,
        };
        StreamingClassifier::with_schedule(FrameCounter, spec, schedule).unwrap()
    }

    fn placer(nan: bool) -> PelvisPlacer<LinearHead> {
        PelvisPlacer::new(
            PoseHeadSpec {
                min_history: 4,
                activities: vec![Activity::SittingOnFloor],
                max_sigma_m: f64::INFINITY,
            },
            LinearHead { nan, seen: vec![] },
        )
    }

    /// Classifies the person at `positions` (one per scan, 20 Hz; `None`: hidden, predicted
    /// 0.1 m along x from where last seen) and places the pelvis.
    fn run(
        framing: Framing,
        placer: &mut PelvisPlacer<LinearHead>,
        positions: &[Option<DVec2>],
    ) -> Vec<Option<PlacedPelvis>> {
        run_on(classifier(framing), placer, positions)
    }

    fn run_on(
        mut classifier: StreamingClassifier<FrameCounter>,
        placer: &mut PelvisPlacer<LinearHead>,
        positions: &[Option<DVec2>],
    ) -> Vec<Option<PlacedPelvis>> {
        let points = [DVec2::new(2.0, 1.0)];
        let mut last_seen = DVec2::ZERO;
        positions
            .iter()
            .enumerate()
            .map(|(k, &position)| {
                let scan = PersonScan {
                    stamp_s: k as f64 * 0.05,
                    points: &points,
                    position,
                    sensor: DVec2::ZERO,
                };
                let prediction = classifier.classify(&scan).unwrap();
                let person = match position {
                    Some(seen) => {
                        last_seen = seen;
                        PersonAt::Seen(seen)
                    }
                    None => PersonAt::Predicted(last_seen + DVec2::new(0.1, 0.0)),
                };
                placer.place(&classifier, person, &prediction).unwrap()
            })
            .collect()
    }

    #[test]
    fn room_fixed_head_sees_the_position_from_the_lanes_first_and_adds_its_offset() {
        let mut placer = placer(false);
        let walk: Vec<Option<DVec2>> = (0..6)
            .map(|k| Some(DVec2::new(1.0 + 0.1 * k as f64, 2.0)))
            .collect();
        let placed = run(Framing::RoomFixed, &mut placer, &walk);
        // Too little history for the first three scans (and standing for the first two).
        assert_eq!(&placed[..3], &[None, None, None]);
        for (k, pelvis) in placed.iter().enumerate().skip(3) {
            let frames = k + 1;
            let expected = walk[k].unwrap() + DVec2::new(frames as f64 / 10.0, 0.0)
                - DVec2::new(0.1 * k as f64, 0.0);
            let pelvis = pelvis.unwrap();
            assert!(
                pelvis.position.distance(expected) < 1e-12,
                "scan {k}: {pelvis:?}"
            );
            assert!((pelvis.sigma_m - frames as f64 / 100.0).abs() < 1e-12);
        }
        // Located from the first position of the lane (both lanes started at scan 0).
        assert!(placer.head.seen.iter().all(|(frames, located)| {
            located.distance(DVec2::new(0.1 * (*frames as f64 - 1.0), 0.0)) < 1e-12
        }));
    }

    #[test]
    fn head_reads_every_state_with_enough_history_and_weighs_each_by_its_doubt() {
        let still = vec![Some(DVec2::new(3.0, -1.0)); 24];
        let mut between = placer(false);
        let placed = run_on(
            classifier_with_lanes_between(Framing::PersonCentred, 1),
            &mut between,
            &still,
        );
        assert!(placed[..3].iter().all(Option::is_none));
        assert!(placed[3..].iter().all(Option::is_some));
        // Four states restarting every 2 scans: on scan 23 they have 8, 6, 4 and 2 frames
        // behind them, and the head (offset frames / 10, doubt frames / 100) reads the first
        // three, after the 21 it read on scans 3-22.
        let last: Vec<usize> = between.head.seen[between.head.seen.len() - 3..]
            .iter()
            .map(|(frames, _)| *frames)
            .collect();
        assert_eq!(last, [8, 6, 4]);
        let weights: Vec<f64> = last.iter().map(|&f| (f as f64 / 100.0).powi(-2)).collect();
        let mean = |value: &dyn Fn(f64) -> f64| {
            last.iter()
                .zip(&weights)
                .map(|(&f, w)| w * value(f as f64))
                .sum::<f64>()
                / weights.iter().sum::<f64>()
        };
        let pelvis = placed[23].unwrap();
        let offset = mean(&|f| f / 10.0);
        assert!((pelvis.position - DVec2::new(3.0 + offset, -1.0)).length() < 1e-12);
        assert!((pelvis.sigma_m - mean(&|f| f / 100.0)).abs() < 1e-12);
        assert!(
            offset < 0.6,
            "the surest (least history) weighs most: {offset}"
        );

        // A state whose estimate is doubted beyond the limit counts for nothing.
        let mut doubtful = placer(false);
        doubtful.spec.max_sigma_m = 0.07;
        let placed = run_on(
            classifier_with_lanes_between(Framing::PersonCentred, 1),
            &mut doubtful,
            &still,
        );
        let weights = [6.0_f64, 4.0].map(|f| (f / 100.0).powi(-2));
        let offset = (weights[0] * 0.6 + weights[1] * 0.4) / (weights[0] + weights[1]);
        assert!((placed[23].unwrap().position.x - (3.0 + offset)).abs() < 1e-12);
    }

    #[test]
    fn a_person_on_the_floor_gets_the_pelvis_combined_over_their_scans() {
        use Activity::{Crawling, LyingDown, SittingOnFloor};
        let mut p = placer(false).fusing_on_floor_within(1.0, 0.5);
        let mut stamp_s = 0.0;
        let mut at = |p: &mut PelvisPlacer<LinearHead>, activity, x: f64, sigma_m| {
            stamp_s += 0.05;
            p.floor
                .place(stamp_s, activity, DVec2::new(x, 2.0), sigma_m)
        };
        let x = |placed: PlacedPelvis| placed.position.x;
        assert_eq!(
            at(&mut p, LyingDown, 1.0, 0.1).position,
            DVec2::new(1.0, 2.0)
        );
        // Seen end-on, 0.6 m off and doubted twice as much: a fifth of the weight.
        let fused = at(&mut p, LyingDown, 1.6, 0.2);
        assert!((fused.position.x - 1.12).abs() < 1e-12, "{fused:?}");
        assert!((fused.sigma_m - 0.12).abs() < 1e-12, "{fused:?}");
        // Sitting up is the same spell on the floor.
        assert!((x(at(&mut p, SittingOnFloor, 1.12, 0.1)) - 1.12).abs() < 1e-12);
        // Beyond the radius from the combination: elsewhere, a new spell.
        assert_eq!(x(at(&mut p, LyingDown, 2.5, 0.1)), 2.5);
        // Read as anything but on the floor for a moment: that scan's own, the spell kept.
        assert_eq!(x(at(&mut p, Crawling, 2.9, 0.3)), 2.9);
        assert!((x(at(&mut p, LyingDown, 2.5, 0.1)) - 2.5).abs() < 1e-12);
        assert!((x(at(&mut p, LyingDown, 2.2, 0.1)) - 2.4).abs() < 1e-12);
        // For the gap or longer (0.5 s): a new spell after.
        for _ in 0..12 {
            assert_eq!(x(at(&mut p, Crawling, 2.9, 0.3)), 2.9);
        }
        assert_eq!(x(at(&mut p, LyingDown, 2.2, 0.3)), 2.2);
        // Another person's track forgets the spell.
        p.reset();
        assert_eq!(x(at(&mut p, LyingDown, 2.6, 0.3)), 2.6);
        // Off: each scan's own.
        let mut off = placer(false);
        assert_eq!(x(at(&mut off, LyingDown, 1.0, 0.1)), 1.0);
        assert_eq!(x(at(&mut off, LyingDown, 1.6, 0.2)), 1.6);
    }

    #[test]
    fn person_centred_head_sees_the_person_at_the_centre() {
        let mut placer = placer(false);
        let still = vec![Some(DVec2::new(3.0, -1.0)); 6];
        let placed = run(Framing::PersonCentred, &mut placer, &still);
        assert_eq!(placed[5].map(|p| p.position), Some(DVec2::new(3.6, -1.0)));
        assert!(
            placer
                .head
                .seen
                .iter()
                .all(|(_, located)| *located == DVec2::ZERO)
        );
    }

    #[test]
    fn no_pelvis_for_a_hidden_person_other_activities_or_a_non_finite_offset() {
        let mut seen_only = placer(false);
        let mut hidden = vec![Some(DVec2::new(1.0, 1.0)); 6];
        hidden[4] = None;
        hidden[5] = Some(DVec2::new(f64::NAN, 1.0));
        let placed = run(Framing::RoomFixed, &mut seen_only, &hidden);
        assert_eq!(&placed[4..], &[None, None]);
        assert!(placed[3].is_some());

        let mut standing_only = placer(false);
        standing_only.spec.activities = vec![Activity::Standing];
        assert!(
            run(
                Framing::RoomFixed,
                &mut standing_only,
                &[Some(DVec2::ONE); 6]
            )
            .iter()
            .all(Option::is_none)
        );

        let mut broken = placer(true);
        let placed = run(Framing::RoomFixed, &mut broken, &[Some(DVec2::ONE); 6]);
        assert!(placed.iter().all(Option::is_none));
        // Asked from the fourth scan on; on the fourth of both lanes (they start together).
        assert_eq!(broken.head.seen.len(), 4);
    }

    #[test]
    fn a_hidden_person_keeps_the_last_seen_offset_for_the_hold_and_no_longer() {
        let mut seen = vec![Some(DVec2::ONE); 6];
        seen.extend([None; 4]);
        seen.push(Some(DVec2::ONE));
        seen.extend([None; 1]);
        let mut holding = placer(false).holding_for(0.12);
        let placed = run(Framing::RoomFixed, &mut holding, &seen);
        // Scan 5 (6 frames): offset 0.6 along x, expected error 0.06 m.
        let last = placed[5].unwrap();
        assert!((last.sigma_m - 0.06).abs() < 1e-12);
        for k in [6, 7] {
            let held = placed[k].unwrap();
            assert!(
                held.position.distance(last.position + DVec2::new(0.1, 0.0)) < 1e-12,
                "scan {k}: {held:?}"
            );
            assert_eq!(held.sigma_m, last.sigma_m);
        }
        assert_eq!(
            &placed[8..10],
            &[None, None],
            "0.15 s after: beyond the hold"
        );
        assert!(placed[10].is_some() && placed[11].is_some());

        // Off by default; and a reset (another track) forgets the last placement.
        let placed = run(Framing::RoomFixed, &mut placer(false), &seen);
        assert_eq!(&placed[6..8], &[None, None]);
        let mut classifier = classifier(Framing::RoomFixed);
        let points = [DVec2::ONE];
        let mut reset = placer(false).holding_for(1.0);
        for k in 0..7 {
            let position = (k < 6).then_some(DVec2::ONE);
            let prediction = classifier
                .classify(&PersonScan {
                    stamp_s: k as f64 * 0.05,
                    points: &points,
                    position,
                    sensor: DVec2::ZERO,
                })
                .unwrap();
            if k == 6 {
                reset.reset();
            }
            let person = position.map_or(PersonAt::Predicted(DVec2::ONE), PersonAt::Seen);
            let placed = reset.place(&classifier, person, &prediction).unwrap();
            assert_eq!(placed.is_some(), (3..6).contains(&k), "scan {k}");
        }
    }

    #[test]
    fn no_pelvis_where_the_head_doubts_itself_beyond_its_limit() {
        // Expected error frames / 100: 0.04, 0.05, 0.06 m on scans 4-6.
        let mut doubtful = placer(false);
        doubtful.spec.max_sigma_m = 0.05;
        let placed = run(Framing::RoomFixed, &mut doubtful, &[Some(DVec2::ONE); 6]);
        let sigmas: Vec<Option<f64>> = placed
            .iter()
            .map(|p| p.map(|p| (p.sigma_m * 1e3).round() / 1e3))
            .collect();
        assert_eq!(sigmas, [None, None, None, Some(0.04), Some(0.05), None]);
    }

    /// Offset 0.1 m along x, expected error exp(-3) m; on states with more than 5 frames
    /// behind them the log of it is 100, and exp() overflows to infinity.
    struct OverflowingHead;

    impl PoseHead<usize> for OverflowingHead {
        type Error = std::io::Error;
        fn estimate(&mut self, frames: &usize, _: DVec2) -> Result<HeadEstimate, Self::Error> {
            let log_sigma: f32 = if *frames > 5 { 100.0 } else { -3.0 };
            Ok(HeadEstimate {
                offset: DVec2::new(0.1, 0.0),
                sigma_m: f64::from(log_sigma.exp()),
            })
        }
    }

    #[test]
    fn an_infinite_expected_error_counts_for_nothing_even_without_a_limit() {
        let spec = PoseHeadSpec {
            min_history: 4,
            activities: vec![Activity::SittingOnFloor],
            max_sigma_m: f64::INFINITY,
        };
        let mut placer = PelvisPlacer::new(spec, OverflowingHead).fusing_on_floor_within(1.0, 0.5);
        let mut classifier = classifier_with_lanes_between(Framing::PersonCentred, 1);
        let points = [DVec2::ONE];
        let mut placed = 0;
        for k in 0..40 {
            let prediction = classifier
                .classify(&PersonScan {
                    stamp_s: k as f64 * 0.05,
                    points: &points,
                    position: Some(DVec2::ONE),
                    sensor: DVec2::ZERO,
                })
                .unwrap();
            let person = PersonAt::Seen(DVec2::ONE);
            // Where every state overflows there is no pelvis; elsewhere the finite ones
            // alone. Their mean error used to be 0 x inf = NaN, on /human/pelvis.
            if let Some(pelvis) = placer.place(&classifier, person, &prediction).unwrap() {
                placed += 1;
                assert!(
                    (pelvis.sigma_m - (-3.0f32).exp() as f64).abs() < 1e-9,
                    "{pelvis:?}"
                );
                assert!(
                    pelvis.position.distance(DVec2::new(1.1, 1.0)) < 1e-9,
                    "{pelvis:?}"
                );
            }
        }
        assert!(placed > 20, "{placed}");
    }

    #[test]
    fn a_combination_leaves_out_estimates_that_are_not_finite() {
        let mut combination = Combination::default();
        combination.add(DVec2::new(1.0, 2.0), 0.125);
        for (estimate, sigma_m) in [
            (DVec2::new(5.0, 5.0), f64::INFINITY),
            // A NaN expected error weighed as a millimetre's (NaN.max(floor)).
            (DVec2::new(5.0, 5.0), f64::NAN),
            (DVec2::new(f64::NAN, 5.0), 0.1),
            (DVec2::new(5.0, 5.0), -0.1),
        ] {
            combination.add(estimate, sigma_m);
        }
        assert_eq!(combination.mean(), Some((DVec2::new(1.0, 2.0), 0.125)));
        let mut nothing = Combination::default();
        nothing.add(DVec2::ONE, f64::INFINITY);
        assert_eq!(nothing.mean(), None);
    }

    #[test]
    fn no_pelvis_once_the_person_has_left_the_lanes_image() {
        // The image spans 1.6 m (16 pixels of 0.1 m): half of it is 0.8 m from the centre.
        let mut runner = placer(false);
        let run_by: Vec<Option<DVec2>> = (0..6)
            .map(|k| Some(DVec2::new(0.3 * k as f64, 0.0)))
            .collect();
        let placed = run(Framing::RoomFixed, &mut runner, &run_by);
        assert!(placed[3].is_none() && placed[4].is_none(), "{placed:?}");
        assert!(runner.head.seen.is_empty());
        let mut stroller = placer(false);
        let stroll: Vec<Option<DVec2>> = (0..6)
            .map(|k| Some(DVec2::new(0.1 * k as f64, 0.0)))
            .collect();
        assert!(
            run(Framing::RoomFixed, &mut stroller, &stroll)[3..]
                .iter()
                .all(Option::is_some)
        );
    }

    #[test]
    fn spec_reads_its_metadata_and_names_a_bad_key() {
        let metadata = |activities: &'static str, max_sigma: &'static str| {
            move |key: &str| match key {
                PoseHeadSpec::KEY_MIN_HISTORY => Some("12".to_string()),
                PoseHeadSpec::KEY_ACTIVITIES => Some(activities.to_string()),
                PoseHeadSpec::KEY_MAX_SIGMA => Some(max_sigma.to_string()),
                _ => None,
            }
        };
        let spec =
            PoseHeadSpec::from_metadata(metadata("getting_up, sitting_on_floor", "0.08")).unwrap();
        assert_eq!(spec.min_history, 12);
        assert_eq!(
            spec.activities,
            vec![Activity::GettingUp, Activity::SittingOnFloor]
        );
        assert_eq!(spec.max_sigma_m, 0.08);
        let unlimited = PoseHeadSpec::from_metadata(metadata("lying_down", "inf")).unwrap();
        assert_eq!(unlimited.max_sigma_m, f64::INFINITY);
        assert!(
            PoseHeadSpec::from_metadata(metadata("", "0.08"))
                .unwrap()
                .activities
                .is_empty()
        );

        let e = PoseHeadSpec::from_metadata(metadata("sitting,lying_down", "0.08")).unwrap_err();
        assert!(
            e.to_string().contains("'sitting' is not an activity"),
            "{e}"
        );
        for bad in ["nan", "0", "-0.1"] {
            let e = PoseHeadSpec::from_metadata(metadata("lying_down", bad)).unwrap_err();
            assert!(
                e.to_string().contains(PoseHeadSpec::KEY_MAX_SIGMA),
                "{bad}: {e}"
            );
        }
        let e = PoseHeadSpec::from_metadata(|_: &str| None).unwrap_err();
        assert!(e.to_string().contains("is missing"), "{e}");
    }
}
