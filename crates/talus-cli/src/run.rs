//! Running a scene: build, step with progress, sample the report, write the outputs,
//! and on a blow-up stop with a diagnosis and the last good state on disk.

use std::fmt;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use bevy_ecs::prelude::*;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use talus_contact::LawRegistry;
use talus_core::prelude::*;
use talus_scene::SceneError;
use talus_scene::state::{BinaryStateFile, SavedState};

use crate::report::{BlowUpReport, Report, ReportSample, WallClock};

/// How to run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Output folder; default `out/<scene name>/`.
    pub out: Option<PathBuf>,
    /// Print nothing but errors.
    pub quiet: bool,
    /// Show a progress bar (only drawn on a terminal).
    pub progress: bool,
    /// Continue the run saved in this state file (written by this scene's run) instead
    /// of starting it: bit-identical to the run that was not interrupted.
    pub resume: Option<PathBuf>,
    /// Write the final state to `state.ron` even if the scene does not ask for it.
    pub save_state: bool,
}

/// What a finished run produced.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Output folder.
    pub out_dir: PathBuf,
    /// The recording, if one was written.
    pub recording: Option<PathBuf>,
    /// The report file.
    pub report_path: PathBuf,
    /// The report.
    pub report: Report,
    /// The final state, if one was written.
    pub state: Option<PathBuf>,
}

impl RunSummary {
    /// A few lines for the terminal.
    pub fn describe(&self) -> String {
        let r = &self.report;
        let mut s = format!(
            "{}: {} grains, {} steps of {:.3e} s ({:.4} s simulated, {}) in {:.2} s wall clock ({:.3e} grain-steps/s)\n",
            r.scene,
            r.grain_count,
            r.steps,
            r.time_step,
            r.simulated_time,
            r.stopped,
            r.wall_clock.total,
            r.wall_clock.grain_steps_per_second
        );
        s += &format!("report:    {}\n", self.report_path.display());
        if let Some(state) = &self.state {
            s += &format!(
                "state:     {}  (continue with `talus run SCENE --resume {}`)\n",
                state.display(),
                state.display()
            );
        }
        if let Some(rec) = &self.recording {
            s += &format!(
                "recording: {}  (open with the rerun viewer 0.36.3: `rerun {}`)\n",
                rec.display(),
                rec.display()
            );
        }
        s
    }
}

/// Why a run failed.
#[derive(Debug)]
pub enum RunError {
    /// The scene is invalid.
    Scene(SceneError),
    /// An output could not be written.
    Output(String),
    /// The state became unphysical; the report and the last good state were written.
    BlowUp {
        /// Diagnosis.
        message: String,
        /// The report written before stopping.
        report_path: PathBuf,
    },
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RunError::Scene(e) => write!(f, "{e}"),
            RunError::Output(e) => write!(f, "{e}"),
            RunError::BlowUp {
                message,
                report_path,
            } => write!(f, "{message}\nreport: {}", report_path.display()),
        }
    }
}

impl std::error::Error for RunError {}

impl From<SceneError> for RunError {
    fn from(e: SceneError) -> Self {
        RunError::Scene(e)
    }
}

/// Validates a scene and describes its plan.
pub fn check_scene(path: &Path, registry: &LawRegistry) -> Result<String, SceneError> {
    let scene = talus_scene::load(path)?;
    let built = scene.build(registry)?;
    let plan = built.builder.plan();
    let mut s = format!("scene `{}` ({}): valid\n", built.name, path.display());
    s += &format!("plugins built: {}\n", plan.plugins.join(", "));
    for note in &plan.notes {
        s += &format!("{note}\n");
    }
    if built.output.recording {
        s += &format!(
            "export: rerun recording every {} s of simulated time\n",
            built.output.recording_interval
        );
    }
    s += "stages:\n";
    for (stage, systems) in &plan.stages {
        s += &format!(
            "  {:<22} {}\n",
            stage.name(),
            if systems.is_empty() {
                "-".to_string()
            } else {
                systems.join(", ")
            }
        );
    }
    Ok(s)
}

