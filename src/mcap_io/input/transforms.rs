//! Looking up a fixed transform between two frames in a recording's transform channels
//! (`/tf_static`, `/tf`: Foxglove `FrameTransform(s)`, ROS `TFMessage`/`TransformStamped`),
//! following chains of transforms (e.g. colour optical ← colour ← link → depth → depth
//! optical, as camera drivers publish them).
//!
//! Static channels (topics containing `tf_static`) are read first and whole; other
//! transform channels only until the chain is found. Each edge keeps its first transform,
//! which is exact for the fixed links between a camera's sensors. Frame names are compared
//! without a leading `/` (ROS 1 writes `/camera_link`, ROS 2 forbids the slash).

use std::collections::{BTreeMap, VecDeque};

use nalgebra::Isometry3;

use crate::error::Result;

use super::decode::{decode_poses, MessageType};
use super::McapInput;

/// A transform found by [`find_transform`].
#[derive(Debug, Clone, PartialEq)]
pub struct TransformChain {
    /// `target_from_source`.
    pub target_from_source: Isometry3<f64>,
    /// The frames from target to source (both included).
    pub frames: Vec<String>,
    /// The topics whose messages gave the edges, in reading order.
    pub topics: Vec<String>,
}

impl TransformChain {
    /// The chain as text: `a -> b -> c (on /tf_static)`.
    pub fn describe(&self) -> String {
        format!("{} (on {})", self.frames.join(" -> "), self.topics.join(", "))
    }
}

/// The frame name without a leading `/`.
pub fn normalize_frame(frame: &str) -> &str {
    frame.trim_start_matches('/')
}

/// How the search reached a frame: (previous frame, `previous_from_frame`, topic of the edge).
type Step<'a> = (&'a str, Isometry3<f64>, &'a str);

/// Edges `parent -> child` with `parent_from_child`, first sample per edge, and the topic.
#[derive(Default)]
struct TransformGraph {
    edges: BTreeMap<(String, String), (Isometry3<f64>, String)>,
}

impl TransformGraph {
    fn add(&mut self, parent: &str, child: &str, parent_from_child: Isometry3<f64>, topic: &str) -> bool {
        let key = (
            normalize_frame(parent).to_owned(),
            normalize_frame(child).to_owned(),
        );
        if key.0 == key.1 || self.edges.contains_key(&key) {
            return false;
        }
        self.edges.insert(key, (parent_from_child, topic.to_owned()));
        true
    }

    /// Breadth-first search from `target` to `source` over the edges in both directions.
    fn chain(&self, target: &str, source: &str) -> Option<TransformChain> {
        let (target, source) = (normalize_frame(target), normalize_frame(source));
        let mut reached: BTreeMap<&str, Option<Step<'_>>> = BTreeMap::new();
        reached.insert(target, None);
        let mut queue = VecDeque::from([target]);
        while let Some(frame) = queue.pop_front() {
            if frame == source {
                break;
            }
            for ((parent, child), (parent_from_child, topic)) in &self.edges {
                let step = if parent == frame {
                    Some((child.as_str(), *parent_from_child))
                } else if child == frame {
                    Some((parent.as_str(), parent_from_child.inverse()))
                } else {
                    None
                };
                if let Some((next, frame_from_next)) = step {
                    if !reached.contains_key(next) {
                        reached.insert(next, Some((frame, frame_from_next, topic.as_str())));
                        queue.push_back(next);
                    }
                }
            }
        }
        reached.get(source)?;
        let mut frames = vec![source.to_owned()];
        let mut topics: Vec<String> = Vec::new();
        let mut target_from_source = Isometry3::identity();
        let mut at = source;
        while let Some(Some((previous, previous_from_at, topic))) = reached.get(at) {
            target_from_source = previous_from_at * target_from_source;
            frames.push((*previous).to_owned());
            if !topics.iter().any(|t| t == topic) {
                topics.push((*topic).to_owned());
            }
            at = previous;
        }
        frames.reverse();
        topics.reverse();
        Some(TransformChain {
            target_from_source,
            frames,
            topics,
        })
    }
}

