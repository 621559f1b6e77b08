use super::oracles::{flood_scalar, square_filter_scalar, UNLABELLED};
use super::*;
use crate::xorshift::XorShift64;

/// The components of `set` by the reference flood fill, in seed (row-major) order, each as
/// its sorted pixels.
fn label_all(set: &[u8], size: ImageSize) -> Vec<Vec<u32>> {
    let mut labels: Vec<u32> = set.iter().map(|&v| if v != 0 { UNLABELLED } else { 0 }).collect();
    let mut found = Vec::new();
    for seed in 0..set.len() {
        if labels[seed] == UNLABELLED {
            let mut pixels = flood_scalar(&mut labels, size.width, size.height, seed, found.len() as u32 + 1);
            pixels.sort_unstable();
            found.push(pixels);
        }
    }
    found
}

#[test]
fn chunked_scans_match_the_reference_scans() {
    let mut rng = XorShift64::new(4242);
    let mut next = || (rng.next_u64() >> 33) as u32;
    // Hits from dense to absent, lengths around the chunk size.
    for len in [0, 1, 31, 32, 33, 64, 100, 257] {
        for one_in in [1, 5, 40, 1000, u32::MAX] {
            let values: Vec<u8> = (0..len)
                .map(|_| {
                    if next() % one_in == 0 {
                        1 + (next() % 255) as u8
                    } else {
                        0
                    }
                })
                .collect();
            for start in [0, len / 3, len] {
                assert_eq!(
                    position_nonzero_u8(&values[start..]),
                    values[start..].iter().position(|&v| v != 0),
                    "len {len} one in {one_in} start {start}"
                );
                // The same bytes inverted: long non-zero stretches with sparse zeros,
                // including 0x80 and 0x01 bytes (the word trick's edge cases).
                let inverted: Vec<u8> = values[start..]
                    .iter()
                    .map(|&v| {
                        if v == 0 {
                            [1u8, 0x80, 0xff, 0x7f][(next() % 4) as usize]
                        } else {
                            0
                        }
                    })
                    .collect();
                assert_eq!(
                    position_zero_u8(&inverted),
                    inverted.iter().position(|&v| v == 0),
                    "len {len} one in {one_in} start {start}"
                );
            }
        }
    }
}

#[test]
fn run_labelling_matches_the_reference_flood_fill() {
    let size = ImageSize::new(67, 29);
    let mut rng = XorShift64::new(13579);
    let mut next = || (rng.next_u64() >> 33) as u32;
    let mut runs = RunLabelling::new(size.width, size.height);
    // Sparse to dense random sets (many touching runs, diagonal contacts), plus runs that
    // reach the window's edges.
    for density in [1u32, 3, 4, 5, 6, 9, 10] {
        let set: Vec<u8> = (0..size.area())
            .map(|_| u8::from(next() % 10 < density))
            .collect();
        // Whole image, and a window of it (the rest cleared) read through a stride.
        for (x0, y0, x1, y1) in [(0, 0, 66, 28), (5, 3, 40, 20), (0, 7, 66, 7), (30, 0, 30, 28)] {
            let windowed: Vec<u8> = (0..size.area())
                .map(|i| {
                    let (x, y) = (i % size.width, i / size.width);
                    let inside = (x0..=x1).contains(&x) && (y0..=y1).contains(&y);
                    if inside {
                        set[i]
                    } else {
                        0
                    }
                })
                .collect();
            let expected = label_all(&windowed, size);
            let count = runs.label(
                &windowed[y0 * size.width + x0..],
                size.width,
                x1 - x0 + 1,
                y1 - y0 + 1,
                (x0, y0),
            );
            let found: Vec<Vec<u32>> = (0..count)
                .map(|k| {
                    let component = runs.runs(k);
                    assert!(component
                        .windows(2)
                        .all(|w| (w[0].y, w[0].x0) < (w[1].y, w[1].x0)));
                    let pixels: Vec<u32> = component
                        .iter()
                        .flat_map(|run| run.pixels(size.width))
                        .map(|p| p as u32)
                        .collect();
                    assert_eq!(pixels.len(), runs.pixels(k));
                    pixels
                })
                .collect();
            if density <= 4 && x1 > x0 {
                assert!(expected.len() > 1, "density {density}");
            }
            assert_eq!(found, expected, "density {density} window {x0} {y0} {x1} {y1}");
        }
    }
    // Empty and full windows.
    let size = ImageSize::new(9, 4);
    let (empty, full) = (vec![0u8; size.area()], vec![1u8; size.area()]);
    assert_eq!(runs.label(&empty, 9, 9, 4, (0, 0)), 0);
    assert_eq!(runs.label(&full, 9, 9, 4, (0, 0)), 1);
    assert_eq!(runs.pixels(0), 36);
    assert_eq!(runs.runs(0).len(), 4);
}

