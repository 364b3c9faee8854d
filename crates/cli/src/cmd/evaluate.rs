//! `lidar-har evaluate`: runs an ONNX step model (through `lidar-har-infer`, as the robot
//! does) over a dataset's test windows and compares the figures with the paper's.
//!
//! Each window is stepped scan by scan from a zero state, exactly as one streaming lane
//! does. The headline figures use the prediction at the window's last scan (history `T`);
//! the accuracy at step index `T/2` (`T/2 + 1` frames of history, the shortest that training
//! scores; streaming answers from one frame less, docs/model_contract.md) is reported beside
//! it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use lidar_har_core::activity::Activity;
use lidar_har_core::classifier::{StepModel, StreamSpec};
use lidar_har_core::metrics::ConfusionMatrix;
use lidar_har_core::stats::{median, nearest_rank};
use lidar_har_infer::ActivityModel;
use lidar_har_sim::render::font;
use ndarray::{Array2, s};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::Serialize;

use super::dataset::{DatasetIndex, DatasetSpec, EpisodeEntry, Generator, SplitData};

#[derive(clap::Args, Debug)]
pub struct EvaluateArgs {
    /// The ONNX step model (e.g. models/activity.onnx). Its training report beside it
    /// (`M.training.json`, written by training/train.sh) names the dataset it trained on: a
    /// dataset whose test episodes it trained on, or whose unseen rooms it trained in, is
    /// refused.
    #[arg(long)]
    pub model: PathBuf,
    /// A dataset directory written by `lidar-har dataset`.
    #[arg(long)]
    pub data: PathBuf,
    /// Where metrics.json, report.md and the confusion PNGs go.
    #[arg(long)]
    pub out: PathBuf,
    /// ONNX Runtime intra-op threads; at least 1.
    #[arg(long, default_value_t = 1, value_parser = parse_threads)]
    pub threads: usize,
}

/// `--threads`: at least 1, refused here naming the flag, as ONNX Runtime would take 0 as
/// one thread per core (and the model loader refuses it).
fn parse_threads(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(0) => Err("must be at least 1 (ONNX Runtime intra-op threads)".to_string()),
        Ok(threads) => Ok(threads),
        Err(_) => Err("not a whole number of threads".to_string()),
    }
}

/// The paper's per-class Boolean-grid results (Bouazizi et al. 2023): recall, precision in %.
const PAPER_BOOLEAN: [(f64, f64); Activity::COUNT] = [
    (88.3, 91.2),
    (81.2, 88.5),
    (93.4, 90.0),
    (99.0, 99.3),
    (73.0, 77.5),
    (93.9, 95.1),
    (97.4, 95.3),
    (83.4, 87.0),
    (89.1, 85.1),
];
/// The paper's accuracy and F1 in % per representation. Its F1 is the support-weighted one:
/// recomputed from its Boolean-grid per-class table and test sample counts it is 91.27 %,
/// where the macro F1 is 89.27 % ([`paper_boolean_macro_f1`]).
const PAPER_ACCURACY_AND_WEIGHTED_F1: [(&str, f64, f64); 3] = [
    ("boolean_grid", 91.3, 91.3),
    ("circles", 78.8, 76.5),
    ("ellipses", 78.3, 76.9),
];

/// The paper's fixed-Lidar accuracy in % (Boolean grid) at its worst and its best Lidar
/// position: all it gives for a fixed Lidar (no F1, no per-class table).
const PAPER_FIXED_LIDAR_ACCURACY: (f64, f64) = (74.0, 82.9);

/// report.md's "paper" column: the figures of the paper's set-up that the dataset's matches,
/// as text, "-" where the paper gives none.
struct PaperColumn {
    /// The set-up, for the report's header.
    setting: String,
    accuracy: String,
    weighted_f1: String,
    macro_f1: String,
}

impl PaperColumn {
    /// The moving robot's figures for `representation`; for a `--fixed-lidar` dataset the
    /// fixed-Lidar accuracy range instead, as a fixed Lidar's accuracy beside the moving
    /// robot's would misstate how far it is from the paper.
    fn new(representation: &str, fixed_lidar: bool) -> Self {
        let one = |x: f64| format!("{x:.1}");
        let boolean_grid = representation == "boolean_grid";
        if fixed_lidar {
            let (worst, best) = PAPER_FIXED_LIDAR_ACCURACY;
            return Self {
                setting: format!(
                    "Boolean grid, fixed Lidar: {best:.1} % accuracy at its best position, \
                     {worst:.1} % at its worst; no F1 for it"
                ),
                accuracy: if boolean_grid {
                    format!("{worst:.1}-{best:.1}")
                } else {
                    "-".into()
                },
                weighted_f1: "-".into(),
                macro_f1: "-".into(),
            };
        }
        let figures = PAPER_ACCURACY_AND_WEIGHTED_F1
            .iter()
            .find(|(k, _, _)| *k == representation);
        Self {
            setting: "Boolean grid, moving robot".into(),
            accuracy: figures.map_or("-".into(), |&(_, accuracy, _)| one(accuracy)),
            weighted_f1: figures.map_or("-".into(), |&(_, _, f1)| one(f1)),
            macro_f1: if boolean_grid {
                one(paper_boolean_macro_f1())
            } else {
                "-".into()
            },
        }
    }
}

/// The paper's Boolean-grid macro F1 in %, from its per-class table (it gives only the
/// support-weighted one; the other representations have no per-class table).
fn paper_boolean_macro_f1() -> f64 {
    PAPER_BOOLEAN
        .iter()
        .map(|&(recall, precision)| 2.0 * recall * precision / (recall + precision))
        .sum::<f64>()
        / Activity::COUNT as f64
}

#[derive(Serialize)]
struct SplitMetrics {
    /// Every window, scored at its last scan.
    #[serde(flatten)]
    all: Scores,
    /// Accuracy of the prediction at step T/2 of each window against that scan's activity.
    accuracy_at_half_window: f64,
    /// Only the windows whose T scans all show one activity: the paper's samples are cut from
    /// one activity each, while a quarter of ours end just after a change (a window whose last
    /// two scans are a fall after 18 of walking is labelled falling).
    within_one_activity: Scores,
    /// Only the windows in which the localiser saw the person on every scan: in the rest they
    /// were hidden (behind furniture, out of the Lidar's view) for at least one scan, which
    /// the paper's samples, cut where the person was recorded, rarely are.
    in_full_view: Scores,
    /// Within one activity and in full view: the closest to the paper's samples.
    within_one_activity_in_full_view: Scores,
    /// Only the windows whose last scan the localiser saw the person on: the robot publishes
    /// no activity for a scan where the person is hidden, so these are the predictions it
    /// would publish.
    seen_at_last_scan: Scores,
    /// Accuracy per episode (one room, one robot path or fixed Lidar spot, one person).
    per_episode: Option<EpisodeSpread>,
}

