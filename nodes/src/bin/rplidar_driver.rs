//! `rplidar_driver`: reads an RPLIDAR on a serial port and publishes /scan (fixed-size
//! LaserScans stamped at their first ray, beam 0) and /diagnostics (device state,
//! rates, faults). The driver library reconnects and resets on faults instead of exiting;
//! only a scan mode the device does not have ends the node, with status 2 naming
//! `scan_mode`, like any other bad parameter.
//!
//! Parameters: `port`, `baud`, `frame_id`, `beams`, `range_min`, `range_max`, `scan_mode`
//! (auto, standard, express or a device mode name), `motor_pwm` (-1 = 660 where the A2/A3
//! accessory board drives the motor, else none sent), `motor_rpm` (-1 = device default),
//! `diagnostics_period` (s, 0.01..=5). Scans are stamped by the wall clock, also with
//! `use_sim_time` (warned about): a live device's time is the wall clock.
//!
//! Services: `stop_motor` and `start_motor` (`std_srvs/srv/Empty`), answered between events,
//! so within a diagnostics period while the motor is stopped.

use std::process::ExitCode;

use lidar_har::{NodeInfo, Shutdown, bad_parameter, seconds};
use lidar_har_msgs::topics;
use lidar_har_ros::{EmptyService, Node, NodeSetup, ParamDecl, ParamValue, Parameters, RosError};
use lidar_har_rplidar::config::MIN_BAUD;
use lidar_har_rplidar::{Config, ConfigField, Driver, Error, Event, ScanModeChoice};

/// Allowed `diagnostics_period`: the node sees a shutdown signal only between events, which
/// come at least once a period, and `ros2 launch` escalates SIGINT to SIGTERM after 5 s.
const DIAGNOSTICS_PERIOD_S: std::ops::RangeInclusive<f64> = 0.01..=5.0;

fn main() -> ExitCode {
    lidar_har::run(
        &NodeInfo {
            name: "rplidar_driver",
            about: "publishes an RPLIDAR's rotations on /scan and its state on /diagnostics",
            parameters: decls,
        },
        drive,
    )
}

fn decls() -> Vec<ParamDecl> {
    use ParamValue as V;
    let d = Config::new("/dev/ttyUSB0");
    vec![
        ParamDecl::new(
            "port",
            V::String(d.port.clone()),
            "serial device of the Lidar",
        ),
        ParamDecl::new(
            "baud",
            V::Integer(i64::from(d.baud)),
            "115200 (A1/A2M8), 256000 (A2M12/A3/S1), 460800 (C1), 1000000 (S2/S3); at least 115200",
        ),
        ParamDecl::new(
            "frame_id",
            V::String(d.frame_id.clone()),
            "frame of the published scans",
        ),
        ParamDecl::new(
            "beams",
            V::Integer(d.geometry.beams as i64),
            "beams per published scan",
        ),
        ParamDecl::new(
            "range_min",
            V::Double(as_written(d.geometry.range_min_m)),
            "shortest valid range, m",
        ),
        ParamDecl::new(
            "range_max",
            V::Double(as_written(d.geometry.range_max_m)),
            "longest valid range, m",
        ),
        ParamDecl::new(
            "scan_mode",
            V::String("auto".into()),
            "auto, standard, express or a device mode name",
        ),
        ParamDecl::new(
            "motor_pwm",
            V::Integer(-1),
            "A2/A3 motor duty 0..1023; -1 = 660 where the accessory board drives the motor",
        ),
        ParamDecl::new(
            "motor_rpm",
            V::Integer(-1),
            "time-of-flight motor speed, rpm; -1 = device default",
        ),
        ParamDecl::new(
            "diagnostics_period",
            V::Double(d.diagnostics_period.as_secs_f64()),
            "s between reports, 0.01..=5",
        ),
        // Declared here for its description: a live device knows no simulation time.
        ParamDecl::new(
            "use_sim_time",
            V::Bool(false),
            "read /clock; scans are stamped by the wall clock all the same (a live device)",
        ),
    ]
}

/// An f32 setting as the double one writes for it: 0.15, where `f64::from` gives
/// 0.15000000596046448 (in `--help` and `ros2 param get`). Narrowed back to f32, both are
/// the same value.
fn as_written(value: f32) -> f64 {
    value.to_string().parse().unwrap_or(f64::from(value))
}

fn integer<T: TryFrom<i64>>(p: &Parameters, name: &str, rule: &str) -> Result<T, RosError> {
    let v = p.i64(name)?;
    T::try_from(v).map_err(|_| bad_parameter(name, format!("{v} is out of range: must be {rule}")))
}

