//! `lidar-har bag` (being built; see the issue tracker).

#[derive(clap::Subcommand)]
pub enum BagCommand {
    /// Not available in this build yet.
    Info,
}

pub fn run(_command: BagCommand) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har bag` is not available in this build yet")
}