/// `target_from_source` from the file's transform channels, or `None` when they hold no
/// chain between the two frames. Also returns every frame seen, for error messages.
///
/// # Errors
/// I/O and MCAP errors, and [`crate::Error::Decode`] for a transform message that does not
/// decode.
pub fn find_transform(
    input: &McapInput,
    target: &str,
    source: &str,
) -> Result<(Option<TransformChain>, Vec<String>)> {
    let mut channels: Vec<_> = input
        .channels()
        .values()
        .filter(|c| {
            c.channel_type.is_some_and(|ct| {
                matches!(
                    ct.message,
                    MessageType::FrameTransform | MessageType::FrameTransforms
                )
            })
        })
        .collect();
    // Static transforms first: they are few and hold the sensor-to-sensor links.
    channels.sort_by_key(|c| (!c.topic.contains("tf_static"), c.id));
    let mut graph = TransformGraph::default();
    let mut found = None;
    for channel in channels {
        let Some(ct) = channel.channel_type else { continue };
        let topic = channel.topic.clone();
        input.for_each_message(Some(std::slice::from_ref(&topic)), None, |m| {
            let mut added = false;
            for sample in decode_poses(ct, &topic, &m.data)? {
                if let Some(child) = &sample.child_frame {
                    added |= graph.add(&sample.parent_frame, child, sample.parent_from_child, &topic);
                }
            }
            if added {
                found = graph.chain(target, source);
            }
            Ok(found.is_none())
        })?;
        if found.is_some() {
            break;
        }
    }
    let mut frames: Vec<String> = graph
        .edges
        .keys()
        .flat_map(|(p, c)| [p.clone(), c.clone()])
        .collect();
    frames.sort();
    frames.dedup();
    Ok((found, frames))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn iso(x: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.01, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        )
    }

    #[test]
    fn chains_compose_through_parents_and_children() {
        // color_optical <- color <- link -> depth -> depth_optical, as RealSense publishes it.
        let link_from_color = iso(0.015, 0.0);
        let color_from_color_optical = iso(0.0, -1.2);
        let link_from_depth = iso(0.0, 0.0);
        let depth_from_depth_optical = iso(0.0, -1.2);
        let mut g = TransformGraph::default();
        assert!(g.add(
            "/camera_link",
            "camera_color_frame",
            link_from_color,
            "/tf_static"
        ));
        assert!(g.add(
            "camera_color_frame",
            "camera_color_optical_frame",
            color_from_color_optical,
            "/tf_static"
        ));
        assert!(g.add("camera_link", "camera_depth_frame", link_from_depth, "/tf_static"));
        assert!(g.add(
            "camera_depth_frame",
            "camera_depth_optical_frame",
            depth_from_depth_optical,
            "/tf"
        ));
        // The first sample of an edge is kept.
        assert!(!g.add("camera_link", "camera_depth_frame", iso(5.0, 0.0), "/tf"));
        let chain = g
            .chain("camera_color_optical_frame", "/camera_depth_optical_frame")
            .unwrap();
        let expected = color_from_color_optical.inverse()
            * link_from_color.inverse()
            * link_from_depth
            * depth_from_depth_optical;
        assert!((chain.target_from_source.to_homogeneous() - expected.to_homogeneous()).norm() < 1e-12);
        assert_eq!(
            chain.frames,
            [
                "camera_color_optical_frame",
                "camera_color_frame",
                "camera_link",
                "camera_depth_frame",
                "camera_depth_optical_frame"
            ]
        );
        assert_eq!(chain.topics, ["/tf_static", "/tf"]);
        // The way back is the inverse.
        let back = g
            .chain("camera_depth_optical_frame", "camera_color_optical_frame")
            .unwrap();
        assert!(
            ((back.target_from_source * chain.target_from_source).to_homogeneous()
                - nalgebra::Matrix4::identity())
            .norm()
                < 1e-12
        );
        assert!(g.chain("camera_color_optical_frame", "imu").is_none());
    }
}
