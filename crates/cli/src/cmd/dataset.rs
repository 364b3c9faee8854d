//! `lidar-har dataset` (being built; see the issue tracker).

#[derive(clap::Args)]
pub struct DatasetArgs {}

pub fn run(_args: DatasetArgs) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har dataset` is not available in this build yet")
}