#[test]
fn run_pruning_matches_the_reference_pruning() {
    let size = ImageSize::new(71, 43);
    let mut rng = XorShift64::new(2468);
    let mut next = |n: usize| rng.below(n);
    let (mut some_pruned, mut some_kept, mut some_leaving) = (false, false, false);
    for trial in 0..12 {
        // Object rectangles, predicted rectangles (and scattered pixels) inside the objects,
        // some reaching the border; carried pixels scattered.
        let mut mask = Mask::filled(size, 0);
        let mut predicted = Image::filled(size, 0u8);
        let mut carried = Image::filled(size, 0u8);
        for (rectangles, value) in [(4, 0u8), (14, 1)] {
            for _ in 0..rectangles {
                let (x0, y0) = (next(size.width), next(size.height));
                let (x1, y1) = (
                    (x0 + 1 + next(20)).min(size.width),
                    (y0 + 1 + next(15)).min(size.height),
                );
                for y in y0..y1 {
                    for x in x0..x1 {
                        if value == 0 {
                            mask.set(x, y, crate::image_buf::MASK_SET);
                        } else if mask.get(x, y) != 0 {
                            predicted.set(x, y, 1);
                        }
                    }
                }
            }
        }
        for i in 0..size.area() {
            if next(20) == 0 {
                carried.as_mut_slice()[i] = 1;
            }
            if next(40) == 0 {
                mask.as_mut_slice()[i] = crate::image_buf::MASK_SET;
                predicted.as_mut_slice()[i] = 1;
            }
        }
        let rows: Vec<usize> = (0..size.height)
            .filter(|&y| predicted.row(y).iter().any(|&p| p != 0))
            .collect();
        let bounds = PixelBounds {
            x0: 0,
            x1: size.width - 1,
            y0: rows[0],
            y1: *rows.last().unwrap(),
        };
        let a = DepthMeters::from_vec(size, (0..size.area()).map(|i| 1.0 + i as f32).collect()).unwrap();
        for (adjacency, exit_margin_px) in [(Adjacency::Four, 0), (Adjacency::Four, 8), (Adjacency::Eight, 3)]
        {
            let config = OcclusionConfig {
                prune_adjacency: adjacency,
                prune_exit_margin_px: exit_margin_px,
                ..OcclusionConfig::default()
            };
            let mut components = Components::new(size);
            let (mut fast_mask, mut fast_p, mut fast_a) = (mask.clone(), predicted.clone(), a.clone());
            let fast = components.prune_unattached_predictions(
                &config,
                bounds,
                &carried,
                &mut fast_p,
                &mut fast_mask,
                &mut fast_a,
            );
            let (mut slow_mask, mut slow_p, mut slow_a) = (mask.clone(), predicted.clone(), a.clone());
            let slow = components.prune_unattached_predictions_scalar(
                &config,
                &carried,
                &mut slow_p,
                &mut slow_mask,
                &mut slow_a,
            );
            let context = format!("trial {trial} {adjacency:?} margin {exit_margin_px}");
            assert_eq!(fast, slow, "{context}");
            assert_eq!(fast_mask, slow_mask, "{context}");
            assert_eq!(fast_p, slow_p, "{context}");
            assert_eq!(fast_a.as_slice(), slow_a.as_slice(), "{context}");
            some_pruned |= slow > 0;
            some_kept |= slow_p.as_slice().iter().any(|&p| p != 0);
            if exit_margin_px == 8 {
                let mut no_exit = (mask.clone(), predicted.clone(), a.clone());
                let config = OcclusionConfig {
                    prune_exit_margin_px: 0,
                    ..config
                };
                let pruned_without_exit = components.prune_unattached_predictions_scalar(
                    &config,
                    &carried,
                    &mut no_exit.1,
                    &mut no_exit.0,
                    &mut no_exit.2,
                );
                some_leaving |= pruned_without_exit > slow;
            }
        }
    }
    assert!(some_pruned && some_kept && some_leaving);
}