/// Accuracy, per-class figures and confusion over a set of windows. A class's precision,
/// recall or F1 without windows to measure it by is 0 here (scikit-learn's
/// `zero_division=0`, kept for readers of earlier reports); `support` and the confusion's
/// columns tell those apart, and report.md shows them as "-".
#[derive(Serialize)]
struct Scores {
    windows: usize,
    accuracy: f64,
    precision: std::collections::BTreeMap<String, f64>,
    recall: std::collections::BTreeMap<String, f64>,
    f1: std::collections::BTreeMap<String, f64>,
    /// Windows truly of each class.
    support: std::collections::BTreeMap<String, u64>,
    macro_f1: f64,
    weighted_f1: f64,
    confusion: Vec<Vec<u64>>,
}

impl Scores {
    /// Windows predicted as `class`.
    fn predicted(&self, class: Activity) -> u64 {
        self.confusion.iter().map(|row| row[class.index()]).sum()
    }

    /// Recall, precision and F1 of `class` in % for report.md; "-" where there is nothing to
    /// measure them by (no window of the class; none predicted as it; neither), which 0 %
    /// beside the paper's figures would misstate.
    fn class_cells(&self, class: Activity) -> [String; 3] {
        let label = class.label();
        let (support, predicted) = (self.support[label], self.predicted(class));
        let cell = |value: f64, defined: bool| {
            if defined {
                format!("{:.1}", 100.0 * value)
            } else {
                "-".to_string()
            }
        };
        [
            cell(self.recall[label], support > 0),
            cell(self.precision[label], predicted > 0),
            cell(self.f1[label], support + predicted > 0),
        ]
    }

    /// One window is one sample of the matrix.
    fn new(confusion: &ConfusionMatrix) -> Self {
        let report = confusion.report();
        let by_class = |f: fn(&lidar_har_core::metrics::ClassMetrics) -> f64| {
            report
                .per_class
                .iter()
                .map(|c| (c.activity.label().to_string(), f(c)))
                .collect()
        };
        Self {
            windows: report.samples as usize,
            accuracy: report.accuracy,
            precision: by_class(|c| c.precision),
            recall: by_class(|c| c.recall),
            f1: by_class(|c| c.f1),
            support: report
                .per_class
                .iter()
                .map(|c| (c.activity.label().to_string(), c.support))
                .collect(),
            macro_f1: report.macro_f1,
            weighted_f1: report.weighted_f1,
            confusion: report.confusion.clone(),
        }
    }
}

/// How accuracy varies between episodes; in a `--fixed-lidar` dataset, between Lidar spots
/// (the paper's best and worst fixed positions).
#[derive(Serialize)]
struct EpisodeSpread {
    /// Episodes with at least [`MIN_EPISODE_WINDOWS`] windows (the others are too short to
    /// score).
    episodes: usize,
    median: f64,
    best: EpisodeAccuracy,
    worst: EpisodeAccuracy,
}

#[derive(Serialize, Clone)]
struct EpisodeAccuracy {
    episode: usize,
    scene: String,
    accuracy: f64,
    windows: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    fixed_lidar_at: Option<[f64; 2]>,
}

const MIN_EPISODE_WINDOWS: usize = 20;

/// The splits scored, each with its `confusion_<split>.png`.
const SCORED_SPLITS: [&str; 2] = ["test", "test_unseen"];

#[derive(Serialize)]
struct Metrics {
    model: String,
    data: String,
    classes: Vec<&'static str>,
    representation: String,
    framing: String,
    /// The `test` split's figures at the top level (what the issue asks for).
    #[serde(flatten)]
    test: SplitMetrics,
    splits: std::collections::BTreeMap<String, SplitMetrics>,
    /// Mean wall time of one model step (one scan, one lane), milliseconds.
    step_ms_mean: f64,
    step_ms_p99: f64,
    threads: usize,
}

