//! A fake RPLIDAR on a pseudo-terminal, for tests of the driver and of anything built on it.
//!
//! It speaks the real protocol on the master side of a pty pair and publishes the slave
//! side under a fixed path (a symbolic link, like a udev rule's `/dev/rplidar`), so a driver
//! opens it by path exactly as it opens a USB device. "Unplugging" closes the pty and
//! removes the link; "plugging back" creates a new pty and points the link at it.
//!
//! It serves rotations from a [`RangeSource`] (a closure, the simulator, a bag; by default
//! [`SyntheticRoom`]) in standard, express or dense mode at a chosen rotation rate, answers
//! info, health, sample rate, scan-mode configuration and desired motor speed requests, and
//! injects faults: garbage bytes, dropped bytes, stalls, a hung device that only a reset
//! revives, health errors, a blinded window (samples without a return) and disconnects.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::config::Config;
use crate::driver::DEFAULT_MOTOR_PWM;
use crate::encode;
use crate::protocol::{
    Descriptor, DeviceHealth, DeviceInfo, HealthStatus, REQUEST_SYNC, SendMode, answer, command,
    conf, xor,
};

/// Ranges of one rotation: `samples` values in metres at device angles
/// `k · 360° / samples` (clockwise, k = 0..samples). 0, negative, NaN or infinite values are
/// "no return".
pub trait RangeSource: Send {
    fn rotation(&mut self, index: u64, samples: usize) -> Vec<f32>;
}

impl<F> RangeSource for F
where
    F: FnMut(u64, usize) -> Vec<f32> + Send,
{
    fn rotation(&mut self, index: u64, samples: usize) -> Vec<f32> {
        self(index, samples)
    }
}

/// A rectangular room with a round pillar and a window that returns nothing, seen from a
/// fixed point: a static scene whose ranges are known exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticRoom {
    pub width_m: f32,
    pub depth_m: f32,
    /// Sensor position in the room (the room spans 0..width, 0..depth).
    pub sensor: (f32, f32),
    /// Pillar centre and radius.
    pub pillar: (f32, f32, f32),
    /// Device angles (degrees, from, to) with no return, like a window.
    pub window_deg: (f32, f32),
}

impl Default for SyntheticRoom {
    fn default() -> Self {
        Self {
            width_m: 5.0,
            depth_m: 4.0,
            sensor: (1.5, 1.2),
            pillar: (3.5, 2.8, 0.3),
            window_deg: (200.0, 215.0),
        }
    }
}

impl SyntheticRoom {
    /// Range in metres at a device angle (clockwise degrees; device 0° is the room's +x),
    /// `f32::INFINITY` in the window.
    pub fn range_at(&self, device_angle_deg: f32) -> f32 {
        let a = device_angle_deg.rem_euclid(360.0);
        if a >= self.window_deg.0 && a < self.window_deg.1 {
            return f32::INFINITY;
        }
        let theta = -a.to_radians();
        let (dx, dy) = (theta.cos(), theta.sin());
        let (sx, sy) = self.sensor;
        let mut best = f32::INFINITY;
        for t in [
            if dx > 0.0 {
                (self.width_m - sx) / dx
            } else {
                f32::INFINITY
            },
            if dx < 0.0 { -sx / dx } else { f32::INFINITY },
            if dy > 0.0 {
                (self.depth_m - sy) / dy
            } else {
                f32::INFINITY
            },
            if dy < 0.0 { -sy / dy } else { f32::INFINITY },
        ] {
            if t > 0.0 {
                best = best.min(t);
            }
        }
        let (px, py, r) = self.pillar;
        let (ox, oy) = (sx - px, sy - py);
        let b = ox * dx + oy * dy;
        let c = ox * ox + oy * oy - r * r;
        let disc = b * b - c;
        if disc >= 0.0 {
            let t = -b - disc.sqrt();
            if t > 0.0 {
                best = best.min(t);
            }
        }
        best
    }
}

