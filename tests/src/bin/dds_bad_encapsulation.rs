//! A DDS writer whose samples carry an encapsulation id that is not plain CDR (XCDR2's, as
//! RustDDS writes it: `00 11`), what a misbehaving or differently configured peer can put on
//! the network; lidar_har's transport only ever writes plain CDR. For the test that a node
//! skips such samples (tests/ros_nodes.rs). Run it only inside a private network namespace,
//! as that test does.
//!
//! Usage: `dds_bad_encapsulation DDS_TOPIC DDS_TYPE COUNT` (`rt/tf`
//! `tf2_msgs::msg::dds_::TFMessage_` 3): reliable, keep last 10, on `ROS_DOMAIN_ID` (0). It
//! waits up to 20 s for a reader to match, writes COUNT samples, waits up to 10 s for them
//! to be acknowledged, and exits 0 only if they were.

use std::time::{Duration, Instant};

use ros2_client::dds::rustdds;
use rustdds::no_key::SerializerAdapter;
use rustdds::{
    DataWriterStatus, DomainParticipantBuilder, QosPolicyBuilder, RepresentationIdentifier,
    StatusEvented, TopicKind, policy,
};

/// Bytes as they are, under an encapsulation other than plain CDR.
struct NotCdr;

impl SerializerAdapter<Vec<u8>> for NotCdr {
    type Error = std::io::Error;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR2_LE
    }

    fn to_bytes(value: &Vec<u8>) -> Result<rustdds::bytes::Bytes, Self::Error> {
        Ok(rustdds::bytes::Bytes::copy_from_slice(value))
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [topic, type_name, count] = args.as_slice() else {
        return Err("usage: dds_bad_encapsulation DDS_TOPIC DDS_TYPE COUNT".into());
    };
    let count: usize = count.parse()?;
    let domain = std::env::var("ROS_DOMAIN_ID")
        .ok()
        .filter(|d| !d.is_empty())
        .map_or(Ok(0), |d| d.parse())?;
    let participant = DomainParticipantBuilder::new(domain).build()?;
    let qos = QosPolicyBuilder::new()
        .reliability(policy::Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .history(policy::History::KeepLast { depth: 10 })
        .build();
    let topic =
        participant.create_topic(topic.clone(), type_name.clone(), &qos, TopicKind::NoKey)?;
    let writer = participant
        .create_publisher(&qos)?
        .create_datawriter_no_key::<Vec<u8>, NotCdr>(&topic, None)?;
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut matched = false;
    while !matched {
        if Instant::now() >= deadline {
            return Err("no reader matched within 20 s".into());
        }
        while let Some(status) = writer.try_recv_status() {
            if let DataWriterStatus::PublicationMatched { current, .. } = status {
                matched = current.count() > 0;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    for _ in 0..count {
        writer.write(vec![0; 8], None)?;
    }
    if !writer.wait_for_acknowledgments(Duration::from_secs(10))? {
        return Err("not acknowledged within 10 s".into());
    }
    eprintln!("dds_bad_encapsulation: {count} samples written and acknowledged");
    Ok(())
}