pub fn run(args: EvaluateArgs) -> anyhow::Result<()> {
    let index = DatasetIndex::load(&args.data)?;
    let mut model = ActivityModel::load(&args.model, args.threads)?;
    check_model_matches(&model.info().stream, &index.spec, &args.model)?;
    check_not_trained_on(&args.model, &index, &args.data)?;
    if !index.windows.iter().any(|w| w.split == "test") {
        bail!("{}: the dataset has no test windows", args.data.display());
    }
    // A file in the way is found now, not after minutes of scoring.
    if args.out.exists() && !args.out.is_dir() {
        bail!(
            "--out {} is a file: give a folder (made if missing)",
            args.out.display()
        );
    }

    // Every split is scored before anything is written: a broken split leaves no outputs.
    let mut splits = std::collections::BTreeMap::new();
    let mut confusions = Vec::new();
    let mut step_times = Vec::new();
    for split in SCORED_SPLITS {
        let Some(data) = index.read_split(&args.data, split)? else {
            continue;
        };
        let (mut metrics, confusion, correct) = evaluate_split(&mut model, &data, &mut step_times)?;
        metrics.per_episode = episode_spread(&index, split, &correct);
        confusions.push((split, confusion));
        splits.insert(split.to_string(), metrics);
    }
    let Some(test) = splits.remove("test") else {
        bail!("{}: the test split has no images", args.data.display());
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for (split, confusion) in &confusions {
        draw_confusion(
            confusion,
            split,
            &args.out.join(format!("confusion_{split}.png")),
        )?;
    }
    // An earlier run's picture of a split this dataset lacks would pass for this one's.
    for split in SCORED_SPLITS {
        let path = args.out.join(format!("confusion_{split}.png"));
        if !confusions.iter().any(|(s, _)| *s == split) && path.exists() {
            std::fs::remove_file(&path)
                .with_context(|| format!("cannot remove {}", path.display()))?;
        }
    }
    step_times.sort_by(f64::total_cmp);
    let mean = step_times.iter().sum::<f64>() / step_times.len().max(1) as f64;
    let p99 = nearest_rank(&step_times, 0.99).unwrap_or(0.0);
    let metrics = Metrics {
        model: args.model.display().to_string(),
        data: args.data.display().to_string(),
        classes: Activity::ALL.iter().map(|a| a.label()).collect(),
        representation: index.spec.representation.to_string(),
        framing: index.spec.framing.to_string(),
        test,
        splits,
        step_ms_mean: mean,
        step_ms_p99: p99,
        threads: args.threads,
    };
    let json_path = args.out.join("metrics.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&metrics)? + "\n")
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    let report_path = args.out.join("report.md");
    std::fs::write(&report_path, report(&metrics, &index))
        .with_context(|| format!("cannot write {}", report_path.display()))?;
    outln!(
        "test accuracy {:.1} % ({} windows){}; step {:.3} ms; wrote {}",
        100.0 * metrics.test.all.accuracy,
        metrics.test.all.windows,
        metrics
            .splits
            .get("test_unseen")
            .map(|u| format!(
                ", unseen rooms {:.1} % ({} windows)",
                100.0 * u.all.accuracy,
                u.all.windows
            ))
            .unwrap_or_default(),
        mean,
        args.out.display()
    );
    Ok(())
}

/// The model must have been trained on images made like the dataset's, at its scan rate and
/// on windows as long: on shorter ones it would be scored with less history than training
/// scores it at, and room-fixed images would be centred per shorter window.
fn check_model_matches(stream: &StreamSpec, spec: &DatasetSpec, path: &Path) -> anyhow::Result<()> {
    let rep = &stream.representation;
    if rep.kind != spec.representation
        || rep.framing != spec.framing
        || rep.size != spec.size
        || (rep.resolution_m - spec.resolution_m).abs() > 1e-9
    {
        bail!(
            "{}: the model expects {} {} {}x{} at {} m, the dataset has {} {} {}x{} at {} m",
            path.display(),
            rep.kind,
            rep.framing,
            rep.size,
            rep.size,
            rep.resolution_m,
            spec.representation,
            spec.framing,
            spec.size,
            spec.size,
            spec.resolution_m
        );
    }
    if (stream.scan_rate_hz - spec.scan_rate_hz).abs() > 1e-6 {
        bail!(
            "{}: the model was trained at {} Hz, the dataset scans at {} Hz",
            path.display(),
            stream.scan_rate_hz,
            spec.scan_rate_hz
        );
    }
    if stream.window != spec.window {
        bail!(
            "{}: the model was trained on windows of {} scans, the dataset's are {} scans",
            path.display(),
            stream.window,
            spec.window
        );
    }
    Ok(())
}

/// Refuses a dataset whose test episodes the model trained on, as its training report
/// (`M.training.json` beside `M.onnx`) records: a dataset made with the same `--seed` but
/// another `--episodes` or `--test-fraction` holds the same episodes split otherwise, and
/// its figures would flatter the model. Without a report (or one naming no dataset)
/// nothing can be checked; a report that cannot be read is warned about, naming why (until
/// session 57 it was passed over in silence: train.py wrote a diverged epoch's loss as a
/// bare `NaN`, which is no JSON). A model fine-tuned from another (`--init-from`) names
/// only its last dataset.
fn check_not_trained_on(model: &Path, index: &DatasetIndex, data: &Path) -> anyhow::Result<()> {
    let report = model.with_extension("training.json");
    let trained_on = match training_dataset(&report) {
        Ok(Some(generator)) => generator,
        Ok(None) => return Ok(()),
        Err(err) => {
            errln!(
                "lidar-har: warning: {err:#}; whether {} trained on the test episodes of {} is not checked",
                model.display(),
                data.display()
            );
            return Ok(());
        }
    };
    check_unseen_rooms_unseen(&trained_on, &index.episodes, data, &report)?;
    let Some(trained) = trained_on.trained_episodes() else {
        return Ok(());
    };
    let tested: Vec<_> = index
        .episodes
        .iter()
        .filter(|e| e.split != "train")
        .collect();
    let overlap = tested
        .iter()
        .filter(|e| trained.contains(&(e.scene.clone(), e.seed)))
        .count();
    if overlap > 0 {
        bail!(
            "{}: {overlap} of its {} test episodes are episodes {} trained on ({}: a dataset of \
             `{}`, this one of `{}`): the same --seed with another --episodes or \
             --test-fraction splits the same episodes otherwise; make the test data with \
             another --seed",
            data.display(),
            tested.len(),
            model.display(),
            report.display(),
            trained_on.split_options(),
            index.generator.split_options(),
        );
    }
    Ok(())
}

/// Refuses a dataset whose `test_unseen` episodes are in rooms the model trained in: the
/// "unseen rooms" accuracy would be a seen room's, whatever the seeds.
fn check_unseen_rooms_unseen(
    trained_on: &Generator,
    episodes: &[EpisodeEntry],
    data: &Path,
    report: &Path,
) -> anyhow::Result<()> {
    let trained_in =
        |scene: &String| trained_on.scenes.contains(scene) && !trained_on.held_out.contains(scene);
    let mut seen: Vec<&str> = episodes
        .iter()
        .filter(|e| e.split == "test_unseen" && trained_in(&e.scene))
        .map(|e| e.scene.as_str())
        .collect();
    seen.sort_unstable();
    seen.dedup();
    if !seen.is_empty() {
        bail!(
            "{}: its unseen rooms ({}) are rooms the model trained in ({}: scenes {:?}, held \
             out {:?}); make the test data with --held-out naming rooms the model never saw",
            data.display(),
            seen.join(", "),
            report.display(),
            trained_on.scenes,
            trained_on.held_out,
        );
    }
    Ok(())
}

/// The dataset a training report (`M.training.json`) names: `None` without a report, or
/// with one that names none (a dataset made before `index.json` recorded its generator).
fn training_dataset(report: &Path) -> anyhow::Result<Option<Generator>> {
    let text = match std::fs::read_to_string(report) {
        Ok(text) => text,
        Err(err) if err.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(err) => bail!(
            "{}: cannot read the training report: {err}",
            report.display()
        ),
    };
    let value: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: the training report is not JSON", report.display()))?;
    match value.get("dataset_generator") {
        None | Some(serde_json::Value::Null) => Ok(None),
        Some(generator) => serde_json::from_value(generator.clone())
            .map(Some)
            .with_context(|| {
                format!(
                    "{}: the training report's dataset_generator is not a dataset's generator",
                    report.display()
                )
            }),
    }
}

fn evaluate_split(
    model: &mut ActivityModel,
    data: &SplitData,
    step_times: &mut Vec<f64>,
) -> anyhow::Result<(SplitMetrics, ConfusionMatrix, Vec<bool>)> {
    let (n, t, size, _) = data.images.dim();
    let half = t / 2;
    let mut confusion = ConfusionMatrix::new();
    let mut within_one = ConfusionMatrix::new();
    let mut in_view = ConfusionMatrix::new();
    let mut within_one_in_view = ConfusionMatrix::new();
    let mut seen_last = ConfusionMatrix::new();
    let mut half_right = 0usize;
    let mut correct = Vec::with_capacity(n);
    let mut frame = Array2::<f32>::zeros((size, size));
    let mut state = model.initial_state();
    for w in 0..n {
        model.reset_state(&mut state);
        let labels = data.labels.row(w);
        for k in 0..t {
            frame.zip_mut_with(&data.images.slice(s![w, k, .., ..]), |f, &v| {
                *f = f32::from(v) / 255.0
            });
            let started = Instant::now();
            let logits = model.step(frame.view(), &mut state)?;
            step_times.push(started.elapsed().as_secs_f64() * 1e3);
            let (predicted, _) = Activity::most_likely(&logits);
            let truth = Activity::from_index(labels[k] as usize).unwrap_or(Activity::Standing);
            if k == half && predicted == truth {
                half_right += 1;
            }
            if k == t - 1 {
                confusion.add(truth, predicted);
                correct.push(predicted == truth);
                let one_activity = labels.iter().all(|&l| l == labels[0]);
                let seen = data.seen.row(w);
                let seen_throughout = seen.iter().all(|&s| s);
                if one_activity {
                    within_one.add(truth, predicted);
                }
                if seen_throughout {
                    in_view.add(truth, predicted);
                }
                if one_activity && seen_throughout {
                    within_one_in_view.add(truth, predicted);
                }
                if seen[t - 1] {
                    seen_last.add(truth, predicted);
                }
            }
        }
    }
    let metrics = SplitMetrics {
        all: Scores::new(&confusion),
        accuracy_at_half_window: half_right as f64 / n.max(1) as f64,
        within_one_activity: Scores::new(&within_one),
        in_full_view: Scores::new(&in_view),
        within_one_activity_in_full_view: Scores::new(&within_one_in_view),
        seen_at_last_scan: Scores::new(&seen_last),
        per_episode: None,
    };
    Ok((metrics, confusion, correct))
}

/// Per-episode accuracy of one split from each window's outcome (`correct[row]`).
fn episode_spread(index: &DatasetIndex, split: &str, correct: &[bool]) -> Option<EpisodeSpread> {
    let mut counts: std::collections::BTreeMap<usize, (usize, usize)> = Default::default();
    for w in index.windows.iter().filter(|w| w.split == split) {
        if let Some(&ok) = correct.get(w.row) {
            let c = counts.entry(w.episode).or_default();
            c.0 += usize::from(ok);
            c.1 += 1;
        }
    }
    let mut scored: Vec<EpisodeAccuracy> = index
        .episodes
        .iter()
        .filter_map(|e| {
            let &(right, windows) = counts.get(&e.id)?;
            (windows >= MIN_EPISODE_WINDOWS).then(|| EpisodeAccuracy {
                episode: e.id,
                scene: e.scene.clone(),
                accuracy: right as f64 / windows as f64,
                windows,
                fixed_lidar_at: e.fixed_lidar_at,
            })
        })
        .collect();
    scored.sort_by(|a, b| a.accuracy.total_cmp(&b.accuracy));
    let worst = scored.first()?.clone();
    let best = scored.last()?.clone();
    let mut accuracies: Vec<f64> = scored.iter().map(|e| e.accuracy).collect();
    Some(EpisodeSpread {
        episodes: scored.len(),
        median: median(&mut accuracies)?,
        best,
        worst,
    })
}

/// Picks one subset's scores out of a split's metrics (for the report's rows).
type SubsetOf = fn(&SplitMetrics) -> &Scores;

fn report(m: &Metrics, index: &DatasetIndex) -> String {
    let mut out = String::new();
    let pct = |x: f64| format!("{:.1}", 100.0 * x);
    out += "# Activity recognition: evaluation against the paper\n\n";
    let paper = PaperColumn::new(&m.representation, index.spec.fixed_lidar);
    out += &format!(
        "Model `{}` on dataset `{}` ({} {}{}, {}x{} px at {} m, window {} scans). Paper: \
         Bouazizi et al., Sensors 23(5) 2534, 2023 ({}).\n\n",
        m.model,
        m.data,
        m.representation,
        m.framing,
        if index.spec.fixed_lidar {
            ", fixed Lidar"
        } else {
            ""
        },
        index.spec.size,
        index.spec.size,
        index.spec.resolution_m,
        index.spec.window,
        paper.setting
    );
    out += "| | ours: test | ours: unseen rooms | paper |\n|---|---|---|---|\n";
    let unseen = m.splits.get("test_unseen");
    out += &format!(
        "| accuracy (%) | {} | {} | {} |\n",
        pct(m.test.all.accuracy),
        unseen.map(|u| pct(u.all.accuracy)).unwrap_or("-".into()),
        paper.accuracy
    );
    out += &format!(
        "| accuracy at T/2 (%) | {} | {} | - |\n",
        pct(m.test.accuracy_at_half_window),
        unseen
            .map(|u| pct(u.accuracy_at_half_window))
            .unwrap_or("-".into())
    );
    out += &format!(
        "| F1, support-weighted (%) | {} | {} | {} |\n",
        pct(m.test.all.weighted_f1),
        unseen.map(|u| pct(u.all.weighted_f1)).unwrap_or("-".into()),
        paper.weighted_f1
    );
    out += &format!(
        "| macro F1 (%) | {} | {} | {} |\n",
        pct(m.test.all.macro_f1),
        unseen.map(|u| pct(u.all.macro_f1)).unwrap_or("-".into()),
        paper.macro_f1
    );
    out += &format!(
        "| windows | {} | {} | - |\n",
        m.test.all.windows,
        unseen
            .map(|u| u.all.windows.to_string())
            .unwrap_or("-".into())
    );
    let subsets: [(&str, SubsetOf, &str); 4] = [
        (
            "windows ending with the person in view (published)",
            |s| &s.seen_at_last_scan,
            "-",
        ),
        (
            "windows within one activity",
            |s| &s.within_one_activity,
            &paper.accuracy,
        ),
        ("windows in full view", |s| &s.in_full_view, "-"),
        (
            "within one activity and in full view",
            |s| &s.within_one_activity_in_full_view,
            &paper.accuracy,
        ),
    ];
    for (title, scores, paper_cell) in subsets {
        let cell = |s: &SplitMetrics| {
            let w = scores(s);
            format!("{} ({} windows)", pct(w.accuracy), w.windows)
        };
        out += &format!(
            "| accuracy, {title} (%) | {} | {} | {paper_cell} |\n",
            cell(&m.test),
            unseen.map(cell).unwrap_or("-".into()),
        );
    }
    out += "\n";
    out += "A window is scored at its last scan. \"Published\": only windows whose last scan \
            the localiser saw the person on; the robot publishes no activity for a scan where \
            the person is hidden. \"Within one activity\": only windows whose scans \
            all show one activity, as each of the paper's samples is cut from one activity; the \
            others end just after a change (the last two scans falling after 18 of walking). \
            \"In full view\": only windows with the person seen on every scan; in the others \
            furniture or the robot's path hid them for at least one scan. The paper's F1 is \
            the support-weighted one (recomputed from its Boolean-grid per-class table and test \
            counts: 91.27 %); its macro F1 is derived from that table, so only for the Boolean \
            grid.\n\n";
    if let Some(spread) = &m.test.per_episode {
        let at = |e: &EpisodeAccuracy| {
            e.fixed_lidar_at
                .map(|[x, y]| format!(", Lidar at ({x:.2}, {y:.2}) m"))
                .unwrap_or_default()
        };
        let what = if index.spec.fixed_lidar {
            let (worst, best) = PAPER_FIXED_LIDAR_ACCURACY;
            format!(
                "Fixed Lidar, one random spot per test episode (paper, fixed Lidar: {best:.1} % \
                 at the best position, {worst:.1} % at the worst)"
            )
        } else {
            "Moving robot, per test episode".to_string()
        };
        out += &format!(
            "{what}: best {} % (episode {}, {}{}), median {} %, worst {} % (episode {}, {}{}) \
             over {} episodes of at least {MIN_EPISODE_WINDOWS} windows.\n\n",
            pct(spread.best.accuracy),
            spread.best.episode,
            spread.best.scene,
            at(&spread.best),
            pct(spread.median),
            pct(spread.worst.accuracy),
            spread.worst.episode,
            spread.worst.scene,
            at(&spread.worst),
            spread.episodes
        );
    }
    out += &format!(
        "Per class on the test split, recall / precision in % (paper: Boolean grid{}):\n\n",
        if index.spec.fixed_lidar {
            ", moving robot; it gives none for a fixed Lidar"
        } else {
            ""
        }
    );
    out += "| class | ours recall | ours precision | ours F1 | ours recall, within one activity | paper recall | paper precision |\n|---|---|---|---|---|---|---|\n";
    for a in Activity::ALL {
        let (pr, pp) = PAPER_BOOLEAN[a.index()];
        let [recall, precision, f1] = m.test.all.class_cells(a);
        let [within_recall, _, _] = m.test.within_one_activity.class_cells(a);
        out += &format!(
            "| {} | {recall} | {precision} | {f1} | {within_recall} | {pr:.1} | {pp:.1} |\n",
            a.label()
        );
    }
    out += "\n\"-\": no test window of the class (recall), none predicted as it (precision), \
            neither (F1).\n";
    out += "\nConfusion matrix on the test split (rows: truth, columns: prediction, class order above):\n\n";
    out += "| | ";
    out += &(0..Activity::COUNT)
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(" | ");
    out += " |\n|---|";
    out += &"---|".repeat(Activity::COUNT);
    out += "\n";
    for (a, row) in Activity::ALL.iter().zip(&m.test.all.confusion) {
        out += &format!("| {} {} | ", a.index(), a.label());
        out += &row
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(" | ");
        out += " |\n";
    }
    out += &format!(
        "\nInference: {:.3} ms per model step (mean), {:.3} ms p99, {} ONNX Runtime thread(s); \
         streaming runs one step per state and scan: `lanes` of them (2 in \
         config/classifier.yaml), and with a pose head `pose_head_lanes_between` more between \
         each two (4 states in all as shipped).\n\nThe PNGs `confusion_<split>.png` draw the \
         same matrices, each cell with its count and share of the row (shade: the share; blue \
         diagonal, red errors).\n",
        m.step_ms_mean, m.step_ms_p99, m.threads
    );
    out
}

/// The confusion picture's layout: a title line, the columns' title and (upright) class names
/// above the cells, the rows' title and class names on their left.
const CONFUSION_CELL: i32 = 56;
const CONFUSION_NAMES: i32 = 150;
const CONFUSION_TITLE: i32 = 28;
const CONFUSION_LEFT: i32 = 24 + CONFUSION_NAMES;
const CONFUSION_TOP: i32 = CONFUSION_TITLE + 20 + CONFUSION_NAMES;
const CONFUSION_MARGIN: i32 = 12;
const CONFUSION_FONT: f64 = 13.0;

/// The top left corner of the cell of true class `row`, predicted `column`.
fn confusion_cell(row: usize, column: usize) -> (i32, i32) {
    (
        CONFUSION_LEFT + column as i32 * CONFUSION_CELL,
        CONFUSION_TOP + row as i32 * CONFUSION_CELL,
    )
}

/// A row-normalised confusion matrix as coloured cells (truth down, prediction across), each
/// with its count and its share of the row, under a title naming `split`.
fn draw_confusion(confusion: &ConfusionMatrix, split: &str, path: &Path) -> anyhow::Result<()> {
    let n = Activity::COUNT as i32;
    let size = (
        (CONFUSION_LEFT + n * CONFUSION_CELL + CONFUSION_MARGIN) as u32,
        (CONFUSION_TOP + n * CONFUSION_CELL + CONFUSION_MARGIN) as u32,
    );
    let root = BitMapBackend::new(path, size).into_drawing_area();
    let draw = |e: &dyn std::fmt::Display| anyhow::anyhow!("cannot draw {}: {e}", path.display());
    let text = |size: f64, colour: &RGBColor, h: HPos, v: VPos| {
        font(size)
            .map(|f| f.color(colour).pos(Pos::new(h, v)))
            .map_err(|e| draw(&e))
    };
    root.fill(&WHITE).map_err(|e| draw(&e))?;
    let centre = text(CONFUSION_FONT, &BLACK, HPos::Center, VPos::Center)?;
    let matrix_middle = (
        CONFUSION_LEFT + n * CONFUSION_CELL / 2,
        CONFUSION_TOP + n * CONFUSION_CELL / 2,
    );
    root.draw(&Text::new(
        format!("{split} split: count and share of the row in each cell"),
        (size.0 as i32 / 2, CONFUSION_TITLE / 2),
        &centre,
    ))
    .map_err(|e| draw(&e))?;
    root.draw(&Text::new(
        "predicted class",
        (matrix_middle.0, CONFUSION_TITLE + 10),
        &centre,
    ))
    .map_err(|e| draw(&e))?;
    root.draw(&Text::new(
        "true class",
        (10, matrix_middle.1),
        centre.transform(FontTransform::Rotate270),
    ))
    .map_err(|e| draw(&e))?;
    let row_name = text(CONFUSION_FONT, &BLACK, HPos::Right, VPos::Center)?;
    // Turned a quarter, read upwards from the cells.
    let column_name =
        text(CONFUSION_FONT, &BLACK, HPos::Left, VPos::Center)?.transform(FontTransform::Rotate270);
    for (k, a) in Activity::ALL.iter().enumerate() {
        let (x, y) = confusion_cell(k, k);
        let half = CONFUSION_CELL / 2;
        root.draw(&Text::new(
            a.label(),
            (CONFUSION_LEFT - 6, y + half),
            &row_name,
        ))
        .map_err(|e| draw(&e))?;
        root.draw(&Text::new(
            a.label(),
            (x + half, CONFUSION_TOP - 6),
            &column_name,
        ))
        .map_err(|e| draw(&e))?;
    }
    let counts = confusion.counts();
    for (r, row) in counts.iter().enumerate() {
        let total: u64 = row.iter().sum();
        for (c, &v) in row.iter().enumerate() {
            let share = if total == 0 {
                0.0
            } else {
                v as f64 / total as f64
            };
            let shade = (255.0 * (1.0 - share)).round() as u8;
            // Diagonal in blue, errors in red.
            let colour = if r == c {
                RGBColor(shade, shade, 255)
            } else {
                RGBColor(255, shade, shade)
            };
            let (x, y) = confusion_cell(r, c);
            let corners = [(x, y), (x + CONFUSION_CELL - 1, y + CONFUSION_CELL - 1)];
            root.draw(&Rectangle::new(corners, colour.filled()))
                .map_err(|e| draw(&e))?;
            root.draw(&Rectangle::new(corners, BLACK.stroke_width(1)))
                .map_err(|e| draw(&e))?;
            // Dark cells get white text; empty ones a grey 0.
            let ink = match (v, share > 0.55) {
                (0, _) => RGBColor(150, 150, 150),
                (_, true) => WHITE,
                (_, false) => BLACK,
            };
            let half = CONFUSION_CELL / 2;
            let value = text(CONFUSION_FONT, &ink, HPos::Center, VPos::Center)?;
            // The count, above the share when there is one.
            let count_y = if v == 0 { y + half } else { y + half - 7 };
            root.draw(&Text::new(v.to_string(), (x + half, count_y), &value))
                .map_err(|e| draw(&e))?;
            if v > 0 {
                let percent = text(11.0, &ink, HPos::Center, VPos::Center)?;
                let share = format!("{:.0} %", share * 100.0);
                root.draw(&Text::new(share, (x + half, y + half + 9), &percent))
                    .map_err(|e| draw(&e))?;
            }
        }
    }
    root.present().map_err(|e| draw(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unseen_rooms_the_model_trained_in_are_refused_by_name() {
        let trained_on = |scenes: &[&str], held_out: &[&str]| Generator {
            command: String::new(),
            scenes: scenes.iter().map(|s| s.to_string()).collect(),
            held_out: held_out.iter().map(|s| s.to_string()).collect(),
            episodes: 8,
            seed: 1,
            test_fraction: Some(0.25),
            episode_seconds: 60.0,
            person_points: String::new(),
        };
        let episode = |scene: &str, split: &str| EpisodeEntry {
            id: 0,
            scene: scene.into(),
            scene_file: String::new(),
            seed: 7,
            split: split.into(),
            scans: 1200,
            person_visible_scans: 1000,
            windows: 10,
            fixed_lidar_at: None,
        };
        let episodes = [
            episode("hall", "train"),
            episode("hall", "test"),
            episode("office", "test_unseen"),
            episode("office", "test_unseen"),
        ];
        let check = |generator: &Generator| {
            check_unseen_rooms_unseen(generator, &episodes, Path::new("d"), Path::new("m.json"))
        };
        check(&trained_on(&["hall", "office"], &["office"])).unwrap();
        check(&trained_on(&["hall"], &[])).unwrap();
        let err = check(&trained_on(&["hall", "office"], &[]))
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("d: its unseen rooms (office) are rooms the model trained in (m.json"),
            "{err}"
        );
    }

    /// A training report that exists but cannot be read is an error naming it and why (a
    /// bare `NaN`, as train.py wrote a diverged epoch's loss until session 57, used to read as
    /// no report); no report, or one naming no dataset, is `None`.
    #[test]
    fn a_training_report_that_cannot_be_read_is_named_with_why() {
        let dir = tempfile::tempdir().unwrap();
        let report = dir.path().join("m.training.json");
        assert!(training_dataset(&report).unwrap().is_none(), "no report");
        let why = |text: &str| {
            std::fs::write(&report, text).unwrap();
            format!("{:#}", training_dataset(&report).unwrap_err())
        };
        let named = report.display().to_string();
        let nan = why(r#"{"dataset_generator": null, "history": [{"loss": NaN}]}"#);
        assert!(
            nan.starts_with(&format!(
                "{named}: the training report is not JSON: expected value at line 1"
            )),
            "{nan}"
        );
        let generator = why(r#"{"dataset_generator": {"seed": "five"}}"#);
        assert!(
            generator.starts_with(&format!("{named}: the training report's dataset_generator")),
            "{generator}"
        );
        for names_none in [r#"{"dataset_generator": null}"#, r#"{"history": []}"#] {
            std::fs::write(&report, names_none).unwrap();
            assert!(training_dataset(&report).unwrap().is_none(), "{names_none}");
        }
        std::fs::create_dir(dir.path().join("d.training.json")).unwrap();
        let unreadable = format!(
            "{:#}",
            training_dataset(&dir.path().join("d.training.json")).unwrap_err()
        );
        assert!(
            unreadable.contains("cannot read the training report"),
            "{unreadable}"
        );
    }

    /// The pixels of a box of the picture, row by row.
    fn pixels(img: &image::RgbImage, (x0, y0): (i32, i32), (w, h): (i32, i32)) -> Vec<[u8; 3]> {
        (y0..y0 + h)
            .flat_map(|y| (x0..x0 + w).map(move |x| img.get_pixel(x as u32, y as u32).0))
            .collect()
    }

    fn dark(pixels: &[[u8; 3]]) -> usize {
        pixels.iter().filter(|p| p.iter().all(|v| *v < 128)).count()
    }

    /// The confusion picture had no text: neither which row or column was which class, nor
    /// which axis was the truth, nor any count. Class names on both axes, the axes' titles
    /// and each cell's count (cells of equal count alike, of different counts not).
    #[test]
    fn the_confusion_picture_names_classes_axes_and_counts() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("confusion_test.png");
        draw_confusion(&confusion(), "test", &png).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        let n = Activity::COUNT as i32;
        let (matrix_w, matrix_h) = (n * CONFUSION_CELL, n * CONFUSION_CELL);
        let title = pixels(&img, (0, 0), (img.width() as i32, CONFUSION_TITLE));
        assert!(dark(&title) > 200, "the title");
        let columns_title = pixels(&img, (CONFUSION_LEFT, CONFUSION_TITLE), (matrix_w, 20));
        assert!(dark(&columns_title) > 50, "predicted class");
        let rows_title = pixels(&img, (0, CONFUSION_TOP), (20, matrix_h));
        assert!(dark(&rows_title) > 50, "true class");
        let (mut rows, mut columns) = (Vec::new(), Vec::new());
        for a in Activity::ALL {
            let (x, y) = confusion_cell(a.index(), a.index());
            let row = pixels(&img, (24, y), (CONFUSION_NAMES - 2, CONFUSION_CELL));
            let column = pixels(
                &img,
                (x, CONFUSION_TOP - CONFUSION_NAMES),
                (CONFUSION_CELL, CONFUSION_NAMES - 2),
            );
            assert!(
                dark(&row) > 20 && dark(&column) > 20,
                "{} unnamed",
                a.label()
            );
            assert!(
                !rows.contains(&row) && !columns.contains(&column),
                "{} named as another",
                a.label()
            );
            rows.push(row);
            columns.push(column);
        }
        let cell = |truth: Activity, predicted: Activity| {
            let corner = confusion_cell(truth.index(), predicted.index());
            pixels(
                &img,
                (corner.0 + 2, corner.1 + 2),
                (CONFUSION_CELL - 4, CONFUSION_CELL - 4),
            )
        };
        use Activity::*;
        // Walking: 3 right (75 %, white on dark blue), 1 taken for running (25 %).
        let three = cell(Walking, Walking);
        let light = three.iter().filter(|p| p.iter().all(|v| *v > 200)).count();
        assert!(
            light > 10,
            "a white count on dark blue: {light} light pixels"
        );
        let one = cell(Walking, Running);
        assert!(dark(&one) > 10, "count 1");
        let zero = cell(Walking, Standing);
        assert_ne!(zero, one);
        assert_eq!(zero, cell(Walking, Crawling), "two empty cells alike");
        assert_ne!(
            zero,
            pixels(&img, (0, 0), (CONFUSION_CELL - 4, CONFUSION_CELL - 4)),
            "a 0 is written"
        );
    }
    use crate::cmd::dataset::FORMAT_VERSION;
    use lidar_har_core::representation::{Framing, RepresentationKind, RepresentationSpec};

    /// Walking 4 (one taken for running), standing 1 (taken for walking); running never
    /// true, standing never predicted, crawling neither.
    fn confusion() -> ConfusionMatrix {
        use Activity::*;
        ConfusionMatrix::from_pairs([
            (Walking, Walking),
            (Walking, Walking),
            (Walking, Walking),
            (Walking, Running),
            (Standing, Walking),
        ])
    }

    fn split_metrics(confusion: &ConfusionMatrix) -> SplitMetrics {
        let scores = || Scores::new(confusion);
        SplitMetrics {
            all: scores(),
            accuracy_at_half_window: 0.6,
            within_one_activity: scores(),
            in_full_view: scores(),
            within_one_activity_in_full_view: scores(),
            seen_at_last_scan: scores(),
            per_episode: None,
        }
    }

    fn metrics(test: SplitMetrics, representation: RepresentationKind) -> Metrics {
        Metrics {
            model: "m.onnx".into(),
            data: "d".into(),
            classes: Activity::ALL.iter().map(|a| a.label()).collect(),
            representation: representation.to_string(),
            framing: "room_fixed".into(),
            test,
            splits: Default::default(),
            step_ms_mean: 0.1,
            step_ms_p99: 0.2,
            threads: 1,
        }
    }

    fn dataset_spec() -> DatasetSpec {
        DatasetSpec {
            representation: RepresentationKind::BooleanGrid,
            framing: Framing::RoomFixed,
            size: 32,
            resolution_m: 0.08,
            window: 20,
            stride: 10,
            scan_rate_hz: 20.0,
            fixed_lidar: false,
        }
    }

    fn index(spec: DatasetSpec) -> DatasetIndex {
        DatasetIndex {
            format_version: FORMAT_VERSION,
            spec,
            classes: Vec::new(),
            generator: Generator {
                command: String::new(),
                scenes: Vec::new(),
                held_out: Vec::new(),
                episodes: 1,
                seed: 1,
                test_fraction: Some(0.2),
                episode_seconds: 60.0,
                person_points: String::new(),
            },
            splits: Default::default(),
            episodes: Vec::new(),
            windows: Vec::new(),
        }
    }

    /// The report's line starting with `start`.
    fn line<'a>(text: &'a str, start: &str) -> &'a str {
        text.lines()
            .find(|l| l.starts_with(start))
            .unwrap_or_else(|| panic!("no line starting with {start:?}:\n{text}"))
    }

    #[test]
    fn classes_without_windows_or_predictions_are_shown_as_unmeasured() {
        let split = split_metrics(&confusion());
        let json = serde_json::to_value(&split).unwrap();
        assert_eq!(json["support"]["walking"], 4);
        assert_eq!(json["support"]["running"], 0);
        assert_eq!(json["recall"]["running"], 0.0, "kept for earlier readers");
        let text = report(
            &metrics(split, RepresentationKind::BooleanGrid),
            &index(dataset_spec()),
        );
        let row = |class: &str| line(&text, &format!("| {class} |")).to_string();
        assert_eq!(
            row("crawling"),
            "| crawling | - | - | - | - | 88.3 | 91.2 |"
        );
        assert_eq!(
            row("running"),
            "| running | - | 0.0 | 0.0 | - | 73.0 | 77.5 |"
        );
        assert_eq!(
            row("standing"),
            "| standing | 0.0 | - | 0.0 | 0.0 | 97.4 | 95.3 |"
        );
        assert_eq!(
            row("walking"),
            "| walking | 75.0 | 75.0 | 75.0 | 75.0 | 83.4 | 87.0 |"
        );
    }

    /// The paper's F1 is support-weighted: ours beside it must be too, and the macro F1 is
    /// set beside the paper's only where its per-class table gives it.
    #[test]
    fn the_papers_f1_is_set_beside_our_support_weighted_f1() {
        // Walking F1 0.75 over 4 windows, standing 0 over 1: weighted 60 %; macro over
        // walking, standing and running (predicted once): 25 %.
        let text = report(
            &metrics(split_metrics(&confusion()), RepresentationKind::BooleanGrid),
            &index(dataset_spec()),
        );
        assert_eq!(
            line(&text, "| F1, support-weighted (%) |"),
            "| F1, support-weighted (%) | 60.0 | - | 91.3 |"
        );
        assert_eq!(
            line(&text, "| macro F1 (%) |"),
            "| macro F1 (%) | 25.0 | - | 89.3 |"
        );
        let text = report(
            &metrics(split_metrics(&confusion()), RepresentationKind::Circles),
            &index(DatasetSpec {
                representation: RepresentationKind::Circles,
                ..dataset_spec()
            }),
        );
        assert_eq!(
            line(&text, "| F1, support-weighted (%) |"),
            "| F1, support-weighted (%) | 60.0 | - | 76.5 |"
        );
        assert_eq!(
            line(&text, "| macro F1 (%) |"),
            "| macro F1 (%) | 25.0 | - | - |"
        );
    }

    /// Used to say 0 windows for a split the dataset does not have, as if scored on none.
    #[test]
    fn a_split_the_dataset_lacks_has_no_window_count() {
        let text = report(
            &metrics(split_metrics(&confusion()), RepresentationKind::BooleanGrid),
            &index(dataset_spec()),
        );
        assert_eq!(line(&text, "| windows |"), "| windows | 5 | - | - |");
    }

    /// A fixed Lidar's figures used to be set beside the paper's moving robot's (91.3 %).
    #[test]
    fn a_fixed_lidar_dataset_is_set_beside_the_papers_fixed_lidar_figures() {
        let fixed = DatasetSpec {
            fixed_lidar: true,
            ..dataset_spec()
        };
        let text = report(
            &metrics(split_metrics(&confusion()), RepresentationKind::BooleanGrid),
            &index(fixed.clone()),
        );
        let header = line(&text, "Model `m.onnx`");
        assert!(
            header.contains("room_fixed, fixed Lidar,")
                && header.contains("(Boolean grid, fixed Lidar: 82.9 % accuracy at its best")
                && !header.contains("moving robot"),
            "{header}"
        );
        for (start, expected) in [
            (
                "| accuracy (%) |",
                "| accuracy (%) | 60.0 | - | 74.0-82.9 |",
            ),
            (
                "| F1, support-weighted (%) |",
                "| F1, support-weighted (%) | 60.0 | - | - |",
            ),
            ("| macro F1 (%) |", "| macro F1 (%) | 25.0 | - | - |"),
            (
                "| accuracy, windows within one activity (%) |",
                "| accuracy, windows within one activity (%) | 60.0 (5 windows) | - | 74.0-82.9 |",
            ),
            (
                "| accuracy, within one activity and in full view (%) |",
                "| accuracy, within one activity and in full view (%) | 60.0 (5 windows) | - | \
                 74.0-82.9 |",
            ),
        ] {
            assert_eq!(line(&text, start), expected);
        }
        assert!(
            line(&text, "Per class on the test split").contains("moving robot"),
            "the per-class figures are the moving robot's"
        );
        // The paper gives its fixed-Lidar figures for the Boolean grid only.
        let text = report(
            &metrics(split_metrics(&confusion()), RepresentationKind::Circles),
            &index(DatasetSpec {
                representation: RepresentationKind::Circles,
                ..fixed
            }),
        );
        assert_eq!(
            line(&text, "| accuracy (%) |"),
            "| accuracy (%) | 60.0 | - | - |"
        );
        // The moving robot's as before.
        let text = report(
            &metrics(split_metrics(&confusion()), RepresentationKind::BooleanGrid),
            &index(dataset_spec()),
        );
        assert!(line(&text, "Model `m.onnx`").contains("(Boolean grid, moving robot)."));
        assert_eq!(
            line(&text, "| accuracy (%) |"),
            "| accuracy (%) | 60.0 | - | 91.3 |"
        );
    }

    /// `--threads 0` used to reach the model loader, whose error blamed the model file.
    #[test]
    fn zero_threads_are_refused_naming_the_flag() {
        #[derive(clap::Parser)]
        struct Command {
            #[command(flatten)]
            args: EvaluateArgs,
        }
        let parse = |threads: &str| {
            <Command as clap::Parser>::try_parse_from([
                "evaluate".to_string(),
                "--model=m.onnx".to_string(),
                "--data=d".to_string(),
                "--out=o".to_string(),
                format!("--threads={threads}"),
            ])
            .map(|c| c.args.threads)
        };
        assert_eq!(parse("2").unwrap(), 2);
        for (threads, needle) in [
            ("0", "must be at least 1"),
            ("-1", "not a whole number"),
            ("x", "not a whole number"),
        ] {
            let error = parse(threads).unwrap_err().to_string();
            assert!(
                error.contains(&format!("'{threads}' for '--threads <THREADS>'"))
                    && error.contains(needle),
                "{threads}: {error}"
            );
        }
    }

    #[test]
    fn a_dataset_of_other_windows_than_the_models_is_refused() {
        let dataset = dataset_spec();
        let model = StreamSpec {
            representation: RepresentationSpec::new(
                dataset.representation,
                dataset.framing,
                dataset.size,
                dataset.resolution_m,
            ),
            window: dataset.window,
            scan_rate_hz: dataset.scan_rate_hz,
        };
        let path = Path::new("models/activity.onnx");
        check_model_matches(&model, &dataset, path).expect("the same spec is accepted");
        let shorter = DatasetSpec {
            window: 10,
            ..dataset
        };
        let error = check_model_matches(&model, &shorter, path)
            .expect_err("a 10-scan dataset for a 20-scan model")
            .to_string();
        assert_eq!(
            error,
            "models/activity.onnx: the model was trained on windows of 20 scans, the \
             dataset's are 10 scans"
        );
    }
}
