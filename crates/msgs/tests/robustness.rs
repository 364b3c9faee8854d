//! Bad input gives a clear error naming the type, never a panic: short or truncated payloads,
//! foreign encapsulations, trailing bytes, invalid booleans, invalid and unterminated strings.

mod common;

use common::sample;
use lidar_har_msgs::{CdrError, RosMessage, decode, encode};

/// Every strict prefix of a valid payload fails with an error naming the type.
fn truncations<M: RosMessage>() -> usize {
    let bytes = encode(&sample::<M>()).expect("encodes");
    for len in 0..bytes.len() {
        match decode::<M>(&bytes[..len]) {
            Ok(_) => panic!(
                "{}: a {len}-byte prefix of {} bytes decoded",
                M::TYPE_NAME,
                bytes.len()
            ),
            Err(e) => assert!(e.to_string().contains(M::TYPE_NAME), "{e}"),
        }
    }
    bytes.len()
}

macro_rules! truncate {
    ($ty:ty) => {
        truncations::<$ty>()
    };
}

#[test]
fn every_truncated_payload_is_an_error() {
    let lengths = for_every_type!(truncate);
    assert!(
        lengths.iter().sum::<usize>() > 1000,
        "samples are non-trivial"
    );
}

#[test]
fn payload_shorter_than_the_header() {
    for len in 0..4 {
        let err =
            decode::<lidar_har_msgs::sensor_msgs::LaserScan>(&[0, 1, 0][..len.min(3)]).unwrap_err();
        assert!(matches!(err, CdrError::TooShort { .. }), "{err}");
        assert!(err.to_string().contains("sensor_msgs/msg/LaserScan"));
    }
}

#[test]
fn foreign_encapsulations_are_refused_by_name() {
    let mut bytes = encode(&sample::<lidar_har_msgs::nav_msgs::Odometry>()).unwrap();
    // PL_CDR_LE (RTPS parameter list), XCDR2 little endian, and garbage.
    for header in [
        [0x00, 0x03, 0, 0],
        [0x00, 0x07, 0, 0],
        [0x00, 0x0b, 0, 0],
        [0xff, 0x01, 0, 0],
    ] {
        bytes[..4].copy_from_slice(&header);
        let err = decode::<lidar_har_msgs::nav_msgs::Odometry>(&bytes).unwrap_err();
        assert!(matches!(err, CdrError::Encapsulation { .. }), "{err}");
        assert!(err.to_string().contains("nav_msgs/msg/Odometry"), "{err}");
    }
}

#[test]
fn up_to_three_padding_bytes_are_accepted_more_are_refused() {
    let scan = sample::<lidar_har_msgs::sensor_msgs::LaserScan>();
    let bytes = encode(&scan).unwrap();
    for pad in 1..=3 {
        let mut padded = bytes.clone();
        padded.extend(std::iter::repeat_n(0, pad));
        assert_eq!(
            decode::<lidar_har_msgs::sensor_msgs::LaserScan>(&padded).unwrap(),
            scan
        );
    }
    let mut long = bytes.clone();
    long.extend([0, 0, 0, 0]);
    let err = decode::<lidar_har_msgs::sensor_msgs::LaserScan>(&long).unwrap_err();
    assert!(
        matches!(err, CdrError::TrailingBytes { trailing: 4, .. }),
        "{err}"
    );
    // A Point decoded from a Pose payload: bytes left over reveal the wrong type.
    let pose = encode(&sample::<lidar_har_msgs::geometry_msgs::Pose>()).unwrap();
    let err = decode::<lidar_har_msgs::geometry_msgs::Point>(&pose).unwrap_err();
    assert!(
        matches!(err, CdrError::TrailingBytes { trailing: 32, .. }),
        "{err}"
    );
}

#[test]
fn an_invalid_bool_is_an_error_and_invalid_utf8_is_replaced() {
    use lidar_har_msgs::lidar_har_msgs::HumanObservation;
    let observation = sample::<HumanObservation>();
    let bytes = encode(&observation).unwrap();
    // header: stamp (8) + frame_id "map" (4 + 4) + track_id (4) = offset 20 after the encapsulation.
    let visible_at = 4 + 8 + 8 + 4;
    assert_eq!(bytes[visible_at], 1, "layout assumed by this test");
    let mut bad = bytes.clone();
    bad[visible_at] = 2;
    let err = decode::<HumanObservation>(&bad).unwrap_err();
    assert!(err.to_string().contains("Boolean"), "{err}");
    let mut bad = bytes.clone();
    bad[4 + 8 + 4] = 0xff; // first byte of "map"
    let decoded = decode::<HumanObservation>(&bad).unwrap();
    assert_eq!(decoded.header.frame_id, "\u{FFFD}ap");
    assert_eq!(decoded.track_id, observation.track_id);
}

