//! `classes.json`: instance id → class name, written by our synthesiser.

use std::collections::BTreeMap;
use std::path::Path;

use crate::{DatasetError, InstanceClass};

pub(crate) fn read_class_table(path: &Path) -> Result<Vec<InstanceClass>, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
    let map: BTreeMap<u16, String> =
        serde_json::from_str(&text).map_err(|e| DatasetError::Parse {
            path: path.to_path_buf(),
            line: e.line(),
            message: format!("expected {{\"id\": \"class\", ...}}: {e}"),
        })?;
    Ok(map
        .into_iter()
        .map(|(id, class)| InstanceClass { id, class })
        .collect())
}

pub(crate) fn write_class_table(
    path: &Path,
    classes: &[InstanceClass],
) -> Result<(), DatasetError> {
    let map: BTreeMap<u16, &str> = classes.iter().map(|c| (c.id, c.class.as_str())).collect();
    let text = serde_json::to_string_pretty(&map)
        .map_err(|e| DatasetError::invalid(path, e.to_string()))?;
    std::fs::write(path, text + "\n").map_err(|e| DatasetError::io(path, e))
}
