//! One module per subcommand. Each defines its clap arguments and a `run` function.

pub mod alerts;
pub mod bag;
pub mod dataset;
pub mod demo;
pub mod evaluate;
pub mod random_scenes;
pub mod run;
pub mod simulate;
pub mod topic;

use std::path::Path;

use lidar_har_bag::MetadataVersion;
use lidar_har_pipeline::classifier::{ClassifierConfig, load_classifier_config};

/// The classifier configuration a command runs with: `--classifier-config`'s file (defaults
/// when absent) with its `model` replaced by `--model` when that is given. Shared, so that
/// every command takes its model from the same place.
pub fn classifier_config(
    config: Option<&Path>,
    model: Option<&Path>,
) -> anyhow::Result<ClassifierConfig> {
    let mut classifier = match config {
        Some(path) => load_classifier_config(path)?,
        None => ClassifierConfig::default(),
    };
    if let Some(model) = model {
        classifier.model = model.to_path_buf();
    }
    Ok(classifier)
}

/// `--rosbag2-version`'s value, for every command that writes a bag: 8 (Humble, Iron and
/// later read it) or 9 (Jazzy and later). Without the option, `bag convert` and `run` take
/// [`MetadataVersion::like_source`], `simulate` 9.
pub fn parse_metadata_version(s: &str) -> Result<MetadataVersion, String> {
    s.parse()
}

/// Makes the folder of an output file given as `flag` now, so that a bad path fails before
/// the work rather than after it.
pub fn prepare_output_file(path: &Path, flag: &str) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(folder) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder)
            .with_context(|| format!("{flag} {}: cannot create its folder", path.display()))?;
    }
    anyhow::ensure!(
        !path.is_dir(),
        "{flag} {}: is a folder, not a file",
        path.display()
    );
    Ok(())
}

/// Whether `a` and `b` name one file (links followed), whether it exists yet or not.
pub fn same_file(a: &Path, b: &Path) -> bool {
    let resolve = |path: &Path| -> Option<std::path::PathBuf> {
        if let Ok(full) = path.canonicalize() {
            return Some(full);
        }
        let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
        let folder = folder.unwrap_or(Path::new(".")).canonicalize().ok()?;
        Some(folder.join(path.file_name()?))
    };
    matches!((resolve(a), resolve(b)), (Some(a), Some(b)) if a == b)
}

/// A path for a message; a relative one says what it is relative to, since configuration
/// files name models relative to the folder the command runs in, not to themselves.
pub fn shown_path(path: &Path) -> String {
    match std::env::current_dir() {
        Ok(folder) if path.is_relative() => {
            format!("{} (relative to {})", path.display(), folder.display())
        }
        _ => path.display().to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_sees_one_file_under_two_names_existing_or_not() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("r.zst");
        let other = dir.path().join("sub/../r.zst");
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        assert!(same_file(&file, &other), "not yet written");
        std::fs::write(&file, b"readings").unwrap();
        assert!(same_file(&file, &other));
        std::os::unix::fs::symlink(&file, dir.path().join("link")).unwrap();
        assert!(same_file(&file, &dir.path().join("link")));
        assert!(!same_file(&file, &dir.path().join("report.json")));
    }

    #[test]
    fn the_model_is_the_command_lines_else_the_configurations_else_the_default() {
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("classifier.yaml");
        std::fs::write(&config, "model: from_config.onnx\n").unwrap();
        let model = |config: Option<&Path>, model: Option<&Path>| {
            classifier_config(config, model).unwrap().model
        };
        let given = Path::new("given.onnx");
        assert_eq!(model(Some(&config), Some(given)), given);
        assert_eq!(model(Some(&config), None), Path::new("from_config.onnx"));
        assert_eq!(model(None, None), ClassifierConfig::default().model);
        let missing = dir.path().join("missing.yaml");
        let error = classifier_config(Some(&missing), None)
            .unwrap_err()
            .to_string();
        assert!(error.contains("missing.yaml"), "{error}");
    }

    #[test]
    fn a_rosbag2_version_other_than_8_or_9_is_refused_saying_which_read_what() {
        assert_eq!(parse_metadata_version("8"), Ok(MetadataVersion::V8));
        assert_eq!(parse_metadata_version("9"), Ok(MetadataVersion::V9));
        assert!(
            parse_metadata_version("5")
                .unwrap_err()
                .contains("expected 8, read by Humble")
        );
    }
}
