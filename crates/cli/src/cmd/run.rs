//! `lidar-har run` (being built; see the issue tracker).

#[derive(clap::Args)]
pub struct RunArgs {}

pub fn run(_args: RunArgs) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har run` is not available in this build yet")
}
