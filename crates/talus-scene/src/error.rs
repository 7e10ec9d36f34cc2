//! Scene errors: always a file, a line and column, a field and what was expected.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::locate::Locator;

/// A problem with a scene file.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneError {
    /// The scene file.
    pub file: PathBuf,
    /// 1-based line (0 when the file could not be read).
    pub line: usize,
    /// 1-based column.
    pub column: usize,
    /// Path of the offending field, e.g. `grains[1].radius`.
    pub field: String,
    /// What was expected there.
    pub expected: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: ", self.file.display(), self.line, self.column)?;
        if self.field.is_empty() {
            write!(f, "expected {}", self.expected)
        } else {
            write!(f, "field `{}`: expected {}", self.field, self.expected)
        }
    }
}

impl std::error::Error for SceneError {}

/// Turns a ron parse error into a located scene error, naming the field that encloses
/// the error position.
pub fn from_ron(path: &Path, source: &str, e: ron::error::SpannedError) -> SceneError {
    use ron::error::Error as E;
    let pos = e.span.start;
    let locator = Locator::new(source);
    let enclosing = locator.field_at(pos.line, pos.col).unwrap_or_default();
    let (mut line, mut column) = (pos.line, pos.col);
    let (field, expected) = match &e.code {
        E::NoSuchStructField {
            expected, found, ..
        } => (
            join(&enclosing_parent(&enclosing, found), found),
            format!("one of the fields {} (found `{found}`)", list(expected)),
        ),
        E::MissingStructField { field, outer } => {
            // ron reports the closing bracket; point at the struct that lacks the field.
            let (group, start) = locator
                .group_at(pos.line, pos.col)
                .unwrap_or((String::new(), (pos.line, pos.col)));
            (line, column) = start;
            (
                join(&group, field),
                format!(
                    "a required field `{field}`{}",
                    outer
                        .as_ref()
                        .map(|o| format!(" in {o}"))
                        .unwrap_or_default()
                ),
            )
        }
        E::NoSuchEnumVariant {
            expected, found, ..
        } => (
            enclosing,
            format!("one of {} (found `{found}`)", list(expected)),
        ),
        E::DuplicateStructField { field, .. } => (
            join(&enclosing, field),
            "each field at most once".to_string(),
        ),
        other => (enclosing, format!("valid RON: {other}")),
    };
    SceneError {
        file: path.to_path_buf(),
        line,
        column,
        field,
        expected,
    }
}

fn enclosing_parent(enclosing: &str, found: &str) -> String {
    // The locator may already have entered the unknown field; strip it.
    enclosing
        .strip_suffix(found)
        .map(|s| s.trim_end_matches('.').to_string())
        .unwrap_or_else(|| enclosing.to_string())
}

fn join(parent: &str, field: &str) -> String {
    if parent.is_empty() {
        field.to_string()
    } else {
        format!("{parent}.{field}")
    }
}

fn list(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}
