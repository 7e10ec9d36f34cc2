//! Validation of a parsed scene and the building of its simulation: materials, law
//! resolution per material pair (mixing, overrides), the time step and its reason,
//! whether rotation is needed, grain generation and the initial-overlap check.

use std::any::Any;
use std::path::Path;

use glam::DVec3;
use talus_collision::{CellGrid, CollisionPlugin};
use talus_contact::{
    ContactPlugin, LawDescriptor, LawRegistry, PairAssignment, ParamValues, TimeScale, check_params,
};
use talus_core::grain_order::RowsOfCells;
use talus_core::prelude::*;
use talus_stress::{CoarseGrainingPlugin, FieldSpec, RegionShape, RegionSpec, StressPlugin};

use crate::Scene;

/// Name under which the whole domain is reported when `sampling.domain` is true.
pub const DOMAIN_REGION: &str = "domain";

/// A strain-rate drive resolved against the built walls (indices among them).
struct ResolvedStrainDrive {
    wall: usize,
    opposite: usize,
    rate: f64,
    share: f64,
}

/// Finds each strain-rate wall's opposite wall by name and checks the pair: a different,
/// parallel, facing wall at a positive gap; when both walls of a pair are driven against
/// each other they must share one rate, and each then makes half of it.
fn resolve_strain_drives(
    cx: &Ctx,
    walls: &[(usize, WallBundle)],
    drives: &[(usize, usize, &StrainRateSpec)],
) -> Result<Vec<ResolvedStrainDrive>, SceneError> {
    let mut resolved = Vec::with_capacity(drives.len());
    for &(i, k, spec) in drives {
        let field = format!("walls[{k}].strain_rate.opposite");
        let names = || {
            walls
                .iter()
                .map(|(_, w)| format!("`{}`", w.wall.name))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let Some(j) = walls.iter().position(|(_, w)| w.wall.name == spec.opposite) else {
            return Err(cx.err(
                &field,
                format!("the name of another wall, one of {}", names()),
            ));
        };
        if j == i {
            return Err(cx.err(&field, "another wall than this one"));
        }
        let (me, other) = (&walls[i].1.wall, &walls[j].1.wall);
        if (me.normal + other.normal).length() > 1e-9 {
            return Err(cx.err(
                &field,
                format!(
                    "a wall facing this one (normals opposite); `{}` has normal ({}, {}, {}), this wall ({}, {}, {})",
                    other.name,
                    other.normal.x,
                    other.normal.y,
                    other.normal.z,
                    me.normal.x,
                    me.normal.y,
                    me.normal.z
                ),
            ));
        }
        let gap = (me.point - other.point).dot(other.normal);
        // Negated, so that a NaN gap is refused too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(gap > 0.0) {
            return Err(cx.err(
                &field,
                format!(
                    "a wall on the far side of the grains (the gap to `{}` is {gap:e} m)",
                    other.name
                ),
            ));
        }
        let mutual = drives
            .iter()
            .find(|&&(i2, _, s2)| i2 == j && s2.opposite == me.name);
        let share = match mutual {
            Some(&(_, k2, s2)) if s2.rate != spec.rate => {
                return Err(cx.err(
                    &format!("walls[{k}].strain_rate.rate"),
                    format!(
                        "the same rate as walls[{k2}], which is driven against this wall ({} against {} 1/s)",
                        s2.rate, spec.rate
                    ),
                ));
            }
            Some(_) => 0.5,
            None => 1.0,
        };
        resolved.push(ResolvedStrainDrive {
            wall: i,
            opposite: j,
            rate: spec.rate,
            share,
        });
    }
    Ok(resolved)
}

/// Most plane walls a scene may have (the narrow phase encodes wall indices in the
/// top of the grain-index range).
pub const MAX_WALLS: usize = 1024;

/// Fraction of the stability bound the automatic time step stays below when a stiff
/// part, not the contact time, limits it.
pub const STABILITY_SAFETY: f64 = 0.2;
use crate::error::SceneError;
use crate::generate::{GrainInit, RESTORED_SOURCE, generate};
use crate::locate::Locator;
use crate::schema::*;
use crate::state::{RestoreMode, SavedState};
use bevy_ecs::prelude::*;

/// When a run stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopCondition {
    /// Number of steps to run at most.
    pub steps: u64,
    /// Stop once the mean kinetic energy per grain is below this, J.
    pub settle_kinetic_energy: Option<f64>,
}

/// A scene turned into a simulation builder, ready for output plugins and `build()`.
pub struct BuiltScene {
    /// The builder: add export plugins, then call `build()`.
    pub builder: SimBuilder,
    /// Scene name.
    pub name: String,
    /// When to stop.
    pub stop: StopCondition,
    /// Outputs asked for.
    pub output: OutputSpec,
    /// Number of grains.
    pub grain_count: usize,
    /// Time step and why it was chosen.
    pub time_step_reason: String,
    /// The smallest stability limit of the step over the scene's material pairs, s
    /// (infinite when no pair reports one).
    pub stability_limit: f64,
    /// Whether the scene was resumed from a saved state ([`Scene::resume`]): its forces
    /// are those of the state, so the simulation must be marked primed, not primed.
    pub resumed: bool,
}

/// Puts a resumed run's walls, clock, energy totals and integrator history back.
fn restore_run(world: &mut World, state: &SavedState) {
    let mut q = world.query::<(&mut Wall, &mut WallLoad)>();
    for (mut w, mut load) in q.iter_mut(world) {
        if let Some(s) = state.walls.iter().find(|s| s.name == w.name) {
            w.point = s.point;
            w.normal = s.normal;
            w.velocity = s.velocity;
            load.0 = s.load;
        }
    }
    {
        let mut clock = world.resource_mut::<Clock>();
        clock.step = state.step;
        clock.time = state.time;
        clock.pass_dt = state.time_step;
    }
    world.insert_resource(state.ledger.clone());
    world.insert_resource(state.energy.clone());
    if let Some(gear) = &state.gear {
        world.insert_resource(gear.clone());
    }
}

struct Ctx<'a> {
    scene: &'a Scene,
    locator: Locator,
}

impl Ctx<'_> {
    fn err(&self, field: &str, expected: impl Into<String>) -> SceneError {
        let (line, column) = self.locator.position(field);
        SceneError {
            file: self.scene.path.clone(),
            line,
            column,
            field: field.to_string(),
            expected: expected.into(),
        }
    }
}

fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

fn vec3(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

/// A law and the pairs it serves, installed as one plugin.
struct LawInstall<'a> {
    law: &'a dyn LawDescriptor,
    pairs: Vec<(PairAssignment, Box<dyn Any + Send + Sync>)>,
}

impl Plugin for LawInstall<'_> {
    fn name(&self) -> String {
        format!("law:{}", self.law.name())
    }
    fn build(&self, sim: &mut SimBuilder) {
        self.law.install(sim, &self.pairs);
    }
}

impl Scene {
    /// Validates the scene against the registered laws and builds its simulation.
    pub fn build(&self, registry: &LawRegistry) -> Result<BuiltScene, SceneError> {
        self.build_inner(registry, None)
    }

    /// Validates the scene and builds it resumed from a state its own run saved: the
    /// grains, walls, contacts (with their histories), periodic box, clock, energy
    /// totals and time step come from the state, the rest (laws, plugins, outputs, the
    /// end of the run) from the scene. Stepping it continues the saved run bit for bit;
    /// call [`talus_core::schedule::Simulation::mark_primed`] (see
    /// [`BuiltScene::resumed`]) instead of priming it.
    pub fn resume(
        &self,
        registry: &LawRegistry,
        state: &SavedState,
    ) -> Result<BuiltScene, SceneError> {
        self.build_inner(registry, Some(state))
    }

