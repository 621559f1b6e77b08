//! What `process` does to a recording's images before odometry and detection, decided once per
//! file from its calibrations, frame ids and transforms ([`plan_geometry`]), and the per-frame
//! tables that do it ([`Rectifier`]).
//!
//! The pipeline sees one undistorted pinhole camera: the colour camera with its own K.
//! - Colour with lens distortion is undistorted (bilinear remap), unless switched off.
//! - Depth already aligned to colour (the recording says so: a topic such as
//!   `aligned_depth_to_color`, `--depth-aligned`, or the same `frame_id`, size and
//!   calibration as colour) is only undistorted with the colour image (interpolated on one
//!   surface, never across a depth edge).
//! - Depth from another camera (another size, calibration or `frame_id`) is registered into
//!   the colour camera ([`crate::registration::DepthRegistration`]) with both calibrations and
//!   `color_from_depth` from `--depth-to-color` or the file's transforms.
//! - Masks are mapped back to the published colour image's pixels.
//!
//! A depth image from another camera is never used as if it were registered: what cannot be
//! registered is an error naming what is missing and the flag that supplies it.

use std::time::Instant;

use nalgebra::Isometry3;

use crate::error::{Error, RegistrationNeed, Result};
use crate::geometry::distortion::{CameraModel, LensDistortion};
use crate::image_buf::{DepthMeters, GrayF32, Image, ImageSize};
use crate::mcap_io::input::decode::CalibrationMsg;
use crate::mcap_io::input::detect::RgbdTopics;
use crate::mcap_io::input::transforms::{find_transform, normalize_frame};
use crate::mcap_io::input::McapInput;
use crate::registration::{
    distortion_map, inscribed_pinhole, undistortion_map, BilinearMap, DepthRegistration, NearestMap,
};

/// Words in a depth topic that mean "registered to the colour camera" in the usual drivers:
/// RealSense (`aligned_depth_to_color`), OpenNI/Orbbec (`depth_registered`), Azure Kinect
/// (`depth_to_rgb`).
pub const ALIGNED_DEPTH_TOPIC_WORDS: [&str; 4] = [
    "aligned_depth_to_color",
    "aligned_depth_to_colour",
    "depth_registered",
    "depth_to_rgb",
];

/// Calibrations closer than this (relative, per K entry and distortion coefficient) are the
/// same camera: recorders print them with 6–9 significant digits.
const SAME_CALIBRATION_RELATIVE: f64 = 1e-6;

/// How the depth images relate to the colour camera.
#[derive(Debug, Clone, PartialEq)]
pub enum DepthGeometry {
    /// Depth pixels are colour pixels already.
    Aligned {
        /// Why: the topic name, the flag, or identical frame, size and calibration.
        reason: String,
    },
    /// Depth comes from another camera and is registered into the colour camera.
    Registered {
        /// The depth camera.
        depth: CameraModel,
        /// The depth camera's pose in the colour camera's frame.
        color_from_depth: Isometry3<f64>,
        /// Where `color_from_depth` came from (the flag, the transform chain, "same frame").
        transform_source: String,
    },
}

/// The plan for one file.
#[derive(Debug, Clone, PartialEq)]
pub struct InputGeometry {
    /// The colour camera as published (with its distortion).
    pub color: CameraModel,
    /// `frame_id` of the colour images.
    pub color_frame: String,
    /// `frame_id` of the depth images.
    pub depth_frame: String,
    /// Undistort colour (it has distortion and undistortion is not switched off).
    pub undistort_color: bool,
    /// The pinhole camera the pipeline sees: [`inscribed_pinhole`] of the colour camera when
    /// undistorting, else the colour camera without its distortion.
    pub pipeline: CameraModel,
    /// Depth.
    pub depth: DepthGeometry,
}

/// Choices from the command line.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GeometryOptions {
    /// `--depth-aligned`: the depth is registered to colour, whatever the file says.
    pub depth_aligned: bool,
    /// `--depth-to-color`: `color_from_depth`, instead of the file's transforms.
    pub color_from_depth: Option<Isometry3<f64>>,
    /// `--no-undistort`: treat the colour camera as a pinhole.
    pub no_undistort: bool,
}

