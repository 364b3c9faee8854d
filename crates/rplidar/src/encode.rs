//! Encoders of the measurement formats: what a device sends. Used by the fake device, the
//! tests, the benchmark and the fuzz seeds; the driver itself only decodes.

use crate::protocol::{hq_crc32, xor};

fn q6(angle_deg: f32) -> u16 {
    ((angle_deg.rem_euclid(360.0) * 64.0).round() as u32 % (360 * 64)) as u16
}

/// A 5-byte standard node.
pub fn standard_node(angle_deg: f32, distance_mm: f32, quality: u8, start: bool) -> [u8; 5] {
    let s = u8::from(start);
    let sync_quality = (quality & 0xFC) | ((1 - s) << 1) | s;
    let angle = (q6(angle_deg) << 1) | 1;
    let dist = (distance_mm * 4.0).round().clamp(0.0, 65535.0) as u16;
    let a = angle.to_le_bytes();
    let d = dist.to_le_bytes();
    [sync_quality, a[0], a[1], d[0], d[1]]
}

/// Sync nibbles, checksum and start angle around a capsule body.
fn capsule_frame(start_deg: f32, new_scan: bool, body: &[u8]) -> Vec<u8> {
    let word = q6(start_deg) | (u16::from(new_scan) << 15);
    let mut out = vec![0, 0];
    out.extend_from_slice(&word.to_le_bytes());
    out.extend_from_slice(body);
    let checksum = xor(&out[2..]);
    out[0] = 0xA0 | (checksum & 0x0F);
    out[1] = 0x50 | (checksum >> 4);
    out
}

/// An 84-byte express capsule holding 32 `(angle_deg, distance_mm)` samples.
///
/// The capsule's start angle is `first_angle_deg + lead_deg` and the next capsule's is
/// `next_first_angle_deg + lead_deg` (a device reports the start angle ahead of the samples
/// by its compensation); each sample's compensation is chosen so that the decoded angle is
/// the given angle within the q3 resolution (1/16 degree). `lead_deg` must lie in
/// 0.5..7.5 so that every compensation fits its 6 bits.
pub fn express_capsule(
    first_angle_deg: f32,
    next_first_angle_deg: f32,
    lead_deg: f32,
    samples: &[(f32, f32)],
    new_scan: bool,
) -> Vec<u8> {
    let start = f32::from(q6(first_angle_deg + lead_deg)) / 64.0;
    let next = f32::from(q6(next_first_angle_deg + lead_deg)) / 64.0;
    let step = (next - start).rem_euclid(360.0) / 32.0;
    let field = |k: usize| -> (u16, u8) {
        let (angle, dist) = samples.get(k).copied().unwrap_or((0.0, 0.0));
        let nominal = start + step * k as f32;
        let comp_deg = (nominal - angle + 540.0).rem_euclid(360.0) - 180.0;
        let comp = (comp_deg * 8.0).round().clamp(0.0, 63.0) as u8;
        let d = dist.round().clamp(0.0, 16383.0) as u16;
        ((d << 2) | u16::from(comp >> 4), comp & 0x0F)
    };
    let mut body = Vec::with_capacity(80);
    for cabin in 0..16 {
        let (w1, c1) = field(2 * cabin);
        let (w2, c2) = field(2 * cabin + 1);
        body.extend_from_slice(&w1.to_le_bytes());
        body.extend_from_slice(&w2.to_le_bytes());
        body.push(c1 | (c2 << 4));
    }
    capsule_frame(start, new_scan, &body)
}

/// An 84-byte dense capsule of 40 distances in mm.
pub fn dense_capsule(start_deg: f32, distances_mm: &[u16], new_scan: bool) -> Vec<u8> {
    let mut body = Vec::with_capacity(80);
    for k in 0..40 {
        body.extend_from_slice(&distances_mm.get(k).copied().unwrap_or(0).to_le_bytes());
    }
    capsule_frame(start_deg, new_scan, &body)
}

/// Inverse of the variable bit scale: the 12-bit code and the shift of a distance, or
/// `None` when the distance is not exactly representable.
fn var_bit_scale_encode(distance_mm: u32) -> Option<(u32, u32)> {
    let (code, shift) = match distance_mm {
        d if d < 512 => (d, 0),
        d if d < 2048 => (512 + ((d - 512) >> 1), 1),
        d if d < 4096 => (1280 + ((d - 2048) >> 2), 2),
        d if d < 16384 => (1792 + ((d - 4096) >> 3), 3),
        d => (3328 + ((d - 16384) >> 4), 4),
    };
    (code < 4096).then_some((code, shift))
}

fn ultra_prediction(distance_mm: u32, base_mm: u32, shift: u32) -> u32 {
    let diff = i64::from(distance_mm) - i64::from(base_mm);
    let p = diff >> shift;
    if distance_mm == 0 || p << shift != diff || !(-511..511).contains(&p) {
        return 0x1FF; // "no return"
    }
    (p as u32) & 0x3FF
}

/// A 132-byte ultra capsule of 32 cabins of three distances each. The second prediction of
/// a cabin refers to the next cabin's major distance; `next_major_mm` is that of the next
/// capsule's first cabin. Distances that the compression cannot represent exactly are sent
/// as "no return".
pub fn ultra_capsule(
    start_deg: f32,
    cabins: &[[u32; 3]],
    next_major_mm: u32,
    new_scan: bool,
) -> Vec<u8> {
    let major = |i: usize| cabins.get(i).map_or(next_major_mm, |c| c[0]);
    let mut body = Vec::with_capacity(128);
    for i in 0..32 {
        let c = cabins.get(i).copied().unwrap_or([0; 3]);
        let (code, shift) = var_bit_scale_encode(c[0]).unwrap_or((0, 0));
        let next = major(i + 1);
        let (_, next_shift) = var_bit_scale_encode(next).unwrap_or((0, 0));
        let p1 = ultra_prediction(c[1], c[0], shift);
        let p2 = ultra_prediction(c[2], next, next_shift);
        let word = code | (p1 << 12) | (p2 << 22);
        body.extend_from_slice(&word.to_le_bytes());
    }
    capsule_frame(start_deg, new_scan, &body)
}

/// A 781-byte HQ capsule: sync, timestamp, 96 nodes `(angle_deg, distance_mm, quality,
/// start)` and the CRC.
pub fn hq_capsule(timestamp: u64, nodes: &[(f32, f32, u8, bool)]) -> Vec<u8> {
    let mut out = vec![0xA5];
    out.extend_from_slice(&timestamp.to_le_bytes());
    for k in 0..96 {
        let (angle, dist, quality, start) = nodes.get(k).copied().unwrap_or((0.0, 0.0, 0, false));
        let angle_q14 = ((angle.rem_euclid(360.0) * 16384.0 / 90.0).round() as u32)
            .min(u32::from(u16::MAX)) as u16;
        out.extend_from_slice(&angle_q14.to_le_bytes());
        out.extend_from_slice(&((dist * 4.0).round().max(0.0) as u32).to_le_bytes());
        out.push(quality);
        out.push(u8::from(start));
    }
    let crc = hq_crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}