    fn build_inner(
        &self,
        registry: &LawRegistry,
        resume: Option<&SavedState>,
    ) -> Result<BuiltScene, SceneError> {
        let cx = Ctx {
            scene: self,
            locator: Locator::new(&self.source),
        };
        let f = &self.file;
        let dimension = match f.dimension {
            2 => Dimension::Two,
            3 => Dimension::Three,
            _ => return Err(cx.err("dimension", "2 or 3")),
        };
        let two_d = dimension == Dimension::Two;
        let gravity = vec3(f.gravity);
        if !gravity.is_finite() {
            return Err(cx.err("gravity", "finite components"));
        }
        if two_d && gravity.z != 0.0 {
            return Err(cx.err("gravity", "a z component of 0 in a 2-D scene"));
        }
        match (f.duration, f.steps) {
            (Some(_), Some(_)) => {
                return Err(cx.err("steps", "either `duration` or `steps`, not both"));
            }
            (None, None) => {
                return Err(cx.err("duration", "a `duration` (s) or a number of `steps`"));
            }
            (Some(d), None) if !positive(d) => {
                return Err(cx.err("duration", "a positive duration in seconds"));
            }
            (None, Some(0)) => return Err(cx.err("steps", "at least one step")),
            _ => {}
        }
        if let Some(dt) = f.time_step
            && !positive(dt)
        {
            return Err(cx.err("time_step", "a positive time step in seconds"));
        }
        if !positive(f.steps_per_collision) || f.steps_per_collision < 1.0 {
            return Err(cx.err("steps_per_collision", "a number ≥ 1"));
        }
        if !(f.initial_overlap_tolerance.is_finite() && f.initial_overlap_tolerance >= 0.0) {
            return Err(cx.err(
                "initial_overlap_tolerance",
                "a non-negative fraction of a radius",
            ));
        }
        if let Some(e) = f.settle_kinetic_energy
            && !positive(e)
        {
            return Err(cx.err("settle_kinetic_energy", "a positive energy in joules"));
        }
        let sort_grains_every = f
            .sort_grains_every
            .map(|n| {
                std::num::NonZeroU64::new(n)
                    .ok_or_else(|| cx.err("sort_grains_every", "a positive number of steps"))
            })
            .transpose()?;
        if !positive(f.output.recording_interval) {
            return Err(cx.err(
                "output.recording_interval",
                "a positive interval in seconds",
            ));
        }
        if !positive(f.output.report_interval) {
            return Err(cx.err("output.report_interval", "a positive interval in seconds"));
        }
        let sampling_regions = match &f.sampling {
            Some(s) => Some(check_sampling(&cx, s, two_d)?),
            None => None,
        };
        for (k, name) in f.plugins.iter().enumerate() {
            if !registry.has(name) {
                return Err(cx.err(
                    &format!("plugins[{k}]"),
                    format!("a known plugin: {}", registry.names().join(", ")),
                ));
            }
        }

        // Materials.
        if f.materials.is_empty() {
            return Err(cx.err("materials", "at least one material"));
        }
        if f.materials.len() > u16::MAX as usize {
            return Err(cx.err("materials", "at most 65535 materials"));
        }
        let mut materials = Vec::new();
        for (i, m) in f.materials.iter().enumerate() {
            if f.materials[..i].iter().any(|o| o.name == m.name) {
                return Err(cx.err(
                    &format!("materials[{i}].name"),
                    "a name not used by another material",
                ));
            }
            if !positive(m.density) {
                return Err(cx.err(
                    &format!("materials[{i}].density"),
                    "a positive density in kg/m³",
                ));
            }
            if let Some(c) = &m.contact {
                check_contact(
                    &cx,
                    registry,
                    &f.plugins,
                    c,
                    &format!("materials[{i}].contact"),
                )?;
            }
            materials.push(Material {
                name: m.name.clone(),
                density: m.density,
            });
        }
        let material_id = |name: &str, field: &str| -> Result<u16, SceneError> {
            f.materials
                .iter()
                .position(|m| m.name == name)
                .map(|i| i as u16)
                .ok_or_else(|| {
                    let known: Vec<String> = f
                        .materials
                        .iter()
                        .map(|m| format!("`{}`", m.name))
                        .collect();
                    cx.err(
                        field,
                        format!(
                            "a material defined in `materials` ({}), found `{name}`",
                            known.join(", ")
                        ),
                    )
                })
        };
        let mut overrides: Vec<(u16, u16, usize)> = Vec::new();
        for (k, p) in f.pairs.iter().enumerate() {
            let a = material_id(&p.materials.0, &format!("pairs[{k}].materials"))?;
            let b = material_id(&p.materials.1, &format!("pairs[{k}].materials"))?;
            check_contact(
                &cx,
                registry,
                &f.plugins,
                &p.contact,
                &format!("pairs[{k}].contact"),
            )?;
            if let Some(&(_, _, j)) = overrides
                .iter()
                .find(|o| (o.0, o.1) == (a.min(b), a.max(b)))
            {
                return Err(cx.err(
                    &format!("pairs[{k}].materials"),
                    format!("a material pair not already given (pairs[{j}] sets the same pair)"),
                ));
            }
            overrides.push((a.min(b), a.max(b), k));
        }

        // Walls.
        let mut walls = Vec::new();
        let mut servos: Vec<(usize, Servo)> = Vec::new();
        // (index among the built walls, walls[k] of the scene, spec).
        let mut strain_drives: Vec<(usize, usize, &StrainRateSpec)> = Vec::new();
        for (k, w) in f.walls.iter().enumerate() {
            let field = |s: &str| format!("walls[{k}].{s}");
            match w {
                WallSpec::Plane {
                    name,
                    point,
                    normal,
                    material,
                    velocity,
                    servo,
                    strain_rate,
                } => {
                    if let Some(sr) = strain_rate {
                        if !sr.rate.is_finite() {
                            return Err(
                                cx.err(&field("strain_rate.rate"), "a finite strain rate in 1/s")
                            );
                        }
                        if servo.is_some() {
                            return Err(cx.err(
                                &field("strain_rate"),
                                "either a servo or a strain rate on a wall, not both",
                            ));
                        }
                        if *velocity != [0.0; 3] {
                            return Err(cx.err(
                                &field("velocity"),
                                "no velocity on a strain-rate wall (the strain rate sets it)",
                            ));
                        }
                        strain_drives.push((walls.len(), k, sr));
                    }
                    if let Some(sv) = servo {
                        let positive = |x: f64| x.is_finite() && x > 0.0;
                        if !(sv.pressure.is_finite() && sv.pressure >= 0.0) {
                            return Err(
                                cx.err(&field("servo.pressure"), "a non-negative pressure in Pa")
                            );
                        }
                        if !positive(sv.area) {
                            return Err(cx.err(&field("servo.area"), "a positive area in m²"));
                        }
                        if !positive(sv.gain) {
                            return Err(cx.err(&field("servo.gain"), "a positive gain in m/(s N)"));
                        }
                        if sv.max_speed.is_some_and(|v| !positive(v)) {
                            return Err(
                                cx.err(&field("servo.max_speed"), "a positive speed in m/s")
                            );
                        }
                        if *velocity != [0.0; 3] {
                            return Err(cx.err(
                                &field("velocity"),
                                "no velocity on a servo wall (the servo sets it)",
                            ));
                        }
                        servos.push((
                            walls.len(),
                            Servo {
                                target_load: sv.pressure * sv.area,
                                gain: sv.gain,
                                max_speed: sv.max_speed.unwrap_or(f64::INFINITY),
                            },
                        ));
                    }
                    let mat = material_id(material, &field("material"))?;
                    let n = vec3(*normal);
                    if !n.is_finite() || n.length() == 0.0 {
                        return Err(cx.err(&field("normal"), "a non-zero normal vector"));
                    }
                    if two_d && (n.z != 0.0 || point[2] != 0.0 || velocity[2] != 0.0) {
                        return Err(cx.err(
                            &field("normal"),
                            "a wall in the xy-plane (z components 0) in a 2-D scene",
                        ));
                    }
                    if !vec3(*point).is_finite() || !vec3(*velocity).is_finite() {
                        return Err(cx.err(&field("point"), "finite coordinates"));
                    }
                    walls.push((
                        k,
                        WallBundle::new(name.clone(), vec3(*point), n, MaterialId(mat))
                            .with_velocity(vec3(*velocity)),
                    ));
                }
                WallSpec::Box {
                    min,
                    max,
                    material,
                    omit,
                } => {
                    let mat = material_id(material, &field("material"))?;
                    let (lo, hi) = (vec3(*min), vec3(*max));
                    let axes = if two_d { 2 } else { 3 };
                    // Negated, so that a NaN bound is refused too.
                    #[allow(clippy::neg_cmp_op_on_partial_ord)]
                    let empty = (0..axes).any(|d| !(lo[d] < hi[d]));
                    if empty || !lo.is_finite() || !hi.is_finite() {
                        return Err(cx.err(
                            &field("max"),
                            "every component of `max` above that of `min`",
                        ));
                    }
                    const FACES: [&str; 6] = ["x_min", "x_max", "y_min", "y_max", "z_min", "z_max"];
                    for (j, o) in omit.iter().enumerate() {
                        if !FACES[..2 * axes].contains(&o.as_str()) {
                            return Err(cx.err(
                                &format!("walls[{k}].omit[{j}]"),
                                format!("one of {}", FACES[..2 * axes].join(", ")),
                            ));
                        }
                    }
                    // Face names must be unique across walls: prefix them when the
                    // scene has more than one box.
                    let boxes = f
                        .walls
                        .iter()
                        .filter(|w| matches!(w, WallSpec::Box { .. }))
                        .count();
                    let face = |j: usize| -> String {
                        if boxes > 1 {
                            format!("box{k}_{}", FACES[j])
                        } else {
                            FACES[j].to_string()
                        }
                    };
                    for d in 0..axes {
                        let mut n = DVec3::ZERO;
                        n[d] = 1.0;
                        let mid = if two_d {
                            DVec3::new(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), 0.0)
                        } else {
                            0.5 * (lo + hi)
                        };
                        let mut p_lo = mid;
                        p_lo[d] = lo[d];
                        let mut p_hi = mid;
                        p_hi[d] = hi[d];
                        if !omit.iter().any(|o| o == FACES[2 * d]) {
                            walls.push((k, WallBundle::new(face(2 * d), p_lo, n, MaterialId(mat))));
                        }
                        if !omit.iter().any(|o| o == FACES[2 * d + 1]) {
                            walls.push((
                                k,
                                WallBundle::new(face(2 * d + 1), p_hi, -n, MaterialId(mat)),
                            ));
                        }
                    }
                }
            }
        }

        if walls.len() > MAX_WALLS {
            return Err(cx.err(
                "walls",
                format!("at most {MAX_WALLS} plane walls, found {}", walls.len()),
            ));
        }
        for (i, (k, w)) in walls.iter().enumerate() {
            if let Some((j, _)) = walls[..i].iter().find(|(_, o)| o.wall.name == w.wall.name) {
                return Err(cx.err(
                    &format!("walls[{k}].name"),
                    format!(
                        "a wall name not already used (`{}` is also walls[{j}])",
                        w.wall.name
                    ),
                ));
            }
        }

