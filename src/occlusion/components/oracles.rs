//! Test oracles of the component logic: the reference flood fill, pruning and square filter
//! written plainly, for the agreement tests.

use super::super::{Adjacency, OcclusionConfig};
use super::{Components, NEIGHBOURS_4, NEIGHBOURS_8};
use crate::image_buf::{DepthMeters, Image, Mask};

/// Label of a set pixel not yet assigned to a component (the reference flood fill's input).
#[cfg(test)]
pub(super) const UNLABELLED: u32 = u32::MAX;

/// Neighbour (x + dx, y + dy) if inside the image.
#[cfg(test)]
fn neighbour(x: usize, y: usize, dx: isize, dy: isize, width: usize, height: usize) -> Option<usize> {
    let nx = x.checked_add_signed(dx)?;
    let ny = y.checked_add_signed(dy)?;
    (nx < width && ny < height).then_some(ny * width + nx)
}

impl Components {
    /// Reference pruning: flood fill per component and a neighbour test per pixel (for the
    /// agreement test of [`Components::prune_unattached_predictions`]).
    #[cfg(test)]
    pub(super) fn prune_unattached_predictions_scalar(
        &self,
        config: &OcclusionConfig,
        predicted_carried: &Image<u8>,
        predicted: &mut Image<u8>,
        mask: &mut Mask,
        accumulation_m: &mut DepthMeters,
    ) -> usize {
        let (width, height) = (self.width, self.height);
        let exit_margin_px = config.prune_exit_margin_px;
        let carried = predicted_carried.as_slice();
        let near_border = |q: u32| {
            let (x, y) = (q as usize % width, q as usize / width);
            x < exit_margin_px
                || y < exit_margin_px
                || x + exit_margin_px >= width
                || y + exit_margin_px >= height
        };
        let neighbours: &[(isize, isize)] = match config.prune_adjacency {
            Adjacency::Four => &NEIGHBOURS_4,
            Adjacency::Eight => &NEIGHBOURS_8,
        };
        let mut labels: Vec<u32> = predicted
            .as_slice()
            .iter()
            .map(|&p| if p != 0 { UNLABELLED } else { 0 })
            .collect();
        let mut pruned = 0;
        let mut next_id = 0u32;
        for seed in 0..width * height {
            if labels[seed] != UNLABELLED {
                continue;
            }
            next_id += 1;
            let component = flood_scalar(&mut labels, width, height, seed, next_id);
            let (m, p) = (mask.as_slice(), predicted.as_slice());
            let attached = component.iter().any(|&q| {
                let (x, y) = (q as usize % width, q as usize / width);
                neighbours.iter().any(|&(dx, dy)| {
                    neighbour(x, y, dx, dy, width, height).is_some_and(|n| m[n] != 0 && p[n] == 0)
                })
            });
            let leaving = exit_margin_px > 0
                && component
                    .iter()
                    .any(|&q| carried[q as usize] & super::super::PREDICTED != 0)
                && component.iter().any(|&q| near_border(q));
            if !attached && !leaving {
                let (m, a, p) = (
                    mask.as_mut_slice(),
                    accumulation_m.as_mut_slice(),
                    predicted.as_mut_slice(),
                );
                for &q in &component {
                    m[q as usize] = 0;
                    a[q as usize] = 0.0;
                    p[q as usize] = 0;
                }
                pruned += component.len();
            }
        }
        pruned
    }
}

/// Reference flood fill: depth-first over the 8 neighbours of every pixel of `labels` holding
/// [`UNLABELLED`], from `seed`; labels the component `id` and returns its pixels.
#[cfg(test)]
pub(super) fn flood_scalar(
    labels: &mut [u32],
    width: usize,
    height: usize,
    seed: usize,
    id: u32,
) -> Vec<u32> {
    let mut component = Vec::new();
    let mut stack = vec![seed as u32];
    labels[seed] = id;
    while let Some(p) = stack.pop() {
        let p = p as usize;
        component.push(p as u32);
        let (x, y) = (p % width, p / width);
        for &(dx, dy) in &NEIGHBOURS_8 {
            if let Some(n) = neighbour(x, y, dx, dy, width, height) {
                if labels[n] == UNLABELLED {
                    labels[n] = id;
                    stack.push(n as u32);
                }
            }
        }
    }
    component
}

/// Reference square filter: the definition, pixel by pixel (for the agreement test).
#[cfg(test)]
pub(super) fn square_filter_scalar(
    image: &[u8],
    width: usize,
    height: usize,
    r: usize,
    erode: bool,
) -> Vec<u8> {
    let mut out = vec![0; image.len()];
    for y in 0..height {
        for x in 0..width {
            let mut all = true;
            let mut any = false;
            for dy in -(r as isize)..=r as isize {
                for dx in -(r as isize)..=r as isize {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    let inside = xx >= 0 && yy >= 0 && xx < width as isize && yy < height as isize;
                    let v = inside && image[yy as usize * width + xx as usize] != 0;
                    all &= v;
                    any |= v;
                }
            }
            out[y * width + x] = u8::from(if erode { all } else { any });
        }
    }
    out
}
