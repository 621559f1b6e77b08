//! Timestamped camera poses: chaining inter-frame motions, TUM text, interpolation.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::error::Mismatch;
use crate::time::{format_ns_as_seconds, parse_seconds_to_ns};

/// A camera pose at a time: `world_from_camera` maps camera-frame points into the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Time of the pose, nanoseconds.
    pub timestamp_ns: u64,
    /// Pose of the camera's optical frame in the world.
    pub world_from_camera: Isometry3<f64>,
}

/// Chains one more inter-frame motion onto a pose:
/// C_{i+1} = C_i · (current_from_reference)⁻¹ (see [`crate::geometry`]).
pub fn chain(
    world_from_reference: &Isometry3<f64>,
    current_from_reference: &Isometry3<f64>,
) -> Isometry3<f64> {
    world_from_reference * current_from_reference.inverse()
}

/// The motion between two poses in the convention of [`chain`]: C_{i+1}⁻¹ · C_i.
pub fn motion_between(
    world_from_reference: &Isometry3<f64>,
    world_from_current: &Isometry3<f64>,
) -> Isometry3<f64> {
    world_from_current.inverse() * world_from_reference
}

/// One TUM trajectory line: `timestamp tx ty tz qx qy qz qw` (timestamp in seconds).
pub fn tum_line(pose: &StampedPose) -> String {
    let t = pose.world_from_camera.translation.vector;
    let q = pose.world_from_camera.rotation;
    format!(
        "{} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
        format_ns_as_seconds(pose.timestamp_ns, 6),
        t.x,
        t.y,
        t.z,
        q.i,
        q.j,
        q.k,
        q.w
    )
}

/// The comment line that starts a TUM trajectory file.
pub const TUM_HEADER: &str = "# timestamp tx ty tz qx qy qz qw";

/// A TUM trajectory file's text: [`TUM_HEADER`], then one [`tum_line`] per pose.
pub fn to_tum_text(poses: &[StampedPose]) -> String {
    let mut out = format!("{TUM_HEADER}\n");
    for p in poses {
        out.push_str(&tum_line(p));
        out.push('\n');
    }
    out
}

/// Largest accepted deviation of a quaternion's norm from 1 before it is called malformed.
/// TUM files print 4 decimals, so a norm within 1e-3 is rounding; anything further is a bug
/// in the producer, not something to normalise silently.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-2;

/// Parses one TUM pose line (`timestamp tx ty tz qx qy qz qw`, whitespace separated).
///
/// # Errors
/// What was expected and what was found (the caller adds file and line).
pub fn parse_tum_line(line: &str) -> Result<StampedPose, Mismatch> {
    let fields: Vec<&str> = line.split_whitespace().collect();
    if fields.len() != 8 {
        return Err(Mismatch::new(
            "8 fields 'timestamp tx ty tz qx qy qz qw'",
            fields.len().to_string(),
        ));
    }
    let timestamp_ns = parse_seconds_to_ns(fields[0])?;
    let mut v = [0.0f64; 7];
    for (i, f) in fields[1..].iter().enumerate() {
        let x: f64 = f
            .parse()
            .map_err(|_| Mismatch::new(format!("a number in field {}", i + 2), format!("{f:?}")))?;
        if !x.is_finite() {
            return Err(Mismatch::new(
                format!("a finite number in field {}", i + 2),
                format!("{f:?}"),
            ));
        }
        v[i] = x;
    }
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(Mismatch::new(
            "a unit quaternion qx qy qz qw",
            format!("one of norm {norm:.4}"),
        ));
    }
    Ok(StampedPose {
        timestamp_ns,
        world_from_camera: Isometry3::from_parts(
            Translation3::new(v[0], v[1], v[2]),
            UnitQuaternion::from_quaternion(q),
        ),
    })
}

