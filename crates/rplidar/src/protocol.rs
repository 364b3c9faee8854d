//! RPLIDAR serial protocol: request packets, response descriptors and the single-answer
//! payloads (device info, health, sample rate, configuration entries).
//!
//! Every request starts with `0xA5` and the command byte. Commands with a payload set bit 7
//! of the command byte and append the payload size, the payload and an XOR checksum of all
//! preceding bytes. Every answer starts with a 7-byte descriptor: `0xA5 0x5A`, a
//! little-endian `u32` holding the payload length (30 bits) and the send mode (2 bits), and
//! the answer type.

use crate::error::{Error, Result};

/// First byte of every request.
pub const REQUEST_SYNC: u8 = 0xA5;
/// The two first bytes of every response descriptor.
pub const RESPONSE_SYNC: [u8; 2] = [0xA5, 0x5A];
/// Length of a response descriptor in bytes.
pub const DESCRIPTOR_LEN: usize = 7;

/// Command bytes (without the payload flag, which [`Request::encode`] adds).
pub mod command {
    pub const STOP: u8 = 0x25;
    pub const RESET: u8 = 0x40;
    pub const SCAN: u8 = 0x20;
    pub const FORCE_SCAN: u8 = 0x21;
    pub const EXPRESS_SCAN: u8 = 0x82;
    pub const GET_INFO: u8 = 0x50;
    pub const GET_HEALTH: u8 = 0x52;
    pub const GET_SAMPLERATE: u8 = 0x59;
    pub const GET_LIDAR_CONF: u8 = 0x84;
    pub const HQ_MOTOR_SPEED: u8 = 0xA8;
    pub const SET_MOTOR_PWM: u8 = 0xF0;
    pub const GET_ACC_BOARD_FLAG: u8 = 0xFF;
    /// Set in the command byte when a payload follows.
    pub const HAS_PAYLOAD: u8 = 0x80;
}

/// Answer types found in the last byte of a response descriptor.
pub mod answer {
    pub const DEVICE_INFO: u8 = 0x04;
    pub const DEVICE_HEALTH: u8 = 0x06;
    pub const SAMPLE_RATE: u8 = 0x15;
    pub const GET_LIDAR_CONF: u8 = 0x20;
    pub const MEASUREMENT: u8 = 0x81;
    pub const MEASUREMENT_CAPSULED: u8 = 0x82;
    pub const MEASUREMENT_HQ: u8 = 0x83;
    pub const MEASUREMENT_ULTRA_CAPSULED: u8 = 0x84;
    pub const MEASUREMENT_DENSE_CAPSULED: u8 = 0x85;
    pub const ACC_BOARD_FLAG: u8 = 0xFF;
}

/// Bit of the `GET_ACC_BOARD_FLAG` answer: the accessory board drives the motor
/// (`SET_MOTOR_PWM` works).
pub const ACC_BOARD_MOTOR_CTRL: u32 = 0x1;

/// Configuration entries readable with `GET_LIDAR_CONF`.
pub mod conf {
    /// The motor speed the device prefers: rpm, then PWM reference (2 bytes each).
    pub const DESIRED_ROT_FREQ: u32 = 0x01;
    pub const SCAN_MODE_COUNT: u32 = 0x70;
    pub const SCAN_MODE_US_PER_SAMPLE: u32 = 0x71;
    pub const SCAN_MODE_MAX_DISTANCE: u32 = 0x74;
    pub const SCAN_MODE_ANS_TYPE: u32 = 0x75;
    pub const SCAN_MODE_TYPICAL: u32 = 0x7C;
    pub const SCAN_MODE_NAME: u32 = 0x7F;
}

/// A request to the device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Request {
    Stop,
    Reset,
    Scan,
    ForceScan,
    /// Start a capsuled scan. `working_mode` is a scan mode id from the configuration
    /// (0 = legacy express on firmware without scan modes).
    ExpressScan {
        working_mode: u8,
        working_flags: u16,
        param: u16,
    },
    GetInfo,
    GetHealth,
    GetSampleRate,
    /// Read a configuration entry; the scan-mode entries take the mode id.
    GetLidarConf {
        entry: u32,
        mode: Option<u16>,
    },
    /// Motor duty cycle (0..=1023) through the A2/A3 accessory board.
    SetMotorPwm(u16),
    /// Motor speed in rpm on the time-of-flight models (S-series).
    SetMotorRpm(u16),
    /// Ask whether the accessory board can control the motor.
    GetAccBoardFlag,
}