/// The first image of a stream: what the plan needs of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StreamInfo {
    /// The image's `frame_id`.
    pub frame_id: String,
    /// The image's size.
    pub size: ImageSize,
}

fn format_distortion(distortion: Option<&LensDistortion>) -> String {
    match distortion {
        None => "none".to_owned(),
        Some(d) => {
            let (model, coefficients) = d.to_ros();
            format!("{model} {coefficients:?}")
        }
    }
}

fn format_camera(camera: &CameraModel) -> String {
    let k = camera.intrinsics;
    format!(
        "{} fx {} fy {} cx {} cy {}, distortion {}",
        camera.size,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        format_distortion(camera.distortion.as_ref())
    )
}

fn format_pose(pose: &Isometry3<f64>) -> String {
    let t = pose.translation.vector;
    let q = pose.rotation;
    format!("{},{},{},{},{},{},{}", t.x, t.y, t.z, q.i, q.j, q.k, q.w)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME_CALIBRATION_RELATIVE * a.abs().max(b.abs()).max(1.0)
}

/// True when both describe the same camera (size, K and distortion).
fn same_camera(a: &CameraModel, b: &CameraModel) -> bool {
    let (ka, kb) = (a.intrinsics, b.intrinsics);
    let coefficients = |d: Option<LensDistortion>| d.map_or_else(|| vec![0.0; 8], |d| d.to_ros().1);
    let (da, db) = (coefficients(a.distortion), coefficients(b.distortion));
    a.size == b.size
        && [(ka.fx, kb.fx), (ka.fy, kb.fy), (ka.cx, kb.cx), (ka.cy, kb.cy)]
            .iter()
            .all(|&(x, y)| close(x, y))
        && (0..da.len().max(db.len())).all(|i| close(*da.get(i).unwrap_or(&0.0), *db.get(i).unwrap_or(&0.0)))
}

