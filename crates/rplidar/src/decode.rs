//! Decoders of the measurement streams: standard nodes, express (capsuled), ultra-capsuled,
//! dense-capsuled and HQ capsules.
//!
//! A [`StreamDecoder`] takes bytes as they arrive, in chunks of any size, and returns
//! samples. It verifies every check bit and checksum; after garbage it scans byte by byte
//! for the next valid packet, discards a bad packet and keeps going.
//!
//! Capsule formats carry a start angle per capsule; the angles of a capsule's samples are
//! spread between its start angle and the *next* capsule's start angle, so the samples of a
//! capsule are only known once the next capsule has arrived. The difference of the two
//! start angles is taken modulo 360 degrees, so a rotation's wrap-around is handled, and a
//! difference that is much larger than usual (a capsule lost in between) spreads the
//! samples over the usual step instead of smearing them over the gap. The usual step is
//! learnt from the stream; when several "gaps" in a row agree with each other, they are the
//! real step and replace it (a falsely accepted packet can seed a wrong one).

use crate::protocol::{answer, hq_crc32};

/// One measurement, in the device's own frame: angles clockwise in degrees, [0, 360).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub angle_deg: f32,
    /// Distance in millimetres; 0 means no return.
    pub distance_mm: f32,
    /// Signal quality on a 0..=255 scale (capsule formats carry none: a valid sample gets a
    /// fixed mid value, a missing one 0).
    pub quality: u8,
    /// The device's start flag: the first sample of a turn (standard and HQ nodes).
    /// Capsules carry none: their nominal start angles wrap up to 8° before the compensated
    /// sample angles do, and a rotation must start where the sample angles wrap.
    pub start_of_rotation: bool,
}

/// How far the angles of neighbouring samples of triangulation devices can step back, or
/// ahead beyond their spacing: each angle carries a distance-dependent compensation (the
/// device's for standard nodes, the capsule's for capsules) of about 8° for far returns and
/// down to about -20° for returns at 5 cm (see [`ultra_compensation_deg`]).
pub(crate) const COMPENSATION_SPREAD_DEG: f32 = 30.0;

/// How far ahead of its predecessor a sample can lie: the compensation spread plus a few
/// lost samples.
pub(crate) const MAX_STEP_AHEAD_DEG: f32 = COMPENSATION_SPREAD_DEG + 15.0;

/// Whether a sample at `next` degrees can follow one at `angle`: a step forward (across 360
/// included) of at most [`MAX_STEP_AHEAD_DEG`], or a step back within the compensation
/// spread, as at the near and far edges of an object.
pub(crate) fn angle_continues(angle: f32, next: f32) -> bool {
    // Both angles lie in [0, 360).
    let delta = if next >= angle {
        next - angle
    } else {
        next - angle + 360.0
    };
    delta <= MAX_STEP_AHEAD_DEG || delta >= 360.0 - COMPENSATION_SPREAD_DEG
}

/// Quality reported for valid samples of formats that carry no quality.
pub const CAPSULE_QUALITY: u8 = 188;

/// The measurement stream formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ScanFormat {
    /// 5-byte nodes (`SCAN`, `FORCE_SCAN`).
    Standard,
    /// 84-byte capsules of 32 samples with angle compensation (`EXPRESS_SCAN`, answer 0x82).
    Express,
    /// 132-byte capsules of 96 compressed samples (answer 0x84).
    Ultra,
    /// 84-byte capsules of 40 distances (answer 0x85).
    Dense,
    /// 781-byte capsules of 96 HQ nodes with a timestamp and CRC-32 (answer 0x83).
    Hq,
}

impl ScanFormat {
    /// The format of a measurement answer type, if it is one this crate decodes.
    pub fn from_answer_type(answer_type: u8) -> Option<Self> {
        match answer_type {
            answer::MEASUREMENT => Some(Self::Standard),
            answer::MEASUREMENT_CAPSULED => Some(Self::Express),
            answer::MEASUREMENT_ULTRA_CAPSULED => Some(Self::Ultra),
            answer::MEASUREMENT_DENSE_CAPSULED => Some(Self::Dense),
            answer::MEASUREMENT_HQ => Some(Self::Hq),
            _ => None,
        }
    }

    pub fn answer_type(self) -> u8 {
        match self {
            Self::Standard => answer::MEASUREMENT,
            Self::Express => answer::MEASUREMENT_CAPSULED,
            Self::Ultra => answer::MEASUREMENT_ULTRA_CAPSULED,
            Self::Dense => answer::MEASUREMENT_DENSE_CAPSULED,
            Self::Hq => answer::MEASUREMENT_HQ,
        }
    }

    /// Bytes per packet.
    pub fn packet_len(self) -> usize {
        match self {
            Self::Standard => 5,
            Self::Express | Self::Dense => 84,
            Self::Ultra => 132,
            Self::Hq => HQ_LEN,
        }
    }

