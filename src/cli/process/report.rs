//! What `occmask process` prints after the files are done: warnings, the summary and the
//! timings.

use super::*;

/// True when the input was truncated inside its messages (a cut after the data section loses
/// only the index, which the reader rebuilds).
pub(super) fn lost_input(rep: &ProcessReport) -> bool {
    rep.input_truncated && !rep.input_truncation.is_some_and(|t| t.messages_intact)
}

/// One line per problem of a file that was still processed: a truncated input (what was
/// lost) and frames skipped for their timestamps.
pub(super) fn report_warnings(input: &Path, rep: &ProcessReport) -> Vec<String> {
    let mut out = Vec::new();
    if rep.input_truncated {
        let lost = match &rep.input_truncation {
            Some(t) if t.messages_intact => {
                "no message lost (only the summary/index after the data is missing)".to_owned()
            }
            Some(t) => format!(
                "the last {} bytes (an incomplete record at byte {}{}) are lost{}",
                t.lost_bytes,
                t.intact_bytes,
                if t.salvaged_messages > 0 {
                    format!(
                        ", whose first {} complete messages were read",
                        t.salvaged_messages
                    )
                } else {
                    String::new()
                },
                t.lost_log_time_range
                    .map(|(a, b)| format!(
                        ", with the messages logged from {} to {} s",
                        format_ns_as_seconds(a, 6),
                        format_ns_as_seconds(b, 6)
                    ))
                    .unwrap_or_default()
            ),
            None => "its last record is incomplete".to_owned(),
        };
        out.push(format!(
            "{} ends early (unfinished recording): {lost}; processed and copied every complete \
             message ({} frames); the output's occmask.process metadata records the loss; \
             `mcap recover` can rebuild the input's index",
            input.display(),
            rep.frames
        ));
    }
    if let Some(anchor) = rep.anchor_frame.filter(|a| a.index > 0) {
        out.push(format!(
            "{}: the odometry is anchored at frame {} (t = {} s), the first the ground truth \
             covers; the {} frames before it are in the same frame",
            input.display(),
            anchor.index,
            format_ns_as_seconds(anchor.timestamp_ns, 6),
            anchor.index
        ));
    }
    if let Some(why) = &rep.anchor_skipped {
        out.push(format!(
            "{}: the odometry starts at the first camera, not at the ground truth: {why}",
            input.display()
        ));
    }
    if let Some(u) = &rep.anchor_unreadable {
        out.push(format!(
            "{}: {} ground-truth message(s) did not decode and were left out of the odometry's \
             anchor and /occmask/anchor_path; the first: {}",
            input.display(),
            u.messages,
            u.first_error
        ));
    }
    if let Some(r) = rep.colour_registration.filter(|r| !r.registered) {
        out.push(format!(
            "{}: colour not registered to depth (registration score {:.2}, below {:.2}): the \
             offline refinement used the causal closed loop's depth-weighted DVO and no temporal hysteresis \
             (docs/method.md D18; `--config tools/detector_configs/no_registration_check.json` \
             turns the check off)",
            input.display(),
            r.score.unwrap_or(f32::NAN),
            r.min_score
        ));
    }
    if rep.out_of_order_frames > 0 {
        out.push(format!(
            "{}: skipped {} frame(s) whose colour stamp is not after the previous frame's \
             (timestamps going backwards or duplicated on {})",
            input.display(),
            rep.out_of_order_frames,
            rep.topics.color.topic
        ));
    }
    out
}

/// The narrowest the file-name column of the summary tables gets.
const MIN_NAME_COLUMN: usize = 32;

/// `path`'s file name, as the summary tables print it.
fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The width of the file-name column: the longest name, so that long names keep the columns
/// aligned.
fn name_column(results: &[JobResult]) -> usize {
    results
        .iter()
        .map(|r| file_name(&r.input).chars().count())
        .fold(MIN_NAME_COLUMN, usize::max)
}

