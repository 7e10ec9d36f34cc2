//! `talus accuracy`: what accuracy costs in time. Runs one scene under a list of settings
//! (steps per collision, integrator, contact-law parameters), measures a quantity in each
//! run against a reference (an analytic value, or the finest run), and writes the error
//! beside the wall-clock time as a table (Markdown and CSV) and a log–log plot (SVG), with
//! the setting that reaches a requested tolerance fastest.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::Deserialize;
use talus_contact::LawRegistry;
use talus_core::prelude::*;
use talus_scene::schema::IntegratorName;
use talus_scene::{Scene, SceneError};

/// A study file: `Study(scene: "impact.ron", quantity: Restitution(grains: (0, 1)), ...)`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "Study")]
pub struct StudySpec {
    /// The scene, relative to the study file.
    pub scene: String,
    /// What is measured in each run.
    pub quantity: Quantity,
    /// What the measurement is compared with.
    #[serde(default)]
    pub reference: Reference,
    /// Relative error the user needs; the report names the fastest setting below it.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// The settings to run, each a variation of the scene.
    pub settings: Vec<Setting>,
}

fn default_tolerance() -> f64 {
    1e-3
}

/// A measured quantity.
#[derive(Clone, Debug, Deserialize)]
pub enum Quantity {
    /// Normal restitution of the collision of two grains (indices in the scene's grain
    /// order): −(v_a − v_b)·n_0 at the end over the same at the start, n_0 the initial
    /// direction from b to a.
    Restitution {
        /// The two grains.
        grains: (usize, usize),
    },
    /// Duration of the first contact between two grains, s: from the instant their overlap
    /// becomes positive to the instant it returns to zero, each interpolated between steps.
    ContactTime {
        /// The two grains.
        grains: (usize, usize),
    },
    /// A field of the report sample at the end of the run (or once the scene's
    /// `settle_kinetic_energy` is reached, as `talus run` stops) (`translational_kinetic`, `elastic`,
    /// `dissipated_total`, `contacts`, ...), or a JSON pointer into it for nested fields
    /// (`/stress/regions/0/solid_fraction` when the scene samples stress).
    Final {
        /// The field name.
        field: String,
    },
}

/// What the error is measured against.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
pub enum Reference {
    /// The run with the smallest time step (default).
    #[default]
    Finest,
    /// A known value (an analytic solution).
    Analytic(f64),
}

/// One setting: every field left out keeps the scene's own value.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Setting {
    /// Steps per shortest collision (the automatic time step).
    #[serde(default)]
    pub steps_per_collision: Option<f64>,
    /// The time step as a fraction of the critical (stability) step of the scene's
    /// stiffest pair; above 1 the run is forced and may blow up (a reported failure).
    #[serde(default)]
    pub critical_step_fraction: Option<f64>,
    /// Integration scheme.
    #[serde(default)]
    pub integrator: Option<IntegratorName>,
    /// Contact-law parameters set on every material's contact, e.g. a smoothing width.
    #[serde(default)]
    pub params: Vec<(String, f64)>,
}

impl Setting {
    /// A short label for tables and legends.
    pub fn label(&self) -> String {
        let mut parts = Vec::new();
        if let Some(n) = self.steps_per_collision {
            parts.push(format!("{n} steps/collision"));
        }
        if let Some(f) = self.critical_step_fraction {
            parts.push(format!("dt = {f} × critical"));
        }
        if let Some(i) = self.integrator {
            parts.push(format!("{i:?}"));
        }
        for (k, v) in &self.params {
            parts.push(format!("{k} = {v}"));
        }
        if parts.is_empty() {
            "scene as written".into()
        } else {
            parts.join(", ")
        }
    }

    fn family(&self) -> String {
        let mut parts = vec![format!("{:?}", self.integrator.unwrap_or_default())];
        for (k, v) in &self.params {
            parts.push(format!("{k} = {v}"));
        }
        parts.join(", ")
    }
}

/// One run of a study.
#[derive(Clone, Debug)]
pub struct StudyRow {
    /// The setting.
    pub setting: Setting,
    /// Its time step, s.
    pub dt: f64,
    /// Steps run.
    pub steps: u64,
    /// The measured value.
    pub value: f64,
    /// |value − reference| / |reference|.
    pub error: f64,
    /// Wall-clock time of the run, s.
    pub seconds: f64,
}