        let strain_drives = resolve_strain_drives(&cx, &walls, &strain_drives)?;

        // A saved state to start from or to resume.
        let start_state = match (resume, &f.start_from) {
            (None, Some(file)) => {
                let path = self
                    .path
                    .parent()
                    .map_or_else(|| Path::new(file).to_path_buf(), |d| d.join(file));
                Some(
                    SavedState::read(&path)
                        .map_err(|e| cx.err("start_from", format!("a Talus state file: {e}")))?,
                )
            }
            _ => None,
        };
        let restore: Option<(&SavedState, RestoreMode)> = match (resume, &start_state) {
            (Some(s), _) => Some((s, RestoreMode::Resume)),
            (None, Some(s)) => Some((s, RestoreMode::StartFrom)),
            (None, None) => None,
        };
        let restore_field = if resume.is_some() {
            "name"
        } else {
            "start_from"
        };

        // Grains.
        let mut grains: Vec<GrainInit> = Vec::new();
        if let Some((state, mode)) = restore {
            if state.dimension != f.dimension {
                return Err(cx.err(
                    restore_field,
                    format!(
                        "a state of a {}-D scene (the state is {}-D)",
                        f.dimension, state.dimension
                    ),
                ));
            }
            if mode == RestoreMode::Resume && state.scene != f.name {
                return Err(cx.err(
                    "name",
                    format!(
                        "the scene that saved the state to resume (`{}`), found `{}`",
                        state.scene, f.name
                    ),
                ));
            }
            for (i, g) in state.grains.iter().enumerate() {
                let material = material_id(&g.material, restore_field).map_err(|_| {
                    cx.err(
                        restore_field,
                        format!(
                            "a state whose materials the scene defines: grain {i} of the state is of material `{}`",
                            g.material
                        ),
                    )
                })?;
                let finite = g.position.is_finite()
                    && g.velocity.is_finite()
                    && g.angular_velocity.is_finite()
                    && g.force.is_finite()
                    && g.torque.is_finite();
                if !(finite && positive(g.radius) && positive(g.mass) && positive(g.inertia)) {
                    return Err(cx.err(
                        restore_field,
                        format!("a state with finite positions, velocities and forces and positive radii, masses and inertias: grain {i} is not"),
                    ));
                }
                let volume = mass_and_inertia(dimension, g.radius, 1.0).0;
                grains.push(GrainInit {
                    position: g.position,
                    radius: g.radius,
                    velocity: g.velocity,
                    angular_velocity: g.angular_velocity,
                    material,
                    source: RESTORED_SOURCE,
                    density: Some(g.mass / volume),
                    frozen: g.frozen,
                    saved: Some(i as u32),
                });
            }
        }
        let resuming = matches!(restore, Some((_, RestoreMode::Resume)));
        // A resumed run's grains are all in the state: the sources made them already.
        for (k, g) in f.grains.iter().enumerate().filter(|_| !resuming) {
            let field = |s: &str| format!("grains[{k}].{s}");
            let material = match g {
                GrainSource::List {
                    material,
                    grains: list,
                } => {
                    for (j, s) in list.iter().enumerate() {
                        if !positive(s.radius) {
                            return Err(cx.err(
                                &format!("grains[{k}].grains[{j}].radius"),
                                "a positive radius in metres",
                            ));
                        }
                        if !vec3(s.position).is_finite()
                            || !vec3(s.velocity).is_finite()
                            || !vec3(s.angular_velocity).is_finite()
                        {
                            return Err(cx.err(
                                &format!("grains[{k}].grains[{j}]"),
                                "finite position and velocities",
                            ));
                        }
                    }
                    material
                }
                GrainSource::Lattice {
                    material,
                    radius,
                    region,
                    spacing,
                    velocity,
                } => {
                    if !positive(*radius) {
                        return Err(cx.err(&field("radius"), "a positive radius in metres"));
                    }
                    check_region(&cx, region, &field("region"), two_d)?;
                    if let Some(a) = spacing
                        && !(positive(*a))
                    {
                        return Err(cx.err(&field("spacing"), "a positive spacing in metres"));
                    }
                    if !vec3(*velocity).is_finite() {
                        return Err(cx.err(&field("velocity"), "a finite velocity"));
                    }
                    material
                }
                GrainSource::LammpsData {
                    file,
                    types,
                    replicate,
                } => {
                    let atoms = self.read_lammps(&cx, k, file, types, two_d, &material_id)?;
                    let (nx, ny, nz) = replicate.unwrap_or((1, 1, 1));
                    if nx == 0 || ny == 0 || nz == 0 || (two_d && nz != 1) {
                        return Err(cx.err(
                            &field("replicate"),
                            "positive copy counts (nx, ny, nz), nz = 1 in a 2-D scene",
                        ));
                    }
                    let first = grains.len();
                    if (nx, ny, nz) == (1, 1, 1) {
                        grains.extend(atoms);
                    } else {
                        let path = self
                            .path
                            .parent()
                            .map_or_else(|| Path::new(file).to_path_buf(), |d| d.join(file));
                        let lengths = crate::lammps::box_lengths(&path).map_err(|e| {
                            cx.err(
                                &field("file"),
                                format!(
                                    "a valid LAMMPS data file: {}:{}: {}",
                                    path.display(),
                                    e.line,
                                    e.message
                                ),
                            )
                        })?;
                        let mut shift = DVec3::ZERO;
                        for (a, n) in [nx, ny, nz].into_iter().enumerate() {
                            if n > 1 {
                                shift[a] = lengths[a].ok_or_else(|| {
                                    cx.err(&field("replicate"), format!("a box length on axis {} in the data file's header to replicate along", ["x", "y", "z"][a]))
                                })?;
                            }
                        }
                        for iz in 0..nz {
                            for iy in 0..ny {
                                for ix in 0..nx {
                                    let offset = DVec3::new(
                                        ix as f64 * shift.x,
                                        iy as f64 * shift.y,
                                        iz as f64 * shift.z,
                                    );
                                    grains.extend(atoms.iter().map(|g| GrainInit {
                                        position: g.position + offset,
                                        ..*g
                                    }));
                                }
                            }
                        }
                    }
                    sort_spatially(&mut grains[first..]);
                    continue;
                }
                GrainSource::Random {
                    material,
                    region,
                    count,
                    radius,
                    velocity_spread,
                    ..
                } => {
                    check_region(&cx, region, &field("region"), two_d)?;
                    if *count == 0 {
                        return Err(cx.err(&field("count"), "at least one grain"));
                    }
                    check_radius(&cx, radius, &field("radius"))?;
                    if !(velocity_spread.is_finite() && *velocity_spread >= 0.0) {
                        return Err(cx.err(&field("velocity_spread"), "a non-negative speed"));
                    }
                    material
                }
            };
            let mat = material_id(material, &field("material"))?;
            let made = generate(g, k, mat, two_d)
                .map_err(|(sub, expected)| cx.err(&field(&sub), expected))?;
            let first = grains.len();
            grains.extend(made);
            // Drawn at random, neighbours in space would lie anywhere in memory; a
            // lattice is made in rows already, and a list keeps the order it was given.
            if matches!(g, GrainSource::Random { .. }) {
                sort_spatially(&mut grains[first..]);
            }
        }
        // Sequential deposition: its first batch is part of the initial grains (a
        // resumed run has its batches in the state already).
        let mut deposition = None;
        if let Some(d) = &f.deposition {
            let field = |s: &str| format!("deposition.{s}");
            let mat = material_id(&d.material, &field("material"))?;
            check_region(&cx, &d.region, &field("region"), two_d)?;
            check_radius(&cx, &d.radius, &field("radius"))?;
            if d.batch_size == 0 || d.batches == 0 {
                return Err(cx.err(
                    &field(if d.batch_size == 0 {
                        "batch_size"
                    } else {
                        "batches"
                    }),
                    "at least one",
                ));
            }
            if !positive(d.settle_kinetic_energy) {
                return Err(cx.err(
                    &field("settle_kinetic_energy"),
                    "a positive energy in joules",
                ));
            }
            if !positive(d.unbalanced_force) {
                return Err(cx.err(&field("unbalanced_force"), "a positive ratio"));
            }
            if d.check_interval.is_some_and(|t| !positive(t)) {
                return Err(cx.err(&field("check_interval"), "a positive interval in seconds"));
            }
            if f.integrator == IntegratorName::Gear {
                return Err(cx.err(
                    "integrator",
                    "VelocityVerlet or SymplecticEuler with `deposition` (Gear keeps per-grain derivatives in grain order, which inserted grains would shift)",
                ));
            }
            let progress = match restore {
                Some((state, RestoreMode::Resume)) => state.deposition.unwrap_or_default(),
                _ => {
                    let existing: Vec<(DVec3, f64)> =
                        grains.iter().map(|g| (g.position, g.radius)).collect();
                    let batch = crate::generate::random_insertion(
                        &d.region,
                        d.batch_size,
                        &d.radius,
                        d.seed,
                        0.0,
                        two_d,
                        &existing,
                    )
                    .map_err(|(sub, expected)| {
                        cx.err(
                            &field(if sub == "count" { "batch_size" } else { &sub }),
                            expected,
                        )
                    })?;
                    let first = grains.len();
                    grains.extend(batch.into_iter().map(|(p, r, _)| GrainInit {
                        position: p,
                        radius: r,
                        velocity: DVec3::ZERO,
                        angular_velocity: DVec3::ZERO,
                        material: mat,
                        source: RESTORED_SOURCE - 1,
                        density: None,
                        frozen: false,
                        saved: None,
                    }));
                    sort_spatially(&mut grains[first..]);
                    crate::packing::DepositionProgress {
                        batches_inserted: 1,
                    }
                }
            };
            deposition = Some((mat, progress));
        }
        if grains.is_empty() {
            return Err(cx.err("grains", "at least one grain"));
        }
        // A saved periodic box (which a compression may have changed) replaces the
        // scene's extents along the axes both make periodic.
        let periodic_spec = f.periodic.as_ref().map(|spec| {
            let mut spec = spec.clone();
            if let Some(saved) = restore.and_then(|(s, _)| s.periodic) {
                for (a, extent) in [&mut spec.x, &mut spec.y, &mut spec.z]
                    .into_iter()
                    .enumerate()
                {
                    if extent.is_some() && saved.axes[a] {
                        *extent = Some((saved.lo[a], saved.hi[a]));
                    }
                }
            }
            spec
        });
        let periodic = match &periodic_spec {
            Some(spec) => Some(check_periodic(&cx, spec, &grains, two_d)?),
            None => None,
        };
        if let Some(b) = periodic.filter(|b| b.shear.is_some()) {
            if f.integrator == IntegratorName::Gear {
                return Err(cx.err(
                    "integrator",
                    "VelocityVerlet or SymplecticEuler with Lees–Edwards shear (Gear's stored derivatives cannot follow a grain's velocity jump through the sheared seam)",
                ));
            }
            let spec = f.periodic.as_ref().and_then(|p| p.shear.as_ref());
            // A resumed run's velocities are the saved ones, already on the profile:
            // adding it again would double the streaming velocity.
            let resuming = matches!(restore, Some((_, RestoreMode::Resume)));
            if spec.is_some_and(|s| s.start_on_profile) && !resuming {
                for g in grains.iter_mut().filter(|g| !g.frozen) {
                    g.velocity += b.streaming_velocity(g.position);
                }
            }
        }
        check_initial_overlaps(&cx, &grains, &walls, f.initial_overlap_tolerance)?;
        if let Some(b) = &periodic {
            check_overlaps_across_seams(&cx, &grains, b, f.initial_overlap_tolerance)?;
        }