    /// Samples per packet.
    pub fn samples_per_packet(self) -> usize {
        match self {
            Self::Standard => 1,
            Self::Express => 32,
            Self::Ultra => 96,
            Self::Dense => 40,
            Self::Hq => 96,
        }
    }

    fn is_capsule(self) -> bool {
        matches!(self, Self::Express | Self::Ultra | Self::Dense)
    }
}

const HQ_LEN: usize = 1 + 8 + 96 * 8 + 4;
const HQ_SYNC: u8 = 0xA5;
const FULL_CIRCLE_Q6: u16 = 360 * 64;

/// Counters of what the decoder saw, for diagnostics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Packets that passed all checks.
    pub packets: u64,
    /// Samples produced.
    pub samples: u64,
    /// Bytes skipped while searching for a packet start.
    pub skipped_bytes: u64,
    /// Candidate packets that had a valid start but a wrong checksum or check bit.
    pub rejected_packets: u64,
    /// Capsules followed by a gap (the capsule after them lost): their samples were spread
    /// over the usual step, or dropped when bytes were skipped before any step was known.
    pub gaps: u64,
}

/// Incremental decoder of one measurement stream (see the module documentation).
#[derive(Debug, Clone)]
pub struct StreamDecoder {
    format: ScanFormat,
    buf: Vec<u8>,
    /// The last valid capsule, waiting for the next start angle.
    prev_capsule: Option<Vec<u8>>,
    /// Usual angle between consecutive capsule starts, to detect lost capsules.
    typical_step_deg: Option<f32>,
    /// The last step taken for a gap and how many gaps in a row agreed with it.
    gap_run: Option<(f32, u32)>,
    /// Angle (q6) of the last standard node taken, which the next one must continue.
    last_node_angle: Option<u16>,
    stats: DecodeStats,
}

/// Gaps in a row of about the same size that replace the usual step: lost capsules give
/// gaps of varying size, a wrong usual step gives the same "gap" every capsule.
const RESEED_AFTER_GAPS: u32 = 3;

/// Valid nodes that must follow a standard node which does not continue the last one taken.
/// After a lost byte, misaligned windows of a node stream pass the check bits far more often
/// than random bytes (the angle's low bits and the distance bytes change slowly) and, with
/// one node of look-ahead, carry arbitrary angles into the scan; a real jump of the angle (a
/// stall, lost data) is followed by a long run of nodes that continue each other.
const RESYNC_CHAIN_NODES: usize = 3;

enum Check {
    /// Not the start of a packet: skip one byte.
    NoSync,
    /// Starts like a packet but fails the checksum or a check bit: skip one byte.
    Corrupt,
    Valid,
    /// Cannot tell yet: wait for more bytes.
    NeedMore,
}

impl StreamDecoder {
    pub fn new(format: ScanFormat) -> Self {
        Self {
            format,
            buf: Vec::with_capacity(4096),
            prev_capsule: None,
            typical_step_deg: None,
            gap_run: None,
            last_node_angle: None,
            stats: DecodeStats::default(),
        }
    }

    pub fn format(&self) -> ScanFormat {
        self.format
    }

    pub fn stats(&self) -> DecodeStats {
        self.stats
    }