fn steps_for(interval: f64, dt: f64) -> u64 {
    ((interval / dt).round() as u64).max(1)
}

/// Builds and runs a scene, writing the report (and the recording if asked for).
pub fn run_scene(
    path: &Path,
    registry: &LawRegistry,
    options: &RunOptions,
) -> Result<RunSummary, RunError> {
    let scene = talus_scene::load(path)?;
    let built = match &options.resume {
        Some(state_path) => {
            let state = SavedState::read(state_path).map_err(RunError::Output)?;
            scene.resume(registry, &state)?
        }
        None => scene.build(registry)?,
    };
    let resumed = built.resumed;
    let out_dir = options
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&built.name));
    std::fs::create_dir_all(&out_dir)
        .map_err(|e| RunError::Output(format!("cannot create {}: {e}", out_dir.display())))?;
    let mut builder = built.builder;
    let dt = builder.config().dt;
    // Steps between recorded frames, when the scene records (a frame logs the energies).
    let mut recording_every = None;
    let recording = if built.output.recording {
        let rec = out_dir.join("recording.rrd");
        let every = steps_for(built.output.recording_interval, dt);
        recording_every = Some(every);
        talus_rerun::RerunExportPlugin::new(&rec, every)
            .with_recording_name(format!("talus/{}", built.name))
            .install(&mut builder)
            .map_err(|e| RunError::Output(format!("cannot write {}: {e}", rec.display())))?;
        Some(rec)
    } else {
        None
    };
    let mut sim = builder.build();
    if resumed {
        sim.mark_primed();
    }
    let report_every = steps_for(built.output.report_interval, dt);
    let total_steps = built.stop.steps;
    // The kinetic energies are read at report steps, recorded frames and, by a deposition,
    // at its checks: the second kick sums them only for those steps
    // (`KineticEnergyDue`).
    let deposition = sim
        .world
        .contains_resource::<talus_scene::packing::Deposition>();
    let kinetic_due = |step: u64| {
        deposition
            || step.is_multiple_of(report_every)
            || step == total_steps
            || recording_every.is_some_and(|every| step.is_multiple_of(every))
    };
    let config = sim.config().clone();

    let progress = if options.progress && !options.quiet && std::io::stderr().is_terminal() {
        let bar = ProgressBar::with_draw_target(Some(total_steps), ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template(
                "{bar:30} {pos}/{len} steps  t = {msg}  {per_sec}  ETA {eta}",
            )
            .expect("valid template"),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let progress_every = (total_steps / 500).max(1);

    let start = Instant::now();
    let mut samples = Vec::new();
    let mut stopped = "completed".to_string();
    let mut blow_up = None;
    // The last good state lives on disk, rewritten at every report, not in memory.
    let mut last_good = BinaryStateFile::new(out_dir.join("last_good_state.bin"));
    let primed = sim.prime();
    let priming = start.elapsed().as_secs_f64();
    // The stage timings are those of the steps; the priming pass has its own figure.
    sim.world.resource_mut::<StageTimings>().clear();
    let mut stepping = 0.0;
    let first_step = sim.step_count();
    if let Err(b) = primed {
        blow_up = Some(b);
    } else {
        samples.push(ReportSample::take(&sim.world));
        keep_last_good(&mut last_good, &mut sim.world, &built.name, options.quiet);
        // The pool's other workers poll for work through the whole loop, not only through
        // each step: between two steps they went back to rayon's idle loop and joined the
        // next step's first parallel loop some 10 µs late (`with_workers_polling`).
        let idle = sim.world.resource::<StageTimings>().idle.clone();
        talus_core::workers::with_workers_polling_booked(Some(&idle), || {
            for step in sim.step_count() + 1..=total_steps {
                let due = kinetic_due(step);
                sim.world.resource_mut::<KineticEnergyDue>().0 = due;
                let step_start = Instant::now();
                // A step whose end is neither reported nor recorded may leave its second kick
                // to the next step (one pass over the grains fewer, the same bits).
                let stepped = if due {
                    sim.step()
                } else {
                    sim.step_before_another()
                };
                stepping += step_start.elapsed().as_secs_f64();
                if let Err(b) = stepped {
                    sim.synchronize();
                    blow_up = Some(b);
                    break;
                }
                if step % progress_every == 0 {
                    progress.set_position(step);
                    progress.set_message(format!("{:.4} s", sim.time()));
                }
                let requested = sim.world.resource::<StopRequest>().0.clone();
                if step % report_every == 0 || step == total_steps || requested.is_some() {
                    if !due {
                        // A stop asked for at a step that was not to be reported.
                        sim.synchronize();
                        talus_core::integrate::sum_kinetic_energy(&mut sim.world);
                    }
                    let sample = ReportSample::take(&sim.world);
                    let settled = built
                        .stop
                        .settle_kinetic_energy
                        .is_some_and(|e| sample.kinetic() / built.grain_count as f64 <= e);
                    samples.push(sample);
                    keep_last_good(&mut last_good, &mut sim.world, &built.name, options.quiet);
                    if let Some(reason) = requested {
                        stopped = reason;
                        break;
                    }
                    if settled {
                        stopped = "settled".into();
                        break;
                    }
                }
            }
        });
    }
    // The last step is always reported; whatever ended the loop, the state is the last
    // step's end.
    sim.synchronize();
    progress.finish_and_clear();
    let elapsed = start.elapsed().as_secs_f64();
    if recording.is_some() {
        talus_rerun::finish(&mut sim.world)
            .map_err(|e| RunError::Output(format!("recording: {e}")))?;
    }

    let timings = sim.world.resource::<StageTimings>();
    let steps_run = sim.step_count();
    let mut report = Report {
        scene: built.name.clone(),
        scene_file: path.display().to_string(),
        talus_version: env!("CARGO_PKG_VERSION").to_string(),
        dimension: config.dimension.as_number(),
        time_step: config.dt,
        time_step_reason: built.time_step_reason.clone(),
        integrator: format!("{:?}", config.integrator),
        rotation: config.rotation,
        grain_count: built.grain_count,
        steps: steps_run,
        simulated_time: sim.time(),
        stopped,
        plugins: sim.plan.plugins.clone(),
        dissipation_channels: sim.world.resource::<DissipationChannels>().names.clone(),
        energy_ledger: sim
            .world
            .get_resource::<ContactEnergyBooking>()
            .is_none_or(|b| b.0),
        samples,
        neighbour_list_builds: sim
            .world
            .get_resource::<talus_collision::NeighbourList>()
            .map_or(0, |list| list.builds),
        wall_clock: WallClock {
            total: elapsed,
            priming,
            stepping,
            stages: Stage::ALL
                .iter()
                .map(|s| (s.name().to_string(), timings.get(*s)))
                .collect(),
            stage_idle: Stage::ALL
                .iter()
                .map(|s| (s.name().to_string(), timings.idle_seconds(*s)))
                .collect(),
            grain_steps_per_second: built.grain_count as f64
                * steps_run.saturating_sub(first_step) as f64
                / stepping.max(1e-12),
            grain_sorts: timings.grain_sorts,
            grain_sorting: timings.grain_sort_seconds,
        },
        blow_up: None,
    };
    let report_path = out_dir.join("report.json");
    let mut blow_message = None;
    if let Some(b) = blow_up {
        report.stopped = "blow_up".into();
        let state_path = out_dir.join("last_good_state.ron");
        // A state that cannot be read back or written costs the state, not the report.
        let (written, state_error) = match last_good.step() {
            Some(_) => match last_good
                .read(&sim.world)
                .and_then(|s| s.write(&state_path))
            {
                Ok(()) => (Some(state_path.display().to_string()), None),
                Err(e) => (None, Some(e)),
            },
            None => (None, None),
        };
        let bodies: Vec<String> = b
            .entities
            .iter()
            .map(|&e| describe_body(&sim.world, e))
            .collect();
        blow_message = Some(format!(
            "run stopped at step {}: {}\nbodies involved: {}\nlast good state (step {}): {}",
            b.step,
            b.reason,
            if bodies.is_empty() {
                "-".to_string()
            } else {
                bodies.join(", ")
            },
            last_good.step().unwrap_or(0),
            written
                .clone()
                .or(state_error)
                .unwrap_or_else(|| "none".into())
        ));
        report.blow_up = Some(BlowUpReport {
            step: b.step,
            reason: b.reason,
            bodies: b.entities.iter().map(|e| e.to_bits()).collect(),
            last_good_state: written,
        });
    }
    // Written as RON if the run blew up; a scratch file otherwise (deleted on drop).
    drop(last_good);
    let state_path = (blow_message.is_none() && (built.output.state || options.save_state))
        .then(|| out_dir.join("state.ron"));
    if let Some(p) = &state_path {
        SavedState::capture(&mut sim.world, &built.name)
            .write(p)
            .map_err(RunError::Output)?;
    }
    write_json(&report_path, &report)?;
    write_fields(&sim.world, &out_dir)?;
    if let Some(message) = blow_message {
        return Err(RunError::BlowUp {
            message,
            report_path,
        });
    }
    Ok(RunSummary {
        out_dir,
        recording,
        report_path,
        report,
        state: state_path,
    })
}

/// Rewrites the last good state on disk. A failed write (a full disk) does not stop the
/// run: the previous state stays, and a warning says so.
fn keep_last_good(file: &mut BinaryStateFile, world: &mut World, scene: &str, quiet: bool) {
    if let Err(e) = file.write(world, scene)
        && !quiet
    {
        eprintln!(
            "warning: {e}; the last good state on disk stays at step {}",
            file.step().map_or("none".to_string(), |s| s.to_string())
        );
    }
}

/// A body named for a person: a grain by its entity id,
/// position and radius, a wall by its name.
fn describe_body(world: &World, e: Entity) -> String {
    if let Some(wall) = world.get::<Wall>(e) {
        return format!("wall `{}`", wall.name);
    }
    match (world.get::<Position>(e), world.get::<Radius>(e)) {
        (Some(p), Some(r)) => format!(
            "grain {} (entity {}) at ({:.6e}, {:.6e}, {:.6e}) m, radius {:.4e} m",
            e.index_u32(),
            e.to_bits(),
            p.0.x,
            p.0.y,
            p.0.z,
            r.0
        ),
        _ => format!("entity {}", e.to_bits()),
    }
}

/// Writes the last coarse-grained field sample to `fields.json` (compact: a field is
/// large), when the scene samples fields (`docs/report-format.md` §3.3).
fn write_fields(world: &World, out_dir: &Path) -> Result<(), RunError> {
    let Some(fields) = world
        .get_resource::<talus_stress::FieldRecord>()
        .and_then(|r| r.latest.as_ref())
    else {
        return Ok(());
    };
    let path = out_dir.join(FIELDS_FILE);
    let text = serde_json::to_string(fields)
        .map_err(|e| RunError::Output(format!("cannot encode {}: {e}", path.display())))?;
    std::fs::write(&path, text)
        .map_err(|e| RunError::Output(format!("cannot write {}: {e}", path.display())))
}

/// Name of the file holding the last coarse-grained field sample, in the output folder.
pub const FIELDS_FILE: &str = "fields.json";

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), RunError> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| RunError::Output(format!("cannot encode {}: {e}", path.display())))?;
    std::fs::write(path, text)
        .map_err(|e| RunError::Output(format!("cannot write {}: {e}", path.display())))
}
