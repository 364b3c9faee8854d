//! Driver configuration.

use std::str::FromStr;
use std::time::Duration;

use crate::error::{Error, Result};
use crate::scan::ScanGeometry;

/// The slowest rate an RPLIDAR speaks (A1, A2M8): at a lower one no device answers, and the
/// driver would only reconnect for ever.
pub const MIN_BAUD: u32 = 115_200;

/// A field of [`Config`], as [`Error::Config`] names the one it refuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ConfigField {
    Port,
    Baud,
    FrameId,
    Beams,
    RangeMin,
    RangeMax,
    ScanMode,
    MotorPwm,
    RequestTimeout,
    DataTimeout,
    ReconnectMin,
    ReconnectMax,
    DiagnosticsPeriod,
}

/// An [`Error::Config`] refusing `field`.
pub(crate) fn invalid(field: ConfigField, reason: impl Into<String>) -> Error {
    Error::Config {
        field,
        reason: reason.into(),
    }
}

/// Which measurement mode to start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScanModeChoice {
    /// `SCAN`: 5-byte nodes, every model and firmware.
    Standard,
    /// `EXPRESS_SCAN` capsules (firmware 1.17 and later), more samples per second.
    Express,
    /// The device's typical mode from its configuration; express or standard on firmware
    /// without scan modes.
    Auto,
    /// A scan mode by the name the device gives it (e.g. `Sensitivity`, `Boost`, `DenseBoost`).
    Named(String),
}

impl FromStr for ScanModeChoice {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let t = s.trim();
        match t.to_ascii_lowercase().as_str() {
            "" => Err(invalid(
                ConfigField::ScanMode,
                "scan_mode is empty; use standard, express, auto or a device mode name",
            )),
            "standard" => Ok(Self::Standard),
            "express" => Ok(Self::Express),
            "auto" | "typical" => Ok(Self::Auto),
            _ => Ok(Self::Named(t.to_owned())),
        }
    }
}

/// Everything the [`crate::Driver`] needs. `Config::new(port)` gives working defaults for
/// an A1/A2 on USB.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// Serial device path, e.g. `/dev/ttyUSB0` or a udev symlink like `/dev/rplidar`.
    pub port: String,
    /// 115200 for A1/A2M8, 256000 for A2M12/A3/S1, 460800 for C1, 1000000 for S2/S3.
    pub baud: u32,
    /// `frame_id` of the published scans.
    pub frame_id: String,
    /// Beams per scan and valid range interval.
    pub geometry: ScanGeometry,
    pub scan_mode: ScanModeChoice,
    /// Motor duty cycle 0..=1023 for A2/A3 through the accessory board (`SET_MOTOR_PWM`);
    /// `None` leaves the board's default.
    pub motor_pwm: Option<u16>,
    /// Motor speed in rpm for time-of-flight models (`0xA8`); `None` leaves the default.
    pub motor_rpm: Option<u16>,
    /// How long to wait for the answer to a request.
    pub request_timeout: Duration,
    /// No valid sample for this long while scanning: reset the device and start again.
    pub data_timeout: Duration,
    /// Pause after `RESET` before talking to the device again (it reboots).
    pub reset_wait: Duration,
    /// First and longest wait between reconnection attempts (the wait doubles).
    pub reconnect_min: Duration,
    pub reconnect_max: Duration,
    /// Period of the routine diagnostics report.
    pub diagnostics_period: Duration,
}

impl Config {
    pub fn new(port: impl Into<String>) -> Self {
        Self {
            port: port.into(),
            baud: 115_200,
            frame_id: "laser".into(),
            geometry: ScanGeometry {
                beams: 720,
                range_min_m: 0.15,
                range_max_m: 12.0,
            },
            scan_mode: ScanModeChoice::Auto,
            motor_pwm: None,
            motor_rpm: None,
            request_timeout: Duration::from_millis(1000),
            data_timeout: Duration::from_millis(1500),
            reset_wait: Duration::from_millis(800),
            reconnect_min: Duration::from_millis(250),
            reconnect_max: Duration::from_secs(5),
            diagnostics_period: Duration::from_secs(1),
        }
    }