/// `--timings`: where each file's frame loop spent its time (the pipeline should dominate).
pub(super) fn print_timings(results: &[JobResult]) {
    let w = name_column(results);
    let mut out = std::io::stderr().lock();
    let _ = writeln!(
        out,
        "{:<w$} {:>7} {:>9} {:>8} {:>11} {:>12} {:>12}",
        "frame loop (s)", "loop", "pipeline", "rectify", "input wait", "output wait", "writer tail"
    );
    for r in results {
        if let FileOutcome::Done(rep, _) = &r.outcome {
            let t = &rep.timings;
            let _ = writeln!(
                out,
                "{:<w$} {:>7.3} {:>9.3} {:>8.3} {:>11.3} {:>12.3} {:>12.3}",
                file_name(&r.input),
                t.loop_s,
                t.pipeline_s,
                t.rectify_s,
                t.input_wait_s,
                t.output_wait_s,
                t.writer_tail_s
            );
        }
    }
}

pub(super) fn print_summary(results: &[JobResult], jobs: &[Job], budget: &ThreadBudget) {
    let mut out = std::io::stderr().lock();
    let _ = writeln!(
        out,
        "{} file(s), {} at a time, {} compute thread(s) each ({} cores)",
        results.len(),
        budget.files_in_flight(),
        budget.threads_per_file_text(),
        available_cores()
    );
    let _ = write!(out, "{}", summary_table(results, jobs));
}

/// One row per file (frames, unpaired messages, time, output), then what was done to each
/// file's images and to an earlier run's messages in it.
fn summary_table(results: &[JobResult], jobs: &[Job]) -> String {
    use std::fmt::Write as _;
    let w = name_column(results);
    let mut out = format!(
        "{:<w$} {:>7} {:>9} {:>9} {:>8} {:>7} {:>7}  output\n",
        "input", "frames", "unp.col", "unp.dep", "no pose", "s", "fps"
    );
    for r in results {
        let name = file_name(&r.input);
        let output = jobs
            .iter()
            .find(|j| j.input == r.input)
            .map(|j| j.output.display().to_string())
            .unwrap_or_default();
        let _ = match &r.outcome {
            FileOutcome::Done(rep, secs) => writeln!(
                out,
                "{name:<w$} {:>7} {:>9} {:>9} {:>8} {:>7.1} {:>7.1}  {output}{}",
                rep.frames,
                rep.unpaired_color,
                rep.unpaired_depth,
                rep.outside_pose_stream,
                secs,
                rep.frames as f64 / secs.max(1e-9),
                match &rep.input_truncation {
                    Some(t) if t.messages_intact => "  (input truncated, no message lost)".to_owned(),
                    Some(t) => format!("  (input truncated: last {} bytes lost)", t.lost_bytes),
                    None => String::new(),
                }
            ),
            FileOutcome::Kept => writeln!(
                out,
                "{name:<w$} kept: {output} exists, a finished run of it with these parameters"
            ),
            FileOutcome::Failed(_) => writeln!(out, "{name:<w$} FAILED (see below)"),
        };
    }
    // What was done to the images (registration and undistortion change what the pipeline
    // saw) and to an earlier run's messages is never silent.
    for r in results {
        if let FileOutcome::Done(rep, _) = &r.outcome {
            if !rep.geometry.is_identity() {
                let _ = writeln!(out, "{}: {}", file_name(&r.input), rep.geometry.describe());
            }
            if rep.replaced_messages > 0 {
                let _ = writeln!(
                    out,
                    "{}: the earlier run's {} messages left out, this run's channels in their place \
                     (--replace-annotations)",
                    file_name(&r.input),
                    rep.replaced_messages
                );
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_file_name_widens_the_name_column_instead_of_shifting_its_row() {
        let long = "a_recording_name_longer_than_thirty_two_characters.mcap";
        let results: Vec<JobResult> = [
            ("short.mcap", FileOutcome::Kept),
            (long, FileOutcome::Failed(String::new())),
        ]
        .into_iter()
        .map(|(name, outcome)| JobResult {
            input: PathBuf::from("in").join(name),
            outcome,
        })
        .collect();
        let table = summary_table(&results, &[]);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 3, "{table}");
        // The header's right-aligned "frames" and every row's second column start one space
        // after the longest name.
        assert_eq!(lines[0].find("frames"), Some(long.len() + 2), "{table}");
        for line in &lines[1..] {
            assert_eq!(line.as_bytes()[long.len()], b' ', "{table}");
            assert_ne!(line.as_bytes()[long.len() + 1], b' ', "{table}");
        }
        assert!(
            lines[1].starts_with("short.mcap ") && lines[2].starts_with(long),
            "{table}"
        );
        assert_eq!(name_column(&results[..1]), MIN_NAME_COLUMN);
    }
}