#[test]
fn prediction_with_stamps_near_the_target_matches_stamping_every_source() {
    let size = ImageSize::new(97, 71);
    let mut rng = XorShift64::new(8642);
    let mut next = |n: usize| rng.below(n);
    let mut predicted_total = 0;
    for trial in 0..8 {
        // Rectangles (some wider than a stamp segment, some small) with a band of Ñ on one
        // side, scattered Ñ pixels, and a depth with steps so the gate matters.
        let mut object = vec![0u8; size.area()];
        let mut newly = Image::filled(size, 0u8);
        for _ in 0..6 {
            let (x0, y0) = (next(size.width - 10), next(size.height - 10));
            let (w, h) = (2 + next(80), 2 + next(40));
            let (x1, y1) = ((x0 + w).min(size.width - 1), (y0 + h).min(size.height - 1));
            let band = 1 + next(6);
            for y in y0..y1 {
                for x in x0..x1 {
                    object[y * size.width + x] = 1;
                }
                for x in x1..(x1 + band).min(size.width) {
                    newly.set(x, y, 1);
                }
            }
        }
        for (o, n) in object.iter_mut().zip(newly.as_mut_slice()) {
            if next(30) == 0 {
                *n = 1;
            }
            if *n != 0 {
                *o = 0;
            }
        }
        let depth = DepthMeters::from_vec(
            size,
            (0..size.area())
                .map(|i| 1.0 + 0.01 * (i % size.width) as f32 + if next(12) == 0 { 0.3 } else { 0.0 })
                .collect(),
        )
        .unwrap();
        let a = DepthMeters::from_vec(
            size,
            object
                .iter()
                .map(|&o| if o != 0 { 0.3 + 0.01 * next(10) as f32 } else { 0.0 })
                .collect(),
        )
        .unwrap();
        let rows: Vec<usize> = (0..size.height)
            .filter(|&y| object[y * size.width..(y + 1) * size.width].contains(&1))
            .collect();
        let columns: Vec<usize> = (0..size.width)
            .filter(|&x| (0..size.height).any(|y| object[y * size.width + x] != 0))
            .collect();
        let bounds = PixelBounds {
            x0: columns[0],
            x1: *columns.last().unwrap(),
            y0: rows[0],
            y1: *rows.last().unwrap(),
        };
        let config = OcclusionConfig {
            thin_structure_border_margin_px: 4,
            ..OcclusionConfig::default()
        };
        let run = |stamp_all_sources: bool| {
            let mut components = Components::new(size);
            components.stamp_all_sources = stamp_all_sources;
            components.object_set.copy_from_slice(&object);
            let mut a = a.clone();
            let stats = components.suppress_and_predict(
                &config,
                MinObjectSize {
                    pixels: 20,
                    leaving: None,
                },
                Some(bounds),
                &depth,
                (&newly, &Image::filled(size, 0u8)),
                &mut a,
            );
            // The target is left all 0 for the next frame.
            assert!(components.target.iter().all(|&t| t == 0));
            let bits: Vec<u32> = a.as_slice().iter().map(|v| v.to_bits()).collect();
            let counts = (
                stats.thin_pixels_erased,
                stats.components,
                stats.small_components_erased,
                stats.predicted_pixels,
                stats.predicted_bounds,
            );
            (counts, bits)
        };
        let (fast, reference) = (run(false), run(true));
        assert_eq!(fast.0, reference.0, "trial {trial}");
        assert!(fast.1 == reference.1, "trial {trial}");
        predicted_total += reference.0 .3;
    }
    assert!(predicted_total > 500, "{predicted_total}");
}

