//! `lidar-har dataset`: labelled windows for training, made by the real pipeline.
//!
//! Per episode (a scene, a seed and a randomised activity script covering the nine classes):
//! the simulator runs, the real localiser (map subtraction, clustering, tracker) finds the
//! person in each scan, the person's points become an image (`lidar_har_core::representation`)
//! and the scans are cut into windows of `T` scans with a label per scan. Episodes, never
//! windows, are split into train and test; scenes named by `--held-out` are never trained on
//! and form the `test_unseen` split. Layout on disk: docs/training.md.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{Context, bail};
use glam::DVec2;
use indicatif::{ProgressBar, ProgressStyle};
use lidar_har_core::activity::Activity;
use lidar_har_core::localiser::{Localiser, LocaliserConfig, Motion, Reference};
use lidar_har_core::representation::{Framing, Renderer, RepresentationKind, RepresentationSpec};
use lidar_har_core::scan::Scan;
use lidar_har_pipeline::bag_run::StopRequest;
use lidar_har_sim::lidar::ScanGeometry;
use lidar_har_sim::map::{DEFAULT_RESOLUTION, OccupancyMap as SimMap};
use lidar_har_sim::scripts::{self, ScriptKind};
use lidar_har_sim::{Scene, Simulator};
use ndarray::{Array2, Array3, Array4, Axis, s};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Bumped when the layout of `index.json` or the arrays changes.
pub const FORMAT_VERSION: u32 = 1;
const DEFAULT_TEST_FRACTION: f64 = 0.2;
pub const SPLITS: [&str; 3] = ["train", "test", "test_unseen"];

