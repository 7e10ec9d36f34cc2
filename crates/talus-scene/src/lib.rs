//! Talus scene files: the RON schema of an experiment, its validation with errors
//! that name the file, line, column, field and what was expected, and the building of
//! a simulation from it.
//!
//! ```text
//! let scene = talus_scene::load("scenes/pour.ron")?;   // parse + validate
//! let built = scene.build(&registry)?;                  // generate grains, pick dt, ...
//! ```

pub mod build;
pub mod error;
pub mod generate;
pub mod lammps;
pub mod locate;
pub mod packing;
pub mod schema;
pub mod state;

pub use build::{BuiltScene, StopCondition};
pub use error::SceneError;
pub use schema::SceneFile;

use std::path::{Path, PathBuf};

/// A parsed scene with the text it came from (kept to locate later errors).
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file it was read from (or a label for in-memory text).
    pub path: PathBuf,
    /// The source text.
    pub source: String,
    /// The parsed content.
    pub file: SceneFile,
}

/// Reads and parses a scene file.
pub fn load(path: impl AsRef<Path>) -> Result<Scene, SceneError> {
    let path = path.as_ref();
    let source = std::fs::read_to_string(path).map_err(|e| SceneError {
        file: path.to_path_buf(),
        line: 0,
        column: 0,
        field: String::new(),
        expected: format!("a readable scene file ({e})"),
    })?;
    parse(path, &source)
}

/// Parses scene text; `path` is used in messages.
pub fn parse(path: impl AsRef<Path>, source: &str) -> Result<Scene, SceneError> {
    let path = path.as_ref().to_path_buf();
    let options =
        ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME);
    match options.from_str::<SceneFile>(source) {
        Ok(file) => Ok(Scene {
            path,
            source: source.to_string(),
            file,
        }),
        Err(e) => Err(error::from_ron(&path, source, e)),
    }
}
