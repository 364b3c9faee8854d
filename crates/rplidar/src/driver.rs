//! The driver: owns the serial port and runs the device through its states, turning every
//! fault into a diagnostic and a recovery instead of an error; only a configuration the
//! device cannot satisfy (a scan mode it lacks) stops it, since retrying cannot help.
//!
//! ```text
//! Disconnected --open, stop, info, health, start scan--> Scanning
//!   |  ^   (failure: wait, doubling up to reconnect_max)      |
//!   |  |                                                        | no valid data for data_timeout:
//!   |  +------------- read/write error (unplugged) -------------+   RESET, then start again
//!   |                                                                 health error at start: RESET
//!   +--scan mode the device lacks--> Failed (next_event returns the error)
//!
//! Scanning --stop_motor--> StoppedOnRequest (STOP, motor off, port kept open)
//!   --start_motor--> Scanning (started again on the kept port)
//! Disconnected --stop_motor--> Disconnected, then stopped as soon as the device is found
//! ```
//!
//! A host (the ROS node) only loops over [`Driver::next_event`] and publishes what it gets.
//! `next_event` blocks until there is a scan or a diagnostics report; reports come at
//! least every `diagnostics_period`, so a host can check for shutdown between events.

use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::{AsRawFd, BorrowedFd};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;
use log::{debug, error, info, warn};
use nix::sys::termios::{ControlFlags, SetArg, tcgetattr, tcsetattr};
use serialport::{ClearBuffer, SerialPort, TTYPort};

use crate::config::{Config, ScanModeChoice};
use crate::decode::{DecodeStats, Sample, ScanFormat, StreamDecoder};
use crate::error::{Error, Result};
use crate::protocol::{
    ACC_BOARD_MOTOR_CTRL, DESCRIPTOR_LEN, Descriptor, DeviceHealth, DeviceInfo, HealthStatus,
    RESPONSE_SYNC, Request, SampleRate, ScanModeInfo, answer, conf, conf_string, conf_u32,
    parse_conf_answer,
};
use crate::rotation::{Rotation, RotationAssembler};
use crate::scan::ScanFrame;

/// What the driver has for its host.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// One rotation as a fixed-size scan.
    Scan(LaserScan),
    /// A state change or the routine report.
    Diagnostics(DiagnosticArray),
}

/// A caller-given clock: nanoseconds of the time the scans are stamped in (wall clock by
/// default; a simulation clock for `use_sim_time`).
pub type Clock = Box<dyn Fn() -> i64 + Send>;

/// Longest single wait on the port, so that reports stay on time.
const POLL: Duration = Duration::from_millis(50);
/// A read at least this large may have left more of a backlog in the kernel: a tty hands
/// over at most 4095 bytes at a time (0.35 s of samples at 115200 baud, 40 ms at 1 Mbaud).
const LARGE_READ: usize = 2048;
/// How long to wait for the rest of a backlog after a large read (the wait ends with the
/// first bytes).
const BACKLOG_READ_WAIT: Duration = Duration::from_millis(10);
/// The longest backlog dated as one (2.6 s at 1 Mbaud); a longer one crowds (`rotation`).
const MAX_BACKLOG: usize = 256 * 1024;
/// Pause after `STOP` (the device needs at least 1 ms to stop sending).
const AFTER_STOP: Duration = Duration::from_millis(20);
/// Requests that older firmware ignores (scan modes, accessory board, sample rate) get no
/// answer there: do not wait long for them (Slamtec's SDK 2 waits 250 ms for the mode count).
const CONF_PROBE_TIMEOUT: Duration = Duration::from_millis(300);
/// Motor duty cycle Slamtec's SDK starts an accessory-board motor with (`DEFAULT_MOTOR_PWM`).
pub const DEFAULT_MOTOR_PWM: u16 = 660;
/// Speed Slamtec's SDK 2 gives a time-of-flight motor when the device does not tell the one
/// it prefers (`setMotorSpeed`).
const FALLBACK_MOTOR_RPM: u16 = 600;
/// The routine report while [`Driver::stop_motor`] holds the device.
const MOTOR_STOPPED_MESSAGE: &str = "motor stopped on request (stop_motor); start_motor resumes";
/// Answers longer than this are not single answers of this protocol.
const MAX_ANSWER_LEN: u32 = 4096;

/// Driver state and counters, for hosts and tests.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DriverStatus {
    pub scanning: bool,
    pub device: Option<DeviceInfo>,
    pub health: Option<DeviceHealth>,
    pub scan_mode: Option<String>,
    pub format: Option<ScanFormat>,
    /// Samples per second the device announces for the mode (what it really delivers is
    /// `rotation_hz x samples_per_rotation`).
    pub nominal_sample_rate_hz: Option<f32>,
    /// Baud rate the port reports after opening (a pseudo-terminal accepts any).
    pub baud_readback: Option<u32>,
    pub scans: u64,
    pub resets: u64,
    pub connects: u64,
    pub disconnects: u64,
    pub decode: DecodeStats,
    /// Measured rotation rate (smoothed) and samples in the last rotation.
    pub rotation_hz: Option<f64>,
    pub samples_per_rotation: Option<usize>,
    /// Beams with a valid return (in `range_min..=range_max`) in the last rotation.
    pub valid_beams: Option<usize>,
    /// Rotations in a row, up to the last, without a valid return on any beam: a blinded
    /// sensor still scans, and its all-`+inf` scans read as free space downstream.
    pub rotations_without_return: u64,
    /// Motor duty cycle sent through the accessory board this session (`None`: not used).
    pub motor_pwm: Option<u16>,
    /// [`Driver::stop_motor`] holds the device stopped until [`Driver::start_motor`].
    pub motor_stopped_on_request: bool,
    pub last_error: Option<String>,
}

/// The serial port with a receive buffer. It leaves the device stopped with its motor off
/// when dropped, whatever failed before: a motor started for a scan that then did not
/// start would otherwise keep turning through every retry and after the host exits.
struct Link {
    port: Box<dyn SerialPort>,
    path: String,
    rx: Vec<u8>,
    chunk: Vec<u8>,
    /// A request that starts measurements or the motor was sent, or DTR set to run it.
    started: bool,
    /// A non-zero duty cycle was sent: the accessory board keeps the motor turning until
    /// told 0 (`STOP` ends the measurements only).
    motor_pwm: bool,
}

impl Link {
    fn open(config: &Config) -> Result<Self> {
        let port = serialport::new(&config.port, config.baud)
            .timeout(POLL)
            .open_native()
            .map_err(|cause| Error::Port {
                path: config.port.clone(),
                cause,
            })?;
        keep_modem_lines_at_close(&port, &config.port);
        Ok(Self {
            port: Box::new(port),
            path: config.port.clone(),
            rx: Vec::with_capacity(8192),
            chunk: vec![0; 8192],
            started: false,
            motor_pwm: false,
        })
    }

    fn io_error(&self, cause: std::io::Error) -> Error {
        Error::Io {
            path: self.path.clone(),
            cause,
        }
    }

    fn send(&mut self, request: &Request) -> Result<()> {
        debug!("{}: send {request:?}", self.path);
        match request {
            Request::Scan
            | Request::ForceScan
            | Request::ExpressScan { .. }
            | Request::SetMotorRpm(_) => self.started = true,
            Request::SetMotorPwm(pwm) => {
                self.started = true;
                self.motor_pwm = *pwm != 0;
            }
            _ => {}
        }
        let bytes = request.encode();
        self.port.write_all(&bytes).map_err(|e| self.io_error(e))?;
        self.port.flush().map_err(|e| self.io_error(e))
    }

    /// Reads what is available within `timeout` into `rx`; 0 on timeout.
    fn read_some(&mut self, timeout: Duration) -> Result<usize> {
        let _ = self.port.set_timeout(timeout.max(Duration::from_millis(1)));
        match self.port.read(&mut self.chunk) {
            Ok(0) => {
                Err(self.io_error(std::io::Error::new(ErrorKind::UnexpectedEof, "port closed")))
            }
            Ok(n) => {
                self.rx.extend_from_slice(&self.chunk[..n]);
                Ok(n)
            }
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {
                Ok(0)
            }
            Err(e) => Err(self.io_error(e)),
        }
    }

    /// Reads what is available within `timeout` and the rest of a backlog that the kernel
    /// hands over in several reads, so that its samples are dated from the arrival of the
    /// last (see `rotation`).
    fn read_backlog(&mut self, timeout: Duration) -> Result<usize> {
        let mut total = self.read_some(timeout)?;
        let mut last = total;
        while last >= LARGE_READ && total < MAX_BACKLOG {
            last = self.read_some(BACKLOG_READ_WAIT)?;
            total += last;
        }
        Ok(total)
    }

    fn clear_input(&mut self) {
        self.rx.clear();
        if let Err(e) = self.port.clear(ClearBuffer::Input) {
            debug!("{}: clearing the input buffer failed: {e}", self.path);
        }
    }

    /// Motor on/off through DTR (A1/A2 on their USB adapter: DTR low runs the motor).
    /// Ports without modem lines (pseudo-terminals: ENOTTY) are fine.
    fn set_motor_dtr(&mut self, on: bool) {
        self.started |= on;
        if let Err(e) = self.port.write_data_terminal_ready(!on) {
            debug!(
                "{}: DTR not supported on this port ({e}); motor left as it is",
                self.path
            );
        }
    }