    /// Forgets buffered bytes and capsule history (after a restart of the scan).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.prev_capsule = None;
        self.typical_step_deg = None;
        self.gap_run = None;
        self.last_node_angle = None;
    }

    /// Samples of packets already received that [`StreamDecoder::push`] has not returned:
    /// a capsule waiting for the next start angle, nodes waiting for their look-ahead. They
    /// were measured after every sample returned so far, which dating needs to know.
    pub fn held_back_samples(&self) -> usize {
        let waiting_packets = self.buf.len() / self.format.packet_len();
        let waiting_capsule = usize::from(self.prev_capsule.is_some());
        (waiting_packets + waiting_capsule) * self.format.samples_per_packet()
    }

    /// Decodes `bytes` (appended to what is buffered) and appends the samples to `out`.
    /// Returns the number of samples appended.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Sample>) -> usize {
        let before = out.len();
        self.buf.extend_from_slice(bytes);
        let len = self.format.packet_len();
        let mut pos = 0;
        let buf = std::mem::take(&mut self.buf);
        while buf.len() - pos >= len {
            let packet = &buf[pos..pos + len];
            match self.check(packet, &buf[pos + len..]) {
                Check::NeedMore => break,
                Check::NoSync => {
                    self.stats.skipped_bytes += 1;
                    self.lose_sync(out);
                    pos += 1;
                }
                Check::Corrupt => {
                    self.stats.rejected_packets += 1;
                    self.lose_sync(out);
                    pos += 1;
                }
                Check::Valid => {
                    self.stats.packets += 1;
                    self.decode_packet(packet, out);
                    pos += len;
                }
            }
        }
        self.buf = buf;
        self.buf.drain(..pos);
        let produced = out.len() - before;
        self.stats.samples += produced as u64;
        produced
    }

    /// After skipped bytes the capsule before them has no successor: its samples are
    /// spread over the usual angle step instead (dropped if there is none yet).
    fn lose_sync(&mut self, out: &mut Vec<Sample>) {
        if let Some(prev) = self.prev_capsule.take() {
            match self.typical_step_deg {
                Some(step) => self.decode_capsule(&prev, step, None, out),
                None => self.stats.gaps += 1,
            }
        }
    }

    /// Checks the packet `p`; `following` are the bytes after it (the standard format looks
    /// one node ahead).
    fn check(&self, p: &[u8], following: &[u8]) -> Check {
        match self.format {
            ScanFormat::Standard => {
                // Check bits pass for a quarter of random bytes, so a node is only taken
                // when the node after it also passes and continues its angle, and one that
                // does not continue the last node taken only at the head of a longer chain:
                // after garbage or a lost byte this finds the real node boundary again.
                let Some(angle) = standard_angle_q6(p) else {
                    return if (p[0] ^ (p[0] >> 1)) & 1 == 1 {
                        Check::Corrupt
                    } else {
                        Check::NoSync
                    };
                };
                let continues = self
                    .last_node_angle
                    .is_none_or(|last| angle_follows(last, angle));
                let chain = if continues { 1 } else { RESYNC_CHAIN_NODES };
                let Some(chained) = following.get(..5 * chain) else {
                    return Check::NeedMore;
                };
                let mut previous = angle;
                for next in chained.chunks_exact(5) {
                    match standard_angle_q6(next) {
                        Some(next_angle) if angle_follows(previous, next_angle) => {
                            previous = next_angle;
                        }
                        _ => return Check::Corrupt,
                    }
                }
                Check::Valid
            }
            ScanFormat::Express | ScanFormat::Ultra | ScanFormat::Dense => {
                if p[0] >> 4 != 0xA || p[1] >> 4 != 0x5 {
                    return Check::NoSync;
                }
                let expected = (p[0] & 0x0F) | (p[1] << 4);
                let start = u16::from_le_bytes([p[2], p[3]]) & 0x7FFF;
                if crate::protocol::xor(&p[2..]) != expected || start >= FULL_CIRCLE_Q6 {
                    return Check::Corrupt;
                }
                Check::Valid
            }
            ScanFormat::Hq => {
                if p[0] != HQ_SYNC {
                    return Check::NoSync;
                }
                let stored = u32::from_le_bytes([
                    p[HQ_LEN - 4],
                    p[HQ_LEN - 3],
                    p[HQ_LEN - 2],
                    p[HQ_LEN - 1],
                ]);
                if hq_crc32(&p[..HQ_LEN - 4]) != stored {
                    return Check::Corrupt;
                }
                Check::Valid
            }
        }
    }

    fn decode_packet(&mut self, p: &[u8], out: &mut Vec<Sample>) {
        match self.format {
            ScanFormat::Standard => {
                let sample = decode_standard(p);
                self.last_node_angle = standard_angle_q6(p);
                out.push(sample);
            }
            ScanFormat::Hq => decode_hq(p, out),
            capsule => {
                debug_assert!(capsule.is_capsule());
                let word = u16::from_le_bytes([p[2], p[3]]);
                let new_scan = word & 0x8000 != 0;
                if new_scan {
                    // The first capsule of a scan: what came before belongs to no rotation.
                    self.prev_capsule = None;
                }
                if let Some(prev) = self.prev_capsule.take() {
                    self.decode_capsule_pair(&prev, p, out);
                }
                self.prev_capsule = Some(p.to_vec());
            }
        }
    }

    /// Samples of capsule `prev`, whose angles end where capsule `next` starts.
    fn decode_capsule_pair(&mut self, prev: &[u8], next: &[u8], out: &mut Vec<Sample>) {
        let start = f32::from(u16::from_le_bytes([prev[2], prev[3]]) & 0x7FFF) / 64.0;
        let next_start = f32::from(u16::from_le_bytes([next[2], next[3]]) & 0x7FFF) / 64.0;
        let mut step_total = next_start - start;
        if step_total < 0.0 {
            step_total += 360.0;
        }
        if let Some(typical) = self.typical_step_deg
            && step_total > 1.5 * typical + 1.0
        {
            let run = match self.gap_run {
                Some((last, n)) if (step_total - last).abs() <= 0.1 * last + 0.1 => n + 1,
                _ => 1,
            };
            if run < RESEED_AFTER_GAPS {
                // Capsules were lost in between: use the usual step.
                self.gap_run = Some((step_total, run));
                self.stats.gaps += 1;
                self.decode_capsule(prev, typical, None, out);
                return;
            }
            // The same "gap" every capsule: it is the real step, the usual one was wrong.
            self.typical_step_deg = None;
        }
        self.gap_run = None;
        self.typical_step_deg = Some(match self.typical_step_deg {
            Some(t) => 0.8 * t + 0.2 * step_total,
            None => step_total,
        });
        let next_first_cabin = u32::from_le_bytes([next[4], next[5], next[6], next[7]]);
        self.decode_capsule(prev, step_total, Some(next_first_cabin), out);
    }

    /// Samples of capsule `prev` spread over `step_total` degrees from its start angle.
    /// `next_first_cabin` is the first ultra cabin of the next capsule, when known.
    fn decode_capsule(
        &self,
        prev: &[u8],
        step_total: f32,
        next_first_cabin: Option<u32>,
        out: &mut Vec<Sample>,
    ) {
        let start = f32::from(u16::from_le_bytes([prev[2], prev[3]]) & 0x7FFF) / 64.0;
        let n = self.format.samples_per_packet();
        let step = step_total / n as f32;
        let emit = |k: usize, distance_mm: f32, compensation_deg: f32, out: &mut Vec<Sample>| {
            out.push(Sample {
                angle_deg: wrap_degrees(start + step * k as f32 - compensation_deg),
                distance_mm,
                quality: if distance_mm > 0.0 {
                    CAPSULE_QUALITY
                } else {
                    0
                },
                start_of_rotation: false,
            });
        };
        match self.format {
            ScanFormat::Express => {
                for (i, cabin) in prev[4..84].chunks_exact(5).enumerate() {
                    let d1 = u16::from_le_bytes([cabin[0], cabin[1]]);
                    let d2 = u16::from_le_bytes([cabin[2], cabin[3]]);
                    // 6-bit compensation in q3 degrees: 4 bits in the offset byte, 2 in the
                    // low bits of the distance word. Unsigned, as devices send it.
                    let comp1 = ((cabin[4] & 0x0F) as u16 | ((d1 & 3) << 4)) as f32 / 8.0;
                    let comp2 = ((cabin[4] >> 4) as u16 | ((d2 & 3) << 4)) as f32 / 8.0;
                    emit(2 * i, f32::from(d1 >> 2), comp1, out);
                    emit(2 * i + 1, f32::from(d2 >> 2), comp2, out);
                }
            }
            ScanFormat::Dense => {
                for (i, d) in prev[4..84].chunks_exact(2).enumerate() {
                    emit(i, f32::from(u16::from_le_bytes([d[0], d[1]])), 0.0, out);
                }
            }
            ScanFormat::Ultra => {
                let cabin = |p: &[u8], i: usize| {
                    let o = 4 + 4 * i;
                    u32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]])
                };
                for i in 0..32 {
                    let word = cabin(prev, i);
                    let next_word = if i == 31 {
                        next_first_cabin
                    } else {
                        Some(cabin(prev, i + 1))
                    };
                    let distances = ultra_distances(word, next_word);
                    for (j, d) in distances.into_iter().enumerate() {
                        emit(3 * i + j, d as f32, ultra_compensation_deg(d), out);
                    }
                }
            }
            ScanFormat::Standard | ScanFormat::Hq => {}
        }
    }
}