/// Decides what to do to the images of one file; see the module documentation.
///
/// `color_camera` is the colour camera as the pipeline will use it (from `--camera` or the
/// colour calibration, sized like the colour images); `color_calibration` and
/// `depth_calibration` are the file's own calibrations (the depth one is what makes
/// registration possible).
///
/// # Errors
/// [`Error::DepthNotRegistered`] when depth is from another camera and the depth calibration
/// is missing or disagrees with the images, or a topic that says "aligned" has another size;
/// [`Error::MissingTransform`] when no transform links the two frames; decode errors of the
/// calibrations and transforms.
#[allow(clippy::too_many_arguments)]
pub fn plan_geometry(
    input: &McapInput,
    topics: &RgbdTopics,
    color: &StreamInfo,
    depth: &StreamInfo,
    color_camera: CameraModel,
    color_calibration: Option<&CalibrationMsg>,
    depth_calibration: Option<&CalibrationMsg>,
    options: &GeometryOptions,
) -> Result<InputGeometry> {
    let (color_topic, depth_topic) = (&topics.color.topic, &topics.depth.topic);
    let not_registered = |found: String, needed: RegistrationNeed| Error::DepthNotRegistered {
        depth_topic: depth_topic.clone(),
        color_topic: color_topic.clone(),
        found,
        needed: Box::new(needed),
    };
    let undistort_color = color_camera.distortion.is_some() && !options.no_undistort;
    let plan = |depth_geometry| InputGeometry {
        color: color_camera,
        color_frame: color.frame_id.clone(),
        depth_frame: depth.frame_id.clone(),
        undistort_color,
        pipeline: if undistort_color {
            inscribed_pinhole(&color_camera)
        } else {
            color_camera.undistorted()
        },
        depth: depth_geometry,
    };
    let aligned = |reason: String| -> Result<InputGeometry> {
        if depth.size != color.size {
            return Err(not_registered(
                format!("depth {} vs colour {}", depth.size, color.size),
                RegistrationNeed::AlignedSameSize { reason },
            ));
        }
        Ok(plan(DepthGeometry::Aligned { reason }))
    };
    if options.depth_aligned {
        return aligned("--depth-aligned".into());
    }
    // `--depth-to-color` asks for registration: neither the topic name nor identical
    // calibrations override it.
    let forced = options.color_from_depth.is_some();
    let lower = depth_topic.to_ascii_lowercase();
    if let Some(word) = ALIGNED_DEPTH_TOPIC_WORDS.iter().find(|w| lower.contains(*w)) {
        if !forced {
            return aligned(format!("the topic name ({word})"));
        }
    }
    // Only compared: a colour calibration that `--camera` overrides need not decode.
    let color_file_camera = color_calibration.and_then(|c| c.camera_model(color_topic).ok());
    let depth_calibration_topic = topics
        .depth_calibration
        .as_ref()
        .map_or_else(|| depth_topic.clone(), |c| c.topic.clone());
    let depth_file_camera = depth_calibration.map(|c| c.camera_model(&depth_calibration_topic));
    let same_frame = normalize_frame(&color.frame_id) == normalize_frame(&depth.frame_id);
    let same_calibration = match &depth_file_camera {
        None => true,
        Some(Ok(d)) => same_camera(d, color_file_camera.as_ref().unwrap_or(&color_camera)),
        Some(Err(_)) => false,
    };
    if same_frame && depth.size == color.size && same_calibration && !forced {
        return Ok(plan(DepthGeometry::Aligned {
            reason: if depth_file_camera.is_some() {
                "same frame_id, size and calibration as colour".into()
            } else {
                "same frame_id and size as colour".into()
            },
        }));
    }
    let mut differences = Vec::new();
    if depth.size != color.size {
        differences.push(format!("size {} vs {}", depth.size, color.size));
    }
    if !same_frame {
        differences.push(format!("frame_id {:?} vs {:?}", depth.frame_id, color.frame_id));
    }
    if !same_calibration {
        differences.push("another calibration".to_owned());
    }
    if forced && differences.is_empty() {
        differences.push("--depth-to-color given".to_owned());
    }
    let found = differences.join(", ");
    let Some(depth_camera) = depth_file_camera else {
        return Err(not_registered(found, RegistrationNeed::DepthCalibration));
    };
    let mut depth_camera = depth_camera?;
    if depth_camera.size.area() == 0 {
        depth_camera.size = depth.size;
    }
    if depth_camera.size != depth.size {
        return Err(not_registered(
            found,
            RegistrationNeed::DepthCalibrationSize {
                topic: depth_calibration_topic.clone(),
                calibration: depth_camera.size,
                image: depth.size,
            },
        ));
    }
    let (color_from_depth, transform_source) = if let Some(pose) = options.color_from_depth {
        (pose, "--depth-to-color".to_owned())
    } else if same_frame {
        (Isometry3::identity(), "same frame_id".to_owned())
    } else {
        let (chain, frames) = find_transform(input, &color.frame_id, &depth.frame_id)?;
        match chain {
            Some(chain) => (chain.target_from_source, chain.describe()),
            None => {
                let channels: Vec<&str> = input
                    .channels()
                    .values()
                    .filter(|c| {
                        c.channel_type.is_some_and(|ct| {
                            matches!(
                                ct.message,
                                crate::mcap_io::input::MessageType::FrameTransform
                                    | crate::mcap_io::input::MessageType::FrameTransforms
                            )
                        })
                    })
                    .map(|c| c.topic.as_str())
                    .collect();
                let searched = if channels.is_empty() {
                    "the file has no transform channel (/tf_static, /tf)".to_owned()
                } else if frames.is_empty() {
                    format!("searched {} and found no transforms", channels.join(", "))
                } else {
                    format!(
                        "searched {}, whose frames are {}",
                        channels.join(", "),
                        frames.join(", ")
                    )
                };
                return Err(Error::MissingTransform {
                    depth_frame: depth.frame_id.clone(),
                    color_frame: color.frame_id.clone(),
                    searched,
                });
            }
        }
    };
    Ok(plan(DepthGeometry::Registered {
        depth: depth_camera,
        color_from_depth,
        transform_source,
    }))
}

impl InputGeometry {
    /// True when images go to the pipeline unchanged.
    pub fn is_identity(&self) -> bool {
        !self.undistort_color && matches!(self.depth, DepthGeometry::Aligned { .. })
    }

