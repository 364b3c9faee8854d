//! `lidar-har evaluate` (being built; see the issue tracker).

#[derive(clap::Args)]
pub struct EvaluateArgs {}

pub fn run(_args: EvaluateArgs) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har evaluate` is not available in this build yet")
}
