//! The library's one error type.
//!
//! Every variant says what was expected and what was found. Variants that come from a
//! user-supplied file carry its path (last in the message) and, for text files, the line.
//! Messages do not name command-line flags: the CLI adds the flag that fixes an error from its
//! variant (`src/cli/hints.rs`), so library users get the same facts without them.

use std::path::PathBuf;

use crate::image_buf::ImageSize;

/// Result alias used throughout the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in the library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A buffer does not hold `width * height` elements.
    #[error("image buffer has {found} elements, expected {expected} for {size}")]
    BufferLength {
        /// Elements the size requires.
        expected: usize,
        /// Elements supplied.
        found: usize,
        /// The image size.
        size: ImageSize,
    },

    /// Two images that must share a size do not.
    #[error("{what}: image size {found} does not match the expected {expected}")]
    SizeMismatch {
        /// Which images were compared.
        what: String,
        /// The size required.
        expected: ImageSize,
        /// The size found.
        found: ImageSize,
    },

    /// A line of a text file could not be parsed.
    #[error("line {line}: expected {expected}, found {found} (in {})", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What the line should hold there.
        expected: String,
        /// What it holds.
        found: String,
    },

    /// A file or directory could not be read or written.
    // The OS error is part of the message and deliberately not a `source()`, so anyhow's
    // `{:#}` chain does not print it twice.
    #[error("{action}: {os_error} ({})", path.display())]
    Io {
        /// What was being done ("cannot open", "cannot write").
        action: String,
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        os_error: std::io::Error,
    },

    /// An image file could not be decoded or has the wrong pixel format.
    #[error("expected {expected}, found {found} ({})", path.display())]
    BadImage {
        /// The file.
        path: PathBuf,
        /// The image the file should hold.
        expected: String,
        /// What it holds (or the decoder's reason).
        found: String,
    },

    /// A dataset folder is not laid out as its kind requires (missing or misplaced files and
    /// directories, empty sequence, ...).
    #[error("expected {expected}, found {found} ({})", path.display())]
    DatasetLayout {
        /// The dataset folder, or the file or directory in it.
        path: PathBuf,
        /// What should be there.
        expected: String,
        /// What is there.
        found: String,
    },

    /// No colour frame of a dataset has a depth frame within the pairing tolerance.
    #[error(
        "no colour frame has a depth frame within {:.1} ms (closest pair: {}) ({})",
        *max_pair_gap_ns as f64 / 1e6,
        nearest_gap_ns.map_or_else(|| "n/a".to_owned(), |g| format!("{:.1} ms", g as f64 / 1e6)),
        root.display()
    )]
    NoPairs {
        /// The dataset folder.
        root: PathBuf,
        /// The largest colour–depth stamp difference allowed, nanoseconds.
        max_pair_gap_ns: u64,
        /// The smallest difference found, nanoseconds (`None` when a stream is empty).
        nearest_gap_ns: Option<u64>,
    },

    /// A file is not an output of `occmask process`: it has none of the channels scored.
    #[error(
        "no {mask_topic} or {odometry_topic} channel: run `occmask process` on the recording first ({})",
        path.display()
    )]
    NotProcessed {
        /// The file.
        path: PathBuf,
        /// The mask topic looked for.
        mask_topic: &'static str,
        /// The odometry topic looked for.
        odometry_topic: &'static str,
    },

    /// The MCAP container is not usable (not MCAP, a directory, damaged chunks, ...).
    #[error("{problem} ({})", path.display())]
    BadMcap {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        problem: McapProblem,
    },

    /// A parameter is outside its valid range.
    #[error("parameter {name} = {value} is invalid: expected {expected}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// The value given.
        value: String,
        /// The valid range or form.
        expected: String,
    },

    /// An MCAP message could not be decoded.
    #[error(
        "topic {topic}: {}{problem}",
        at.as_ref().map(|at| format!("{at}: ")).unwrap_or_default()
    )]
    Decode {
        /// The channel's topic.
        topic: String,
        /// Which message, when the caller knows it.
        at: Option<MessageAt>,
        /// What was expected and what was found.
        problem: DecodeProblem,
    },

    /// A message could not be encoded for writing.
    #[error("topic {topic}: cannot encode {what}: {reason}")]
    Encode {
        /// The channel's topic (or `channel N` when only its id is known).
        topic: String,
        /// What was encoded ("message", "stats").
        what: &'static str,
        /// The encoder's reason.
        reason: String,
    },

    /// A calibration's camera matrix K is not a pinhole matrix.
    #[error("topic {topic}: {}", describe_bad_k(k))]
    BadIntrinsics {
        /// The calibration topic.
        topic: String,
        /// K as found, row-major.
        k: Vec<f64>,
    },

    /// A calibration's lens distortion cannot be applied.
    #[error("topic {topic}: {}", reason.0)]
    UnsupportedDistortion {
        /// The calibration topic.
        topic: String,
        /// Which model or coefficients were refused, and why.
        reason: crate::geometry::distortion::UnsupportedDistortion,
    },

    /// Depth comes from another camera than colour and cannot be registered to it as given.
    #[error("depth {depth_topic} is not registered to colour {color_topic} ({found}): {needed}")]
    DepthNotRegistered {
        /// The depth topic.
        depth_topic: String,
        /// The colour topic.
        color_topic: String,
        /// How depth and colour differ.
        found: String,
        /// What registering needs (boxed: it keeps the error small).
        needed: Box<RegistrationNeed>,
    },

    /// No transform between the depth camera's and the colour camera's frames.
    #[error(
        "no transform from the depth frame {depth_frame:?} to the colour frame {color_frame:?} ({searched})"
    )]
    MissingTransform {
        /// The depth image's `frame_id`.
        depth_frame: String,
        /// The colour image's `frame_id`.
        color_frame: String,
        /// Which channels were searched and which frames they hold.
        searched: String,
    },

    /// The colour images have no camera calibration.
    #[error("no camera calibration for {color_topic}: {reason} ({})", path.display())]
    MissingCalibration {
        /// The input file.
        path: PathBuf,
        /// The colour topic.
        color_topic: String,
        /// Why none was found.
        reason: CalibrationGap,
    },

    /// The colour calibration is for images of another size.
    #[error(
        "calibration vs colour {color_topic}: image size {calibration} does not match the expected {image}"
    )]
    CalibrationSize {
        /// The colour topic.
        color_topic: String,
        /// The colour images' size.
        image: ImageSize,
        /// The calibration's size.
        calibration: ImageSize,
    },

    /// The depth channel's metadata gives a depth scale that is not a positive number.
    #[error("topic {topic}: channel metadata {key} = {value:?} is not a positive number")]
    BadDepthUnits {
        /// The depth topic.
        topic: String,
        /// The metadata key.
        key: &'static str,
        /// Its value.
        value: String,
    },

    /// No channel of `role` could be chosen in an input file.
    #[error(
        "no {role} channel found{found}; supported image schemas are foxglove.RawImage/\
         foxglove.CompressedImage (protobuf or json), sensor_msgs/msg/Image/CompressedImage (ROS 2, \
         cdr) and sensor_msgs/Image/CompressedImage (ROS 1, ros1); {channels} ({})",
        path.display()
    )]
    NoTopic {
        /// The input file.
        path: PathBuf,
        /// What the channel was for.
        role: TopicRole,
        /// What was found instead (empty, or e.g. " among the image topics (…)").
        found: String,
        /// Every channel of the file, as `topic (schema, encoding)`.
        channels: String,
    },

    /// Several channels could be the one for `role`.
    #[error("several {role} topics: {} ({})", candidates.join(", "), path.display())]
    AmbiguousTopic {
        /// The input file.
        path: PathBuf,
        /// What the channel is for.
        role: TopicRole,
        /// The candidates' topics.
        candidates: Vec<String>,
    },

    /// A topic given for `role` is not in the file.
    #[error("{role} topic {topic}: no such topic; {channels} ({})", path.display())]
    UnknownTopic {
        /// The input file.
        path: PathBuf,
        /// What the topic was given for.
        role: TopicRole,
        /// The topic given.
        topic: String,
        /// Every channel of the file, as `topic (schema, encoding)`.
        channels: String,
    },

    /// A topic given for `role` has a schema that cannot serve it.
    #[error(
        "{role} topic {topic}: schema {schema:?} with message encoding {message_encoding:?} is not \
         supported here (expected {} as Foxglove protobuf/json, ROS 2 cdr or ROS 1) ({})",
        role.expected_messages(),
        path.display()
    )]
    UnsupportedTopic {
        /// The input file.
        path: PathBuf,
        /// What the topic was given for.
        role: TopicRole,
        /// The topic given.
        topic: String,
        /// Its schema name.
        schema: String,
        /// Its message encoding.
        message_encoding: String,
    },

    /// External poses were asked for without a topic to read them from.
    #[error("external poses need a pose topic to read them from")]
    MissingPoseTopic,

    /// A pose channel holds no usable pose.
    #[error(
        "{role} {topic}: no poses{}{} ({})",
        child_frame.as_ref().map(|c| format!(" with child frame {c}")).unwrap_or_default(),
        if channels.is_empty() { String::new() } else { format!(" in the file (channels: {})", channels.join(", ")) },
        path.display()
    )]
    NoPoses {
        /// The input file.
        path: PathBuf,
        /// What the poses were for.
        role: PoseRole,
        /// The pose topic.
        topic: String,
        /// The child frame asked for, if any.
        child_frame: Option<String>,
        /// The file's channels, when the topic is missing altogether.
        channels: Vec<String>,
    },

    /// The required anchor channel does not decode.
    #[error("{error} (anchor poses)")]
    AnchorPoses {
        /// The anchor topic.
        topic: String,
        /// The decoding error.
        error: Box<Error>,
    },

    /// The input holds the channels of an earlier `occmask process` run, which a new run's
    /// would mix with.
    #[error(
        "the input holds the channels of an earlier occmask run ({}): this run's masks and poses would be \
         mixed into them",
        topics.join(", ")
    )]
    AlreadyAnnotated {
        /// The earlier run's topics.
        topics: Vec<String>,
    },

    /// The output exists and may not be overwritten.
    #[error("output file {} exists{}", path.display(), if *appeared_while_writing { " (it appeared while writing)" } else { "" })]
    OutputExists {
        /// The output path.
        path: PathBuf,
        /// It was created by someone else while the output was being written.
        appeared_while_writing: bool,
    },

    /// An existing output was to be kept as a finished run, but it is not one of the same input
    /// with the same choices and parameters.
    #[error("output file {} exists but {problem}", path.display())]
    ExistingOutputNotReusable {
        /// The output path.
        path: PathBuf,
        /// What it is instead.
        problem: ExistingOutputProblem,
    },

    /// The dataset reader stopped before every image and pose was written (its own error, if it
    /// had one, is reported instead).
    #[error("conversion stopped after {done} of {total} images and poses")]
    ReaderStopped {
        /// Images and poses written.
        done: usize,
        /// Images and poses planned.
        total: usize,
    },

    /// The output writer thread stopped (the error it stopped on is reported instead).
    #[error("the output writer stopped")]
    WriterStopped,

    /// The MCAP library reported an error.
    // Its causes (the OS error under an I/O error) are part of the message and deliberately
    // not a `source()` (as for `Io`): the library's own message already names the error kind.
    #[error("MCAP: {}", with_causes(.0))]
    Mcap(mcap::McapError),

    /// The caller asked to stop (e.g. Ctrl-C); partial output is discarded.
    #[error("interrupted after {done} of {total} items; no output was written")]
    Interrupted {
        /// Items finished.
        done: usize,
        /// Items planned.
        total: usize,
    },

    /// The operating system refused to start worker threads.
    // The cause is part of the message and deliberately not a `source()` (as for `Io`).
    #[error("cannot start a pool of {threads} worker thread(s): {cause}")]
    ThreadPool {
        /// Threads asked for.
        threads: usize,
        /// The thread pool's error.
        cause: rayon::ThreadPoolBuildError,
    },
}