    /// Checks every field; the error names the field and what is wrong with it.
    pub fn validate(&self) -> Result<()> {
        if self.port.trim().is_empty() {
            return Err(invalid(
                ConfigField::Port,
                "port is empty; give the serial device path, e.g. /dev/ttyUSB0",
            ));
        }
        if self.baud < MIN_BAUD {
            return Err(invalid(
                ConfigField::Baud,
                format!(
                    "baud = {} is below {MIN_BAUD}, the slowest RPLIDAR rate: use 115200 \
                 (A1/A2M8), 256000 (A2M12/A3/S1), 460800 (C1), 1000000 (S2/S3) or another rate >= \
                 {MIN_BAUD}",
                    self.baud
                ),
            ));
        }
        if self.frame_id.trim().is_empty() {
            return Err(invalid(ConfigField::FrameId, "frame_id is empty"));
        }
        // tf2 refuses such frame ids, so rviz and every transform lookup would drop the scans.
        if self.frame_id.starts_with('/') || self.frame_id.trim() != self.frame_id {
            return Err(invalid(
                ConfigField::FrameId,
                format!(
                    "frame_id = {:?}: a tf2 frame id has no leading '/' (a ROS 1 habit) and no \
                 surrounding spaces, e.g. \"laser\"",
                    self.frame_id
                ),
            ));
        }
        self.geometry.validate()?;
        if let Some(pwm) = self.motor_pwm
            && pwm > 1023
        {
            return Err(invalid(
                ConfigField::MotorPwm,
                format!("motor_pwm = {pwm} must be in 0..=1023"),
            ));
        }
        if let ScanModeChoice::Named(name) = &self.scan_mode
            && name.trim().is_empty()
        {
            return Err(invalid(ConfigField::ScanMode, "scan_mode name is empty"));
        }
        for (field, name, value) in [
            (
                ConfigField::RequestTimeout,
                "request_timeout",
                self.request_timeout,
            ),
            (ConfigField::DataTimeout, "data_timeout", self.data_timeout),
            (
                ConfigField::ReconnectMin,
                "reconnect_min",
                self.reconnect_min,
            ),
            (
                ConfigField::ReconnectMax,
                "reconnect_max",
                self.reconnect_max,
            ),
            (
                ConfigField::DiagnosticsPeriod,
                "diagnostics_period",
                self.diagnostics_period,
            ),
        ] {
            if value.is_zero() {
                return Err(invalid(field, format!("{name} must be longer than zero")));
            }
        }
        if self.reconnect_max < self.reconnect_min {
            return Err(invalid(
                ConfigField::ReconnectMax,
                format!(
                    "reconnect_max ({:?}) is shorter than reconnect_min ({:?})",
                    self.reconnect_max, self.reconnect_min
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        Config::new("/dev/ttyUSB0").validate().unwrap();
    }

    #[test]
    fn each_bad_field_is_named() {
        let base = Config::new("/dev/ttyUSB0");
        let cases: Vec<(Config, &str)> = vec![
            (
                Config {
                    port: " ".into(),
                    ..base.clone()
                },
                "port",
            ),
            (
                Config {
                    baud: 0,
                    ..base.clone()
                },
                "baud",
            ),
            (
                Config {
                    frame_id: String::new(),
                    ..base.clone()
                },
                "frame_id",
            ),
            (
                Config {
                    frame_id: "/laser".into(),
                    ..base.clone()
                },
                "frame_id",
            ),
            (
                Config {
                    frame_id: "laser ".into(),
                    ..base.clone()
                },
                "frame_id",
            ),
            (
                Config {
                    motor_pwm: Some(2000),
                    ..base.clone()
                },
                "motor_pwm",
            ),
            (
                Config {
                    data_timeout: Duration::ZERO,
                    ..base.clone()
                },
                "data_timeout",
            ),
            (
                Config {
                    reconnect_max: Duration::from_millis(1),
                    ..base.clone()
                },
                "reconnect_max",
            ),
            (
                Config {
                    geometry: ScanGeometry {
                        beams: 0,
                        range_min_m: 0.1,
                        range_max_m: 1.0,
                    },
                    ..base.clone()
                },
                "beams",
            ),
        ];
        for (config, field) in cases {
            let e = config.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
    }

    #[test]
    fn the_error_carries_the_field_refused_even_when_its_text_names_others() {
        let base = Config::new("/dev/ttyUSB0");
        let field = |config: Config| match config.validate() {
            Err(Error::Config { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        let mut short_max = base.clone();
        short_max.geometry.range_max_m = 0.1;
        assert_eq!(field(short_max), ConfigField::RangeMax);
        let port_frame = Config {
            frame_id: "/laser_port".into(),
            ..base.clone()
        };
        assert_eq!(field(port_frame), ConfigField::FrameId);
        let zero_period = Config {
            diagnostics_period: Duration::ZERO,
            ..base
        };
        assert_eq!(field(zero_period), ConfigField::DiagnosticsPeriod);
    }

    #[test]
    fn a_baud_below_the_slowest_rplidar_rate_is_refused_naming_it() {
        // 12 used to pass (only 0 was refused), and the driver retried for ever.
        for baud in [0, 12, 9600, MIN_BAUD - 1] {
            let config = Config {
                baud,
                ..Config::new("/dev/ttyUSB0")
            };
            let e = config.validate().unwrap_err().to_string();
            assert!(
                e.contains(&format!("baud = {baud} ")) && e.contains("115200"),
                "{baud}: {e}"
            );
        }
        for baud in [MIN_BAUD, 256_000, 460_800, 1_000_000] {
            let config = Config {
                baud,
                ..Config::new("/dev/ttyUSB0")
            };
            config.validate().unwrap();
        }
    }

    #[test]
    fn scan_mode_parses() {
        assert_eq!(
            "Standard".parse::<ScanModeChoice>().unwrap(),
            ScanModeChoice::Standard
        );
        assert_eq!(
            "auto".parse::<ScanModeChoice>().unwrap(),
            ScanModeChoice::Auto
        );
        assert_eq!(
            "express".parse::<ScanModeChoice>().unwrap(),
            ScanModeChoice::Express
        );
        assert_eq!(
            "Sensitivity".parse::<ScanModeChoice>().unwrap(),
            ScanModeChoice::Named("Sensitivity".into())
        );
        assert!("  ".parse::<ScanModeChoice>().is_err());
    }
}
