//! Reading a finished recording back: per-step counts of grain points and force-chain
//! strips, and the entities logged, for tests and checks. Uses [`rerun::ChunkStore::from_rrd_reader`], available
//! with the `sdk` feature alone.

use std::collections::BTreeMap;
use std::path::Path;

use rerun::external::arrow::array::{Array, AsArray as _};
use rerun::external::arrow::datatypes::Float64Type;
use rerun::{ChunkStore, ChunkStoreConfig, StoreKind, TimelineName};

use crate::{FORCE_CHAINS_PATH, GRAINS_PATH, STEP_TIMELINE, TIME_TIMELINE};

/// What one exported frame holds, as read back from the file.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameCounts {
    /// Value on the [`STEP_TIMELINE`] timeline.
    pub step: u64,
    /// Value on the [`TIME_TIMELINE`] timeline, seconds (nanosecond resolution).
    pub sim_time: f64,
    /// Number of points in the [`GRAINS_PATH`] batch (0 if none was logged).
    pub grains: usize,
    /// Number of strips in the [`FORCE_CHAINS_PATH`] batch (0 if none was logged).
    pub force_chains: usize,
}

/// Reads the recording at `path` and returns, for each logged step in increasing
/// order, the number of grain points and of force-chain strips. The file must be
/// complete (see [`crate::finish`]).
pub fn read_counts(path: impl AsRef<Path>) -> Result<Vec<FrameCounts>, String> {
    let path = path.as_ref();
    let stores = open_stores(path)?;

    let positions = rerun::Points3D::descriptor_positions().component;
    let strips = rerun::LineStrips3D::descriptor_strips().component;
    let step_timeline = TimelineName::from_static_str(STEP_TIMELINE);
    let time_timeline = TimelineName::from_static_str(TIME_TIMELINE);
    let grains_path = rerun::EntityPath::from(GRAINS_PATH);
    let chains_path = rerun::EntityPath::from(FORCE_CHAINS_PATH);

    let mut frames: BTreeMap<u64, FrameCounts> = BTreeMap::new();
    for store in &stores {
        for chunk in store.iter_physical_chunks() {
            let (component, is_grains) = if chunk.entity_path() == &grains_path {
                (positions, true)
            } else if chunk.entity_path() == &chains_path {
                (strips, false)
            } else {
                continue;
            };
            let Some(steps) = chunk.timelines().get(&step_timeline) else {
                continue;
            };
            let times = chunk.timelines().get(&time_timeline);
            let Some(column) = chunk.components().get(component) else {
                continue;
            };
            let lists = &column.list_array;
            for (row, step) in logged_rows(steps.times_raw(), lists, path)? {
                let count = lists.value_length(row) as usize;
                let frame = frames.entry(step).or_insert(FrameCounts {
                    step,
                    ..FrameCounts::default()
                });
                if let Some(t) = times.and_then(|t| t.times_raw().get(row)) {
                    frame.sim_time = *t as f64 * 1e-9;
                }
                if is_grains {
                    frame.grains = count;
                } else {
                    frame.force_chains = count;
                }
            }
        }
    }
    Ok(frames.into_values().collect())
}

/// The rows of a chunk's component column that hold a value, with their step (the chunk's
/// step times); an error names the file if a step is negative.
fn logged_rows(steps: &[i64], lists: &dyn Array, path: &Path) -> Result<Vec<(usize, u64)>, String> {
    let mut rows = Vec::with_capacity(steps.len());
    for (row, &step) in steps.iter().enumerate() {
        if lists.is_null(row) {
            continue;
        }
        let step = u64::try_from(step)
            .map_err(|_| format!("negative step {step} in {}", path.display()))?;
        rows.push((row, step));
    }
    Ok(rows)
}

/// Reads the per-contact values of one contact quantity of one law back from the
/// recording at `path` (entity `contacts/<law>/<quantity>`, component
/// [`crate::QUANTITY_VALUE_FIELD`]): for each recorded step in increasing order, one value
/// per active contact of the law, in the order of that frame's strips.
pub fn read_contact_quantity(
    path: impl AsRef<Path>,
    law: &str,
    quantity: &str,
) -> Result<Vec<(u64, Vec<f64>)>, String> {
    let path = path.as_ref();
    let stores = open_stores(path)?;
    let entity = rerun::EntityPath::new(vec![
        rerun::EntityPathPart::from("contacts"),
        rerun::EntityPathPart::new(law),
        rerun::EntityPathPart::new(quantity),
    ]);
    let field = rerun::ComponentIdentifier::from(crate::QUANTITY_VALUE_FIELD);
    let step_timeline = TimelineName::from_static_str(STEP_TIMELINE);
    let mut rows: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for store in &stores {
        for chunk in store.iter_physical_chunks() {
            if chunk.entity_path() != &entity {
                continue;
            }
            let (Some(steps), Some(column)) = (
                chunk.timelines().get(&step_timeline),
                chunk.components().get(field),
            ) else {
                continue;
            };
            let lists = &column.list_array;
            for (row, step) in logged_rows(steps.times_raw(), lists, path)? {
                let values = lists.value(row);
                let values = values
                    .as_primitive_opt::<Float64Type>()
                    .ok_or_else(|| format!("{entity}: values are not f64 in {}", path.display()))?;
                rows.insert(step, values.values().to_vec());
            }
        }
    }
    Ok(rows.into_iter().collect())
}

/// Rows logged to one entity, as read back from the file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EntitySummary {
    /// Entity path as rerun prints it, e.g. `/walls/floor` (special characters escaped,
    /// e.g. `/walls/x\ min`).
    pub path: String,
    /// Rows logged statically (`log_static`).
    pub static_rows: usize,
    /// Rows logged on the timelines.
    pub temporal_rows: usize,
}

/// Reads the recording at `path` and lists every entity that holds data, sorted by
/// path, with how many rows were logged to it statically and on the timelines.
pub fn read_entities(path: impl AsRef<Path>) -> Result<Vec<EntitySummary>, String> {
    let stores = open_stores(path.as_ref())?;
    let mut entities: BTreeMap<String, EntitySummary> = BTreeMap::new();
    for store in &stores {
        for chunk in store.iter_physical_chunks() {
            let name = chunk.entity_path().to_string();
            let entry = entities.entry(name.clone()).or_insert(EntitySummary {
                path: name,
                ..EntitySummary::default()
            });
            if chunk.is_static() {
                entry.static_rows += chunk.num_rows();
            } else {
                entry.temporal_rows += chunk.num_rows();
            }
        }
    }
    Ok(entities.into_values().collect())
}

/// Decodes the recording stores (not blueprints) of the file at `path`.
fn open_stores(path: &Path) -> Result<Vec<ChunkStore>, String> {
    let mut file = std::fs::File::open(path)
        .map_err(|e| format!("cannot open rerun recording {}: {e}", path.display()))?;
    // No compaction: every logged row stays in the chunk it was written in.
    let stores = ChunkStore::from_rrd_reader(&ChunkStoreConfig::ALL_DISABLED, &mut file)
        .map_err(|e| format!("cannot read rerun recording {}: {e:#}", path.display()))?;
    Ok(stores
        .into_iter()
        .filter(|(id, _)| id.kind() == StoreKind::Recording)
        .map(|(_, store)| store)
        .collect())
}