#[test]
fn thin_structure_opening_on_the_bounding_box_matches_the_whole_image() {
    let size = ImageSize::new(61, 47);
    let mut rng = XorShift64::new(555);
    // A blob with noisy edges and thin strips inside [10, 50) × [5, 40).
    let set: Vec<u8> = (0..size.area())
        .map(|i| {
            let (x, y) = (i % size.width, i / size.width);
            let inside = (10..50).contains(&x) && (5..40).contains(&y);
            u8::from(rng.below(10) < 7 && inside)
        })
        .collect();
    let bounding = PixelBounds {
        x0: 10,
        x1: 49,
        y0: 5,
        y1: 39,
    };
    let whole = PixelBounds {
        x0: 0,
        x1: size.width - 1,
        y0: 0,
        y1: size.height - 1,
    };
    // The previous frame's erased pixels: a scattered band along the blob's left side.
    let previous: Vec<u8> = (0..size.area())
        .map(|i| {
            let x = i % size.width;
            if (6..12).contains(&x) && rng.below(10) < 8 {
                THIN_ERASED
            } else {
                0
            }
        })
        .collect();
    for (radius, reconnect, margin) in [(1, 0, 0), (1, 0, 12), (2, 0, 3), (1, 2, 0), (2, 3, 5)] {
        for previous in [None, Some(&previous[..])] {
            let run = |bounds: PixelBounds| {
                let mut components = Components::new(size);
                components.object_set.copy_from_slice(&set);
                let mut a = DepthMeters::filled(size, 1.0);
                let erased = components
                    .thin_filter_and_targets()
                    .0
                    .erase(radius, reconnect, margin, bounds, previous, &mut a);
                (
                    erased,
                    components.thin_erased,
                    components.object_set,
                    a.into_vec(),
                )
            };
            let (fast, slow) = (run(bounding), run(whole));
            assert!(slow.0 > 0, "radius {radius}");
            assert_eq!(slow.0, slow.1.len());
            assert_eq!(
                fast,
                slow,
                "radius {radius} reconnect {reconnect} margin {margin} previous {}",
                previous.is_some()
            );
        }
    }
}