impl Request {
    /// The command byte without the payload flag.
    pub fn command(&self) -> u8 {
        match self {
            Request::Stop => command::STOP,
            Request::Reset => command::RESET,
            Request::Scan => command::SCAN,
            Request::ForceScan => command::FORCE_SCAN,
            Request::ExpressScan { .. } => command::EXPRESS_SCAN,
            Request::GetInfo => command::GET_INFO,
            Request::GetHealth => command::GET_HEALTH,
            Request::GetSampleRate => command::GET_SAMPLERATE,
            Request::GetLidarConf { .. } => command::GET_LIDAR_CONF,
            Request::SetMotorPwm(_) => command::SET_MOTOR_PWM,
            Request::SetMotorRpm(_) => command::HQ_MOTOR_SPEED,
            Request::GetAccBoardFlag => command::GET_ACC_BOARD_FLAG,
        }
    }

    fn payload(&self) -> Vec<u8> {
        match *self {
            Request::ExpressScan {
                working_mode,
                working_flags,
                param,
            } => {
                let mut p = vec![working_mode];
                p.extend_from_slice(&working_flags.to_le_bytes());
                p.extend_from_slice(&param.to_le_bytes());
                p
            }
            Request::GetLidarConf { entry, mode } => {
                let mut p = entry.to_le_bytes().to_vec();
                if let Some(mode) = mode {
                    p.extend_from_slice(&mode.to_le_bytes());
                }
                p
            }
            Request::SetMotorPwm(v) | Request::SetMotorRpm(v) => v.to_le_bytes().to_vec(),
            Request::GetAccBoardFlag => vec![0; 4],
            _ => Vec::new(),
        }
    }

    /// The bytes to send: sync, command, and for commands with a payload the size, the
    /// payload and the XOR checksum.
    pub fn encode(&self) -> Vec<u8> {
        let payload = self.payload();
        if payload.is_empty() {
            return vec![REQUEST_SYNC, self.command()];
        }
        // Payloads are at most 6 bytes here, so the size always fits the size byte.
        let mut out = vec![
            REQUEST_SYNC,
            self.command() | command::HAS_PAYLOAD,
            payload.len() as u8,
        ];
        out.extend_from_slice(&payload);
        out.push(xor(&out));
        out
    }
}

/// XOR of all bytes: the checksum of requests and capsules.
pub fn xor(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0, |acc, b| acc ^ b)
}

/// Whether the device sends one answer or keeps sending (scans).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendMode {
    Single,
    Multiple,
    /// Send-mode values 2 and 3 are reserved by the protocol.
    Reserved(u8),
}

/// The 7-byte header of every answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Descriptor {
    /// Payload length in bytes (of one packet, for multiple-answer modes).
    pub len: u32,
    pub mode: SendMode,
    pub answer_type: u8,
}

impl Descriptor {
    /// Parses a descriptor from exactly its 7 bytes.
    pub fn parse(bytes: &[u8]) -> Result<Self> {
        if bytes.len() != DESCRIPTOR_LEN {
            return Err(Error::Protocol(format!(
                "response descriptor needs {DESCRIPTOR_LEN} bytes, got {}",
                bytes.len()
            )));
        }
        if bytes[..2] != RESPONSE_SYNC {
            return Err(Error::Protocol(format!(
                "response descriptor starts with {:02X} {:02X}, expected A5 5A",
                bytes[0], bytes[1]
            )));
        }
        let word = u32::from_le_bytes([bytes[2], bytes[3], bytes[4], bytes[5]]);
        let mode = match (word >> 30) as u8 {
            0 => SendMode::Single,
            1 => SendMode::Multiple,
            other => SendMode::Reserved(other),
        };
        Ok(Self {
            len: word & 0x3FFF_FFFF,
            mode,
            answer_type: bytes[6],
        })
    }

    /// The 7 bytes of this descriptor (used by the fake device and the tests).
    pub fn encode(&self) -> [u8; DESCRIPTOR_LEN] {
        let mode = match self.mode {
            SendMode::Single => 0,
            SendMode::Multiple => 1,
            SendMode::Reserved(m) => u32::from(m & 3),
        };
        let word = (self.len & 0x3FFF_FFFF) | (mode << 30);
        let w = word.to_le_bytes();
        [
            RESPONSE_SYNC[0],
            RESPONSE_SYNC[1],
            w[0],
            w[1],
            w[2],
            w[3],
            self.answer_type,
        ]
    }
}

