//! `lidar-har topic` (being built; see the issue tracker).

#[derive(clap::Subcommand)]
pub enum TopicCommand {
    /// Not available in this build yet.
    Info,
}

pub fn run(_command: TopicCommand) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har topic` is not available in this build yet")
}