    /// Stops as Slamtec's SDK does: `STOP` ends the measurements only; an accessory-board
    /// motor then needs PWM 0, a time-of-flight one 0 rpm (`zero_rpm`: the SDK's
    /// `setMotorSpeed(0)`), the others DTR raised. Every step is tried; the first error is
    /// returned.
    fn stop_device(&mut self, zero_rpm: bool) -> Result<()> {
        let mut result = self.send(&Request::Stop);
        if self.motor_pwm || zero_rpm {
            std::thread::sleep(AFTER_STOP);
        }
        if self.motor_pwm {
            result = result.and(self.send(&Request::SetMotorPwm(0)));
        }
        if zero_rpm {
            result = result.and(self.send(&Request::SetMotorRpm(0)));
        }
        self.set_motor_dtr(false);
        self.started = false;
        result
    }

    /// Waits for a descriptor of `expected` type, skipping anything else (stale scan data,
    /// boot messages). Returns as soon as it has arrived.
    fn wait_descriptor(
        &mut self,
        expected: u8,
        deadline: Instant,
        what: &str,
    ) -> Result<Descriptor> {
        let started = Instant::now();
        let mut seen = None;
        loop {
            while let Some(i) = self.rx.windows(2).position(|w| w == RESPONSE_SYNC) {
                if self.rx.len() < i + DESCRIPTOR_LEN {
                    self.rx.drain(..i);
                    break;
                }
                let d = Descriptor::parse(&self.rx[i..i + DESCRIPTOR_LEN])?;
                if d.answer_type == expected {
                    self.rx.drain(..i + DESCRIPTOR_LEN);
                    return Ok(d);
                }
                seen = Some(d.answer_type);
                self.rx.drain(..i + 1);
            }
            if self.rx.windows(2).all(|w| w != RESPONSE_SYNC) {
                // Keep a trailing 0xA5: it may start the next descriptor.
                let keep = usize::from(self.rx.last() == Some(&RESPONSE_SYNC[0]));
                let cut = self.rx.len() - keep;
                self.rx.drain(..cut);
            }
            let now = Instant::now();
            if now >= deadline {
                let what = match seen {
                    Some(t) => format!("{what} (answer type 0x{expected:02X}; saw only 0x{t:02X})"),
                    None => format!("{what} (answer type 0x{expected:02X})"),
                };
                return Err(Error::Timeout {
                    what,
                    waited_ms: now.duration_since(started).as_millis() as u64,
                });
            }
            self.read_some((deadline - now).min(POLL))?;
        }
    }

    fn wait_bytes(&mut self, len: usize, deadline: Instant, what: &str) -> Result<Vec<u8>> {
        let started = Instant::now();
        while self.rx.len() < len {
            let now = Instant::now();
            if now >= deadline {
                return Err(Error::Timeout {
                    what: format!("{what}: {} of {len} bytes", self.rx.len()),
                    waited_ms: now.duration_since(started).as_millis() as u64,
                });
            }
            self.read_some((deadline - now).min(POLL))?;
        }
        Ok(self.rx.drain(..len).collect())
    }

    /// Sends a request and returns the payload of its single answer.
    fn request(
        &mut self,
        request: &Request,
        expected: u8,
        timeout: Duration,
        what: &str,
    ) -> Result<Vec<u8>> {
        self.send(request)?;
        let deadline = Instant::now() + timeout;
        let d = self.wait_descriptor(expected, deadline, what)?;
        if d.len > MAX_ANSWER_LEN {
            return Err(Error::Protocol(format!(
                "{what}: answer length {} is implausible",
                d.len
            )));
        }
        self.wait_bytes(d.len as usize, deadline, what)
    }
}

/// How a scan is started and decoded.
struct ScanPlan {
    request: Request,
    format: ScanFormat,
    mode_name: String,
    /// Samples per second the device announces for this mode.
    nominal_rate_hz: Option<f32>,
}

impl ScanPlan {
    /// `SCAN`: every model and firmware.
    fn standard() -> Self {
        Self {
            request: Request::Scan,
            format: ScanFormat::Standard,
            mode_name: "Standard".into(),
            nominal_rate_hz: None,
        }
    }

    /// `EXPRESS_SCAN` working mode 0: express capsules on firmware without scan modes.
    fn legacy_express() -> Self {
        Self {
            request: Request::ExpressScan {
                working_mode: 0,
                working_flags: 0,
                param: 0,
            },
            format: ScanFormat::Express,
            mode_name: "Express".into(),
            nominal_rate_hz: None,
        }
    }
}

/// A device that is scanning.
struct Session {
    link: Link,
    info: DeviceInfo,
    health: DeviceHealth,
    mode_name: String,
    nominal_rate_hz: Option<f32>,
    decoder: StreamDecoder,
    assembler: RotationAssembler,
    /// Time between two samples of the device (see [`sample_interval`]).
    sample_interval: Duration,
    samples: Vec<Sample>,
    rotations: Vec<Rotation>,
    last_data: Instant,
    /// When the last rotation completed (or the scan started).
    last_rotation: Instant,
    baud_readback: Option<u32>,
    /// Duty cycle sent with `SET_MOTOR_PWM`, for the diagnostics.
    motor_pwm: Option<u16>,
}

enum State {
    Disconnected {
        next_attempt: Instant,
    },
    Scanning(Box<Session>),
    /// Held by [`Driver::stop_motor`]: the device stopped with its motor off and its port
    /// kept open: where HUPCL could not be cleared ([`keep_modem_lines_at_close`]), closing it
    /// lowers DTR, which runs an A1's motor.
    StoppedOnRequest(Link),
    /// Stopped for good: the configuration asks for what the device does not have.
    Failed {
        parameter: &'static str,
        reason: String,
    },
}

/// The RPLIDAR driver (see the module documentation).
pub struct Driver {
    config: Config,
    clock: Clock,
    state: State,
    pending: VecDeque<Event>,
    backoff: Duration,
    next_report: Instant,
    status: DriverStatus,
    scans_at_last_report: u64,
    /// Decode counters of earlier sessions, so totals survive reconnects.
    decode_before: DecodeStats,
    /// Start of the first of the `rotations_without_return`.
    no_return_since: Option<Instant>,
    /// The last routine report warned of rotations without a return: the change is logged
    /// once, not at every report.
    warned_no_return: bool,
    /// A motor parameter the connected family has no use for was warned about (once, not at
    /// every reconnect).
    warned_motor_parameter: bool,
    /// `stop_motor` told a time-of-flight motor 0 rpm: the next start gives it a speed again.
    motor_rpm_zeroed: bool,
}

/// Wall-clock nanoseconds since the Unix epoch.
pub fn system_clock_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

impl Driver {
    /// A driver stamping scans with the wall clock. Fails only on an invalid configuration;
    /// the device is opened by [`Driver::next_event`].
    pub fn new(config: Config) -> Result<Self> {
        Self::with_clock(config, Box::new(system_clock_ns))
    }

