//! The export system: logs grains, force chains, walls and energy statistics of one
//! step into the recording, each new stress sample as scalars under `stress/`, and each
//! new coarse-grained field sample as point clouds under `fields/`.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rerun::{EntityPath, EntityPathPart};
use talus_contact::{Contact, ContactForce, ContactGeometry, ContactKind, ContactQuantitySources};
use talus_core::prelude::*;
use talus_stress::{FieldRecord, FieldSample, RegionStress, StressRecord, StressSample};

use crate::{
    FORCE_CHAINS_PATH, GRAINS_PATH, RerunRecorder, STATS_PATH, STEP_TIMELINE, TIME_TIMELINE,
    WALLS_PATH,
};

/// Parent entity path of the stress scalars (`stress/<region>/<quantity>`).
pub const STRESS_PATH: &str = "stress";
/// Point cloud of the field grid nodes coloured by density.
pub const FIELD_DENSITY_PATH: &str = "fields/density";
/// Point cloud of the field grid nodes coloured by pressure.
pub const FIELD_PRESSURE_PATH: &str = "fields/pressure";
/// Radius of a field node's point, as a fraction of the smallest cell edge.
const FIELD_NODE_RADIUS: f64 = 0.25;

/// Smallest force-chain radius, as a fraction of the mean grain radius.
const MIN_CHAIN_RADIUS: f32 = 0.02;
/// Force-chain radius at the largest normal force, as a fraction of the mean grain radius.
const MAX_CHAIN_RADIUS: f32 = 0.5;

/// How a wall is recorded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum WallMode {
    /// At rest at its first export: logged once, statically.
    Static,
    /// Moving at its first export: logged every frame.
    Moving,
}

/// Per-recording state kept between frames; scratch buffers are reused so that a
/// frame allocates only what the rerun serialisation itself needs.
#[derive(Default)]
pub(crate) struct ExportState {
    view_logged: bool,
    walls: Vec<(Entity, EntityPath, WallMode)>,
    stats_paths: Vec<EntityPath>,
    dissipated_paths: Vec<EntityPath>,
    power_paths: Vec<EntityPath>,
    positions: Vec<[f32; 3]>,
    radii: Vec<f32>,
    speeds: Vec<f64>,
    colors: Vec<rerun::Color>,
    strips: Vec<[[f32; 3]; 2]>,
    normal_forces: Vec<f64>,
    strip_radii: Vec<f32>,
    /// `stress/<region>/<quantity>` paths, per region, in [`STRESS_SCALARS`] order.
    stress_paths: Vec<Vec<EntityPath>>,
    /// [`StressRecord::taken`] of the last stress sample logged.
    stress_logged: u64,
    /// [`FieldRecord::taken`] of the last field sample logged.
    fields_logged: u64,
    /// `contacts/<law>/<quantity>` paths, per law of [`ContactQuantitySources`].
    quantity_paths: Vec<Vec<EntityPath>>,
    /// Contacts of one law in the frame being logged.
    quantity_contacts: Vec<Entity>,
    /// Their quantities, `names.len()` per contact.
    quantity_values: Vec<f64>,
    /// One quantity of every contact, in contact order.
    quantity_column: Vec<f64>,
}

/// Scalars logged per stress region, under `stress/<region>/`.
const STRESS_SCALARS: [&str; 17] = [
    "pressure",
    "shear_stress",
    "kinetic_share",
    "solid_fraction",
    "antisymmetric_norm",
    "couple_stress_norm",
    "shear_rate",
    "inertial_number",
    "sigma_xx",
    "sigma_yy",
    "sigma_zz",
    "sigma_xy",
    "sigma_yx",
    "sigma_xz",
    "sigma_zx",
    "sigma_yz",
    "sigma_zy",
];

/// Fixed scalar statistics, in the order of [`ExportState::stats_paths`].
const STATS: [&str; 7] = [
    "translational_kinetic",
    "rotational_kinetic",
    "elastic",
    "gravity_work",
    "wall_work",
    "contacts",
    "max_overlap_ratio",
];