        // Lightest grain of each material, for reduced masses and the time step.
        let n_mat = materials.len();
        let mut lightest = vec![f64::INFINITY; n_mat];
        let mut smallest = vec![f64::INFINITY; n_mat];
        for g in &grains {
            let density = g.density.unwrap_or(materials[g.material as usize].density);
            let (m, _) = mass_and_inertia(dimension, g.radius, density);
            lightest[g.material as usize] = lightest[g.material as usize].min(m);
            smallest[g.material as usize] = smallest[g.material as usize].min(g.radius);
        }
        let wall_material: Vec<bool> = (0..n_mat)
            .map(|m| walls.iter().any(|(_, w)| w.wall.material.0 as usize == m))
            .collect();

        // Resolve a law for each material pair.
        let mut installs: Vec<LawInstall> = Vec::new();
        let mut time_scale: Option<(TimeScale, String)> = None;
        let mut stability: Option<(f64, String)> = None;
        let mut rotation = false;
        let mut interaction_range = 0.0f64;
        for a in 0..n_mat as u16 {
            for b in a..n_mat as u16 {
                let mut sides: Option<(ContactSpec, ContactSpec)> = None;
                let (spec, field) = if let Some(&(_, _, k)) =
                    overrides.iter().find(|o| o.0 == a && o.1 == b)
                {
                    (f.pairs[k].contact.clone(), format!("pairs[{k}].contact"))
                } else {
                    match (
                        &f.materials[a as usize].contact,
                        &f.materials[b as usize].contact,
                    ) {
                        (Some(x), Some(y))
                            if (&x.law, &x.rolling, &x.twisting)
                                == (&y.law, &y.rolling, &y.twisting) =>
                        {
                            let law = lookup(registry, x).expect("checked above");
                            sides = Some((x.clone(), y.clone()));
                            let mixed = ParamValues::mix(
                                law.params(),
                                &ParamValues(x.params.clone()),
                                &ParamValues(y.params.clone()),
                            );
                            (
                                ContactSpec {
                                    params: mixed.0,
                                    ..x.clone()
                                },
                                format!("materials[{b}].contact"),
                            )
                        }
                        (Some(x), Some(y)) => {
                            return Err(cx.err(
                                &format!("materials[{b}].contact.law"),
                                format!(
                                    "the same law and parts as material `{}` ({}, found {}), or a `pairs` entry for ({}, {})",
                                    f.materials[a as usize].name,
                                    x.label(),
                                    y.label(),
                                    f.materials[a as usize].name,
                                    f.materials[b as usize].name
                                ),
                            ));
                        }
                        (Some(x), None) => {
                            sides = Some((x.clone(), x.clone()));
                            (x.clone(), format!("materials[{a}].contact"))
                        }
                        (None, Some(y)) => {
                            sides = Some((y.clone(), y.clone()));
                            (y.clone(), format!("materials[{b}].contact"))
                        }
                        (None, None) => continue,
                    }
                };
                // Reduced masses of the contacts this pair can have.
                let mut min_mass = f64::INFINITY;
                let mut min_radius = f64::INFINITY;
                let (la, lb) = (lightest[a as usize], lightest[b as usize]);
                if la.is_finite() && lb.is_finite() {
                    min_mass = min_mass.min(la * lb / (la + lb));
                    let (ra, rb) = (smallest[a as usize], smallest[b as usize]);
                    min_radius = min_radius.min(ra * rb / (ra + rb));
                }
                if la.is_finite() && wall_material[b as usize] {
                    min_mass = min_mass.min(la);
                    min_radius = min_radius.min(smallest[a as usize]);
                }
                if lb.is_finite() && wall_material[a as usize] {
                    min_mass = min_mass.min(lb);
                    min_radius = min_radius.min(smallest[b as usize]);
                }
                if !min_mass.is_finite() {
                    continue; // no contact of this pair can occur
                }
                let law = lookup(registry, &spec).expect("checked above");
                let values = check_params(law.params(), &ParamValues(spec.params.clone()))
                    .map_err(|e| cx.err(&format!("{field}.{}", e.field), e.expected))?;
                let pair = PairAssignment {
                    materials: (a, b),
                    names: (
                        materials[a as usize].name.clone(),
                        materials[b as usize].name.clone(),
                    ),
                    values,
                    min_effective_mass: min_mass,
                    min_effective_radius: min_radius,
                    dimension,
                    material_values: match &sides {
                        Some((x, y)) => Some((
                            check_params(law.params(), &ParamValues(x.params.clone()))
                                .map_err(|e| cx.err(&format!("{field}.{}", e.field), e.expected))?,
                            check_params(law.params(), &ParamValues(y.params.clone()))
                                .map_err(|e| cx.err(&format!("{field}.{}", e.field), e.expected))?,
                        )),
                        None => None,
                    },
                };
                let (typed, ts) = law
                    .resolve(&pair)
                    .map_err(|e| cx.err(&format!("{field}.{}", e.field), e.expected))?;
                interaction_range = interaction_range.max(law.interaction_range(&pair.values));
                if law.produces_torque(&pair.values) {
                    if f.rotation == Some(false) {
                        return Err(cx.err(
                            &format!("{field}.law"),
                            format!(
                                "a law that cannot torque grains, since the scene sets `rotation: false` ({} can: it needs grain rotation)",
                                spec.label()
                            ),
                        ));
                    }
                    rotation = true;
                }
                let label = format!("{} for {}–{}", spec.label(), pair.names.0, pair.names.1);
                if time_scale
                    .as_ref()
                    .is_none_or(|(t, _)| ts.contact_time < t.contact_time)
                {
                    time_scale = Some((ts, label.clone()));
                }
                if stability
                    .as_ref()
                    .is_none_or(|(s, _)| ts.stability_limit < *s)
                {
                    stability = Some((ts.stability_limit, label));
                }
                match installs.iter_mut().find(|i| std::ptr::addr_eq(i.law, law)) {
                    Some(i) => i.pairs.push((pair, typed)),
                    None => installs.push(LawInstall {
                        law,
                        pairs: vec![(pair, typed)],
                    }),
                }
            }
        }