fn optional_u16(p: &Parameters, name: &str) -> Result<Option<u16>, RosError> {
    match p.i64(name)? {
        -1 => Ok(None),
        _ => integer::<u16>(p, name, "-1 or 0..=65535").map(Some),
    }
}

fn config(p: &Parameters) -> Result<Config, RosError> {
    let mut c = Config::new(p.string("port")?);
    c.baud = integer(p, "baud", &format!("{MIN_BAUD}..={}", u32::MAX))?;
    c.frame_id = p.string("frame_id")?;
    c.geometry.beams = integer(p, "beams", "a positive number of beams")?;
    c.geometry.range_min_m = p.f64_checked("range_min", ">= 0 m", |v| v >= 0.0)? as f32;
    c.geometry.range_max_m = p.f64_checked("range_max", "> 0 m", |v| v > 0.0)? as f32;
    c.scan_mode = p
        .string("scan_mode")?
        .parse::<ScanModeChoice>()
        .map_err(|e| bad_parameter("scan_mode", e))?;
    c.motor_pwm = optional_u16(p, "motor_pwm")?;
    c.motor_rpm = optional_u16(p, "motor_rpm")?;
    c.diagnostics_period = seconds(p, "diagnostics_period", DIAGNOSTICS_PERIOD_S)?;
    // The library's own checks, blamed on the parameter of the field they refuse.
    c.validate().map_err(|e| match &e {
        Error::Config { field, .. } => bad_parameter(parameter_of(*field), &e),
        // `validate` refuses nothing else.
        _ => bad_parameter("port", &e),
    })?;
    Ok(c)
}

/// The parameter that sets a configuration field. Timeouts and back-off are not parameters
/// and keep their defaults, so they name the field.
fn parameter_of(field: ConfigField) -> &'static str {
    match field {
        ConfigField::Port => "port",
        ConfigField::Baud => "baud",
        ConfigField::FrameId => "frame_id",
        ConfigField::Beams => "beams",
        ConfigField::RangeMin => "range_min",
        ConfigField::RangeMax => "range_max",
        ConfigField::ScanMode => "scan_mode",
        ConfigField::MotorPwm => "motor_pwm",
        ConfigField::DiagnosticsPeriod => "diagnostics_period",
        ConfigField::RequestTimeout => "request_timeout",
        ConfigField::DataTimeout => "data_timeout",
        ConfigField::ReconnectMin => "reconnect_min",
        ConfigField::ReconnectMax => "reconnect_max",
    }
}

fn drive(shutdown: &Shutdown) -> anyhow::Result<()> {
    let setup = NodeSetup::new("rplidar_driver")
        .parameters(decls())
        .prepare()?;
    // The parameters are checked before the node joins the graph: a bad one used to be
    // found with the participant up, and its discovery warnings came before the error.
    let mut driver = Driver::new(config(setup.params())?).map_err(|e| bad_parameter("port", e))?;
    let node = lidar_har::join(setup)?;
    if node.params().bool("use_sim_time")? {
        log::warn!(
            "rplidar_driver: use_sim_time is true, but the scans of a live device are stamped by \
             the wall clock"
        );
    }
    let scans = node.publisher_for(&topics::SCAN)?;
    let diagnostics = node.publisher_for(&topics::DIAGNOSTICS)?;
    let motor_services = MotorServices::offer(&node);
    // next_event returns at least once per diagnostics period, so a signal or a service
    // request is seen promptly.
    while !shutdown.requested() {
        match driver.next_event().map_err(driver_error)? {
            Event::Scan(scan) => scans.publish_msg(&scan)?,
            Event::Diagnostics(report) => diagnostics.publish_msg(&report)?,
        }
        if let Some(services) = &motor_services {
            services.answer(&mut driver);
        }
    }
    log::info!(
        "rplidar_driver: stopped after {} scans",
        driver.status().scans
    );
    Ok(())
}

/// `stop_motor` and `start_motor` (`std_srvs/srv/Empty`), as rplidar_ros offers them: a
/// docked robot stops its Lidar's motor instead of wearing it for hours.
struct MotorServices {
    stop: EmptyService,
    start: EmptyService,
}

impl MotorServices {
    /// The services, or none (warned) where the transport cannot offer them: scanning goes on
    /// without them.
    fn offer(node: &Node) -> Option<Self> {
        let services = node
            .empty_service("stop_motor")
            .and_then(|stop| Ok((stop, node.empty_service("start_motor")?)));
        match services {
            Ok((stop, start)) => Some(Self { stop, start }),
            Err(e) => {
                log::warn!("rplidar_driver: {e}; stop_motor and start_motor are not offered");
                None
            }
        }
    }