/// The [`crate::RerunExportPlugin`] system, in [`Stage::Export`]: when a
/// [`RerunRecorder`] exists and `clock.step` is a multiple of its period, logs one frame.
/// A logging error is kept in the recorder (see [`RerunRecorder::error`]), never panics.
#[allow(clippy::too_many_arguments)]
pub fn rerun_export(
    clock: Res<Clock>,
    config: Res<SimConfig>,
    energy: Res<EnergySnapshot>,
    ledger: Res<EnergyLedger>,
    channels: Res<DissipationChannels>,
    booking: Option<Res<ContactEnergyBooking>>,
    recorder: Option<ResMut<RerunRecorder>>,
    grains: Query<(&Position, &Velocity, &Radius), With<Grain>>,
    contacts: Query<(&Contact, &ContactGeometry, &ContactForce)>,
    walls: Query<(Entity, &Wall)>,
    stress: Option<Res<StressRecord>>,
    periodic: Option<Res<PeriodicBox>>,
    fields: Option<Res<FieldRecord>>,
) {
    let Some(mut recorder) = recorder else {
        return;
    };
    // Stress samples are logged when they are taken, whatever the frame period.
    if let Some(record) = stress
        && let Some(sample) = &record.latest
        && record.taken != recorder.state.stress_logged
    {
        let recorder = &mut *recorder;
        recorder.state.stress_logged = record.taken;
        let planar = config.dimension == Dimension::Two;
        if let Err(e) = log_stress(&recorder.stream, &mut recorder.state, sample, planar)
            && recorder.error.is_none()
        {
            recorder.error = Some(format!("rerun stress export at step {}: {e}", clock.step));
        }
    }
    // Field samples too.
    if let Some(record) = fields
        && let Some(sample) = &record.latest
        && record.taken != recorder.state.fields_logged
    {
        let recorder = &mut *recorder;
        recorder.state.fields_logged = record.taken;
        let planar = config.dimension == Dimension::Two;
        if let Err(e) = log_fields(&recorder.stream, &mut recorder.state, sample, planar)
            && recorder.error.is_none()
        {
            recorder.error = Some(format!("rerun field export at step {}: {e}", clock.step));
        }
    }
    if !clock.step.is_multiple_of(recorder.every) {
        return;
    }
    let recorder = &mut *recorder;
    let result = log_frame(
        &recorder.stream,
        &mut recorder.state,
        &clock,
        &config,
        &grains,
        &contacts,
        &walls,
        periodic.as_deref(),
    )
    .and(log_stats(
        &recorder.stream,
        &mut recorder.state,
        &energy,
        &ledger,
        &channels,
        booking.is_none_or(|b| b.0),
    ));
    recorder.frames += 1;
    if let Err(e) = result
        && recorder.error.is_none()
    {
        recorder.error = Some(format!("rerun export at step {}: {e}", clock.step));
    }
}

/// Radius of a contact-quantity strip, as a fraction of the radius of the contact's grain.
const QUANTITY_STRIP_RADIUS: f64 = 0.15;

/// Name of the per-contact value column of a contact-quantity entity.
pub const QUANTITY_VALUE_FIELD: &str = "value";

/// The per-contact quantity export, in [`Stage::Export`] after [`rerun_export`], scheduled
/// only when a law of the scene exposes contact quantities ([`ContactQuantitySources`]):
/// on every recorded frame, for each such law and each of its quantities, logs to
/// `contacts/<law>/<quantity>` one `LineStrips3D` batch with one strip per active contact
/// of the law (drawn as the force chains are), coloured by the value (grey at 0, red
/// positive, blue negative, scaled by the frame's largest |value|), and the values
/// themselves as the component [`QUANTITY_VALUE_FIELD`] (one f64 per strip, same order).
pub fn rerun_export_contact_quantities(world: &mut World) {
    let step = world.resource::<Clock>().step;
    let time = world.resource::<Clock>().time;
    let Some(sources) = world.get_resource::<ContactQuantitySources>().cloned() else {
        return;
    };
    let Some(mut recorder) = world.remove_resource::<RerunRecorder>() else {
        return;
    };
    if step.is_multiple_of(recorder.every) {
        let result = log_contact_quantities(world, &mut recorder, &sources, step, time);
        if let Err(e) = result
            && recorder.error.is_none()
        {
            recorder.error = Some(format!("rerun contact-quantity export at step {step}: {e}"));
        }
    }
    world.insert_resource(recorder);
}

