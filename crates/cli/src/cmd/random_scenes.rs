//! `lidar-har random-scenes`: random furnished rooms written as scene files, for training
//! on more rooms than `config/scenes/` has (`lidar-har dataset --scenes` takes them beside
//! the drawn ones). Same seeds, same files.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use lidar_har_sim::generate::random_scene;

#[derive(clap::Args, Debug)]
pub struct RandomScenesArgs {
    /// How many rooms.
    #[arg(long, default_value_t = 20)]
    pub count: u64,
    /// The first room's seed; the others follow (`random_<seed>.yaml`).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory (created); one that already holds random rooms is refused.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: RandomScenesArgs) -> anyhow::Result<()> {
    if args.count == 0 {
        anyhow::bail!("--count 0: nothing to write");
    }
    let last = args
        .seed
        .checked_add(args.count - 1)
        .with_context(|| format!("--seed {} + --count {} overflows", args.seed, args.count))?;
    refuse_earlier_rooms(&args.out)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for seed in args.seed..=last {
        let scene = random_scene(seed)?;
        let path = args.out.join(format!("{}.yaml", scene.name));
        let yaml = serde_yaml_ng::to_string(&scene).context("cannot write the scene as YAML")?;
        let text = format!(
            "# A random room (`lidar-har random-scenes`, seed {seed}): {} pieces of furniture.\n\
             # The person's script is a placeholder: `lidar-har dataset` writes its own.\n{yaml}",
            scene.furniture.len()
        );
        std::fs::File::create_new(&path)
            .and_then(|mut file| file.write_all(text.as_bytes()))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    outln!(
        "wrote {} scenes to {} (random_{}.yaml .. random_{last}.yaml)",
        args.count,
        args.out.display(),
        args.seed
    );
    Ok(())
}

/// Refuses a folder that already holds random rooms: they may have been edited, and
/// `dataset --scenes 'DIR/*.yaml'` would take the rooms of both runs.
fn refuse_earlier_rooms(out: &Path) -> anyhow::Result<()> {
    let entries = match std::fs::read_dir(out) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", out.display())),
    };
    let mut earlier: Vec<String> = entries
        .filter_map(|entry| entry.ok()?.file_name().into_string().ok())
        .filter(|name| name.starts_with("random_") && name.ends_with(".yaml"))
        .collect();
    if earlier.is_empty() {
        return Ok(());
    }
    earlier.sort();
    anyhow::bail!(
        "{} already holds {} random rooms ({}{}): choose another folder, or remove them first",
        out.display(),
        earlier.len(),
        earlier[..earlier.len().min(3)].join(", "),
        if earlier.len() > 3 { ", ..." } else { "" }
    )
}