#[derive(clap::Args, Debug, Clone)]
pub struct DatasetArgs {
    /// Scene files, as globs or paths (e.g. 'config/scenes/*.yaml' out/rooms/*.yaml).
    #[arg(long, required = true, num_args = 1..)]
    pub scenes: Vec<String>,
    /// Episodes over the training scenes (train + test); the held-out scenes get as many more
    /// as the test split has, and at least one each. Which episodes are test depends on it
    /// (and on `--test-fraction`) while each episode depends only on `--seed` and its number:
    /// the same `--seed` with another count gives the same episodes split otherwise, so a
    /// model trained on one would be tested on its own training episodes (`evaluate` refuses
    /// that when the model's training report lies beside it). Test with another `--seed`.
    #[arg(long, default_value_t = 40)]
    pub episodes: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory (created; existing dataset files are replaced).
    #[arg(long)]
    pub out: PathBuf,
    /// The image made of each scan: boolean_grid, circles or ellipses.
    #[arg(long, default_value = "boolean_grid")]
    pub representation: RepresentationKind,
    /// Where the image is centred: person_centred, or room_fixed (the paper's; the
    /// committed model's).
    #[arg(long, default_value = "person_centred")]
    pub framing: Framing,
    /// Image side, pixels (a multiple of 4 for the model's encoder).
    #[arg(long, default_value_t = 32)]
    pub size: usize,
    /// Metres per pixel.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Scans per window (T).
    #[arg(long, default_value_t = 20)]
    pub window: usize,
    /// Scans between the starts of consecutive windows.
    #[arg(long, default_value_t = 10)]
    pub stride: usize,
    /// Share of the training scenes' episodes that go to the test split (rounded to whole
    /// episodes; neither split may end up empty, unless 0 is given for no test split).
    #[arg(long, default_value_t = DEFAULT_TEST_FRACTION)]
    pub test_fraction: f64,
    /// Scene names (their `name:` field; comma-separated or repeated) kept out of training:
    /// the `test_unseen` split.
    #[arg(long, value_delimiter = ',')]
    pub held_out: Vec<String>,
    /// Seconds simulated per episode.
    #[arg(long, default_value_t = 60.0)]
    pub episode_seconds: f64,
    /// A Lidar fixed in the room (at a random free spot per episode) instead of the moving robot.
    #[arg(long)]
    pub fixed_lidar: bool,
    /// Worker threads (episodes run in parallel); at least 1.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

/// What every image and window of a dataset was made with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetSpec {
    pub representation: RepresentationKind,
    pub framing: Framing,
    pub size: usize,
    pub resolution_m: f64,
    pub window: usize,
    pub stride: usize,
    pub scan_rate_hz: f64,
    pub fixed_lidar: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeEntry {
    pub id: usize,
    pub scene: String,
    pub scene_file: String,
    pub seed: u64,
    pub split: String,
    pub scans: usize,
    /// Scans in which the localiser had the person in view.
    pub person_visible_scans: usize,
    pub windows: usize,
    /// Where the Lidar stood (map frame, metres) in a `--fixed-lidar` dataset: each episode
    /// has its own spot, so per-episode accuracy compares Lidar placements.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_lidar_at: Option<[f64; 2]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowEntry {
    pub split: String,
    /// Row in the split's arrays.
    pub row: usize,
    pub episode: usize,
    pub start_scan: usize,
    /// Stamp of the window's first scan, seconds from the episode start.
    pub start_s: f64,
    /// The activity at the window's last scan.
    pub label: Activity,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitEntry {
    pub windows: usize,
    /// `[windows, T, size, size]` uint8: pixel value x 255.
    pub images: String,
    /// `[windows, T]` uint8: the class index of each scan.
    pub labels: String,
    /// `[windows, T, 4]` float32: the pelvis (ground truth) and the localiser's position,
    /// metres from the scan's image centre along the map's x and y, NaN where the localiser
    /// did not see the person: what a pose head learns from. Absent in older datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<String>,
    /// Windows per class (by last label), class order.
    pub class_counts: Vec<usize>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Generator {
    pub command: String,
    pub scenes: Vec<String>,
    pub held_out: Vec<String>,
    pub episodes: usize,
    pub seed: u64,
    /// With `seed` and `episodes`, what decides the split. Recorded since session 48; before,
    /// only in `command` ([`Generator::test_fraction`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_fraction: Option<f64>,
    pub episode_seconds: f64,
    /// How the person's points were found.
    pub person_points: String,
}

impl Generator {
    /// The test fraction the dataset was made with: recorded, else read from the recorded
    /// command line (the default when it names none; the default has not changed).
    fn test_fraction(&self) -> Option<f64> {
        if self.test_fraction.is_some() {
            return self.test_fraction;
        }
        let mut words = self.command.split_whitespace();
        while let Some(word) = words.next() {
            if word == "--test-fraction" {
                return words.next()?.parse().ok();
            }
            if let Some(value) = word.strip_prefix("--test-fraction=") {
                return value.parse().ok();
            }
        }
        Some(DEFAULT_TEST_FRACTION)
    }

    /// The options that decide the split, as the command line gives them.
    pub(crate) fn split_options(&self) -> String {
        let fraction = self
            .test_fraction()
            .map_or("?".to_string(), |f| f.to_string());
        format!(
            "--seed {} --episodes {} --test-fraction {fraction}",
            self.seed, self.episodes
        )
    }

    /// What this run of `lidar-har dataset` (`args` over `scenes`) records of how it made
    /// its episodes.
    fn of(args: &DatasetArgs, scenes: &[(String, Scene)]) -> Self {
        Self {
            command: std::env::args_os()
                .map(|arg| arg.to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join(" "),
            scenes: scenes.iter().map(|(_, s)| s.name.clone()).collect(),
            held_out: args.held_out.clone(),
            episodes: args.episodes,
            seed: args.seed,
            test_fraction: Some(args.test_fraction),
            episode_seconds: args.episode_seconds,
            person_points:
                "localiser (map subtraction, clustering, tracker; lidar_har_core::localiser)"
                    .to_string(),
        }
    }

    /// The (scene name, simulator seed) of every episode a dataset made so trained on: the
    /// training scenes' episodes outside its test split. `None` when its test fraction cannot
    /// be told, or its episode count is more than `dataset` makes (a damaged report).
    pub(crate) fn trained_episodes(&self) -> Option<HashSet<(String, u64)>> {
        if self.episodes > MAX_EPISODES {
            return None;
        }
        let test = test_episodes(self.seed, self.episodes, self.test_fraction()?);
        let seen: Vec<&String> = self
            .scenes
            .iter()
            .filter(|name| !self.held_out.contains(name))
            .collect();
        if seen.is_empty() {
            return Some(HashSet::new());
        }
        Some(
            (0..self.episodes)
                .filter(|id| !test.contains(id))
                .map(|id| {
                    let seed = episode_seed(self.seed, id, EpisodeStream::Dataset);
                    (seen[id % seen.len()].clone(), seed)
                })
                .collect(),
        )
    }
}

/// `index.json`: everything about a dataset except the pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetIndex {
    pub format_version: u32,
    pub spec: DatasetSpec,
    pub classes: Vec<String>,
    pub generator: Generator,
    pub splits: std::collections::BTreeMap<String, SplitEntry>,
    pub episodes: Vec<EpisodeEntry>,
    pub windows: Vec<WindowEntry>,
}

impl DatasetIndex {
    /// Reads and checks `dir/index.json` (classes in `Activity::ALL` order, rows consistent).
    pub fn load(dir: &Path) -> anyhow::Result<Self> {
        let path = dir.join("index.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let index: DatasetIndex = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a lidar-har dataset index", path.display()))?;
        if index.format_version != FORMAT_VERSION {
            bail!(
                "{}: format version {} (this build reads {FORMAT_VERSION})",
                path.display(),
                index.format_version
            );
        }
        let expected: Vec<&str> = Activity::ALL.iter().map(|a| a.label()).collect();
        if index.classes != expected {
            bail!(
                "{}: classes {:?} differ from the class order {:?}",
                path.display(),
                index.classes,
                expected
            );
        }
        Ok(index)
    }

    /// The split's images, per-scan labels and sightings, shape-checked.
    pub fn read_split(&self, dir: &Path, split: &str) -> anyhow::Result<Option<SplitData>> {
        let Some(entry) = self.splits.get(split) else {
            return Ok(None);
        };
        if entry.windows == 0 {
            return Ok(None);
        }
        let images_path = dir.join(&entry.images);
        let labels_path = dir.join(&entry.labels);
        let positions_path = entry.positions.as_ref().map(|file| dir.join(file));
        let (n, t, size) = (entry.windows, self.spec.window, self.spec.size);
        expect_npy_shape(&images_path, &[n, t, size, size])?;
        expect_npy_shape(&labels_path, &[n, t])?;
        if let Some(path) = &positions_path {
            expect_npy_shape(path, &[n, t, 4])?;
        }
        let images: Array4<u8> = ndarray_npy::read_npy(&images_path).with_context(|| {
            format!(
                "cannot read {} as a uint8 [N, T, S, S] array",
                images_path.display()
            )
        })?;
        let labels: Array2<u8> = ndarray_npy::read_npy(&labels_path).with_context(|| {
            format!(
                "cannot read {} as a uint8 [N, T] array",
                labels_path.display()
            )
        })?;
        if let Some(bad) = labels.iter().find(|&&l| l as usize >= Activity::COUNT) {
            bail!(
                "{}: class index {bad} is out of range 0..8",
                labels_path.display()
            );
        }
        let seen = match &positions_path {
            Some(path) => {
                let positions: Array3<f32> = ndarray_npy::read_npy(path).with_context(|| {
                    format!(
                        "cannot read {} as a float32 [N, T, 4] array",
                        path.display()
                    )
                })?;
                positions.map_axis(Axis(2), |p| p[2].is_finite() && p[3].is_finite())
            }
            None => images
                .map_axis(Axis(3), |row| row.iter().any(|&v| v > 0))
                .map_axis(Axis(2), |rows| rows.iter().any(|&r| r)),
        };
        Ok(Some(SplitData {
            images,
            labels,
            seen,
        }))
    }
}

/// One split of a dataset, in memory.
pub struct SplitData {
    /// `[N, T, S, S]`: pixel value x 255.
    pub images: Array4<u8>,
    /// `[N, T]`: the class index of each scan.
    pub labels: Array2<u8>,
    /// `[N, T]`: whether the localiser saw the person on the scan, which is when the robot
    /// publishes. From the positions; in a dataset made before they were written, from a
    /// non-empty image, which misses a person seen outside a room-fixed image.
    pub seen: Array2<bool>,
}

/// One simulated episode, ready to run.
struct EpisodePlan {
    id: usize,
    scene: Scene,
    scene_file: String,
    seed: u64,
    split: &'static str,
}

/// What an episode gives: its windows, their labels and positions.
struct EpisodeWindows {
    windows: RenderedWindows,
    scans: usize,
    visible: usize,
    fixed_lidar_at: Option<[f64; 2]>,
}

/// Makes the dataset `args` asks for; a `stop` request ends it between episodes with nothing
/// written (the scratch arrays removed, a dataset already in `--out` left whole).
pub fn run(args: DatasetArgs, stop: &StopRequest) -> anyhow::Result<()> {
    validate_args(&args)?;
    let spec = RepresentationSpec::new(
        args.representation,
        args.framing,
        args.size,
        args.resolution,
    );
    let renderer = Renderer::new(spec).context("--size/--resolution")?;
    let scenes = with_episode_seconds(load_scenes(&args.scenes)?, args.episode_seconds, 0.0)?;
    check_window_fits(&args, &scenes)?;
    for name in &args.held_out {
        if !scenes.iter().any(|(_, s)| &s.name == name) {
            bail!(
                "--held-out '{name}' is not the name of any scene matched by '{}'",
                args.scenes.join(" ")
            );
        }
    }
    let plans = plan_episodes(&args, &scenes)?;
    let rate_hz = plans.first().map(|p| p.scene.lidar.rate_hz).unwrap_or(20.0);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;

    let bar = ProgressBar::new(plans.len() as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} episodes {pos}/{len} [{bar:30}] {elapsed_precise} eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut writers = SPLITS
        .iter()
        .map(|split| SplitWriter::create(&args.out, split, args.window, args.size))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut episodes = Vec::new();
    let period_s = 1.0 / rate_hz;
    stop.arm();
    run_in_order(
        &plans,
        args.threads,
        |plan| {
            let result = run_episode(plan, &args, &renderer);
            bar.inc(1);
            result
        },
        |plan, result| {
            if let Some(reason) = stop.reason() {
                bail!("{reason}; nothing was written to {}", args.out.display());
            }
            let windows = match result {
                Ok(windows) => windows,
                // A scene too small for a random script (e.g. no room to run) loses that
                // episode only.
                Err(err) => {
                    bar.suspend(|| {
                        errln!(
                            "dataset: skipping episode {} (scene '{}', seed {}): {err:#}",
                            plan.id,
                            plan.scene.name,
                            plan.seed
                        )
                    });
                    return Ok(());
                }
            };
            episodes.push(EpisodeEntry {
                id: plan.id,
                scene: plan.scene.name.clone(),
                scene_file: plan.scene_file.clone(),
                seed: plan.seed,
                split: plan.split.to_string(),
                scans: windows.scans,
                person_visible_scans: windows.visible,
                windows: windows.windows.starts.len(),
                fixed_lidar_at: windows.fixed_lidar_at,
            });
            let k = SPLITS.iter().position(|s| *s == plan.split).unwrap_or(0);
            writers[k].push(plan.id, &windows.windows, period_s)
        },
    )?;
    bar.finish_and_clear();

    // Before anything is renamed: a failed run leaves a dataset already in `--out` whole (the
    // writers remove their files when dropped).
    if let Some(reason) = stop.reason() {
        bail!("{reason}; nothing was written to {}", args.out.display());
    }
    if episodes.is_empty() {
        bail!(
            "no episode could be run (each skipped above); nothing was written to {}",
            args.out.display()
        );
    }
    let mut index = DatasetIndex {
        format_version: FORMAT_VERSION,
        spec: DatasetSpec {
            representation: args.representation,
            framing: args.framing,
            size: args.size,
            resolution_m: args.resolution,
            window: args.window,
            stride: args.stride,
            scan_rate_hz: rate_hz,
            fixed_lidar: args.fixed_lidar,
        },
        classes: Activity::ALL
            .iter()
            .map(|a| a.label().to_string())
            .collect(),
        generator: Generator::of(&args, &scenes),
        splits: Default::default(),
        episodes,
        windows: Vec::new(),
    };
    let mut written = PartialFiles::default();
    for writer in writers {
        let split = writer.finish()?;
        index.splits.insert(split.name.to_string(), split.entry);
        index.windows.extend(split.windows);
        written.0.extend(split.files);
    }
    written.publish(&args.out, &(serde_json::to_string_pretty(&index)? + "\n"))?;
    print_counts(&index);
    outln!(
        "wrote {} windows to {}",
        index.windows.len(),
        args.out.display()
    );
    Ok(())
}

/// Finished arrays under their temporary names, as (temporary, final) paths. Dropped before
/// [`PartialFiles::publish`] has put them in place (an error, a full disk), they are removed:
/// each is as large as a split.
#[derive(Default)]
struct PartialFiles(Vec<(PathBuf, PathBuf)>);

impl PartialFiles {
    /// Puts the arrays, then `index.json` (`index_json`), in place in `out`. The old index goes first: a
    /// dataset cut short here has none, so it reads as not made, never as an index over
    /// another run's arrays (of the same shapes when only the seed or scenes differ).
    fn publish(self, out: &Path, index_json: &str) -> anyhow::Result<()> {
        let index_path = out.join("index.json");
        match std::fs::remove_file(&index_path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot replace {}", index_path.display()));
            }
            _ => {}
        }
        for (partial, path) in &self.0 {
            std::fs::rename(partial, path).with_context(|| {
                format!("cannot rename {} to {}", partial.display(), path.display())
            })?;
        }
        let partial = out.join("index.json.partial");
        std::fs::write(&partial, index_json)
            .and_then(|()| std::fs::rename(&partial, &index_path))
            .with_context(|| format!("cannot write {}", index_path.display()))
            .inspect_err(|_| {
                let _ = std::fs::remove_file(&partial);
            })
    }
}

impl Drop for PartialFiles {
    fn drop(&mut self) {
        // Those put in place are gone from here already.
        for (partial, _) in &self.0 {
            let _ = std::fs::remove_file(partial);
        }
    }
}

/// One split's arrays and index entries, taken an episode at a time as the episodes finish.
struct SplitWriter {
    name: &'static str,
    images: NpyRows<u8>,
    labels: NpyRows<u8>,
    positions: NpyRows<f32>,
    windows: Vec<WindowEntry>,
    counts: Vec<usize>,
}

/// A split written: its entry in the index, its windows', and its arrays as (temporary,
/// final) paths.
struct FinishedSplit {
    name: &'static str,
    entry: SplitEntry,
    windows: Vec<WindowEntry>,
    files: Vec<(PathBuf, PathBuf)>,
}

impl SplitWriter {
    /// `window` scans of `size` x `size` images per row.
    fn create(out: &Path, name: &'static str, window: usize, size: usize) -> anyhow::Result<Self> {
        let file = |array: &str| out.join(format!("{name}_{array}.npy"));
        Ok(Self {
            name,
            images: NpyRows::create(&file("images"), &[window, size, size])?,
            labels: NpyRows::create(&file("labels"), &[window])?,
            positions: NpyRows::create(&file("positions"), &[window, 4])?,
            windows: Vec::new(),
            counts: vec![0; Activity::COUNT],
        })
    }

