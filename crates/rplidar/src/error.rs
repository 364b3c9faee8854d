//! Errors of the driver.

/// Everything that can go wrong talking to a device. None of them is fatal to the
/// [`crate::Driver`], which reports them as diagnostics and recovers.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The serial port could not be opened or configured.
    #[error("serial port {path}: {cause}")]
    Port {
        path: String,
        cause: serialport::Error,
    },
    /// Reading or writing the port failed (e.g. the device was unplugged).
    #[error("serial I/O on {path}: {cause}")]
    Io { path: String, cause: std::io::Error },
    /// The device did not answer in time.
    #[error("timed out after {waited_ms} ms waiting for {what}")]
    Timeout { what: String, waited_ms: u64 },
    /// The device answered something the protocol does not allow here.
    #[error("protocol error: {0}")]
    Protocol(String),
    /// The device does not support what was asked.
    #[error("unsupported: {0}")]
    Unsupported(String),
    /// A configuration value is invalid.
    #[error("invalid configuration: {0}")]
    Config(String),
}

pub type Result<T> = std::result::Result<T, Error>;