impl RangeSource for SyntheticRoom {
    fn rotation(&mut self, _index: u64, samples: usize) -> Vec<f32> {
        (0..samples)
            .map(|k| self.range_at(k as f32 * 360.0 / samples as f32))
            .collect()
    }
}

/// The measurement format the fake is streaming.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FakeMode {
    Standard,
    Express,
    Dense,
}

impl FakeMode {
    /// The format of a scan mode's answer type; `None` for those the fake cannot stream.
    fn of_answer_type(answer_type: u8) -> Option<Self> {
        match answer_type {
            answer::MEASUREMENT => Some(Self::Standard),
            answer::MEASUREMENT_CAPSULED => Some(Self::Express),
            answer::MEASUREMENT_DENSE_CAPSULED => Some(Self::Dense),
            _ => None,
        }
    }
}

/// A scan mode the fake lists (its id is its index in [`FakeConfig::scan_modes`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FakeScanMode {
    pub name: String,
    /// Answer type of its stream: 0x81, 0x82 and 0x85 are streamed; any other is only listed
    /// (a mode the driver must refuse, such as ultra-dense 0x86).
    pub answer_type: u8,
}

impl FakeScanMode {
    pub fn new(name: &str, answer_type: u8) -> Self {
        Self {
            name: name.into(),
            answer_type,
        }
    }
}

/// What the fake device is.
#[derive(Debug, Clone, PartialEq)]
pub struct FakeConfig {
    pub info: DeviceInfo,
    pub samples_per_rotation: usize,
    pub rotation_hz: f32,
    /// The modes `GET_LIDAR_CONF` lists; empty: scan-mode requests get no answer (A-series
    /// firmware before 1.24) and `EXPRESS_SCAN` streams legacy express capsules.
    pub scan_modes: Vec<FakeScanMode>,
    /// Id of the mode the device calls typical.
    pub typical_mode: u16,
    /// How far capsule start angles run ahead of their samples (the angle compensation the
    /// driver must subtract), degrees in 0.5..7.5.
    pub express_lead_deg: f32,
    /// Print a boot text after `RESET`, as real devices do.
    pub boot_banner: bool,
    /// Answer `GET_ACC_BOARD_FLAG` with the motor-control bit: an A2/A3 whose motor runs
    /// only on `SET_MOTOR_PWM`.
    pub accessory_board_motor: bool,
    /// Device angle (degrees) of the sample whose packet takes the injected faults
    /// ([`FakeLidar::inject_garbage`], [`FakeLidar::drop_bytes`]): 0 is a rotation's first
    /// sample, where a lost byte and the wrap coincide; elsewhere the fault lands mid-turn.
    pub fault_angle_deg: f32,
}

impl Default for FakeConfig {
    fn default() -> Self {
        Self {
            info: DeviceInfo {
                model: 0x18,
                firmware_major: 1,
                firmware_minor: 29,
                hardware: 7,
                serial: *b"FAKE-RPLIDAR-001",
            },
            samples_per_rotation: 720,
            rotation_hz: 20.0,
            scan_modes: vec![
                FakeScanMode::new("Standard", answer::MEASUREMENT),
                FakeScanMode::new("Express", answer::MEASUREMENT_CAPSULED),
                FakeScanMode::new("DenseBoost", answer::MEASUREMENT_DENSE_CAPSULED),
            ],
            typical_mode: 1,
            express_lead_deg: 2.0,
            boot_banner: true,
            accessory_board_motor: false,
            fault_angle_deg: 0.0,
        }
    }
}