fn wrap_degrees(a: f32) -> f32 {
    let w = a.rem_euclid(360.0);
    // rem_euclid can return exactly 360.0 for tiny negative inputs.
    if w >= 360.0 { 0.0 } else { w }
}

/// The angle of a standard node whose check bits pass, in q6 degrees.
fn standard_angle_q6(p: &[u8]) -> Option<u16> {
    let sync_ok = (p[0] ^ (p[0] >> 1)) & 1 == 1;
    let angle_word = u16::from_le_bytes([p[1], p[2]]);
    (sync_ok && angle_word & 1 == 1 && angle_word >> 1 < FULL_CIRCLE_Q6).then_some(angle_word >> 1)
}

/// [`angle_continues`] in the q6 degrees of standard nodes, without floating point in the
/// byte-by-byte search.
fn angle_follows(angle: u16, next: u16) -> bool {
    const MAX_STEP_Q6: i32 = MAX_STEP_AHEAD_DEG as i32 * 64;
    const MAX_BACK_Q6: i32 = COMPENSATION_SPREAD_DEG as i32 * 64;
    let delta = (i32::from(next) - i32::from(angle)).rem_euclid(i32::from(FULL_CIRCLE_Q6));
    delta <= MAX_STEP_Q6 || delta >= i32::from(FULL_CIRCLE_Q6) - MAX_BACK_Q6
}

