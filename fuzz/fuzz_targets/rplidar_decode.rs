//! Arbitrary bytes through the RPLIDAR response decoders: every measurement format fed in
//! arbitrary chunks, then rotation assembly and LaserScan conversion, plus the single-answer
//! parsers. Nothing may panic; every sample must be a real angle and distance, and every
//! scan must have the configured beam count.
#![no_main]

use std::time::Instant;

use libfuzzer_sys::fuzz_target;
use lidar_har_rplidar::protocol::{Descriptor, DeviceHealth, DeviceInfo, SampleRate, conf_string, parse_conf_answer};
use lidar_har_rplidar::{RotationAssembler, ScanFormat, ScanFrame, ScanGeometry, StreamDecoder};

const FORMATS: [ScanFormat; 5] =
    [ScanFormat::Standard, ScanFormat::Express, ScanFormat::Ultra, ScanFormat::Dense, ScanFormat::Hq];

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    // The selector's low three bits choose the format (so a seed keeps its format whatever
    // its read size), its high bits the read size, as a serial port hands bytes over.
    let format = FORMATS[usize::from(selector & 7) % FORMATS.len()];
    let chunk = 1 + usize::from(selector >> 3) * 7;
    let geometry = ScanGeometry { beams: 360, range_min_m: 0.0, range_max_m: 1.0e6 };
    let mut decoder = StreamDecoder::new(format);
    let mut assembler = RotationAssembler::new();
    let mut samples = Vec::new();
    let mut rotations = Vec::new();
    let t0 = Instant::now();
    let mut produced = 0u64;
    for piece in rest.chunks(chunk) {
        samples.clear();
        produced += decoder.push(piece, &mut samples) as u64;
        for s in &samples {
            assert!((0.0..360.0).contains(&s.angle_deg), "angle {}", s.angle_deg);
            assert!(s.distance_mm.is_finite() && s.distance_mm >= 0.0, "distance {}", s.distance_mm);
        }
        assembler.push(&samples, t0, &mut rotations);
    }
    let stats = decoder.stats();
    assert_eq!(stats.samples, produced);
    assert!(stats.skipped_bytes <= rest.len() as u64);
    for r in &rotations {
        let scan = ScanFrame::from_rotation(r, 0, &geometry);
        assert_eq!(scan.ranges.len(), 360);
        assert_eq!(scan.intensities.len(), 360);
    }

    let _ = Descriptor::parse(rest.get(..7).unwrap_or(rest));
    let _ = DeviceInfo::parse(rest);
    let _ = DeviceHealth::parse(rest);
    let _ = SampleRate::parse(rest);
    if let Ok(value) = parse_conf_answer(rest, 0x7F) {
        let _ = conf_string(value);
    }
});