/// The pose at `timestamp_ns`, linearly interpolated in translation and slerped in rotation
/// between the two samples around it. `poses` must be sorted by time. `None` outside the
/// covered interval or when the bracketing samples are more than `max_gap_ns` apart.
pub fn interpolate(poses: &[StampedPose], timestamp_ns: u64, max_gap_ns: u64) -> Option<Isometry3<f64>> {
    let idx = poses.partition_point(|p| p.timestamp_ns < timestamp_ns);
    if let Some(p) = poses.get(idx) {
        if p.timestamp_ns == timestamp_ns {
            return Some(p.world_from_camera);
        }
    }
    if idx == 0 || idx >= poses.len() {
        return None;
    }
    let (a, b) = (&poses[idx - 1], &poses[idx]);
    let gap = b.timestamp_ns - a.timestamp_ns;
    if gap > max_gap_ns {
        return None;
    }
    let s = (timestamp_ns - a.timestamp_ns) as f64 / gap as f64;
    let ta = a.world_from_camera.translation.vector;
    let tb = b.world_from_camera.translation.vector;
    let rotation = a
        .world_from_camera
        .rotation
        .slerp(&b.world_from_camera.rotation, s);
    Some(Isometry3::from_parts(
        Translation3::from(ta + (tb - ta) * s),
        rotation,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{se3_exp, Twist};
    use approx::assert_relative_eq;

    #[test]
    fn chain_then_motion_between_round_trips() {
        let c0 = se3_exp(&Twist::new(0.1, -0.2, 1.0, 0.2, 0.1, -0.3));
        let m = se3_exp(&Twist::new(0.02, 0.01, -0.03, 0.01, -0.02, 0.005));
        let c1 = chain(&c0, &m);
        assert_relative_eq!(
            motion_between(&c0, &c1).to_homogeneous(),
            m.to_homogeneous(),
            epsilon = 1e-12
        );
        // The motion maps a point expressed in camera 0 into camera 1 coordinates.
        let p_world = nalgebra::Point3::new(0.5, 0.2, 3.0);
        let p0 = c0.inverse() * p_world;
        let p1 = c1.inverse() * p_world;
        assert_relative_eq!(m * p0, p1, epsilon = 1e-12);
    }

    #[test]
    fn tum_line_round_trips() {
        let pose = StampedPose {
            timestamp_ns: 1_311_868_164_363_181_000,
            world_from_camera: se3_exp(&Twist::new(0.1, -1.4, 1.5, 0.3, -0.2, 2.0)),
        };
        let back = parse_tum_line(&tum_line(&pose)).unwrap();
        assert_eq!(back.timestamp_ns, pose.timestamp_ns);
        assert_relative_eq!(
            back.world_from_camera.to_homogeneous(),
            pose.world_from_camera.to_homogeneous(),
            epsilon = 1e-8
        );
    }

    #[test]
    fn tum_line_errors_say_what_is_wrong() {
        assert!(parse_tum_line("1.0 1 2 3")
            .unwrap_err()
            .to_string()
            .contains("found 4"));
        assert!(parse_tum_line("1.0 1 2 x 0 0 0 1")
            .unwrap_err()
            .to_string()
            .contains("field 4"));
        assert!(parse_tum_line("1.0 1 2 3 0 0 0 2")
            .unwrap_err()
            .to_string()
            .contains("norm 2.0000"));
        assert!(parse_tum_line("1.0 1 2 NaN 0 0 0 1")
            .unwrap_err()
            .to_string()
            .contains("finite"));
    }

    #[test]
    fn interpolation_hits_samples_and_midpoints() {
        let a = StampedPose {
            timestamp_ns: 100,
            world_from_camera: se3_exp(&Twist::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
        };
        let b = StampedPose {
            timestamp_ns: 200,
            world_from_camera: se3_exp(&Twist::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.2)),
        };
        let poses = [a, b];
        assert_eq!(interpolate(&poses, 100, 1000), Some(a.world_from_camera));
        assert_eq!(interpolate(&poses, 200, 1000), Some(b.world_from_camera));
        let mid = interpolate(&poses, 150, 1000).unwrap();
        assert_relative_eq!(mid.rotation.angle(), 0.1, epsilon = 1e-12);
        assert_relative_eq!(
            mid.translation.vector.x,
            b.world_from_camera.translation.vector.x / 2.0,
            epsilon = 1e-12
        );
        assert!(interpolate(&poses, 99, 1000).is_none());
        assert!(interpolate(&poses, 201, 1000).is_none());
        assert!(interpolate(&poses, 150, 50).is_none());
    }
}