    pub fn with_clock(config: Config, clock: Clock) -> Result<Self> {
        config.validate()?;
        let now = Instant::now();
        Ok(Self {
            backoff: config.reconnect_min,
            next_report: now + config.diagnostics_period,
            config,
            clock,
            state: State::Disconnected { next_attempt: now },
            pending: VecDeque::new(),
            status: DriverStatus::default(),
            scans_at_last_report: 0,
            decode_before: DecodeStats::default(),
            no_return_since: None,
            warned_no_return: false,
            warned_motor_parameter: false,
            motor_rpm_zeroed: false,
        })
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    pub fn status(&self) -> DriverStatus {
        let mut s = self.status.clone();
        s.decode = self.decode_totals();
        s
    }

    /// Stops scanning and the motor (Slamtec's SDK `stop()` and `setMotorSpeed(0)`, the
    /// `stop_motor` service of `rplidar_ros`) and keeps the port open, until
    /// [`Driver::start_motor`]: meanwhile [`Driver::next_event`] gives only the routine
    /// reports (OK, saying so), and neither reads, resets nor reconnects the device. Scans read
    /// before the stop and not yet taken are dropped. Without a device (unplugged, or waiting
    /// to reconnect) the driver goes on looking for it and stops it once it answers; an I/O
    /// error while stopping is a lost device, looked for the same way. Stopping again only
    /// records the request; a driver failed for good (its device already stopped) stays as
    /// it is.
    pub fn stop_motor(&mut self) {
        if self.status.motor_stopped_on_request || matches!(self.state, State::Failed { .. }) {
            return;
        }
        self.status.motor_stopped_on_request = true;
        self.pending
            .retain(|event| !matches!(event, Event::Scan(_)));
        // Measured on a turning motor: the next start measures afresh (a motor spinning up
        // gets `data_timeout` before a late rotation is warned of).
        self.status.rotation_hz = None;
        self.status.samples_per_rotation = None;
        self.status.valid_beams = None;
        self.status.rotations_without_return = 0;
        self.no_return_since = None;
        self.warned_no_return = false;
        info!("{}: stop_motor: stopping the device", self.config.port);
        self.hold_stopped();
    }

    /// Stops the device of a scanning session and holds it: the state
    /// `stop_motor` asks for. Without a device, nothing to do until `connect` finds one.
    fn hold_stopped(&mut self) {
        let now = Instant::now();
        let disconnected = State::Disconnected { next_attempt: now };
        let link = match std::mem::replace(&mut self.state, disconnected) {
            State::Scanning(session) => {
                self.decode_before = add_stats(self.decode_before, session.decoder.stats());
                let zero_rpm = session.info.is_time_of_flight();
                self.motor_rpm_zeroed |= zero_rpm;
                let mut link = session.link;
                if let Err(e) = link.stop_device(zero_rpm) {
                    self.status.scanning = false;
                    self.status.disconnects += 1;
                    self.status.last_error = Some(e.to_string());
                    let message = format!(
                        "lost the device while stopping its motor: {e}; it is stopped once it \
                         answers again"
                    );
                    error!("{}: {message}", self.config.port);
                    self.state = State::Disconnected {
                        next_attempt: now + self.backoff,
                    };
                    self.report(DiagnosticStatus::ERROR, message);
                    return;
                }
                link
            }
            other => {
                self.state = other;
                return;
            }
        };
        self.state = State::StoppedOnRequest(link);
        self.status.scanning = false;
        info!("{}: {MOTOR_STOPPED_MESSAGE}", self.config.port);
        self.report(DiagnosticStatus::OK, MOTOR_STOPPED_MESSAGE.into());
    }

    /// Ends [`Driver::stop_motor`]: starts scanning on the kept port as at the first
    /// connection (its failure is a fault, retried as any), or has the next
    /// [`Driver::next_event`] look for the device at once. Does nothing unless stopped.
    pub fn start_motor(&mut self) {
        if !self.status.motor_stopped_on_request {
            return;
        }
        self.status.motor_stopped_on_request = false;
        self.backoff = self.config.reconnect_min;
        info!("{}: start_motor: starting the device", self.config.port);
        let disconnected = State::Disconnected {
            next_attempt: Instant::now(),
        };
        match std::mem::replace(&mut self.state, disconnected) {
            State::StoppedOnRequest(link) => {
                let started = self.start_session(link);
                self.begin_scanning(started, |session| {
                    format!("scanning again (start_motor), mode {}", session.mode_name)
                });
            }
            State::Disconnected { .. } => {}
            other => self.state = other,
        }
    }

    /// Blocks until the next scan or diagnostics report. Faults are reported and recovered
    /// from; only a permanent one ([`Error::Unsupported`], naming the parameter to change)
    /// is returned, after its diagnostics report, and from then on at every call.
    pub fn next_event(&mut self) -> Result<Event> {
        loop {
            if let Some(event) = self.pending.pop_front() {
                return Ok(event);
            }
            if let State::Failed { parameter, reason } = &self.state {
                return Err(Error::Unsupported {
                    parameter,
                    reason: reason.clone(),
                });
            }
            self.step();
        }
    }

    fn step(&mut self) {
        let now = Instant::now();
        if now >= self.next_report {
            self.next_report = now + self.config.diagnostics_period;
            self.routine_report();
            return;
        }
        match &mut self.state {
            State::Disconnected { next_attempt } => {
                if now < *next_attempt {
                    std::thread::sleep((*next_attempt).min(self.next_report) - now);
                } else {
                    self.connect();
                }
            }
            State::Scanning(_) => self.poll_scan(),
            // Nothing to read or retry: the host gets the reports, and its requests between them.
            State::StoppedOnRequest(_) => {
                std::thread::sleep(self.next_report.saturating_duration_since(now));
            }
            State::Failed { .. } => {}
        }
    }

    fn connect(&mut self) {
        let started = Link::open(&self.config).and_then(|link| self.start_session(link));
        if started.is_ok() {
            self.status.connects += 1;
            self.backoff = self.config.reconnect_min;
        }
        self.begin_scanning(started, |session| {
            format!(
                "scanning: RPLIDAR {} firmware {} hardware {}, mode {}",
                session.info.family(),
                session.info.firmware(),
                session.info.hardware,
                session.mode_name
            )
        });
        // Asked while there was no device: stopped as soon as it answers (its family, which
        // says how to stop the motor, is known only now).
        if self.status.scanning && self.status.motor_stopped_on_request {
            self.hold_stopped();
        }
    }

    /// Scans with a started session, reported OK as `describe` says, or takes its failure
    /// to start as a fault.
    fn begin_scanning(
        &mut self,
        started: Result<Session>,
        describe: impl FnOnce(&Session) -> String,
    ) {
        match started {
            Ok(session) => {
                let message = describe(&session);
                info!("{}: {message}", self.config.port);
                self.status.last_error = None;
                self.enter_scanning(session);
                self.report(DiagnosticStatus::OK, message);
            }
            Err(e) => self.fail_connect(e),
        }
    }

    fn fail_connect(&mut self, e: Error) {
        if let Error::Unsupported { parameter, reason } = e {
            let message = format!("{parameter}: {reason}; not retrying: change {parameter}");
            error!("{}: {message}", self.config.port);
            self.status.last_error = Some(message.clone());
            self.leave_scanning();
            self.state = State::Failed { parameter, reason };
            self.report(DiagnosticStatus::ERROR, message);
            return;
        }
        let wait = self.backoff;
        self.backoff = (self.backoff * 2).min(self.config.reconnect_max);
        let hint = match &e {
            Error::Timeout { what, .. } if what.starts_with("device info") => {
                " (no answer at all: wrong baud rate, or not an RPLIDAR?)"
            }
            _ => "",
        };
        let message = format!(
            "cannot start the device: {e}{hint}; retrying in {} ms",
            wait.as_millis()
        );
        warn!("{}: {message}", self.config.port);
        self.status.last_error = Some(e.to_string());
        self.leave_scanning();
        self.state = State::Disconnected {
            next_attempt: Instant::now() + wait,
        };
        self.report(DiagnosticStatus::ERROR, message);
    }

    fn enter_scanning(&mut self, session: Session) {
        self.status.scanning = true;
        self.status.device = Some(session.info.clone());
        self.status.health = Some(session.health);
        self.status.scan_mode = Some(session.mode_name.clone());
        self.status.format = Some(session.decoder.format());
        self.status.nominal_sample_rate_hz = session.nominal_rate_hz;
        self.status.baud_readback = session.baud_readback;
        self.status.motor_pwm = session.motor_pwm;
        // Returns are judged on this session's rotations: a gap spent reconnecting is no
        // time without a return.
        self.status.valid_beams = None;
        self.status.rotations_without_return = 0;
        self.no_return_since = None;
        self.state = State::Scanning(Box::new(session));
    }

    /// Ends a session (keeping its decode counters) and leaves the state to the caller.
    fn leave_scanning(&mut self) {
        if let State::Scanning(session) = &self.state {
            self.decode_before = add_stats(self.decode_before, session.decoder.stats());
        }
        self.status.scanning = false;
        self.state = State::Disconnected {
            next_attempt: Instant::now(),
        };
    }

    fn decode_totals(&self) -> DecodeStats {
        match &self.state {
            State::Scanning(s) => add_stats(self.decode_before, s.decoder.stats()),
            _ => self.decode_before,
        }
    }

    /// Stop whatever runs, read info and health (resetting on a health error), set the
    /// motor, choose the mode and start scanning.
    fn start_session(&mut self, mut link: Link) -> Result<Session> {
        let baud_readback = link.port.baud_rate().ok();
        link.set_motor_dtr(true);
        link.send(&Request::Stop)?;
        std::thread::sleep(AFTER_STOP);
        link.clear_input();
        let timeout = self.config.request_timeout;
        let info = DeviceInfo::parse(&link.request(
            &Request::GetInfo,
            answer::DEVICE_INFO,
            timeout,
            "device info",
        )?)?;
        let mut health = self.get_health(&mut link)?;
        if health.status == HealthStatus::Error {
            let message = format!(
                "device reports a health error (code 0x{:04X}): resetting it",
                health.error_code
            );
            warn!("{}: {message}", self.config.port);
            self.report(DiagnosticStatus::ERROR, message);
            self.reset_device(&mut link)?;
            health = self.get_health(&mut link)?;
            if health.status == HealthStatus::Error {
                return Err(Error::Protocol(format!(
                    "health error (code 0x{:04X}) persists after a reset",
                    health.error_code
                )));
            }
        } else if health.status != HealthStatus::Good {
            let message = format!(
                "device health {:?} (code 0x{:04X})",
                health.status, health.error_code
            );
            warn!("{}: {message}", self.config.port);
            self.report(DiagnosticStatus::WARN, message);
        }
        // Chosen before a PWM motor is started, so that a mode the device lacks (permanent)
        // never starts it; the link stops a DTR motor when dropped with the error.
        let mut plan = self.plan_scan(&mut link, &info)?;
        self.warn_of_motor_parameter_ignored(&info);
        let mut motor_pwm = None;
        if info.is_time_of_flight() {
            let rpm = match self.config.motor_rpm {
                // Told 0 rpm by `stop_motor`: it turns again only when told a speed.
                None if self.motor_rpm_zeroed => Some(self.desired_rpm(&mut link)),
                configured => configured,
            };
            if let Some(rpm) = rpm {
                link.send(&Request::SetMotorRpm(rpm))?;
                self.motor_rpm_zeroed = false;
            }
        } else {
            // A2/A3 motors on the accessory board stand still until told a duty cycle.
            motor_pwm = self.config.motor_pwm.or_else(|| {
                self.accessory_board_motor(&mut link, &info)
                    .then_some(DEFAULT_MOTOR_PWM)
            });
            if let Some(pwm) = motor_pwm {
                link.send(&Request::SetMotorPwm(pwm))?;
            }
        }
        if plan.nominal_rate_hz.is_none() && info.supports_express() {
            plan.nominal_rate_hz = self.legacy_sample_rate(&mut link, plan.format);
        }
        link.send(&plan.request)?;
        let deadline = Instant::now() + timeout;
        let descriptor = link.wait_descriptor(plan.format.answer_type(), deadline, "scan start")?;
        if descriptor.len as usize != plan.format.packet_len() {
            debug!(
                "{}: scan descriptor announces {} bytes per packet, format {:?} has {}",
                self.config.port,
                descriptor.len,
                plan.format,
                plan.format.packet_len()
            );
        }
        // Measurements that came with the descriptor stay in `link.rx` for the first poll.
        let interval = sample_interval(plan.nominal_rate_hz, plan.format, self.config.baud);
        Ok(Session {
            link,
            info,
            health,
            mode_name: plan.mode_name,
            nominal_rate_hz: plan.nominal_rate_hz,
            decoder: StreamDecoder::new(plan.format),
            assembler: RotationAssembler::with_sample_interval(interval),
            sample_interval: interval,
            samples: Vec::with_capacity(4096),
            rotations: Vec::new(),
            last_data: Instant::now(),
            last_rotation: Instant::now(),
            baud_readback,
            motor_pwm,
        })
    }

    /// `motor_pwm` drives A2/A3 accessory boards and `motor_rpm` time-of-flight motors: the
    /// other one is not sent, and a user who set it to tune the scan rate is told why nothing
    /// changed rather than left guessing.
    fn warn_of_motor_parameter_ignored(&mut self, info: &DeviceInfo) {
        let ignored = if info.is_time_of_flight() {
            self.config
                .motor_pwm
                .map(|pwm| format!("motor_pwm = {pwm} ignored: this device takes motor_rpm"))
        } else {
            self.config.motor_rpm.map(|rpm| {
                format!("motor_rpm = {rpm} ignored: only time-of-flight (S-series) devices take it; set motor_pwm (A2/A3) instead")
            })
        };
        let Some(ignored) = ignored else { return };
        if self.warned_motor_parameter {
            return;
        }
        self.warned_motor_parameter = true;
        let message = format!("{} ({})", ignored, info.family());
        warn!("{}: {message}", self.config.port);
        self.report(DiagnosticStatus::WARN, message);
    }

    /// Whether the device's motor is driven by the accessory board (`GET_ACC_BOARD_FLAG`,
    /// bit 0), asked of A2/A3 only as Slamtec's SDK does. No answer (older firmware) or a
    /// malformed one means no: the motor is then run by DTR.
    fn accessory_board_motor(&self, link: &mut Link, info: &DeviceInfo) -> bool {
        if !(2..6).contains(&info.major_model()) {
            return false;
        }
        let probe = self.probe_timeout();
        match link.request(
            &Request::GetAccBoardFlag,
            answer::ACC_BOARD_FLAG,
            probe,
            "accessory board flag",
        ) {
            Ok(payload) if payload.len() >= 4 => {
                let flag = u32::from_le_bytes([payload[0], payload[1], payload[2], payload[3]]);
                flag & ACC_BOARD_MOTOR_CTRL != 0
            }
            Ok(payload) => {
                debug!(
                    "{}: accessory board flag of {} bytes ignored",
                    self.config.port,
                    payload.len()
                );
                false
            }
            Err(e) => {
                debug!("{}: no accessory board flag: {e}", self.config.port);
                link.clear_input();
                false
            }
        }
    }

    /// The rpm a time-of-flight device prefers (`GET_LIDAR_CONF` entry 0x01), as Slamtec's SDK
    /// 2 asks it when starting the motor, and its fallback without an answer.
    fn desired_rpm(&self, link: &mut Link) -> u16 {
        let probe = self.probe_timeout();
        match conf_request(link, conf::DESIRED_ROT_FREQ, None, probe)
            .and_then(|v| conf_u32(&v, 2, "desired rpm"))
        {
            Ok(rpm) if rpm > 0 => rpm as u16,
            answer => {
                debug!(
                    "{}: no desired motor speed ({answer:?}): {FALLBACK_MOTOR_RPM} rpm",
                    self.config.port
                );
                link.clear_input();
                FALLBACK_MOTOR_RPM
            }
        }
    }

    /// `GET_SAMPLERATE` (firmware 1.17 and later): samples per second of the standard or
    /// express scan; `None` when the device does not answer.
    fn legacy_sample_rate(&self, link: &mut Link, format: ScanFormat) -> Option<f32> {
        let probe = self.probe_timeout();
        match link.request(
            &Request::GetSampleRate,
            answer::SAMPLE_RATE,
            probe,
            "sample rate",
        ) {
            Ok(payload) => {
                let rate = SampleRate::parse(&payload).ok()?;
                let us = if format == ScanFormat::Standard {
                    rate.standard_us
                } else {
                    rate.express_us
                };
                (us > 0).then(|| 1e6 / f32::from(us))
            }
            Err(e) => {
                debug!("{}: no sample rate: {e}", self.config.port);
                link.clear_input();
                None
            }
        }
    }

    /// Wait for answers that firmware without the request never sends.
    fn probe_timeout(&self) -> Duration {
        self.config.request_timeout.min(CONF_PROBE_TIMEOUT)
    }

    fn get_health(&self, link: &mut Link) -> Result<DeviceHealth> {
        let timeout = self.config.request_timeout;
        DeviceHealth::parse(&link.request(
            &Request::GetHealth,
            answer::DEVICE_HEALTH,
            timeout,
            "device health",
        )?)
    }

    fn reset_device(&mut self, link: &mut Link) -> Result<()> {
        self.status.resets += 1;
        link.send(&Request::Reset)?;
        std::thread::sleep(self.config.reset_wait);
        // The device prints a boot banner after a reset: not protocol, drop it.
        link.clear_input();
        Ok(())
    }

    /// The scan modes the device lists, or `None` when it does not answer the count (or
    /// answers it malformed) within the probe timeout, as firmware without them does.
    fn scan_modes(&self, link: &mut Link) -> Result<Option<Vec<ScanModeInfo>>> {
        let count = match conf_request(link, conf::SCAN_MODE_COUNT, None, self.probe_timeout())
            .and_then(|v| conf_u32(&v, 2, "scan mode count"))
        {
            Ok(count) => count as u16,
            Err(e @ (Error::Timeout { .. } | Error::Protocol(_))) => {
                debug!("{}: no scan-mode list: {e}", self.config.port);
                link.clear_input();
                return Ok(None);
            }
            Err(e) => return Err(e),
        };
        let timeout = self.config.request_timeout;
        let mut modes = Vec::with_capacity(usize::from(count));
        for id in 0..count {
            let us = conf_u32(
                &conf_request(link, conf::SCAN_MODE_US_PER_SAMPLE, Some(id), timeout)?,
                4,
                "us per sample",
            )?;
            let dist = conf_u32(
                &conf_request(link, conf::SCAN_MODE_MAX_DISTANCE, Some(id), timeout)?,
                4,
                "max distance",
            )?;
            let ans = conf_u32(
                &conf_request(link, conf::SCAN_MODE_ANS_TYPE, Some(id), timeout)?,
                1,
                "answer type",
            )?;
            let name = conf_string(&conf_request(
                link,
                conf::SCAN_MODE_NAME,
                Some(id),
                timeout,
            )?);
            modes.push(ScanModeInfo {
                id,
                name,
                us_per_sample: us as f32 / 256.0,
                max_distance_m: dist as f32 / 256.0,
                answer_type: ans as u8,
            });
        }
        Ok(Some(modes))
    }

    /// Chooses the scan. Like Slamtec's SDK 2, the device is asked for its scan modes rather
    /// than its firmware number trusted (S-series numbering restarts: an S3 reports 1.02);
    /// only A-series firmware old enough to prove there are none is not asked. Without a
    /// list, the legacy choice by firmware number.
    fn plan_scan(&mut self, link: &mut Link, info: &DeviceInfo) -> Result<ScanPlan> {
        let choice = self.config.scan_mode.clone();
        if choice == ScanModeChoice::Standard {
            return Ok(ScanPlan::standard());
        }
        let modes = if info.lacks_scan_modes() {
            None
        } else {
            self.scan_modes(link)?
        };
        match modes {
            Some(modes) => self.plan_from_modes(link, &choice, &modes),
            None => self.legacy_plan(&choice, info),
        }
    }

    /// The scan of a device without a scan-mode list: legacy express from firmware 1.17 on,
    /// standard before.
    fn legacy_plan(&mut self, choice: &ScanModeChoice, info: &DeviceInfo) -> Result<ScanPlan> {
        if let ScanModeChoice::Named(name) = choice {
            if info.lacks_scan_modes() {
                return Err(scan_mode_unsupported(format!(
                    "`{name}`: firmware {} has no scan modes (they came with 1.24); use auto, \
                     standard or express",
                    info.firmware()
                )));
            }
            // No answer proves nothing on this device (a glitch, a slow start): try again.
            return Err(Error::Timeout {
                what: format!("the device's list of scan modes (scan mode `{name}` needs it)"),
                waited_ms: self.probe_timeout().as_millis() as u64,
            });
        }
        if info.supports_express() {
            return Ok(ScanPlan::legacy_express());
        }
        if *choice == ScanModeChoice::Express {
            let message = format!(
                "firmware {} has no express scan: using standard",
                info.firmware()
            );
            self.report(DiagnosticStatus::WARN, message);
        }
        Ok(ScanPlan::standard())
    }

    /// The scan of the mode `choice` names among those the device lists.
    fn plan_from_modes(
        &mut self,
        link: &mut Link,
        choice: &ScanModeChoice,
        modes: &[ScanModeInfo],
    ) -> Result<ScanPlan> {
        let offered = || {
            modes
                .iter()
                .map(|m| format!("{} (id {})", m.name, m.id))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mode = match choice {
            ScanModeChoice::Standard => return Ok(ScanPlan::standard()),
            ScanModeChoice::Express => modes
                .iter()
                .find(|m| {
                    m.answer_type == answer::MEASUREMENT_CAPSULED
                        && m.name.eq_ignore_ascii_case("express")
                })
                .or_else(|| {
                    modes
                        .iter()
                        .find(|m| m.answer_type == answer::MEASUREMENT_CAPSULED)
                })
                .ok_or_else(|| {
                    scan_mode_unsupported(format!(
                        "express: the device has no express-capsule mode; it offers: {}; use \
                         auto or one of these names",
                        offered()
                    ))
                })?,
            ScanModeChoice::Auto => {
                let v = conf_request(
                    link,
                    conf::SCAN_MODE_TYPICAL,
                    None,
                    self.config.request_timeout,
                )?;
                let typical = conf_u32(&v, 2, "typical scan mode")? as u16;
                modes.iter().find(|m| m.id == typical).ok_or_else(|| {
                    Error::Protocol(format!(
                        "typical scan mode id {typical} is not among the listed modes: {}",
                        offered()
                    ))
                })?
            }
            ScanModeChoice::Named(name) => modes
                .iter()
                .find(|m| m.name.eq_ignore_ascii_case(name.trim()))
                .ok_or_else(|| {
                    scan_mode_unsupported(format!(
                        "`{name}` is not offered; the device offers: {}",
                        offered()
                    ))
                })?,
        };
        if mode.answer_type == answer::MEASUREMENT {
            return Ok(ScanPlan {
                mode_name: mode.name.clone(),
                nominal_rate_hz: Some(mode.sample_rate_hz()),
                ..ScanPlan::standard()
            });
        }
        let format = ScanFormat::from_answer_type(mode.answer_type).ok_or_else(|| {
            let decoded: Vec<&str> = modes
                .iter()
                .filter(|m| {
                    m.answer_type == answer::MEASUREMENT
                        || ScanFormat::from_answer_type(m.answer_type).is_some()
                })
                .map(|m| m.name.as_str())
                .collect();
            scan_mode_unsupported(format!(
                "mode `{}` streams answer type 0x{:02X}, which this driver does not decode; \
                 set a mode it decodes: {}",
                mode.name,
                mode.answer_type,
                decoded.join(", ")
            ))
        })?;
        let working_mode = u8::try_from(mode.id).map_err(|_| {
            Error::Protocol(format!("scan mode id {} does not fit the request", mode.id))
        })?;
        info!(
            "{}: scan mode {} (id {}): {:.0} samples/s, max {:.1} m",
            self.config.port,
            mode.name,
            mode.id,
            mode.sample_rate_hz(),
            mode.max_distance_m
        );
        Ok(ScanPlan {
            request: Request::ExpressScan {
                working_mode,
                working_flags: 0,
                param: 0,
            },
            format,
            mode_name: mode.name.clone(),
            nominal_rate_hz: Some(mode.sample_rate_hz()),
        })
    }

    fn poll_scan(&mut self) {
        let State::Scanning(session) = &mut self.state else {
            return;
        };
        let wait = self
            .next_report
            .saturating_duration_since(Instant::now())
            .min(POLL);
        let read = session.link.read_backlog(wait);
        let arrival = Instant::now();
        if let Err(e) = read {
            self.lose_device(e);
            return;
        }
        if !session.link.rx.is_empty() {
            session.samples.clear();
            let rx = std::mem::take(&mut session.link.rx);
            session.decoder.push(&rx, &mut session.samples);
            session.link.rx = rx;
            session.link.rx.clear();
            if !session.samples.is_empty() {
                session.last_data = arrival;
            }
            session.assembler.push_with_held_back(
                &session.samples,
                session.decoder.held_back_samples(),
                arrival,
                &mut session.rotations,
            );
        }
        let silent_for = arrival.saturating_duration_since(session.last_data);
        if !session.rotations.is_empty() {
            session.last_rotation = arrival;
        }
        let turnless_for = arrival.saturating_duration_since(session.last_rotation);
        let interval = session.sample_interval.as_secs_f64();
        let rotations = std::mem::take(&mut session.rotations);
        // One reading of both clocks for all rotations of this read: reading them anew for
        // each would add the time between the readings to the spacing of the stamps.
        let (now, clock_now) = (Instant::now(), (self.clock)());
        for rotation in &rotations {
            let start_ns = clock_now
                .saturating_sub(now.saturating_duration_since(rotation.started).as_nanos() as i64);
            let frame = ScanFrame::from_rotation(rotation, start_ns, &self.config.geometry);
            self.status.scans += 1;
            // A rotation shorter than half the time the device takes for its samples is part
            // of a backlog handed over in several reads (crowded, see `rotation`), not a
            // faster motor: it does not move the measured rate.
            if f64::from(frame.scan_time) >= 0.5 * interval * rotation.samples.len() as f64 {
                let hz = 1.0 / f64::from(frame.scan_time);
                self.status.rotation_hz = Some(
                    self.status
                        .rotation_hz
                        .map_or(hz, |old| 0.8 * old + 0.2 * hz),
                );
            }
            self.status.samples_per_rotation = Some(frame.samples_in_rotation);
            self.status.valid_beams = Some(frame.valid_beams);
            if frame.valid_beams == 0 {
                self.status.rotations_without_return += 1;
                self.no_return_since.get_or_insert(rotation.started);
            } else {
                self.status.rotations_without_return = 0;
                self.no_return_since = None;
            }
            self.pending
                .push_back(Event::Scan(frame.to_laser_scan(&self.config.frame_id)));
        }
        if silent_for > self.config.data_timeout {
            self.recover(format!(
                "no valid data for {:.1} s: resetting the device",
                silent_for.as_secs_f64()
            ));
        } else if turnless_for > 2 * self.config.data_timeout {
            // Samples arrive but the angle never wraps: the motor is stuck or stopped.
            self.recover(format!(
                "data but no complete rotation for {:.1} s (motor stopped?): resetting the device",
                turnless_for.as_secs_f64()
            ));
        }
    }

    fn lose_device(&mut self, e: Error) {
        self.status.disconnects += 1;
        self.status.last_error = Some(e.to_string());
        let message = format!("lost the device: {e}; reconnecting");
        error!("{}: {message}", self.config.port);
        self.leave_scanning();
        self.backoff = self.config.reconnect_min;
        self.state = State::Disconnected {
            next_attempt: Instant::now() + self.config.reconnect_min,
        };
        self.report(DiagnosticStatus::ERROR, message);
    }

    /// Resets the device on the open port and starts scanning again.
    fn recover(&mut self, message: String) {
        warn!("{}: {message}", self.config.port);
        self.report(DiagnosticStatus::WARN, message);
        let old = std::mem::replace(
            &mut self.state,
            State::Disconnected {
                next_attempt: Instant::now(),
            },
        );
        let State::Scanning(session) = old else {
            return;
        };
        self.decode_before = add_stats(self.decode_before, session.decoder.stats());
        self.status.scanning = false;
        let mut link = session.link;
        let result = self
            .reset_device(&mut link)
            .and_then(|()| self.start_session(link));
        match result {
            Ok(session) => {
                let message = format!("scanning again after a reset, mode {}", session.mode_name);
                info!("{}: {message}", self.config.port);
                self.enter_scanning(session);
                self.report(DiagnosticStatus::OK, message);
            }
            Err(e) => self.fail_connect(e),
        }
    }

    fn hardware_id(&self) -> String {
        self.status
            .device
            .as_ref()
            .map_or_else(|| self.config.port.clone(), DeviceInfo::serial_hex)
    }

    /// How long without a complete rotation before a routine report warns: two turns at the
    /// measured rate (one late turn is no fault; before a rate is measured, as while the
    /// motor spins up, `data_timeout`), and never less than the report period.
    fn rotation_overdue_after(&self) -> Duration {
        let two_turns = self
            .status
            .rotation_hz
            .and_then(|hz| Duration::try_from_secs_f64(2.0 / hz).ok())
            .unwrap_or(self.config.data_timeout);
        two_turns.max(self.config.diagnostics_period)
    }

    fn routine_report(&mut self) {
        let new_scans = self.status.scans - self.scans_at_last_report;
        self.scans_at_last_report = self.status.scans;
        // By the age of the last rotation, not the rotations of the period: a period shorter
        // than a turn often has none on a healthy device.
        let overdue = match &self.state {
            State::Scanning(session) => Some(session.last_rotation.elapsed())
                .filter(|&turnless_for| turnless_for > self.rotation_overdue_after()),
            _ => None,
        };
        // Every rotation of the period came back empty, not one stray turn: a blinded sensor.
        // A period without a rotation (shorter than a turn) keeps the last judgement.
        let no_return = self.status.scanning
            && if new_scans > 0 {
                self.status.rotations_without_return >= new_scans
            } else {
                self.warned_no_return && self.status.rotations_without_return > 0
            };
        let (level, message) = if matches!(self.state, State::StoppedOnRequest(_)) {
            (DiagnosticStatus::OK, MOTOR_STOPPED_MESSAGE.into())
        } else if !self.status.scanning {
            let why = self
                .status
                .last_error
                .clone()
                .unwrap_or_else(|| "not connected yet".into());
            let stop = if self.status.motor_stopped_on_request {
                "; stop_motor: stopped once the device answers"
            } else {
                ""
            };
            (
                DiagnosticStatus::ERROR,
                format!("not scanning: {why}{stop}"),
            )
        } else if let Some(turnless_for) = overdue {
            (
                DiagnosticStatus::WARN,
                format!(
                    "scanning, but no complete rotation for {:.1} s",
                    turnless_for.as_secs_f64()
                ),
            )
        } else if no_return {
            let seconds = self
                .no_return_since
                .map_or(0.0, |t| t.elapsed().as_secs_f64());
            (
                DiagnosticStatus::WARN,
                format!(
                    "no return on any beam for {} rotations ({seconds:.1} s): covered, \
                     blinded, or facing open space beyond range_max ({} m)",
                    self.status.rotations_without_return, self.config.geometry.range_max_m
                ),
            )
        } else {
            (
                DiagnosticStatus::OK,
                format!(
                    "scanning at {:.1} Hz, {} samples per rotation",
                    self.status.rotation_hz.unwrap_or(0.0),
                    self.status.samples_per_rotation.unwrap_or(0)
                ),
            )
        };
        if no_return && !self.warned_no_return {
            warn!("{}: {message}", self.config.port);
        } else if self.warned_no_return && level == DiagnosticStatus::OK {
            info!("{}: returns again; {message}", self.config.port);
        }
        self.warned_no_return = no_return;
        self.report(level, message);
    }

    /// Queues a diagnostics event with the current values.
    fn report(&mut self, level: u8, message: String) {
        let s = self.status();
        let mut values = vec![
            KeyValue::new("port", self.config.port.clone()),
            KeyValue::new("baud", self.config.baud.to_string()),
            KeyValue::new("scanning", s.scanning.to_string()),
            KeyValue::new(
                "motor_stopped_on_request",
                s.motor_stopped_on_request.to_string(),
            ),
            KeyValue::new("beams", self.config.geometry.beams.to_string()),
            KeyValue::new("scans", s.scans.to_string()),
            KeyValue::new("resets", s.resets.to_string()),
            KeyValue::new("connects", s.connects.to_string()),
            KeyValue::new("disconnects", s.disconnects.to_string()),
            KeyValue::new("skipped_bytes", s.decode.skipped_bytes.to_string()),
            KeyValue::new("rejected_packets", s.decode.rejected_packets.to_string()),
        ];
        if let Some(d) = &s.device {
            values.push(KeyValue::new(
                "model",
                format!("{} (0x{:02X})", d.family(), d.model),
            ));
            values.push(KeyValue::new("firmware", d.firmware()));
            values.push(KeyValue::new("hardware", d.hardware.to_string()));
            values.push(KeyValue::new("serial", d.serial_hex()));
        }
        if let Some(h) = &s.health {
            values.push(KeyValue::new(
                "health",
                format!("{:?} (code 0x{:04X})", h.status, h.error_code),
            ));
        }
        if let Some(mode) = &s.scan_mode {
            values.push(KeyValue::new("scan_mode", mode.clone()));
        }
        if let Some(rate) = s.nominal_sample_rate_hz {
            values.push(KeyValue::new(
                "nominal_sample_rate_hz",
                format!("{rate:.0}"),
            ));
        }
        if let Some(baud) = s.baud_readback {
            values.push(KeyValue::new("baud_readback", baud.to_string()));
        }
        if let Some(pwm) = s.motor_pwm {
            values.push(KeyValue::new("motor_pwm", pwm.to_string()));
        }
        if let Some(hz) = s.rotation_hz {
            values.push(KeyValue::new("rotation_hz", format!("{hz:.2}")));
        }
        if let Some(n) = s.samples_per_rotation {
            values.push(KeyValue::new("samples_per_rotation", n.to_string()));
            if let Some(hz) = s.rotation_hz {
                values.push(KeyValue::new(
                    "sample_rate_hz",
                    format!("{:.0}", hz * n as f64),
                ));
            }
        }
        if let Some(valid) = s.valid_beams {
            let beams = self.config.geometry.beams;
            values.push(KeyValue::new("valid_beams", valid.to_string()));
            values.push(KeyValue::new(
                "valid_beams_percent",
                format!("{:.1}", 100.0 * valid as f64 / beams as f64),
            ));
            values.push(KeyValue::new(
                "rotations_without_return",
                s.rotations_without_return.to_string(),
            ));
        }
        let status = DiagnosticStatus {
            level,
            name: format!("rplidar: {}", self.config.port),
            message,
            hardware_id: self.hardware_id(),
            values,
        };
        let stamp = Time::from_nanos((self.clock)());
        self.pending.push_back(Event::Diagnostics(DiagnosticArray {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            status: vec![status],
        }));
    }
}

/// Clears HUPCL, which Linux sets on ttys by default: with it, closing the port (the host
/// exits, a fault drops the link) lowers DTR, and DTR low runs an A1's motor, so the motor
/// that `stop_device` turned off would start again. Without it DTR keeps the level set last.
/// A port without termios (not a tty) is left as it is, as DTR errors are.
fn keep_modem_lines_at_close(port: &TTYPort, path: &str) {
    // SAFETY: the descriptor belongs to `port`, which outlives this borrow.
    let fd = unsafe { BorrowedFd::borrow_raw(port.as_raw_fd()) };
    let cleared = tcgetattr(fd).and_then(|mut termios| {
        if !termios.control_flags.contains(ControlFlags::HUPCL) {
            return Ok(());
        }
        termios.control_flags.remove(ControlFlags::HUPCL);
        tcsetattr(fd, SetArg::TCSANOW, &termios)
    });
    if let Err(e) = cleared {
        debug!(
            "{path}: clearing HUPCL failed ({e}); closing the port will lower DTR (an A1's motor runs)"
        );
    }
}

impl Drop for Link {
    /// Stops as Slamtec's SDK `stop()` does (`stop_device`, without the rpm command). Errors
    /// are moot here (an unplugged device has stopped anyway).
    fn drop(&mut self) {
        if self.started {
            let _ = self.stop_device(false);
        }
    }
}

fn conf_request(
    link: &mut Link,
    entry: u32,
    mode: Option<u16>,
    timeout: Duration,
) -> Result<Vec<u8>> {
    let what = format!("configuration entry 0x{entry:X}");
    let payload = link.request(
        &Request::GetLidarConf { entry, mode },
        answer::GET_LIDAR_CONF,
        timeout,
        &what,
    )?;
    Ok(parse_conf_answer(&payload, entry)?.to_vec())
}

/// The device lacks what `scan_mode` asks for: a permanent error.
fn scan_mode_unsupported(reason: String) -> Error {
    Error::Unsupported {
        parameter: "scan_mode",
        reason,
    }
}

/// Time between two samples of the device: the interval it announces for the mode, else
/// the wire time of one sample at `baud` (10 bits a byte), which a device on a real serial
/// link cannot beat. Used to date back the samples of one read (see `rotation`).
fn sample_interval(announced_hz: Option<f32>, format: ScanFormat, baud: u32) -> Duration {
    announced_hz
        .and_then(|hz| Duration::try_from_secs_f64(1.0 / f64::from(hz)).ok())
        .filter(|d| !d.is_zero())
        .unwrap_or_else(|| {
            let bit_ns = 1_000_000_000 / u64::from(baud.max(1));
            let bytes = format.packet_len() as u64;
            Duration::from_nanos(10 * bit_ns * bytes / format.samples_per_packet() as u64)
        })
}

fn add_stats(a: DecodeStats, b: DecodeStats) -> DecodeStats {
    DecodeStats {
        packets: a.packets + b.packets,
        samples: a.samples + b.samples,
        skipped_bytes: a.skipped_bytes + b.skipped_bytes,
        rejected_packets: a.rejected_packets + b.rejected_packets,
        gaps: a.gaps + b.gaps,
    }
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use crate::encode;
    use crate::protocol::{REQUEST_SYNC, SendMode, command};
    use serialport::TTYPort;
    use std::sync::atomic::{AtomicI64, Ordering};
    use std::thread::JoinHandle;

    /// Samples per turn of the scripted device and its sample interval (1 kHz: 10 Hz).
    const TURN: usize = 100;
    const SAMPLE_US: u16 = 1000;

    /// Standard nodes `range` of an endless stream of 100-sample turns.
    fn nodes(range: std::ops::Range<usize>) -> Vec<u8> {
        nodes_at(range, 1000.0)
    }

    /// [`nodes`] with every return at `distance_mm` (0: none, a covered window).
    fn nodes_at(range: std::ops::Range<usize>, distance_mm: f32) -> Vec<u8> {
        let quality = if distance_mm > 0.0 { 188 } else { 0 };
        range
            .flat_map(|j| {
                let k = j % TURN;
                encode::standard_node(k as f32 * 360.0 / TURN as f32, distance_mm, quality, k == 0)
            })
            .collect()
    }

    /// A descriptor and payload; a stream's descriptor gives its packet length (5 bytes).
    fn answer(answer_type: u8, mode: SendMode, payload: &[u8]) -> Vec<u8> {
        let len = payload.len() as u32;
        let mut out = Descriptor {
            len: if mode == SendMode::Multiple { 5 } else { len },
            mode,
            answer_type,
        }
        .encode()
        .to_vec();
        out.extend_from_slice(payload);
        out
    }

    /// An A1 with firmware 1.29 on a pseudo-terminal, answering until it has answered `SCAN`
    /// with the scan descriptor followed by `first_data` in the same write; it then hands
    /// over its end of the line. A write of this size reaches the reader in one piece.
    fn scripted_device(mut master: TTYPort, first_data: Vec<u8>) -> JoinHandle<TTYPort> {
        std::thread::spawn(move || {
            let info = DeviceInfo {
                model: 0x18,
                firmware_major: 1,
                firmware_minor: 29,
                hardware: 7,
                serial: *b"SCRIPTED-LIDAR-1",
            };
            let mut rate = SAMPLE_US.to_le_bytes().to_vec();
            rate.extend_from_slice(&SAMPLE_US.to_le_bytes());
            master.set_timeout(Duration::from_millis(20)).unwrap();
            let deadline = Instant::now() + Duration::from_secs(20);
            let mut rx = Vec::new();
            let mut buf = [0u8; 256];
            while Instant::now() < deadline {
                if let Ok(n) = master.read(&mut buf) {
                    rx.extend_from_slice(&buf[..n]);
                }
                while let Some(i) = rx.iter().position(|b| *b == REQUEST_SYNC) {
                    let Some(&cmd) = rx.get(i + 1) else { break };
                    rx.drain(..i + 2);
                    let single = SendMode::Single;
                    let out = match cmd {
                        command::GET_INFO => answer(answer::DEVICE_INFO, single, &info.encode()),
                        command::GET_HEALTH => answer(answer::DEVICE_HEALTH, single, &[0, 0, 0]),
                        command::GET_SAMPLERATE => answer(answer::SAMPLE_RATE, single, &rate),
                        command::SCAN => {
                            let multiple = SendMode::Multiple;
                            master
                                .write_all(&answer(answer::MEASUREMENT, multiple, &first_data))
                                .unwrap();
                            return master;
                        }
                        _ => continue,
                    };
                    master.write_all(&out).unwrap();
                }
            }
            panic!("the driver never asked for a scan");
        })
    }

    /// A driver scanning the scripted device, the device's end of the line (to send more
    /// measurements) and the slave end, kept open.
    fn scanning(first_data: Vec<u8>) -> (Driver, TTYPort, TTYPort) {
        let (master, slave) = TTYPort::pair().unwrap();
        let path = slave.name().unwrap();
        let device = scripted_device(master, first_data);
        // Every reading of the clock jumps by a second: stamps of rotations converted with
        // separate readings would be a second apart.
        let readings = AtomicI64::new(0);
        let t0 = Instant::now();
        let clock = Box::new(move || {
            let n = readings.fetch_add(1, Ordering::SeqCst);
            t0.elapsed().as_nanos() as i64 + n * 1_000_000_000
        });
        let mut config = Config::new(&path);
        config.scan_mode = ScanModeChoice::Standard;
        let mut driver = Driver::with_clock(config, clock).unwrap();
        driver.connect();
        let master = device.join().unwrap();
        assert!(driver.status().scanning, "{:?}", driver.status().last_error);
        assert_eq!(driver.status().nominal_sample_rate_hz, Some(1000.0));
        (driver, master, slave)
    }

    fn scans(driver: &mut Driver) -> Vec<LaserScan> {
        driver
            .pending
            .drain(..)
            .filter_map(|e| match e {
                Event::Scan(scan) => Some(scan),
                Event::Diagnostics(_) => None,
            })
            .collect()
    }

    /// The level and message of each diagnostics report queued, in order.
    fn reports(driver: &mut Driver) -> Vec<(u8, String)> {
        driver
            .pending
            .drain(..)
            .filter_map(|e| match e {
                Event::Diagnostics(array) => Some(array.status),
                Event::Scan(_) => None,
            })
            .flatten()
            .map(|s| (s.level, s.message))
            .collect()
    }

    #[test]
    fn a_report_period_shorter_than_a_turn_warns_only_when_rotations_are_overdue() {
        // Two turns at 10 Hz read at once (the rate is measured), then a third that ends
        // without returns (its first two samples came with the first read).
        let (mut driver, mut master, _slave) = scanning(nodes(0..2 * TURN + 2));
        driver.config.diagnostics_period = Duration::from_millis(20);
        driver.poll_scan();
        master
            .write_all(&nodes_at(2 * TURN + 2..3 * TURN + 2, 0.0))
            .unwrap();
        driver.poll_scan();
        assert_eq!(scans(&mut driver).len(), 3);
        let last_rotation_ago = |driver: &mut Driver, ago: Duration| {
            let State::Scanning(session) = &mut driver.state else {
                panic!("not scanning: {:?}", driver.status.last_error);
            };
            session.last_rotation = Instant::now() - ago;
        };
        // A healthy device between two rotations: the second period has none, and was OK
        // (it used to warn "no complete rotation in the last period").
        last_rotation_ago(&mut driver, Duration::from_millis(50));
        driver.routine_report();
        driver.routine_report();
        let got = reports(&mut driver);
        assert!(
            got.iter()
                .all(|(level, m)| *level == DiagnosticStatus::OK && m.starts_with("scanning at")),
            "{got:?}"
        );

        // Two turns without a return: blinded, also in the next period without a rotation.
        master
            .write_all(&nodes_at(3 * TURN + 2..5 * TURN + 2, 0.0))
            .unwrap();
        driver.poll_scan();
        assert_eq!(scans(&mut driver).len(), 2);
        last_rotation_ago(&mut driver, Duration::from_millis(50));
        driver.routine_report();
        driver.routine_report();
        let got = reports(&mut driver);
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(
            got.iter().all(|(level, m)| *level == DiagnosticStatus::WARN
                && m.starts_with("no return on any beam")),
            "{got:?}"
        );

        // No rotation for longer than two turns (0.2 s at 10 Hz): stalled, warned.
        last_rotation_ago(&mut driver, Duration::from_millis(300));
        driver.routine_report();
        let got = reports(&mut driver);
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0].0, DiagnosticStatus::WARN, "{got:?}");
        assert!(
            got[0]
                .1
                .starts_with("scanning, but no complete rotation for 0.3 s"),
            "{got:?}"
        );
    }

