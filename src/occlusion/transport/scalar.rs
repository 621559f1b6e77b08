//! The scalar reference of the transport, for the agreement test.

use nalgebra::Point3;

use super::{
    source_at_depth_edge, PixelBounds, TransportCounts, TransportInputs, TransportOutputs, NO_SOURCE,
};
use crate::occlusion::WarpDepth;

/// The scalar reference's warp field: per pixel the nearest previous pixel (None when invalid)
/// and, where the current depth was used (`geometric` and measured), the warped point's depth z′.
fn scalar_warp(inputs: &TransportInputs<'_>, geometric: bool) -> (Vec<Option<usize>>, Vec<Option<f32>>) {
    let size = inputs.depth_m.size();
    let (width, height) = (size.width, size.height);
    let mut warp: Vec<Option<usize>> = vec![None; size.area()];
    let mut warped_depth: Vec<Option<f32>> = vec![None; size.area()];
    for y in 0..height {
        for x in 0..width {
            let measured = inputs.depth_m.get(x, y);
            let use_current = geometric && measured > 0.0;
            let z = if use_current {
                measured
            } else {
                inputs.compensated_previous_m.get(x, y)
            };
            if z <= 0.0 {
                continue;
            }
            let point_in_current = inputs.intrinsics.back_project(x as f64, y as f64, z as f64);
            let point_in_previous: Point3<f64> = inputs.previous_from_current * point_in_current;
            if let Some(pixel) = inputs.intrinsics.project(&point_in_previous) {
                if pixel.x >= 0.0
                    && pixel.y >= 0.0
                    && pixel.x <= (width - 1) as f64
                    && pixel.y <= (height - 1) as f64
                {
                    warp[y * width + x] = Some(pixel.y.round() as usize * width + pixel.x.round() as usize);
                    warped_depth[y * width + x] = use_current.then_some(point_in_previous.z as f32);
                }
            }
        }
    }
    (warp, warped_depth)
}

/// Reference implementation: the docs/method.md steps as separate full-image passes, with f64
/// nalgebra transforms and [`PinholeIntrinsics::project`]. Slow; for tests.
///
/// [`PinholeIntrinsics::project`]: crate::geometry::PinholeIntrinsics::project
pub fn transport_scalar(inputs: &TransportInputs<'_>, mut outputs: TransportOutputs<'_>) -> TransportCounts {
    let size = inputs.depth_m.size();
    let width = size.width;
    // Step 2: warp field (and W's geometric warp).
    let geometric = inputs.config.warp_depth == WarpDepth::Current;
    let (warp, warped_depth) = scalar_warp(inputs, geometric);
    let (slow_warp, slow_warped_depth) = scalar_warp(inputs, true);
    // Steps 3–9, pixel by pixel in the documented order.
    let mut counts = TransportCounts::default();
    let config = inputs.config;
    let slow_events = config.slow_evidence.is_some_and(|c| c.occlusion_events);
    for (i, source) in warp.iter().enumerate() {
        let (x, y) = (i % width, i / width);
        let measured = inputs.depth_m.get(x, y);
        let sampled = source.map_or(0.0, |n| inputs.compensated_previous_m.as_slice()[n]);
        let compensated = if measured > 0.0 { measured } else { sampled };
        let compared = warped_depth[i].unwrap_or(compensated);
        let delta_z = if source.is_some() { sampled - compared } else { 0.0 };
        let carried_a = source.map_or(0.0, |n| inputs.accumulation_previous_m.as_slice()[n]);
        let carried_p = source.map_or(0, |n| inputs.predicted_previous.as_slice()[n]);
        let mut a = carried_a + delta_z;
        if a <= config.threshold(config.alpha, compensated) {
            a = config.sub_threshold_retention * a.max(0.0);
        }
        if delta_z <= -config.threshold(config.beta, compensated) {
            a = 0.0;
        }
        let newly = (sampled == 0.0) != (compensated == 0.0);
        if let (Some((previous_w, retention)), Some(w)) =
            (inputs.slow_previous, outputs.slow_m.as_deref_mut())
        {
            let slow_source = slow_warp[i];
            let carried_w = slow_source.map_or(0.0, |n| previous_w.as_slice()[n]);
            let slow_sampled = slow_source.map_or(0.0, |n| inputs.compensated_previous_m.as_slice()[n]);
            let delta_z = match (slow_source, slow_warped_depth[i]) {
                (Some(_), Some(z_prime)) => slow_sampled - z_prime,
                // Unmeasured: the release's comparison, which is 0 (compensated = sampled).
                _ => 0.0,
            };
            let tau_alpha = config.threshold(config.alpha, compensated);
            let source = slow_source.map_or(NO_SOURCE, |n| n as u32);
            let value = if slow_source.is_some()
                && delta_z > -config.threshold(config.beta, compensated)
                && (delta_z <= tau_alpha
                    || (slow_events
                        && !source_at_depth_edge(
                            inputs.compensated_previous_m.as_slice(),
                            inputs.compensated_previous_m.width(),
                            source,
                        ))) {
                retention * carried_w + delta_z.min(tau_alpha)
            } else {
                0.0
            };
            w.set(x, y, value);
        }
        outputs.compensated_m.set(x, y, compensated);
        if let Some(delta_z_m) = outputs.delta_z_m.as_deref_mut() {
            delta_z_m.set(x, y, delta_z);
        }
        outputs.accumulation_m.set(x, y, a);
        outputs.predicted_carried.set(x, y, carried_p);
        outputs.newly_discovered.set(x, y, u8::from(newly));
        counts.warped += usize::from(source.is_some());
        counts.newly_discovered += usize::from(newly);
    }
    // Step 10's input: the object set O₀ = {A > τ_α} and its bounding box.
    for (i, label) in outputs.object_set[..size.area()].iter_mut().enumerate() {
        let (x, y) = (i % width, i / width);
        let object = outputs.accumulation_m.get(x, y)
            > config.threshold(config.alpha, outputs.compensated_m.get(x, y));
        *label = u8::from(object);
        if object {
            counts.object += 1;
            let pixel = PixelBounds {
                x0: x,
                x1: x,
                y0: y,
                y1: y,
            };
            counts.object_bounds = PixelBounds::union(counts.object_bounds, Some(pixel));
        }
    }
    counts
}
