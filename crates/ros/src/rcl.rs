//! The rcl backend (feature `r2r`): the same byte-level interface through r2r's untyped
//! publishers and raw subscriptions, so our codec serves both backends. It needs a sourced
//! ROS 2 to build; CI only type-checks it (`--features r2r-doc-only`).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures::{FutureExt, Stream, StreamExt};
use lidar_har_msgs::qos::{Durability, History, QosProfile, Reliability};

use crate::params::ParamValue;
use crate::{
    NodeBackend, OfferedQos, PublisherBackend, RosError, Sample, SubscriberBackend, TopicInfo,
};

fn rcl_err(e: impl std::fmt::Display) -> RosError {
    RosError::Dds(format!("rcl: {e}"))
}

fn qos_profile(qos: &QosProfile) -> r2r::QosProfile {
    let p = r2r::QosProfile::default();
    let p = match qos.reliability {
        Reliability::Reliable => p.reliable(),
        Reliability::BestEffort => p.best_effort(),
    };
    let p = match qos.durability {
        Durability::Volatile => p.volatile(),
        Durability::TransientLocal => p.transient_local(),
    };
    match qos.history {
        History::KeepLast(depth) => {
            p.keep_last(usize::try_from(depth.max(1)).unwrap_or(usize::MAX))
        }
        History::KeepAll => p.keep_all(),
    }
}

pub(crate) struct RclNode {
    node: Arc<Mutex<r2r::Node>>,
}

impl RclNode {
    /// rcl parses `--ros-args` of the process itself (remapping, `-p`, `--params-file`); our
    /// own parsing has already validated them.
    pub(crate) fn new(name: &str, namespace: &str, _args: &[String]) -> Result<Self, RosError> {
        let context = r2r::Context::create().map_err(rcl_err)?;
        let node = r2r::Node::create(context, name, namespace).map_err(rcl_err)?;
        Ok(Self {
            node: Arc::new(Mutex::new(node)),
        })
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, r2r::Node>, RosError> {
        self.node
            .lock()
            .map_err(|_| RosError::Dds("rcl node lock poisoned".into()))
    }
}

impl NodeBackend for RclNode {
    fn publisher(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<Box<dyn PublisherBackend>, RosError> {
        crate::split_type_name(type_name)?;
        let publisher = self
            .lock()?
            .create_publisher_untyped(topic, type_name, qos_profile(qos))
            .map_err(|e| RosError::Topic {
                topic: topic.into(),
                reason: e.to_string(),
            })?;
        Ok(Box::new(RclPublisher {
            topic: topic.to_string(),
            publisher: Mutex::new(publisher),
        }))
    }

    fn subscriber(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<Box<dyn SubscriberBackend>, RosError> {
        crate::split_type_name(type_name)?;
        let stream = self
            .lock()?
            .subscribe_raw(topic, type_name, qos_profile(qos))
            .map_err(|e| RosError::Topic {
                topic: topic.into(),
                reason: e.to_string(),
            })?;
        Ok(Box::new(RclSubscriber {
            stream: Mutex::new(Box::new(stream)),
        }))
    }

    fn wait(&self, timeout: Duration) -> Result<(), RosError> {
        self.lock()?.spin_once(timeout);
        Ok(())
    }

    fn now_ns(&self) -> i64 {
        let Ok(node) = self.lock() else { return 0 };
        let clock = node.get_ros_clock();
        let Ok(mut clock) = clock.lock() else {
            return 0;
        };
        clock
            .get_now()
            .map(|d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
            .unwrap_or(0)
    }

    fn parameter(&self, name: &str) -> Option<ParamValue> {
        let node = self.lock().ok()?;
        let params = node.params.lock().ok()?;
        Some(match params.get(name)?.value.clone() {
            r2r::ParameterValue::Bool(b) => ParamValue::Bool(b),
            r2r::ParameterValue::Integer(i) => ParamValue::Integer(i),
            r2r::ParameterValue::Double(d) => ParamValue::Double(d),
            r2r::ParameterValue::String(s) => ParamValue::String(s),
            r2r::ParameterValue::BoolArray(v) => ParamValue::BoolArray(v),
            r2r::ParameterValue::IntegerArray(v) => ParamValue::IntegerArray(v),
            r2r::ParameterValue::DoubleArray(v) => ParamValue::DoubleArray(v),
            r2r::ParameterValue::StringArray(v) => ParamValue::StringArray(v),
            _ => return None,
        })
    }

    fn topics(&self) -> Vec<TopicInfo> {
        let Ok(node) = self.lock() else {
            return Vec::new();
        };
        node.get_topic_names_and_types()
            .map(|topics| {
                topics
                    .into_iter()
                    .flat_map(|(name, types)| {
                        types.into_iter().map(move |t| TopicInfo {
                            name: name.clone(),
                            type_name: t,
                        })
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    fn publishers_qos(&self, topic: &str) -> Vec<OfferedQos> {
        use r2r::qos::{DurabilityPolicy, ReliabilityPolicy};
        let Ok(node) = self.lock() else {
            return Vec::new();
        };
        node.get_publishers_info_by_topic(topic, false)
            .map(|publishers| {
                publishers
                    .into_iter()
                    .map(|p| OfferedQos {
                        reliability: match p.qos_profile.reliability {
                            ReliabilityPolicy::BestEffort => Reliability::BestEffort,
                            _ => Reliability::Reliable,
                        },
                        durability: match p.qos_profile.durability {
                            DurabilityPolicy::TransientLocal => Durability::TransientLocal,
                            _ => Durability::Volatile,
                        },
                    })
                    .collect()
            })
            .unwrap_or_default()
    }
}

struct RclPublisher {
    topic: String,
    /// r2r's publisher may move between threads but not be shared (`Send`, not `Sync`).
    publisher: Mutex<r2r::PublisherUntyped>,
}

impl RclPublisher {
    fn lock(&self) -> Result<std::sync::MutexGuard<'_, r2r::PublisherUntyped>, RosError> {
        self.publisher
            .lock()
            .map_err(|_| RosError::Dds(format!("rcl publisher lock poisoned ({})", self.topic)))
    }
}

impl PublisherBackend for RclPublisher {
    fn publish(&self, cdr: &[u8]) -> Result<(), RosError> {
        self.lock()?.publish_raw(cdr).map_err(|e| RosError::Topic {
            topic: self.topic.clone(),
            reason: e.to_string(),
        })
    }

    fn subscription_count(&self) -> usize {
        self.lock()
            .ok()
            .and_then(|publisher| publisher.get_inter_process_subscription_count().ok())
            .unwrap_or(0)
    }

    /// r2r 0.9 does not expose `rcl_publisher_wait_for_all_acked` (nor the rcl handle).
    fn wait_for_acknowledgments(&self, _timeout: Duration) -> Result<bool, RosError> {
        Err(RosError::Topic {
            topic: self.topic.clone(),
            reason: "waiting for acknowledgements is not available through r2r".into(),
        })
    }
}

type RawStream = Box<dyn Stream<Item = Vec<u8>> + Unpin + Send>;

struct RclSubscriber {
    stream: Mutex<RawStream>,
}

impl SubscriberBackend for RclSubscriber {
    /// Messages arrive in the stream during `Node::wait` (rcl's spin_once).
    fn try_take(&self) -> Result<Option<Sample>, RosError> {
        let mut stream = self
            .stream
            .lock()
            .map_err(|_| RosError::Dds("rcl stream lock poisoned".into()))?;
        Ok(stream.next().now_or_never().flatten().map(|bytes| Sample {
            bytes,
            source_time_ns: None,
        }))
    }
}
