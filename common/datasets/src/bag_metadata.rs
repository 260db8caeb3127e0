//! A rosbag2 bag directory's `metadata.yaml`: the few keys the reader needs, and the file
//! the writer leaves beside its MCAP file.
//!
//! rosbag2 writes (block-style YAML) a `rosbag2_bagfile_information` mapping: `version`,
//! `storage_identifier` (`mcap` or `sqlite3`), `relative_file_paths` (the storage files,
//! in order), `compression_mode` (empty, `message` or `file`) and `compression_format`, and
//! per topic its name, type and message count. The reader takes `storage_identifier`,
//! `relative_file_paths`, `compression_mode` and `compression_format` from the text, line by
//! line (scalars, quoted or not; a list as `- item` lines or `[a, b]`), and ignores the rest.

use std::path::Path;

use crate::DatasetError;

/// Conversions a user can run on a bag we do not read, named in errors.
pub(crate) const CONVERT_HINT: &str = "convert it to MCAP with `ros2 bag convert -i BAG -o \
     out.yaml` (out.yaml: `output_bags: [{uri: NEW, storage_id: mcap}]`) or, without ROS, \
     `pip install rosbags` and `rosbags-convert --src BAG --dst NEW --dst-storage mcap`";

/// What `metadata.yaml` says about the storage.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) struct BagMetadata {
    pub storage_identifier: Option<String>,
    pub relative_file_paths: Vec<String>,
    pub compression_mode: String,
    pub compression_format: String,
}

fn unquote(s: &str) -> String {
    let s = s.trim();
    let quoted = s.len() >= 2
        && ((s.starts_with('"') && s.ends_with('"')) || (s.starts_with('\'') && s.ends_with('\'')));
    if quoted {
        s[1..s.len() - 1].to_string()
    } else {
        s.to_string()
    }
}

impl BagMetadata {
    /// Reads `metadata.yaml` at `path`.
    pub fn read(path: &Path) -> Result<Self, DatasetError> {
        let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
        Self::parse(&text, path)
    }

    /// Parses the text of a `metadata.yaml` read from `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, DatasetError> {
        if !text.contains("rosbag2_bagfile_information") {
            return Err(DatasetError::invalid(
                path,
                "not a rosbag2 metadata file (no rosbag2_bagfile_information)",
            ));
        }
        let mut meta = Self::default();
        let lines: Vec<&str> = text.lines().collect();
        let mut i = 0;
        while i < lines.len() {
            let line = lines[i].trim();
            i += 1;
            let Some((key, value)) = line.split_once(':') else {
                continue;
            };
            let value = value.trim();
            match key.trim() {
                "storage_identifier" => meta.storage_identifier = Some(unquote(value)),
                "compression_mode" => meta.compression_mode = unquote(value),
                "compression_format" => meta.compression_format = unquote(value),
                "relative_file_paths" if value.starts_with('[') => {
                    let inner = value.trim_start_matches('[').trim_end_matches(']');
                    meta.relative_file_paths = inner
                        .split(',')
                        .map(unquote)
                        .filter(|s| !s.is_empty())
                        .collect();
                }
                "relative_file_paths" => {
                    while let Some(item) = lines.get(i).and_then(|l| l.trim().strip_prefix('-')) {
                        meta.relative_file_paths.push(unquote(item));
                        i += 1;
                    }
                }
                _ => {}
            }
        }
        Ok(meta)
    }
}

/// One topic of a bag being written.
pub(crate) struct TopicRecord<'a> {
    pub name: &'a str,
    pub type_name: &'a str,
    pub message_count: u64,
}

/// The QoS rosbag2 records for a sensor topic (reliable, volatile, keep last), as the YAML
/// string rosbag2 versions before 9 store (in metadata.yaml and in the MCAP channel's
/// `offered_qos_profiles`; readers match the two).
pub(crate) const SENSOR_QOS: &str =
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  \
     deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    \
     nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    \
     nsec: 854775807\n  avoid_ros_namespace_conventions: false";

