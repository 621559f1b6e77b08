//! Outlines of mask regions as polygons, for `foxglove.ImageAnnotations`.
//!
//! The outline follows pixel borders: vertices are pixel corners, `(0, 0)` is the top-left
//! corner of the top-left pixel and `(width, height)` the bottom-right corner of the image.
//! Every border between a set pixel and an unset one (or the image edge) is a directed edge
//! with the set pixel on its right-hand side as seen on screen (y down); chaining the edges
//! gives closed loops, clockwise on screen around regions and counter-clockwise around holes.
//! Where two regions touch only at a corner the walk turns left, so diagonal neighbours belong
//! to one region (8-connectivity, like the detector's labelling). Outer loops are then
//! simplified with Douglas–Peucker so staircases become a few segments.

use crate::image_buf::{Mask, MASK_SET};

/// A closed polygon in pixel-corner coordinates (the last vertex connects to the first).
pub type Polygon = Vec<[f64; 2]>;

/// Options of `outer_contours`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourOptions {
    /// Regions with a smaller enclosed area (pixels) are dropped as noise.
    pub min_area_px: f64,
    /// Douglas–Peucker tolerance in pixels: 1 px removes the staircase of diagonal borders
    /// while staying within one pixel of the true border.
    pub simplify_tolerance_px: f64,
    /// At most this many polygons (largest first), so one noisy frame cannot produce a huge
    /// message.
    pub max_polygons: usize,
}

impl Default for ContourOptions {
    fn default() -> Self {
        Self {
            min_area_px: 16.0,
            simplify_tolerance_px: 1.0,
            max_polygons: 64,
        }
    }
}

// Directions as bits: right (+x), down (+y), left (−x), up (−y), in clockwise order on screen.
const DIRS: [(i64, i64); 4] = [(1, 0), (0, 1), (-1, 0), (0, -1)];

/// Signed area (shoelace) in screen coordinates: positive for clockwise-on-screen loops.
pub fn signed_area(polygon: &[[f64; 2]]) -> f64 {
    let n = polygon.len();
    let mut twice = 0.0;
    for i in 0..n {
        let [x0, y0] = polygon[i];
        let [x1, y1] = polygon[(i + 1) % n];
        twice += x0 * y1 - x1 * y0;
    }
    twice / 2.0
}

/// All boundary loops of the set pixels, as corner lists (only direction changes kept).
/// Outer loops have positive [`signed_area`], holes negative.
pub fn boundary_loops(mask: &Mask) -> Vec<Polygon> {
    let (mut out, mut edges) = boundary_edges(mask);
    let vw = mask.width() + 1;
    let mut loops = Vec::new();
    let mut start_index = 0;
    while edges > 0 {
        start_index = first_nonzero_from(&out, start_index);
        let (sx, sy) = ((start_index % vw) as i64, (start_index / vw) as i64);
        let mut dir = out[start_index].trailing_zeros() as usize;
        let (mut x, mut y) = (sx, sy);
        let mut polygon = Vec::new();
        let mut previous_dir = usize::MAX;
        loop {
            let v = y as usize * vw + x as usize;
            out[v] &= !(1 << dir);
            edges -= 1;
            if dir != previous_dir {
                polygon.push([x as f64, y as f64]);
            }
            previous_dir = dir;
            x += DIRS[dir].0;
            y += DIRS[dir].1;
            let next = out[y as usize * vw + x as usize];
            if next == 0 {
                break; // back at the start with every edge of the loop used
            }
            // Prefer turning left, then straight, then right (8-connectivity at saddles).
            let left = (dir + 3) % 4;
            let right = (dir + 1) % 4;
            dir = [left, dir, right]
                .into_iter()
                .find(|d| next & (1 << d) != 0)
                .unwrap_or(next.trailing_zeros() as usize);
        }
        // The start vertex is a corner unless the loop entered it going straight.
        if polygon.len() > 1 && previous_dir == out_dir_of(&polygon) {
            polygon.remove(0);
        }
        loops.push(polygon);
    }
    loops
}

