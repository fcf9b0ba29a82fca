//! `tdma-run --role rov --camera ros2:TOPIC`: the ROV's camera is a ROS 2 image topic, raw
//! (`sensor_msgs/msg/Image`: `rgb8`, `bgr8`, `rgba8`, `bgra8`, `mono8`) or compressed
//! (`sensor_msgs/msg/CompressedImage`: JPEG or PNG, as `image_transport` publishes on
//! `.../compressed`). Each capture takes the newest frame that came; with none new, the last
//! one again (a still camera); before the first, an error (the ROV sends status only and tries
//! again at the next slot). Best-effort reader, keep-last 1: it hears sensor-data and reliable
//! publishers alike, and holds one frame. A frame over [`MAX_FRAME_BYTES`] or of more than
//! [`MAX_DECODED_PIXELS`] pixels is refused, as one that does not decode is.

use rovlink_rcp::camera::{Camera, MAX_DECODED_PIXELS, camera_picture};
use rovlink_ros2::msgs;
use rovlink_ros2::{History, Node, Qos, Reader, Reliability, Ros2Error};

/// The largest image message taken, bytes.
pub const MAX_FRAME_BYTES: usize = 64 << 20;

/// Whether the topic carries raw or compressed frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frames {
    /// `sensor_msgs/msg/Image`.
    Raw,
    /// `sensor_msgs/msg/CompressedImage`.
    Compressed,
}

impl Frames {
    /// `image_transport`'s convention: a topic ending in `/compressed` is compressed.
    pub fn of_topic(topic: &str) -> Frames {
        match topic.ends_with("/compressed") {
            true => Frames::Compressed,
            false => Frames::Raw,
        }
    }
}

/// The camera; see the [module documentation](self).
pub struct Ros2Camera {
    _node: Node,
    reader: Reader,
    frames: Frames,
    last: Option<rovlink_debt::Image>,
}

/// Joins `domain` and subscribes to `topic`.
pub fn ros2_camera(
    topic: &str,
    frames: Frames,
    domain: Option<u16>,
) -> Result<Ros2Camera, Ros2Error> {
    let domain = rovlink_ros2::names::domain_id(domain)?;
    let mut node = Node::join(domain)?;
    let ros_type = match frames {
        Frames::Raw => msgs::IMAGE,
        Frames::Compressed => msgs::COMPRESSED_IMAGE,
    };
    let qos = Qos {
        reliability: Reliability::BestEffort,
        history: History::KeepLast(1),
        ..Qos::DEFAULT
    };
    let reader = node.subscribe(topic, ros_type, qos, MAX_FRAME_BYTES)?;
    Ok(Ros2Camera {
        _node: node,
        reader,
        frames,
        last: None,
    })
}

/// A raw frame as a picture: 8-bit RGB, BGR, RGBA, BGRA or grey.
pub fn raw_picture(img: &msgs::RawImage<'_>) -> Result<rovlink_debt::Image, String> {
    let (channels_in, order): (usize, [usize; 3]) = match img.encoding.as_str() {
        "rgb8" => (3, [0, 1, 2]),
        "bgr8" => (3, [2, 1, 0]),
        "rgba8" => (4, [0, 1, 2]),
        "bgra8" => (4, [2, 1, 0]),
        "mono8" | "8UC1" => (1, [0, 0, 0]),
        other => {
            return Err(format!(
                "Image encoding {other:?} not taken (rgb8, bgr8, rgba8, bgra8, mono8)"
            ));
        }
    };
    let pixels = (img.width as u64).saturating_mul(img.height as u64);
    if pixels == 0 || pixels > MAX_DECODED_PIXELS {
        return Err(format!(
            "Image of {} x {}: expected 1 ..= {MAX_DECODED_PIXELS} pixels",
            img.width, img.height
        ));
    }
    if img.step < img.width.saturating_mul(channels_in) {
        return Err(format!(
            "Image: a row step of {} bytes for {} pixels of {channels_in} bytes",
            img.step, img.width
        ));
    }
    let channels = if channels_in == 1 { 1 } else { 3 };
    let mut data = Vec::with_capacity(img.width * img.height * channels);
    for row in img.data.chunks(img.step).take(img.height) {
        for px in row.chunks(channels_in).take(img.width) {
            if channels == 1 {
                data.push(px[0]);
            } else {
                data.extend(order.iter().map(|&k| px[k]));
            }
        }
    }
    Ok(rovlink_debt::Image {
        width: img.width,
        height: img.height,
        channels,
        data,
    })
}

impl Camera for Ros2Camera {
    fn capture(&mut self) -> Result<rovlink_debt::Image, String> {
        let mut newest = None;
        while let Some(m) = self.reader.take().map_err(|e| e.to_string())? {
            newest = Some(m.message);
        }
        let name = self.reader.topic().to_string();
        if let Some(m) = newest {
            let picture = match self.frames {
                Frames::Raw => {
                    msgs::decode_image(&m, MAX_FRAME_BYTES).and_then(|i| raw_picture(&i))
                }
                Frames::Compressed => msgs::decode_compressed_image(&m, MAX_FRAME_BYTES)
                    .and_then(|(_, bytes)| camera_picture(&name, bytes)),
            };
            match picture {
                Ok(p) => self.last = Some(p),
                Err(e) => return Err(format!("{name}: {e}")),
            }
        }
        self.last.clone().ok_or_else(|| {
            format!(
                "{name}: no frame yet ({} frames over {MAX_FRAME_BYTES} bytes refused)",
                self.reader.too_big()
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_frames_become_pictures_in_rgb_order() {
        let data = [1, 2, 3, 9, 4, 5, 6, 9];
        let img = msgs::RawImage {
            width: 2,
            height: 1,
            encoding: "bgra8".into(),
            step: 8,
            data: &data,
        };
        let p = raw_picture(&img).unwrap();
        assert_eq!(
            (p.channels, p.data.as_slice()),
            (3, &[3u8, 2, 1, 6, 5, 4][..])
        );
        let grey = msgs::RawImage {
            encoding: "mono8".into(),
            step: 4,
            ..img.clone()
        };
        assert_eq!(raw_picture(&grey).unwrap().data, [1, 2]);
        for bad in ["16UC1", "yuv422"] {
            let e = raw_picture(&msgs::RawImage {
                encoding: bad.into(),
                ..img.clone()
            })
            .unwrap_err();
            assert!(e.contains(bad), "{e}");
        }
        let short = msgs::RawImage { step: 2, ..img };
        assert!(raw_picture(&short).is_err());
        assert_eq!(
            Frames::of_topic("/cam/image/compressed"),
            Frames::Compressed
        );
        assert_eq!(Frames::of_topic("/cam/image_raw"), Frames::Raw);
    }
}
