//! Declared lengths are not trusted: a sequence or string length of 0xFFFFFFFF in a short
//! payload fails at once without allocating for it, and the memory a hostile payload can make
//! the decoder allocate grows only linearly with the payload. Measured with a counting
//! allocator (one test in this binary, so nothing else allocates meanwhile).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use lidar_har_msgs::diagnostic_msgs::DiagnosticArray;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::visualization_msgs::MarkerArray;
use lidar_har_msgs::{CDR_LE_HEADER, RosMessage, decode};

struct Counting;
static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(now, Ordering::Relaxed);
        // SAFETY: forwards the caller's layout to the system allocator unchanged.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        CURRENT.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: `ptr` was allocated by `alloc` above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Peak bytes allocated (above what was live before) while decoding `bytes` as `M`.
fn peak_while_decoding<M: RosMessage>(bytes: &[u8]) -> (usize, bool) {
    let before = CURRENT.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let ok = decode::<M>(bytes).is_ok();
    (PEAK.load(Ordering::Relaxed) - before, ok)
}

fn payload(body: &[u8]) -> Vec<u8> {
    let mut out = CDR_LE_HEADER.to_vec();
    out.extend_from_slice(body);
    out
}

/// A LaserScan whose header and angles are valid, then `ranges` declared with `count` elements.
fn scan_with_range_count(count: u32, extra: &[u8]) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend_from_slice(&[0; 8]); // stamp
    body.extend_from_slice(&2u32.to_le_bytes());
    body.extend_from_slice(b"a\0\0\0"); // frame_id "a", padded to 4
    body.extend_from_slice(&[0; 7 * 4]); // seven float32
    body.extend_from_slice(&count.to_le_bytes());
    body.extend_from_slice(extra);
    payload(&body)
}

#[test]
fn huge_declared_lengths_fail_fast_and_allocation_stays_linear_in_the_input() {
    // 1. A sequence length of 0xFFFFFFFF with 12 bytes behind it.
    let (peak, ok) = peak_while_decoding::<LaserScan>(&scan_with_range_count(u32::MAX, &[0; 12]));
    eprintln!("LaserScan ranges length 0xFFFFFFFF: peak allocation {peak} bytes");
    assert!(!ok);
    assert!(
        peak < 64 * 1024,
        "allocated {peak} bytes for a 60-byte payload"
    );

    // 2. A string length of 0xFFFFFFFF (the frame_id).
    let mut body = vec![0; 8];
    body.extend_from_slice(&u32::MAX.to_le_bytes());
    body.extend_from_slice(b"abc\0");
    let (peak, ok) = peak_while_decoding::<LaserScan>(&payload(&body));
    eprintln!("LaserScan frame_id length 0xFFFFFFFF: peak allocation {peak} bytes");
    assert!(!ok);
    assert!(peak < 64 * 1024);

    // 3. Nested: 0xFFFFFFFF markers, the first of which is cut short.
    let mut body = u32::MAX.to_le_bytes().to_vec();
    body.extend_from_slice(&[0; 64]);
    let (peak, ok) = peak_while_decoding::<MarkerArray>(&payload(&body));
    eprintln!("MarkerArray with 0xFFFFFFFF markers: peak allocation {peak} bytes");
    assert!(!ok);
    assert!(peak < 64 * 1024);

    // 4. Worst amplification we know: many minimal DiagnosticStatus entries (20 bytes on the
    //    wire, over 100 bytes in memory) in 1 MiB, every one valid until the end is cut.
    let count = (1 << 20) / 20;
    let mut body = vec![0; 8]; // stamp
    body.extend_from_slice(&1u32.to_le_bytes());
    body.extend_from_slice(b"\0\0\0\0"); // frame_id "" (length 1: the terminator), padded
    body.extend_from_slice(&(count as u32 + 1).to_le_bytes());
    for _ in 0..count {
        body.extend_from_slice(&[1, 0, 0, 0]); // level, padding
        for _ in 0..3 {
            // length 0, not even a terminator: cdr-encoding accepts it as ""
            body.extend_from_slice(&0u32.to_le_bytes());
        }
        body.extend_from_slice(&0u32.to_le_bytes()); // no values
    }
    let input = payload(&body);
    let (peak, ok) = peak_while_decoding::<DiagnosticArray>(&input);
    let ratio = peak as f64 / input.len() as f64;
    eprintln!(
        "DiagnosticArray, {} statuses in {} bytes: peak allocation {peak} bytes ({ratio:.1} x the input)",
        count,
        input.len()
    );
    assert!(!ok, "one status more was declared than present");
    assert!(
        ratio < 32.0,
        "allocation grows faster than linearly: {ratio:.1} x"
    );
}