/// The message of [`Error::BadIntrinsics`]: what a pinhole K looks like and what was found.
fn describe_bad_k(k: &[f64]) -> String {
    if k.len() == 9 {
        format!(
            "expected a pinhole K [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0, found {k:?} (an all-zero \
             K means the camera is uncalibrated)"
        )
    } else {
        format!("expected a 3x3 K (9 numbers), found {} numbers", k.len())
    }
}

/// What was expected and what was found instead: the body of [`Error::Parse`] (and of the
/// other expected/found variants) from parsers that do not know the file they read, so the
/// caller adds the file and line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected {expected}, found {found}")]
pub struct Mismatch {
    /// What was expected.
    pub expected: String,
    /// What was found.
    pub found: String,
}

impl Mismatch {
    /// A mismatch of `expected` and `found`.
    pub fn new(expected: impl Into<String>, found: impl Into<String>) -> Self {
        Self {
            expected: expected.into(),
            found: found.into(),
        }
    }

    /// [`Error::Parse`] for line `line` of `path`.
    pub fn at_line(self, path: &std::path::Path, line: usize) -> Error {
        Error::Parse {
            path: path.to_owned(),
            line,
            expected: self.expected,
            found: self.found,
        }
    }
}

impl From<mcap::McapError> for Error {
    fn from(error: mcap::McapError) -> Self {
        Error::Mcap(error)
    }
}