        // Time step.
        let (dt, time_step_reason) = match (f.time_step, &time_scale) {
            (Some(dt), _) => {
                if let Some((limit, label)) = &stability
                    && dt > *limit
                    && !f.force_time_step
                {
                    return Err(cx.err(
                        "time_step",
                        format!(
                            "a step below the stability bound {limit:.4e} s of {label} (set `force_time_step: true` to run anyway)"
                        ),
                    ));
                }
                (dt, format!("set by the scene ({dt:.4e} s)"))
            }
            (None, Some((ts, label))) => {
                let dt = ts.contact_time / f.steps_per_collision;
                let (limit, limit_label) =
                    stability.clone().unwrap_or((f64::INFINITY, String::new()));
                // A part stiffer than the normal spring (a rolling or tangential spring)
                // can make the stability bound the tighter constraint; keep a margin of
                // STABILITY_SAFETY below it.
                if dt > STABILITY_SAFETY * limit {
                    let dt = STABILITY_SAFETY * limit;
                    (
                        dt,
                        format!(
                            "automatic: {STABILITY_SAFETY} × stability bound {limit:.4e} s ({limit_label}) = {dt:.4e} s, below shortest contact time {:.4e} s ({label}) / {} steps per collision",
                            ts.contact_time, f.steps_per_collision
                        ),
                    )
                } else {
                    (
                        dt,
                        format!(
                            "automatic: shortest contact time {:.4e} s ({label}) / {} steps per collision = {dt:.4e} s (stability bound {limit:.4e} s)",
                            ts.contact_time, f.steps_per_collision,
                        ),
                    )
                }
            }
            (None, None) => {
                return Err(cx.err(
                    "time_step",
                    "a time step: no material pair has a contact law to derive one from",
                ));
            }
        };
        // A resumed run keeps the step it was saved with, to the bit.
        let (dt, time_step_reason) = match restore {
            Some((state, RestoreMode::Resume)) => {
                if !(positive(state.time_step)) {
                    return Err(cx.err("time_step", "a state with a positive time step"));
                }
                (
                    state.time_step,
                    format!(
                        "resumed from a saved state at step {} ({:.4e} s; the scene would choose {dt:.4e} s: {time_step_reason})",
                        state.step, state.time_step
                    ),
                )
            }
            _ => (dt, time_step_reason),
        };
        let steps = match (f.steps, f.duration) {
            (Some(n), _) => n,
            (None, Some(d)) => (d / dt).ceil() as u64,
            _ => unreachable!("checked above"),
        };

        let rotation = rotation || f.rotation == Some(true);
        let integrator = match f.integrator {
            IntegratorName::VelocityVerlet => Integrator::VelocityVerlet,
            IntegratorName::SymplecticEuler => Integrator::SymplecticEuler,
            IntegratorName::Gear => Integrator::Gear,
        };
        let mut builder = SimBuilder::new(SimConfig {
            dimension,
            dt,
            gravity,
            integrator,
            rotation,
        });
        builder.world.insert_resource(Materials(materials));
        if let Some(every) = sort_grains_every {
            builder.sort_grains_every(every);
        }
        // Only when off: no resource means booked, and a default run's world (whose
        // resources are entities in bevy_ecs 0.20) stays as it was.
        if !f.output.energy_ledger {
            builder
                .world
                .insert_resource(talus_core::energy::ContactEnergyBooking(false));
        }
        builder.add_plugin(&ContactPlugin);
        for install in &installs {
            builder.add_plugin(install);
        }
        builder.add_plugin(&CollisionPlugin { interaction_range });
        if let Some(b) = periodic {
            // The interaction range is known only now: a pair must not reach two images.
            let reach =
                2.0 * grains.iter().map(|g| g.radius).fold(0.0, f64::max) + interaction_range;
            for a in 0..3 {
                if b.axes[a] && b.length()[a] <= 2.0 * reach {
                    return Err(cx.err(
                        &format!("periodic.{}", ["x", "y", "z"][a]),
                        format!(
                            "a periodic length above twice the largest reach 2 R_max + r_c = {reach:.4e} m, got {:.4e} m",
                            b.length()[a]
                        ),
                    ));
                }
            }
            builder.periodic(b);
            let names: Vec<&str> = (0..3)
                .filter(|&a| b.axes[a])
                .map(|a| ["x", "y", "z"][a])
                .collect();
            builder.note(format!("periodic along {}", names.join(", ")));
            if let Some(shear) = &b.shear {
                let axis = |a: usize| ["x", "y", "z"][a];
                builder.note(format!(
                    "Lees–Edwards shear: rate {:e} /s, flow {}, gradient {} (images slide at {:.4e} m/s)",
                    shear.rate,
                    axis(shear.flow),
                    axis(shear.gradient),
                    shear.rate * b.length()[shear.gradient]
                ));
            }
        }
        // Stress sampling only when the scene asks for it: otherwise no system is added.
        if let (Some(spec), Some(regions)) = (&f.sampling, sampling_regions) {
            let interval = spec.interval.unwrap_or(f.output.report_interval);
            if !regions.is_empty() {
                builder.add_plugin(&StressPlugin {
                    every: ((interval / dt).round() as u64).max(1),
                    regions,
                });
            }
            if let Some(fields) = &spec.fields {
                let (cells, width) = check_fields(&cx, fields, two_d, periodic.as_ref())?;
                let interval = fields.interval.unwrap_or(interval);
                builder.add_plugin(&CoarseGrainingPlugin {
                    spec: FieldSpec {
                        cells,
                        width,
                        every: ((interval / dt).round() as u64).max(1),
                    },
                });
            }
        }
        if interaction_range > 0.0 {
            builder.note(format!(
                "interaction range beyond touch: {interaction_range:.4e} m (a contact law acts at a distance)"
            ));
        }
        for install in &installs {
            let law = install.law;
            let parts: Vec<String> = law
                .parts()
                .iter()
                .map(|(kind, name)| format!("{} `{name}`", kind.word()))
                .collect();
            let pairs: Vec<String> = install
                .pairs
                .iter()
                .map(|(p, _)| format!("{}–{}", p.names.0, p.names.1))
                .collect();
            builder.note(format!(
                "law `{}`{}: {}{} — pairs {}",
                law.name(),
                [("rolling", law.rolling()), ("twisting", law.twisting())]
                    .iter()
                    .filter_map(|(w, p)| p.map(|p| format!(" + {w} `{p}`")))
                    .collect::<String>(),
                law.summary(),
                if parts.is_empty() {
                    " (written whole)".to_string()
                } else {
                    format!(" (parts: {})", parts.join(", "))
                },
                pairs.join(", ")
            ));
        }
        builder.note(format!("time step: {time_step_reason}"));
        builder.note(format!("integrator: {integrator:?}"));
        builder.note(match (rotation, f.rotation) {
            (true, Some(true)) => "rotation: integrated (the scene asks for it)".to_string(),
            (true, _) => "rotation: integrated (a contact law can torque grains)".to_string(),
            (false, Some(false)) => "rotation: not integrated (the scene turns it off)".to_string(),
            (false, _) => {
                "rotation: not integrated (no contact law in this scene can torque a grain)"
                    .to_string()
            }
        });
        builder.note(format!(
            "steps: {steps}, grains: {}, walls: {}",
            grains.len(),
            walls.len()
        ));
        if let (Some(d), Some((mat, progress))) = (&f.deposition, deposition) {
            let interval = d.check_interval.unwrap_or(f.output.report_interval);
            let density = builder.world.resource::<Materials>().0[mat as usize].density;
            builder.world.insert_resource(crate::packing::Deposition {
                region: d.region.clone(),
                radius: d.radius.clone(),
                batch_size: d.batch_size,
                batches: d.batches,
                seed: d.seed,
                settle_kinetic_energy: d.settle_kinetic_energy,
                unbalanced_force: d.unbalanced_force,
                check_every: ((interval / dt).round() as u64).max(1),
                material: MaterialId(mat),
                density,
                progress,
            });
            builder.add_system(Stage::Sample, "deposition", crate::packing::deposition);
            builder.note(format!(
                "deposition: {} batches of {} grains, each once the last has settled (mean kinetic energy < {:.3e} J per grain and unbalanced-force ratio < {:.3e})",
                d.batches, d.batch_size, d.settle_kinetic_energy, d.unbalanced_force
            ));
        }
        if let Some(c) = &f.compression {
            let axes = if two_d { 2 } else { 3 };
            let Some(cell) = &periodic else {
                return Err(cx.err(
                    "compression",
                    "a scene periodic along every axis (`periodic`)",
                ));
            };
            if (0..axes).any(|a| !cell.axes[a]) {
                return Err(cx.err(
                    "periodic",
                    format!(
                        "periodic boundaries along every axis ({}) for `compression`",
                        if two_d { "x and y" } else { "x, y and z" }
                    ),
                ));
            }
            if gravity != DVec3::ZERO {
                return Err(cx.err("gravity", "no gravity with an isotropic `compression`"));
            }
            if f.integrator == IntegratorName::Gear {
                return Err(cx.err(
                    "integrator",
                    "VelocityVerlet or SymplecticEuler with `compression`",
                ));
            }
            let target = match (c.target_solid_fraction, c.target_pressure) {
                (Some(phi), None) if phi > 0.0 && phi < 1.0 => {
                    crate::packing::CompressionTarget::SolidFraction(phi)
                }
                (None, Some(p)) if positive(p) => crate::packing::CompressionTarget::Pressure(p),
                (Some(_), None) => {
                    return Err(cx.err(
                        "compression.target_solid_fraction",
                        "a solid fraction in (0, 1)",
                    ));
                }
                (None, Some(_)) => {
                    return Err(cx.err("compression.target_pressure", "a positive pressure in Pa"));
                }
                _ => {
                    return Err(cx.err(
                        "compression",
                        "exactly one of `target_solid_fraction` and `target_pressure`",
                    ));
                }
            };
            for (name, v) in [
                ("max_strain_rate", c.max_strain_rate),
                ("max_inertial_number", c.max_inertial_number),
                ("unbalanced_force", c.unbalanced_force),
                ("pressure_tolerance", c.pressure_tolerance),
            ] {
                if !positive(v) {
                    return Err(cx.err(&format!("compression.{name}"), "a positive number"));
                }
            }
            let densities = &builder.world.resource::<Materials>().0;
            let n = grains.len() as f64;
            let grain_volume: f64 = grains
                .iter()
                .map(|g| mass_and_inertia(dimension, g.radius, 1.0).0)
                .sum();
            let mean_diameter = grains.iter().map(|g| 2.0 * g.radius).sum::<f64>() / n;
            let density = grains
                .iter()
                .map(|g| g.density.unwrap_or(densities[g.material as usize].density))
                .sum::<f64>()
                / n;
            builder.world.insert_resource(crate::packing::Compression {
                target,
                max_strain_rate: c.max_strain_rate,
                max_inertial_number: c.max_inertial_number,
                unbalanced_force: c.unbalanced_force,
                pressure_tolerance: c.pressure_tolerance,
                grain_volume,
                mean_diameter,
                density,
                check_every: ((f.output.report_interval / dt).round() as u64).clamp(1, 100),
                dims: axes,
                strain_rate: 0.0,
                pressure: 0.0,
            });
            builder.add_system(
                Stage::Prepare,
                "isotropic_compression",
                crate::packing::compression,
            );
            builder.note(format!(
                "isotropic compression of the periodic cell to {target:?}, inertial number ≤ {:.1e}, strain rate ≤ {:.3e} 1/s; stops at unbalanced-force ratio < {:.1e}",
                c.max_inertial_number, c.max_strain_rate, c.unbalanced_force
            ));
        }
        if !servos.is_empty() {
            builder.add_system(
                Stage::Prepare,
                "servo_walls",
                talus_core::integrate::servo_walls,
            );
        }
        let wall_entities: Vec<Entity> = walls
            .into_iter()
            .enumerate()
            .map(|(k, (_, w))| {
                let mut entity = builder.world.spawn(w);
                if let Some((_, servo)) = servos.iter().find(|(i, _)| *i == k) {
                    entity.insert(*servo);
                }
                entity.id()
            })
            .collect();
        if !strain_drives.is_empty() {
            builder.add_system(
                Stage::Prepare,
                "strain_rate_walls",
                talus_core::integrate::strain_rate_walls,
            );
            for d in &strain_drives {
                builder
                    .world
                    .entity_mut(wall_entities[d.wall])
                    .insert(StrainRateDrive {
                        rate: d.rate,
                        opposite: wall_entities[d.opposite],
                        share: d.share,
                    });
            }
        }
        let grain_count = grains.len();
        let densities: Vec<f64> = builder
            .world
            .resource::<Materials>()
            .0
            .iter()
            .map(|m| m.density)
            .collect();
        let bundle = |g: &GrainInit| {
            GrainBundle::new(
                dimension,
                g.position,
                g.radius,
                g.density.unwrap_or(densities[g.material as usize]),
                MaterialId(g.material),
            )
            .with_velocity(g.velocity)
            .with_angular_velocity(g.angular_velocity)
        };
        let frozen_count = grains.iter().filter(|g| g.frozen).count();
        if let Some((state, mode)) = restore {
            // One by one in the saved order, so that the grains keep their dense order
            // (frozen ones go to their own table, as they did in the saving run).
            let mut saved_entities = vec![Entity::PLACEHOLDER; state.grains.len()];
            for g in &grains {
                let mut b = bundle(g);
                if let Some(i) = g.saved {
                    let s = &state.grains[i as usize];
                    b.mass = Mass(s.mass);
                    b.inertia = MomentOfInertia(s.inertia);
                    if mode == RestoreMode::Resume {
                        b.force = Force(s.force);
                        b.torque = Torque(s.torque);
                    }
                }
                let e = if g.frozen {
                    builder.world.spawn((b, Frozen)).id()
                } else {
                    builder.world.spawn(b).id()
                };
                if let Some(i) = g.saved {
                    saved_entities[i as usize] = e;
                }
            }
            if mode == RestoreMode::Resume {
                restore_run(&mut builder.world, state);
            }
            let restored =
                crate::state::restore_contacts(&mut builder.world, state, &saved_entities)
                    .map_err(|e| cx.err(restore_field, format!("a consistent state: {e}")))?;
            builder.note(format!(
                "{} saved state (step {} of scene `{}`): {} grains, {} contacts with their history",
                match mode {
                    RestoreMode::Resume => "resumed from a",
                    RestoreMode::StartFrom => "started from a",
                },
                state.step,
                state.scene,
                state.grains.len(),
                restored
            ));
        } else {
            builder.world.spawn_batch(
                grains
                    .iter()
                    .filter(|g| !g.frozen)
                    .map(bundle)
                    .collect::<Vec<_>>(),
            );
            if frozen_count > 0 {
                builder.world.spawn_batch(
                    grains
                        .iter()
                        .filter(|g| g.frozen)
                        .map(|g| (bundle(g), Frozen))
                        .collect::<Vec<_>>(),
                );
                builder.note(format!(
                    "frozen grains: {frozen_count} (in contacts, never moved)"
                ));
            }
        }
        Ok(BuiltScene {
            resumed: resuming,
            builder,
            name: f.name.clone(),
            stop: StopCondition {
                steps,
                settle_kinetic_energy: f.settle_kinetic_energy,
            },
            output: f.output.clone(),
            grain_count,
            time_step_reason,
            stability_limit: stability.as_ref().map_or(f64::INFINITY, |s| s.0),
        })
    }
}

