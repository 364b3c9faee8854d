//! `lidar-har demo` (being built; see the issue tracker).

#[derive(clap::Args)]
pub struct DemoArgs {}

pub fn run(_args: DemoArgs) -> anyhow::Result<()> {
    anyhow::bail!("`lidar-har demo` is not available in this build yet")
}
