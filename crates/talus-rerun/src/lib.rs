//! Talus rerun exporter: writes a rerun recording (`.rrd` file) of a running simulation,
//! headless (no viewer, no network), as a Talus [`Plugin`].
//!
//! # Use
//!
//! ```no_run
//! # use talus_core::schedule::SimBuilder;
//! # fn scene(mut builder: SimBuilder) -> Result<(), String> {
//! use talus_rerun::RerunExportPlugin;
//! // Opens (creates) the file now, so that a bad path is an error here, not a panic.
//! RerunExportPlugin::new("run.rrd", 100).install(&mut builder)?;
//! let mut sim = builder.build();
//! sim.run_steps(10_000).map_err(|b| b.reason)?;
//! // Flushes and closes the file; also reports the first logging error, if any.
//! talus_rerun::finish(&mut sim.world)?;
//! # Ok(()) }
//! ```
//!
//! Open the result with the rerun viewer of the same version (0.36.3):
//! `rerun run.rrd`.
//!
//! # What is recorded
//!
//! Every `every` steps (step 0, the priming pass that evaluates the initial forces,
//! included), on the timelines [`STEP_TIMELINE`] (sequence: the step number) and
//! [`TIME_TIMELINE`] (duration: simulated seconds):
//!
//! * [`GRAINS_PATH`]: one `Points3D` batch, one point per grain at its centre with its
//!   own radius, coloured by speed on a blue → grey → red ("cool–warm") ramp
//!   normalised by the frame's largest speed (all blue when everything is at rest).
//! * [`FORCE_CHAINS_PATH`]: one `LineStrips3D` batch with exactly one two-point strip
//!   per active contact: grain–grain from the centre of `a` to the centre of `b`,
//!   grain–wall from the centre of the grain to the contact point. With
//!   f = |F_n| / max|F_n| over the frame (F_n = force · normal), a strip's radius is
//!   R_mean · max(0.5 f, 0.02) (R_mean: mean grain radius) and its colour is the same
//!   blue → red ramp evaluated at f. An empty batch is logged when there is no contact.
//! * `walls/<name>`: each wall as a square outline in its plane (a segment in 2-D),
//!   centred on the projection of the grains' bounding-box centre and spanning the
//!   bounding box plus two largest radii. A wall at rest at the first exported frame
//!   is logged once, statically (so a scene that sets it in motion later keeps showing
//!   it where it was: static data shadows timeline data in rerun); a wall moving at the
//!   first exported frame is logged every frame.
//! * `stats/...`: scalars `translational_kinetic`, `rotational_kinetic`, `elastic`,
//!   `dissipated/<channel>` (one per dissipation channel), `gravity_work`, `wall_work`,
//!   `contacts`, `max_overlap_ratio`.
//! * `contacts/<law>/<quantity>`: only for a law that exposes per-contact quantities
//!   ([`talus_contact::ContactLaw::contact_quantity_names`]): one strip per active
//!   contact of the law, coloured by the value, and the values as the component
//!   [`QUANTITY_VALUE_FIELD`] (one f64 per strip); [`read_contact_quantity`] reads them
//!   back. Logged by a second system, scheduled only when such a law is installed.
//! * `/`: view coordinates, once, statically: right-handed, +Y up in 2-D or when gravity
//!   lies mostly along y, +Z up otherwise.
//!
//! [`read_counts`] reads a finished recording back (grain and strip counts per step),
//! [`read_entities`] lists what was logged where; the tests use them.

mod export;
mod readback;

use std::path::{Path, PathBuf};

use bevy_ecs::prelude::*;
use talus_core::schedule::{Plugin, SimBuilder, Stage};

pub use export::{QUANTITY_VALUE_FIELD, rerun_export, rerun_export_contact_quantities};
pub use readback::{EntitySummary, FrameCounts, read_contact_quantity, read_counts, read_entities};

/// Application id of the recordings this crate writes.
pub const APPLICATION_ID: &str = "talus";
/// Entity path of the grain points.
pub const GRAINS_PATH: &str = "grains";
/// Entity path of the force-chain strips (one per active contact).
pub const FORCE_CHAINS_PATH: &str = "contacts/force_chains";
/// Parent entity path of the walls (`walls/<name>`).
pub const WALLS_PATH: &str = "walls";
/// Parent entity path of the scalar statistics.
pub const STATS_PATH: &str = "stats";
/// Sequence timeline holding the step number.
pub const STEP_TIMELINE: &str = "step";
/// Duration timeline holding the simulated time.
pub const TIME_TIMELINE: &str = "sim_time";
/// Name of the export system in the plan.
pub const SYSTEM_NAME: &str = "rerun_export";
/// Name of the per-contact quantity export system in the plan (scheduled only when a law
/// of the scene exposes contact quantities).
pub const CONTACT_QUANTITIES_SYSTEM_NAME: &str = "rerun_export_contact_quantities";

/// The exporter plugin: records the simulation into a rerun `.rrd` file every
/// `every` steps from the [`Stage::Export`] stage.
///
/// Prefer [`RerunExportPlugin::install`], which opens the file first and returns an
/// error if it cannot be created. `SimBuilder::add_plugin` also works: then the file
/// is opened in [`Plugin::build`], and if that fails no system is added, the error is
/// noted in the plan and stored in a [`RerunExportError`] resource, and [`finish`]
/// returns it. Nothing panics.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RerunExportPlugin {
    /// Path of the `.rrd` file to create (truncated if it exists).
    pub path: PathBuf,
    /// Export every this many steps (0 is treated as 1). Step 0 is always exported.
    pub every: u64,
    /// Recording name shown by the viewer.
    pub recording_name: String,
}

