//! Synthetic sequences written as recordings with exact ground truth: occmask's own layout
//! (`occmask demo`, tests) and a ROS driver's layout through a two-camera rig.

use super::*;

/// Writes a synthetic sequence ([`crate::synthetic`]) in `convert`'s channel layout: colour as
/// `rgb8` RawImage, depth `16UC1` at [`crate::synthetic::DEPTH_UNITS_PER_M`], calibration per
/// image, ground-truth poses, `/tf` and ground-truth masks, all in log-time order. This is a
/// dataset with exact ground truth for `process` and `eval` (used by `occmask demo`).
///
/// `frame_done(i)` is called after frame `i`; `Break` stops with [`Error::Interrupted`].
///
/// # Errors
/// Writing fails, or `frame_done` asked to stop.
pub fn write_synthetic_sequence<W: Write + Seek>(
    sequence: &crate::synthetic::SyntheticSequence,
    sink: W,
    options: &McapWriteOptions,
    frame_done: &mut dyn FnMut(usize) -> ControlFlow<()>,
) -> Result<W> {
    use crate::synthetic::DEPTH_UNITS_PER_M;
    let mut w = RgbdMcapWriter::new(sink, options)?;
    let mut frame = sequence.frame(0);
    for i in 0..sequence.len() {
        sequence.render_into(i, &mut frame);
        let t = frame.timestamp_ns;
        let size = frame.rgb.size();
        w.write_pose(TOPIC_GROUNDTRUTH_POSE, t, &frame.world_from_camera)?;
        w.write_tf(t, FRAME_WORLD, FRAME_CAMERA_GROUNDTRUTH, &frame.world_from_camera)?;
        w.write_color_raw(TOPIC_COLOR_IMAGE, t, &frame.rgb)?;
        w.write_camera_info(TOPIC_COLOR_CAMERA_INFO, t, &frame.intrinsics, size, None)?;
        w.write_depth_u16(
            TOPIC_DEPTH_IMAGE,
            t,
            frame.depth_raw.as_slice(),
            size,
            f64::from(DEPTH_UNITS_PER_M),
        )?;
        w.write_camera_info(TOPIC_DEPTH_CAMERA_INFO, t, &frame.intrinsics, size, None)?;
        w.write_mask(TOPIC_GROUNDTRUTH_MASK, t, &frame.gt_mask)?;
        if frame_done(i).is_break() {
            return Err(Error::Interrupted {
                done: i + 1,
                total: sequence.len(),
            });
        }
    }
    w.write_metadata(
        "occmask.synthetic",
        BTreeMap::from([
            (
                "scenario".to_owned(),
                sequence.scenario.map_or("custom", |s| s.name()).to_owned(),
            ),
            ("frames".to_owned(), sequence.len().to_string()),
        ]),
    )?;
    w.finish()
}

/// Topic and frame names of [`write_synthetic_rig_recording`], as the RealSense ROS wrapper
/// publishes them without `aligned_depth_to_color`.
pub mod rig_names {
    /// Colour images, `rgb8`.
    pub const COLOR_IMAGE: &str = "/camera/color/image_raw";
    /// Colour calibration (with its distortion).
    pub const COLOR_INFO: &str = "/camera/color/camera_info";
    /// Depth images, `16UC1` millimetres, in the depth camera.
    pub const DEPTH_IMAGE: &str = "/camera/depth/image_rect_raw";
    /// Depth calibration.
    pub const DEPTH_INFO: &str = "/camera/depth/camera_info";
    /// The rig's fixed transforms.
    pub const TF_STATIC: &str = "/tf_static";
    /// The colour camera's optical frame.
    pub const COLOR_FRAME: &str = "camera_color_optical_frame";
    /// The depth camera's optical frame.
    pub const DEPTH_FRAME: &str = "camera_depth_optical_frame";
}

/// Depth units per metre of [`write_synthetic_rig_recording`]'s depth: millimetres, as
/// RealSense drivers publish `16UC1` (ROS REP 118).
pub const RIG_DEPTH_UNITS_PER_METER: f64 = 1000.0;

