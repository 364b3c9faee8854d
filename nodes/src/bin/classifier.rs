//! `classifier`: recognises the person's activity and raises fall alerts. Subscribes
//! /human/observation; publishes /human/activity, /human/fall_alert, a text marker on
//! /human/markers and, with a pose head in the configuration, /human/pelvis. The work is the
//! pipeline's classifier stage (ONNX step model), the same code `lidar-har run` runs over a
//! bag. At start it logs the model and the pose head it runs on.
//!
//! Parameters: `config` (a `config/classifier.yaml`-format file; empty = defaults), `model`
//! and `pose_head` (ONNX files; empty = those the configuration names, which are relative
//! to the working directory, so launch files pass the installed ones; `pose_head:=none`
//! turns the head off).

use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use lidar_har::{NodeInfo, Outputs, Shutdown, bad_parameter, optional_path};
use lidar_har_pipeline::classifier::{
    ClassifierConfig, ClassifierError, ClassifierStage, load_classifier_config,
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
    match optional_path(p, "pose_head")? {
        Some(head) if head.as_os_str() == "none" => config.pose_head = None,
        Some(head) => config.pose_head = Some(head),
        None => {}
    }
    let model = optional_path(p, "model")?;
    let model_path = model.as_deref().unwrap_or(&config.model);
    let mut stage = ClassifierStage::load(&config, Some(model_path))
        .map_err(|e| load_error(e, config_path.as_deref()))?;
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

/// A failed [`ClassifierStage::load`], blamed on what is at fault: the installation (status
/// 1, the message says the fix), the `config` file (`config_path`) when its lanes do not fit
/// the model, else `model`.
fn load_error(e: ClassifierError, config_path: Option<&Path>) -> anyhow::Error {
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
        let text = load_error(lanes8(), Some(Path::new("/c/lanes8.yaml"))).to_string();
        assert!(
            text.starts_with(
                "parameter `config`: classifier configuration /c/lanes8.yaml: lanes = 8"
            ) && text.contains("do not fit model /m/window4.onnx (a window of 4 scans)"),
            "{text}"
        );
        let text = load_error(lanes8(), None).to_string();
        assert!(
            text.starts_with("parameter `model`: lanes = 8")
                && text.contains("the default classifier configuration"),
            "{text}"
        );
    }
}
