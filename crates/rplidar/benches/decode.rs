//! Decode throughput (samples per second on one core) for the standard, express and dense
//! formats, the full path to fixed-size scans, and the latency from the bytes that
//! complete a rotation to its `LaserScan`.
//!
//! Run: `cargo bench -p lidar-har-rplidar --bench decode`. Target: at least 100 times the
//! fastest device's sample rate (32 kHz), i.e. 3.2 M samples/s.

use std::hint::black_box;
use std::time::{Duration, Instant};

use lidar_har_rplidar::encode;
use lidar_har_rplidar::{RotationAssembler, ScanFormat, ScanFrame, ScanGeometry, StreamDecoder};

const PER_ROTATION: usize = 720;
const ROTATIONS: usize = 1000;
/// Bytes per read, about what a USB serial adapter hands over at a time.
const CHUNK: usize = 64;

fn range_mm(j: usize) -> f32 {
    500.0 + ((j % PER_ROTATION) * 37 % 8000) as f32
}

fn angle(j: usize) -> f32 {
    (j % PER_ROTATION) as f32 * 360.0 / PER_ROTATION as f32
}

fn stream(format: ScanFormat) -> Vec<u8> {
    let total = PER_ROTATION * ROTATIONS;
    let mut bytes = Vec::new();
    match format {
        ScanFormat::Standard => {
            for j in 0..total {
                bytes.extend_from_slice(&encode::standard_node(
                    angle(j),
                    range_mm(j),
                    188,
                    j % PER_ROTATION == 0,
                ));
            }
        }
        ScanFormat::Express => {
            for c in 0..total / 32 {
                let samples: Vec<(f32, f32)> = (0..32)
                    .map(|k| (angle(c * 32 + k), range_mm(c * 32 + k)))
                    .collect();
                bytes.extend(encode::express_capsule(
                    angle(c * 32),
                    angle(c * 32 + 32),
                    2.0,
                    &samples,
                    c == 0,
                ));
            }
        }
        ScanFormat::Dense => {
            for c in 0..total / 40 {
                let d: Vec<u16> = (0..40).map(|k| range_mm(c * 40 + k) as u16).collect();
                bytes.extend(encode::dense_capsule(angle(c * 40), &d, c == 0));
            }
        }
        ScanFormat::Ultra | ScanFormat::Hq => unreachable!("not benchmarked"),
    }
    bytes
}

/// Best of three runs of `f`, which returns how many samples it produced.
fn best_rate(mut f: impl FnMut() -> u64) -> (f64, u64) {
    let mut best = f64::MAX;
    let mut samples = 0;
    for _ in 0..3 {
        let t = Instant::now();
        samples = f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    (samples as f64 / best, samples)
}

fn decode_only(format: ScanFormat, bytes: &[u8]) -> u64 {
    let mut decoder = StreamDecoder::new(format);
    let mut out = Vec::with_capacity(4096);
    let mut n = 0;
    for chunk in bytes.chunks(CHUNK) {
        out.clear();
        n += decoder.push(chunk, &mut out) as u64;
        black_box(&out);
    }
    n
}

fn to_scans(format: ScanFormat, bytes: &[u8], geometry: &ScanGeometry) -> u64 {
    let mut decoder = StreamDecoder::new(format);
    let mut assembler = RotationAssembler::new();
    let mut samples = Vec::with_capacity(4096);
    let mut rotations = Vec::new();
    let mut n = 0;
    let t0 = Instant::now();
    for chunk in bytes.chunks(CHUNK) {
        samples.clear();
        n += decoder.push(chunk, &mut samples) as u64;
        assembler.push(&samples, t0, &mut rotations);
        for r in rotations.drain(..) {
            black_box(ScanFrame::from_rotation(&r, 0, geometry).to_laser_scan("laser"));
        }
    }
    n
}

/// Time from handing over the chunk that completes a rotation to having its LaserScan.
fn latency(format: ScanFormat, bytes: &[u8], geometry: &ScanGeometry) -> Vec<Duration> {
    let mut decoder = StreamDecoder::new(format);
    let mut assembler = RotationAssembler::new();
    let mut samples = Vec::with_capacity(4096);
    let mut rotations = Vec::new();
    let mut latencies = Vec::new();
    for chunk in bytes.chunks(CHUNK) {
        let t = Instant::now();
        samples.clear();
        decoder.push(chunk, &mut samples);
        assembler.push(&samples, t, &mut rotations);
        if let Some(r) = rotations.pop() {
            black_box(ScanFrame::from_rotation(&r, 0, geometry).to_laser_scan("laser"));
            latencies.push(t.elapsed());
        }
    }
    latencies
}

fn main() {
    let geometry = ScanGeometry {
        beams: 720,
        range_min_m: 0.15,
        range_max_m: 12.0,
    };
    let target = 100.0 * 32_000.0;
    println!(
        "RPLIDAR decode benchmark: {ROTATIONS} rotations x {PER_ROTATION} samples, {CHUNK}-byte reads"
    );
    println!("target: {:.1} M samples/s (100 x 32 kHz)", target / 1e6);
    for format in [ScanFormat::Standard, ScanFormat::Express, ScanFormat::Dense] {
        let bytes = stream(format);
        let (decode_rate, n) = best_rate(|| decode_only(format, &bytes));
        let (scan_rate, _) = best_rate(|| to_scans(format, &bytes, &geometry));
        let mut lat = latency(format, &bytes, &geometry);
        lat.sort();
        let pct = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize].as_secs_f64() * 1e6;
        println!(
            "{format:?}: decode {:.1} M samples/s ({:.0} x 32 kHz, {n} samples); decode+rotation+LaserScan {:.1} M samples/s ({:.0} x 32 kHz)",
            decode_rate / 1e6,
            decode_rate / 32_000.0,
            scan_rate / 1e6,
            scan_rate / 32_000.0,
        );
        println!(
            "{format:?}: latency last chunk -> LaserScan over {} rotations: p50 {:.1} us, p99 {:.1} us, max {:.1} us",
            lat.len(),
            pct(0.5),
            pct(0.99),
            pct(1.0)
        );
    }
    println!(
        "note: a rotation is known complete only when the next rotation's first sample arrives \
         (plus one node of look-ahead in standard mode, one capsule in capsule modes); at 14.4 kHz \
         that is ~0.14 ms (standard) or ~2.2 ms (express) of protocol wait on top of these figures"
    );
}