impl FakeConfig {
    /// An RPLIDAR S3 as it reports itself (model 0x81, firmware 1.02: S-series numbering
    /// restarts, so the number says nothing about scan modes), listing Standard and
    /// DenseBoost (typical), turning at 10 Hz.
    pub fn s_series() -> Self {
        Self {
            info: DeviceInfo {
                model: 0x81,
                firmware_major: 1,
                firmware_minor: 2,
                hardware: 18,
                serial: *b"FAKE-RPLIDAR-S03",
            },
            rotation_hz: 10.0,
            scan_modes: vec![
                FakeScanMode::new("Standard", answer::MEASUREMENT),
                FakeScanMode::new("DenseBoost", answer::MEASUREMENT_DENSE_CAPSULED),
            ],
            typical_mode: 1,
            ..Self::default()
        }
    }
}

/// What the fake has seen and done.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FakeLog {
    /// Command bytes of every well-formed request, in order.
    pub commands: Vec<u8>,
    pub resets: u64,
    pub scans_started: Vec<FakeMode>,
    pub rotations_served: u64,
    pub motor_pwm: Option<u16>,
    pub motor_rpm: Option<u16>,
    /// Times the pty was created (1 + replugs).
    pub plugs: u64,
}

#[derive(Debug)]
struct Control {
    garbage: Vec<u8>,
    drop_bytes: usize,
    stall_until: Option<Instant>,
    hung: bool,
    motor_stopped: bool,
    blinded: bool,
    health: DeviceHealth,
    health_cleared_by_reset: bool,
    plugged: bool,
    stop: bool,
}

struct Shared {
    control: Mutex<Control>,
    log: Mutex<FakeLog>,
}

