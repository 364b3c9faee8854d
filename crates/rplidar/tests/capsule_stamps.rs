//! The real driver on a pseudo-terminal against a scripted A1 with firmware 1.20 (legacy
//! express capsules, 4 kHz) that writes each capsule when its last sample is measured: a
//! scan's stamp must be the time of its beam 0, not one capsule (8 ms) later.

use std::io::{Read, Write};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lidar_har_rplidar::protocol::{
    Descriptor, DeviceInfo, REQUEST_SYNC, SendMode, answer, command,
};
use lidar_har_rplidar::{Config, Driver, Event, ScanModeChoice, encode};
use serialport::{SerialPort, TTYPort};

const PER_TURN: usize = 400;
const TURNS: usize = 40;
const INTERVAL: Duration = Duration::from_micros(250);

fn reply(answer_type: u8, mode: SendMode, len: u32, payload: &[u8]) -> Vec<u8> {
    let mut out = Descriptor {
        len,
        mode,
        answer_type,
    }
    .encode()
    .to_vec();
    out.extend_from_slice(payload);
    out
}

/// Answers until `EXPRESS_SCAN`, then streams capsules in real time; records the time of
/// the last sample of every turn (device angle 359.1°, 0.1 ms before beam 0's 359.5°), as
/// its capsule's write makes it.
fn device(mut master: TTYPort, t0: Instant, turn_ends: Arc<Mutex<Vec<Instant>>>) -> TTYPort {
    let info = DeviceInfo {
        model: 0x18,
        firmware_major: 1,
        firmware_minor: 20,
        hardware: 7,
        serial: *b"SCRIPTED-EXPRESS",
    };
    let us = (INTERVAL.as_micros() as u16).to_le_bytes();
    let rate = [us, us].concat();
    master.set_timeout(Duration::from_millis(5)).unwrap();
    let mut rx = Vec::new();
    let mut buf = [0u8; 256];
    let deadline = t0 + Duration::from_secs(30);
    'requests: loop {
        assert!(Instant::now() < deadline, "the driver never started a scan");
        if let Ok(n) = master.read(&mut buf) {
            rx.extend_from_slice(&buf[..n]);
        }
        while let Some(i) = rx.iter().position(|b| *b == REQUEST_SYNC) {
            let Some(&cmd) = rx.get(i + 1) else { break };
            let end = if cmd & command::HAS_PAYLOAD != 0 {
                let Some(&size) = rx.get(i + 2) else { break };
                i + 4 + usize::from(size)
            } else {
                i + 2
            };
            if rx.len() < end {
                break;
            }
            rx.drain(..end);
            let single = SendMode::Single;
            let out = match cmd {
                command::GET_INFO => reply(answer::DEVICE_INFO, single, 20, &info.encode()),
                command::GET_HEALTH => reply(answer::DEVICE_HEALTH, single, 3, &[0, 0, 0]),
                command::GET_SAMPLERATE => reply(answer::SAMPLE_RATE, single, 4, &rate),
                command::EXPRESS_SCAN => {
                    let multiple = SendMode::Multiple;
                    master
                        .write_all(&reply(answer::MEASUREMENT_CAPSULED, multiple, 84, &[]))
                        .unwrap();
                    break 'requests;
                }
                _ => continue,
            };
            master.write_all(&out).unwrap();
        }
    }
    let start = Instant::now();
    let angle = |j: usize| (j % PER_TURN) as f32 * 360.0 / PER_TURN as f32;
    for c in 0..TURNS * PER_TURN / 32 {
        let last = 32 * c + 31;
        let due = start + INTERVAL * last as u32;
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        let group: Vec<(f32, f32)> = (32 * c..=last).map(|j| (angle(j), 2000.0)).collect();
        let capsule = encode::express_capsule(angle(32 * c), angle(last + 1), 2.0, &group, c == 0);
        master.write_all(&capsule).unwrap();
        // Timed from the write, not from the schedule: a busy machine that wakes this thread
        // late delays the capsule, which the driver rightly dates by its arrival.
        let written = Instant::now();
        if let Some(j) = (32 * c..=last).find(|j| j % PER_TURN == PER_TURN - 1) {
            let end = written - INTERVAL * (last - j) as u32;
            turn_ends.lock().unwrap().push(end);
        }
    }
    master
}

#[test]
fn express_scans_are_stamped_at_beam_0_not_one_capsule_later() {
    let (master, slave) = TTYPort::pair().unwrap();
    let t0 = Instant::now();
    let turn_ends = Arc::new(Mutex::new(Vec::new()));
    let device = {
        let turn_ends = Arc::clone(&turn_ends);
        std::thread::spawn(move || device(master, t0, turn_ends))
    };
    let mut config = Config::new(slave.name().unwrap());
    config.scan_mode = ScanModeChoice::Express;
    config.request_timeout = Duration::from_secs(20);
    config.data_timeout = Duration::from_secs(10);
    let clock = Box::new(move || t0.elapsed().as_nanos() as i64);
    let mut driver = Driver::with_clock(config, clock).unwrap();
    let mut stamps = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(40);
    while stamps.len() < TURNS - 4 {
        assert!(Instant::now() < deadline, "{} scans", stamps.len());
        if let Event::Scan(scan) = driver.next_event().unwrap() {
            stamps.push(scan.header.stamp.to_nanos());
        }
    }
    let _master = device.join().unwrap();
    let turn_ends: Vec<i64> = turn_ends
        .lock()
        .unwrap()
        .iter()
        .map(|t| t.duration_since(t0).as_nanos() as i64)
        .collect();
    let mut offsets_ms: Vec<f64> = stamps
        .iter()
        .map(|&stamp| {
            let nearest = turn_ends
                .iter()
                .min_by_key(|end| (stamp - **end).abs())
                .unwrap();
            (stamp - nearest) as f64 / 1e6
        })
        .collect();
    offsets_ms.sort_by(f64::total_cmp);
    eprintln!("stamp - end of turn (ms), sorted: {offsets_ms:?}");
    // Beam 0 lies 0.1 ms after the turn's last sample. A read the machine wakes late stamps
    // late: on a loaded machine most may be, so the test takes one of the promptest turns,
    // which one capsule late (8 ms) would still leave late. Not the promptest itself: when
    // this thread wrote the turn's capsule late but the next one on time, the driver rightly
    // dates the turn by the next, ahead of the late write (-3 ms under a parallel build).
    let promptest = offsets_ms[offsets_ms.len() / 10];
    assert!(
        (-1.0..2.5).contains(&promptest),
        "promptest {promptest:.2} ms"
    );
}