/// The outcome of a study.
#[derive(Clone, Debug)]
pub struct StudyResult {
    /// One row per setting, in the study's order.
    pub rows: Vec<StudyRow>,
    /// The reference value.
    pub reference: f64,
    /// Index of the fastest row within the tolerance, if any.
    pub fastest_within_tolerance: Option<usize>,
    /// The tolerance.
    pub tolerance: f64,
    /// Files written: table (Markdown), CSV, plot (SVG).
    pub files: Vec<PathBuf>,
}

/// Why a study could not be done.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The study file is invalid.
    #[error("{0}")]
    Study(String),
    /// The scene, or a setting of it, is invalid.
    #[error("{0}")]
    Scene(#[from] SceneError),
    /// A run blew up or an output could not be written.
    #[error("{0}")]
    Run(String),
}

/// Reads a study file; errors name the file, line and column.
pub fn load_study(path: &Path) -> Result<StudySpec, StudyError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| StudyError::Study(format!("{}: cannot read: {e}", path.display())))?;
    let spec: StudySpec = ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str(&text)
        .map_err(|e| {
            StudyError::Study(format!(
                "{}:{}:{}: {}",
                path.display(),
                e.span.start.line,
                e.span.start.col,
                e.code
            ))
        })?;
    if spec.settings.is_empty() {
        return Err(StudyError::Study(format!(
            "{}: field `settings`: expected at least one setting",
            path.display()
        )));
    }
    if !(spec.tolerance > 0.0 && spec.tolerance.is_finite()) {
        return Err(StudyError::Study(format!(
            "{}: field `tolerance`: expected a positive relative error",
            path.display()
        )));
    }
    Ok(spec)
}

/// Runs a study and writes its table, CSV and plot into `out`.
pub fn run_study(
    study_path: &Path,
    registry: &LawRegistry,
    out: &Path,
) -> Result<StudyResult, StudyError> {
    let spec = load_study(study_path)?;
    let scene_path = study_path
        .parent()
        .map_or_else(|| PathBuf::from(&spec.scene), |d| d.join(&spec.scene));
    let base = talus_scene::load(&scene_path)?;
    let mut rows = Vec::with_capacity(spec.settings.len());
    for setting in &spec.settings {
        rows.push(run_setting(&base, setting, &spec.quantity, registry)?);
    }
    let reference = match spec.reference {
        Reference::Analytic(v) => v,
        Reference::Finest => {
            let finest = rows
                .iter()
                .min_by(|a, b| a.dt.total_cmp(&b.dt))
                .expect("at least one setting");
            finest.value
        }
    };
    for r in &mut rows {
        r.error = (r.value - reference).abs() / reference.abs().max(f64::MIN_POSITIVE);
    }
    let is_reference =
        |r: &StudyRow| matches!(spec.reference, Reference::Finest) && r.value == reference;
    let fastest_within_tolerance = rows
        .iter()
        .enumerate()
        .filter(|(_, r)| r.error <= spec.tolerance && !is_reference(r))
        .min_by(|a, b| a.1.seconds.total_cmp(&b.1.seconds))
        .map(|(i, _)| i);
    std::fs::create_dir_all(out)
        .map_err(|e| StudyError::Run(format!("cannot create {}: {e}", out.display())))?;
    let mut result = StudyResult {
        rows,
        reference,
        fastest_within_tolerance,
        tolerance: spec.tolerance,
        files: Vec::new(),
    };
    write_outputs(&mut result, &spec, out)?;
    Ok(result)
}