    fn push(
        &mut self,
        episode: usize,
        part: &RenderedWindows,
        period_s: f64,
    ) -> anyhow::Result<()> {
        let row = self.images.rows;
        for (k, &start) in part.starts.iter().enumerate() {
            let last = part.labels[[k, part.labels.ncols() - 1]] as usize;
            self.counts[last] += 1;
            self.windows.push(WindowEntry {
                split: self.name.to_string(),
                row: row + k,
                episode,
                start_scan: start,
                start_s: start as f64 * period_s,
                label: Activity::from_index(last).unwrap_or(Activity::Standing),
            });
        }
        self.images.push(part.images.view().into_dyn())?;
        self.labels.push(part.labels.view().into_dyn())?;
        self.positions.push(part.positions.view().into_dyn())
    }

    fn finish(self) -> anyhow::Result<FinishedSplit> {
        let entry = SplitEntry {
            windows: self.windows.len(),
            images: self.images.file_name(),
            labels: self.labels.file_name(),
            positions: Some(self.positions.file_name()),
            class_counts: self.counts,
        };
        Ok(FinishedSplit {
            name: self.name,
            entry,
            windows: self.windows,
            files: vec![
                self.images.finish()?,
                self.labels.finish()?,
                self.positions.finish()?,
            ],
        })
    }
}

/// A `.npy` array written a part at a time without holding the parts: their rows go to a
/// data file beside `path` as they come (`.npy.rows`, removed when done or dropped), and
/// `finish` writes the array, its header declaring the rows pushed, under a temporary name.
/// The file is the one `ndarray_npy::write_npy` writes for the gathered array.
struct NpyRows<A> {
    path: PathBuf,
    rows_path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
    row_shape: Vec<usize>,
    rows: usize,
    element: std::marker::PhantomData<A>,
}

impl<A: ndarray_npy::WritableElement + Clone> NpyRows<A> {
    fn create(path: &Path, row_shape: &[usize]) -> anyhow::Result<Self> {
        let rows_path = path.with_extension("npy.rows");
        let file = std::fs::File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&rows_path)
            .with_context(|| format!("cannot create {}", rows_path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            rows_path,
            out: std::io::BufWriter::new(file),
            row_shape: row_shape.to_vec(),
            rows: 0,
            element: std::marker::PhantomData,
        })
    }

    fn file_name(&self) -> String {
        self.path
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_default()
    }

    /// Appends `part`'s rows (its first axis).
    fn push(&mut self, part: ndarray::ArrayViewD<'_, A>) -> anyhow::Result<()> {
        if part.shape()[1..] != self.row_shape[..] {
            bail!(
                "{}: rows of shape {:?}, not {:?}",
                self.path.display(),
                &part.shape()[1..],
                self.row_shape
            );
        }
        let standard = part.as_standard_layout();
        let Some(elements) = standard.as_slice() else {
            bail!("an array in standard layout is not contiguous");
        };
        A::write_slice(elements, &mut self.out)
            .with_context(|| format!("cannot write {}", self.rows_path.display()))?;
        self.rows += part.shape()[0];
        Ok(())
    }

    /// Writes the array under a temporary name; returns (temporary, final) paths.
    fn finish(mut self) -> anyhow::Result<(PathBuf, PathBuf)> {
        use std::io::{Seek, Write};
        let partial = self.path.with_extension("npy.partial");
        let shape: Vec<usize> = std::iter::once(self.rows)
            .chain(self.row_shape.iter().copied())
            .collect();
        let mut write = || -> anyhow::Result<()> {
            self.out.flush()?;
            let rows = self.out.get_mut();
            let data_len = rows.stream_position()?;
            rows.rewind()?;
            let file = std::fs::File::create(&partial)?;
            // The header, then the data's length in zeros; the cursor stays where the data
            // begins.
            ndarray_npy::write_zeroed_npy::<A, _>(&file, ndarray::IxDyn(&shape))?;
            let copied = std::io::copy(rows, &mut &file)?;
            if copied != data_len {
                bail!("{copied} of {data_len} bytes of the rows copied");
            }
            Ok(())
        };
        write()
            .with_context(|| format!("cannot write {}", partial.display()))
            .inspect_err(|_| {
                let _ = std::fs::remove_file(&partial);
            })?;
        Ok((partial, self.path.clone()))
    }
}

impl<A> Drop for NpyRows<A> {
    fn drop(&mut self) {
        // The rows are in the finished array, or the run failed: spent either way.
        let _ = std::fs::remove_file(&self.rows_path);
    }
}

