//! Whether an output that already exists is a finished run of the same input and parameters,
//! so that a batch can be resumed without processing its finished files again
//! ([`check_existing_output`]).
//!
//! Outputs are written to a temporary name and renamed only when complete, so an output under
//! its final name was finished, unless someone else put a file there. What is compared is what
//! the output's `occmask.process` metadata record holds of what decides its masks and poses:
//! the input (its message count and log-time span, [`input_identity`]: a recording of the same
//! name from another folder or day differs there), the run's choices ([`RunChoices`]: the
//! colour and depth topics, the pose source, the time range) and the processor configuration.
//! Its last such record is the run's own: an annotated copy writes the input's metadata records
//! first.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use crate::error::{Error, ExistingOutputProblem, Result};
use crate::mcap_io::annotate::{METADATA_PROCESS, METADATA_PROCESSOR_CONFIG};
use crate::mcap_io::input::detect::{detect_topics, RgbdTopics};
use crate::mcap_io::input::{ExtraRecord, McapInput};
use crate::pipeline::ProcessorConfig;

use super::poses::topic_overrides;
use super::ProcessConfig;

/// Key of the `occmask.process` record that names the pose source.
const METADATA_POSE_SOURCE: &str = "pose_source";
/// Keys of the `occmask.process` record that name the colour and depth topics.
const METADATA_COLOR_TOPIC: &str = "color_topic";
const METADATA_DEPTH_TOPIC: &str = "depth_topic";
/// Keys of the `occmask.process` record: the time range processed (ns after the first frame),
/// recorded only when given.
const METADATA_START_OFFSET: &str = "start_offset_ns";
const METADATA_END_OFFSET: &str = "end_offset_ns";
/// Key of the `occmask.process` record: the input's message count.
const METADATA_INPUT_MESSAGES: &str = "input_messages";
/// Key of the `occmask.process` record: the input's first and last message log time,
/// `FIRST..LAST` in ns.
const METADATA_INPUT_LOG_TIME_SPAN: &str = "input_log_time_span_ns";

/// The processor configuration as the `occmask.process` record holds it (the JSON that
/// `--config` reads).
///
/// # Errors
/// [`Error::InvalidParameter`] when it does not serialise (a non-finite parameter).
pub(super) fn recorded_processor_config(processor: &ProcessorConfig) -> Result<String> {
    serde_json::to_string(processor).map_err(|e| Error::InvalidParameter {
        name: "processor config",
        value: e.to_string(),
        expected: "a configuration that serialises to JSON".into(),
    })
}

