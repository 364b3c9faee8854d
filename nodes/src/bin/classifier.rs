//! `classifier`: recognises the person's activity and raises fall alerts. Subscribes
//! /human/observation; publishes /human/activity, /human/fall_alert, a text marker on
//! /human/markers and, with a pose head in the configuration, /human/pelvis. The work is the
//! pipeline's classifier stage (ONNX step model), the same code `lidar-har run` runs over a
//! bag. At start it logs the model and the pose head it runs on.
//!
//! Parameters: `config` (a `config/classifier.yaml`-format file; empty = defaults), `model`
//! and `pose_head` (ONNX files; empty = those the configuration names, which are relative
//! to the working directory, so launch files pass the installed ones; `pose_head:=none`
//! turns the head off). A non-empty `model` or `pose_head` wins over the configuration's,
//! with a warning when the configuration sets another than the default.

use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use lidar_har::{NodeInfo, Outputs, Shutdown, bad_parameter, optional_path};
use lidar_har_pipeline::classifier::{
    ClassifierConfig, ClassifierError, ClassifierStage, load_classifier_config, pose_head_setting,
};
use lidar_har_ros::{NodeSetup, ParamDecl, ParamValue};

fn main() -> ExitCode {
    lidar_har::run(
        &NodeInfo {
            name: "classifier",
            about: "recognises the activity of the person the localiser tracks and raises fall alerts",
            parameters: decls,
        },
        classify,
    )
}

fn decls() -> Vec<ParamDecl> {
    use ParamValue as V;
    vec![
        ParamDecl::new(
            "config",
            V::String(String::new()),
            "classifier configuration file; empty = defaults",
        ),
        ParamDecl::new(
            "model",
            V::String(String::new()),
            "ONNX step model; empty = the configuration's",
        ),
        ParamDecl::new(
            "pose_head",
            V::String(String::new()),
            "ONNX pose head for /human/pelvis; empty = the configuration's, none = no head",
        ),
    ]
}

fn classify(shutdown: &Shutdown) -> anyhow::Result<()> {
    let setup = NodeSetup::new("classifier").parameters(decls()).prepare()?;
    // The configuration, the model and ONNX Runtime are loaded before the node joins the
    // graph: a bad one used to be found with the participant up, after the DDS stack's
    // discovery warnings.
    let p = setup.params();
    let config_path = optional_path(p, "config")?;
    let mut config = match &config_path {
        Some(path) => load_classifier_config(path).map_err(|e| bad_parameter("config", e))?,
        None => ClassifierConfig::default(),
    };
    let defaults = ClassifierConfig::default();
    let replaced = |name, set: Option<&Path>, default: Option<&Path>, given: Option<&Path>| {
        let config_path = config_path.as_deref()?;
        replaced_by_parameter(name, config_path, set, default, given)
    };
    if let Some(head) = optional_path(p, "pose_head")? {
        let head = pose_head_setting(Some(head));
        let (set, default) = (config.pose_head.as_deref(), defaults.pose_head.as_deref());
        if let Some(warning) = replaced("pose_head", set, default, head.as_deref()) {
            log::warn!("{warning}");
        }
        config.pose_head = head;
    }
    let model = optional_path(p, "model")?;
    if let Some(model) = &model
        && let Some(warning) = replaced(
            "model",
            Some(&config.model),
            Some(&defaults.model),
            Some(model),
        )
    {
        log::warn!("{warning}");
    }
    let model_path = model.as_deref().unwrap_or(&config.model);
    let mut stage = ClassifierStage::load(&config, Some(model_path))
        .map_err(|e| load_error(e, config_path.as_deref(), model.is_some()))?;
    // Which files the node runs on: a launch file or a working directory can change them.
    log::info!(
        "classifier: model {}; pose head {}",
        model_path.display(),
        stage.pose_head()
    );
    let node = lidar_har::join(setup)?;
    let [input] = ClassifierStage::INPUTS;
    let input = node.subscriber_for(&input)?;
    let outputs = Outputs::new(&node, &ClassifierStage::OUTPUTS)?;
    let mut errors = 0u64;
    while !shutdown.requested() {
        let Some(sample) = input.take_timeout(&node, Duration::from_millis(100))? else {
            continue;
        };
        match stage.handle_cdr(&sample.bytes) {
            Ok((_, outgoing)) => outputs.publish(&outgoing)?,
            Err(e) => {
                errors += 1;
                if errors.is_power_of_two() {
                    log::warn!("{e} ({errors} unusable observations so far)");
                }
            }
        }
    }
    log::info!("classifier: stopped; {errors} unusable observations");
    Ok(())
}

/// The warning when the parameter `name` (`given`; `None`: no pose head) replaces a different
/// `set` that the configuration file `config_path` gives: the launch files always pass the
/// installed model and pose head, so a configuration's own used to go unused without a word.
/// None when the configuration keeps the `default` (a relative path the launch files replace
/// with the installed file) or names the same file.
fn replaced_by_parameter(
    name: &str,
    config_path: &Path,
    set: Option<&Path>,
    default: Option<&Path>,
    given: Option<&Path>,
) -> Option<String> {
    let same_file = |a: &Path, b: &Path| {
        a == b || matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
    };
    let same = match (set, given) {
        (Some(set), Some(given)) => same_file(set, given),
        (set, given) => set == given,
    };
    // `./models/activity.onnx` is the default too (a leading `.` is a path component).
    let plain = |path: &Path| -> std::path::PathBuf {
        path.components()
            .filter(|c| *c != std::path::Component::CurDir)
            .collect()
    };
    if set.map(plain) == default.map(plain) || same {
        return None;
    }
    let show =
        |path: Option<&Path>| path.map_or_else(|| "none".into(), |p| p.display().to_string());
    Some(format!(
        "parameter `{name}` ({}) replaces the `{name}` of the classifier configuration {} ({}): \
         the launch files pass the installed {name}, so set `{name}` in params_file beside \
         `config` for the configuration's to apply (`pose_head: none` for no head)",
        show(given),
        config_path.display(),
        show(set),
    ))
}

