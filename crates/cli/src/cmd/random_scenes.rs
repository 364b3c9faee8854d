//! `lidar-har random-scenes`: random furnished rooms written as scene files, for training
//! on more rooms than `config/scenes/` has (`lidar-har dataset --scenes` takes them beside
//! the drawn ones). Same seeds, same files.

use std::path::PathBuf;

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
    /// Output directory (created).
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
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    outln!(
        "wrote {} scenes to {} (random_{}.yaml .. random_{last}.yaml)",
        args.count,
        args.out.display(),
        args.seed
    );
    Ok(())
}