fn log_contact_quantities(
    world: &mut World,
    recorder: &mut RerunRecorder,
    sources: &ContactQuantitySources,
    step: u64,
    time: f64,
) -> rerun::RecordingStreamResult<()> {
    let s = &mut recorder.state;
    if s.quantity_paths.len() != sources.0.len() {
        s.quantity_paths = sources
            .0
            .iter()
            .map(|source| {
                source
                    .names
                    .iter()
                    .map(|q| {
                        EntityPath::new(vec![
                            "contacts".into(),
                            EntityPathPart::new(source.law),
                            EntityPathPart::new(*q),
                        ])
                    })
                    .collect()
            })
            .collect();
    }
    let rec = &recorder.stream;
    rec.set_time_sequence(STEP_TIMELINE, step as i64);
    rec.set_duration_secs(TIME_TIMELINE, time);
    let periodic = world.get_resource::<PeriodicBox>().cloned();
    for (source, paths) in sources.0.iter().zip(&s.quantity_paths) {
        s.quantity_contacts.clear();
        s.quantity_values.clear();
        (source.collect)(world, &mut s.quantity_contacts, &mut s.quantity_values);
        s.strips.clear();
        s.strip_radii.clear();
        for &entity in &s.quantity_contacts {
            let (Some(c), Some(g)) = (
                world.get::<Contact>(entity),
                world.get::<ContactGeometry>(entity),
            ) else {
                continue;
            };
            s.strips.push(strip_ends(
                c,
                g,
                |e| {
                    world
                        .get::<Position>(e)
                        .zip(world.get::<Radius>(e))
                        .map(|(p, r)| (p.0, r.0))
                },
                periodic.as_ref(),
            ));
            let radius = world.get::<Radius>(c.a).map_or(0.0, |r| r.0);
            s.strip_radii.push((QUANTITY_STRIP_RADIUS * radius) as f32);
        }
        let n = source.names.len();
        for (k, path) in paths.iter().enumerate() {
            s.quantity_column.clear();
            s.quantity_column
                .extend(s.quantity_values.iter().skip(k).step_by(n.max(1)).copied());
            let largest = s
                .quantity_column
                .iter()
                .map(|v| v.abs())
                .fold(0.0, f64::max);
            s.colors.clear();
            s.colors.extend(s.quantity_column.iter().map(|&v| {
                ramp(if largest > 0.0 {
                    0.5 + 0.5 * (v / largest).clamp(-1.0, 1.0)
                } else {
                    0.5
                })
            }));
            rec.log(
                path.clone(),
                &rerun::LineStrips3D::new(s.strips.iter().copied())
                    .with_radii(s.strip_radii.iter().copied())
                    .with_colors(s.colors.iter().copied()),
            )?;
            rec.log(
                path.clone(),
                &rerun::AnyValues::default().with_component::<rerun::components::Scalar>(
                    QUANTITY_VALUE_FIELD,
                    s.quantity_column.iter().copied(),
                ),
            )?;
        }
    }
    Ok(())
}

/// Axis-aligned bounding box of the grains, and radius statistics.
struct Extent {
    lo: DVec3,
    hi: DVec3,
    mean_radius: f64,
    max_radius: f64,
}