/// Answer to `GET_INFO`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Model byte: the high nibble is the major model (1 = A1, 2 = A2, 3 = A3, 6 and up:
    /// time-of-flight S-series), the low nibble the sub-model.
    pub model: u8,
    pub firmware_major: u8,
    pub firmware_minor: u8,
    pub hardware: u8,
    pub serial: [u8; 16],
}

impl DeviceInfo {
    pub const LEN: usize = 20;

    pub fn parse(payload: &[u8]) -> Result<Self> {
        if payload.len() < Self::LEN {
            return Err(Error::Protocol(format!(
                "device info needs {} bytes, got {}",
                Self::LEN,
                payload.len()
            )));
        }
        let mut serial = [0; 16];
        serial.copy_from_slice(&payload[4..20]);
        Ok(Self {
            model: payload[0],
            firmware_minor: payload[1],
            firmware_major: payload[2],
            hardware: payload[3],
            serial,
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut out = vec![
            self.model,
            self.firmware_minor,
            self.firmware_major,
            self.hardware,
        ];
        out.extend_from_slice(&self.serial);
        out
    }

    pub fn major_model(&self) -> u8 {
        self.model >> 4
    }

    /// A readable model family for logs and diagnostics.
    pub fn family(&self) -> String {
        match self.major_model() {
            1 => "A1".into(),
            2 => "A2".into(),
            3 => "A3".into(),
            // Slamtec's SDK 2 numbers the C series (C1) from major model 4, the S series
            // from 6.
            m @ (4 | 5) => format!("C-series (major model {m})"),
            m if m >= 6 => format!("S-series (time of flight, major model {m})"),
            m => format!("unknown (major model {m})"),
        }
    }

    /// Time-of-flight models take their motor speed in rpm (`0xA8`), not through DTR or PWM.
    pub fn is_time_of_flight(&self) -> bool {
        self.major_model() >= 6
    }

    /// Whether the firmware knows the legacy `EXPRESS_SCAN` (A-series 1.17 and later). Only
    /// for devices that do not list scan modes: S-series numbering restarts (an S3 reports
    /// 1.02), so the number says nothing there.
    pub fn supports_express(&self) -> bool {
        (self.firmware_major, self.firmware_minor) >= (1, 17)
    }

    /// Whether the firmware number proves that the device cannot list scan modes
    /// (`GET_LIDAR_CONF`): A1/A2/A3 firmware before 1.24, the threshold of Slamtec's SDK 1.
    /// Other models are asked, as SDK 2 asks every device.
    pub fn lacks_scan_modes(&self) -> bool {
        (1..=3).contains(&self.major_model())
            && (self.firmware_major, self.firmware_minor) < (1, 24)
    }

    /// Serial number as the 32 hexadecimal digits Slamtec prints.
    pub fn serial_hex(&self) -> String {
        self.serial.iter().map(|b| format!("{b:02X}")).collect()
    }

    pub fn firmware(&self) -> String {
        format!("{}.{:02}", self.firmware_major, self.firmware_minor)
    }
}

/// Device health status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HealthStatus {
    Good,
    Warning,
    Error,
    Unknown(u8),
}

/// Answer to `GET_HEALTH`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceHealth {
    pub status: HealthStatus,
    pub error_code: u16,
}

impl DeviceHealth {
    pub const LEN: usize = 3;

    pub fn parse(payload: &[u8]) -> Result<Self> {
        if payload.len() < Self::LEN {
            return Err(Error::Protocol(format!(
                "device health needs 3 bytes, got {}",
                payload.len()
            )));
        }
        let status = match payload[0] {
            0 => HealthStatus::Good,
            1 => HealthStatus::Warning,
            2 => HealthStatus::Error,
            other => HealthStatus::Unknown(other),
        };
        Ok(Self {
            status,
            error_code: u16::from_le_bytes([payload[1], payload[2]]),
        })
    }

    pub fn encode(&self) -> Vec<u8> {
        let status = match self.status {
            HealthStatus::Good => 0,
            HealthStatus::Warning => 1,
            HealthStatus::Error => 2,
            HealthStatus::Unknown(v) => v,
        };
        let code = self.error_code.to_le_bytes();
        vec![status, code[0], code[1]]
    }
}

/// Answer to `GET_SAMPLERATE`: microseconds per sample in standard and express scans.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleRate {
    pub standard_us: u16,
    pub express_us: u16,
}