    /// Acts on the requests waiting and answers each once done: stops first, then starts, so
    /// a stop and a start waiting together (their order is not known) leave the Lidar
    /// scanning, the safe side for a robot that may move.
    fn answer(&self, driver: &mut Driver) {
        let stops = self.stop.answer(|| driver.stop_motor());
        let starts = self.start.answer(|| driver.start_motor());
        for (count, name) in [(stops, self.stop.name()), (starts, self.start.name())] {
            if count > 0 {
                log::info!("rplidar_driver: {name} called");
            }
        }
    }
}

/// The driver's permanent errors are bad parameters (exit status 2), named as it names them.
fn driver_error(e: Error) -> anyhow::Error {
    match e {
        Error::Unsupported { parameter, reason } => bad_parameter(parameter, reason).into(),
        other => other.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(overrides: &[(&str, ParamValue)]) -> Parameters {
        let overrides: Vec<(String, ParamValue)> = overrides
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect();
        Parameters::resolve(&decls(), "/rplidar_driver", &[], &overrides).unwrap()
    }

    #[test]
    fn defaults_make_a_valid_config() {
        config(&params(&[])).unwrap();
    }

    #[test]
    fn the_robot_params_file_gives_the_defaults() {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/robot.yaml");
        let p = Parameters::resolve(&decls(), "/rplidar_driver", &[file], &[]).unwrap();
        assert_eq!(config(&p).unwrap(), config(&params(&[])).unwrap());
        // As declared, not only once narrowed to the driver's f32: `--help` and `ros2 param
        // get` showed range_min 0.15000000596046448 where the file and the docs say 0.15.
        let defaults = params(&[]);
        for (name, value) in p.iter() {
            assert_eq!(Some(value), defaults.get(name), "{name}");
        }
    }

    #[test]
    fn f32_settings_are_declared_as_their_shortest_decimal() {
        assert_eq!(as_written(0.15), 0.15);
        assert_eq!(as_written(12.0), 12.0);
        for value in [0.15, 0.1 + 0.2, f32::MAX, f32::MIN_POSITIVE] {
            assert_eq!(as_written(value) as f32, value, "{value}");
        }
    }

    #[test]
    fn a_scan_mode_the_device_lacks_is_a_bad_parameter() {
        let err = driver_error(Error::Unsupported {
            parameter: "scan_mode",
            reason: "`Boost` is not offered".into(),
        });
        assert!(
            matches!(
                err.downcast_ref::<RosError>(),
                Some(RosError::Parameter { name, .. }) if name == "scan_mode"
            ),
            "{err:#}"
        );
        assert!(
            format!("{err:#}").contains("`Boost` is not offered"),
            "{err:#}"
        );
    }

    #[test]
    fn a_baud_too_slow_for_any_rplidar_is_a_bad_baud() {
        // `baud:=12` used to be accepted, and the driver retried for ever.
        for bad in [12, -1, 0] {
            let err = config(&params(&[("baud", ParamValue::Integer(bad))])).unwrap_err();
            let text = err.to_string();
            assert!(
                matches!(&err, RosError::Parameter { name, .. } if name == "baud")
                    && text.contains(&bad.to_string())
                    && text.contains("115200"),
                "{bad}: {text}"
            );
        }
    }

    #[test]
    fn a_refused_value_names_its_own_parameter_not_one_its_message_mentions() {
        // The range_max message quotes range_min; a frame id may contain "port".
        for (overrides, parameter) in [
            (vec![("range_max", ParamValue::Double(0.1))], "range_max"),
            (
                vec![("frame_id", ParamValue::String("/laser_port".into()))],
                "frame_id",
            ),
            (
                vec![("frame_id", ParamValue::String(" baud beams".into()))],
                "frame_id",
            ),
        ] {
            let err = config(&params(&overrides)).unwrap_err();
            assert!(
                matches!(&err, RosError::Parameter { name, .. } if name == parameter),
                "{parameter}: {err}"
            );
        }
    }

    #[test]
    fn huge_or_tiny_diagnostics_period_is_an_error_naming_it() {
        for bad in [1e300, 1e6, 0.0, -1.0] {
            let err = config(&params(&[("diagnostics_period", ParamValue::Double(bad))]))
                .unwrap_err()
                .to_string();
            assert!(err.contains("`diagnostics_period`"), "{bad}: {err}");
        }
    }
}
