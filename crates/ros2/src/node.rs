//! One participant on a ROS 2 domain: writers and readers of raw CDR messages under ROS 2's
//! wire names, and a wait for the readers' next samples.

use std::time::Duration;

use rustdds::mio1;
use rustdds::no_key::{DataReader, DataWriter};
use rustdds::{DomainParticipant, Publisher, Subscriber, Topic, TopicKind};

use crate::Ros2Error;
use crate::names::{dds_topic, dds_type, topic_name};
use crate::qos::Qos;
use crate::raw::{CDR_LE_HEADER, RawAdapter, RawCdr};

/// A participant on a domain, with one publisher and one subscriber for its topics.
pub struct Node {
    participant: DomainParticipant,
    publisher: Publisher,
    subscriber: Subscriber,
    poll: mio1::Poll,
    events: mio1::Events,
    readers: usize,
}

/// A message taken from a topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Received {
    /// The whole CDR message, encapsulation header first (as a bag stores it).
    pub message: Vec<u8>,
    /// When the writer wrote it, nanoseconds since the epoch, when it said.
    pub source_stamp_ns: Option<i64>,
}

/// A subscription: raw messages of one topic.
pub struct Reader {
    topic: String,
    reader: DataReader<RawCdr, RawAdapter>,
    max_message_bytes: usize,
    too_big: u64,
}

/// A publication: raw messages to one topic.
pub struct Writer {
    topic: String,
    writer: DataWriter<RawCdr, RawAdapter>,
}

fn dds_error(doing: &str, topic: &str, e: impl std::fmt::Display) -> Ros2Error {
    Ros2Error::Dds(format!("{doing} {topic}: {e}"))
}

impl Node {
    /// Joins `domain_id` (see [`crate::names::domain_id`]): a participant that discovers its
    /// peers by multicast where the host allows it and by unicast on loopback (RustDDS also
    /// announces itself to 127.0.0.1).
    pub fn join(domain_id: u16) -> Result<Node, Ros2Error> {
        let participant = DomainParticipant::new(domain_id)
            .map_err(|e| Ros2Error::Dds(format!("joining domain {domain_id}: {e}")))?;
        let default = Qos::DEFAULT.to_dds();
        let publisher = participant
            .create_publisher(&default)
            .map_err(|e| Ros2Error::Dds(format!("creating a publisher: {e}")))?;
        let subscriber = participant
            .create_subscriber(&default)
            .map_err(|e| Ros2Error::Dds(format!("creating a subscriber: {e}")))?;
        let poll = mio1::Poll::new().map_err(|e| Ros2Error::Dds(format!("polling: {e}")))?;
        Ok(Node {
            participant,
            publisher,
            subscriber,
            poll,
            events: mio1::Events::with_capacity(64),
            readers: 0,
        })
    }

    /// The domain joined.
    pub fn domain_id(&self) -> u16 {
        self.participant.domain_id()
    }

    /// Subscribes to `topic` (a ROS 2 name) of `ros_type` (`pkg/msg/Type`) with `qos`. Messages
    /// longer than `max_message_bytes` are dropped and counted ([`Reader::too_big`]).
    pub fn subscribe(
        &mut self,
        topic: &str,
        ros_type: &str,
        qos: Qos,
        max_message_bytes: usize,
    ) -> Result<Reader, Ros2Error> {
        let (name, dds) = self.topic(topic, ros_type, qos)?;
        let mut reader = self
            .subscriber
            .create_datareader_no_key::<RawCdr, RawAdapter>(&dds, Some(qos.to_dds()))
            .map_err(|e| dds_error("subscribing to", &name, e))?;
        self.poll
            .registry()
            .register(
                &mut reader,
                mio1::Token(self.readers),
                mio1::Interest::READABLE,
            )
            .map_err(|e| dds_error("polling", &name, e))?;
        self.readers += 1;
        Ok(Reader {
            topic: name,
            reader,
            max_message_bytes,
            too_big: 0,
        })
    }

    /// The DDS topic of a ROS 2 topic and type, and the topic's ROS 2 name.
    fn topic(&self, topic: &str, ros_type: &str, qos: Qos) -> Result<(String, Topic), Ros2Error> {
        let name = topic_name(topic)?;
        let dds = self
            .participant
            .create_topic(
                dds_topic(topic)?,
                dds_type(ros_type)?,
                &qos.to_dds(),
                TopicKind::NoKey,
            )
            .map_err(|e| dds_error("creating topic", &name, e))?;
        Ok((name, dds))
    }

    /// Advertises `topic` of `ros_type` with `qos`.
    pub fn advertise(&self, topic: &str, ros_type: &str, qos: Qos) -> Result<Writer, Ros2Error> {
        let (name, dds) = self.topic(topic, ros_type, qos)?;
        let writer = self
            .publisher
            .create_datawriter_no_key::<RawCdr, RawAdapter>(&dds, Some(qos.to_dds()))
            .map_err(|e| dds_error("advertising", &name, e))?;
        Ok(Writer {
            topic: name,
            writer,
        })
    }

    /// Waits until a reader of this node may have a sample, or `timeout` passes. Take from
    /// every reader until it has none after each wait: the wake-up is edge-triggered.
    pub fn wait(&mut self, timeout: Duration) {
        // An interrupted or failed poll is a spurious wake-up: the caller takes (finds
        // nothing) and waits again.
        let _ = self.poll.poll(&mut self.events, Some(timeout));
    }
}

impl Reader {
    /// The topic's ROS 2 name.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The next message, if one has come. A sample that cannot be read (an encoding other
    /// than plain CDR) is an error naming the topic; the reader goes on with the next.
    pub fn take(&mut self) -> Result<Option<Received>, Ros2Error> {
        loop {
            let sample = match self.reader.take_next_sample() {
                Ok(Some(s)) => s,
                Ok(None) => return Ok(None),
                Err(e) => return Err(dds_error("reading", &self.topic, e)),
            };
            let source_stamp_ns = sample.sample_info().source_timestamp().map(|t| {
                // RTPS time: seconds and 2^-32 fractions since the epoch.
                let ticks = t.to_ticks();
                let secs = (ticks >> 32) as i64;
                let frac = (ticks & 0xffff_ffff) as i64;
                secs * 1_000_000_000 + ((frac * 1_000_000_000) >> 32)
            });
            let message = sample.into_value().0;
            if message.len() > self.max_message_bytes {
                self.too_big += 1;
                continue;
            }
            return Ok(Some(Received {
                message,
                source_stamp_ns,
            }));
        }
    }

    /// How many messages were dropped for being longer than the bound.
    pub fn too_big(&self) -> u64 {
        self.too_big
    }
}

impl Writer {
    /// The topic's ROS 2 name.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// Writes one whole CDR message (little-endian: header `00 01 00 00`).
    pub fn write(&self, message: &[u8]) -> Result<(), Ros2Error> {
        if message.get(..2) != Some(&CDR_LE_HEADER[..2]) {
            return Err(Ros2Error::Dds(format!(
                "writing {}: expected a little-endian CDR message",
                self.topic
            )));
        }
        self.writer
            .write(RawCdr(message.to_vec()), None)
            .map_err(|e| dds_error("writing", &self.topic, e))
    }
}