impl SampleRate {
    pub fn parse(payload: &[u8]) -> Result<Self> {
        if payload.len() < 4 {
            return Err(Error::Protocol(format!(
                "sample rate needs 4 bytes, got {}",
                payload.len()
            )));
        }
        Ok(Self {
            standard_us: u16::from_le_bytes([payload[0], payload[1]]),
            express_us: u16::from_le_bytes([payload[2], payload[3]]),
        })
    }
}

/// One scan mode as the configuration describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanModeInfo {
    pub id: u16,
    pub name: String,
    /// Microseconds per sample (the device sends it in q8 fixed point).
    pub us_per_sample: f32,
    /// Maximum distance in metres (q8 on the wire).
    pub max_distance_m: f32,
    /// Answer type of the data stream (0x81 standard, 0x82 express, ...).
    pub answer_type: u8,
}

impl ScanModeInfo {
    /// Samples per second of this mode.
    pub fn sample_rate_hz(&self) -> f32 {
        if self.us_per_sample > 0.0 {
            1e6 / self.us_per_sample
        } else {
            0.0
        }
    }
}

/// Splits a `GET_LIDAR_CONF` answer into its entry type and value, checking the echoed type.
pub fn parse_conf_answer(payload: &[u8], expected_entry: u32) -> Result<&[u8]> {
    if payload.len() < 4 {
        return Err(Error::Protocol(format!(
            "configuration answer needs at least 4 bytes, got {}",
            payload.len()
        )));
    }
    let entry = u32::from_le_bytes([payload[0], payload[1], payload[2], payload[3]]);
    if entry != expected_entry {
        return Err(Error::Protocol(format!(
            "configuration answer is for entry 0x{entry:X}, asked for 0x{expected_entry:X}"
        )));
    }
    Ok(&payload[4..])
}

/// Reads a little-endian unsigned value of 1 to 4 bytes from a configuration value.
pub fn conf_u32(value: &[u8], len: usize, what: &str) -> Result<u32> {
    if value.len() < len {
        return Err(Error::Protocol(format!(
            "configuration value {what} needs {len} bytes, got {}",
            value.len()
        )));
    }
    Ok(value[..len]
        .iter()
        .rev()
        .fold(0u32, |acc, b| (acc << 8) | u32::from(*b)))
}

/// A configuration string: bytes up to the first NUL, lossily decoded.
pub fn conf_string(value: &[u8]) -> String {
    let end = value.iter().position(|b| *b == 0).unwrap_or(value.len());
    String::from_utf8_lossy(&value[..end]).into_owned()
}

/// HQ capsule CRC: reflected CRC-32 (polynomial 0x04C11DB7, initial value all ones, final
/// inversion) over the data followed by `4 - len % 4` zero bytes, as the HQ stream defines.
pub fn hq_crc32(data: &[u8]) -> u32 {
    const TABLE: [u32; 256] = crc_table();
    let mut crc = 0xFFFF_FFFFu32;
    let step = |crc: u32, b: u8| (crc >> 8) ^ TABLE[((crc ^ u32::from(b)) & 0xFF) as usize];
    for &b in data {
        crc = step(crc, b);
    }
    for _ in 0..(4 - data.len() % 4) {
        crc = step(crc, 0);
    }
    crc ^ 0xFFFF_FFFF
}