    /// The `occmask.process` metadata keys describing the plan.
    pub fn metadata(&self) -> Vec<(String, String)> {
        let mut v = vec![
            ("color_frame".to_owned(), self.color_frame.clone()),
            ("depth_frame".to_owned(), self.depth_frame.clone()),
            (
                "color_distortion".to_owned(),
                format_distortion(self.color.distortion.as_ref()),
            ),
            (
                "color_undistortion".to_owned(),
                match (self.color.distortion.is_some(), self.undistort_color) {
                    (false, _) => "none (pinhole calibration)".to_owned(),
                    (true, true) => {
                        let k = self.pipeline.intrinsics;
                        format!(
                            "undistorted to the pinhole camera fx {} fy {} cx {} cy {} (the smallest \
                             magnification of K with data at every pixel); masks mapped back to the \
                             published pixels",
                            k.fx, k.fy, k.cx, k.cy
                        )
                    }
                    (true, false) => "off (--no-undistort): distortion ignored".to_owned(),
                },
            ),
        ];
        match &self.depth {
            DepthGeometry::Aligned { reason } => {
                v.push(("depth_registration".to_owned(), "aligned".to_owned()));
                v.push(("depth_registration_reason".to_owned(), reason.clone()));
            }
            DepthGeometry::Registered {
                depth,
                color_from_depth,
                transform_source,
            } => {
                v.push(("depth_registration".to_owned(), "registered".to_owned()));
                v.push(("depth_camera".to_owned(), format_camera(depth)));
                v.push((
                    "color_from_depth_xyz_qxyzw".to_owned(),
                    format_pose(color_from_depth),
                ));
                v.push(("color_from_depth_source".to_owned(), transform_source.clone()));
            }
        }
        v
    }

    /// One line for the command's summary.
    pub fn describe(&self) -> String {
        let depth = match &self.depth {
            DepthGeometry::Aligned { reason } => format!("depth aligned to colour ({reason})"),
            DepthGeometry::Registered {
                depth,
                color_from_depth,
                transform_source,
            } => {
                let t = color_from_depth.translation.vector;
                format!(
                    "depth {} ({}) registered into colour {} ({}), baseline {:.1} mm from {transform_source}",
                    self.depth_frame,
                    depth.size,
                    self.color_frame,
                    self.color.size,
                    t.norm() * 1e3
                )
            }
        };
        let color = match (&self.color.distortion, self.undistort_color) {
            (None, _) => String::new(),
            (Some(d), true) => format!("; colour undistorted ({})", d.to_ros().0),
            (Some(_), false) => "; colour distortion ignored (--no-undistort)".to_owned(),
        };
        format!("{depth}{color}")
    }

    /// The depth images' expected size.
    pub fn depth_size(&self) -> ImageSize {
        match &self.depth {
            DepthGeometry::Aligned { .. } => self.color.size,
            DepthGeometry::Registered { depth, .. } => depth.size,
        }
    }
}

/// The input side of an [`InputGeometry`]: its tables and buffers, built once per file and
/// used on the prefetch thread, which decodes each image and hands the pipeline the
/// undistorted, registered result. That thread runs beside the pipeline and outside the
/// file's rayon pool, so the kernels run serially on it (a parallel kernel there would hand
/// its work to rayon's global pool, beside the file's own).
pub struct Rectifier {
    color_size: ImageSize,
    depth_size: ImageSize,
    /// Undistorts grey, and depth when it is aligned to the distorted colour.
    undistort: Option<BilinearMap>,
    registration: Option<DepthRegistration>,
    /// The decoded images, when they are rectified into the caller's buffers.
    gray_in: GrayF32,
    depth_in: DepthMeters,
}

/// The output side of an [`InputGeometry`]: maps images computed on the pipeline's
/// undistorted pixels (masks, the accumulation map) back to the published colour pixels.
pub struct Publisher {
    back_map: Option<NearestMap>,
}

impl Rectifier {
    /// Builds the tables of `geometry`: the input side, and the output side for the frame loop.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for images too small or too large for the tables.
    pub fn new(geometry: &InputGeometry) -> Result<(Self, Publisher)> {
        let (undistort, back_map) = if geometry.undistort_color {
            (
                Some(undistortion_map(&geometry.color, &geometry.pipeline)?),
                Some(distortion_map(&geometry.color, &geometry.pipeline)?),
            )
        } else {
            (None, None)
        };
        let registration = match &geometry.depth {
            DepthGeometry::Aligned { .. } => None,
            DepthGeometry::Registered {
                depth,
                color_from_depth,
                ..
            } => Some(DepthRegistration::new(
                depth,
                &geometry.pipeline,
                color_from_depth,
                1,
            )?),
        };
        let rectifier = Self {
            color_size: geometry.color.size,
            depth_size: geometry.depth_size(),
            undistort,
            registration,
            gray_in: GrayF32::filled(ImageSize::default(), 0.0),
            depth_in: DepthMeters::filled(ImageSize::default(), 0.0),
        };
        Ok((rectifier, Publisher { back_map }))
    }

