//! Shared plumbing of the lidar_har node binaries: start-up, exit codes, signals and stamps.
//! The nodes themselves stay thin: parameters in, library crates do the work, topics out.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use lidar_har_ros::RosError;

/// Runs a node's body: logs to stderr (`RUST_LOG`, default info), and turns an error into a
/// one-line message and a non-zero exit code: 2 for a bad argument or parameter, 1 otherwise.
pub fn run(node: &str, body: impl FnOnce(&Shutdown) -> anyhow::Result<()>) -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("info")).init();
    let shutdown = match Shutdown::install() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{node}: error: cannot install signal handlers: {e}");
            return ExitCode::FAILURE;
        }
    };
    match body(&shutdown) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("{node}: error: {err:#}");
            let bad_input = err.chain().any(|cause| {
                matches!(
                    cause.downcast_ref::<RosError>(),
                    Some(RosError::Parameter { .. } | RosError::ParamsFile { .. } | RosError::Args(_))
                )
            });
            if bad_input { ExitCode::from(2) } else { ExitCode::FAILURE }
        }
    }
}

/// Set by SIGINT or SIGTERM; nodes poll it between messages and leave their loop cleanly.
#[derive(Clone)]
pub struct Shutdown(Arc<AtomicBool>);

impl Shutdown {
    fn install() -> std::io::Result<Self> {
        let flag = Arc::new(AtomicBool::new(false));
        for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            signal_hook::flag::register(signal, flag.clone())?;
        }
        Ok(Self(flag))
    }

    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// Sleeps until `deadline` in short steps; false when shutdown was requested meanwhile.
    pub fn sleep_until(&self, deadline: Instant) -> bool {
        loop {
            if self.requested() {
                return false;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return true;
            }
            std::thread::sleep(left.min(Duration::from_millis(50)));
        }
    }
}
