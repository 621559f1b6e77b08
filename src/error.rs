//! The library's one error type.
//!
//! Every variant says what was expected and what was found. Variants that come from a
//! user-supplied file carry its path (last in the message) and, for text files, the line.

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
    #[error("line {line}: {message} (in {})", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was expected and what was found.
        message: String,
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
    #[error("{message} ({})", path.display())]
    BadImage {
        /// The file.
        path: PathBuf,
        /// What was expected and what was found.
        message: String,
    },

    /// A dataset folder is not usable as a whole (missing files, empty sequence, ...).
    #[error("{message} ({})", path.display())]
    Dataset {
        /// The dataset folder or file.
        path: PathBuf,
        /// What was expected and what was found.
        message: String,
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
    #[error("topic {topic}: {message}")]
    Decode {
        /// The channel's topic.
        topic: String,
        /// What was expected and what was found.
        message: String,
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
        /// What registering needs and the flags that give it.
        needed: String,
    },

    /// No transform between the depth camera's and the colour camera's frames.
    #[error(
        "no transform from the depth frame {depth_frame:?} to the colour frame {color_frame:?} \
         ({searched}); pass --depth-to-color X,Y,Z,QX,QY,QZ,QW (the depth camera's pose in the \
         colour camera's frame: translation in metres, then the rotation quaternion), or \
         --depth-aligned if the depth is already registered to colour"
    )]
    MissingTransform {
        /// The depth image's `frame_id`.
        depth_frame: String,
        /// The colour image's `frame_id`.
        color_frame: String,
        /// Which channels were searched and which frames they hold.
        searched: String,
    },

    /// The MCAP library reported an error.
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),

    /// The caller asked to stop (e.g. Ctrl-C); partial output is discarded.
    #[error("interrupted after {done} of {total} items; no output was written")]
    Interrupted {
        /// Items finished.
        done: usize,
        /// Items planned.
        total: usize,
    },

    /// The operating system refused to start worker threads.
    #[error("cannot start a pool of {threads} worker thread(s): {message}")]
    ThreadPool {
        /// Threads asked for.
        threads: usize,
        /// The reason given.
        message: String,
    },
}

impl Error {
    /// Builds an [`Error::Io`] for `path`.
    pub fn io(action: impl Into<String>, path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            action: action.into(),
            path: path.into(),
            os_error: source,
        }
    }
}
