//! Echoes raw messages between two topics of one type, for measuring the layer against
//! another DDS (`scripts/ros2-measure.sh`): every message taken on `IN` is written, byte for
//! byte, to `OUT`. Prints `ready` once its endpoints exist, and `echoed N` at exit.
//!
//! usage: ros2_echo DOMAIN TYPE IN OUT [SECONDS]

use std::time::{Duration, Instant};

use rovlink_ros2::{Node, Qos};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, domain, ros_type, input, output, rest @ ..] = args.as_slice() else {
        return Err("usage: ros2_echo DOMAIN TYPE IN OUT [SECONDS]".into());
    };
    let seconds: f64 = rest.first().map_or(Ok(60.0), |s| s.parse())?;
    let mut node = Node::join(domain.parse()?)?;
    let qos = Qos {
        history: rovlink_ros2::History::KeepLast(4),
        ..Qos::DEFAULT
    };
    let mut reader = node.subscribe(input, ros_type, qos, 64 << 20)?;
    let writer = node.advertise(output, ros_type, qos)?;
    println!("ready");
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut echoed = 0u64;
    while Instant::now() < end {
        node.wait(Duration::from_millis(20));
        while let Some(m) = reader.take()? {
            writer.write(&m.message)?;
            echoed += 1;
        }
    }
    println!("echoed {echoed}");
    Ok(())
}
