//! Arbitrary bytes opened as a bare `.mcap` by the bag reader (the in-memory path of the same
//! streaming code that reads files): opening, listing topics and streaming every message must
//! return data or an error, never panic, hang or allocate without bound.
#![no_main]

use libfuzzer_sys::fuzz_target;
use lidar_har_bag::BagReader;

fuzz_target!(|data: &[u8]| {
    let Ok(reader) = BagReader::from_mcap_bytes(data.to_vec()) else {
        return;
    };
    let _ = reader.metadata();
    for topic in reader.topics() {
        let _ = topic.offered_qos.iter().map(|q| q.describe()).count();
    }
    let Ok(messages) = reader.messages() else {
        return;
    };
    for message in messages {
        if message.is_err() {
            break;
        }
    }
});