/// A failed [`ClassifierStage::load`], blamed on what is at fault: the installation (status
/// 1, the message says the fix), the `config` file (`config_path`) when its lanes do not fit
/// the model or the model is its `model` key's (`model_parameter` false), else `model`.
fn load_error(
    e: ClassifierError,
    config_path: Option<&Path>,
    model_parameter: bool,
) -> anyhow::Error {
    match (e, config_path) {
        (ClassifierError::Model(e), _) if e.is_runtime() => anyhow::Error::new(e),
        (e @ ClassifierError::LanesDoNotFit { .. }, Some(path)) => bad_parameter(
            "config",
            format!("classifier configuration {}: {e}", path.display()),
        )
        .into(),
        (e @ ClassifierError::LanesDoNotFit { .. }, None) => bad_parameter(
            "model",
            format!("{e} (the default classifier configuration; `config` is empty)"),
        )
        .into(),
        // The path came from the file: parameter `model` is empty.
        (e, Some(path)) if !model_parameter => bad_parameter(
            "config",
            format!(
                "classifier configuration {}, key `model`: {e}",
                path.display()
            ),
        )
        .into(),
        (e, _) => bad_parameter("model", e).into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lidar_har_core::classifier::StreamSpecError;

    /// The reviewer's case: `lanes: 8` in the config file against a model of window 4 was
    /// reported as "parameter `model`" without naming the file.
    #[test]
    fn lanes_that_do_not_fit_the_model_blame_the_config_file_and_name_the_model() {
        let lanes8 = || ClassifierError::LanesDoNotFit {
            model: "/m/window4.onnx".into(),
            window: 4,
            lanes: 8,
            lane_period_windows: 1.2,
            cause: StreamSpecError::LaneCount {
                lanes: 8,
                period: 5,
            },
        };
        let text = load_error(lanes8(), Some(Path::new("/c/lanes8.yaml")), true).to_string();
        assert!(
            text.starts_with(
                "parameter `config`: classifier configuration /c/lanes8.yaml: lanes = 8"
            ) && text.contains("do not fit model /m/window4.onnx (a window of 4 scans)"),
            "{text}"
        );
        let text = load_error(lanes8(), None, true).to_string();
        assert!(
            text.starts_with("parameter `model`: lanes = 8")
                && text.contains("the default classifier configuration"),
            "{text}"
        );
    }

    /// A model that fails to load is blamed on where its path came from: the `model` key of
    /// the `config` file when parameter `model` is empty (it used to be "parameter `model`"
    /// there too), else parameter `model`.
    #[test]
    fn a_bad_model_from_the_config_file_blames_config_and_its_key() {
        let bad_model = || {
            ClassifierError::Stream(StreamSpecError::LaneCount {
                lanes: 8,
                period: 5,
            })
        };
        let config = Some(Path::new("/c/my_classifier.yaml"));
        let text = load_error(bad_model(), config, false).to_string();
        assert!(
            text.starts_with(
                "parameter `config`: classifier configuration /c/my_classifier.yaml, key `model`:"
            ),
            "{text}"
        );
        for (config, model_parameter) in [(config, true), (None, false), (None, true)] {
            let text = load_error(bad_model(), config, model_parameter).to_string();
            assert!(text.starts_with("parameter `model`:"), "{text}");
        }
    }

    /// The launch files always pass the installed model and pose head: a configuration's own
    /// used to be replaced without a word. Warned about, naming both, unless the
    /// configuration keeps the default or names the same file.
    #[test]
    fn a_parameter_replacing_the_configurations_own_file_is_warned_about() {
        let dir = scratch_dir();
        let config = dir.join("my_classifier.yaml");
        let (retrained, installed) = (dir.join("retrained.onnx"), dir.join("activity.onnx"));
        let default = Path::new("models/activity.onnx");
        let replaced = |set: &Path, given: &Path| {
            replaced_by_parameter("model", &config, Some(set), Some(default), Some(given))
        };
        let warning = replaced(&retrained, &installed).expect("no warning");
        for needle in [
            "parameter `model`",
            &*installed.display().to_string(),
            &*retrained.display().to_string(),
            &*config.display().to_string(),
            "set `model` in params_file",
        ] {
            assert!(warning.contains(needle), "{needle}: {warning}");
        }
        // The committed configuration keeps the default, which the launch files replace,
        // however it is written.
        assert_eq!(replaced(default, &installed), None);
        assert_eq!(
            replaced(Path::new("./models/activity.onnx"), &installed),
            None
        );
        assert_eq!(replaced(&retrained, &retrained), None);
        // The same file by another path (a link, which only the file system resolves).
        std::fs::write(&retrained, b"").unwrap();
        let link = dir.join("link.onnx");
        std::os::unix::fs::symlink(&retrained, &link).unwrap();
        assert_eq!(replaced(&retrained, &link), None);
        // `pose_head: null` in the configuration, the installed head given.
        let head = Path::new("models/pose_head.onnx");
        let warning = replaced_by_parameter("pose_head", &config, None, Some(head), Some(head))
            .expect("no warning");
        assert!(
            warning.contains("`pose_head` of the classifier configuration")
                && warning.contains("(none)"),
            "{warning}"
        );
        assert_eq!(
            replaced_by_parameter("pose_head", &config, None, Some(head), None),
            None
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A fresh directory of this test process.
    fn scratch_dir() -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("classifier_test_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }
}