/// A one-pixel strip (a leading edge that advanced by a pixel) stays when the previous frame
/// erased the two columns beside it (the edge before), and is erased when the previous frame
/// erased it in place (a band that flickers) or nothing; the previous frame's pixels never join
/// the set.
#[test]
fn a_strip_beside_the_previous_frames_erased_strip_stays_and_one_in_place_goes() {
    let size = ImageSize::new(40, 30);
    let strip = |x: usize, y: usize| x == 20 && (5..25).contains(&y);
    let set: Vec<u8> = (0..size.area())
        .map(|i| u8::from(strip(i % size.width, i / size.width)))
        .collect();
    let bounds = PixelBounds {
        x0: 20,
        x1: 20,
        y0: 5,
        y1: 24,
    };
    let flags = |columns: std::ops::Range<usize>| -> Vec<u8> {
        (0..size.area())
            .map(|i| {
                let (x, y) = (i % size.width, i / size.width);
                if columns.contains(&x) && (5..25).contains(&y) {
                    THIN_ERASED
                } else {
                    0
                }
            })
            .collect()
    };
    let (beside, in_place, none) = (flags(18..20), flags(20..21), flags(0..0));
    for (previous, stays) in [(&beside, true), (&in_place, false), (&none, false)] {
        let mut components = Components::new(size);
        components.object_set.copy_from_slice(&set);
        let mut a = DepthMeters::filled(size, 0.0);
        for (i, &s) in set.iter().enumerate() {
            a.as_mut_slice()[i] = f32::from(s);
        }
        let erased = components
            .thin_filter_and_targets()
            .0
            .erase(1, 2, 0, bounds, Some(previous), &mut a);
        assert_eq!(erased, if stays { 0 } else { 20 });
        assert_eq!(components.thin_erased.len(), erased);
        let expected: Vec<u8> = set.iter().map(|&s| if stays { s } else { 0 }).collect();
        assert!(components.object_set == expected, "stays {stays}");
        assert_eq!(a.as_slice().iter().sum::<f32>(), if stays { 20.0 } else { 0.0 });
    }
}

/// The reconnection keeps exactly the set's pixels within `reconnect` steps of the opening
/// along 8-connected paths through the set (breadth-first search from the opening), and with
/// more steps never fewer.
#[test]
fn thin_structure_reconnection_keeps_the_set_within_its_geodesic_distance_of_the_opening() {
    let size = ImageSize::new(53, 41);
    let (width, height) = (size.width, size.height);
    let mut rng = XorShift64::new(2024);
    let mut previous_kept = 0;
    let set: Vec<u8> = (0..size.area())
        .map(|i| {
            let (x, y) = (i % width, i / width);
            let noise = rng.below(10) < 3;
            // A solid block with a one-pixel limb, scattered noise and a detached strip.
            let block = (8..20).contains(&x) && (8..20).contains(&y);
            let limb = y == 14 && (20..40).contains(&x);
            let strip = x == 45 && (5..35).contains(&y);
            u8::from(block || limb || strip || noise)
        })
        .collect();
    let whole = PixelBounds {
        x0: 0,
        x1: width - 1,
        y0: 0,
        y1: height - 1,
    };
    let eroded = square_filter_scalar(&set, width, height, 1, true);
    let opened = square_filter_scalar(&eroded, width, height, 1, false);
    for reconnect in 0..5 {
        // Breadth-first search from the opening through the set, `reconnect` rings deep.
        let mut distance: Vec<Option<usize>> = opened.iter().map(|&o| (o != 0).then_some(0)).collect();
        let mut frontier: Vec<usize> = (0..set.len()).filter(|&i| opened[i] != 0).collect();
        for ring in 1..=reconnect {
            let mut next = Vec::new();
            for &i in &frontier {
                let (x, y) = ((i % width) as isize, (i / width) as isize);
                for (dx, dy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))) {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                        continue;
                    }
                    let n = ny as usize * width + nx as usize;
                    if set[n] != 0 && distance[n].is_none() {
                        distance[n] = Some(ring);
                        next.push(n);
                    }
                }
            }
            frontier = next;
        }
        let mut components = Components::new(size);
        components.object_set.copy_from_slice(&set);
        let mut a = DepthMeters::filled(size, 1.0);
        let erased = components
            .thin_filter_and_targets()
            .0
            .erase(1, reconnect, 0, whole, None, &mut a);
        let expected: Vec<u8> = distance.iter().map(|d| u8::from(d.is_some())).collect();
        assert_eq!(components.object_set, expected, "reconnect {reconnect}");
        let kept = expected.iter().filter(|&&k| k != 0).count();
        assert_eq!(erased, set.iter().filter(|&&s| s != 0).count() - kept);
        assert!(kept >= previous_kept, "reconnect {reconnect}");
        // The limb is kept `reconnect` pixels out from the block's opening; the strip is gone.
        assert_eq!(components.object_set[14 * width + 45], 0, "reconnect {reconnect}");
        previous_kept = kept;
    }
}