/// Runs `work` on each item on `threads` threads and hands the results to `take`, on the
/// calling thread, in the items' order. A worker does not start an item more than
/// `2 * threads` ahead of the first one not yet taken, so few results wait at once. The
/// first error from `take` stops the workers (after their current item) and is returned; a
/// panic in `work` stops them too and becomes an error.
fn run_in_order<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    work: impl Fn(&T) -> R + Sync,
    mut take: impl FnMut(&T, R) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    struct Progress {
        next: usize,
        taken: usize,
        stop: bool,
        /// The first item whose work panicked.
        panicked: Option<usize>,
    }
    let ahead = 2 * threads.max(1);
    let progress = Mutex::new(Progress {
        next: 0,
        taken: 0,
        stop: false,
        panicked: None,
    });
    let wake = std::sync::Condvar::new();
    let lock = || {
        progress
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    };
    let stop_workers = || {
        lock().stop = true;
        wake.notify_all();
    };
    let (results, received) = std::sync::mpsc::channel::<(usize, R)>();
    std::thread::scope(|scope| {
        for _ in 0..threads {
            let results = results.clone();
            let (work, wake, lock, stop_workers) = (&work, &wake, &lock, &stop_workers);
            scope.spawn(move || {
                loop {
                    let i = {
                        let mut p = lock();
                        while !p.stop && p.next < items.len() && p.next >= p.taken + ahead {
                            p = wake
                                .wait(p)
                                .unwrap_or_else(|poisoned| poisoned.into_inner());
                        }
                        if p.stop || p.next >= items.len() {
                            break;
                        }
                        p.next += 1;
                        p.next - 1
                    };
                    // A panic (printed by the hook) stops the run: its item never comes.
                    let Ok(result) =
                        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&items[i])))
                    else {
                        lock().panicked.get_or_insert(i);
                        stop_workers();
                        break;
                    };
                    if results.send((i, result)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(results);
        // However the calling thread leaves (error, panic in `take`, or done), no worker is
        // left waiting for it.
        let _stop_on_exit = StopOnDrop(&stop_workers);
        let mut waiting = std::collections::BTreeMap::new();
        let mut taken = 0;
        let mut outcome = Ok(());
        'received: for (i, result) in received.iter() {
            waiting.insert(i, result);
            while let Some(result) = waiting.remove(&taken) {
                outcome = take(&items[taken], result);
                if outcome.is_err() {
                    break 'received;
                }
                taken += 1;
                lock().taken = taken;
                wake.notify_all();
            }
        }
        if outcome.is_ok() && taken < items.len() {
            outcome = Err(match lock().panicked {
                Some(i) => anyhow::anyhow!("item {i} did not finish: it panicked (see above)"),
                None => anyhow::anyhow!("item {taken} did not run (a worker stopped)"),
            });
        }
        outcome
    })
}

/// Runs its closure when dropped, unwinding included.
struct StopOnDrop<'a>(&'a dyn Fn());

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        (self.0)();
    }
}

fn validate_args(args: &DatasetArgs) -> anyhow::Result<()> {
    if args.window < 2 {
        bail!("--window {} must be at least 2 scans", args.window);
    }
    if args.stride == 0 {
        bail!("--stride must be at least 1");
    }
    if !args.size.is_multiple_of(4) {
        bail!(
            "--size {} must be a multiple of 4 (the model's encoder halves it twice)",
            args.size
        );
    }
    if !(args.test_fraction >= 0.0 && args.test_fraction < 1.0) {
        bail!("--test-fraction {} must be in [0, 1)", args.test_fraction);
    }
    if !(1..=MAX_EPISODES).contains(&args.episodes) {
        bail!(
            "--episodes {} must be within 1..={MAX_EPISODES}",
            args.episodes
        );
    }
    if !(args.episode_seconds.is_finite() && args.episode_seconds > 0.0) {
        bail!(
            "--episode-seconds {} must be a positive number",
            args.episode_seconds
        );
    }
    if args.threads == 0 {
        bail!("--threads 0: must be at least 1 (episodes run on this many threads)");
    }
    Ok(())
}

/// Refuses a window longer than an episode before any episode runs (every episode has the
/// same scans: the scenes share one rate).
fn check_window_fits(args: &DatasetArgs, scenes: &[(String, Scene)]) -> anyhow::Result<()> {
    let Some((_, scene)) = scenes.first() else {
        return Ok(());
    };
    let scans = scene.frame_count();
    if scans < args.window as u64 {
        bail!(
            "--window {} is longer than an episode: --episode-seconds {} at {} Hz gives {scans} \
             scans (raise --episode-seconds or lower --window); nothing was written to {}",
            args.window,
            args.episode_seconds,
            scene.lidar.rate_hz,
            args.out.display()
        );
    }
    Ok(())
}

/// The scenes with their `duration` set to `episode_seconds`, each checked as a scene file
/// is, for `run_on_s` more than that (what `alerts` episodes run on): a length the simulator
/// refuses (over its limit, or past the last ROS stamp after a scene's `start_time`) is the
/// option's fault, and would otherwise show only as every episode's script failing.
pub(crate) fn with_episode_seconds(
    mut scenes: Vec<(String, Scene)>,
    episode_seconds: f64,
    run_on_s: f64,
) -> anyhow::Result<Vec<(String, Scene)>> {
    let run_on = if run_on_s > 0.0 {
        format!(
            " plus the {run_on_s} s that episodes run on past their end (with falls: the \
             longest fall and --latency-target-s; staying down: 3 s)"
        )
    } else {
        String::new()
    };
    for (file, scene) in &mut scenes {
        scene.duration = episode_seconds + run_on_s;
        scene.validate().map_err(|(key, message)| {
            anyhow::anyhow!(
                "--episode-seconds {episode_seconds}{run_on}: {key}: {message} (scene {file})"
            )
        })?;
        scene.duration = episode_seconds;
    }
    Ok(scenes)
}

/// Scenes matching the globs (each must match a file), each file once, each with a person (the
/// activities come from it), in the order of their names: the episodes go round-robin over
/// this order, so where the files lie must not change which episodes a seed draws.
pub(crate) fn load_scenes(patterns: &[String]) -> anyhow::Result<Vec<(String, Scene)>> {
    let pattern = patterns.join(" ");
    let mut paths: Vec<PathBuf> = Vec::new();
    for one in patterns {
        let matched: Vec<PathBuf> = glob::glob(one)
            .with_context(|| format!("--scenes '{one}' is not a valid glob"))?
            .collect::<Result<_, _>>()
            .with_context(|| format!("--scenes '{one}'"))?;
        if matched.is_empty() {
            bail!("--scenes '{one}' matches no file");
        }
        paths.extend(matched);
    }
    paths.sort();
    paths.dedup();
    let mut scenes = Vec::new();
    for path in paths {
        let scene = Scene::load(&path)?;
        if scene.person.is_none() {
            errln!("skipping {} (no person in the scene)", path.display());
            continue;
        }
        scenes.push((path.display().to_string(), scene));
    }
    if scenes.is_empty() {
        bail!("--scenes '{pattern}': no scene has a person");
    }
    scenes.sort_by(|(a_file, a), (b_file, b)| (&a.name, a_file).cmp(&(&b.name, b_file)));
    // A model counts scans (its window, the alerts' confirmations): one rate for all.
    let (first_file, first) = &scenes[0];
    if let Some((file, scene)) = scenes
        .iter()
        .find(|(_, s)| s.lidar.rate_hz != first.lidar.rate_hz)
    {
        bail!(
            "--scenes '{pattern}': {file} scans at {} Hz but {first_file} at {} Hz; use scenes \
             of one scan rate",
            scene.lidar.rate_hz,
            first.lidar.rate_hz
        );
    }
    Ok(scenes)
}