/// Sets the timelines and logs the view coordinates (once), grains, force chains and walls.
#[allow(clippy::too_many_arguments)]
fn log_frame(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    clock: &Clock,
    config: &SimConfig,
    grains: &Query<(&Position, &Velocity, &Radius), With<Grain>>,
    contacts: &Query<(&Contact, &ContactGeometry, &ContactForce)>,
    walls: &Query<(Entity, &Wall)>,
    periodic: Option<&PeriodicBox>,
) -> rerun::RecordingStreamResult<()> {
    // Timelines are thread-local to the stream; set them right before logging.
    rec.set_time_sequence(STEP_TIMELINE, clock.step as i64);
    rec.set_duration_secs(TIME_TIMELINE, clock.time);
    if !s.view_logged {
        let g = config.gravity;
        let view = if config.dimension == Dimension::Two || g.y.abs() > g.z.abs() {
            rerun::ViewCoordinates::RIGHT_HAND_Y_UP()
        } else {
            rerun::ViewCoordinates::RIGHT_HAND_Z_UP()
        };
        rec.log_static(EntityPath::root(), &view)?;
        s.view_logged = true;
    }
    let extent = log_grains(rec, s, grains)?;
    log_force_chains(rec, s, &extent, grains, contacts, periodic)?;
    log_walls(rec, s, &extent, config.dimension == Dimension::Two, walls)
}

fn log_grains(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    grains: &Query<(&Position, &Velocity, &Radius), With<Grain>>,
) -> rerun::RecordingStreamResult<Extent> {
    s.positions.clear();
    s.radii.clear();
    s.speeds.clear();
    s.colors.clear();
    let mut lo = DVec3::INFINITY;
    let mut hi = DVec3::NEG_INFINITY;
    let mut sum_radius = 0.0;
    let mut max_radius = 0.0f64;
    let mut max_speed = 0.0f64;
    for (p, v, r) in grains.iter() {
        s.positions.push(to_f32(p.0));
        s.radii.push(r.0 as f32);
        let speed = v.0.length();
        s.speeds.push(speed);
        max_speed = max_speed.max(speed);
        lo = lo.min(p.0 - DVec3::splat(r.0));
        hi = hi.max(p.0 + DVec3::splat(r.0));
        sum_radius += r.0;
        max_radius = max_radius.max(r.0);
    }
    let n = s.positions.len();
    s.colors
        .extend(s.speeds.iter().map(|&v| ramp(fraction(v, max_speed))));
    rec.log(
        GRAINS_PATH,
        &rerun::Points3D::new(s.positions.iter().copied())
            .with_radii(s.radii.iter().copied())
            .with_colors(s.colors.iter().copied()),
    )?;
    Ok(if n == 0 {
        Extent {
            lo: DVec3::splat(-0.5),
            hi: DVec3::splat(0.5),
            mean_radius: 0.0,
            max_radius: 0.0,
        }
    } else {
        Extent {
            lo,
            hi,
            mean_radius: sum_radius / n as f64,
            max_radius,
        }
    })
}

/// The ends of a contact's strip: from the centre of `a` to that of the image of `b`
/// nearest to it (across a periodic seam), or to the contact point for a wall.
/// `body_of` gives a grain's centre and radius. A contact's grains are always alive; one
/// not found would put that end at the contact point (or, for `a`, the origin), so that
/// every contact still gets its strip.
fn strip_ends(
    c: &Contact,
    g: &ContactGeometry,
    body_of: impl Fn(Entity) -> Option<(DVec3, f64)>,
    periodic: Option<&PeriodicBox>,
) -> [[f32; 3]; 2] {
    let (start, radius) = body_of(c.a).unwrap_or((DVec3::ZERO, 0.0));
    let point = g.point(start, radius);
    let end = match c.kind {
        ContactKind::GrainGrain => {
            let centre = body_of(c.b).map_or(point, |(centre, _)| centre);
            match periodic {
                Some(b) => start - b.min_image(start - centre),
                None => centre,
            }
        }
        ContactKind::GrainWall => point,
    };
    [to_f32(start), to_f32(end)]
}