/// `error`'s message followed by its causes' (`source()` chain), each once.
fn with_causes(error: &dyn std::error::Error) -> String {
    let mut message = error.to_string();
    let mut cause = error.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !message.ends_with(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        cause = c.source();
    }
    message
}

impl Error {
    /// `Ok` when `value` is finite and > 0, else [`Error::InvalidParameter`] naming `name`.
    pub(crate) fn require_finite_positive(name: &'static str, value: f32) -> Result<()> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(Error::InvalidParameter {
                name,
                value: value.to_string(),
                expected: "finite and > 0".into(),
            })
        }
    }

    /// Builds an [`Error::Decode`] for a message of `topic` (the caller may add which one).
    pub fn decode(topic: impl Into<String>, problem: DecodeProblem) -> Self {
        Error::Decode {
            topic: topic.into(),
            at: None,
            problem,
        }
    }

    /// Builds an [`Error::BadMcap`] for `path`.
    pub fn bad_mcap(path: impl Into<PathBuf>, problem: McapProblem) -> Self {
        Error::BadMcap {
            path: path.into(),
            problem,
        }
    }

    /// Builds an [`Error::Io`] for `path`.
    pub fn io(action: impl Into<String>, path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            action: action.into(),
            path: path.into(),
            os_error: source,
        }
    }
}