/// The run's choices as the `occmask.process` record holds them: the colour and depth topics,
/// the pose source and the time range, every key with its value (`None`: not recorded, an end
/// of the time range not given).
type RunChoices = [(&'static str, Option<String>); 5];

/// The run's choices ([`RunChoices`]) for `topics` and `config`.
fn run_choices(topics: &RgbdTopics, config: &ProcessConfig) -> RunChoices {
    [
        (METADATA_COLOR_TOPIC, Some(topics.color.topic.clone())),
        (METADATA_DEPTH_TOPIC, Some(topics.depth.topic.clone())),
        (
            METADATA_POSE_SOURCE,
            Some(config.processor.pose_source.as_str().to_owned()),
        ),
        (
            METADATA_START_OFFSET,
            config.start_offset_ns.map(|ns| ns.to_string()),
        ),
        (METADATA_END_OFFSET, config.end_offset_ns.map(|ns| ns.to_string())),
    ]
}

/// The record's entries for the run's choices: those with a value.
pub(super) fn recorded_run_choices(topics: &RgbdTopics, config: &ProcessConfig) -> BTreeMap<String, String> {
    recorded(&run_choices(topics, config))
}

fn recorded(choices: &RunChoices) -> BTreeMap<String, String> {
    choices
        .iter()
        .filter_map(|(key, value)| Some(((*key).to_owned(), value.clone()?)))
        .collect()
}

/// What the `occmask.process` record holds of its input: the message count and the log-time
/// span, where the input's summary or scan gives them. The same for a file and a copy of it
/// that lost only its index (the messages are the same).
pub(super) fn input_identity(input: &McapInput) -> BTreeMap<String, String> {
    let messages = input
        .message_count()
        .map(|n| (METADATA_INPUT_MESSAGES.to_owned(), n.to_string()));
    let span = input.log_time_span().map(|(first, last)| {
        (
            METADATA_INPUT_LOG_TIME_SPAN.to_owned(),
            format!("{first}..{last}"),
        )
    });
    messages.into_iter().chain(span).collect()
}

/// Checks that the MCAP file at `path` is a complete output of `process_file` made from
/// `input` with the topics, pose source, time range and processor configuration of `config`
/// (the calibration, registration and output options are not compared).
///
/// # Errors
/// [`Error::ExistingOutputNotReusable`] when it is truncated or has no summary, has no
/// `occmask.process` record or none with a readable configuration, or was made from another
/// input or with other choices or parameters (the first field that differs is named);
/// [`Error::Io`], [`Error::BadMcap`] and [`Error::Mcap`] when it cannot be read as MCAP; the
/// errors of [`detect_topics`] when `input` has no RGB-D channels to process.
pub fn check_existing_output(path: &Path, input: &McapInput, config: &ProcessConfig) -> Result<()> {
    let not_reusable = |problem| Error::ExistingOutputNotReusable {
        path: path.to_owned(),
        problem,
    };
    let output = McapInput::open(path)?;
    if output.is_truncated() || !output.is_indexed() {
        return Err(not_reusable(ExistingOutputProblem::Incomplete));
    }
    let record = last_process_record(output.extras()?)
        .ok_or_else(|| not_reusable(ExistingOutputProblem::NotProcessed))?;
    let choices = run_choices(&detect_topics(input, &topic_overrides(config))?, config);
    // Through the same text as the record: a value built from the configuration directly
    // would hold its f32 parameters widened (0.15 as 0.15000000596…), the record's as written.
    let configuration: Value =
        serde_json::from_str(&recorded_processor_config(&config.processor)?).map_err(|e| {
            Error::InvalidParameter {
                name: "processor config",
                value: e.to_string(),
                expected: "JSON".into(),
            }
        })?;
    compare_record(&record, &input_identity(input), &choices, &configuration).map_err(not_reusable)
}

/// The last `occmask.process` record among `extras` (the run's own), its key/value pairs.
fn last_process_record(extras: Vec<ExtraRecord>) -> Option<BTreeMap<String, String>> {
    extras
        .into_iter()
        .filter_map(|extra| match extra {
            ExtraRecord::Metadata(m) if m.name == METADATA_PROCESS => Some(m.metadata),
            _ => None,
        })
        .next_back()
}

/// A field of an input's identity (`input_identity`) that an output's `occmask.process`
/// record holds otherwise.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct InputDifference {
    /// `input_messages` or `input_log_time_span_ns`.
    pub field: String,
    /// Its value in the output's record (`absent` when it has none).
    pub recorded: String,
    /// Its value for the input at hand.
    pub found: String,
}

/// The first field of `identity` ([`input_identity`]) that `record` holds otherwise (or not at
/// all).
fn identity_difference(
    record: &BTreeMap<String, String>,
    identity: &BTreeMap<String, String>,
) -> Option<InputDifference> {
    identity.iter().find_map(|(key, value)| {
        let recorded = record.get(key);
        (recorded != Some(value)).then(|| InputDifference {
            field: key.clone(),
            recorded: recorded.map_or("absent", String::as_str).to_owned(),
            found: value.clone(),
        })
    })
}

/// Whether `output`, an output of `occmask process`, was made from `input`: the first field of
/// `input`'s identity (`input_identity`) that `output`'s `occmask.process` record holds
/// otherwise; `None` when they agree, or when `output` has no such record.
///
/// # Errors
/// [`Error::Io`], [`Error::BadMcap`] and [`Error::Mcap`] when `output`'s metadata cannot be read.
pub fn recorded_input_difference(output: &McapInput, input: &McapInput) -> Result<Option<InputDifference>> {
    Ok(last_process_record(output.extras()?)
        .and_then(|record| identity_difference(&record, &input_identity(input))))
}

/// `record` against this run's input identity, choices and configuration (as JSON), in that
/// order: the first difference.
fn compare_record(
    record: &BTreeMap<String, String>,
    identity: &BTreeMap<String, String>,
    choices: &RunChoices,
    configuration: &Value,
) -> std::result::Result<(), ExistingOutputProblem> {
    if let Some(difference) = identity_difference(record, identity) {
        return Err(ExistingOutputProblem::OtherInput {
            field: difference.field,
            found: difference.recorded,
            expected: difference.found,
        });
    }
    // Every key: one recorded but not chosen now differs too.
    for (key, expected) in choices {
        let (found, expected) = (record.get(*key), expected.as_ref());
        if found != expected {
            let shown =
                |value: Option<&String>| value.map_or_else(|| "absent".to_owned(), |v| json_string(v));
            return Err(ExistingOutputProblem::OtherParameters {
                field: (*key).to_owned(),
                found: shown(found),
                expected: shown(expected),
            });
        }
    }
    let Some(Ok(found)) = record
        .get(METADATA_PROCESSOR_CONFIG)
        .map(|text| serde_json::from_str::<Value>(text))
    else {
        return Err(ExistingOutputProblem::NoConfiguration);
    };
    match first_difference(&found, configuration, "") {
        None => Ok(()),
        Some((field, found, expected)) => Err(ExistingOutputProblem::OtherParameters {
            field,
            found,
            expected,
        }),
    }
}

/// The first place (in key order, depth first) where `found` and `expected` differ: its
/// dotted path below `at`, and the two values as JSON text (`absent` for a missing field).
fn first_difference(found: &Value, expected: &Value, at: &str) -> Option<(String, String, String)> {
    match (found, expected) {
        (Value::Object(f), Value::Object(e)) => {
            let mut keys: Vec<&String> = f.keys().chain(e.keys()).collect();
            keys.sort_unstable();
            keys.dedup();
            keys.into_iter().find_map(|key| {
                let path = if at.is_empty() {
                    key.clone()
                } else {
                    format!("{at}.{key}")
                };
                match (f.get(key), e.get(key)) {
                    (Some(fv), Some(ev)) => first_difference(fv, ev, &path),
                    (fv, ev) => Some((path, json_or_absent(fv), json_or_absent(ev))),
                }
            })
        }
        _ if found == expected => None,
        _ => Some((at.to_owned(), found.to_string(), expected.to_string())),
    }
}

fn json_string(text: &str) -> String {
    Value::from(text).to_string()
}

fn json_or_absent(value: Option<&Value>) -> String {
    value.map_or_else(|| "absent".to_owned(), Value::to_string)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn map(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect()
    }

    /// This run's identity, choices and configuration, and a record that matches them.
    struct Run {
        identity: BTreeMap<String, String>,
        choices: RunChoices,
        configuration_text: String,
        configuration: Value,
    }

    impl Run {
        fn new() -> Self {
            let configuration_text = recorded_processor_config(&ProcessorConfig::default()).unwrap();
            Self {
                identity: map(&[
                    (METADATA_INPUT_MESSAGES, "40"),
                    (METADATA_INPUT_LOG_TIME_SPAN, "10..90"),
                ]),
                choices: [
                    (METADATA_COLOR_TOPIC, Some("/rgb".to_owned())),
                    (METADATA_DEPTH_TOPIC, Some("/depth".to_owned())),
                    (METADATA_POSE_SOURCE, Some("dvo".to_owned())),
                    (METADATA_START_OFFSET, None),
                    (METADATA_END_OFFSET, None),
                ],
                configuration: serde_json::from_str(&configuration_text).unwrap(),
                configuration_text,
            }
        }

        /// The record this run writes.
        fn record(&self) -> BTreeMap<String, String> {
            let mut record = self.identity.clone();
            record.extend(recorded(&self.choices));
            record.insert(
                METADATA_PROCESSOR_CONFIG.to_owned(),
                self.configuration_text.clone(),
            );
            record.insert("tool".to_owned(), "occmask".to_owned());
            record
        }

        fn compare(
            &self,
            record: &BTreeMap<String, String>,
        ) -> std::result::Result<(), ExistingOutputProblem> {
            compare_record(record, &self.identity, &self.choices, &self.configuration)
        }
    }

    #[test]
    fn the_record_the_run_writes_matches_it() {
        let run = Run::new();
        assert_eq!(run.compare(&run.record()), Ok(()));
    }

    /// An output of another input (a recording of the same name) is named by the first field
    /// of the input's identity that differs; one recorded without an identity differs too.
    #[test]
    fn an_output_of_another_input_is_not_kept() {
        let run = Run::new();
        let mut record = run.record();
        record.insert(METADATA_INPUT_MESSAGES.to_owned(), "41".to_owned());
        assert_eq!(
            run.compare(&record),
            Err(ExistingOutputProblem::OtherInput {
                field: METADATA_INPUT_MESSAGES.into(),
                found: "41".into(),
                expected: "40".into(),
            })
        );
        record.remove(METADATA_INPUT_LOG_TIME_SPAN);
        assert_eq!(
            run.compare(&record),
            Err(ExistingOutputProblem::OtherInput {
                field: METADATA_INPUT_LOG_TIME_SPAN.into(),
                found: "absent".into(),
                expected: "10..90".into(),
            })
        );
    }

    /// Another topic, pose source or time range, also one recorded but not chosen now.
    #[test]
    fn other_choices_are_named_with_both_values() {
        let run = Run::new();
        let mut record = run.record();
        record.insert(METADATA_DEPTH_TOPIC.to_owned(), "/aligned_depth".to_owned());
        assert_eq!(
            run.compare(&record),
            Err(ExistingOutputProblem::OtherParameters {
                field: METADATA_DEPTH_TOPIC.into(),
                found: "\"/aligned_depth\"".into(),
                expected: "\"/depth\"".into(),
            })
        );
        let mut record = run.record();
        record.insert(METADATA_END_OFFSET.to_owned(), "1000000000".to_owned());
        assert_eq!(
            run.compare(&record),
            Err(ExistingOutputProblem::OtherParameters {
                field: METADATA_END_OFFSET.into(),
                found: "\"1000000000\"".into(),
                expected: "absent".into(),
            })
        );
    }

    #[test]
    fn other_parameters_are_named_by_the_first_field_that_differs() {
        let run = Run::new();
        let mut record = run.record();
        let causal = run
            .configuration_text
            .replace("\"mode\":\"offline\"", "\"mode\":\"causal\"");
        assert_ne!(causal, run.configuration_text);
        record.insert(METADATA_PROCESSOR_CONFIG.to_owned(), causal);
        assert_eq!(
            run.compare(&record),
            Err(ExistingOutputProblem::OtherParameters {
                field: "mode".into(),
                found: "\"causal\"".into(),
                expected: "\"offline\"".into(),
            })
        );
        for unreadable in [None, Some("{not json")] {
            let mut record = run.record();
            match unreadable {
                None => record.remove(METADATA_PROCESSOR_CONFIG),
                Some(text) => record.insert(METADATA_PROCESSOR_CONFIG.to_owned(), text.to_owned()),
            };
            assert_eq!(run.compare(&record), Err(ExistingOutputProblem::NoConfiguration));
        }
    }

    /// The run's own record is the last: an annotated copy of an output holds its input's
    /// record before it.
    #[test]
    fn the_last_process_record_is_the_runs_own() {
        let metadata = |name: &str, value: &str| {
            ExtraRecord::Metadata(mcap::records::Metadata {
                name: name.to_owned(),
                metadata: map(&[("k", value)]),
            })
        };
        let extras = vec![
            metadata(METADATA_PROCESS, "input's"),
            metadata(METADATA_PROCESS, "own"),
            metadata("other", "later"),
        ];
        assert_eq!(last_process_record(extras), Some(map(&[("k", "own")])));
        assert_eq!(last_process_record(vec![metadata("other", "x")]), None);
    }

    #[test]
    fn equal_values_have_no_difference() {
        let v = json!({"a": 1, "b": {"c": [1, 2], "d": null}});
        assert_eq!(first_difference(&v, &v.clone(), ""), None);
    }

    #[test]
    fn the_first_differing_leaf_is_named_by_its_dotted_path() {
        let found = json!({"occlusion": {"alpha": 0.1, "beta": 0.2}, "mode": "offline"});
        let expected = json!({"occlusion": {"alpha": 0.15, "beta": 0.3}, "mode": "causal"});
        assert_eq!(
            first_difference(&found, &expected, ""),
            Some(("mode".into(), "\"offline\"".into(), "\"causal\"".into()))
        );
        let expected = json!({"occlusion": {"alpha": 0.15, "beta": 0.2}, "mode": "offline"});
        assert_eq!(
            first_difference(&found, &expected, ""),
            Some(("occlusion.alpha".into(), "0.1".into(), "0.15".into()))
        );
    }

    #[test]
    fn a_field_on_one_side_only_is_absent_on_the_other() {
        let found = json!({"dvo": {"levels": 5}});
        let expected = json!({"dvo": {"levels": 5, "keyframe": null}});
        assert_eq!(
            first_difference(&found, &expected, ""),
            Some(("dvo.keyframe".into(), "absent".into(), "null".into()))
        );
        assert_eq!(
            first_difference(&expected, &found, ""),
            Some(("dvo.keyframe".into(), "null".into(), "absent".into()))
        );
    }

    #[test]
    fn values_of_different_kinds_differ_where_they_stand() {
        assert_eq!(
            first_difference(&json!({"a": {"b": 1}}), &json!({"a": [1]}), ""),
            Some(("a".into(), "{\"b\":1}".into(), "[1]".into()))
        );
    }
}