/// Episodes round-robin over the scenes; a seeded shuffle picks the test episodes among the
/// training scenes' (whole episodes, never windows); held-out scenes are all `test_unseen`.
fn plan_episodes(
    args: &DatasetArgs,
    scenes: &[(String, Scene)],
) -> anyhow::Result<Vec<EpisodePlan>> {
    let (unseen, seen): (Vec<_>, Vec<_>) = scenes
        .iter()
        .partition(|(_, s)| args.held_out.contains(&s.name));
    if seen.is_empty() {
        bail!("every scene is held out: nothing left to train on");
    }
    let test = test_episodes(args.seed, args.episodes, args.test_fraction);
    if test.is_empty() && args.test_fraction > 0.0 {
        bail!(
            "--test-fraction {} of --episodes {} rounds to no episode: the test split would be \
             empty (raise --episodes, or give --test-fraction 0 for no test split)",
            args.test_fraction,
            args.episodes
        );
    }
    if test.len() == args.episodes {
        bail!(
            "--test-fraction {} of --episodes {} rounds to every episode: the train split would \
             be empty (raise --episodes or lower --test-fraction)",
            args.test_fraction,
            args.episodes
        );
    }
    let mut plans = Vec::new();
    let mut push = |id: usize, (file, scene): &(String, Scene), split: &'static str| {
        let seed = episode_seed(args.seed, id, EpisodeStream::Dataset);
        plans.push(EpisodePlan {
            id,
            scene: scene.clone(),
            scene_file: file.clone(),
            seed,
            split,
        });
    };
    for id in 0..args.episodes {
        let split = if test.contains(&id) { "test" } else { "train" };
        push(id, seen[id % seen.len()], split);
    }
    if !unseen.is_empty() {
        let count = test.len().max(unseen.len());
        for k in 0..count {
            push(args.episodes + k, unseen[k % unseen.len()], "test_unseen");
        }
    }
    Ok(plans)
}

/// The numbers of the test episodes among `episodes` (a seeded shuffle): a share of them, so
/// which they are depends on the count as well as the seed.
fn test_episodes(seed: u64, episodes: usize, test_fraction: f64) -> HashSet<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let test_count = (test_fraction * episodes as f64).round() as usize;
    let mut order: Vec<usize> = (0..episodes).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    order.into_iter().take(test_count).collect()
}

/// Whose episodes a seed makes: `lidar-har alerts` must not replay the episodes a dataset
/// made with the same `--seed` trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum EpisodeStream {
    Dataset,
    Alerts,
}

/// The simulator seed of episode `id` of a run with `seed`. The dataset's are those of every
/// dataset made so far (models/MODEL_CARD.md); the alerts' differ in their top bits, which
/// a dataset seed would reach only above 2^40.
pub(crate) fn episode_seed(seed: u64, id: usize, stream: EpisodeStream) -> u64 {
    let seed = seed.wrapping_mul(1_000_003).wrapping_add(id as u64);
    match stream {
        EpisodeStream::Dataset => seed,
        EpisodeStream::Alerts => seed ^ 0xa1e7_0000_0000_0000,
    }
}

fn run_episode(
    plan: &EpisodePlan,
    args: &DatasetArgs,
    renderer: &Renderer,
) -> anyhow::Result<EpisodeWindows> {
    let mut sim = scripts::episode(
        &plan.scene,
        plan.seed,
        args.fixed_lidar,
        ScriptKind::WithFalls,
    )?;
    let mut localiser = episode_localiser(&sim, args.fixed_lidar)?;
    let geometry = sim.scan_geometry();
    let mut scans: Vec<ScanRecord> = Vec::new();
    let mut visible = 0;
    while let Some(frame) = sim.step() {
        let stamp = frame.stamp_ns as i64;
        if !args.fixed_lidar {
            localiser.add_odometry(stamp, frame.robot);
        }
        let result = localiser.process_scan(&core_scan(&geometry, stamp, frame.ranges));
        let seen = result
            .output
            .as_ref()
            .and_then(|o| o.person.as_ref())
            .filter(|p| p.visible);
        visible += usize::from(seen.is_some());
        scans.push(ScanRecord {
            seen: seen.map(|p| (p.position, p.points.clone())),
            sensor: frame.laser.position(),
            truth: frame
                .person
                .as_ref()
                .map(|p| p.activity)
                .unwrap_or(Activity::Standing),
            pelvis: frame.person.as_ref().map(|p| p.pose.position()),
        });
    }
    let start = sim.scene().robot.start;
    Ok(EpisodeWindows {
        windows: render_windows(&scans, args.window, args.stride, args.framing, renderer),
        scans: scans.len(),
        visible,
        fixed_lidar_at: args.fixed_lidar.then_some([start.x, start.y]),
    })
}

/// One scan of an episode, as the runtime classifier gets it.
struct ScanRecord {
    /// The person's position and points, when the localiser saw them (not when it only
    /// predicted them: the runtime renders and anchors nothing on a hidden person).
    seen: Option<(DVec2, Vec<DVec2>)>,
    sensor: DVec2,
    truth: Activity,
    /// The ground-truth pelvis, when the scene has a person.
    pelvis: Option<DVec2>,
}

/// An episode's windows (every `stride` scans, `window` long).
struct RenderedWindows {
    /// Each window's first scan.
    starts: Vec<usize>,
    images: Array4<u8>,
    /// Per-scan class indices.
    labels: Array2<u8>,
    /// Per scan: pelvis and localiser position from the image centre (`SplitEntry::positions`).
    positions: Array3<f32>,
}

/// Renders the episode's windows. A room-fixed window is centred on its first seen position,
/// as the runtime centres each streaming state (docs/model_contract.md).
fn render_windows(
    scans: &[ScanRecord],
    t: usize,
    stride: usize,
    framing: Framing,
    renderer: &Renderer,
) -> RenderedWindows {
    let starts: Vec<usize> = if scans.len() >= t {
        (0..=scans.len() - t).step_by(stride).collect()
    } else {
        Vec::new()
    };
    let size = renderer.spec().size;
    let mut images = Array4::<u8>::zeros((starts.len(), t, size, size));
    let mut labels = Array2::<u8>::zeros((starts.len(), t));
    let mut positions = Array3::<f32>::from_elem((starts.len(), t, 4), f32::NAN);
    let mut image = Array2::<f32>::zeros((size, size));
    for (w, &start) in starts.iter().enumerate() {
        let window = &scans[start..start + t];
        let anchor = window
            .iter()
            .find_map(|scan| scan.seen.as_ref().map(|s| s.0));
        for (k, scan) in window.iter().enumerate() {
            labels[[w, k]] = scan.truth.index() as u8;
            let Some((position, points)) = &scan.seen else {
                continue;
            };
            let centre = match framing {
                Framing::PersonCentred => *position,
                Framing::RoomFixed => anchor.unwrap_or(*position),
            };
            let from_centre = |p: DVec2| [(p.x - centre.x) as f32, (p.y - centre.y) as f32];
            let pelvis = scan.pelvis.map_or([f32::NAN; 2], from_centre);
            let [ex, ey] = from_centre(*position);
            positions
                .slice_mut(s![w, k, ..])
                .assign(&ndarray::arr1(&[pelvis[0], pelvis[1], ex, ey]));
            renderer.render(
                points.iter().copied(),
                centre,
                scan.sensor,
                image.view_mut(),
            );
            images
                .slice_mut(s![w, k, .., ..])
                .zip_mut_with(&image, |o, &v| {
                    *o = (v.clamp(0.0, 1.0) * 255.0).round() as u8
                });
        }
    }
    RenderedWindows {
        starts,
        images,
        labels,
        positions,
    }
}

/// The real localiser for a simulated episode: the simulator's map, its Lidar mount, and
/// odometry (or a static pose for a fixed Lidar).
pub(crate) fn episode_localiser(sim: &Simulator, fixed_lidar: bool) -> anyhow::Result<Localiser> {
    let map = SimMap::from_world(sim.world(), DEFAULT_RESOLUTION)
        .to_localiser_map()
        .context("simulated map")?;
    let config = LocaliserConfig {
        mount: sim.lidar_mount(),
        ..LocaliserConfig::default()
    };
    let motion = if fixed_lidar {
        Motion::Stationary(sim.scene().robot.start.to_pose())
    } else {
        Motion::Odometry
    };
    Localiser::new(config, Reference::Map(map), motion).context("localiser configuration")
}

