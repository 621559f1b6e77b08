//! Timestamps as integer nanoseconds, parsed from and printed as decimal seconds.
//!
//! Dataset stamps such as `1311868164.363181` are parsed from their decimal text directly
//! into integer nanoseconds, never through `f64` (which rounds by ~240 ns at 1.3e9 s and
//! would make re-runs differ).

use crate::error::Mismatch;

const NANOS_PER_SECOND: u64 = 1_000_000_000;
/// Digits after the decimal point that fit in nanoseconds.
const NANO_DIGITS: usize = 9;

/// Parses non-negative decimal seconds (`"1311868164.363181"`, `"12"`, `"1.5e0"` is rejected)
/// into nanoseconds. Digits beyond the ninth decimal must be zero, so no precision is lost.
///
/// # Errors
/// What was expected and what was found (the caller adds the file and line).
pub fn parse_seconds_to_ns(text: &str) -> Result<u64, Mismatch> {
    let bad = || {
        Mismatch::new(
            "a timestamp in decimal seconds such as 1311868164.363181",
            format!("{text:?}"),
        )
    };
    let (int_part, frac_part) = match text.split_once('.') {
        Some((i, f)) => (i, f),
        None => (text, ""),
    };
    if int_part.is_empty() && frac_part.is_empty() {
        return Err(bad());
    }
    if !int_part.bytes().all(|b| b.is_ascii_digit()) || !frac_part.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad());
    }
    let seconds: u64 = if int_part.is_empty() {
        0
    } else {
        int_part.parse().map_err(|_| bad())?
    };
    let (kept, extra) = frac_part.split_at(frac_part.len().min(NANO_DIGITS));
    if extra.bytes().any(|b| b != b'0') {
        return Err(Mismatch::new(
            "a timestamp with at most nanosecond precision (9 decimals)",
            format!("{text:?}"),
        ));
    }
    let mut nanos: u64 = 0;
    for b in kept.bytes() {
        nanos = nanos * 10 + u64::from(b - b'0');
    }
    nanos *= 10u64.pow((NANO_DIGITS - kept.len()) as u32);
    seconds
        .checked_mul(NANOS_PER_SECOND)
        .and_then(|s| s.checked_add(nanos))
        .ok_or_else(|| Mismatch::new("a timestamp up to about 1.8e10 s", format!("{text:?}")))
}

/// Formats nanoseconds as decimal seconds with at least `min_decimals` digits after the point
/// (trailing zeros beyond that are dropped), so the text parses back to the same nanoseconds.
pub fn format_ns_as_seconds(timestamp_ns: u64, min_decimals: usize) -> String {
    let secs = timestamp_ns / NANOS_PER_SECOND;
    let nanos = timestamp_ns % NANOS_PER_SECOND;
    let mut frac = format!("{nanos:09}");
    while frac.len() > min_decimals.min(NANO_DIGITS) && frac.ends_with('0') {
        frac.pop();
    }
    if frac.is_empty() {
        secs.to_string()
    } else {
        format!("{secs}.{frac}")
    }
}

/// Splits nanoseconds into (seconds, nanoseconds) as Foxglove's `Timestamp` wants them.
///
/// Saturates the seconds at `u32::MAX` (year 2106).
pub fn split_ns(timestamp_ns: u64) -> (u32, u32) {
    let secs = (timestamp_ns / NANOS_PER_SECOND).min(u64::from(u32::MAX)) as u32;
    (secs, (timestamp_ns % NANOS_PER_SECOND) as u32)
}

/// Joins (seconds, nanoseconds) into nanoseconds. `seconds` must be below about 1.8e10
/// (always true for `u32` seconds); use [`checked_join_ns`] for untrusted 64-bit seconds.
pub fn join_ns(seconds: u64, nanos: u32) -> u64 {
    seconds * NANOS_PER_SECOND + u64::from(nanos)
}

/// [`join_ns`], or `None` when the result does not fit in `u64` nanoseconds.
pub fn checked_join_ns(seconds: u64, nanos: u32) -> Option<u64> {
    seconds
        .checked_mul(NANOS_PER_SECOND)
        .and_then(|s| s.checked_add(u64::from(nanos)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_tum_stamps_exactly() {
        assert_eq!(
            parse_seconds_to_ns("1311868164.363181"),
            Ok(1_311_868_164_363_181_000)
        );
        assert_eq!(
            parse_seconds_to_ns("1311868163.8697"),
            Ok(1_311_868_163_869_700_000)
        );
        assert_eq!(parse_seconds_to_ns("1.000000"), Ok(1_000_000_000));
        assert_eq!(parse_seconds_to_ns("12"), Ok(12_000_000_000));
        assert_eq!(parse_seconds_to_ns(".5"), Ok(500_000_000));
        assert_eq!(parse_seconds_to_ns("0.1234567890"), Ok(123_456_789));
    }

    #[test]
    fn rejects_malformed() {
        for bad in [
            "",
            ".",
            "-1.0",
            "1e9",
            "abc",
            "1.2.3",
            " 1",
            "1.0000000001",
            "99999999999.0",
        ] {
            assert!(parse_seconds_to_ns(bad).is_err(), "{bad:?} should be rejected");
        }
    }

    #[test]
    fn format_round_trips() {
        for ns in [
            0u64,
            1,
            1_311_868_164_363_181_000,
            1_311_868_163_869_700_000,
            999_999_999,
        ] {
            let text = format_ns_as_seconds(ns, 6);
            assert_eq!(parse_seconds_to_ns(&text), Ok(ns), "{text}");
        }
        assert_eq!(
            format_ns_as_seconds(1_311_868_164_363_181_000, 6),
            "1311868164.363181"
        );
        assert_eq!(format_ns_as_seconds(1_000_000_000, 6), "1.000000");
        assert_eq!(format_ns_as_seconds(1_000_000_001, 6), "1.000000001");
    }

    #[test]
    fn split_and_join() {
        let ns = 1_311_868_164_363_181_000;
        let (s, n) = split_ns(ns);
        assert_eq!(join_ns(u64::from(s), n), ns);
    }
}