/// Why no camera calibration was found ([`Error::MissingCalibration`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CalibrationGap {
    /// The file has no calibration channel.
    #[error("the file has no CameraCalibration/CameraInfo channel")]
    NoChannel,
    /// The calibration channel has no messages.
    #[error("{topic} has no messages")]
    NoMessages {
        /// The calibration topic.
        topic: String,
    },
    /// The calibration channel's schema is not supported.
    #[error("unsupported schema")]
    UnsupportedSchema {
        /// The calibration topic.
        topic: String,
    },
}

/// What registering depth to colour needs ([`Error::DepthNotRegistered`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegistrationNeed {
    /// Depth was said to be registered (`reason`), but has another size than colour.
    #[error(
        "{reason} says the depth is registered to colour, but registered depth has the colour image's size"
    )]
    AlignedSameSize {
        /// What said so (the option, or the topic name).
        reason: String,
    },
    /// The depth camera's calibration is missing.
    #[error("registering it needs the depth camera's calibration")]
    DepthCalibration,
    /// The depth calibration is for images of another size.
    #[error("the depth calibration {topic} is for {calibration} images but the depth images are {image}")]
    DepthCalibrationSize {
        /// The depth calibration topic.
        topic: String,
        /// Its image size.
        calibration: ImageSize,
        /// The depth images' size.
        image: ImageSize,
    },
}

/// What an input channel is chosen for ([`Error::NoTopic`] and the other topic errors).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TopicRole {
    /// Colour images.
    #[error("colour image")]
    Color,
    /// Depth images.
    #[error("depth image")]
    Depth,
    /// The colour camera's calibration.
    #[error("camera calibration")]
    Calibration,
    /// The depth camera's calibration.
    #[error("depth camera calibration")]
    DepthCalibration,
    /// External poses.
    #[error("pose")]
    Poses,
}

impl TopicRole {
    /// The message types a channel for this role may hold.
    pub const fn expected_messages(self) -> &'static str {
        match self {
            TopicRole::Color | TopicRole::Depth => "a raw or compressed image",
            TopicRole::Calibration | TopicRole::DepthCalibration => "a camera calibration",
            TopicRole::Poses => "a pose in frame, frame transform or frame transforms",
        }
    }
}

/// What a pose channel was read for ([`Error::NoPoses`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PoseRole {
    /// The external pose source.
    #[error("pose topic")]
    External,
    /// The odometry anchor.
    #[error("anchor topic")]
    Anchor,
    /// The ground truth `eval` scores against.
    #[error("ground-truth topic")]
    GroundTruth,
}

/// Which message of a channel an error is about, as a player shows it ([`Error::Decode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageAt {
    /// The message's log time, nanoseconds.
    pub log_time_ns: u64,
    /// Its sequence number.
    pub sequence: u32,
}

