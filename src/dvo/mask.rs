//! Ignore-mask helpers: 2×2 OR-pooling and square dilation, on raw row-major `u8` buffers
//! (nonzero = ignore).

use crate::image_buf::ImageSize;

/// `dst` (half of `src`, odd sides cropped) is set where any of the 2×2 children is set, so
/// an ignored region never shrinks when going coarser.
pub fn pool_or_into(src: &[u8], src_size: ImageSize, dst: &mut [u8], dst_size: ImageSize) {
    debug_assert_eq!(dst_size.width, src_size.width / 2);
    debug_assert_eq!(dst_size.height, src_size.height / 2);
    let (sw, dw) = (src_size.width, dst_size.width);
    for y in 0..dst_size.height {
        let a = &src[2 * y * sw..];
        let b = &src[(2 * y + 1) * sw..];
        for x in 0..dw {
            let any = a[2 * x] | a[2 * x + 1] | b[2 * x] | b[2 * x + 1];
            dst[y * dw + x] = u8::from(any != 0);
        }
    }
}

/// Dilates `mask` in place by a square of half-width `radius_px` (every pixel within
/// Chebyshev distance `radius_px` of a set pixel becomes set). `column_scratch` holds one
/// counter per column. O(width · height) whatever the radius. Input values must be 0 or 1
/// (newly covered pixels are marked 2 during the passes so they do not seed further growth).
pub fn dilate_square(mask: &mut [u8], size: ImageSize, radius_px: usize, column_scratch: &mut Vec<u32>) {
    if radius_px == 0 || size.area() == 0 {
        return;
    }
    let (w, h) = (size.width, size.height);
    let r = radius_px as u32;
    // Horizontal: distance to the nearest set pixel to the left, then to the right.
    for row in mask.chunks_exact_mut(w) {
        let mut since = u32::MAX;
        for v in row.iter_mut() {
            if *v == 1 {
                since = 0;
            } else {
                since = since.saturating_add(1);
            }
            if since <= r && *v != 1 {
                *v = 2;
            }
        }
        since = u32::MAX;
        for v in row.iter_mut().rev() {
            if *v == 1 {
                since = 0;
            } else {
                since = since.saturating_add(1);
                if since <= r {
                    *v = 2;
                }
            }
        }
        for v in row.iter_mut() {
            *v = u8::from(*v != 0);
        }
    }
    // Vertical: the same with one counter per column, down then up.
    column_scratch.clear();
    column_scratch.resize(w, u32::MAX);
    for y in 0..h {
        let row = &mut mask[y * w..(y + 1) * w];
        for (v, since) in row.iter_mut().zip(column_scratch.iter_mut()) {
            if *v == 1 {
                *since = 0;
            } else {
                *since = since.saturating_add(1);
                if *since <= r {
                    *v = 2;
                }
            }
        }
    }
    column_scratch.fill(u32::MAX);
    for y in (0..h).rev() {
        let row = &mut mask[y * w..(y + 1) * w];
        for (v, since) in row.iter_mut().zip(column_scratch.iter_mut()) {
            if *v == 1 {
                *since = 0;
            } else {
                *since = since.saturating_add(1);
                if *since <= r {
                    *v = 2;
                }
            }
        }
    }
    for v in mask.iter_mut() {
        *v = u8::from(*v != 0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_dilate(mask: &[u8], size: ImageSize, r: usize) -> Vec<u8> {
        let (w, h) = (size.width as i64, size.height as i64);
        let r = r as i64;
        let mut out = vec![0u8; mask.len()];
        for y in 0..h {
            for x in 0..w {
                let mut any = false;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (xx, yy) = (x + dx, y + dy);
                        if xx >= 0 && yy >= 0 && xx < w && yy < h && mask[(yy * w + xx) as usize] != 0 {
                            any = true;
                        }
                    }
                }
                out[(y * w + x) as usize] = u8::from(any);
            }
        }
        out
    }

    #[test]
    fn dilation_matches_brute_force() {
        let size = ImageSize::new(37, 23);
        let mask: Vec<u8> = (0..size.area())
            .map(|i| u8::from((i * 7919) % 97 == 0 || (i > 300 && i < 305)))
            .collect();
        let mut scratch = Vec::new();
        for r in [0, 1, 2, 4, 9] {
            let mut m = mask.clone();
            dilate_square(&mut m, size, r, &mut scratch);
            assert_eq!(m, brute_dilate(&mask, size, r), "radius {r}");
        }
    }

    #[test]
    fn pooling_never_shrinks() {
        let src_size = ImageSize::new(9, 7);
        let mut src = vec![0u8; src_size.area()];
        src[3 * 9 + 5] = 1; // fine (5, 3) -> coarse (2, 1)
        let dst_size = ImageSize::new(4, 3);
        let mut dst = vec![9u8; dst_size.area()];
        pool_or_into(&src, src_size, &mut dst, dst_size);
        let set: Vec<usize> = dst
            .iter()
            .enumerate()
            .filter(|(_, &v)| v != 0)
            .map(|(i, _)| i)
            .collect();
        assert_eq!(set, vec![4 + 2]);
    }
}