/// Writes a synthetic sequence seen through `rig` as a ROS driver records it ([`rig_names`]):
/// colour `rgb8` with its calibration (distortion included), depth `16UC1` mm from the depth
/// camera with its calibration, `/tf_static` with the rig's transforms as RealSense publishes
/// them (`camera_link` → sensor frame → optical frame), and the ground truth: the colour
/// camera's pose (`/groundtruth/pose`, `PoseStamped` in `world`) and moving-object mask in the
/// published colour pixels (`/groundtruth/mask`, `mono8`). A registered rig
/// ([`crate::synthetic::RgbdRig::registered`]) writes depth in the colour frame with the colour
/// calibration, as a recording with aligned depth has it.
///
/// `frame_done(i)` is called after frame `i`; `Break` stops with [`Error::Interrupted`].
///
/// # Errors
/// Writing fails, or `frame_done` asked to stop.
pub fn write_synthetic_rig_recording<W: Write + Seek>(
    sequence: &crate::synthetic::SyntheticSequence,
    rig: &crate::synthetic::RgbdRig,
    version: crate::mcap_io::ros_out::RosVersion,
    sink: W,
    options: &McapWriteOptions,
    frame_done: &mut dyn FnMut(usize) -> ControlFlow<()>,
) -> Result<W> {
    use crate::mcap_io::ros_out::{RosImage, RosMcapWriter, RosTransform};
    use nalgebra::{Isometry3, Matrix3, Rotation3, UnitQuaternion};
    use rig_names::*;
    let mut w = RosMcapWriter::new(sink, version, options)?;
    let registered = rig.color_from_depth == Isometry3::identity() && rig.depth == rig.color;
    let depth_frame = if registered { COLOR_FRAME } else { DEPTH_FRAME };
    // camera_link: x forward, y left, z up; optical frames: x right, y down, z forward.
    let link_from_optical = Isometry3::from_parts(
        nalgebra::Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::new(
            0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
        ))),
    );
    // The depth sensor sits at camera_link; the colour sensor where color_from_depth puts it.
    let link_from_color_optical = link_from_optical * rig.color_from_depth.inverse();
    let link_from_color = link_from_color_optical * link_from_optical.inverse();
    let mut color = crate::synthetic::SyntheticFrame::empty(rig.color.size);
    let mut depth = crate::synthetic::SyntheticFrame::empty(rig.depth.size);
    let mut depth_mm = Vec::with_capacity(rig.depth.size.area() * 2);
    for i in 0..sequence.len() {
        sequence.render_rig_into(i, rig, &mut color, &mut depth);
        let t = color.timestamp_ns;
        if i == 0 && !registered {
            let tf = |parent, child, parent_from_child| RosTransform {
                parent,
                child,
                parent_from_child,
            };
            w.transforms(
                TF_STATIC,
                t,
                &[
                    tf("camera_link", "camera_depth_frame", Isometry3::identity()),
                    tf("camera_depth_frame", DEPTH_FRAME, link_from_optical),
                    tf("camera_link", "camera_color_frame", link_from_color),
                    tf("camera_color_frame", COLOR_FRAME, link_from_optical),
                ],
            )?;
        }
        w.pose(TOPIC_GROUNDTRUTH_POSE, t, FRAME_WORLD, &color.world_from_camera)?;
        let rgb: Vec<u8> = color.rgb.as_slice().iter().flatten().copied().collect();
        w.image(
            COLOR_IMAGE,
            t,
            &RosImage {
                frame_id: COLOR_FRAME,
                encoding: ColorEncoding::Rgb8.as_str(),
                size: rig.color.size,
                step: rig.color.size.width * 3,
                data: &rgb,
            },
        )?;
        w.camera_info(COLOR_INFO, t, COLOR_FRAME, &rig.color)?;
        depth_mm.clear();
        for &d in depth.depth_m.as_slice() {
            let mm = (f64::from(d) * RIG_DEPTH_UNITS_PER_METER).round();
            let mm = if (1.0..=f64::from(u16::MAX)).contains(&mm) {
                mm as u16
            } else {
                0
            };
            depth_mm.extend_from_slice(&mm.to_le_bytes());
        }
        w.image(
            DEPTH_IMAGE,
            t,
            &RosImage {
                frame_id: depth_frame,
                encoding: DepthEncoding::U16.as_str(),
                size: rig.depth.size,
                step: rig.depth.size.width * 2,
                data: &depth_mm,
            },
        )?;
        w.camera_info(DEPTH_INFO, t, depth_frame, &rig.depth)?;
        w.image(
            TOPIC_GROUNDTRUTH_MASK,
            t,
            &RosImage {
                frame_id: COLOR_FRAME,
                encoding: ColorEncoding::Mono8.as_str(),
                size: rig.color.size,
                step: rig.color.size.width,
                data: color.gt_mask.as_slice(),
            },
        )?;
        if frame_done(i).is_break() {
            return Err(Error::Interrupted {
                done: i + 1,
                total: sequence.len(),
            });
        }
    }
    w.metadata(
        "occmask.synthetic",
        BTreeMap::from([
            (
                "scenario".to_owned(),
                sequence.scenario.map_or("custom", |s| s.name()).to_owned(),
            ),
            ("frames".to_owned(), sequence.len().to_string()),
            (
                "rig".to_owned(),
                if registered {
                    "registered"
                } else {
                    "separate depth camera"
                }
                .to_owned(),
            ),
        ]),
    )?;
    w.finish()
}
