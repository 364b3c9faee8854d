//! `lidar-har simulate` (being built; see the issue tracker).

#[derive(clap::Args)]
pub struct SimulateArgs {}

pub fn run(_args: SimulateArgs) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har simulate` is not available in this build yet")
}