fn decode_standard(p: &[u8]) -> Sample {
    let angle_word = u16::from_le_bytes([p[1], p[2]]);
    Sample {
        angle_deg: f32::from(angle_word >> 1) / 64.0,
        distance_mm: f32::from(u16::from_le_bytes([p[3], p[4]])) / 4.0,
        quality: (p[0] >> 2) << 2,
        start_of_rotation: p[0] & 1 == 1,
    }
}

fn decode_hq(p: &[u8], out: &mut Vec<Sample>) {
    for node in p[9..9 + 96 * 8].chunks_exact(8) {
        let angle_q14 = u16::from_le_bytes([node[0], node[1]]);
        let dist_q2 = u32::from_le_bytes([node[2], node[3], node[4], node[5]]);
        out.push(Sample {
            angle_deg: wrap_degrees(f32::from(angle_q14) * 90.0 / 16384.0),
            distance_mm: dist_q2 as f32 / 4.0,
            quality: node[6],
            start_of_rotation: node[7] & 1 == 1,
        });
    }
}

/// Decodes a variable-bit-scale 12-bit distance: returns the distance in mm and the scale
/// level (the shift applied to the predictions that refer to it).
fn var_bit_scale(scaled: u32) -> (u32, u32) {
    // (first scaled value of the segment, distance at that value, shift)
    const SEGMENTS: [(u32, u32, u32); 4] = [
        (3328, 1 << 14, 4),
        (1792, 1 << 12, 3),
        (1280, 1 << 11, 2),
        (512, 1 << 9, 1),
    ];
    for (base, target, shift) in SEGMENTS {
        if scaled >= base {
            return (target + ((scaled - base) << shift), shift);
        }
    }
    (scaled, 0)
}

/// The three distances (mm) of an ultra cabin: a 12-bit major value and two signed 10-bit
/// predictions relative to it (or to the next cabin's major when this one is 0).
/// Without the next cabin, the third distance is unknown (0).
fn ultra_distances(word: u32, next_word: Option<u32>) -> [u32; 3] {
    let (major, scale1) = var_bit_scale(word & 0xFFF);
    let (major_next, scale2) = var_bit_scale(next_word.unwrap_or(0) & 0xFFF);
    let predict1 = ((word << 10) as i32) >> 22;
    let predict2 = (word as i32) >> 22;
    let (base1, scale1) = if major == 0 && major_next != 0 {
        (major_next, scale2)
    } else {
        (major, scale1)
    };
    let predicted = |predict: i32, base: u32, scale: u32| -> u32 {
        // -512 and 511 mark "no return".
        if predict == -512 || predict == 511 {
            return 0;
        }
        let d = i64::from(predict) * (1 << scale) + i64::from(base);
        u32::try_from(d).unwrap_or(0)
    };
    let third = if next_word.is_some() {
        predicted(predict2, major_next, scale2)
    } else {
        0
    };
    [major, predicted(predict1, base1, scale1), third]
}