#[test]
fn sliding_square_filter_matches_the_definition() {
    let (width, height) = (37, 23);
    let mut rng = XorShift64::new(12345);
    let image: Vec<u8> = (0..width * height).map(|_| u8::from(rng.below(3) != 0)).collect();
    for r in 0..4 {
        for erode in [true, false] {
            let mut fast = vec![7; image.len()];
            let mut scratch = vec![7; image.len()];
            square_filter(&image, width, &mut scratch, &mut fast, width, height, r, erode);
            assert_eq!(
                fast,
                square_filter_scalar(&image, width, height, r, erode),
                "r {r} erode {erode}"
            );
        }
    }
}

/// Step 10's size test: a component below the minimum object size stays only as a leaving
/// object's remainder (big enough for the exit size, near the border, on the previous mask).
#[test]
fn a_leaving_objects_remainder_stays_down_to_the_exit_size() {
    let size = ImageSize::new(40, 30);
    let rect = |x0: usize, y0: usize, w: usize, h: usize| -> Vec<usize> {
        (y0..y0 + h)
            .flat_map(|y| (x0..x0 + w).map(move |x| y * size.width + x))
            .collect()
    };
    // 12-px components (the minimum object size is 20, the exit size 5), one 4-px component.
    let at_border_on_previous = rect(0, 2, 3, 4);
    let at_border_elsewhere = rect(0, 20, 3, 4);
    let inside_on_previous = rect(18, 12, 3, 4);
    let tiny_at_border_on_previous = rect(37, 2, 2, 2);
    let big_inside_elsewhere = rect(10, 24, 7, 3);
    // The previous mask touches each of these components at its first pixel only.
    let mut previous_mask = vec![0u8; size.area()];
    for component in [
        &at_border_on_previous,
        &inside_on_previous,
        &tiny_at_border_on_previous,
    ] {
        previous_mask[component[0]] = MASK_SET;
    }
    let components = [
        (&at_border_on_previous, true),
        (&at_border_elsewhere, false),
        (&inside_on_previous, false),
        (&tiny_at_border_on_previous, false),
        (&big_inside_elsewhere, true),
    ];
    let config = OcclusionConfig {
        thin_structure_radius_px: 0,
        predict_newly_discovered: false,
        ..OcclusionConfig::default()
    };
    let depth = DepthMeters::filled(size, 1.0);
    let newly = Image::filled(size, 0u8);
    let bounds = PixelBounds {
        x0: 0,
        x1: size.width - 1,
        y0: 0,
        y1: size.height - 1,
    };
    for leaving in [true, false] {
        let mut labelling = Components::new(size);
        let mut a = DepthMeters::filled(size, 0.0);
        for (component, _) in components {
            for &i in component {
                labelling.object_set[i] = 1;
                a.as_mut_slice()[i] = 0.5;
            }
        }
        let min_size = MinObjectSize {
            pixels: 20,
            leaving: leaving.then_some(LeavingObject {
                previous_mask: &previous_mask,
                min_pixels: 5,
                border_margin_px: 2,
            }),
        };
        let no_flags = Image::filled(size, 0u8);
        let stats = labelling.suppress_and_predict(
            &config,
            min_size,
            Some(bounds),
            &depth,
            (&newly, &no_flags),
            &mut a,
        );
        assert_eq!(stats.components, components.len());
        for (k, (component, stays_when_leaving)) in components.iter().enumerate() {
            let stays = if leaving {
                *stays_when_leaving
            } else {
                component.len() >= 20
            };
            for &i in component.iter() {
                assert_eq!(
                    a.as_slice()[i],
                    if stays { 0.5 } else { 0.0 },
                    "component {k}, leaving {leaving}"
                );
            }
        }
        assert_eq!(stats.small_components_erased, if leaving { 3 } else { 4 });
    }
}