fn log_force_chains(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    extent: &Extent,
    grains: &Query<(&Position, &Velocity, &Radius), With<Grain>>,
    contacts: &Query<(&Contact, &ContactGeometry, &ContactForce)>,
    periodic: Option<&PeriodicBox>,
) -> rerun::RecordingStreamResult<()> {
    s.strips.clear();
    s.normal_forces.clear();
    s.strip_radii.clear();
    s.colors.clear();
    let mut max_force = 0.0f64;
    for (c, g, f) in contacts.iter().filter(|(_, g, f)| f.is_active(g)) {
        s.strips.push(strip_ends(
            c,
            g,
            |e| grains.get(e).ok().map(|(p, _, r)| (p.0, r.0)),
            periodic,
        ));
        let normal_force = f.force.dot(g.normal).abs();
        max_force = max_force.max(normal_force);
        s.normal_forces.push(normal_force);
    }
    let r_mean = extent.mean_radius as f32;
    for &normal_force in &s.normal_forces {
        let t = fraction(normal_force, max_force);
        s.strip_radii
            .push(r_mean * (MAX_CHAIN_RADIUS * t as f32).max(MIN_CHAIN_RADIUS));
        s.colors.push(ramp(t));
    }
    rec.log(
        FORCE_CHAINS_PATH,
        &rerun::LineStrips3D::new(s.strips.iter().copied())
            .with_radii(s.strip_radii.iter().copied())
            .with_colors(s.colors.iter().copied()),
    )
}

fn log_walls(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    extent: &Extent,
    planar: bool,
    walls: &Query<(Entity, &Wall)>,
) -> rerun::RecordingStreamResult<()> {
    let centre = 0.5 * (extent.lo + extent.hi);
    let half = 0.5 * (extent.hi - extent.lo).length() + 2.0 * extent.max_radius;
    for (entity, wall) in walls.iter() {
        let known = s.walls.iter().position(|(e, _, _)| *e == entity);
        let first = known.is_none();
        let index = known.unwrap_or_else(|| {
            let mode = if wall.velocity == DVec3::ZERO {
                WallMode::Static
            } else {
                WallMode::Moving
            };
            let path = EntityPath::new(vec![
                EntityPathPart::from(WALLS_PATH),
                EntityPathPart::new(wall.name.as_str()),
            ]);
            s.walls.push((entity, path, mode));
            s.walls.len() - 1
        });
        let (_, path, mode) = &s.walls[index];
        if *mode == WallMode::Static && !first {
            continue;
        }
        let outline = wall_outline(wall, centre, half, planar);
        let strips = rerun::LineStrips3D::new([outline])
            .with_radii([(0.05 * extent.mean_radius).max(1e-4) as f32])
            .with_colors([rerun::Color::from_rgb(160, 160, 160)]);
        match mode {
            WallMode::Static => rec.log_static(path.clone(), &strips)?,
            WallMode::Moving => rec.log(path.clone(), &strips)?,
        }
    }
    Ok(())
}

/// Logs the energy statistics as scalars under `stats/`; the contact energies
/// (`elastic`, `wall_work`, `dissipated/*`, `dissipation_power/*`) only if `booked`
/// ([`ContactEnergyBooking`]).
fn log_stats(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    energy: &EnergySnapshot,
    ledger: &EnergyLedger,
    channels: &DissipationChannels,
    booked: bool,
) -> rerun::RecordingStreamResult<()> {
    if s.stats_paths.is_empty() {
        s.stats_paths = STATS
            .iter()
            .map(|name| EntityPath::new(vec![STATS_PATH.into(), (*name).into()]))
            .collect();
    }
    let names = &channels.names;
    if s.dissipated_paths.len() != names.len() {
        s.dissipated_paths = names
            .iter()
            .map(|name| {
                EntityPath::new(vec![
                    STATS_PATH.into(),
                    "dissipated".into(),
                    EntityPathPart::new(name.as_str()),
                ])
            })
            .collect();
    }
    let values = [
        energy.translational_kinetic,
        energy.rotational_kinetic,
        energy.elastic,
        ledger.gravity_work,
        ledger.wall_work,
        energy.contacts as f64,
        energy.max_overlap_ratio,
    ];
    for ((path, value), name) in s.stats_paths.iter().zip(values).zip(STATS) {
        if booked || !matches!(name, "elastic" | "wall_work") {
            rec.log(path.clone(), &rerun::Scalars::single(value))?;
        }
    }
    if !booked {
        return Ok(());
    }
    for (i, path) in s.dissipated_paths.iter().enumerate() {
        let value = ledger.dissipated.get(i).copied().unwrap_or(0.0);
        rec.log(path.clone(), &rerun::Scalars::single(value))?;
    }
    if s.power_paths.len() != names.len() {
        s.power_paths = names
            .iter()
            .map(|name| {
                EntityPath::new(vec![
                    STATS_PATH.into(),
                    "dissipation_power".into(),
                    EntityPathPart::new(name.as_str()),
                ])
            })
            .collect();
    }
    for (i, path) in s.power_paths.iter().enumerate() {
        let value = energy.dissipation_power.get(i).copied().unwrap_or(0.0);
        rec.log(path.clone(), &rerun::Scalars::single(value))?;
    }
    Ok(())
}