/// Escapes a string as a double-quoted YAML scalar.
fn quoted(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The `rosbag2_bagfile_information` mapping (version 5, MCAP storage, uncompressed at
/// the bag level) for one storage file, indented for `metadata.yaml`; `start_ns` and
/// `duration_ns` cover the messages' log times.
pub(crate) fn bagfile_information(
    file: &str,
    topics: &[TopicRecord],
    start_ns: u64,
    duration_ns: u64,
) -> String {
    let count: u64 = topics.iter().map(|t| t.message_count).sum();
    let mut y = String::new();
    y.push_str("version: 5\nstorage_identifier: mcap\n");
    y.push_str(&format!("duration:\n  nanoseconds: {duration_ns}\n"));
    y.push_str(&format!(
        "starting_time:\n  nanoseconds_since_epoch: {start_ns}\n"
    ));
    y.push_str(&format!(
        "message_count: {count}\ntopics_with_message_count:\n"
    ));
    for t in topics {
        y.push_str(&format!(
            "  - topic_metadata:\n      name: {}\n      type: {}\n      \
             serialization_format: cdr\n      offered_qos_profiles: {}\n    \
             message_count: {}\n",
            quoted(t.name),
            quoted(t.type_name),
            quoted(SENSOR_QOS),
            t.message_count
        ));
    }
    y.push_str("compression_format: \"\"\ncompression_mode: \"\"\n");
    y.push_str(&format!("relative_file_paths:\n  - {}\n", quoted(file)));
    y.push_str(&format!(
        "files:\n  - path: {}\n    starting_time:\n      nanoseconds_since_epoch: {start_ns}\n    \
         duration:\n      nanoseconds: {duration_ns}\n    message_count: {count}\n",
        quoted(file)
    ));
    y
}

/// The whole `metadata.yaml` around [`bagfile_information`].
pub(crate) fn metadata_yaml(information: &str) -> String {
    let mut out = String::from("rosbag2_bagfile_information:\n");
    for line in information.lines() {
        out.push_str("  ");
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_what_it_writes() {
        let topics = [TopicRecord {
            name: "/camera/color/image_raw",
            type_name: "sensor_msgs/msg/Image",
            message_count: 3,
        }];
        let text = metadata_yaml(&bagfile_information("b_0.mcap", &topics, 10, 20));
        let m = BagMetadata::parse(&text, Path::new("metadata.yaml")).expect("parse");
        assert_eq!(m.storage_identifier.as_deref(), Some("mcap"));
        assert_eq!(m.relative_file_paths, vec!["b_0.mcap".to_string()]);
        assert_eq!(
            (m.compression_mode.as_str(), m.compression_format.as_str()),
            ("", "")
        );
    }

    #[test]
    fn reads_rosbag2_and_rosbags_styles() {
        let rosbag2 =
            "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n  \
                       relative_file_paths:\n    - a_0.db3\n    - a_1.db3\n  \
                       compression_format: zstd\n  compression_mode: FILE\n";
        let m = BagMetadata::parse(rosbag2, Path::new("m")).expect("parse");
        assert_eq!(m.storage_identifier.as_deref(), Some("sqlite3"));
        assert_eq!(m.relative_file_paths, vec!["a_0.db3", "a_1.db3"]);
        assert_eq!(
            (m.compression_mode.as_str(), m.compression_format.as_str()),
            ("FILE", "zstd")
        );
        // ruamel puts the dashes at the key's indentation.
        let rosbags = "rosbag2_bagfile_information:\n  relative_file_paths:\n  - x.mcap\n  \
                       storage_identifier: mcap\n  compression_mode: ''\n";
        let m = BagMetadata::parse(rosbags, Path::new("m")).expect("parse");
        assert_eq!(m.relative_file_paths, vec!["x.mcap"]);
        assert_eq!(m.storage_identifier.as_deref(), Some("mcap"));
        let flow = "rosbag2_bagfile_information:\n  relative_file_paths: [a.mcap, 'b.mcap']\n";
        let m = BagMetadata::parse(flow, Path::new("m")).expect("parse");
        assert_eq!(m.relative_file_paths, vec!["a.mcap", "b.mcap"]);
        assert!(BagMetadata::parse("version: 5\n", Path::new("m")).is_err());
    }
}