impl std::fmt::Display for MessageAt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "message at log time {} s (sequence {})",
            crate::time::format_ns_as_seconds(self.log_time_ns, 6),
            self.sequence
        )
    }
}

/// Why an existing output is not a finished run with the given parameters
/// ([`Error::ExistingOutputNotReusable`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ExistingOutputProblem {
    /// Truncated, or without the summary section a finished output ends with.
    #[error("is incomplete (truncated, or without its summary section)")]
    Incomplete,
    /// No `occmask.process` metadata record: not written by `occmask process`.
    #[error("was not written by occmask process (it has no occmask.process metadata record)")]
    NotProcessed,
    /// Its `occmask.process` record holds no readable processor configuration.
    #[error("records no readable processor configuration (an older or damaged occmask.process record)")]
    NoConfiguration,
    /// Made from another input (a recording of the same name, from another folder or day).
    #[error("was made from another input: its {field} is {found} there and {expected} here")]
    OtherInput {
        /// The field of the input's identity: `input_messages` or `input_log_time_span_ns`.
        field: String,
        /// Its value in the existing output (`absent` when it has none).
        found: String,
        /// The value of this run's input.
        expected: String,
    },
    /// Made with other choices (topics, pose source, time range) or parameters: the first field
    /// that differs.
    #[error("was made with other parameters: {field} is {found} there and {expected} here")]
    OtherParameters {
        /// The field: a key of the `occmask.process` record (`color_topic`, `pose_source`,
        /// `end_offset_ns`, …), or a dotted path in the processor configuration.
        field: String,
        /// Its value in the existing output (JSON; `absent` when it has none).
        found: String,
        /// Its value in this run (JSON; `absent` when it has none).
        expected: String,
    },
}

/// What kind of image an encoding was refused for ([`DecodeProblem::UnsupportedEncoding`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ImageKind {
    /// A colour (or grey) image.
    #[error("colour")]
    Color,
    /// A depth image.
    #[error("depth")]
    Depth,
    /// A mask.
    #[error("mask")]
    Mask,
}

/// Why a message could not be decoded ([`Error::Decode`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeProblem {
    /// The channel's schema or message type is not one that serves here.
    #[error(transparent)]
    Schema(Mismatch),
    /// The bytes are not a valid message of the channel's type.
    #[error("expected a {serialization} {message_type}: {reason}")]
    Malformed {
        /// The serialization ("protobuf", "JSON", "CDR", "ROS 1").
        serialization: &'static str,
        /// The message type.
        message_type: &'static str,
        /// The deserializer's reason.
        reason: String,
    },
    /// A field holds a value outside its range (a stamp, a pose).
    #[error(transparent)]
    Value(Mismatch),
    /// The image's encoding (or compressed format) is not one that can be read.
    #[error("unsupported {image} encoding {found:?}: supported are {supported}")]
    UnsupportedEncoding {
        /// What the image is for.
        image: ImageKind,
        /// The encoding or format string found.
        found: String,
        /// The encodings that can be read.
        supported: &'static str,
    },
    /// A raw image with no pixels.
    #[error("image is {size}: expected at least one pixel")]
    EmptyImage {
        /// The size declared.
        size: ImageSize,
    },
    /// A raw image's row step is shorter than a row of pixels.
    #[error("image step {step} is shorter than a {}-pixel row of {row_bytes} bytes", size.width)]
    RowStep {
        /// The size declared.
        size: ImageSize,
        /// The row step declared, bytes.
        step: usize,
        /// Bytes of a row of pixels.
        row_bytes: usize,
    },
    /// A raw image's data length disagrees with its size, step and encoding (`found < needed`:
    /// truncated).
    #[error(
        "image {size} with step {step} and {bytes_per_pixel} bytes per pixel needs {needed}{} bytes, \
         found {found} (width, height, step or encoding disagree with the data)",
        if needed == full { String::new() } else { format!(" or {full}") }
    )]
    ImageLength {
        /// The size declared.
        size: ImageSize,
        /// The row step declared, bytes.
        step: usize,
        /// Bytes per pixel of the encoding.
        bytes_per_pixel: usize,
        /// Bytes needed when the last row has no padding.
        needed: usize,
        /// Bytes of `height` whole rows of `step` bytes.
        full: usize,
        /// Bytes found.
        found: usize,
    },
    /// A compressed image (PNG, JPEG, compressed depth) cannot be decoded.
    #[error("cannot decode {what}: {reason}")]
    Undecodable {
        /// The image ("png image", the compressed-depth format, ...).
        what: String,
        /// The decoder's reason.
        reason: String,
    },
    /// A compressed image's header or declared size is not what its format allows.
    #[error("{what}: {mismatch}")]
    Compressed {
        /// The image ("png image", the compressed-depth format, ...).
        what: String,
        /// What was expected and found.
        mismatch: Mismatch,
    },
}