fn run_setting(
    base: &Scene,
    setting: &Setting,
    quantity: &Quantity,
    registry: &LawRegistry,
) -> Result<StudyRow, StudyError> {
    let mut scene = base.clone();
    if let Some(n) = setting.steps_per_collision {
        scene.file.steps_per_collision = n;
        scene.file.time_step = None;
    }
    if let Some(i) = setting.integrator {
        scene.file.integrator = i;
    }
    for m in &mut scene.file.materials {
        if let Some(c) = &mut m.contact {
            for (k, v) in &setting.params {
                match c.params.iter_mut().find(|(name, _)| name == k) {
                    Some(slot) => slot.1 = *v,
                    None => c.params.push((k.clone(), *v)),
                }
            }
        }
    }
    let mut built = scene.build(registry)?;
    if let Some(fraction) = setting.critical_step_fraction {
        if !(fraction > 0.0 && fraction.is_finite() && built.stability_limit.is_finite()) {
            return Err(StudyError::Study(format!(
                "field `critical_step_fraction`: expected a positive fraction of a finite critical step, found {fraction} (critical step {:e} s)",
                built.stability_limit
            )));
        }
        // Same duration, the step set from the critical one.
        let duration = built.stop.steps as f64 * built.builder.world.resource::<SimConfig>().dt;
        scene.file.time_step = Some(fraction * built.stability_limit);
        scene.file.force_time_step = true;
        if scene.file.steps.is_some() {
            scene.file.steps = None;
            scene.file.duration = Some(duration);
        }
        built = scene.build(registry)?;
    }
    let steps = built.stop.steps;
    let settle = built.stop.settle_kinetic_energy;
    let grain_count = built.grain_count;
    let report_interval = built.output.report_interval;
    let mut sim = built.builder.build();
    let dt = sim.config().dt;
    let started = Instant::now();
    let fail = |b: BlowUp| {
        StudyError::Run(format!(
            "{}: step {}: {}",
            setting.label(),
            b.step,
            b.reason
        ))
    };
    sim.prime().map_err(fail)?;
    let value = match quantity {
        Quantity::Restitution { grains } => {
            let (a, b) = grain_entities(&mut sim.world, *grains)?;
            let (n0, v0) = relative(&sim.world, a, b);
            sim.run_steps(steps).map_err(fail)?;
            let (_, v1) = relative(&sim.world, a, b);
            -v1.dot(n0) / v0.dot(n0)
        }
        Quantity::ContactTime { grains } => {
            let (a, b) = grain_entities(&mut sim.world, *grains)?;
            let overlap = |world: &World| {
                let pa = world.get::<Position>(a).expect("grain").0;
                let pb = world.get::<Position>(b).expect("grain").0;
                let ra = world.get::<Radius>(a).expect("grain").0;
                let rb = world.get::<Radius>(b).expect("grain").0;
                ra + rb - pa.distance(pb)
            };
            // The instants the overlap crosses zero, interpolated linearly between steps,
            // so that the measure itself does not carry an error of order dt.
            let (mut start, mut end) = (None, None);
            let mut previous = overlap(&sim.world);
            for k in 1..=steps {
                sim.step().map_err(fail)?;
                let now = overlap(&sim.world);
                let crossing = (k - 1) as f64 * dt + dt * previous / (previous - now);
                if previous <= 0.0 && now > 0.0 && start.is_none() {
                    start = Some(crossing);
                } else if previous > 0.0 && now <= 0.0 && start.is_some() && end.is_none() {
                    end = Some(crossing);
                }
                previous = now;
            }
            match (start, end) {
                (Some(t0), Some(t1)) => t1 - t0,
                _ => {
                    return Err(StudyError::Run(format!(
                        "{}: grains {grains:?} did not both start and end a contact within the run",
                        setting.label()
                    )));
                }
            }
        }
        Quantity::Final { field } => {
            // Like `talus run`: stop early once settled, checked every report interval.
            let every = ((report_interval / dt).round() as u64).max(1);
            for k in 1..=steps {
                sim.step().map_err(fail)?;
                if k % every == 0
                    && settle.is_some_and(|e| {
                        crate::ReportSample::take(&sim.world).kinetic() / grain_count as f64 <= e
                    })
                {
                    break;
                }
            }
            let sample = crate::ReportSample::take(&sim.world);
            let json = serde_json::to_value(&sample).expect("a sample serialises");
            // A JSON pointer (`/stress/regions/0/solid_fraction`) reaches nested fields.
            let value = if field.starts_with('/') {
                json.pointer(field)
            } else {
                json.get(field)
            };
            value.and_then(|v| v.as_f64()).ok_or_else(|| {
                StudyError::Study(format!(
                    "field `quantity.field`: expected a numeric field of a report sample (translational_kinetic, elastic, dissipated_total, ...) or a JSON pointer to one (/stress/regions/0/solid_fraction), found `{field}`{}",
                    if sim.world.get_resource::<ContactEnergyBooking>().is_none_or(|b| b.0) {
                        ""
                    } else {
                        " (the contact energies and balances exist only with `output.energy_ledger: true`)"
                    }
                ))
            })?
        }
    };
    Ok(StudyRow {
        setting: setting.clone(),
        dt,
        steps,
        value,
        error: f64::NAN,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The entities of two grains given by their index in the scene's grain order.
fn grain_entities(
    world: &mut World,
    (i, j): (usize, usize),
) -> Result<(Entity, Entity), StudyError> {
    let mut q = world.query_filtered::<Entity, With<Grain>>();
    let all: Vec<Entity> = q.iter(world).collect();
    match (all.get(i), all.get(j)) {
        (Some(&a), Some(&b)) if i != j => Ok((a, b)),
        _ => Err(StudyError::Study(format!(
            "field `quantity.grains`: expected two different grain indices below {}, found ({i}, {j})",
            all.len()
        ))),
    }
}

/// Direction from b to a and relative velocity v_a − v_b.
fn relative(world: &World, a: Entity, b: Entity) -> (DVec3, DVec3) {
    let pa = world.get::<Position>(a).expect("grain").0;
    let pb = world.get::<Position>(b).expect("grain").0;
    let va = world.get::<Velocity>(a).expect("grain").0;
    let vb = world.get::<Velocity>(b).expect("grain").0;
    ((pa - pb).normalize_or_zero(), va - vb)
}

fn write_outputs(result: &mut StudyResult, spec: &StudySpec, out: &Path) -> Result<(), StudyError> {
    let io =
        |p: &Path, e: std::io::Error| StudyError::Run(format!("cannot write {}: {e}", p.display()));
    let mut md = String::new();
    let _ = writeln!(
        md,
        "| setting | dt (s) | steps | value | relative error | wall clock (s) |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|");
    let mut csv = String::from("setting,dt,steps,value,relative_error,seconds\n");
    for (k, r) in result.rows.iter().enumerate() {
        let mark = if Some(k) == result.fastest_within_tolerance {
            " **(fastest within tolerance)**"
        } else {
            ""
        };
        let _ = writeln!(
            md,
            "| {}{mark} | {:.4e} | {} | {:.8e} | {:.3e} | {:.3} |",
            r.setting.label(),
            r.dt,
            r.steps,
            r.value,
            r.error,
            r.seconds
        );
        let _ = writeln!(
            csv,
            "\"{}\",{:e},{},{:e},{:e},{:e}",
            r.setting.label(),
            r.dt,
            r.steps,
            r.value,
            r.error,
            r.seconds
        );
    }
    let _ = writeln!(
        md,
        "\nReference: {} = {:.8e}. Tolerance {:.1e}: {}.",
        match spec.reference {
            Reference::Finest => "the finest run",
            Reference::Analytic(_) => "analytic value",
        },
        result.reference,
        result.tolerance,
        match result.fastest_within_tolerance {
            Some(k) => format!(
                "fastest setting within it: {}",
                result.rows[k].setting.label()
            ),
            None => "no setting reaches it".into(),
        }
    );
    let md_path = out.join("study.md");
    std::fs::write(&md_path, md).map_err(|e| io(&md_path, e))?;
    let csv_path = out.join("study.csv");
    std::fs::write(&csv_path, csv).map_err(|e| io(&csv_path, e))?;
    // One line per family (integrator and law parameters), error against wall clock.
    let mut families: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in &result.rows {
        if r.error > 0.0 && r.seconds > 0.0 {
            let name = r.setting.family();
            match families.iter_mut().find(|f| f.0 == name) {
                Some(f) => f.1.push((r.seconds, r.error)),
                None => families.push((name, vec![(r.seconds, r.error)])),
            }
        }
    }
    let mut chart = talus_plot::Chart::new(
        "What accuracy costs",
        talus_plot::Axis::log("wall-clock time (s)"),
        talus_plot::Axis::log("relative error"),
    );
    for (name, mut points) in families {
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart = chart.with(talus_plot::Series::line_and_points(name, points));
    }
    let svg_path = out.join("study.svg");
    match talus_plot::write_svg(&chart, &svg_path) {
        Ok(()) => result.files.push(svg_path),
        Err(talus_plot::PlotError::Empty(_)) => {} // every error exactly zero: nothing to plot
        Err(e) => return Err(StudyError::Run(e.to_string())),
    }
    result.files.insert(0, csv_path);
    result.files.insert(0, md_path);
    Ok(())
}
