//! `builtin_interfaces`: time stamps and durations.

use serde::{Deserialize, Serialize};

use crate::ros_message;

const NANOS_PER_SEC: i64 = 1_000_000_000;

/// Splits nanoseconds into whole seconds (rounded towards minus infinity) and the
/// non-negative remainder, saturating at the range of a signed 32-bit second count.
fn split_nanos(nanos: i64) -> (i32, u32) {
    let sec = nanos.div_euclid(NANOS_PER_SEC);
    // rem_euclid is in 0..1e9, so it always fits in u32.
    let nanosec = nanos.rem_euclid(NANOS_PER_SEC) as u32;
    match i32::try_from(sec) {
        Ok(sec) => (sec, nanosec),
        Err(_) if sec > 0 => (i32::MAX, (NANOS_PER_SEC - 1) as u32),
        Err(_) => (i32::MIN, 0),
    }
}

/// `builtin_interfaces/msg/Time`: a point in time, `sec` seconds plus `nanosec` (0..1e9)
/// nanoseconds since the epoch of its clock (the Unix epoch, or simulated time).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}
ros_message!(
    Time,
    "builtin_interfaces/msg/Time",
    "int32 sec\nuint32 nanosec\n",
    [],
    "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
);

impl Time {
    /// The time `nanos` nanoseconds after the epoch; negative values give a negative `sec`
    /// and a positive `nanosec` (-1 ns is `sec: -1, nanosec: 999_999_999`). Outside the
    /// range of `sec` (about the years 1901..2038) it saturates instead of wrapping.
    pub fn from_nanos(nanos: i64) -> Self {
        let (sec, nanosec) = split_nanos(nanos);
        Self { sec, nanosec }
    }

    /// Nanoseconds since the epoch (never overflows: `sec` is 32-bit).
    pub fn to_nanos(self) -> i64 {
        i64::from(self.sec) * NANOS_PER_SEC + i64::from(self.nanosec)
    }

    /// Seconds since the epoch as a float (for display and rates, not for exact arithmetic).
    pub fn to_secs_f64(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }
}

/// `builtin_interfaces/msg/Duration`: a signed span of `sec` seconds plus `nanosec`
/// (0..1e9) nanoseconds.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
pub struct Duration {
    pub sec: i32,
    pub nanosec: u32,
}
ros_message!(
    Duration,
    "builtin_interfaces/msg/Duration",
    "int32 sec\nuint32 nanosec\n",
    [],
    "RIHS01_e8d009f659816f758b75334ee1a9ca5b5c0b859843261f14c7f937349599d93b"
);

impl Duration {
    /// A duration of `nanos` nanoseconds; saturates like [`Time::from_nanos`].
    pub fn from_nanos(nanos: i64) -> Self {
        let (sec, nanosec) = split_nanos(nanos);
        Self { sec, nanosec }
    }

    /// The duration in nanoseconds.
    pub fn to_nanos(self) -> i64 {
        i64::from(self.sec) * NANOS_PER_SEC + i64::from(self.nanosec)
    }

    /// The duration in seconds as a float.
    pub fn to_secs_f64(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nanos_round_trip_including_negative_values() {
        for nanos in [
            0,
            1,
            999_999_999,
            1_000_000_000,
            1_700_000_000_123_456_789,
            -1,
            -1_000_000_000,
            -1_500_000_000,
        ] {
            assert_eq!(Time::from_nanos(nanos).to_nanos(), nanos, "{nanos}");
            assert_eq!(Duration::from_nanos(nanos).to_nanos(), nanos, "{nanos}");
        }
        assert_eq!(
            Time::from_nanos(-1),
            Time {
                sec: -1,
                nanosec: 999_999_999
            }
        );
        assert_eq!(
            Time::from_nanos(-1_500_000_000),
            Time {
                sec: -2,
                nanosec: 500_000_000
            }
        );
    }

    #[test]
    fn out_of_range_saturates_without_panic() {
        assert_eq!(
            Time::from_nanos(i64::MAX),
            Time {
                sec: i32::MAX,
                nanosec: 999_999_999
            }
        );
        assert_eq!(
            Time::from_nanos(i64::MIN),
            Time {
                sec: i32::MIN,
                nanosec: 0
            }
        );
        let max = Time {
            sec: i32::MAX,
            nanosec: u32::MAX,
        };
        assert_eq!(
            max.to_nanos(),
            i64::from(i32::MAX) * 1_000_000_000 + i64::from(u32::MAX)
        );
        assert_eq!(
            Time {
                sec: i32::MIN,
                nanosec: 0
            }
            .to_nanos(),
            i64::from(i32::MIN) * 1_000_000_000
        );
    }

    #[test]
    fn times_order_by_seconds_then_nanoseconds() {
        assert!(Time::from_nanos(-1) < Time::from_nanos(0));
        assert!(Time { sec: 1, nanosec: 5 } < Time { sec: 2, nanosec: 0 });
        assert!((Time::from_nanos(1_500_000_000).to_secs_f64() - 1.5).abs() < 1e-12);
    }
}
