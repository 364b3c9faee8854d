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

/// Makes the folder of an output file given as `flag` now, so that a bad path fails before
/// the work rather than after it.
pub fn prepare_output_file(path: &std::path::Path, flag: &str) -> anyhow::Result<()> {
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

/// A path for a message; a relative one says what it is relative to, since configuration
/// files name models relative to the folder the command runs in, not to themselves.
pub fn shown_path(path: &std::path::Path) -> String {
    match std::env::current_dir() {
        Ok(folder) if path.is_relative() => {
            format!("{} (relative to {})", path.display(), folder.display())
        }
        _ => path.display().to_string(),
    }
}