/// The registered law a contact spec names, with its rolling and twisting parts.
fn lookup<'r>(registry: &'r LawRegistry, c: &ContactSpec) -> Option<&'r dyn LawDescriptor> {
    registry.get_with(&c.law, c.rolling.as_deref(), c.twisting.as_deref())
}

fn check_contact(
    cx: &Ctx,
    registry: &LawRegistry,
    plugins: &[String],
    c: &ContactSpec,
    field: &str,
) -> Result<(), SceneError> {
    if !registry.has(&c.law) {
        return Err(cx.err(
            &format!("{field}.law"),
            format!("a registered contact law: {}", registry.names().join(", ")),
        ));
    }
    if !plugins.contains(&c.law) {
        return Err(cx.err(
            &format!("{field}.law"),
            format!("a law listed in `plugins` (add \"{}\" there)", c.law),
        ));
    }
    let Some(law) = lookup(registry, c) else {
        // The law exists; one of its parts does not.
        let part_error = |word: &str, twisting: bool, given: &Option<String>| {
            let choices = registry.part_choices(&c.law, twisting);
            let listed = if choices.is_empty() {
                format!("nothing: `{}` has no {word} parts", c.law)
            } else {
                format!(
                    "one of {}",
                    choices
                        .iter()
                        .map(|p| format!("`{p}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            };
            cx.err(
                &format!("{field}.{word}"),
                format!(
                    "a {word} part registered with `{}`: {listed}{}",
                    c.law,
                    given
                        .as_ref()
                        .map(|g| format!(", found `{g}`"))
                        .unwrap_or_default()
                ),
            )
        };
        let rolling_known = c
            .rolling
            .as_deref()
            .is_none_or(|r| registry.part_choices(&c.law, false).contains(&r));
        return Err(if rolling_known {
            part_error("twisting", true, &c.twisting)
        } else {
            part_error("rolling", false, &c.rolling)
        });
    };
    let values = check_params(law.params(), &ParamValues(c.params.clone()))
        .map_err(|e| cx.err(&format!("{field}.{}", e.field), e.expected))?;
    law.validate(&values)
        .map_err(|e| cx.err(&format!("{field}.{}", e.field), e.expected))
}

/// Checks the `sampling` section and turns it into the regions to sample, the domain
/// first when asked for.
fn check_sampling(cx: &Ctx, s: &SamplingSpec, two_d: bool) -> Result<Vec<RegionSpec>, SceneError> {
    if let Some(interval) = s.interval
        && !positive(interval)
    {
        return Err(cx.err("sampling.interval", "a positive interval in seconds"));
    }
    if !s.domain && s.regions.is_empty() && s.fields.is_none() {
        return Err(cx.err(
            "sampling",
            "at least one region, `domain: true`, or `fields`",
        ));
    }
    if let Some(interval) = s.fields.as_ref().and_then(|f| f.interval)
        && !positive(interval)
    {
        return Err(cx.err("sampling.fields.interval", "a positive interval in seconds"));
    }
    let mut regions = Vec::new();
    if s.domain {
        regions.push(RegionSpec {
            name: DOMAIN_REGION.to_string(),
            shape: RegionShape::Domain,
            shear_rate: None,
        });
    }
    let axes = if two_d { 2 } else { 3 };
    for (k, r) in s.regions.iter().enumerate() {
        let field = |sub: &str| format!("sampling.regions[{k}].{sub}");
        let (name, shear_rate) = match r {
            SamplingRegion::Box {
                name, shear_rate, ..
            }
            | SamplingRegion::Slab {
                name, shear_rate, ..
            } => (name, *shear_rate),
        };
        let name_ok = !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !name_ok {
            return Err(cx.err(
                &field("name"),
                format!("a non-empty name of letters, digits, `_` and `-`, found `{name}`"),
            ));
        }
        if name == DOMAIN_REGION || s.regions[..k].iter().any(|o| region_name(o) == name) {
            return Err(cx.err(
                &field("name"),
                format!(
                    "a name not used by another region (`{DOMAIN_REGION}` is the whole domain), found `{name}`"
                ),
            ));
        }
        if let Some(rate) = shear_rate
            && !(rate.is_finite() && rate >= 0.0)
        {
            return Err(cx.err(&field("shear_rate"), "a non-negative shear rate in 1/s"));
        }
        let shape = match r {
            SamplingRegion::Box { min, max, .. } => {
                let (lo, hi) = (vec3(*min), vec3(*max));
                if !lo.is_finite() || !hi.is_finite() || (0..axes).any(|d| lo[d] >= hi[d]) {
                    return Err(cx.err(
                        &field("max"),
                        if two_d {
                            "x and y components of `max` above those of `min`"
                        } else {
                            "every component of `max` above that of `min`"
                        },
                    ));
                }
                RegionShape::Box { min: lo, max: hi }
            }
            SamplingRegion::Slab { axis, min, max, .. } => {
                let axis = match (axis.as_str(), two_d) {
                    ("x", _) => 0,
                    ("y", _) => 1,
                    ("z", false) => 2,
                    _ => {
                        return Err(cx.err(
                            &field("axis"),
                            if two_d {
                                format!("\"x\" or \"y\" in a 2-D scene, found \"{axis}\"")
                            } else {
                                format!("\"x\", \"y\" or \"z\", found \"{axis}\"")
                            },
                        ));
                    }
                };
                if !min.is_finite() || !max.is_finite() || min >= max {
                    return Err(cx.err(&field("max"), "a finite `max` above `min`"));
                }
                RegionShape::Slab {
                    axis,
                    min: *min,
                    max: *max,
                }
            }
        };
        regions.push(RegionSpec {
            name: name.clone(),
            shape,
            shear_rate,
        });
    }
    Ok(regions)
}

/// Largest number of grid nodes of a field (each node holds about 30 numbers).
const MAX_FIELD_NODES: u64 = 2_000_000;

/// Checks the `sampling.fields` section: the cells and the kernel width, which along a
/// periodic axis must be cut off within half the period (so that the kernel of a grain
/// does not reach round the box onto itself).
fn check_fields(
    cx: &Ctx,
    fields: &SamplingFields,
    two_d: bool,
    periodic: Option<&PeriodicBox>,
) -> Result<([usize; 3], f64), SceneError> {
    let (nx, ny, nz) = fields.cells;
    if nx == 0 || ny == 0 || nz == 0 {
        return Err(cx.err("sampling.fields.cells", "at least one cell along each axis"));
    }
    if two_d && nz != 1 {
        return Err(cx.err(
            "sampling.fields.cells",
            format!("one cell along z in a 2-D scene, (nx, ny, 1), found {nz}"),
        ));
    }
    let nodes = u64::from(nx) * u64::from(ny) * u64::from(nz);
    if nodes > MAX_FIELD_NODES {
        return Err(cx.err(
            "sampling.fields.cells",
            format!("at most {MAX_FIELD_NODES} cells in all, found {nodes}"),
        ));
    }
    let width = fields.width;
    if !positive(width) {
        return Err(cx.err("sampling.fields.width", "a positive kernel width in metres"));
    }
    if let Some(b) = periodic {
        let length = b.length();
        for a in 0..3 {
            let cutoff = talus_stress::field::CUTOFF_WIDTHS * width;
            if b.axes[a] && cutoff > 0.5 * length[a] {
                return Err(cx.err(
                    "sampling.fields.width",
                    format!(
                        "a kernel width whose cut-off 3 w is at most half the periodic length along {} ({:.4e} m), found 3 w = {cutoff:.4e} m",
                        ["x", "y", "z"][a],
                        0.5 * length[a]
                    ),
                ));
            }
        }
    }
    Ok(([nx as usize, ny as usize, nz as usize], width))
}

fn region_name(r: &SamplingRegion) -> &str {
    match r {
        SamplingRegion::Box { name, .. } | SamplingRegion::Slab { name, .. } => name,
    }
}

fn check_radius(cx: &Ctx, radius: &RadiusSpec, field: &str) -> Result<(), SceneError> {
    match *radius {
        RadiusSpec::Fixed(r) if !positive(r) => Err(cx.err(field, "a positive radius in metres")),
        RadiusSpec::Uniform { min, max } if !(positive(min) && positive(max) && min <= max) => {
            Err(cx.err(field, "radii with 0 < min ≤ max"))
        }
        _ => Ok(()),
    }
}

// Negated comparisons, so that a NaN bound is refused too.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn check_region(cx: &Ctx, r: &Region, field: &str, two_d: bool) -> Result<(), SceneError> {
    let axes = if two_d { 2 } else { 3 };
    if !vec3(r.min).is_finite()
        || !vec3(r.max).is_finite()
        || (0..axes).any(|d| !(r.min[d] < r.max[d]))
    {
        return Err(cx.err(
            &format!("{field}.max"),
            "every component of `max` above that of `min`",
        ));
    }
    Ok(())
}

/// Orders grains by cells one largest diameter wide, in rows: x fastest, then y, then z
/// ([`RowsOfCells`], LAMMPS's `atom_modify sort` order), so that grains close in space are
/// close in memory and the neighbour search, the contact loop and the force sums read and
/// write nearby memory (`docs/architecture.md`, "Grain order"). A stable sort of a fixed
/// key: the order is a function of the positions alone.
fn sort_spatially(grains: &mut [GrainInit]) {
    if let Some(rows) = RowsOfCells::over(grains.iter().map(|g| (g.position, g.radius))) {
        grains.sort_by_cached_key(|g| rows.key(g.position));
    }
}

impl Scene {
    /// The grains of a `LammpsData` source: the file is read relative to the scene file,
    /// each atom type mapped to its material (and frozen or not).
    fn read_lammps(
        &self,
        cx: &Ctx,
        k: usize,
        file: &str,
        types: &[LammpsType],
        two_d: bool,
        material_id: &dyn Fn(&str, &str) -> Result<u16, SceneError>,
    ) -> Result<Vec<GrainInit>, SceneError> {
        let field = |s: &str| format!("grains[{k}].{s}");
        if types.is_empty() {
            return Err(cx.err(
                &field("types"),
                "at least one (type: n, material: \"name\") entry",
            ));
        }
        let mut map: Vec<(u32, u16, bool)> = Vec::new();
        for (j, t) in types.iter().enumerate() {
            if map.iter().any(|m| m.0 == t.atom_type) {
                return Err(cx.err(
                    &format!("grains[{k}].types[{j}].type"),
                    format!(
                        "an atom type not already mapped (type {} appears twice)",
                        t.atom_type
                    ),
                ));
            }
            let mat = material_id(&t.material, &format!("grains[{k}].types[{j}].material"))?;
            map.push((t.atom_type, mat, t.frozen));
        }
        let path = self
            .path
            .parent()
            .map_or_else(|| Path::new(file).to_path_buf(), |dir| dir.join(file));
        let atoms = crate::lammps::read_data(&path).map_err(|e| {
            cx.err(
                &field("file"),
                if e.line > 0 {
                    format!(
                        "a valid LAMMPS data file: {}:{}: {}",
                        path.display(),
                        e.line,
                        e.message
                    )
                } else {
                    format!(
                        "a valid LAMMPS data file: {}: {}",
                        path.display(),
                        e.message
                    )
                },
            )
        })?;
        let mut out = Vec::with_capacity(atoms.len());
        for a in atoms {
            let Some(&(_, material, frozen)) = map.iter().find(|m| m.0 == a.atom_type) else {
                return Err(cx.err(
                    &field("types"),
                    format!(
                        "a material for atom type {} (atom {} in {})",
                        a.atom_type,
                        a.id,
                        path.display()
                    ),
                ));
            };
            if two_d && a.position.z != 0.0 {
                return Err(cx.err(
                    &field("file"),
                    format!(
                        "atoms in the plane z = 0 for a 2-D scene (atom {} has z = {})",
                        a.id, a.position.z
                    ),
                ));
            }
            out.push(GrainInit {
                position: a.position,
                radius: 0.5 * a.diameter,
                velocity: if frozen { DVec3::ZERO } else { a.velocity },
                angular_velocity: if frozen {
                    DVec3::ZERO
                } else {
                    a.angular_velocity
                },
                material,
                source: k,
                density: Some(a.density),
                frozen,
                saved: None,
            });
        }
        Ok(out)
    }
}

/// The periodic box of a scene: each axis given must have min < max, must not be z in a
/// 2-D scene, and must hold every grain centre in [min, max).
fn check_periodic(
    cx: &Ctx,
    spec: &PeriodicSpec,
    grains: &[GrainInit],
    two_d: bool,
) -> Result<PeriodicBox, SceneError> {
    let mut b = PeriodicBox {
        lo: DVec3::ZERO,
        hi: DVec3::ONE,
        axes: [false; 3],
        shear: None,
    };
    for (a, (name, extent)) in [("x", spec.x), ("y", spec.y), ("z", spec.z)]
        .into_iter()
        .enumerate()
    {
        let Some((lo, hi)) = extent else { continue };
        let field = format!("periodic.{name}");
        if two_d && a == 2 {
            return Err(cx.err(
                &field,
                "no periodic z axis in a 2-D scene (disks lie in the xy-plane)",
            ));
        }
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(cx.err(&field, "an extent (min, max) with min < max, in metres"));
        }
        b.lo[a] = lo;
        b.hi[a] = hi;
        b.axes[a] = true;
    }
    if !b.axes.iter().any(|&p| p) {
        return Err(cx.err("periodic", "at least one periodic axis: x, y or z"));
    }
    if let Some(shear) = &spec.shear {
        let axis = |name: &str, field: &str| -> Result<usize, SceneError> {
            let a = match name {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                _ => {
                    return Err(cx.err(field, format!("\"x\", \"y\" or \"z\", got \"{name}\"")));
                }
            };
            if !b.axes[a] {
                return Err(cx.err(
                    field,
                    format!("a periodic axis (Lees–Edwards shear needs `periodic.{name}`)"),
                ));
            }
            Ok(a)
        };
        let flow = axis(&shear.flow, "periodic.shear.flow")?;
        let gradient = axis(&shear.gradient, "periodic.shear.gradient")?;
        if flow == gradient {
            return Err(cx.err(
                "periodic.shear.gradient",
                "a gradient axis other than the flow axis",
            ));
        }
        if !shear.rate.is_finite() {
            return Err(cx.err("periodic.shear.rate", "a finite shear rate, 1/s"));
        }
        b.shear = Some(LeesEdwards {
            rate: shear.rate,
            flow,
            gradient,
            offset: 0.0,
        });
    }
    for g in grains {
        for a in 0..3 {
            if b.axes[a] && !(g.position[a] >= b.lo[a] && g.position[a] < b.hi[a]) {
                return Err(cx.err(
                    &format!("grains[{}]", g.source),
                    format!(
                        "grain centres inside the periodic extent [{}, {}) along {}, found {}",
                        b.lo[a],
                        b.hi[a],
                        ["x", "y", "z"][a],
                        g.position[a]
                    ),
                ));
            }
        }
    }
    Ok(b)
}

/// Overlaps between grains on opposite sides of a periodic face, which the plain check
/// cannot see: only grains within 2 R_max of a periodic face can be involved, and those
/// are compared pairwise through the nearest image.
fn check_overlaps_across_seams(
    cx: &Ctx,
    grains: &[GrainInit],
    b: &PeriodicBox,
    tolerance: f64,
) -> Result<(), SceneError> {
    let rmax = grains.iter().map(|g| g.radius).fold(0.0, f64::max);
    let near_face = |p: DVec3| {
        (0..3).any(|a| b.axes[a] && (p[a] - b.lo[a] < 2.0 * rmax || b.hi[a] - p[a] < 2.0 * rmax))
    };
    let band: Vec<&GrainInit> = grains.iter().filter(|g| near_face(g.position)).collect();
    let check = |i: usize, j: usize| {
        let (g, h) = (band[i], band[j]);
        if g.saved.is_some() && h.saved.is_some() {
            return Ok(()); // both from a saved state, where they touch by right
        }
        let plain = g.position - h.position;
        let image = b.min_image(plain);
        if image == plain {
            return Ok(()); // the plain check has seen this pair
        }
        let overlap = g.radius + h.radius - image.length();
        if overlap > tolerance * g.radius.min(h.radius) {
            return Err(cx.err(
                &format!("grains[{}]", h.source),
                format!(
                    "grains that do not overlap across the periodic boundary: grains at ({:.4}, {:.4}, {:.4}) (grains[{}]) and ({:.4}, {:.4}, {:.4}) overlap by {:.3e} m through the seam",
                    g.position.x, g.position.y, g.position.z, g.source, h.position.x, h.position.y, h.position.z, overlap
                ),
            ));
        }
        Ok(())
    };
    if b.shear.as_ref().is_some_and(|s| s.offset != 0.0) {
        // Images already shifted along the flow: a cell's image is not one of its
        // neighbours on the grid, so every pair of the band is tried.
        for i in 0..band.len() {
            for j in i + 1..band.len() {
                check(i, j)?;
            }
        }
        return Ok(());
    }
    let points: Vec<DVec3> = band.iter().map(|g| g.position).collect();
    for_each_close_pair(&points, Some(b), 2.0 * rmax, check)
}

/// Calls `visit(i, j)` once for every pair i < j of `points` that may lie within `reach`
/// of each other, in a fixed order; stops at the first error. The candidates come from the
/// broad phase's own cell grid ([`CellGrid`]: cells at least `reach` wide, wrapping around
/// the periodic axes of `periodic`, their number bounded so that a point flung far away
/// costs no memory). Points must lie inside the box along its periodic axes.
fn for_each_close_pair<E>(
    points: &[DVec3],
    periodic: Option<&PeriodicBox>,
    reach: f64,
    mut visit: impl FnMut(usize, usize) -> Result<(), E>,
) -> Result<(), E> {
    if points.len() < 2 {
        return Ok(());
    }
    // The grid's cells are 2 R_max wide: R_max = reach / 2 makes them `reach` wide.
    let mut s = GrainSnapshot::default();
    s.entity = vec![Entity::PLACEHOLDER; points.len()];
    s.records = points
        .iter()
        .map(|&position| talus_core::snapshot::GrainRecord {
            position,
            ..Default::default()
        })
        .collect();
    s.max_radius = 0.5 * reach;
    s.set_periodic(periodic.copied());
    let mut grid = CellGrid::default();
    grid.rebuild(&s);
    for (i, p) in points.iter().enumerate() {
        let c = grid.coords(*p);
        let [xs, ys, zs] = [0, 1, 2].map(|a| grid.neighbour_cells(c, a));
        for &cz in zs.cells() {
            for &cy in ys.cells() {
                for &cx in xs.cells() {
                    for &j in grid.cell_grains(grid.index([cx, cy, cz])) {
                        if j as usize > i {
                            visit(i, j as usize)?;
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

fn check_initial_overlaps(
    cx: &Ctx,
    grains: &[GrainInit],
    walls: &[(usize, WallBundle)],
    tolerance: f64,
) -> Result<(), SceneError> {
    for g in grains.iter().filter(|g| g.saved.is_none()) {
        for (k, w) in walls {
            let overlap = g.radius - (g.position - w.wall.point).dot(w.wall.normal);
            if overlap > tolerance * g.radius {
                return Err(cx.err(
                    &format!("grains[{}]", g.source),
                    format!(
                        "grains clear of wall `{}` (walls[{k}]): a grain at ({:.4}, {:.4}, {:.4}) overlaps it by {:.3e} m, more than {} of its radius",
                        w.wall.name, g.position.x, g.position.y, g.position.z, overlap, tolerance
                    ),
                ));
            }
        }
    }
    // Grain–grain overlaps, pairs taken from a cell grid.
    let rmax = grains.iter().map(|g| g.radius).fold(0.0, f64::max);
    let points: Vec<DVec3> = grains.iter().map(|g| g.position).collect();
    for_each_close_pair(&points, None, 2.0 * rmax, |i, j| {
        let (g, h) = (&grains[i], &grains[j]);
        if g.saved.is_some() && h.saved.is_some() {
            return Ok(()); // both from a saved state, where they touch by right
        }
        let overlap = g.radius + h.radius - g.position.distance(h.position);
        if overlap > tolerance * g.radius.min(h.radius) {
            return Err(cx.err(
                &format!("grains[{}]", h.source),
                format!(
                    "grains that do not overlap: grains at ({:.4}, {:.4}, {:.4}) (grains[{}]) and ({:.4}, {:.4}, {:.4}) overlap by {:.3e} m, more than {} of the smaller radius",
                    g.position.x, g.position.y, g.position.z, g.source, h.position.x, h.position.y, h.position.z, overlap, tolerance
                ),
            ));
        }
        Ok(())
    })
}

#[cfg(test)]
mod close_pair_tests {
    use super::*;

    /// The grid of the overlap checks visits every pair within reach (through the seams of
    /// a periodic box, or plainly without one), each once, against an all-pairs scan, for
    /// boxes of one, two and many cells per axis.
    #[test]
    fn the_grid_visits_every_pair_within_reach_once() {
        let mut x = 0x9e37_79b9_7f4a_7c15_u64;
        let mut uniform = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for (hi, axes) in [
            (DVec3::new(1.0, 0.5, 0.3), [true, true, false]),
            (DVec3::new(0.05, 0.03, 1.0), [true, true, true]),
            (DVec3::new(0.2, 0.2, 0.2), [false, true, false]),
        ] {
            let b = PeriodicBox {
                lo: DVec3::ZERO,
                hi,
                axes,
                shear: None,
            };
            let reach = 0.02;
            let points: Vec<DVec3> = (0..600)
                .map(|_| DVec3::new(uniform(), uniform(), uniform()) * hi)
                .collect();
            for periodic in [Some(&b), None] {
                let mut found = Vec::new();
                for_each_close_pair(&points, periodic, reach, |i, j| {
                    found.push((i, j));
                    Ok::<(), ()>(())
                })
                .unwrap();
                let visited = found.len();
                found.sort_unstable();
                found.dedup();
                assert_eq!(found.len(), visited, "each pair once");
                let mut expected = 0;
                for i in 0..points.len() {
                    for j in i + 1..points.len() {
                        let d = points[i] - points[j];
                        let d = periodic.map_or(d, |b| b.min_image(d));
                        if d.length() < reach {
                            expected += 1;
                            assert!(
                                found.binary_search(&(i, j)).is_ok(),
                                "pair ({i}, {j}) missed"
                            );
                        }
                    }
                }
                assert!(expected > 10, "the test box has close pairs ({expected})");
                assert!(
                    found.len() < points.len() * (points.len() - 1) / 4,
                    "not all pairs"
                );
            }
        }
    }
}
