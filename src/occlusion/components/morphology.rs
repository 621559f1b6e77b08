//! Binary morphology of the component logic: the separable square min / max filter.

/// Separable square min (`erode`) or max filter of radius `r` over the 0/1 image `source` into
/// `out` (`scratch` holds the row pass); pixels outside the image count as 0. Each pass combines
/// the image with its shifts by 1..=r pixels (rows), whole slices at a time so the compiler
/// vectorises it: O(r) per pixel, at 16+ pixels per instruction (r is 1 by default).
/// `source` row y starts at `source[y * source_stride]`; `out` and `scratch` are compact (rows of
/// `width`). Reference: [`square_filter_scalar`].
#[allow(clippy::too_many_arguments)]
pub(super) fn square_filter(
    source: &[u8],
    source_stride: usize,
    scratch: &mut [u8],
    out: &mut [u8],
    width: usize,
    height: usize,
    r: usize,
    erode: bool,
) {
    square_rows(source, source_stride, scratch, width, height, r, erode);
    square_columns(scratch, out, width, height, r, erode);
}

/// Row pass of [`square_filter`]: `out[x]` = min / max of `source` row `[x − r, x + r]`.
pub(super) fn square_rows(
    source: &[u8],
    source_stride: usize,
    out: &mut [u8],
    width: usize,
    height: usize,
    r: usize,
    erode: bool,
) {
    let combine = |a: u8, b: u8| if erode { a.min(b) } else { a.max(b) };
    for (y, out) in out.chunks_exact_mut(width).take(height).enumerate() {
        let row = &source[y * source_stride..y * source_stride + width];
        out.copy_from_slice(row);
        for k in 1..=r.min(width) {
            for (o, &v) in out[..width - k].iter_mut().zip(&row[k..]) {
                *o = combine(*o, v);
            }
            for (o, &v) in out[k..].iter_mut().zip(&row[..width - k]) {
                *o = combine(*o, v);
            }
        }
        if erode {
            // A window reaching outside the image holds a 0.
            let edge = r.min(width);
            out[..edge].fill(0);
            out[width - edge..].fill(0);
        }
    }
}

/// Column pass of [`square_filter`]: `out` row y = min / max of `source` rows `[y − r, y + r]`.
pub(super) fn square_columns(
    source: &[u8],
    out: &mut [u8],
    width: usize,
    height: usize,
    r: usize,
    erode: bool,
) {
    let combine = |a: u8, b: u8| if erode { a.min(b) } else { a.max(b) };
    for (y, out) in out.chunks_exact_mut(width).take(height).enumerate() {
        if erode && (y < r || y + r >= height) {
            out.fill(0);
            continue;
        }
        out.copy_from_slice(&source[y * width..(y + 1) * width]);
        let first = y.saturating_sub(r);
        let last = (y + r).min(height - 1);
        for other in (first..=last).filter(|&other| other != y) {
            for (o, &v) in out.iter_mut().zip(&source[other * width..(other + 1) * width]) {
                *o = combine(*o, v);
            }
        }
    }
}