/// Logs one stress sample as scalars `stress/<region>/<quantity>` ([`STRESS_SCALARS`]);
/// optional quantities are logged only when defined, and in 2-D only the in-plane
/// components `sigma_xx`, `sigma_yy`, `sigma_xy`, `sigma_yx`.
fn log_stress(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    sample: &StressSample,
    planar: bool,
) -> rerun::RecordingStreamResult<()> {
    rec.set_time_sequence(STEP_TIMELINE, sample.step as i64);
    rec.set_duration_secs(TIME_TIMELINE, sample.time);
    if s.stress_paths.len() != sample.regions.len() {
        s.stress_paths = sample
            .regions
            .iter()
            .map(|r| {
                STRESS_SCALARS
                    .iter()
                    .map(|q| {
                        EntityPath::new(vec![
                            STRESS_PATH.into(),
                            EntityPathPart::new(r.name.as_str()),
                            (*q).into(),
                        ])
                    })
                    .collect()
            })
            .collect();
    }
    for (region, paths) in sample.regions.iter().zip(&s.stress_paths) {
        for (k, path) in paths.iter().enumerate() {
            if let Some(value) = stress_scalar(region, k, planar) {
                rec.log(path.clone(), &rerun::Scalars::single(value))?;
            }
        }
    }
    Ok(())
}

/// Logs one field sample as two point clouds over the grid nodes:
/// [`FIELD_DENSITY_PATH`] coloured by density (blue at 0, red at the largest), and
/// [`FIELD_PRESSURE_PATH`] coloured by pressure (grey at 0, red in compression, blue in
/// tension, scaled by the largest |p|).
fn log_fields(
    rec: &rerun::RecordingStream,
    s: &mut ExportState,
    sample: &FieldSample,
    planar: bool,
) -> rerun::RecordingStreamResult<()> {
    rec.set_time_sequence(STEP_TIMELINE, sample.step as i64);
    rec.set_duration_secs(TIME_TIMELINE, sample.time);
    s.positions.clear();
    s.positions
        .extend((0..sample.node_count()).map(|n| to_f32(sample.node_position(n))));
    let axes = if planar { 2 } else { 3 };
    let edge = sample.cell_size[..axes]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let radius = (FIELD_NODE_RADIUS * edge) as f32;
    let max_density = sample.density.iter().copied().fold(0.0, f64::max);
    s.colors.clear();
    s.colors.extend(
        sample
            .density
            .iter()
            .map(|&rho| ramp(fraction(rho, max_density))),
    );
    rec.log(
        FIELD_DENSITY_PATH,
        &rerun::Points3D::new(s.positions.iter().copied())
            .with_radii([radius])
            .with_colors(s.colors.iter().copied()),
    )?;
    let max_pressure = sample.pressure.iter().map(|p| p.abs()).fold(0.0, f64::max);
    s.colors.clear();
    s.colors.extend(sample.pressure.iter().map(|&p| {
        let t = if max_pressure > 0.0 {
            0.5 + 0.5 * (p / max_pressure).clamp(-1.0, 1.0)
        } else {
            0.5
        };
        ramp(t)
    }));
    rec.log(
        FIELD_PRESSURE_PATH,
        &rerun::Points3D::new(s.positions.iter().copied())
            .with_radii([radius])
            .with_colors(s.colors.iter().copied()),
    )
}