/// Why an MCAP container is not usable ([`Error::BadMcap`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum McapProblem {
    /// The path is a directory.
    #[error("expected an MCAP file, found a directory")]
    Directory,
    /// The file does not start with the MCAP magic bytes.
    #[error("not an MCAP file (expected the magic bytes \\x89MCAP0\\r\\n at the start)")]
    NoMagic,
    /// The magic is not followed by a header record.
    #[error("MCAP file does not start with a header record")]
    NoHeader,
    /// A metadata or attachment index gives a record span outside the file.
    #[error("metadata or attachment index points outside the file")]
    IndexOutsideFile {
        /// The span's offset, bytes.
        offset: u64,
        /// Its length, bytes.
        length: u64,
    },
    /// A metadata or attachment index points at a record of another kind.
    #[error("metadata or attachment index points at another record")]
    IndexWrongRecord {
        /// The record's offset, bytes.
        offset: u64,
    },
    /// A chunk is damaged (the rest of the file is intact).
    #[error(
        "damaged {}: {damage}; the other chunks are intact (`mcap recover` copies them to a new file)",
        chunk.as_ref().map_or_else(|| "a chunk".to_owned(), ToString::to_string)
    )]
    DamagedChunk {
        /// Where the chunk is and what it held, when its index is known.
        chunk: Option<Box<ChunkPlace>>,
        /// What is wrong with it.
        damage: ChunkDamage,
    },
}

/// Where a damaged chunk is and what it held ([`McapProblem::DamagedChunk`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChunkPlace {
    /// Offset of the chunk record, bytes.
    pub start_offset: u64,
    /// Messages it holds, from its message indexes (`None` when they cannot be read).
    pub messages: Option<u64>,
    /// Log time of its first message, nanoseconds.
    pub message_start_time_ns: u64,
    /// Log time of its last message, nanoseconds.
    pub message_end_time_ns: u64,
    /// Its compression ("" for none).
    pub compression: String,
}

impl std::fmt::Display for ChunkPlace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "chunk at byte {}", self.start_offset)?;
        if let Some(n) = self.messages {
            write!(f, " holding {n} messages")?;
        }
        write!(
            f,
            " (messages logged from {} to {} s, compression {:?})",
            crate::time::format_ns_as_seconds(self.message_start_time_ns, 6),
            crate::time::format_ns_as_seconds(self.message_end_time_ns, 6),
            self.compression
        )
    }
}

/// What is wrong with a damaged chunk ([`McapProblem::DamagedChunk`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ChunkDamage {
    /// The chunk index points past the end of the file.
    #[error("its index points past the end of the file")]
    PastEnd,
    /// No chunk record at the offset the index gives.
    #[error("expected a chunk record at the offset its index gives")]
    NotAChunk,
    /// The data does not decompress (or the compression is unknown).
    #[error("{reason}")]
    Decompression {
        /// The MCAP reader's reason.
        reason: String,
    },
    /// The data's CRC is not the one in the chunk header.
    #[error(
        "CRC mismatch: expected {expected:#010x} from the chunk header, computed {computed:#010x} from its data"
    )]
    CrcMismatch {
        /// The CRC in the chunk header.
        expected: u32,
        /// The CRC of the data.
        computed: u32,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_mcap_io_error_names_the_os_error_once() {
        let os_error = std::io::Error::new(std::io::ErrorKind::StorageFull, "No space left on device");
        let error = Error::from(mcap::McapError::Io(os_error));
        let message = error.to_string();
        assert_eq!(
            message,
            "MCAP: I/O error from writing, or reading a compression stream: No space left on device"
        );
        assert!(std::error::Error::source(&error).is_none());
        // As the CLI prints it: the whole chain, each part once.
        let chained = format!("{:#}", anyhow::Error::new(error).context("processing in.mcap"));
        assert_eq!(chained, format!("processing in.mcap: {message}"));
        // A variant without a cause keeps the library's message alone.
        assert_eq!(
            Error::from(mcap::McapError::UnexpectedEof).to_string(),
            format!("MCAP: {}", mcap::McapError::UnexpectedEof)
        );
    }
}