/// A driver configuration for a fake device at `port`, with timings for a loaded 2-core CI
/// machine: request and data timeouts far longer than any stall a busy scheduler causes, so
/// that no answer is missed and reset counts are exact (no start comes near the 20 s request
/// timeout); quick reconnects and diagnostics so that tests of faults stay short.
pub fn driver_config(port: &Path) -> Config {
    Config {
        request_timeout: Duration::from_secs(20),
        data_timeout: Duration::from_secs(10),
        reset_wait: Duration::from_millis(30),
        reconnect_min: Duration::from_millis(20),
        reconnect_max: Duration::from_millis(160),
        diagnostics_period: Duration::from_millis(200),
        ..Config::new(port.to_str().expect("temporary paths are UTF-8"))
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic in the device thread must not hide the test's own failure.
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A running fake device; stops and removes its link when dropped.
pub struct FakeLidar {
    link: PathBuf,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl FakeLidar {
    /// Starts a fake device reachable at `link` (a path that must not exist yet, in a
    /// directory that does).
    pub fn spawn(
        link: impl Into<PathBuf>,
        config: FakeConfig,
        source: impl RangeSource + 'static,
    ) -> std::io::Result<Self> {
        let link = link.into();
        let pty = Pty::new(&link)?;
        let shared = Arc::new(Shared {
            control: Mutex::new(Control {
                garbage: Vec::new(),
                drop_bytes: 0,
                stall_until: None,
                hung: false,
                motor_stopped: false,
                blinded: false,
                health: DeviceHealth {
                    status: HealthStatus::Good,
                    error_code: 0,
                },
                health_cleared_by_reset: true,
                plugged: true,
                stop: false,
            }),
            log: Mutex::new(FakeLog {
                plugs: 1,
                ..FakeLog::default()
            }),
        });
        let device = Device {
            config,
            source: Box::new(source),
            shared: Arc::clone(&shared),
            link: link.clone(),
            pty: Some(pty),
            rx: Vec::new(),
            tx: Vec::new(),
            stream: None,
        };
        let thread = std::thread::Builder::new()
            .name("fake-rplidar".into())
            .spawn(move || device.run())?;
        Ok(Self {
            link,
            shared,
            thread: Some(thread),
        })
    }

    /// The path a driver opens.
    pub fn path(&self) -> &Path {
        &self.link
    }

    /// Inserts these bytes into the measurement stream, three bytes into the next packet
    /// holding the sample at [`FakeConfig::fault_angle_deg`] (by default a rotation's first):
    /// always the same place, however busy the machine.
    pub fn inject_garbage(&self, bytes: &[u8]) {
        lock(&self.shared.control).garbage.extend_from_slice(bytes);
    }

    /// Drops `n` bytes of the measurement stream, from the start of the next packet holding
    /// the sample at [`FakeConfig::fault_angle_deg`].
    pub fn drop_bytes(&self, n: usize) {
        lock(&self.shared.control).drop_bytes += n;
    }

    /// Sends nothing for `duration` (the samples of that time are lost).
    pub fn stall(&self, duration: Duration) {
        lock(&self.shared.control).stall_until = Some(Instant::now() + duration);
    }

    /// The device hangs: no data and no answers until it receives `RESET`.
    pub fn hang(&self) {
        lock(&self.shared.control).hung = true;
    }

    /// The motor stops: samples keep coming, all at one angle, until `RESET`.
    pub fn stop_motor(&self) {
        lock(&self.shared.control).motor_stopped = true;
    }

    /// While `on`, every sample comes without a return (distance 0, quality 0), whatever the
    /// source serves: a covered, dirty or blinded window. The device keeps turning and
    /// streaming, and a `RESET` does not clear it.
    pub fn set_blinded(&self, on: bool) {
        lock(&self.shared.control).blinded = on;
    }

    /// Health reported from now on; `cleared_by_reset`: a `RESET` makes it good again.
    pub fn set_health(&self, status: HealthStatus, error_code: u16, cleared_by_reset: bool) {
        let mut c = lock(&self.shared.control);
        c.health = DeviceHealth { status, error_code };
        c.health_cleared_by_reset = cleared_by_reset;
    }

    /// Closes the pty (the driver's port hangs up) and removes the link.
    pub fn unplug(&self) {
        lock(&self.shared.control).plugged = false;
    }

    /// A new pty behind the same link.
    pub fn replug(&self) {
        lock(&self.shared.control).plugged = true;
    }

    pub fn log(&self) -> FakeLog {
        lock(&self.shared.log).clone()
    }

    /// The log once `done` holds, polled until `limit` passes (then the last one seen, so
    /// that a test's asserts show what did arrive): no fixed sleep guesses the delay.
    pub fn log_when(&self, limit: Duration, done: impl Fn(&FakeLog) -> bool) -> FakeLog {
        let deadline = Instant::now() + limit;
        loop {
            let log = self.log();
            if done(&log) || Instant::now() >= deadline {
                return log;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for FakeLidar {
    fn drop(&mut self) {
        lock(&self.shared.control).stop = true;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        let _ = std::fs::remove_file(&self.link);
    }
}

/// A pty pair whose slave is published at the link. The device keeps its own slave handle
/// open so that the master never sees "no slave" errors while no driver is connected.
struct Pty {
    master: TTYPort,
    _slave: TTYPort,
}

impl Pty {
    fn new(link: &Path) -> std::io::Result<Self> {
        let (mut master, slave) = TTYPort::pair().map_err(std::io::Error::from)?;
        let slave_path = slave
            .name()
            .ok_or_else(|| std::io::Error::other("the pseudo-terminal has no slave path"))?;
        master
            .set_timeout(Duration::from_millis(20))
            .map_err(std::io::Error::from)?;
        // Replace the link atomically, as udev does when a device comes back.
        let tmp = link.with_extension("new-link");
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(&slave_path, &tmp)?;
        std::fs::rename(&tmp, link)?;
        Ok(Self {
            master,
            _slave: slave,
        })
    }
}

struct Stream {
    mode: FakeMode,
    started: Instant,
    next_sample: u64,
    ranges: Option<(u64, Vec<f32>)>,
    group: Vec<(f32, f32)>,
    first_capsule: bool,
}

struct Device {
    config: FakeConfig,
    source: Box<dyn RangeSource>,
    shared: Arc<Shared>,
    link: PathBuf,
    pty: Option<Pty>,
    rx: Vec<u8>,
    /// Bytes the driver has not taken yet (the pty buffer was full).
    tx: Vec<u8>,
    stream: Option<Stream>,
}

/// Most bytes kept for a driver that does not read (seconds of any stream): a driver slowed
/// by a busy machine loses nothing, one that never reads does not make the fake grow.
const TX_BACKLOG_MAX: usize = 1 << 20;

const BOOT_BANNER: &[u8] =
    b"RP LIDAR System.\r\nFirmware Ver 1.29 - rtm, HW Ver 7\r\nModel: 24\r\n";

impl Device {
    fn run(mut self) {
        let mut buf = [0u8; 1024];
        loop {
            let (stop, plugged) = {
                let c = lock(&self.shared.control);
                (c.stop, c.plugged)
            };
            if stop {
                return;
            }
            if !plugged {
                if self.pty.take().is_some() {
                    self.stream = None;
                    self.rx.clear();
                    self.tx.clear();
                    let _ = std::fs::remove_file(&self.link);
                }
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
            if self.pty.is_none() {
                match Pty::new(&self.link) {
                    Ok(pty) => {
                        self.pty = Some(pty);
                        lock(&self.shared.log).plugs += 1;
                    }
                    Err(_) => {
                        std::thread::sleep(Duration::from_millis(5));
                        continue;
                    }
                }
            }
            let Some(pty) = self.pty.as_mut() else {
                continue;
            };
            let _ = pty.master.set_timeout(Duration::from_millis(2));
            match pty.master.read(&mut buf) {
                Ok(n) => self.rx.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(_) => std::thread::sleep(Duration::from_millis(2)),
            }
            while let Some((cmd, payload)) = take_request(&mut self.rx) {
                self.handle(cmd, &payload);
            }
            self.stream_out();
            self.flush();
        }
    }

    /// Queues bytes for the driver; beyond the backlog limit they are lost, as on a wire.
    fn write(&mut self, bytes: &[u8]) {
        let room = TX_BACKLOG_MAX.saturating_sub(self.tx.len());
        self.tx.extend_from_slice(&bytes[..bytes.len().min(room)]);
        self.flush();
    }

    /// Writes what the pty takes now, keeping the rest for later. The master is blocking and
    /// a write waits until all of it fits, which would hang the device (and its `STOP`) when
    /// nobody reads; but once poll says writable a pty has room for 256 bytes (its buffer
    /// grows in 256-byte steps), so writes of at most that never wait.
    fn flush(&mut self) {
        const CHUNK: usize = 256;
        let Some(pty) = self.pty.as_mut() else { return };
        let _ = pty.master.set_timeout(Duration::from_millis(1));
        let mut written = 0;
        while written < self.tx.len() {
            let end = self.tx.len().min(written + CHUNK);
            match pty.master.write(&self.tx[written..end]) {
                Ok(0) | Err(_) => break, // full (or gone): try again next round
                Ok(n) => written += n,
            }
        }
        self.tx.drain(..written);
    }

    fn answer(&mut self, answer_type: u8, payload: &[u8]) {
        let d = Descriptor {
            len: payload.len() as u32,
            mode: SendMode::Single,
            answer_type,
        };
        let mut out = d.encode().to_vec();
        out.extend_from_slice(payload);
        self.write(&out);
    }

    fn start_stream(&mut self, mode: FakeMode) {
        let (packet_len, answer_type) = match mode {
            FakeMode::Standard => (5, answer::MEASUREMENT),
            FakeMode::Express => (84, answer::MEASUREMENT_CAPSULED),
            FakeMode::Dense => (84, answer::MEASUREMENT_DENSE_CAPSULED),
        };
        let d = Descriptor {
            len: packet_len,
            mode: SendMode::Multiple,
            answer_type,
        };
        self.write(&d.encode());
        lock(&self.shared.log).scans_started.push(mode);
        // Start mid-rotation, as a spinning device does.
        let n = self.config.samples_per_rotation as u64;
        self.stream = Some(Stream {
            mode,
            started: Instant::now(),
            next_sample: n / 3,
            ranges: None,
            group: Vec::new(),
            first_capsule: true,
        });
    }

    fn handle(&mut self, cmd: u8, payload: &[u8]) {
        lock(&self.shared.log).commands.push(cmd);
        let hung = lock(&self.shared.control).hung;
        if hung && cmd != command::RESET {
            return;
        }
        match cmd {
            // A stopped device sends nothing more: what the pty did not take is never sent.
            command::STOP => {
                self.stream = None;
                self.tx.clear();
            }
            command::RESET => {
                self.stream = None;
                self.tx.clear();
                {
                    let mut c = lock(&self.shared.control);
                    c.hung = false;
                    c.motor_stopped = false;
                    if c.health_cleared_by_reset {
                        c.health = DeviceHealth {
                            status: HealthStatus::Good,
                            error_code: 0,
                        };
                    }
                }
                lock(&self.shared.log).resets += 1;
                if self.config.boot_banner {
                    self.write(BOOT_BANNER);
                }
            }
            command::SCAN | command::FORCE_SCAN => self.start_stream(FakeMode::Standard),
            command::EXPRESS_SCAN => {
                let id = usize::from(payload.first().copied().unwrap_or(0));
                let mode = if self.config.scan_modes.is_empty() {
                    Some(FakeMode::Express)
                } else {
                    self.config
                        .scan_modes
                        .get(id)
                        .and_then(|m| FakeMode::of_answer_type(m.answer_type))
                };
                // A mode it cannot stream (or does not have) starts nothing.
                if let Some(mode) = mode {
                    self.start_stream(mode);
                }
            }
            command::GET_INFO => {
                let info = self.config.info.encode();
                self.answer(answer::DEVICE_INFO, &info);
            }
            command::GET_HEALTH => {
                let health = lock(&self.shared.control).health.encode();
                self.answer(answer::DEVICE_HEALTH, &health);
            }
            command::GET_SAMPLERATE => {
                let us = self.us_per_sample().round() as u16;
                let mut p = us.to_le_bytes().to_vec();
                p.extend_from_slice(&us.to_le_bytes());
                self.answer(answer::SAMPLE_RATE, &p);
            }
            command::GET_LIDAR_CONF if !self.config.scan_modes.is_empty() => {
                self.answer_conf(payload)
            }
            command::SET_MOTOR_PWM if payload.len() >= 2 => {
                lock(&self.shared.log).motor_pwm =
                    Some(u16::from_le_bytes([payload[0], payload[1]]));
            }
            command::HQ_MOTOR_SPEED if payload.len() >= 2 => {
                lock(&self.shared.log).motor_rpm =
                    Some(u16::from_le_bytes([payload[0], payload[1]]));
            }
            command::GET_ACC_BOARD_FLAG => {
                let flag = u32::from(self.config.accessory_board_motor);
                self.answer(answer::ACC_BOARD_FLAG, &flag.to_le_bytes());
            }
            _ => {}
        }
    }

    fn us_per_sample(&self) -> f32 {
        1e6 / (self.config.samples_per_rotation as f32 * self.config.rotation_hz)
    }

    fn answer_conf(&mut self, payload: &[u8]) {
        if payload.len() < 4 {
            return;
        }
        let entry = u32::from_le_bytes([payload[0], payload[1], payload[2], payload[3]]);
        let mode = payload.get(4..6).map(|m| u16::from_le_bytes([m[0], m[1]]));
        let modes = &self.config.scan_modes;
        let selected = mode.and_then(|m| modes.get(usize::from(m)));
        let value: Vec<u8> = match (entry, selected) {
            (conf::DESIRED_ROT_FREQ, _) => {
                let rpm = (self.config.rotation_hz * 60.0).round() as u16;
                let mut v = rpm.to_le_bytes().to_vec();
                v.extend_from_slice(&DEFAULT_MOTOR_PWM.to_le_bytes());
                v
            }
            (conf::SCAN_MODE_COUNT, _) => (modes.len() as u16).to_le_bytes().to_vec(),
            (conf::SCAN_MODE_TYPICAL, _) => self.config.typical_mode.to_le_bytes().to_vec(),
            (conf::SCAN_MODE_US_PER_SAMPLE, Some(_)) => ((self.us_per_sample() * 256.0) as u32)
                .to_le_bytes()
                .to_vec(),
            (conf::SCAN_MODE_MAX_DISTANCE, Some(_)) => (12u32 * 256).to_le_bytes().to_vec(),
            (conf::SCAN_MODE_ANS_TYPE, Some(m)) => vec![m.answer_type],
            (conf::SCAN_MODE_NAME, Some(m)) => {
                let mut v = m.name.as_bytes().to_vec();
                v.push(0);
                v
            }
            _ => return,
        };
        let mut p = entry.to_le_bytes().to_vec();
        p.extend_from_slice(&value);
        self.answer(answer::GET_LIDAR_CONF, &p);
    }

    fn stream_out(&mut self) {
        let now = Instant::now();
        let (stalled, hung, motor_stopped, blinded) = {
            let c = lock(&self.shared.control);
            (
                c.stall_until.is_some_and(|t| now < t),
                c.hung,
                c.motor_stopped,
                c.blinded,
            )
        };
        let n = self.config.samples_per_rotation;
        let rate = f64::from(self.config.rotation_hz) * n as f64;
        let lead = self.config.express_lead_deg;
        let Some(stream) = self.stream.as_mut() else {
            return;
        };
        let due = n as u64 / 3 + (now.duration_since(stream.started).as_secs_f64() * rate) as u64;
        if stalled || hung {
            stream.next_sample = due.max(stream.next_sample);
            stream.group.clear();
            return;
        }
        let angle = |j: u64| {
            if motor_stopped {
                90.0
            } else {
                (j % n as u64) as f32 * 360.0 / n as f32
            }
        };
        let fault_sample = (self.config.fault_angle_deg.rem_euclid(360.0) / 360.0 * n as f32)
            .round() as u64
            % n as u64;
        // Samples since the one at the fault angle, within a rotation.
        let past_fault = |j: u64| (j + n as u64 - fault_sample) % n as u64;
        let mut out = Vec::new();
        // Where the packet holding the sample at the fault angle starts in `out`: faults go
        // there, a place that does not depend on when the fake runs.
        let mut fault_packet = None;
        let mut served = 0;
        while stream.next_sample < due {
            let j = stream.next_sample;
            let rotation = j / n as u64;
            if stream.ranges.as_ref().is_none_or(|(r, _)| *r != rotation) {
                let mut ranges = self.source.rotation(rotation, n);
                ranges.resize(n, 0.0);
                stream.ranges = Some((rotation, ranges));
                served += 1;
            }
            let range = stream
                .ranges
                .as_ref()
                .map_or(0.0, |(_, r)| r[(j % n as u64) as usize]);
            let dist_mm = if !blinded && range.is_finite() && range > 0.0 {
                range * 1000.0
            } else {
                0.0
            };
            match stream.mode {
                FakeMode::Standard => {
                    let quality = if dist_mm > 0.0 { 47 << 2 } else { 0 };
                    if past_fault(j) == 0 {
                        fault_packet.get_or_insert(out.len());
                    }
                    out.extend_from_slice(&encode::standard_node(
                        angle(j),
                        dist_mm,
                        quality,
                        j % n as u64 == 0,
                    ));
                }
                FakeMode::Express | FakeMode::Dense => {
                    stream.group.push((angle(j), dist_mm));
                    let size = if stream.mode == FakeMode::Express {
                        32
                    } else {
                        40
                    };
                    if stream.group.len() == size {
                        let first = angle(j + 1 - size as u64);
                        let capsule = if stream.mode == FakeMode::Express {
                            encode::express_capsule(
                                first,
                                angle(j + 1),
                                lead,
                                &stream.group,
                                stream.first_capsule,
                            )
                        } else {
                            let d: Vec<u16> = stream
                                .group
                                .iter()
                                .map(|(_, d)| d.round().min(65535.0) as u16)
                                .collect();
                            encode::dense_capsule(first, &d, stream.first_capsule)
                        };
                        // Samples j + 1 - size ..= j hold the one at the fault angle.
                        if past_fault(j) < size as u64 {
                            fault_packet.get_or_insert(out.len());
                        }
                        out.extend_from_slice(&capsule);
                        stream.first_capsule = false;
                        stream.group.clear();
                    }
                }
            }
            stream.next_sample += 1;
        }
        if served > 0 {
            lock(&self.shared.log).rotations_served += served;
        }
        if out.is_empty() {
            return;
        }
        if let Some(at) = fault_packet {
            let mut c = lock(&self.shared.control);
            let dropped = c.drop_bytes.min(out.len() - at);
            c.drop_bytes -= dropped;
            out.drain(at..at + dropped);
            if !c.garbage.is_empty() {
                let at = out.len().min(at + 3);
                let garbage = std::mem::take(&mut c.garbage);
                out.splice(at..at, garbage);
            }
        }
        self.write(&out);
    }
}

/// Takes the next well-formed request from the buffer: (command, payload).
fn take_request(rx: &mut Vec<u8>) -> Option<(u8, Vec<u8>)> {
    loop {
        let start = rx.iter().position(|b| *b == REQUEST_SYNC)?;
        rx.drain(..start);
        let cmd = *rx.get(1)?;
        if cmd & command::HAS_PAYLOAD == 0 {
            rx.drain(..2);
            return Some((cmd, Vec::new()));
        }
        let size = usize::from(*rx.get(2)?);
        let total = 3 + size + 1;
        if rx.len() < total {
            return None;
        }
        if xor(&rx[..total]) == 0 {
            let payload = rx[3..3 + size].to_vec();
            rx.drain(..total);
            return Some((cmd, payload));
        }
        rx.drain(..1); // bad checksum: not a request start
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Request;

    #[test]
    fn requests_are_parsed_back() {
        let mut rx = vec![0x00, 0x13];
        rx.extend(Request::GetInfo.encode());
        rx.extend(
            Request::ExpressScan {
                working_mode: 2,
                working_flags: 0,
                param: 0,
            }
            .encode(),
        );
        rx.extend(Request::Stop.encode());
        assert_eq!(take_request(&mut rx), Some((command::GET_INFO, vec![])));
        assert_eq!(
            take_request(&mut rx),
            Some((command::EXPRESS_SCAN, vec![2, 0, 0, 0, 0]))
        );
        assert_eq!(take_request(&mut rx), Some((command::STOP, vec![])));
        assert_eq!(take_request(&mut rx), None);
    }

    #[test]
    fn room_ranges_are_walls_pillar_and_window() {
        let room = SyntheticRoom::default();
        // Device 0 deg looks along +x: the wall at x = 5 from x = 1.5.
        assert!((room.range_at(0.0) - 3.5).abs() < 1e-5);
        // Device 90 deg clockwise looks along -y: the wall at y = 0 from y = 1.2.
        assert!((room.range_at(90.0) - 1.2).abs() < 1e-5);
        assert!(room.range_at(205.0).is_infinite());
        // Towards the pillar centre (2.0, 1.6 away): hits its near side.
        let to_pillar = -(1.6f32).atan2(2.0).to_degrees();
        let expected = (2.0f32.hypot(1.6)) - 0.3;
        assert!((room.range_at(to_pillar) - expected).abs() < 1e-4);
    }
}
