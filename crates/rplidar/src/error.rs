//! Errors of the driver.

/// Everything that can go wrong talking to a device. The [`crate::Driver`] reports them as
/// diagnostics and recovers, except from [`Error::Unsupported`]: retrying cannot help there.
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
    /// The device does not have what the configuration parameter `parameter` asks for (a
    /// scan mode it does not list, one whose format is not decoded). Permanent: the driver
    /// stops and [`crate::Driver::next_event`] returns it.
    #[error("{parameter}: {reason}")]
    Unsupported {
        parameter: &'static str,
        reason: String,
    },
    /// A configuration value is invalid; `field` is the one refused, so that a caller can
    /// name its own parameter for it.
    #[error("invalid configuration: {reason}")]
    Config {
        field: crate::config::ConfigField,
        reason: String,
    },
}

pub type Result<T> = std::result::Result<T, Error>;