    #[test]
    fn the_sample_interval_is_the_announced_one_else_the_wire_time_of_a_sample() {
        let express = ScanFormat::Express;
        assert_eq!(
            sample_interval(Some(4000.0), express, 115_200),
            Duration::from_micros(250)
        );
        // 5 bytes of 10 bits at 115200 baud; 84 bytes for 32 samples at 1 Mbaud.
        let standard_wire = Duration::from_nanos(50 * 8680);
        assert_eq!(
            sample_interval(None, ScanFormat::Standard, 115_200),
            standard_wire
        );
        assert_eq!(
            sample_interval(None, express, 1_000_000),
            Duration::from_nanos(26_250)
        );
        for nonsense in [0.0, -5.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                sample_interval(Some(nonsense), ScanFormat::Standard, 115_200),
                standard_wire,
                "{nonsense}"
            );
        }
    }

    #[test]
    fn the_c1_baud_rate_is_set_on_the_port() {
        // 460800 has no classic termios constant everywhere; Linux sets any rate (BOTHER).
        let (_master, slave) = TTYPort::pair().unwrap();
        let mut config = Config::new(slave.name().unwrap());
        config.baud = 460_800;
        let link = Link::open(&config).unwrap();
        assert_eq!(link.port.baud_rate().unwrap(), 460_800);
    }

    #[test]
    fn measurements_that_come_with_the_scan_descriptor_are_kept() {
        // A full turn, the next turn's start and one node of look-ahead, all in the read
        // that brings the descriptor; the device then stays silent.
        let (mut driver, _master, _slave) = scanning(nodes(0..TURN + 2));
        driver.poll_scan();
        assert_eq!(scans(&mut driver).len(), 1);
        assert_eq!(driver.status().samples_per_rotation, Some(TURN));
    }

    #[test]
    fn rotations_read_at_once_keep_their_periods_and_stamps() {
        let (mut driver, mut master, _slave) = scanning(Vec::new());
        // Three turns after a stall of the host, read at once (0.3 s of samples, 1510 bytes).
        master.write_all(&nodes(0..3 * TURN + 2)).unwrap();
        driver.poll_scan();
        let first = scans(&mut driver);
        assert_eq!(first.len(), 3);
        let stamps: Vec<i64> = first.iter().map(|s| s.header.stamp.to_nanos()).collect();
        for (k, scan) in first.iter().enumerate() {
            assert!(
                (scan.scan_time - 0.1).abs() < 1e-6,
                "scan {k}: {}",
                scan.scan_time
            );
            assert!((scan.time_increment + 0.1 / 720.0).abs() < 1e-9);
        }
        for pair in stamps.windows(2) {
            assert!(
                (pair[1] - pair[0] - 100_000_000).abs() < 1_000,
                "{stamps:?}"
            );
        }
        let hz = driver.status().rotation_hz.unwrap();
        assert!((hz - 10.0).abs() < 1e-3, "{hz}");

        // The next 0.3 s of the backlog in a second read: these rotations cannot be dated
        // and crowd together, but keep their order, last a positive time, and leave the
        // measured rate alone.
        master
            .write_all(&nodes(3 * TURN + 2..6 * TURN + 2))
            .unwrap();
        driver.poll_scan();
        let second = scans(&mut driver);
        assert_eq!(second.len(), 3);
        let mut last = stamps[2];
        for scan in &second {
            assert!(scan.scan_time > 0.0 && scan.header.stamp.to_nanos() > last);
            last = scan.header.stamp.to_nanos();
        }
        let hz = driver.status().rotation_hz.unwrap();
        assert!((8.0..12.5).contains(&hz), "{hz}");
    }

    #[test]
    fn a_backlog_the_kernel_hands_over_in_several_reads_is_dated_as_one() {
        let (mut driver, mut master, _slave) = scanning(Vec::new());
        // 1.2 s of samples (6 KB): more than a tty passes in one read (4095 bytes).
        let turns = 12;
        let backlog = nodes(0..turns * TURN + 2);
        assert!(backlog.len() > 4096);
        master.write_all(&backlog).unwrap();
        driver.poll_scan();
        let read = scans(&mut driver);
        assert_eq!(read.len(), turns);
        for (k, scan) in read.iter().enumerate() {
            assert!(
                (scan.scan_time - 0.1).abs() < 1e-6,
                "scan {k}: {}",
                scan.scan_time
            );
        }
        let stamps: Vec<i64> = read.iter().map(|s| s.header.stamp.to_nanos()).collect();
        for pair in stamps.windows(2) {
            assert!(
                (pair[1] - pair[0] - 100_000_000).abs() < 1_000,
                "{stamps:?}"
            );
        }
    }

    /// `stop_motor` and `start_motor` against the fake device.
    #[cfg(feature = "fake")]
    mod motor_on_request {
        use super::*;
        use crate::fake::{FakeConfig, FakeLidar, SyntheticRoom, driver_config};
        use std::path::Path;

        /// How long a test waits for what it expects: only a broken driver takes it.
        const LIMIT: Duration = Duration::from_secs(30);

        fn spawn(path: &Path, fake: FakeConfig) -> FakeLidar {
            FakeLidar::spawn(path, fake, SyntheticRoom::default()).expect("fake device starts")
        }

        /// Runs the driver until `done` says so, returning the scans and diagnostics seen.
        fn run_until(
            driver: &mut Driver,
            mut done: impl FnMut(&[LaserScan], &[DiagnosticStatus]) -> bool,
        ) -> (Vec<LaserScan>, Vec<DiagnosticStatus>) {
            let deadline = Instant::now() + LIMIT;
            let (mut scans, mut diags) = (Vec::new(), Vec::new());
            while !done(&scans, &diags) {
                assert!(Instant::now() < deadline, "gave up: {diags:#?}");
                match driver.next_event() {
                    Ok(Event::Scan(scan)) => scans.push(scan),
                    Ok(Event::Diagnostics(array)) => diags.extend(array.status),
                    Err(e) => panic!("the driver stopped: {e}"),
                }
            }
            (scans, diags)
        }

        fn value<'a>(d: &'a DiagnosticStatus, key: &str) -> Option<&'a str> {
            d.values
                .iter()
                .find(|kv| kv.key == key)
                .map(|kv| kv.value.as_str())
        }

        /// Runs the stopped driver for several report periods: only OK reports saying it is
        /// stopped, no scan, and nothing sent to the device.
        fn check_stopped(driver: &mut Driver, fake: &FakeLidar) {
            let sent = fake.log().commands.len();
            let (scans, diags) = run_until(driver, |_, d| d.len() >= 5);
            assert!(scans.is_empty(), "{} scans while stopped", scans.len());
            for d in &diags {
                assert_eq!(
                    (d.level, d.message.as_str()),
                    (DiagnosticStatus::OK, MOTOR_STOPPED_MESSAGE)
                );
                assert_eq!(value(d, "motor_stopped_on_request"), Some("true"));
                assert_eq!(value(d, "scanning"), Some("false"));
            }
            assert_eq!(fake.log().commands.len(), sent, "{:?}", fake.log());
            let status = driver.status();
            assert!(status.motor_stopped_on_request && !status.scanning);
            // The rate was measured on a turning motor: a restart measures afresh.
            assert_eq!(status.rotation_hz, None);
            assert!(diags.iter().all(|d| value(d, "rotation_hz").is_none()));
        }

        #[test]
        fn stop_motor_stops_a_pwm_motor_on_the_open_port_and_start_motor_scans_again() {
            let dir = tempfile::tempdir().unwrap();
            let mut a2 = FakeConfig {
                accessory_board_motor: true,
                ..FakeConfig::default()
            };
            a2.info.model = 0x28;
            let fake = spawn(&dir.path().join("rplidar"), a2);
            let mut driver = Driver::new(driver_config(fake.path())).unwrap();
            run_until(&mut driver, |s, _| s.len() >= 2);
            assert_eq!(fake.log().motor_pwm, Some(DEFAULT_MOTOR_PWM));
            // Scans read before the stop are not the stop's concern.
            driver.pending.clear();

            driver.stop_motor();
            let log = fake.log_when(LIMIT, |l| l.motor_pwm == Some(0));
            assert_eq!(log.motor_pwm, Some(0), "{log:?}");
            assert_eq!(
                log.commands[log.commands.len() - 2..],
                [command::STOP, command::SET_MOTOR_PWM],
                "STOP, then PWM 0"
            );
            assert!(
                matches!(driver.state, State::StoppedOnRequest(_)),
                "the port is kept open"
            );
            driver.stop_motor();
            check_stopped(&mut driver, &fake);

            driver.start_motor();
            driver.start_motor();
            let restarted = log.commands.len();
            let (_, diags) = run_until(&mut driver, |s, d| {
                s.len() >= 2 && d.iter().any(|d| d.message.starts_with("scanning at"))
            });
            assert!(
                diags[0].message.starts_with("scanning again (start_motor)"),
                "{diags:#?}"
            );
            // The stopped time is no stall: no WARN "no complete rotation" or reset.
            assert!(
                diags.iter().all(|d| d.level == DiagnosticStatus::OK),
                "{diags:#?}"
            );
            assert!(
                diags
                    .iter()
                    .all(|d| value(d, "motor_stopped_on_request") == Some("false"))
            );
            let log = fake.log();
            let again = &log.commands[restarted..];
            for c in [command::STOP, command::GET_INFO, command::EXPRESS_SCAN] {
                assert!(again.contains(&c), "0x{c:02X} not in {again:02X?}");
            }
            assert_eq!(
                log.motor_pwm,
                Some(DEFAULT_MOTOR_PWM),
                "the motor runs again"
            );
            assert_eq!(log.scans_started.len(), 2);
            let status = driver.status();
            assert!(status.scanning && !status.motor_stopped_on_request);
            assert_eq!((status.connects, status.resets), (1, 0), "the kept port");
        }

        #[test]
        fn stop_motor_gives_a_time_of_flight_motor_0_rpm_and_start_motor_its_speed() {
            let dir = tempfile::tempdir().unwrap();
            let fake = spawn(&dir.path().join("rplidar"), FakeConfig::s_series());
            let mut driver = Driver::new(driver_config(fake.path())).unwrap();
            run_until(&mut driver, |s, _| !s.is_empty());
            assert_eq!(fake.log().motor_rpm, None, "no motor_rpm configured");
            driver.pending.clear();

            driver.stop_motor();
            let log = fake.log_when(LIMIT, |l| l.motor_rpm == Some(0));
            assert_eq!(log.motor_rpm, Some(0), "{log:?}");
            assert_eq!(
                log.commands[log.commands.len() - 2..],
                [command::STOP, command::HQ_MOTOR_SPEED],
                "STOP, then 0 rpm"
            );
            check_stopped(&mut driver, &fake);

            driver.start_motor();
            run_until(&mut driver, |s, _| !s.is_empty());
            // The speed the device prefers (the fake turns at 10 Hz).
            assert_eq!(fake.log().motor_rpm, Some(600));
        }

        /// Asked while the device is away (unplugged, or a reconnect pending), the stop
        /// waits for it: an S-series left after a lost link turns until told 0 rpm.
        #[test]
        fn stop_motor_without_a_device_stops_it_once_it_answers() {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("rplidar");
            let mut driver = Driver::new(Config {
                motor_rpm: Some(900),
                ..driver_config(&path)
            })
            .unwrap();
            run_until(&mut driver, |_, d| {
                d.iter().any(|d| d.message.starts_with("cannot start"))
            });
            driver.pending.clear();
            driver.stop_motor();
            driver.stop_motor();
            // The routine report says what is pending (the driver goes on looking).
            run_until(&mut driver, |_, d| {
                d.iter().any(|d| {
                    d.message.starts_with("not scanning")
                        && d.message
                            .ends_with("stop_motor: stopped once the device answers")
                })
            });
            let fake = spawn(&path, FakeConfig::s_series());
            run_until(&mut driver, |_, d| {
                d.iter().any(|d| d.message == MOTOR_STOPPED_MESSAGE)
            });
            let log = fake.log_when(LIMIT, |l| l.motor_rpm == Some(0));
            assert_eq!(log.motor_rpm, Some(0), "{log:?}");
            assert_eq!(
                log.commands[log.commands.len() - 2..],
                [command::STOP, command::HQ_MOTOR_SPEED],
                "found, then STOP and 0 rpm"
            );
            driver.pending.clear();
            check_stopped(&mut driver, &fake);
            assert_eq!(driver.status().connects, 1);

            driver.start_motor();
            run_until(&mut driver, |s, _| !s.is_empty());
            assert_eq!(
                fake.log().motor_rpm,
                Some(900),
                "the configured speed again"
            );
        }

        /// Scans read before the stop are not handed out after it: the caller's reply says
        /// the scan has stopped.
        #[test]
        fn stop_motor_drops_the_scans_not_yet_taken() {
            let dir = tempfile::tempdir().unwrap();
            let fake = spawn(&dir.path().join("rplidar"), FakeConfig::default());
            let mut driver = Driver::new(driver_config(fake.path())).unwrap();
            run_until(&mut driver, |s, _| !s.is_empty());
            // A host late to take them: rotations waiting, as after a stall.
            let deadline = Instant::now() + LIMIT;
            while !driver.pending.iter().any(|e| matches!(e, Event::Scan(_))) {
                assert!(Instant::now() < deadline, "no scan waiting before the stop");
                std::thread::sleep(Duration::from_millis(100));
                driver.poll_scan();
            }
            driver.stop_motor();
            let (scans, _) = run_until(&mut driver, |_, d| d.len() >= 2);
            assert!(scans.is_empty(), "{} scans after the stop", scans.len());
        }
    }
}