/// A simulated frame's scan in the core's form.
pub(crate) fn core_scan(geometry: &ScanGeometry, stamp_ns: i64, ranges: Vec<f32>) -> Scan {
    Scan {
        stamp_ns,
        angle_min: geometry.angle_min as f32,
        angle_increment: geometry.angle_increment as f32,
        time_increment: geometry.time_increment as f32,
        range_min: geometry.range_min as f32,
        range_max: geometry.range_max as f32,
        ranges,
    }
}

fn print_counts(index: &DatasetIndex) {
    out!("{:<20}", "class");
    for split in SPLITS {
        out!("{split:>12}");
    }
    outln!();
    for activity in Activity::ALL {
        out!("{:<20}", activity.label());
        for split in SPLITS {
            let n = index
                .splits
                .get(split)
                .map(|e| e.class_counts[activity.index()])
                .unwrap_or(0);
            out!("{n:>12}");
        }
        outln!();
    }
    out!("{:<20}", "episodes");
    for split in SPLITS {
        out!(
            "{:>12}",
            index.episodes.iter().filter(|e| e.split == split).count()
        );
    }
    outln!();
}

/// More episodes than any dataset needs (the committed model's used 6,000): the plan of each
/// is held in memory from the start, so a typo of 10^12 would abort on the allocation.
const MAX_EPISODES: usize = 1_000_000;

/// The largest `.npy` header read: numpy writes a few hundred bytes.
const MAX_NPY_HEADER: usize = 1 << 16;

/// Checks the shape an `.npy` file's header declares against `expected` before the array is
/// read: the reader allocates what the header declares, so a corrupt one (a shape of 10^13)
/// aborted the process instead of giving an error.
fn expect_npy_shape(path: &Path, expected: &[usize]) -> anyhow::Result<()> {
    let shape =
        npy_shape(path).with_context(|| format!("{}: not a readable .npy file", path.display()))?;
    if shape != expected {
        bail!(
            "{}: shape {shape:?}, index says {expected:?}",
            path.display()
        );
    }
    Ok(())
}

