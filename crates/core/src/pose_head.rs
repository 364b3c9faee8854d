//! The pelvis placed from the activity model's state: the pose head (docs/localiser.md,
//! session 23; docs/model_contract.md, "Pose head").
//!
//! The localiser reports the centre of the person's returns, which for someone sitting on the
//! floor or getting up lies a third of a metre from the pelvis. The activity model's ConvLSTM
//! state holds what one scan does not (how the legs swing, where the hands and feet lie), and
//! a small model fitted on it predicts the pelvis's offset from the localiser's position. It
//! runs after each classification on the state the prediction came from, and only where it
//! was fitted and found to help: the person seen, at least `min_history` frames behind the
//! state, an activity in `activities`.

use glam::DVec2;

use crate::activity::Activity;
use crate::classifier::{
    Prediction, StepError, StepModel, StreamSpecError, StreamingClassifier, parse_metadata,
};

/// The model behind the pose head (ONNX Runtime in production, small stand-ins in tests).
pub trait PoseHead<S> {
    type Error: std::error::Error + Send + Sync + 'static;

    /// The pelvis's offset from the localiser's position, metres in map axes, from the state
    /// and where that position lies in the image the state was last stepped on (metres from
    /// the image's centre).
    fn offset(&mut self, state: &S, located: DVec2) -> Result<DVec2, Self::Error>;
}

/// The head of a classifier that has none: there is no value of this type, so a
/// `PelvisPlacer<NoPoseHead>` is never made and places nothing.
#[derive(Debug)]
pub enum NoPoseHead {}

impl<S> PoseHead<S> for NoPoseHead {
    type Error = std::convert::Infallible;

    fn offset(&mut self, _: &S, _: DVec2) -> Result<DVec2, Self::Error> {
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
    /// Deviation of the head's error per axis, metres (its published covariance).
    pub sigma_m: f64,
}

impl PoseHeadSpec {
    pub const KEY_MIN_HISTORY: &'static str = "lidar_har.pose_head.min_history";
    pub const KEY_ACTIVITIES: &'static str = "lidar_har.pose_head.activities";
    pub const KEY_SIGMA: &'static str = "lidar_har.pose_head.sigma_m";

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
        let sigma_m: f64 = parse_metadata(Self::KEY_SIGMA, &get)?;
        if !(sigma_m.is_finite() && sigma_m >= 0.0) {
            return Err(StreamSpecError::Invalid {
                key: Self::KEY_SIGMA,
                value: sigma_m.to_string(),
                reason: "must be finite and not negative".into(),
            });
        }
        Ok(Self {
            min_history: parse_metadata(Self::KEY_MIN_HISTORY, &get)?,
            activities,
            sigma_m,
        })
    }
}

/// A pose head with the rules of its use.
#[derive(Debug)]
pub struct PelvisPlacer<H> {
    head: H,
    spec: PoseHeadSpec,
}

impl<H> PelvisPlacer<H> {
    pub fn new(spec: PoseHeadSpec, head: H) -> Self {
        Self { head, spec }
    }

    pub fn spec(&self) -> &PoseHeadSpec {
        &self.spec
    }

    /// The pelvis after `classifier` made `prediction` from a scan where the localiser put the
    /// person at `position` (`None`: not seen); `None` where the head is not to be used or
    /// gave no finite offset.
    pub fn place<M>(
        &mut self,
        classifier: &StreamingClassifier<M>,
        position: Option<DVec2>,
        prediction: &Prediction,
    ) -> Result<Option<DVec2>, StepError>
    where
        M: StepModel,
        H: PoseHead<M::State>,
    {
        let Some(position) = position.filter(|p| p.is_finite()) else {
            return Ok(None);
        };
        if prediction.history < self.spec.min_history
            || !self.spec.activities.contains(&prediction.activity)
        {
            return Ok(None);
        }
        let (state, located) = classifier.last_state(position);
        // A person outside the image (a runner long after the lane's first position) is not
        // in the state the head reads.
        let representation = classifier.spec().representation;
        let half_extent = representation.size as f64 * representation.resolution_m / 2.0;
        if located.abs().max_element() >= half_extent {
            return Ok(None);
        }
        let offset = self
            .head
            .offset(state, located)
            .map_err(|e| StepError(Box::new(e)))?;
        Ok(offset.is_finite().then_some(position + offset))
    }
}

#[cfg(test)]
mod tests {
    use ndarray::ArrayView2;

    use super::*;
    use crate::classifier::{PersonScan, StreamSpec};
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

    /// Offset: (frames seen / 10, 0) minus where the person lies in the image; NaN when asked.
    struct LinearHead {
        nan: bool,
        seen: Vec<(usize, DVec2)>,
    }

    impl PoseHead<usize> for LinearHead {
        type Error = std::io::Error;
        fn offset(&mut self, frames: &usize, located: DVec2) -> Result<DVec2, Self::Error> {
            self.seen.push((*frames, located));
            if self.nan {
                return Ok(DVec2::new(f64::NAN, 0.0));
            }
            Ok(DVec2::new(*frames as f64 / 10.0, 0.0) - located)
        }
    }

    fn classifier(framing: Framing) -> StreamingClassifier<FrameCounter> {
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
        StreamingClassifier::new(FrameCounter, spec).unwrap()
    }

    fn placer(nan: bool) -> PelvisPlacer<LinearHead> {
        PelvisPlacer::new(
            PoseHeadSpec {
                min_history: 4,
                activities: vec![Activity::SittingOnFloor],
                sigma_m: 0.1,
            },
            LinearHead { nan, seen: vec![] },
        )
    }

    /// Classifies the person at `positions` (one per scan, 20 Hz) and places the pelvis.
    fn run(
        framing: Framing,
        placer: &mut PelvisPlacer<LinearHead>,
        positions: &[Option<DVec2>],
    ) -> Vec<Option<DVec2>> {
        let mut classifier = classifier(framing);
        let points = [DVec2::new(2.0, 1.0)];
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
                placer.place(&classifier, position, &prediction).unwrap()
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
            assert!(
                pelvis.unwrap().distance(expected) < 1e-12,
                "scan {k}: {pelvis:?}"
            );
        }
        // Located from the first position of the lane (both lanes started at scan 0).
        assert!(placer.head.seen.iter().all(|(frames, located)| {
            located.distance(DVec2::new(0.1 * (*frames as f64 - 1.0), 0.0)) < 1e-12
        }));
    }

    #[test]
    fn person_centred_head_sees_the_person_at_the_centre() {
        let mut placer = placer(false);
        let still = vec![Some(DVec2::new(3.0, -1.0)); 6];
        let placed = run(Framing::PersonCentred, &mut placer, &still);
        assert_eq!(placed[5], Some(DVec2::new(3.6, -1.0)));
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
        assert_eq!(broken.head.seen.len(), 3, "asked from the fourth scan on");
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
        let metadata = |activities: &'static str, sigma: &'static str| {
            move |key: &str| match key {
                PoseHeadSpec::KEY_MIN_HISTORY => Some("12".to_string()),
                PoseHeadSpec::KEY_ACTIVITIES => Some(activities.to_string()),
                PoseHeadSpec::KEY_SIGMA => Some(sigma.to_string()),
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
        assert_eq!(spec.sigma_m, 0.08);
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
        let e = PoseHeadSpec::from_metadata(metadata("lying_down", "nan")).unwrap_err();
        assert!(e.to_string().contains(PoseHeadSpec::KEY_SIGMA), "{e}");
        let e = PoseHeadSpec::from_metadata(|_: &str| None).unwrap_err();
        assert!(e.to_string().contains("is missing"), "{e}");
    }
}