impl RerunExportPlugin {
    /// A plugin writing to `path` every `every` steps, with the file stem as
    /// recording name (`"talus"` if the path has none).
    pub fn new(path: impl Into<PathBuf>, every: u64) -> Self {
        let path = path.into();
        let recording_name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| APPLICATION_ID.to_string());
        Self {
            path,
            every,
            recording_name,
        }
    }

    /// Sets the recording name.
    pub fn with_recording_name(mut self, name: impl Into<String>) -> Self {
        self.recording_name = name.into();
        self
    }

    /// Creates the file and the recording stream for this plugin's settings.
    pub fn open(&self) -> Result<RerunRecorder, String> {
        RerunRecorder::create(&self.path, self.every, &self.recording_name)
    }

    /// Opens the file, then adds the plugin to `sim`. Returns the error (and adds
    /// nothing) when the file cannot be created.
    pub fn install(&self, sim: &mut SimBuilder) -> Result<(), String> {
        let recorder = self.open()?;
        sim.world.insert_resource(recorder);
        sim.add_plugin(self);
        Ok(())
    }
}

impl Plugin for RerunExportPlugin {
    fn name(&self) -> String {
        "rerun_export".into()
    }

    fn build(&self, sim: &mut SimBuilder) {
        let opened = sim
            .world
            .get_resource::<RerunRecorder>()
            .is_some_and(|r| r.path == self.path);
        if !opened {
            match self.open() {
                Ok(recorder) => {
                    sim.world.insert_resource(recorder);
                }
                Err(e) => {
                    sim.note(format!("rerun export disabled: {e}"));
                    sim.world.insert_resource(RerunExportError(e));
                    return;
                }
            }
        }
        let every = sim.world.resource::<RerunRecorder>().every;
        sim.note(format!(
            "rerun recording: {} every {every} step(s)",
            self.path.display()
        ));
        sim.add_system(Stage::Export, SYSTEM_NAME, rerun_export);
        // Per-contact quantities only when a law of the scene exposes some.
        if sim
            .world
            .get_resource::<talus_contact::ContactQuantitySources>()
            .is_some_and(|s| !s.0.is_empty())
        {
            sim.add_system(
                Stage::Export,
                CONTACT_QUANTITIES_SYSTEM_NAME,
                rerun_export_contact_quantities,
            );
        }
    }
}

/// Why the exporter could not be started by [`Plugin::build`]; [`finish`] returns it.
#[derive(Resource, Clone, Debug, PartialEq, Eq)]
pub struct RerunExportError(pub String);

/// The open recording and the exporter's state: a resource read by [`rerun_export`].
#[derive(Resource)]
pub struct RerunRecorder {
    stream: rerun::RecordingStream,
    path: PathBuf,
    every: u64,
    frames: u64,
    error: Option<String>,
    state: export::ExportState,
}

impl RerunRecorder {
    /// Creates (truncates) the file at `path` and a headless recording stream writing to
    /// it, exporting every `every` steps (0 is treated as 1). Recording is forced on,
    /// whatever the `RERUN` environment variable says, and the wall-clock `log_time`
    /// timeline is turned off so that only [`STEP_TIMELINE`] and [`TIME_TIMELINE`] appear.
    pub fn create(
        path: impl AsRef<Path>,
        every: u64,
        recording_name: &str,
    ) -> Result<Self, String> {
        let path = path.as_ref().to_path_buf();
        let stream = rerun::RecordingStreamBuilder::new(APPLICATION_ID)
            .recording_name(recording_name)
            .enabled(true)
            .save(&path)
            .map_err(|e| format!("cannot create rerun recording {}: {e}", path.display()))?;
        stream.set_log_time_enabled(false);
        stream.set_log_tick_enabled(false);
        Ok(Self {
            stream,
            path,
            every: every.max(1),
            frames: 0,
            error: None,
            state: export::ExportState::default(),
        })
    }

    /// Path of the file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Export period, steps.
    pub fn every(&self) -> u64 {
        self.every
    }

    /// Frames exported so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The first logging error, if any (logging goes on after an error).
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// The underlying stream, for scenes that log extra data into the same recording.
    pub fn stream(&self) -> &rerun::RecordingStream {
        &self.stream
    }

    /// Flushes everything logged so far to the file and closes it (the file's footer is
    /// written when the stream is dropped here). Returns the number of frames exported,
    /// or the first logging or flushing error.
    pub fn finish(self) -> Result<u64, String> {
        let flushed = self
            .stream
            .flush_blocking()
            .map_err(|e| format!("cannot flush rerun recording {}: {e}", self.path.display()));
        let Self {
            stream,
            frames,
            error,
            ..
        } = self;
        // Dropping the last handle shuts the pipeline down and finalises the file.
        drop(stream);
        flushed?;
        match error {
            Some(e) => Err(e),
            None => Ok(frames),
        }
    }
}

/// Flushes and closes the recording of a simulation: removes the [`RerunRecorder`]
/// resource from `world` and calls [`RerunRecorder::finish`]. Call it once, after the
/// last step; the file is complete (readable by [`read_counts`] and the viewer) when it
/// returns. Returns the number of frames exported, `Ok(0)` when no exporter was
/// installed, or the error that kept the exporter from starting ([`RerunExportError`])
/// or that occurred while logging or flushing.
///
/// Dropping the world also closes the file, but silently.
pub fn finish(world: &mut World) -> Result<u64, String> {
    if let Some(RerunExportError(e)) = world.remove_resource::<RerunExportError>() {
        return Err(e);
    }
    match world.remove_resource::<RerunRecorder>() {
        Some(recorder) => recorder.finish(),
        None => Ok(0),
    }
}
