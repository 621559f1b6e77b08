//! Whether an output that already exists is a finished run of the same input and parameters,
//! so that a batch can be resumed without processing its finished files again
//! ([`check_existing_output`]).
//!
//! Outputs are written to a temporary name and renamed only when complete, so an output under
//! its final name was finished, unless someone else put a file there. What is compared is what
//! the output's `occmask.process` metadata record holds of what decides its masks and poses:
//! the input (its message count and log-time span, [`input_identity`]: a recording of the same
//! name from another folder or day differs there), the pose source and the processor
//! configuration. Its last such record is the run's own: an annotated copy writes the input's
//! metadata records first.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use crate::error::{Error, ExistingOutputProblem, Result};
use crate::mcap_io::annotate::{METADATA_PROCESS, METADATA_PROCESSOR_CONFIG};
use crate::mcap_io::input::{ExtraRecord, McapInput};
use crate::pipeline::ProcessorConfig;

use super::ProcessConfig;

/// Key of the `occmask.process` record that names the pose source.
pub(super) const METADATA_POSE_SOURCE: &str = "pose_source";
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
/// `input` with the pose source and processor configuration of `config` (the topics, exports
/// and output format are not compared).
///
/// # Errors
/// [`Error::ExistingOutputNotReusable`] when it is truncated or has no summary, has no
/// `occmask.process` record or none with a readable configuration, or was made from another
/// input or with another pose source or parameters (the first field that differs is named);
/// [`Error::Io`], [`Error::BadMcap`] and [`Error::Mcap`] when it cannot be read as MCAP.
pub fn check_existing_output(path: &Path, input: &McapInput, config: &ProcessConfig) -> Result<()> {
    let not_reusable = |problem| Error::ExistingOutputNotReusable {
        path: path.to_owned(),
        problem,
    };
    let output = McapInput::open(path)?;
    if output.is_truncated() || !output.is_indexed() {
        return Err(not_reusable(ExistingOutputProblem::Incomplete));
    }
    let record = output
        .extras()?
        .into_iter()
        .filter_map(|extra| match extra {
            ExtraRecord::Metadata(m) if m.name == METADATA_PROCESS => Some(m.metadata),
            _ => None,
        })
        .next_back()
        .ok_or_else(|| not_reusable(ExistingOutputProblem::NotProcessed))?;
    for (key, value) in input_identity(input) {
        let found = record.get(&key);
        if found != Some(&value) {
            return Err(not_reusable(ExistingOutputProblem::OtherInput {
                field: key,
                found: found.map_or("absent", String::as_str).to_owned(),
                expected: value,
            }));
        }
    }
    let pose_source = config.processor.pose_source.as_str();
    let found_pose_source = record.get(METADATA_POSE_SOURCE).map(String::as_str);
    if found_pose_source != Some(pose_source) {
        return Err(not_reusable(ExistingOutputProblem::OtherParameters {
            field: METADATA_POSE_SOURCE.to_owned(),
            found: found_pose_source.map_or_else(|| "absent".to_owned(), json_string),
            expected: json_string(pose_source),
        }));
    }
    let Some(Ok(found)) = record
        .get(METADATA_PROCESSOR_CONFIG)
        .map(|text| serde_json::from_str::<Value>(text))
    else {
        return Err(not_reusable(ExistingOutputProblem::NoConfiguration));
    };
    // Through the same text as the record: a value built from the configuration directly
    // would hold its f32 parameters widened (0.15 as 0.15000000596…), the record's as written.
    let expected: Value =
        serde_json::from_str(&recorded_processor_config(&config.processor)?).map_err(|e| {
            Error::InvalidParameter {
                name: "processor config",
                value: e.to_string(),
                expected: "JSON".into(),
            }
        })?;
    match first_difference(&found, &expected, "") {
        None => Ok(()),
        Some((field, found, expected)) => Err(not_reusable(ExistingOutputProblem::OtherParameters {
            field,
            found,
            expected,
        })),
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
    use std::collections::BTreeMap;

    /// An MCAP file holding only `records` (name, key/value pairs) as metadata records.
    fn with_metadata(dir: &Path, records: &[(&str, &[(&str, &str)])]) -> std::path::PathBuf {
        let path = dir.join("out.mcap");
        let mut writer = mcap::Writer::new(std::fs::File::create(&path).unwrap()).unwrap();
        for (name, pairs) in records {
            let metadata: BTreeMap<String, String> = pairs
                .iter()
                .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
                .collect();
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: (*name).to_owned(),
                    metadata,
                })
                .unwrap();
        }
        writer.finish().unwrap();
        path
    }

    /// [`check_existing_output`] of the file at `path` as the output of itself: a file of
    /// metadata records only, whose identity is its message count, 0.
    fn check(path: &Path, config: &ProcessConfig) -> Result<()> {
        let input = McapInput::open(path).unwrap();
        assert_eq!(
            input_identity(&input),
            BTreeMap::from([(METADATA_INPUT_MESSAGES.to_owned(), "0".to_owned())])
        );
        check_existing_output(path, &input, config)
    }

    fn problem(result: Result<()>) -> ExistingOutputProblem {
        match result {
            Err(Error::ExistingOutputNotReusable { problem, .. }) => problem,
            other => panic!("expected ExistingOutputNotReusable, found {other:?}"),
        }
    }

    /// The run's own record is the last: an annotated copy of an output holds its input's
    /// record before it.
    #[test]
    fn the_last_process_record_decides() {
        let dir = tempfile::tempdir().unwrap();
        let config = ProcessConfig::default();
        let own = recorded_processor_config(&config.processor).unwrap();
        let pose_source = config.processor.pose_source.as_str();
        let other = own.replace("\"mode\":\"offline\"", "\"mode\":\"causal\"");
        assert_ne!(other, own);
        let path = with_metadata(
            dir.path(),
            &[
                (
                    METADATA_PROCESS,
                    &[
                        (METADATA_INPUT_MESSAGES, "0"),
                        (METADATA_POSE_SOURCE, pose_source),
                        (METADATA_PROCESSOR_CONFIG, &other),
                    ],
                ),
                (
                    METADATA_PROCESS,
                    &[
                        (METADATA_INPUT_MESSAGES, "0"),
                        (METADATA_POSE_SOURCE, pose_source),
                        (METADATA_PROCESSOR_CONFIG, &own),
                    ],
                ),
            ],
        );
        check(&path, &config).unwrap();
        let path = with_metadata(
            dir.path(),
            &[(
                METADATA_PROCESS,
                &[
                    (METADATA_INPUT_MESSAGES, "0"),
                    (METADATA_POSE_SOURCE, pose_source),
                    (METADATA_PROCESSOR_CONFIG, &other),
                ],
            )],
        );
        assert_eq!(
            problem(check(&path, &config)),
            ExistingOutputProblem::OtherParameters {
                field: "mode".into(),
                found: "\"causal\"".into(),
                expected: "\"offline\"".into(),
            }
        );
    }

    #[test]
    fn a_record_without_a_readable_configuration_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let config = ProcessConfig::default();
        let pose_source = config.processor.pose_source.as_str();
        for pairs in [
            &[
                (METADATA_INPUT_MESSAGES, "0"),
                (METADATA_POSE_SOURCE, pose_source),
            ][..],
            &[
                (METADATA_INPUT_MESSAGES, "0"),
                (METADATA_POSE_SOURCE, pose_source),
                (METADATA_PROCESSOR_CONFIG, "{not json"),
            ][..],
        ] {
            let path = with_metadata(dir.path(), &[(METADATA_PROCESS, pairs)]);
            assert_eq!(
                problem(check(&path, &config)),
                ExistingOutputProblem::NoConfiguration
            );
        }
        let path = with_metadata(dir.path(), &[("other", &[("a", "b")])]);
        assert_eq!(
            problem(check(&path, &config)),
            ExistingOutputProblem::NotProcessed
        );
    }

    /// An output of another input (a recording of the same name) is named by the first field
    /// of the input's identity that differs; one recorded without an identity differs too.
    #[test]
    fn an_output_of_another_input_is_not_kept() {
        let dir = tempfile::tempdir().unwrap();
        let config = ProcessConfig::default();
        let own = recorded_processor_config(&config.processor).unwrap();
        let pose_source = config.processor.pose_source.as_str();
        for (messages, found) in [(Some("5"), "5"), (None, "absent")] {
            let mut pairs = vec![
                (METADATA_POSE_SOURCE, pose_source),
                (METADATA_PROCESSOR_CONFIG, own.as_str()),
            ];
            pairs.extend(messages.map(|m| (METADATA_INPUT_MESSAGES, m)));
            let path = with_metadata(dir.path(), &[(METADATA_PROCESS, &pairs)]);
            assert_eq!(
                problem(check(&path, &config)),
                ExistingOutputProblem::OtherInput {
                    field: METADATA_INPUT_MESSAGES.into(),
                    found: found.into(),
                    expected: "0".into(),
                }
            );
        }
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