/// Angle compensation of ultra capsules, from the optical geometry of triangulation
/// devices: about 7.5 to 8 degrees for far returns, falling with distance to 0 at about
/// 17 cm and to about -20 degrees at 5 cm (7.5 again below that).
fn ultra_compensation_deg(distance_mm: u32) -> f32 {
    let dist_q2 = distance_mm.saturating_mul(4);
    let offset_rad_q16: i64 = if dist_q2 >= 50 * 4 {
        let k2 = i64::from(98_361 / dist_q2);
        (8.0f64.to_radians() * 65536.0) as i64 - (k2 << 6) - (k2 * k2 * k2) / 98_304
    } else {
        (7.5f64.to_radians() * 65536.0) as i64
    };
    (offset_rad_q16 as f64 / 65536.0).to_degrees() as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encode;

    fn decode_all(format: ScanFormat, bytes: &[u8], chunk: usize) -> (Vec<Sample>, DecodeStats) {
        let mut d = StreamDecoder::new(format);
        let mut out = Vec::new();
        for c in bytes.chunks(chunk.max(1)) {
            d.push(c, &mut out);
        }
        (out, d.stats())
    }

    #[test]
    fn standard_nodes_round_trip_in_any_chunking() {
        let mut bytes = Vec::new();
        let mut expected = Vec::new();
        for k in 0..720 {
            let angle = k as f32 * 0.5;
            let dist = 100.0 + k as f32 * 7.25;
            bytes.extend_from_slice(&encode::standard_node(angle, dist, 47 << 2, k == 0));
            expected.push((angle, dist));
        }
        for chunk in [1, 3, 5, 64, 4096] {
            let (out, stats) = decode_all(ScanFormat::Standard, &bytes, chunk);
            // The last node waits for its successor (the look-ahead check).
            assert_eq!(out.len(), 719, "chunk {chunk}");
            assert_eq!(stats.skipped_bytes, 0);
            for (s, (a, d)) in out.iter().zip(&expected) {
                assert!(
                    (s.angle_deg - a).abs() <= 1.0 / 64.0,
                    "{} vs {a}",
                    s.angle_deg
                );
                assert!((s.distance_mm - d).abs() <= 0.25);
                assert_eq!(s.quality, 188);
            }
            assert!(out[0].start_of_rotation && !out[1].start_of_rotation);
        }
    }

    #[test]
    fn standard_resyncs_after_garbage() {
        let mut bytes = Vec::new();
        for k in 0..100 {
            bytes.extend_from_slice(&encode::standard_node(k as f32, 1000.0, 40, false));
        }
        // Three garbage bytes that fail the check bits, in the middle of the stream.
        bytes.splice(250..250, [0x00, 0xFF, 0x00]);
        let (out, stats) = decode_all(ScanFormat::Standard, &bytes, 7);
        assert!(stats.skipped_bytes >= 1);
        // The node before the garbage has no valid successor and the last one waits.
        assert!(out.len() >= 98, "lost more than one node: {}", out.len());
        assert!(out.iter().all(|s| s.distance_mm == 1000.0));
    }

    #[test]
    fn standard_nodes_keep_the_edges_of_close_objects() {
        // A device compensates each angle for its distance: at the edges of a person at 0.3 m
        // before a wall at 4 m the angle steps 4° back or ahead, and 17° around a return at
        // 8 cm. Every node is valid and must be kept.
        let distance = |k: usize| match k {
            100..140 => 300,
            400 => 80,
            _ => 4000,
        };
        let mut bytes = Vec::new();
        for _ in 0..3 {
            for k in 0..720 {
                let d = distance(k);
                let angle = (k as f32 * 0.5 + 8.0 - ultra_compensation_deg(d)).rem_euclid(360.0);
                bytes.extend_from_slice(&encode::standard_node(angle, d as f32, 188, k == 0));
            }
        }
        let (out, stats) = decode_all(ScanFormat::Standard, &bytes, 64);
        assert_eq!(stats.rejected_packets, 0, "{stats:?}");
        assert_eq!(out.len(), 3 * 720 - 1, "all but the last, which waits");
        assert_eq!(
            out.iter().filter(|s| s.distance_mm == 300.0).count(),
            3 * 40
        );
        assert_eq!(out.iter().filter(|s| s.distance_mm == 80.0).count(), 3);
    }

    fn express_stream(
        samples_per_rotation: usize,
        rotations: usize,
        lead_deg: f32,
    ) -> (Vec<u8>, Vec<(f32, f32)>) {
        let total = samples_per_rotation * rotations;
        let angle =
            |j: usize| (j % samples_per_rotation) as f32 * 360.0 / samples_per_rotation as f32;
        let dist = |j: usize| 300.0 + (((j % samples_per_rotation) * 37) % 5000) as f32;
        let mut bytes = Vec::new();
        let mut truth = Vec::new();
        let capsules = total / 32;
        for c in 0..capsules {
            let samples: Vec<(f32, f32)> = (0..32)
                .map(|k| (angle(c * 32 + k), dist(c * 32 + k)))
                .collect();
            let next_first = angle((c + 1) * 32);
            bytes.extend_from_slice(&encode::express_capsule(
                angle(c * 32),
                next_first,
                lead_deg,
                &samples,
                c == 0,
            ));
            truth.extend(samples);
        }
        (bytes, truth)
    }

    #[test]
    fn express_angles_follow_the_next_capsule_across_the_wrap() {
        let (bytes, truth) = express_stream(720, 3, 2.0);
        let (out, stats) = decode_all(ScanFormat::Express, &bytes, 13);
        assert_eq!(stats.rejected_packets, 0);
        // The last capsule waits for a successor that never comes.
        assert_eq!(out.len(), truth.len() - 32);
        for (s, (a, d)) in out.iter().zip(&truth) {
            let err = (s.angle_deg - a + 540.0).rem_euclid(360.0) - 180.0;
            assert!(err.abs() <= 0.07, "angle {} vs {a}", s.angle_deg);
            assert!(
                (s.distance_mm - d).abs() < 1.0,
                "dist {} vs {d}",
                s.distance_mm
            );
            assert!(!s.start_of_rotation, "capsules carry no start flag");
        }
    }

    #[test]
    fn express_rotations_start_where_the_compensated_angle_wraps() {
        // Start angles 5° ahead of their samples: the nominal angle wraps when the samples
        // are at 355°. Those samples end the turn (beams measured last), not start the next.
        let (bytes, _) = express_stream(720, 4, 5.0);
        let (samples, _) = decode_all(ScanFormat::Express, &bytes, 84);
        let mut assembler = crate::rotation::RotationAssembler::new();
        let mut rotations = Vec::new();
        assembler.push(&samples, std::time::Instant::now(), &mut rotations);
        assert_eq!(rotations.len(), 2);
        for r in &rotations {
            assert_eq!(r.samples.len(), 720);
            let angles: Vec<f32> = r.samples.iter().map(|s| s.angle_deg).collect();
            assert!(
                angles.windows(2).all(|w| w[0] < w[1]),
                "one turn from 0° to 359.5°: {:?}",
                &angles[..12]
            );
        }
    }

    #[test]
    fn express_resyncs_after_corrupt_capsule_with_bounded_loss() {
        let (mut bytes, truth) = express_stream(720, 2, 2.0);
        bytes[84 * 5 + 40] ^= 0x55; // corrupt capsule 5
        bytes.splice(84 * 10..84 * 10, [0xA5, 0x5A, 0x12]); // garbage before capsule 10
        let (out, stats) = decode_all(ScanFormat::Express, &bytes, 100);
        assert!(stats.rejected_packets >= 1);
        // Only the corrupt capsule 5 and the last one (no successor) lose their samples;
        // the capsules before the faults are spread over the usual step.
        assert_eq!(
            out.len(),
            truth.len() - 2 * 32,
            "{} of {}",
            out.len(),
            truth.len()
        );
        for s in &out {
            let k = (s.angle_deg / 0.5).round() as usize % 720;
            let d = truth[k].1;
            assert!((s.distance_mm - d).abs() < 1.0 || s.distance_mm == 0.0);
        }
    }

    #[test]
    fn express_spreads_over_the_usual_step_across_a_lost_capsule() {
        let (mut bytes, truth) = express_stream(720, 1, 2.0);
        bytes.drain(84 * 6..84 * 7); // a whole capsule vanishes: no checksum can notice
        let (out, stats) = decode_all(ScanFormat::Express, &bytes, 84);
        assert_eq!(stats.gaps, 1);
        assert_eq!(
            out.len(),
            truth.len() - 2 * 32,
            "the lost capsule and the last one"
        );
        for s in &out {
            let k = (s.angle_deg / 0.5).round() as usize % 720;
            let expected = 300.0 + ((k * 37) % 5000) as f32;
            assert!(
                (s.distance_mm - expected).abs() < 1.0,
                "smeared sample at {}",
                s.angle_deg
            );
        }
    }

    #[test]
    fn a_wrong_first_step_is_replaced_and_later_capsules_decode_normally() {
        let (bytes, truth) = express_stream(720, 2, 2.0);
        // Start mid-rotation (capsule 1, no start flag) behind a false capsule that passes
        // the checksum and starts 0.2 degrees before it: the first step learnt is 0.2, not
        // the real 16, so every real step looks like a gap.
        let false_capsule = encode::express_capsule(15.8, 16.0, 2.0, &[(15.8, 1.0); 32], false);
        let mut stream = false_capsule;
        stream.extend_from_slice(&bytes[84..]);
        let (out, stats) = decode_all(ScanFormat::Express, &stream, 84);
        assert_eq!(
            stats.gaps,
            u64::from(RESEED_AFTER_GAPS - 1),
            "gaps until the step is replaced"
        );
        // Out: the false capsule, capsules 1 and 2 (gaps), then from capsule 3 on every
        // capsule decodes to the served samples (all but the last, which waits for a
        // successor).
        let good = &out[3 * 32..];
        assert_eq!(good.len(), truth.len() - 4 * 32);
        for (s, (a, d)) in good.iter().zip(&truth[3 * 32..]) {
            let err = (s.angle_deg - a + 540.0).rem_euclid(360.0) - 180.0;
            assert!(err.abs() <= 0.07, "angle {} vs {a}", s.angle_deg);
            assert!((s.distance_mm - d).abs() < 1.0, "{} vs {d}", s.distance_mm);
        }
    }

    #[test]
    fn dense_capsules_decode() {
        let mut bytes = Vec::new();
        for c in 0..10u16 {
            let d: Vec<u16> = (0..40).map(|k| c * 100 + k).collect();
            bytes.extend_from_slice(&encode::dense_capsule(f32::from(c) * 20.0, &d, c == 0));
        }
        let (out, _) = decode_all(ScanFormat::Dense, &bytes, 31);
        assert_eq!(out.len(), 9 * 40);
        assert!((out[41].angle_deg - (20.0 + 0.5)).abs() < 0.02);
        assert_eq!(out[41].distance_mm, 101.0);
        assert_eq!(out[0].quality, 0, "distance 0 is no return");
    }

    #[test]
    fn ultra_capsules_decode_major_and_predictions() {
        // Blocks of 16 cabins in each scale segment, every distance exactly representable;
        // the last cabin of a block has no second return (its base would be the next block).
        let majors = [400u32, 1000, 3000, 20000];
        let cabins: Vec<[u32; 3]> = (0..64)
            .map(|i| {
                let m = majors[i / 16];
                let unit = 1u32 << [0, 1, 2, 4][i / 16];
                [
                    m,
                    m + 8 * unit,
                    if i % 16 == 15 { 0 } else { m + 20 * unit },
                ]
            })
            .collect();
        let mut bytes = encode::ultra_capsule(0.0, &cabins[..32], cabins[32][0], true);
        bytes.extend_from_slice(&encode::ultra_capsule(
            30.0,
            &cabins[32..],
            cabins[0][0],
            false,
        ));
        bytes.extend_from_slice(&encode::ultra_capsule(
            60.0,
            &cabins[..32],
            cabins[32][0],
            false,
        ));
        let (out, stats) = decode_all(ScanFormat::Ultra, &bytes, 50);
        assert_eq!(stats.rejected_packets, 0);
        assert_eq!(out.len(), 2 * 96);
        for (i, s) in out.iter().enumerate() {
            let expected = cabins[i / 3][i % 3];
            assert_eq!(s.distance_mm, expected as f32, "sample {i}");
        }
        // Compensation of about 7.5..8 degrees is subtracted from the nominal angle.
        let nominal = 30.0 + 4.0 * 30.0 / 96.0;
        let comp = nominal - out[96 + 4].angle_deg;
        assert!((7.0..8.1).contains(&comp), "{comp}");
    }

    #[test]
    fn a_close_ultra_return_just_before_the_zero_mark_does_not_split_the_rotation() {
        // 8 capsules of 96 samples a turn, all at 3 m but for one cabin at 8 cm at nominal
        // 357°: compensated by -9.4° instead of 7.7°, it lands past the zero mark ahead of
        // its neighbours.
        let turns = 4;
        let capsules: Vec<(f32, Vec<[u32; 3]>)> = (0..turns * 8)
            .map(|c| {
                let mut cabins = vec![[3000u32; 3]; 32];
                if c % 8 == 7 {
                    cabins[30] = [80; 3];
                }
                ((c % 8) as f32 * 45.0, cabins)
            })
            .collect();
        let mut bytes = Vec::new();
        for (i, (start, cabins)) in capsules.iter().enumerate() {
            let next_major = capsules.get(i + 1).map_or(3000, |c| c.1[0][0]);
            bytes.extend_from_slice(&encode::ultra_capsule(*start, cabins, next_major, i == 0));
        }
        let (samples, stats) = decode_all(ScanFormat::Ultra, &bytes, 132);
        assert_eq!(stats.rejected_packets, 0);
        let mut assembler = crate::rotation::RotationAssembler::new();
        let mut rotations = Vec::new();
        assembler.push(&samples, std::time::Instant::now(), &mut rotations);
        let sizes: Vec<usize> = rotations.iter().map(|r| r.samples.len()).collect();
        // One rotation a turn (the first starts mid-turn, the last capsule has no successor).
        assert_eq!(sizes.len(), turns - 1, "{sizes:?}");
        assert!(sizes[1..].iter().all(|&n| n == 8 * 96), "{sizes:?}");
    }

    #[test]
    fn hq_capsules_need_a_valid_crc() {
        let nodes: Vec<(f32, f32, u8, bool)> = (0..96)
            .map(|k| (k as f32 * 3.75, 1234.5, 200, k == 0))
            .collect();
        let capsule = encode::hq_capsule(123_456, &nodes);
        let mut bytes = capsule.clone();
        let mut bad = capsule.clone();
        bad[100] ^= 1;
        bytes.extend_from_slice(&bad);
        bytes.extend_from_slice(&capsule);
        let (out, stats) = decode_all(ScanFormat::Hq, &bytes, 200);
        assert_eq!(out.len(), 192);
        assert!(stats.rejected_packets >= 1);
        assert!((out[5].angle_deg - 18.75).abs() < 0.01);
        assert_eq!(out[5].distance_mm, 1234.5);
        assert!(out[0].start_of_rotation && out[96].start_of_rotation);
    }

    #[test]
    fn garbage_never_panics_and_is_counted() {
        let mut state = 0x1234_5678u32;
        let bytes: Vec<u8> = (0..20_000)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                state as u8
            })
            .collect();
        for format in [
            ScanFormat::Standard,
            ScanFormat::Express,
            ScanFormat::Ultra,
            ScanFormat::Dense,
            ScanFormat::Hq,
        ] {
            let (out, stats) = decode_all(format, &bytes, 333);
            assert!(stats.skipped_bytes > 0, "{format:?}");
            for s in out {
                assert!((0.0..360.0).contains(&s.angle_deg) && s.distance_mm >= 0.0);
            }
        }
    }
}