/// The `shape` of an `.npy` file's header (format versions 1 to 3).
fn npy_shape(path: &Path) -> anyhow::Result<Vec<usize>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let mut preamble = [0u8; 8];
    file.read_exact(&mut preamble)?;
    anyhow::ensure!(&preamble[..6] == b"\x93NUMPY", "no .npy magic string");
    let header_len = match preamble[6] {
        1 => {
            let mut len = [0u8; 2];
            file.read_exact(&mut len)?;
            usize::from(u16::from_le_bytes(len))
        }
        2 | 3 => {
            let mut len = [0u8; 4];
            file.read_exact(&mut len)?;
            usize::try_from(u32::from_le_bytes(len))?
        }
        major => bail!("format version {major} unknown"),
    };
    anyhow::ensure!(
        header_len <= MAX_NPY_HEADER,
        "a header of {header_len} bytes"
    );
    let mut header = vec![0u8; header_len];
    file.read_exact(&mut header)?;
    let header = String::from_utf8_lossy(&header);
    let tuple = header
        .split_once("'shape':")
        .and_then(|(_, rest)| rest.split_once('(')?.1.split_once(')'))
        .map(|(inside, _)| inside)
        .context("no shape in the header")?;
    tuple
        .split(',')
        .map(str::trim)
        .filter(|dim| !dim.is_empty())
        .map(|dim| {
            dim.parse::<usize>()
                .with_context(|| format!("shape entry `{dim}`"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_pushed_part_by_part_make_the_file_of_the_gathered_array() {
        let dir = tempfile::tempdir().unwrap();
        fn written<A: ndarray_npy::WritableElement + Clone>(
            path: &Path,
            row_shape: &[usize],
            parts: &[ndarray::ArrayViewD<'_, A>],
        ) -> Vec<u8> {
            let mut rows = NpyRows::<A>::create(path, row_shape).unwrap();
            for part in parts {
                rows.push(part.clone()).unwrap();
            }
            let rows_path = rows.rows_path.clone();
            let (partial, _) = rows.finish().unwrap();
            assert!(!rows_path.exists(), "the rows file is removed once written");
            std::fs::read(partial).unwrap()
        }
        let gathered = |name: &str, write: &dyn Fn(&Path)| {
            let path = dir.path().join(name);
            write(&path);
            std::fs::read(path).unwrap()
        };
        let a = Array4::from_shape_fn((2, 3, 4, 4), |(w, t, y, x)| {
            (w * 64 + t * 16 + y * 4 + x) as u8
        });
        let b = Array4::from_shape_fn((1, 3, 4, 4), |(_, t, y, x)| (200 + t * 16 + y + x) as u8);
        let both = ndarray::concatenate(Axis(0), &[a.view(), b.view()]).unwrap();
        assert_eq!(
            written(
                &dir.path().join("images.npy"),
                &[3, 4, 4],
                &[a.view().into_dyn(), b.view().into_dyn()]
            ),
            gathered("images_gathered.npy", &|path| ndarray_npy::write_npy(
                path, &both
            )
            .unwrap())
        );
        // Another layout (transposed), and f32 elements.
        let p = Array3::from_shape_fn((2, 3, 4), |(w, t, c)| {
            w as f32 - 0.5 * t as f32 + c as f32 / 3.0
        });
        let mut transposed = Array3::<f32>::zeros((4, 3, 2));
        transposed.assign(&p.view().reversed_axes());
        assert_eq!(
            written(
                &dir.path().join("positions.npy"),
                &[3, 4],
                &[transposed.view().reversed_axes().into_dyn()]
            ),
            gathered("positions_gathered.npy", &|path| ndarray_npy::write_npy(
                path, &p
            )
            .unwrap())
        );
        // A split without episodes.
        assert_eq!(
            written::<u8>(&dir.path().join("empty.npy"), &[3], &[]),
            gathered("empty_gathered.npy", &|path| {
                ndarray_npy::write_npy(path, &Array2::<u8>::zeros((0, 3))).unwrap()
            })
        );
        // Rows of another shape are an error naming the array, not a bad file.
        let mut rows = NpyRows::<u8>::create(&dir.path().join("bad.npy"), &[3, 5, 5]).unwrap();
        let err = rows.push(a.view().into_dyn()).unwrap_err();
        assert!(
            format!("{err:#}").contains("bad.npy: rows of shape [3, 4, 4], not [3, 5, 5]"),
            "{err:#}"
        );
        // A run that fails before finishing leaves no rows file behind.
        let rows_path = rows.rows_path.clone();
        assert!(rows_path.exists());
        drop(rows);
        assert!(!rows_path.exists());
    }

    #[test]
    fn results_are_taken_in_order_and_the_first_error_stops_the_run() {
        let items: Vec<usize> = (0..40).collect();
        for threads in [1, 3] {
            let mut order = Vec::new();
            // Later items finish first: the results still come in the items' order.
            run_in_order(
                &items,
                threads,
                |&i| {
                    std::thread::sleep(std::time::Duration::from_micros(((40 - i) * 50) as u64));
                    i * 2
                },
                |&i, doubled| {
                    assert_eq!(doubled, i * 2);
                    order.push(i);
                    Ok(())
                },
            )
            .unwrap();
            assert_eq!(order, items);
        }
        let ran = std::sync::atomic::AtomicUsize::new(0);
        let err = run_in_order(
            &items,
            2,
            |&i| {
                ran.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                i
            },
            |&i, _| {
                if i == 5 {
                    bail!("disk full at item {i}")
                }
                Ok(())
            },
        )
        .unwrap_err();
        assert_eq!(err.to_string(), "disk full at item 5");
        // Workers never run more than 2 x threads items past the one that failed.
        let ran = ran.into_inner();
        assert!(ran <= 5 + 1 + 4, "{ran} items ran");
    }

    /// Runs `run` on its own thread; fails the test if it has not returned within 20 s.
    fn returns_in_time<R: Send + 'static>(run: impl FnOnce() -> R + Send + 'static) -> R {
        let (done, finished) = std::sync::mpsc::channel();
        std::thread::spawn(move || done.send(run()));
        finished
            .recv_timeout(std::time::Duration::from_secs(20))
            .expect("run_in_order hung")
    }

    #[test]
    fn a_panicking_item_stops_the_run_with_an_error_instead_of_hanging_it() {
        let err = returns_in_time(|| {
            let items: Vec<usize> = (0..40).collect();
            run_in_order(
                &items,
                2,
                |&i| {
                    assert_ne!(i, 3, "a bug in episode {i}");
                    i
                },
                |_, _| Ok(()),
            )
            .unwrap_err()
        });
        assert_eq!(
            err.to_string(),
            "item 3 did not finish: it panicked (see above)"
        );
    }

    #[test]
    fn a_panic_while_taking_a_result_does_not_leave_the_workers_waiting() {
        let outcome = returns_in_time(|| {
            std::panic::catch_unwind(|| {
                let items: Vec<usize> = (0..40).collect();
                run_in_order(
                    &items,
                    2,
                    |&i| i,
                    |&i, _| {
                        assert_ne!(i, 3, "a bug in taking item {i}");
                        Ok(())
                    },
                )
            })
        });
        assert!(outcome.is_err(), "the panic reaches the caller");
    }

    /// A dataset written again over an old one, failing half way (here a folder where an
    /// array goes; a full disk alike), is left without an index rather than with the old
    /// index over new arrays, and without the temporary arrays.
    #[test]
    fn a_dataset_that_fails_to_be_put_in_place_keeps_no_stale_index_nor_partial_files() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let files = || {
            let files: Vec<_> = ["a", "b"]
                .map(|name| {
                    (
                        out.join(format!("{name}.npy.partial")),
                        out.join(format!("{name}.npy")),
                    )
                })
                .into();
            for (partial, _) in &files {
                std::fs::write(partial, "rows").unwrap();
            }
            PartialFiles(files)
        };
        let names = || {
            let mut names: Vec<String> = std::fs::read_dir(out)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            names
        };
        std::fs::write(out.join("index.json"), "the old run's").unwrap();
        std::fs::create_dir(out.join("b.npy")).unwrap();
        let err = files().publish(out, "{}").unwrap_err();
        assert!(format!("{err:#}").contains("cannot rename"), "{err:#}");
        assert_eq!(names(), ["a.npy", "b.npy"]);
        // Dropped before publishing (a later split failed to finish): removed too.
        drop(files());
        assert_eq!(names(), ["a.npy", "b.npy"]);
        std::fs::remove_dir(out.join("b.npy")).unwrap();
        files().publish(out, "{}").unwrap();
        assert_eq!(names(), ["a.npy", "b.npy", "index.json"]);
        assert_eq!(std::fs::read_to_string(out.join("b.npy")).unwrap(), "rows");
        assert_eq!(
            std::fs::read_to_string(out.join("index.json")).unwrap(),
            "{}"
        );
    }

    #[test]
    fn an_npy_header_declaring_another_shape_is_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        ndarray_npy::write_npy(&path, &Array2::<u8>::zeros((3, 4))).unwrap();
        npy_shape(&path).unwrap();
        expect_npy_shape(&path, &[3, 4]).unwrap();
        assert!(expect_npy_shape(&path, &[3, 5]).is_err());
        // The same data under a header claiming 10^13 rows: an error, not 40 TB allocated.
        let header = "{'descr': '|u1', 'fortran_order': False, 'shape': (9999999999999, 4), }";
        let header = format!("{header:<117}\n");
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(&[0; 12]);
        let corrupt = dir.path().join("b.npy");
        std::fs::write(&corrupt, &bytes).unwrap();
        let err = expect_npy_shape(&corrupt, &[3, 4]).unwrap_err().to_string();
        assert!(
            err.contains("9999999999999") && err.contains("b.npy"),
            "{err}"
        );
        std::fs::write(&corrupt, b"not npy").unwrap();
        let err = format!("{:#}", expect_npy_shape(&corrupt, &[3, 4]).unwrap_err());
        assert!(err.contains("not a readable .npy file"), "{err}");
    }

    fn shipped_scene_path(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../config/scenes/{name}.yaml"))
    }

    #[test]
    fn a_room_fixed_window_is_centred_on_its_first_seen_position_not_a_predicted_one() {
        let spec =
            RepresentationSpec::new(RepresentationKind::BooleanGrid, Framing::RoomFixed, 16, 0.1);
        let renderer = Renderer::new(spec).unwrap();
        let hidden = || ScanRecord {
            seen: None,
            sensor: DVec2::ZERO,
            truth: Activity::Walking,
            pelvis: Some(DVec2::new(2.0, 0.0)),
        };
        let seen_at = |x: f64| ScanRecord {
            seen: Some((DVec2::new(x, 0.0), vec![DVec2::new(x, 0.0)])),
            sensor: DVec2::ZERO,
            truth: Activity::Walking,
            pelvis: Some(DVec2::new(x + 0.1, -0.05)),
        };
        // Hidden for two scans (the tracker predicting them elsewhere), then seen at x = 3
        // twice and at x = 3.2: the window is centred at 3.
        let scans = [hidden(), hidden(), seen_at(3.0), seen_at(3.0), seen_at(3.2)];
        let RenderedWindows {
            starts,
            images,
            labels,
            positions,
        } = render_windows(&scans, 5, 5, Framing::RoomFixed, &renderer);
        assert_eq!(starts, [0]);
        assert_eq!(labels[[0, 4]], Activity::Walking.index() as u8);
        let lit = |k: usize| -> Vec<(usize, usize)> {
            images
                .slice(s![0, k, .., ..])
                .indexed_iter()
                .filter(|(_, v)| **v > 0)
                .map(|(at, _)| at)
                .collect()
        };
        assert!(
            lit(0).is_empty() && lit(1).is_empty(),
            "nothing drawn while hidden"
        );
        assert_eq!(lit(2), lit(3), "the same spot, the window's anchor");
        assert!(!lit(2).is_empty());
        assert_ne!(lit(4), lit(2), "0.2 m further on, two pixels over");
        assert!(
            positions.slice(s![0, 0..2, ..]).iter().all(|v| v.is_nan()),
            "no position while hidden"
        );
        let last: Vec<f32> = positions.slice(s![0, 4, ..]).to_vec();
        let want = [0.3, -0.05, 0.2, 0.0];
        assert!(
            last.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-5),
            "pelvis and localiser from the anchor at x = 3: {last:?}"
        );
    }

    #[test]
    fn scenes_of_two_scan_rates_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let text = std::fs::read_to_string(shipped_scene_path("living_room")).unwrap();
        std::fs::write(dir.path().join("a.yaml"), &text).unwrap();
        let slow = text.replace("lidar: {}", "lidar: {rate_hz: 10}");
        assert_ne!(slow, text);
        std::fs::write(dir.path().join("b.yaml"), slow).unwrap();
        let pattern = format!("{}/*.yaml", dir.path().display());
        let error = load_scenes(&[pattern]).unwrap_err().to_string();
        assert!(
            error.contains("10 Hz") && error.contains("20 Hz"),
            "{error}"
        );
    }

    #[test]
    fn scenes_are_ordered_by_name_wherever_their_files_lie() {
        let dir = tempfile::tempdir().unwrap();
        let text = std::fs::read_to_string(shipped_scene_path("living_room")).unwrap();
        // By path: zeta, mu, alpha; by name the other way round.
        for (file, name) in [
            ("a/x.yaml", "zeta"),
            ("b/y.yaml", "mu"),
            ("b/z.yaml", "alpha"),
        ] {
            let path = dir.path().join(file);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            let renamed = text.replace("name: living_room", &format!("name: {name}"));
            assert_ne!(renamed, text);
            std::fs::write(path, renamed).unwrap();
        }
        let root = dir.path().display();
        let patterns = [format!("{root}/b/*.yaml"), format!("{root}/a/*.yaml")];
        let names: Vec<String> = load_scenes(&patterns)
            .unwrap()
            .into_iter()
            .map(|(_, scene)| scene.name)
            .collect();
        assert_eq!(names, ["alpha", "mu", "zeta"].map(String::from));
    }

    /// `lidar-har dataset`'s arguments as the command line gives them, with `extra`.
    fn dataset_args(extra: &[&str]) -> DatasetArgs {
        #[derive(clap::Parser)]
        struct Command {
            #[command(flatten)]
            args: DatasetArgs,
        }
        let mut line = vec!["dataset", "--scenes", "s.yaml", "--out", "o"];
        line.extend_from_slice(extra);
        <Command as clap::Parser>::try_parse_from(line)
            .unwrap()
            .args
    }

    #[test]
    fn threads_and_episode_lengths_the_run_cannot_use_are_refused_by_name() {
        validate_args(&dataset_args(&[])).unwrap();
        for (extra, needle) in [
            (&["--threads", "0"][..], "--threads 0: must be at least 1"),
            (&["--episode-seconds", "NaN"][..], "--episode-seconds NaN"),
            (&["--episode-seconds=-5"][..], "--episode-seconds -5"),
            (&["--episode-seconds", "inf"][..], "--episode-seconds inf"),
        ] {
            let error = validate_args(&dataset_args(extra)).unwrap_err().to_string();
            assert!(error.contains(needle), "{extra:?}: {error}");
        }
    }

    #[test]
    fn a_window_longer_than_an_episode_is_refused_before_any_episode_runs() {
        let file = shipped_scene_path("living_room");
        let scenes = |seconds| {
            let scene = Scene::load(&file).unwrap();
            with_episode_seconds(vec![(file.display().to_string(), scene)], seconds, 0.0).unwrap()
        };
        // 2.4 s at 20 Hz: 48 scans, one window of 48.
        let args = dataset_args(&["--window", "48", "--episode-seconds", "2.4"]);
        check_window_fits(&args, &scenes(2.4)).unwrap();
        let error = check_window_fits(&args, &scenes(2.35))
            .unwrap_err()
            .to_string();
        assert_eq!(
            error,
            "--window 48 is longer than an episode: --episode-seconds 2.4 at 20 Hz gives 47 \
             scans (raise --episode-seconds or lower --window); nothing was written to o"
        );
    }

    #[test]
    fn an_episode_length_the_simulator_refuses_names_the_option_and_the_limit() {
        let file = shipped_scene_path("living_room");
        let scenes = || vec![(file.display().to_string(), Scene::load(&file).unwrap())];
        let scenes_of_60_s = with_episode_seconds(scenes(), 60.0, 2.4).unwrap();
        assert_eq!(scenes_of_60_s[0].1.duration, 60.0, "without the run-on");
        for (episode_seconds, run_on_s, needle) in [
            (
                1e12,
                0.0,
                "--episode-seconds 1000000000000: duration: must be within",
            ),
            (
                1e-4,
                0.0,
                "--episode-seconds 0.0001: duration: must be within",
            ),
            (9_999_999.0, 2.4, "--latency-target-s"),
        ] {
            let error = with_episode_seconds(scenes(), episode_seconds, run_on_s)
                .unwrap_err()
                .to_string();
            assert!(
                error.contains(needle)
                    && error.contains("10000000")
                    && error.contains("living_room"),
                "{error}"
            );
        }
        // Past the last ROS stamp after the scene's start_time: named as well.
        let mut late = scenes();
        late[0].1.start_time = 2_140_000_000;
        let error = with_episode_seconds(late, 1e7, 0.0)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("--episode-seconds 10000000: start_time"),
            "{error}"
        );
    }

    /// The episodes `lidar-har dataset` plans over the shipped scenes with `extra` options,
    /// as (scene, simulator seed, split), and the generator it records.
    fn planned(extra: &[&str]) -> (Vec<(String, u64, &'static str)>, Generator) {
        let args = dataset_args(extra);
        let pattern = shipped_scene_path("*").display().to_string();
        let scenes = load_scenes(&[pattern]).unwrap();
        let plans = plan_episodes(&args, &scenes).unwrap();
        let generator = Generator {
            command: format!("lidar-har dataset {}", extra.join(" ")),
            ..Generator::of(&args, &scenes)
        };
        let plans = plans
            .into_iter()
            .map(|p| (p.scene.name, p.seed, p.split))
            .collect();
        (plans, generator)
    }

    #[test]
    fn the_same_seed_with_another_episode_count_tests_on_trained_episodes() {
        let options = |episodes| {
            [
                "--seed",
                "11",
                "--held-out",
                "office",
                "--episodes",
                episodes,
            ]
        };
        let (plans, generator) = planned(&options("40"));
        let trained = generator.trained_episodes().unwrap();
        let of = |plans: &[(String, u64, &str)], test: bool| -> HashSet<(String, u64)> {
            plans
                .iter()
                .filter(|(_, _, split)| (*split != "train") == test)
                .map(|(scene, seed, _)| (scene.clone(), *seed))
                .collect()
        };
        // What the generator says it trained on is what the plan trained on.
        assert_eq!(trained, of(&plans, false));
        assert!(of(&plans, true).is_disjoint(&trained));
        // Twice the episodes: the first 40 are the same, split otherwise.
        let (more, _) = planned(&options("80"));
        let leaked = of(&more, true).intersection(&trained).count();
        assert!(leaked > 0, "{leaked}");
        // Another test fraction splits the same episodes otherwise too.
        let mut fraction = options("40").to_vec();
        fraction.extend(["--test-fraction", "0.4"]);
        assert!(!of(&planned(&fraction).0, true).is_disjoint(&trained));
        // Another seed: other episodes.
        let (other, _) = planned(&["--seed", "12", "--held-out", "office", "--episodes", "80"]);
        assert!(of(&other, true).is_disjoint(&trained));
        // A damaged report's episode count is not enumerated (it used to abort on memory).
        let damaged = Generator {
            episodes: usize::MAX,
            ..generator
        };
        assert_eq!(damaged.trained_episodes(), None);
    }

    #[test]
    fn held_out_scenes_get_as_many_episodes_as_the_test_split_and_one_each_at_least() {
        let unseen = |extra: &[&str]| -> Vec<String> {
            planned(extra)
                .0
                .into_iter()
                .filter(|(_, _, split)| *split == "test_unseen")
                .map(|(scene, _, _)| scene)
                .collect()
        };
        let test = planned(&["--episodes", "40"])
            .0
            .iter()
            .filter(|(_, _, split)| *split == "test")
            .count();
        assert_eq!(test, 8);
        assert_eq!(
            unseen(&["--held-out", "office", "--episodes", "40"]),
            vec!["office"; 8]
        );
        let none_tested = ["--test-fraction", "0", "--episodes", "6"];
        let mut one = vec!["--held-out", "office"];
        one.extend(none_tested);
        assert_eq!(unseen(&one), vec!["office"]);
        let mut two = vec!["--held-out", "office,hall"];
        two.extend(none_tested);
        assert_eq!(unseen(&two), vec!["hall", "office"]);
    }

    #[test]
    fn a_dataset_made_before_the_test_fraction_was_recorded_has_it_in_its_command() {
        let (_, mut generator) = planned(&["--test-fraction", "0.5"]);
        generator.test_fraction = None;
        assert_eq!(generator.test_fraction(), Some(0.5));
        generator.command = "lidar-har dataset --test-fraction=0.3 --out o".into();
        assert_eq!(generator.test_fraction(), Some(0.3));
        generator.command = "lidar-har dataset --seed 4".into();
        assert_eq!(generator.test_fraction(), Some(DEFAULT_TEST_FRACTION));
        assert!(generator.split_options().ends_with("--test-fraction 0.2"));
    }

    #[test]
    fn alerts_episodes_are_not_a_datasets_with_the_same_seed() {
        for seed in [1, 12, 13, 21] {
            for id in 0..3000 {
                let alerts = episode_seed(seed, id, EpisodeStream::Alerts);
                // Dataset seeds in use are small; none of their episodes can meet these.
                assert!(alerts >> 48 != 0, "{seed} {id}");
                assert_ne!(alerts, episode_seed(seed, id, EpisodeStream::Dataset));
            }
        }
    }
}
