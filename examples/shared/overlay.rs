//! Error overlays shared by the measurement examples.

/// A pixel of an error overlay over a gray level `g`: true positives green, false positives
/// red, misses blue, the rest gray.
pub fn error_colour(g: u8, marked: bool, truth: bool) -> [u8; 3] {
    match (marked, truth) {
        (true, true) => [g / 3, 255, g / 3],
        (true, false) => [255, g / 3, g / 3],
        (false, true) => [g / 3, g / 3, 255],
        (false, false) => [g, g, g],
    }
}
