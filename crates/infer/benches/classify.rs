//! Per-scan classification cost on one thread: rendering plus one ConvLSTM step per
//! staggered lane (2, 3 and 4 lanes; `lanes` in config/classifier.yaml), as the classifier
//! node does it; then with the pose head run on every scan (its worst case: it runs only on
//! the activities it helps) on every state with the history it asks for: two lanes alone, and
//! with one more between each two (`pose_head_lanes_between`, the default). Prints figures; asserts nothing.
//!
//!   cargo bench -p lidar-har-infer --bench classify [-- MODEL.onnx [HEAD.onnx]]
//!
//! Default model: models/activity.onnx when present, else the tiny test fixture (which only
//! measures the overhead around the model); default head: models/pose_head.onnx with the
//! trained model, the fixture head with the fixture.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec2;
use lidar_har_core::activity::Activity;
use lidar_har_core::classifier::{
    LaneSchedule, PersonScan, Prediction, StepModel, StreamingClassifier,
};
use lidar_har_core::pose_head::{PelvisPlacer, PersonAt, PoseHeadSpec};
use lidar_har_core::representation::Renderer;
use lidar_har_infer::{ActivityModel, PoseHeadModel};

type BenchResult<T> = Result<T, Box<dyn std::error::Error>>;

/// One scan of the benchmark's walk: stamp, the person's position, their points.
type Scan = (f64, DVec2, Vec<DVec2>);

/// Milliseconds per scan for one pass over `scans` (stamps `from_s` later), running `then`
/// on each prediction; the sensor is at the origin.
fn per_scan_ms<M: StepModel>(
    classifier: &mut StreamingClassifier<M>,
    scans: &[Scan],
    from_s: f64,
    mut then: impl FnMut(&StreamingClassifier<M>, &Prediction, DVec2) -> BenchResult<()>,
) -> BenchResult<f64> {
    let start = Instant::now();
    for (t, centre, points) in scans {
        let prediction = classifier.classify(&PersonScan {
            stamp_s: t + from_s,
            points,
            position: Some(*centre),
            sensor: DVec2::ZERO,
        })?;
        then(classifier, &prediction, *centre)?;
    }
    Ok(start.elapsed().as_secs_f64() * 1e3 / scans.len() as f64)
}

fn main() -> BenchResult<()> {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let named: Vec<PathBuf> = std::env::args()
        .skip(1)
        .filter(|a| a.ends_with(".onnx"))
        .map(PathBuf::from)
        .collect();
    let trained = repo.join("models/activity.onnx");
    let fixtures = repo.join("crates/infer/tests/fixtures");
    let (path, head_path) = match named.as_slice() {
        [model, head, ..] => (model.clone(), head.clone()),
        [model] => (model.clone(), repo.join("models/pose_head.onnx")),
        [] if trained.is_file() => (trained, repo.join("models/pose_head.onnx")),
        [] => (
            fixtures.join("step_model.onnx"),
            fixtures.join("pose_head.onnx"),
        ),
    };
    let model = ActivityModel::load(&path, 1)?;
    let info = model.info().clone();
    let spec = info.stream;
    println!(
        "model {} (state {} x {}x{}; {} {} {}x{} at {} m, window {})",
        path.canonicalize().unwrap_or(path.clone()).display(),
        info.hidden,
        info.state_side,
        info.state_side,
        spec.representation.kind,
        spec.representation.framing,
        spec.representation.size,
        spec.representation.size,
        spec.representation.resolution_m,
        spec.window
    );

    // A person walking at 1 m/s past the sensor, ~25 points on a 0.4 m arc, 20 Hz.
    let scans: Vec<Scan> = (0..2000)
        .map(|k| {
            let t = k as f64 / spec.scan_rate_hz;
            let centre = DVec2::new(1.0 + 0.05 * (k % 60) as f64, 0.5);
            let points = (0..25)
                .map(|i| {
                    centre + 0.2 * DVec2::from_angle(std::f64::consts::PI * (0.5 + i as f64 / 24.0))
                })
                .collect();
            (t, centre, points)
        })
        .collect();
    let sensor = DVec2::ZERO;

    let renderer = Renderer::new(spec.representation)?;
    let mut image = spec.representation.blank_image();
    let start = Instant::now();
    for (_, centre, points) in &scans {
        renderer.render(points.iter().copied(), *centre, sensor, image.view_mut());
    }
    let render_us = start.elapsed().as_secs_f64() * 1e6 / scans.len() as f64;

    println!("render one image: {render_us:.2} us");

    let mut model = model;
    for lanes in [2, 3, 4] {
        let schedule = LaneSchedule {
            period: spec.window,
            lanes,
            lanes_between: 0,
        };
        let mut classifier = StreamingClassifier::with_schedule(model, spec, schedule)?;
        let nothing = |_: &_, _: &_, _| Ok(());
        per_scan_ms(&mut classifier, &scans[..100], 0.0, nothing)?;
        let from_s = 100.0 / spec.scan_rate_hz;
        let per_scan_ms = per_scan_ms(&mut classifier, &scans, from_s, nothing)?;
        println!(
            "per scan (render + {lanes} steps + softmax), 1 thread: {per_scan_ms:.3} ms (target <= 0.5 ms)"
        );
        model = classifier.into_model();
    }

    let head = match PoseHeadModel::load(&head_path, &model, 1) {
        Ok(head) => head,
        Err(e) => {
            println!("no pose head timed: {e}");
            return Ok(());
        }
    };
    // Every activity, every state with the history the head asks for.
    let every_scan = PoseHeadSpec {
        min_history: head.spec().min_history,
        activities: Activity::ALL.to_vec(),
        max_sigma_m: f64::INFINITY,
    };
    let mut placer = PelvisPlacer::new(every_scan, head);
    for lanes_between in [0, 1] {
        // config/classifier.yaml's lane period: 1.2 windows.
        let schedule = LaneSchedule {
            period: spec.window * 6 / 5,
            lanes: 2,
            lanes_between,
        };
        let mut classifier = StreamingClassifier::with_schedule(model, spec, schedule)?;
        let mut placed = 0;
        let per_scan_ms = per_scan_ms(
            &mut classifier,
            &scans,
            0.0,
            |classifier, prediction, at| {
                let pelvis = placer.place(classifier, PersonAt::Seen(at), prediction)?;
                placed += usize::from(pelvis.is_some());
                Ok(())
            },
        )?;
        println!(
            "per scan (render + {} steps + softmax + pose head on {placed} of {} scans), 1 \
             thread: {per_scan_ms:.3} ms (target <= 0.5 ms); head {}",
            schedule.states(),
            scans.len(),
            head_path.display()
        );
        model = classifier.into_model();
    }
    Ok(())
}