/// Out-edges per pixel corner (row-major over the `(width + 1) × (height + 1)` corners) as a
/// 4-bit set of [`DIRS`] indices, and their count: each border of a set pixel, directed with
/// the pixel on its right-hand side.
fn boundary_edges(mask: &Mask) -> (Vec<u8>, usize) {
    let (w, h) = (mask.width(), mask.height());
    let vw = w + 1;
    let mut out = vec![0u8; vw * (h + 1)];
    let mut edges = 0usize;
    if w == 0 || h == 0 {
        return (out, edges);
    }
    let rows: Vec<&[u8]> = mask.as_slice().chunks_exact(w).take(h).collect();
    let outside = vec![0u8; w];
    for (y, &row) in rows.iter().enumerate() {
        let above = if y > 0 { rows[y - 1] } else { &outside[..] };
        let below = rows.get(y + 1).copied().unwrap_or(&outside[..]);
        let (upper, lower) = out.split_at_mut((y + 1) * vw);
        let (corners_above, corners_below) = (&mut upper[y * vw..], &mut lower[..vw]);
        // Runs of set pixels: a left border at the run's first pixel, a right border at its
        // last, and top and bottom borders wherever the row above or below is not set.
        let mut x = 0;
        while let Some(offset) = row[x..].iter().position(|&v| v == MASK_SET) {
            let start = x + offset;
            let end = row[start..]
                .iter()
                .position(|&v| v != MASK_SET)
                .map_or(w, |n| start + n);
            // Left border walking up from (start, y + 1), right border walking down from (end, y).
            corners_below[start] |= 1 << 3;
            corners_above[end] |= 1 << 1;
            edges += 2;
            // Top borders walk right from (x, y), bottom borders walk left from (x + 1, y + 1).
            for (((corner_above, corner_below), &a), &b) in corners_above[start..end]
                .iter_mut()
                .zip(&mut corners_below[start + 1..=end])
                .zip(&above[start..end])
                .zip(&below[start..end])
            {
                let (top, bottom) = (u8::from(a != MASK_SET), u8::from(b != MASK_SET));
                *corner_above |= top;
                *corner_below |= bottom << 2;
                edges += usize::from(top + bottom);
            }
            x = end;
        }
    }
    (out, edges)
}

/// Index of the first nonzero byte of `bytes` at or after `from` (`bytes.len()` if none), eight
/// bytes at a time: the corner grid is mostly zero.
fn first_nonzero_from(bytes: &[u8], from: usize) -> usize {
    let mut i = from;
    while !i.is_multiple_of(8) && i < bytes.len() {
        if bytes[i] != 0 {
            return i;
        }
        i += 1;
    }
    for word in bytes[i..].chunks_exact(8) {
        let value = u64::from_le_bytes([
            word[0], word[1], word[2], word[3], word[4], word[5], word[6], word[7],
        ]);
        if value != 0 {
            return i + value.trailing_zeros() as usize / 8;
        }
        i += 8;
    }
    bytes[i..]
        .iter()
        .position(|&b| b != 0)
        .map_or(bytes.len(), |n| i + n)
}

fn out_dir_of(polygon: &[[f64; 2]]) -> usize {
    let [x0, y0] = polygon[0];
    let [x1, y1] = polygon[1];
    let (dx, dy) = ((x1 - x0).signum() as i64, (y1 - y0).signum() as i64);
    DIRS.iter().position(|&d| d == (dx, dy)).unwrap_or(usize::MAX)
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    if len2 == 0.0 {
        return ((p[0] - a[0]).powi(2) + (p[1] - a[1]).powi(2)).sqrt();
    }
    ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len2.sqrt()
}

fn douglas_peucker(points: &[[f64; 2]], tolerance: f64, out: &mut Vec<[f64; 2]>) {
    // Iterative, with an explicit stack: contours can have thousands of vertices.
    let n = points.len();
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0, n - 1)];
    while let Some((a, b)) = stack.pop() {
        let mut best = (0.0, 0);
        for i in a + 1..b {
            let d = point_segment_distance(points[i], points[a], points[b]);
            if d > best.0 {
                best = (d, i);
            }
        }
        if best.0 > tolerance {
            keep[best.1] = true;
            stack.push((a, best.1));
            stack.push((best.1, b));
        }
    }
    out.extend(points.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p));
}

/// Simplifies a closed polygon: splits it at the vertex farthest from the first one and runs
/// Douglas–Peucker on both halves.
pub fn simplify_closed(polygon: &[[f64; 2]], tolerance: f64) -> Polygon {
    if polygon.len() <= 4 {
        return polygon.to_vec();
    }
    let far = (1..polygon.len())
        .max_by(|&i, &j| {
            let d =
                |k: usize| (polygon[k][0] - polygon[0][0]).powi(2) + (polygon[k][1] - polygon[0][1]).powi(2);
            d(i).total_cmp(&d(j))
        })
        .unwrap_or(1);
    let mut first_half = polygon[..=far].to_vec();
    let mut second_half = polygon[far..].to_vec();
    second_half.push(polygon[0]);
    let mut out = Vec::new();
    douglas_peucker(&first_half, tolerance, &mut out);
    out.pop(); // `far` starts the second half
    first_half.clear();
    douglas_peucker(&second_half, tolerance, &mut out);
    out.pop(); // the closing copy of the first vertex
    out
}