    /// The colour image for the pipeline in `gray`: `decode` writes the decoded image (into
    /// `gray` itself when there is nothing to do, else into the rectifier's buffer, which is
    /// then undistorted into `gray`).
    ///
    /// Returns the seconds spent undistorting (not decoding).
    ///
    /// # Errors
    /// What `decode` returns; [`Error::SizeMismatch`] naming `topic` when the image's size is
    /// not the first colour image's.
    pub fn color(
        &mut self,
        topic: &str,
        gray: &mut GrayF32,
        decode: impl FnOnce(&mut GrayF32) -> Result<()>,
    ) -> Result<f64> {
        let decoded = if self.undistort.is_some() {
            &mut self.gray_in
        } else {
            &mut *gray
        };
        decode(decoded)?;
        check_size(topic, "colour", self.color_size, decoded.size())?;
        let start = Instant::now();
        if let Some(map) = &self.undistort {
            resize(gray, self.color_size);
            map.apply_serial(&self.gray_in, gray)?;
        }
        Ok(start.elapsed().as_secs_f64())
    }

    /// The depth for the pipeline in `depth_m` (the colour camera's pixels): `decode` writes
    /// the decoded depth, which is then registered or undistorted as planned.
    ///
    /// Returns the seconds spent registering or undistorting (not decoding).
    ///
    /// # Errors
    /// What `decode` returns; [`Error::SizeMismatch`] naming `topic` when the image's size is
    /// not the first depth image's.
    pub fn depth(
        &mut self,
        topic: &str,
        depth_m: &mut DepthMeters,
        decode: impl FnOnce(&mut DepthMeters) -> Result<()>,
    ) -> Result<f64> {
        let rectified = self.registration.is_some() || self.undistort.is_some();
        let decoded = if rectified {
            &mut self.depth_in
        } else {
            &mut *depth_m
        };
        decode(decoded)?;
        check_size(topic, "depth", self.depth_size, decoded.size())?;
        let start = Instant::now();
        if let Some(registration) = &mut self.registration {
            resize(depth_m, self.color_size);
            registration.register_into(&self.depth_in, depth_m)?;
            if let Some(map) = &self.undistort {
                // Pinhole pixels whose colour lies outside the published image have only a
                // clamped border colour: their depth must not be used.
                map.clear_outside(depth_m, 0.0)?;
            }
        } else if let Some(map) = &self.undistort {
            resize(depth_m, self.color_size);
            map.apply_depth_serial(&self.depth_in, depth_m)?;
        }
        Ok(start.elapsed().as_secs_f64())
    }
}

fn resize<T: Copy + Default>(image: &mut Image<T>, size: ImageSize) {
    if image.size() != size {
        *image = Image::filled(size, T::default());
    }
}

fn check_size(topic: &str, what: &str, expected: ImageSize, found: ImageSize) -> Result<()> {
    if expected != found {
        return Err(Error::SizeMismatch {
            what: format!("{what} image size changed within {topic} (the first image's size is planned for)"),
            expected,
            found,
        });
    }
    Ok(())
}

impl Publisher {
    /// True when images are published as computed.
    pub fn is_identity(&self) -> bool {
        self.back_map.is_none()
    }

    /// `image` (computed on the pipeline's undistorted pixels) in the published colour image's
    /// pixels; unchanged when colour is not undistorted.
    ///
    /// # Errors
    /// [`Error::SizeMismatch`] when `image` does not have the colour image's size.
    pub fn to_published<T: Copy + Default + Send + Sync>(&self, image: Image<T>) -> Result<Image<T>> {
        let Some(map) = &self.back_map else {
            return Ok(image);
        };
        let mut out = Image::filled(map.output_size(), T::default());
        map.apply_into(&image, &mut out)?;
        Ok(out)
    }
}
