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