/// Value of entry `k` of [`STRESS_SCALARS`] for a region, if defined.
fn stress_scalar(r: &RegionStress, k: usize, planar: bool) -> Option<f64> {
    let sigma = |i: usize, j: usize| (!planar || (i < 2 && j < 2)).then_some(r.stress.0[i][j]);
    match k {
        0 => Some(r.pressure),
        1 => Some(r.shear_stress),
        2 => r.kinetic_share,
        3 => Some(r.solid_fraction),
        4 => Some(r.antisymmetric_norm),
        5 => r.couple_stress.map(|c| c.norm()),
        6 => r.shear_rate,
        7 => r.inertial_number,
        8 => sigma(0, 0),
        9 => sigma(1, 1),
        10 => sigma(2, 2),
        11 => sigma(0, 1),
        12 => sigma(1, 0),
        13 => sigma(0, 2),
        14 => sigma(2, 0),
        15 => sigma(1, 2),
        16 => sigma(2, 1),
        _ => None,
    }
}

/// Closed outline of a wall: a square of half-side `half` in its plane (3-D), or a
/// segment of half-length `half` along its trace in the xy-plane (2-D), centred on the
/// projection of `centre` onto the plane.
fn wall_outline(wall: &Wall, centre: DVec3, half: f64, planar: bool) -> Vec<[f32; 3]> {
    let n = wall.normal.normalize_or(DVec3::Z);
    let c = centre - (centre - wall.point).dot(n) * n;
    if planar {
        let t = DVec3::Z.cross(n).normalize_or(DVec3::X);
        return vec![to_f32(c - half * t), to_f32(c + half * t)];
    }
    let (u, v) = n.any_orthonormal_pair();
    let corners = [
        c + half * (u + v),
        c + half * (-u + v),
        c + half * (-u - v),
        c + half * (u - v),
        c + half * (u + v),
    ];
    corners.iter().map(|&p| to_f32(p)).collect()
}

/// `value / max` in [0, 1]; 0 when `max` is 0.
fn fraction(value: f64, max: f64) -> f64 {
    if max > 0.0 {
        (value / max).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Blue → grey → red diverging ramp ("cool–warm") at `t` in [0, 1].
fn ramp(t: f64) -> rerun::Color {
    const BLUE: [f64; 3] = [59.0, 76.0, 192.0];
    const GREY: [f64; 3] = [221.0, 221.0, 221.0];
    const RED: [f64; 3] = [180.0, 4.0, 38.0];
    let (a, b, u) = if t < 0.5 {
        (BLUE, GREY, 2.0 * t)
    } else {
        (GREY, RED, 2.0 * t - 1.0)
    };
    let c = |k: usize| (a[k] + (b[k] - a[k]) * u).round().clamp(0.0, 255.0) as u8;
    rerun::Color::from_rgb(c(0), c(1), c(2))
}

fn to_f32(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_ends_are_blue_and_red() {
        assert_eq!(ramp(0.0), rerun::Color::from_rgb(59, 76, 192));
        assert_eq!(ramp(1.0), rerun::Color::from_rgb(180, 4, 38));
        assert_eq!(fraction(1.0, 0.0), 0.0);
    }

    #[test]
    fn wall_outline_lies_in_the_plane() {
        let wall = Wall {
            name: "floor".into(),
            point: DVec3::new(0.0, 0.0, 0.1),
            normal: DVec3::Z,
            velocity: DVec3::ZERO,
            material: MaterialId(0),
        };
        let outline = wall_outline(&wall, DVec3::new(1.0, 2.0, 3.0), 0.5, false);
        assert_eq!(outline.len(), 5);
        assert_eq!(outline[0], outline[4]);
        for p in &outline {
            assert!((p[2] - 0.1).abs() < 1e-6);
        }
        let segment = wall_outline(&wall, DVec3::ZERO, 0.5, true);
        assert_eq!(segment.len(), 2);
    }
}
