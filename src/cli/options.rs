//! Options and value parsers shared by several subcommands (one definition, flattened into each
//! command's clap struct, so flag names, defaults and help stay the same everywhere).

use clap::{Args as ClapArgs, ValueEnum};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use occmask::dataset;
use occmask::mcap_io::writer::{
    DEFAULT_CHUNK_SIZE_BYTES, DEFAULT_COMPRESSION_LEVEL, DEFAULT_COMPRESSION_THREADS,
};
use occmask::mcap_io::{Compression, McapWriteOptions};

/// Chunk compression choices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CompressionArg {
    /// Smallest files.
    Zstd,
    /// Faster, larger.
    Lz4,
    /// No compression.
    None,
}

/// How the output MCAP is written (`convert` and `process`).
#[derive(Debug, Clone, ClapArgs)]
pub struct WriteArgs {
    /// Chunk compression.
    #[arg(long, value_enum, default_value_t = CompressionArg::Zstd)]
    pub compression: CompressionArg,

    /// Compression level (0 = the codec's default, 3 for zstd; 19 is smallest and slowest;
    /// negative levels are the fast ones: -N is `zstd --fast=N`, lz4's acceleration N+1).
    #[arg(long, default_value_t = DEFAULT_COMPRESSION_LEVEL, allow_negative_numbers = true)]
    pub compression_level: i32,

    /// Uncompressed chunk size, MiB (at most 1024: a chunk is held in memory while written).
    #[arg(long, value_parser = parse_chunk_size_mib, default_value_t = (DEFAULT_CHUNK_SIZE_BYTES >> 20) as f64)]
    pub chunk_size_mib: f64,

    /// zstd worker threads (0 = compress on the writing thread).
    #[arg(long, default_value_t = DEFAULT_COMPRESSION_THREADS)]
    pub compression_threads: u32,
}

impl WriteArgs {
    /// The library's write options.
    pub fn options(&self) -> McapWriteOptions {
        McapWriteOptions {
            compression: match self.compression {
                CompressionArg::Zstd => Compression::Zstd,
                CompressionArg::Lz4 => Compression::Lz4,
                CompressionArg::None => Compression::None,
            },
            compression_level: self.compression_level,
            chunk_size_bytes: (self.chunk_size_mib * 1024.0 * 1024.0) as u64,
            compression_threads: self.compression_threads,
        }
    }
}

/// `--camera`: a preset name or FX,FY,CX,CY, checked at parse time.
pub fn parse_camera_arg(text: &str) -> Result<String, String> {
    dataset::parse_camera(text)
        .map(|_| text.to_owned())
        .map_err(|e| e.to_string())
}

/// A rigid transform `X,Y,Z,QX,QY,QZ,QW`: translation in metres, then a unit quaternion
/// (`--depth-to-color`, `--camera-from-marker`), or a preset name
/// ([`dataset::camera_from_marker_preset`]), checked at parse time.
pub fn parse_pose(text: &str) -> Result<Isometry3<f64>, String> {
    // Hand-typed quaternions carry 4–6 digits; anything further from unit length is a typo.
    const MAX_QUATERNION_NORM_ERROR: f64 = 1e-3;
    let bad =
        |why: &str| format!("expected X,Y,Z,QX,QY,QZ,QW (metres, unit quaternion), found {text:?}: {why}");
    let values: Vec<f64> = match dataset::camera_from_marker_preset(text) {
        Some(preset) => preset.to_vec(),
        None => text
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad("not 7 numbers"))?,
    };
    let [x, y, z, qx, qy, qz, qw] = values[..] else {
        return Err(bad(&format!("{} numbers", values.len())));
    };
    if !values.iter().all(|v| v.is_finite()) {
        return Err(bad("not finite"));
    }
    let q = Quaternion::new(qw, qx, qy, qz);
    if (q.norm() - 1.0).abs() > MAX_QUATERNION_NORM_ERROR {
        return Err(bad(&format!("the quaternion's norm is {}", q.norm())));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// A finite number > 0.
pub fn parse_positive(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a positive number, found {text:?}")),
    }
}

/// A finite number >= 0.
pub fn parse_non_negative(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("expected a number >= 0, found {text:?}")),
    }
}

/// Largest `--max-pair-gap-ms`: frames a minute apart are no colour/depth pair, and the value
/// must stay far from overflowing the nanosecond stamps it is added to.
pub const MAX_PAIR_GAP_MS: f64 = 60_000.0;