/// The text of every string in `value`, in order.
fn strings_of(value: &serde_json::Value, found: &mut Vec<String>) {
    match value {
        serde_json::Value::String(text) => found.push(text.clone()),
        serde_json::Value::Array(items) => items.iter().for_each(|v| strings_of(v, found)),
        serde_json::Value::Object(fields) => fields.values().for_each(|v| strings_of(v, found)),
        _ => {}
    }
}

/// Overwrites the NUL terminator of each string of `M`'s sample in turn: every one must be
/// refused. Returns how many strings were checked.
fn unterminated_strings<M: RosMessage>() -> usize {
    let message = sample::<M>();
    let bytes = encode(&message).expect("encodes");
    let mut texts = Vec::new();
    strings_of(&serde_json::to_value(&message).unwrap(), &mut texts);
    // An empty string could not be told apart in the bytes, so values.json gives every
    // string field text.
    assert!(texts.iter().all(|t| !t.is_empty()), "{}", M::TYPE_NAME);
    let distinct: std::collections::BTreeSet<&String> = texts.iter().collect();
    let mut checked = 0;
    for text in distinct {
        let mut encoded = (text.len() as u32 + 1).to_le_bytes().to_vec();
        encoded.extend_from_slice(text.as_bytes());
        encoded.push(0);
        for start in 0..=bytes.len() - encoded.len() {
            if bytes[start..].starts_with(&encoded) {
                let mut bad = bytes.clone();
                bad[start + encoded.len() - 1] = b'!';
                let Err(e) = decode::<M>(&bad) else {
                    panic!("{}: {text:?} without its NUL decoded", M::TYPE_NAME);
                };
                let e = e.to_string();
                assert!(
                    e.contains(M::TYPE_NAME) && e.contains("without its NUL terminator"),
                    "{e}"
                );
                checked += 1;
            }
        }
    }
    assert_eq!(
        checked,
        texts.len(),
        "{}: strings found in the bytes",
        M::TYPE_NAME
    );
    checked
}

macro_rules! unterminate {
    ($ty:ty) => {
        unterminated_strings::<$ty>()
    };
}

#[test]
fn a_string_without_its_nul_terminator_is_refused_in_every_type() {
    // Used to decode, the last byte of the string dropped.
    let checked: usize = for_every_type!(unterminate).iter().sum();
    assert!(checked > 50, "samples hold strings");
}

#[test]
fn non_finite_floats_survive_a_round_trip_bit_exactly() {
    use lidar_har_msgs::geometry_msgs::{Point32, PoseWithCovariance};
    let specials = [
        f64::NAN,
        -f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::from_bits(0x7ff0_0000_0000_0001),
        -0.0,
        f64::MIN_POSITIVE / 2.0,
    ];
    let mut pose = PoseWithCovariance::default();
    for (i, v) in pose.covariance.iter_mut().enumerate() {
        *v = specials[i % specials.len()];
    }
    pose.pose.position.x = f64::NAN;
    let back: PoseWithCovariance = decode(&encode(&pose).unwrap()).unwrap();
    let bits = |p: &PoseWithCovariance| p.covariance.map(f64::to_bits);
    assert_eq!(bits(&back), bits(&pose));
    assert_eq!(
        back.pose.position.x.to_bits(),
        pose.pose.position.x.to_bits()
    );

    let point = Point32 {
        x: f32::from_bits(0xffc0_1234),
        y: f32::NEG_INFINITY,
        z: -0.0,
    };
    let back: Point32 = decode(&encode(&point).unwrap()).unwrap();
    assert_eq!(
        [back.x, back.y, back.z].map(f32::to_bits),
        [point.x, point.y, point.z].map(f32::to_bits)
    );
}

/// A small deterministic generator (xorshift64*), so failures reproduce.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// The fuzz target's property on mutated valid payloads (so `cargo test` covers it without
/// cargo-fuzz): decoding returns, and what decodes re-encodes stably.
fn mutations<M: RosMessage>() -> usize {
    let valid = encode(&sample::<M>()).expect("encodes");
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ valid.len() as u64);
    let mut decoded = 0;
    for _ in 0..300 {
        let mut bytes = valid.clone();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(bytes.len());
            match rng.below(4) {
                0 => bytes[at] ^= 1 << rng.below(8),
                1 => bytes[at] = 0xff,
                2 if at + 4 <= bytes.len() => {
                    bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes())
                }
                _ => bytes.truncate(at.max(4)),
            }
        }
        if let Ok(message) = decode::<M>(&bytes) {
            decoded += 1;
            let again = encode(&message).expect("a decoded message encodes");
            let back: M = decode(&again).expect("our encoding decodes");
            assert_eq!(
                encode(&back).unwrap(),
                again,
                "{}: unstable re-encoding",
                M::TYPE_NAME
            );
        }
    }
    decoded
}

macro_rules! mutate {
    ($ty:ty) => {
        mutations::<$ty>()
    };
}

#[test]
fn mutated_payloads_of_every_type_decode_or_fail_cleanly() {
    let decoded: usize = for_every_type!(mutate).iter().sum();
    // Some mutations only change values (still valid), most break the structure.
    assert!(decoded > 0);
}