/// Outer outlines of the mask's regions, largest first, simplified (holes are not returned:
/// a filled outline reads better in the viewer than a ring).
pub fn outer_contours(mask: &Mask, options: &ContourOptions) -> Vec<Polygon> {
    let mut outer: Vec<(f64, Polygon)> = boundary_loops(mask)
        .into_iter()
        .map(|p| (signed_area(&p), p))
        .filter(|(area, _)| *area >= options.min_area_px)
        .collect();
    outer.sort_by(|a, b| b.0.total_cmp(&a.0));
    outer.truncate(options.max_polygons);
    outer
        .into_iter()
        .map(|(_, p)| simplify_closed(&p, options.simplify_tolerance_px))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_buf::ImageSize;
    use crate::xorshift::XorShift64;

    fn mask_from(rows: &[&str]) -> Mask {
        let size = ImageSize::new(rows[0].len(), rows.len());
        Mask::from_fn(size, |x, y| {
            if rows[y].as_bytes()[x] == b'#' {
                MASK_SET
            } else {
                0
            }
        })
    }

    #[test]
    fn rectangle_gives_its_four_corners_clockwise() {
        let m = mask_from(&["......", ".###..", ".###..", "......"]);
        let loops = boundary_loops(&m);
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0], vec![[1.0, 1.0], [4.0, 1.0], [4.0, 3.0], [1.0, 3.0]]);
        assert_eq!(signed_area(&loops[0]), 6.0);
    }

    #[test]
    fn loop_areas_equal_pixel_counts_for_random_masks() {
        // Law: outer areas minus hole areas = number of set pixels, for any mask.
        let mut rng = XorShift64::new(12345);
        for _ in 0..50 {
            let m = Mask::from_fn(ImageSize::new(23, 17), |_, _| {
                if rng.below(3) == 0 {
                    MASK_SET
                } else {
                    0
                }
            });
            let total: f64 = boundary_loops(&m).iter().map(|p| signed_area(p)).sum();
            let count = m.as_slice().iter().filter(|&&v| v == MASK_SET).count();
            assert_eq!(total, count as f64);
        }
    }

    /// The run-based corner grid against the per-pixel definition (each border of a set
    /// pixel, with values other than `MASK_SET` counting as unset), and the word-wise scan
    /// against a plain one.
    #[test]
    fn boundary_edges_match_the_per_pixel_definition() {
        let mut rng = XorShift64::new(99);
        for (w, h) in [(23, 17), (1, 9), (9, 1), (64, 3)] {
            let m = Mask::from_fn(ImageSize::new(w, h), |_, _| [MASK_SET, 0, 0, 7][rng.below(4)]);
            let set = |x: i64, y: i64| {
                x >= 0 && y >= 0 && x < w as i64 && y < h as i64 && m.get(x as usize, y as usize) == MASK_SET
            };
            let vw = w + 1;
            let mut expected = vec![0u8; vw * (h + 1)];
            let mut count = 0;
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    if !set(x, y) {
                        continue;
                    }
                    for (neighbour, (vx, vy), dir) in [
                        ((x, y - 1), (x, y), 0),
                        ((x + 1, y), (x + 1, y), 1),
                        ((x, y + 1), (x + 1, y + 1), 2),
                        ((x - 1, y), (x, y + 1), 3),
                    ] {
                        if !set(neighbour.0, neighbour.1) {
                            expected[vy as usize * vw + vx as usize] |= 1 << dir;
                            count += 1;
                        }
                    }
                }
            }
            assert_eq!(boundary_edges(&m), (expected.clone(), count), "{w}x{h}");
            for from in 0..=expected.len() {
                let plain = expected[from..]
                    .iter()
                    .position(|&b| b != 0)
                    .map_or(expected.len(), |n| from + n);
                assert_eq!(first_nonzero_from(&expected, from), plain);
            }
        }
    }

    #[test]
    fn hole_is_negative_and_diagonals_join() {
        let m = mask_from(&["#####", "#...#", "#####"]);
        let mut areas: Vec<f64> = boundary_loops(&m).iter().map(|p| signed_area(p)).collect();
        areas.sort_by(f64::total_cmp);
        assert_eq!(areas, vec![-3.0, 15.0]);
        // Two pixels touching at a corner form one region (8-connectivity).
        let d = mask_from(&["#.", ".#"]);
        let loops = boundary_loops(&d);
        assert_eq!(loops.len(), 1, "{loops:?}");
        assert_eq!(signed_area(&loops[0]), 2.0);
    }

    #[test]
    fn disc_outline_is_simplified_and_stays_near_the_border() {
        let size = ImageSize::new(64, 64);
        let r = 20.0;
        let m = Mask::from_fn(size, |x, y| {
            let (dx, dy) = (x as f64 + 0.5 - 32.0, y as f64 + 0.5 - 32.0);
            if dx * dx + dy * dy <= r * r {
                MASK_SET
            } else {
                0
            }
        });
        let polys = outer_contours(&m, &ContourOptions::default());
        assert_eq!(polys.len(), 1);
        let p = &polys[0];
        assert!(p.len() < 60, "{} vertices", p.len());
        for v in p {
            let dist = ((v[0] - 32.0).powi(2) + (v[1] - 32.0).powi(2)).sqrt();
            assert!((dist - r).abs() < 2.0, "vertex {v:?} at {dist}");
        }
        let area = signed_area(p);
        assert!(
            (area - std::f64::consts::PI * r * r).abs() < 0.05 * area,
            "{area}"
        );
    }

    #[test]
    fn small_regions_are_dropped() {
        let m = mask_from(&["#.....", "......", "...###", "...###"]);
        let opts = ContourOptions {
            min_area_px: 2.0,
            ..Default::default()
        };
        assert_eq!(outer_contours(&m, &opts).len(), 1);
    }
}