const fn crc_table() -> [u32; 256] {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut j = 0;
        while j < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            j += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_without_payload_are_two_bytes() {
        assert_eq!(Request::Stop.encode(), vec![0xA5, 0x25]);
        assert_eq!(Request::Reset.encode(), vec![0xA5, 0x40]);
        assert_eq!(Request::Scan.encode(), vec![0xA5, 0x20]);
        assert_eq!(Request::GetHealth.encode(), vec![0xA5, 0x52]);
    }

    #[test]
    fn express_scan_request_carries_size_payload_and_checksum() {
        let bytes = Request::ExpressScan {
            working_mode: 0,
            working_flags: 0,
            param: 0,
        }
        .encode();
        // A5 82 05 00 00 00 00 00 22: the published example of a legacy express request.
        assert_eq!(bytes, vec![0xA5, 0x82, 0x05, 0, 0, 0, 0, 0, 0x22]);
        let pwm = Request::SetMotorPwm(660).encode();
        assert_eq!(pwm[..3], [0xA5, 0xF0, 2]);
        assert_eq!(
            xor(&pwm),
            0,
            "the checksum makes the XOR of the whole packet zero"
        );
    }

    #[test]
    fn conf_request_appends_mode_id() {
        let bytes = Request::GetLidarConf {
            entry: conf::SCAN_MODE_NAME,
            mode: Some(3),
        }
        .encode();
        assert_eq!(bytes[..3], [0xA5, 0x84, 6]);
        assert_eq!(bytes[3..9], [0x7F, 0, 0, 0, 3, 0]);
        assert_eq!(xor(&bytes), 0);
    }

    #[test]
    fn descriptor_round_trip_and_errors() {
        let d = Descriptor {
            len: 84,
            mode: SendMode::Multiple,
            answer_type: answer::MEASUREMENT_CAPSULED,
        };
        let bytes = d.encode();
        assert_eq!(bytes, [0xA5, 0x5A, 0x54, 0, 0, 0x40, 0x82]);
        assert_eq!(Descriptor::parse(&bytes).unwrap(), d);
        assert!(Descriptor::parse(&bytes[..6]).is_err());
        let mut bad = bytes;
        bad[1] = 0x5B;
        let err = Descriptor::parse(&bad).unwrap_err().to_string();
        assert!(err.contains("A5 5B"), "{err}");
    }

    #[test]
    fn info_and_health_parse() {
        let info = DeviceInfo {
            model: 0x18,
            firmware_major: 1,
            firmware_minor: 29,
            hardware: 7,
            serial: [0xAB; 16],
        };
        let parsed = DeviceInfo::parse(&info.encode()).unwrap();
        assert_eq!(parsed, info);
        assert_eq!(parsed.family(), "A1");
        let c1 = DeviceInfo {
            model: 0x41,
            ..info.clone()
        };
        assert_eq!(c1.family(), "C-series (major model 4)");
        assert_eq!(parsed.firmware(), "1.29");
        assert!(parsed.supports_express());
        assert!(!parsed.lacks_scan_modes());
        assert!(DeviceInfo::parse(&[1, 2, 3]).is_err());
        let health = DeviceHealth::parse(&[2, 0x34, 0x12]).unwrap();
        assert_eq!(
            health,
            DeviceHealth {
                status: HealthStatus::Error,
                error_code: 0x1234
            }
        );
        assert!(DeviceHealth::parse(&[0]).is_err());
    }

    #[test]
    fn only_old_a_series_firmware_proves_there_are_no_scan_modes() {
        let info = |model, major, minor| DeviceInfo {
            model,
            firmware_major: major,
            firmware_minor: minor,
            hardware: 0,
            serial: [0; 16],
        };
        assert!(info(0x18, 1, 15).lacks_scan_modes());
        assert!(info(0x28, 1, 23).lacks_scan_modes());
        assert!(!info(0x28, 1, 24).lacks_scan_modes());
        // An S3 reports firmware 1.02 and does list its modes.
        let s3 = info(0x81, 1, 2);
        assert!(!s3.lacks_scan_modes());
        assert!(!s3.supports_express());
        assert!(s3.is_time_of_flight());
    }

    #[test]
    fn conf_answers_check_the_entry() {
        let mut payload = conf::SCAN_MODE_COUNT.to_le_bytes().to_vec();
        payload.extend_from_slice(&[3, 0]);
        let value = parse_conf_answer(&payload, conf::SCAN_MODE_COUNT).unwrap();
        assert_eq!(conf_u32(value, 2, "count").unwrap(), 3);
        assert!(parse_conf_answer(&payload, conf::SCAN_MODE_NAME).is_err());
        assert!(conf_u32(&[1], 4, "us per sample").is_err());
        assert_eq!(conf_string(b"Sensitivity\0\0"), "Sensitivity");
    }

    #[test]
    fn crc_matches_standard_crc32_for_whole_words() {
        // With the zero padding, the HQ CRC differs from plain CRC-32; check the padding
        // rule against a direct bitwise computation.
        fn bitwise(data: &[u8]) -> u32 {
            let mut crc = 0xFFFF_FFFFu32;
            for &b in data {
                crc ^= u32::from(b);
                for _ in 0..8 {
                    crc = if crc & 1 != 0 {
                        (crc >> 1) ^ 0xEDB8_8320
                    } else {
                        crc >> 1
                    };
                }
            }
            !crc
        }
        assert_eq!(hq_crc32(b"123456789"), bitwise(b"123456789\0\0\0"));
        assert_eq!(hq_crc32(b"1234"), bitwise(b"1234\0\0\0\0"));
    }
}