/// `--max-pair-gap-ms`: milliseconds from 0 to [`MAX_PAIR_GAP_MS`].
pub fn parse_pair_gap_ms(text: &str) -> Result<f64, String> {
    parse_non_negative(text)
        .ok()
        .filter(|&v| v <= MAX_PAIR_GAP_MS)
        .ok_or_else(|| {
            format!("expected milliseconds from 0 to {MAX_PAIR_GAP_MS} (one minute), found {text:?}")
        })
}

/// Largest `--chunk-size-mib`.
pub const MAX_CHUNK_SIZE_MIB: f64 = 1024.0;

/// `--chunk-size-mib`: a number > 0 and at most [`MAX_CHUNK_SIZE_MIB`].
pub fn parse_chunk_size_mib(text: &str) -> Result<f64, String> {
    parse_positive(text)
        .ok()
        .filter(|&v| v <= MAX_CHUNK_SIZE_MIB)
        .ok_or_else(|| {
            format!("expected a size in MiB above 0 and at most {MAX_CHUNK_SIZE_MIB}, found {text:?}")
        })
}

/// Largest count of files in flight or of threads per file.
pub const MAX_COUNT: usize = 1024;

/// A whole number from 1 to [`MAX_COUNT`] (counts of files or threads).
pub fn parse_at_least_one(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(v) if (1..=MAX_COUNT).contains(&v) => Ok(v),
        _ => Err(format!(
            "expected a whole number from 1 to {MAX_COUNT}, found {text:?}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        write: WriteArgs,
    }

    #[test]
    fn defaults_are_the_library_defaults() {
        let cli = Cli::try_parse_from(["x"]).unwrap();
        assert_eq!(cli.write.options(), McapWriteOptions::default());
    }

    #[test]
    fn flags_map_to_write_options() {
        let cli = Cli::try_parse_from([
            "x",
            "--compression",
            "lz4",
            "--compression-level",
            "5",
            "--chunk-size-mib",
            "0.5",
            "--compression-threads",
            "0",
        ])
        .unwrap();
        let o = cli.write.options();
        assert_eq!(o.compression, Compression::Lz4);
        assert_eq!(o.compression_level, 5);
        assert_eq!(o.chunk_size_bytes, 512 * 1024);
        assert_eq!(o.compression_threads, 0);
        assert!(Cli::try_parse_from(["x", "--chunk-size-mib", "0"]).is_err());
        // The codecs' fast levels are negative.
        let fast = Cli::try_parse_from(["x", "--compression-level", "-3"]).unwrap();
        assert_eq!(fast.write.options().compression_level, -3);
    }

    #[test]
    fn parsers_reject_what_they_must() {
        assert_eq!(parse_positive("2.5"), Ok(2.5));
        assert!(parse_positive("0").is_err() && parse_positive("nan").is_err());
        assert_eq!(parse_non_negative("0"), Ok(0.0));
        assert!(parse_non_negative("-1").is_err() && parse_non_negative("inf").is_err());
        assert!(parse_camera_arg("fr2").is_ok() && parse_camera_arg("banana").is_err());
        assert_eq!(parse_at_least_one("3"), Ok(3));
        assert!(parse_at_least_one("0").is_err() && parse_at_least_one("-1").is_err());
        assert!(parse_at_least_one("1.5").is_err() && parse_at_least_one("1025").is_err());
        assert_eq!(parse_pair_gap_ms("60000"), Ok(60_000.0));
        assert!(parse_pair_gap_ms("1e300").is_err() && parse_pair_gap_ms("60000.5").is_err());
        assert!(parse_pair_gap_ms("-1").is_err() && parse_pair_gap_ms("nan").is_err());
        assert_eq!(parse_chunk_size_mib("1024"), Ok(1024.0));
        assert!(parse_chunk_size_mib("1e300").is_err() && parse_chunk_size_mib("0").is_err());
        let pose = parse_pose("0.015, 0, 0, 0, 0, 0.7071068, 0.7071068").unwrap();
        assert!((pose.translation.vector.x - 0.015).abs() < 1e-12);
        assert!((pose.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        assert!(parse_pose("bonn").is_ok());
        for bad in ["1,2,3", "0,0,0,0,0,0,2", "0,0,0,0,0,0,nan", "a,0,0,0,0,0,1"] {
            assert!(parse_pose(bad).is_err(), "{bad}");
        }
    }
}
