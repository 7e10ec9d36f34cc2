//! The staged step schedule, the plugin trait, and the simulation driver.
//!
//! A step is one bevy [`Schedule`] whose systems sit in named, chained stages
//! ([`Stage`]). Plugins add systems to stages through [`SimBuilder`]; only the
//! plugins a scene names are built, so an effect a scene does not ask for costs nothing.

use std::time::Instant;

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{ScheduleLabel, SingleThreadedExecutor};
use bevy_ecs::system::ScheduleSystem;

use crate::energy::{DissipationChannels, EnergyLedger, EnergySnapshot};
use crate::integrate;
use crate::resources::{BlowUp, Clock, Health, SimConfig, StageTimings};
use crate::snapshot::{self, GrainSnapshot};

/// The stages of one time step, run in this order.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    /// Per-step preparation (prescribed motions, bookkeeping).
    Prepare,
    /// First velocity kick and position drift; walls move.
    IntegratePositions,
    /// Dense snapshot of the grains and candidate pairs from the cell grid.
    BroadPhase,
    /// Exact overlap tests; contact entities created and removed.
    NarrowPhase,
    /// Contact laws compute forces and torques for every contact.
    ContactForces,
    /// Contact forces are summed onto grains and walls.
    ApplyContactForces,
    /// Body forces such as gravity.
    BodyForces,
    /// Second velocity kick.
    IntegrateVelocities,
    /// Energies and health checks.
    Sample,
    /// Recordings and reports.
    Export,
}

// Every stage has its part of the workers' idle book.
const _: () = assert!(Stage::ALL.len() <= crate::workers::IdleBook::PARTS);

impl Stage {
    /// All stages in execution order.
    pub const ALL: [Stage; 10] = [
        Stage::Prepare,
        Stage::IntegratePositions,
        Stage::BroadPhase,
        Stage::NarrowPhase,
        Stage::ContactForces,
        Stage::ApplyContactForces,
        Stage::BodyForces,
        Stage::IntegrateVelocities,
        Stage::Sample,
        Stage::Export,
    ];

    /// The stage's place in [`Stage::ALL`] (its order in a step).
    pub fn index(self) -> usize {
        Stage::ALL
            .iter()
            .position(|s| *s == self)
            .expect("every stage is in Stage::ALL")
    }

    /// Snake-case name used in reports and plans.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Prepare => "prepare",
            Stage::IntegratePositions => "integrate_positions",
            Stage::BroadPhase => "broad_phase",
            Stage::NarrowPhase => "narrow_phase",
            Stage::ContactForces => "contact_forces",
            Stage::ApplyContactForces => "apply_contact_forces",
            Stage::BodyForces => "body_forces",
            Stage::IntegrateVelocities => "integrate_velocities",
            Stage::Sample => "sample",
            Stage::Export => "export",
        }
    }
}

/// One ordering slot inside a stage: systems of a stage run in the order they were added.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Slot(Stage, u16);

/// Label of the step schedule.
#[derive(ScheduleLabel, Debug, Clone, PartialEq, Eq, Hash)]
pub struct StepSchedule;

/// What a built simulation will run: shown by `talus check`.
#[derive(Clone, Debug, Default)]
pub struct Plan {
    /// Systems of each stage, in execution order.
    pub stages: Vec<(Stage, Vec<String>)>,
    /// Plugins built, in build order.
    pub plugins: Vec<String>,
    /// Free-form lines: time step and how it was chosen, rotation on or off, and so on.
    pub notes: Vec<String>,
}

/// A unit of functionality a scene can name: it adds systems and resources.
pub trait Plugin {
    /// Name shown in the plan.
    fn name(&self) -> String;
    /// Adds this plugin's systems and resources.
    fn build(&self, sim: &mut SimBuilder);
}

/// Assembles a [`Simulation`]: a world, the step schedule, and the plan.
pub struct SimBuilder {
    /// The world under construction; spawn grains and walls here.
    pub world: World,
    schedule: Schedule,
    plan: Plan,
    /// Whether a plugin adds the weights m g into the grains' force totals as it sums
    /// them ([`Self::gravity_in_force_sums`]); otherwise [`Self::build`] schedules the
    /// `gravity` pass.
    gravity_in_sums: bool,
    /// Whether the core's own systems are all installed: a system added after them to a
    /// stage that runs between two steps' force evaluations marks the plan as
    /// `reads_between_steps`.
    core_installed: bool,
    /// Whether a system besides the core's integrator, wall motion and health check runs in
    /// the prepare, integration, sample or export stages, where it could read or change the
    /// grains' velocities between a step's second kick and the next step's first: a
    /// [`DeferredKick`](crate::resources::DeferredKick) is then never left.
    reads_between_steps: bool,
    /// The system types declared not to read or change the grains' positions, velocities
    /// or spins beyond the core's own use ([`Self::declare_motion_free`]): the core's
    /// integrator, snapshot and health check, and systems that declare no such access but
    /// take the whole world.
    motion_free: Vec<std::any::TypeId>,
    /// The system types declared not to read the frozen grains' force and torque totals
    /// ([`Self::declare_frozen_totals_unread`]).
    frozen_totals_unread: Vec<std::any::TypeId>,
    /// Steps between two re-sorts of the grains in memory ([`Self::sort_grains_every`]).
    sort_every: Option<std::num::NonZeroU64>,
}

impl SimBuilder {
    /// A builder with the core resources and the core systems (integration, snapshot,
    /// gravity, energy sampling) installed.
    pub fn new(config: SimConfig) -> Self {
        let mut world = World::new();
        world.insert_resource(Clock::default());
        world.insert_resource(crate::resources::StopRequest::default());
        world.insert_resource(StageTimings::default());
        world.insert_resource(Health::default());
        world.insert_resource(crate::resources::KineticEnergyDue::default());
        world.insert_resource(crate::resources::DeferredKick::default());
        world.insert_resource(crate::resources::FrozenTotals::default());
        world.insert_resource(crate::resources::SynchronizeHooks::default());
        world.insert_resource(DissipationChannels::default());
        world.insert_resource(EnergyLedger::default());
        world.insert_resource(EnergySnapshot::default());
        world.insert_resource(GrainSnapshot::default());
        let rotation = config.rotation;
        let integrator = config.integrator;
        world.insert_resource(config);

        let mut schedule = Schedule::new(StepSchedule);
        schedule.set_executor(SingleThreadedExecutor::default());
        schedule.configure_sets(
            (
                Stage::Prepare,
                Stage::IntegratePositions,
                Stage::BroadPhase,
                Stage::NarrowPhase,
                Stage::ContactForces,
                Stage::ApplyContactForces,
                Stage::BodyForces,
                Stage::IntegrateVelocities,
                Stage::Sample,
                Stage::Export,
            )
                .chain(),
        );
        let mut builder = Self {
            world,
            schedule,
            plan: Plan {
                stages: Stage::ALL.iter().map(|s| (*s, Vec::new())).collect(),
                ..Plan::default()
            },
            gravity_in_sums: false,
            core_installed: false,
            reads_between_steps: false,
            motion_free: Vec::new(),
            frozen_totals_unread: Vec::new(),
            sort_every: None,
        };
        // The core's own systems that read or change the grains' motion know where it is
        // (`DeferredKick::snapshot_holds_motion`).
        builder.declare_motion_free(&integrate::kick_drift_translation);
        builder.declare_motion_free(&integrate::first_kick_rotation);
        builder.declare_motion_free(&snapshot::gather_snapshot);
        builder.declare_motion_free(&integrate::second_kick_and_kinetic_energy);
        builder.declare_motion_free(&integrate::health_check);
        // The integrators and the health check read the totals of the moving grains only.
        builder.declare_frozen_totals_unread(&integrate::kick_drift_translation);
        builder.declare_frozen_totals_unread(&integrate::first_kick_rotation);
        builder.declare_frozen_totals_unread(&integrate::second_kick_and_kinetic_energy);
        builder.declare_frozen_totals_unread(&integrate::kinetic_energy);
        builder.declare_frozen_totals_unread(&crate::gear::gear_predict);
        builder.declare_frozen_totals_unread(&crate::gear::gear_correct);
        builder.declare_frozen_totals_unread(&integrate::health_check);
        for stage in Stage::ALL {
            builder.add_hidden(stage, mark_stage(stage));
        }
        let gear = integrator == crate::resources::Integrator::Gear;
        if gear {
            builder
                .world
                .insert_resource(crate::gear::GearHistory::default());
            builder.add_system(
                Stage::IntegratePositions,
                "gear_predict",
                crate::gear::gear_predict,
            );
        } else {
            builder.add_system(
                Stage::IntegratePositions,
                "kick_drift_translation",
                integrate::kick_drift_translation,
            );
            if rotation {
                builder.add_system(
                    Stage::IntegratePositions,
                    "kick_rotation",
                    integrate::first_kick_rotation,
                );
            }
        }
        builder.add_system(
            Stage::IntegratePositions,
            "move_walls",
            integrate::move_walls,
        );
        builder.add_system(
            Stage::BroadPhase,
            "gather_snapshot",
            snapshot::gather_snapshot,
        );
        if gear {
            builder.add_system(
                Stage::IntegrateVelocities,
                "gear_correct",
                crate::gear::gear_correct,
            );
            builder.add_system(Stage::Sample, "kinetic_energy", integrate::kinetic_energy);
        } else {
            // The second kick and the kinetic energies in one pass over the grains (the
            // name says what it kicks: rotation only when it is integrated).
            let name = if rotation {
                "kick_translation_rotation_kinetic_energy"
            } else {
                "kick_translation_kinetic_energy"
            };
            builder.add_system(
                Stage::IntegrateVelocities,
                name,
                integrate::second_kick_and_kinetic_energy,
            );
        }
        builder.add_system(Stage::Sample, "health_check", integrate::health_check);
        builder.core_installed = true;
        builder
    }

    /// Makes the simulation periodic along the box's flagged axes: positions are wrapped
    /// into the box by [`snapshot::gather_snapshot`] as it copies them (the first system of
    /// the broad phase, right after the drift), and pair separations take the nearest
    /// image. A box with Lees–Edwards shear gets the sheared wrap (which also advances the
    /// image offset and moves velocities through the gradient seam) after the drift.
    pub fn periodic(&mut self, box_: crate::periodic::PeriodicBox) {
        self.world.insert_resource(box_);
        if box_.shear.is_some() {
            self.add_system(
                Stage::IntegratePositions,
                "wrap_positions_lees_edwards",
                crate::periodic::wrap_positions_sheared,
            );
        }
    }

    /// Adds a system at the end of a stage, under a name shown in the plan.
    pub fn add_system<M>(
        &mut self,
        stage: Stage,
        name: impl Into<String>,
        system: impl IntoScheduleConfigs<ScheduleSystem, M>,
    ) -> &mut Self {
        self.add_hidden(stage, system);
        if self.core_installed
            && matches!(
                stage,
                Stage::Prepare
                    | Stage::IntegratePositions
                    | Stage::IntegrateVelocities
                    | Stage::Sample
                    | Stage::Export
            )
        {
            self.reads_between_steps = true;
        }
        let entry = self
            .plan
            .stages
            .iter_mut()
            .find(|(s, _)| *s == stage)
            .expect("every stage has a plan entry");
        entry.1.push(name.into());
        self
    }

    fn add_hidden<M>(&mut self, stage: Stage, system: impl IntoScheduleConfigs<ScheduleSystem, M>) {
        let count = self.slot_count(stage);
        let slot = Slot(stage, count);
        if count == 0 {
            self.schedule.configure_sets(slot.in_set(stage));
        } else {
            self.schedule
                .configure_sets(slot.in_set(stage).after(Slot(stage, count - 1)));
        }
        self.schedule.add_systems(system.in_set(slot));
        self.slot_counts_mut(stage);
    }

    fn slot_count(&mut self, stage: Stage) -> u16 {
        let counts = self.world.get_resource_or_insert_with(SlotCounts::default);
        counts.0[stage as usize]
    }

    fn slot_counts_mut(&mut self, stage: Stage) {
        let mut counts = self.world.resource_mut::<SlotCounts>();
        counts.0[stage as usize] += 1;
    }

    /// Builds a plugin and records its name in the plan.
    pub fn add_plugin(&mut self, plugin: &dyn Plugin) -> &mut Self {
        self.plan.plugins.push(plugin.name());
        plugin.build(self);
        self
    }

    /// Adds a line to the plan (time step, reasons, options).
    pub fn note(&mut self, line: impl Into<String>) -> &mut Self {
        self.plan.notes.push(line.into());
        self
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        self.world.resource::<SimConfig>()
    }

    /// The plan as it stands.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// Declares that the system which overwrites the grains' force totals each step with
    /// the sum of their contact forces starts each total from the grain's weight m g
    /// (`SimConfig::gravity`), so that gravity needs no pass of its own over the grains
    /// (the contact crate's force sums do). Without such a system, [`Self::build`]
    /// schedules the `gravity` system in [`Stage::BodyForces`].
    pub fn gravity_in_force_sums(&mut self) {
        self.gravity_in_sums = true;
        if self.config().gravity != glam::DVec3::ZERO {
            self.note("gravity: each grain's force total starts from its weight m g in the force sums (no pass of its own)");
        }
    }

    /// Declares that a system added with [`Self::add_system`] reads and changes none of the
    /// grains' positions, velocities and spins (`Position`, `Velocity`, `AngularVelocity`),
    /// whatever access it declares: for a system that takes the whole world (`&mut World`)
    /// to spawn or despawn entities but reads the grains only through the
    /// [`GrainSnapshot`]. Between two steps that nothing observes, the snapshot may hold
    /// the grains' motion in place of those components
    /// ([`DeferredKick::snapshot_holds_motion`](crate::resources::DeferredKick::snapshot_holds_motion));
    /// a system that takes the whole world without this declaration, or that declares an
    /// access to one of them, keeps the components current at every step.
    pub fn declare_motion_free<F: IntoSystem<(), (), M>, M>(&mut self, _system: &F) {
        self.motion_free.push(std::any::TypeId::of::<F::System>());
    }

    /// Declares that a system added with [`Self::add_system`] reads no frozen grain's
    /// force or torque total (`Force`, `Torque` of a grain with `Frozen`), whatever access
    /// it declares: the sums that write them, systems that read the moving grains' only,
    /// systems that take the whole world but not for them. A step whose end nothing
    /// observes may then leave those totals unsummed
    /// ([`FrozenTotals`](crate::resources::FrozenTotals)); a system that takes the whole
    /// world or declares an access to `Force` or `Torque` without this declaration keeps
    /// them summed at every step.
    pub fn declare_frozen_totals_unread<F: IntoSystem<(), (), M>, M>(&mut self, _system: &F) {
        self.frozen_totals_unread
            .push(std::any::TypeId::of::<F::System>());
    }

    /// Adds a function [`Simulation::synchronize`] calls to finish what a step left for
    /// later ([`SynchronizeHooks`](crate::resources::SynchronizeHooks)).
    pub fn on_synchronize(&mut self, hook: fn(&mut World)) {
        let mut hooks = self
            .world
            .resource_mut::<crate::resources::SynchronizeHooks>();
        if !hooks.0.contains(&hook) {
            hooks.0.push(hook);
        }
    }

    /// Whether a system of the step, other than those in `declared`, takes the whole
    /// world or declares an access to one of `components`. Builds the schedule to read
    /// the systems' accesses; true if it cannot.
    fn others_access(
        &mut self,
        components: &[bevy_ecs::component::ComponentId],
        declared: &[std::any::TypeId],
    ) -> bool {
        use bevy_ecs::schedule::ApplyDeferred;
        use bevy_ecs::system::SystemAccess;
        if self.schedule.initialize(&mut self.world).is_err() {
            return true;
        }
        let Ok(mut systems) = self.schedule.systems_with_access() else {
            return true;
        };
        systems.any(|(_, s)| {
            let kind = s.system().system_type();
            if declared.contains(&kind) || kind == std::any::TypeId::of::<ApplyDeferred>() {
                return false;
            }
            match s.access() {
                SystemAccess::None => false,
                SystemAccess::Exclusive => true,
                SystemAccess::Shared(access) => {
                    let access = access.combined_access();
                    components.iter().any(|&c| access.has_read(c))
                }
            }
        })
    }

    /// Whether a system of the step, other than those of [`Self::declare_motion_free`],
    /// takes the whole world or declares an access to the grains' positions, velocities or
    /// spins.
    fn others_touch_motion(&mut self) -> bool {
        use crate::components::{AngularVelocity, Position, Velocity};
        let motion = [
            self.world.register_component::<Position>(),
            self.world.register_component::<Velocity>(),
            self.world.register_component::<AngularVelocity>(),
        ];
        let declared = std::mem::take(&mut self.motion_free);
        let touch = self.others_access(&motion, &declared);
        self.motion_free = declared;
        touch
    }

    /// Whether a system of the step, other than those of
    /// [`Self::declare_frozen_totals_unread`], takes the whole world or declares an access
    /// to the grains' force or torque totals.
    fn others_read_totals(&mut self) -> bool {
        use crate::components::{Force, Torque};
        let totals = [
            self.world.register_component::<Force>(),
            self.world.register_component::<Torque>(),
        ];
        let declared = std::mem::take(&mut self.frozen_totals_unread);
        let read = self.others_access(&totals, &declared);
        self.frozen_totals_unread = declared;
        read
    }

    /// Re-sorts the grains in memory by position ([`crate::grain_order::sort_grains`]) before
    /// the first step and then every `steps` steps (LAMMPS's `atom_modify sort`), so that a
    /// packing whose grains move far keeps its neighbours near in memory. Between two
    /// steps, with the grains' state written back first: no system of the step sees it.
    pub fn sort_grains_every(&mut self, steps: std::num::NonZeroU64) {
        self.sort_every = Some(steps);
        self.note(format!(
            "grains re-sorted in memory (rows of cells) before the first step and every {steps} steps"
        ));
    }

    /// Finishes the simulation. Initial forces are evaluated on the first step call.
    pub fn build(mut self) -> Simulation {
        if self.config().gravity != glam::DVec3::ZERO && !self.gravity_in_sums {
            self.add_system(Stage::BodyForces, "gravity", integrate::gravity);
        }
        self.world.remove_resource::<SlotCounts>();
        let can_defer_kick = !self.reads_between_steps;
        // The snapshot may hold the motion between unobserved steps only where no other
        // system could look for it in the components.
        let can_hold_motion = can_defer_kick && !self.others_touch_motion();
        self.world
            .resource_mut::<crate::resources::DeferredKick>()
            .may_hold_motion = can_hold_motion;
        // Likewise the frozen grains' totals may be left unsummed only where no other
        // system could read them.
        let can_leave_frozen_totals = can_defer_kick && !self.others_read_totals();
        self.world
            .resource_mut::<crate::resources::FrozenTotals>()
            .may_leave = can_leave_frozen_totals;
        Simulation {
            world: self.world,
            schedule: self.schedule,
            plan: self.plan,
            primed: false,
            can_defer_kick,
            sort_every: self.sort_every,
            sorted_at: None,
        }
    }
}

#[derive(Resource, Default)]
struct SlotCounts([u16; 10]);

fn mark_stage(stage: Stage) -> impl FnMut(ResMut<StageTimings>) {
    move |mut timings: ResMut<StageTimings>| {
        let now = Instant::now();
        timings.close_mark(now);
        timings.last_mark = Some((stage, now));
        timings.idle.enter(stage.index());
    }
}

impl StageTimings {
    fn close_mark(&mut self, now: Instant) {
        // Between steps the workers' idle time belongs to no stage.
        self.idle.enter(crate::workers::IdleBook::NONE);
        if let Some((stage, start)) = self.last_mark.take() {
            let elapsed = (now - start).as_secs_f64();
            match self.seconds.iter_mut().find(|(s, _)| *s == stage) {
                Some(entry) => entry.1 += elapsed,
                None => self.seconds.push((stage, elapsed)),
            }
        }
    }
}

/// A built simulation: call [`Simulation::step`] to advance it ([`Simulation::run_steps`]
/// for several steps at once, [`Simulation::step_before_another`] in a driver's loop
/// between the steps it looks at).
pub struct Simulation {
    /// The world: grains, walls, contacts and resources.
    pub world: World,
    schedule: Schedule,
    /// What runs in each stage.
    pub plan: Plan,
    primed: bool,
    /// Whether nothing in the plan reads or changes the grains between two steps, so that
    /// a step followed by another may leave its second kick to the next
    /// ([`DeferredKick`](crate::resources::DeferredKick)).
    can_defer_kick: bool,
    /// Steps between two re-sorts of the grains ([`SimBuilder::sort_grains_every`]).
    sort_every: Option<std::num::NonZeroU64>,
    /// The step count at the last re-sort, so that a step count is sorted at most once.
    sorted_at: Option<u64>,
}

impl Simulation {
    /// Marks the forces of the current state as already evaluated, so that no priming
    /// pass runs: for a state restored from a save, whose forces, contact histories and
    /// energies are those the saving run had computed (a priming pass would re-evaluate
    /// the contacts and could change their histories in the last bits).
    pub fn mark_primed(&mut self) {
        self.primed = true;
    }

    /// Evaluates the forces of the initial state without moving anything (a pass with
    /// zero time advance), so that the first velocity kick uses them. Idempotent.
    pub fn prime(&mut self) -> Result<(), BlowUp> {
        if self.primed {
            return Ok(());
        }
        // The initial contacts are made in the sorted order.
        self.sort_grains_if_due();
        self.primed = true;
        self.world.resource_mut::<Clock>().pass_dt = 0.0;
        self.world
            .resource_mut::<crate::resources::FrozenTotals>()
            .leave_this_step = false;
        self.run_pass()
    }

    /// Advances one time step; the grains' state is the step's end state.
    pub fn step(&mut self) -> Result<(), BlowUp> {
        self.step_deferring(false)
    }

    /// Advances one time step that will be followed by another before anything reads or
    /// changes the grains: the step's second kick may be left to the next step's first kick
    /// ([`DeferredKick`](crate::resources::DeferredKick); the same bits, one pass over
    /// the grains fewer). A step whose kinetic energies are due
    /// ([`KineticEnergyDue`](crate::resources::KineticEnergyDue)) kicks as usual. Where
    /// the plan allows it ([`Self::may_hold_motion`]) the grains' positions, velocities and
    /// spins are then left in the snapshot, their components stale until the next step
    /// that does not defer or [`Self::synchronize`]: call it before reading or changing
    /// the grains after such a step without stepping again. So are the frozen grains'
    /// force and torque totals where the plan allows it
    /// ([`FrozenTotals`](crate::resources::FrozenTotals)). A non-finite velocity this
    /// step produced shows at the next step.
    pub fn step_before_another(&mut self) -> Result<(), BlowUp> {
        self.step_deferring(self.can_defer_kick)
    }

    /// Writes back the motion the snapshot holds, applies the second kick a step left
    /// to the next one, if any ([`Self::step_before_another`]), and finishes what else the
    /// step left ([`SynchronizeHooks`](crate::resources::SynchronizeHooks): the frozen
    /// grains' force totals): the grains' components become the last step's end state.
    pub fn synchronize(&mut self) {
        integrate::write_back_held_motion(&mut self.world);
        integrate::apply_deferred_kick(&mut self.world);
        let hooks = self
            .world
            .resource::<crate::resources::SynchronizeHooks>()
            .0
            .clone();
        for hook in hooks {
            hook(&mut self.world);
        }
    }

    /// Puts the grains in the order of their cells
    /// ([`crate::grain_order::sort_grains`]) after writing back what the last step left
    /// ([`Self::synchronize`]). Returns the number of grains moved (0 when every table was
    /// in order). Changes no grain's state, contact or history; the order of the force
    /// sums over a grain's contacts, and so the last bits of later steps, may change with
    /// the order of contacts the narrow phase makes.
    pub fn sort_grains(&mut self) -> usize {
        self.synchronize();
        crate::grain_order::sort_grains(&mut self.world)
    }

    /// Re-sorts the grains when the step count is a multiple of the interval
    /// ([`SimBuilder::sort_grains_every`]) and they were not sorted at this count yet.
    fn sort_grains_if_due(&mut self) {
        let Some(every) = self.sort_every else {
            return;
        };
        let step = self.world.resource::<Clock>().step;
        if step.is_multiple_of(every.get()) && self.sorted_at != Some(step) {
            self.sorted_at = Some(step);
            let start = Instant::now();
            self.sort_grains();
            let mut timings = self.world.resource_mut::<StageTimings>();
            timings.grain_sorts += 1;
            timings.grain_sort_seconds += start.elapsed().as_secs_f64();
        }
    }

    fn step_deferring(&mut self, defer: bool) -> Result<(), BlowUp> {
        self.sort_grains_if_due();
        self.prime()?;
        // A step that will kick its grains to its end state works on their components:
        // the snapshot gives back the motion it holds first.
        let due = self
            .world
            .resource::<crate::resources::KineticEnergyDue>()
            .0;
        if !defer || due {
            integrate::write_back_held_motion(&mut self.world);
        }
        self.world
            .resource_mut::<crate::resources::DeferredKick>()
            .allowed = defer;
        {
            let mut frozen = self.world.resource_mut::<crate::resources::FrozenTotals>();
            frozen.leave_this_step = frozen.may_leave && defer && !due;
        }
        let dt = self.world.resource::<SimConfig>().dt;
        {
            let mut clock = self.world.resource_mut::<Clock>();
            clock.pass_dt = dt;
            clock.step += 1;
            // Multiply rather than accumulate so that simulated time carries no round-off drift.
            clock.time = clock.step as f64 * dt;
        }
        self.run_pass()
    }

    /// Advances `n` steps, stopping at the first blow-up. Nothing is read between the
    /// steps: all but the last leave their second kick to the next
    /// ([`Self::step_before_another`]) without summing the kinetic energies, and the last
    /// runs as [`Self::step`] with [`KineticEnergyDue`](crate::resources::KineticEnergyDue)
    /// as the caller left it. On a blow-up the pending kick is applied before returning.
    pub fn run_steps(&mut self, n: u64) -> Result<(), BlowUp> {
        use crate::resources::KineticEnergyDue;
        let due = self.world.resource::<KineticEnergyDue>().0;
        let mut result = Ok(());
        for k in 0..n {
            if k + 1 < n && self.can_defer_kick {
                self.world.resource_mut::<KineticEnergyDue>().0 = false;
                result = self.step_before_another();
            } else {
                self.world.resource_mut::<KineticEnergyDue>().0 = due;
                result = self.step();
            }
            if result.is_err() {
                break;
            }
        }
        self.world.resource_mut::<KineticEnergyDue>().0 = due;
        self.synchronize();
        result
    }

    fn run_pass(&mut self) -> Result<(), BlowUp> {
        let idle = self.world.resource::<StageTimings>().idle.clone();
        let (schedule, world) = (&mut self.schedule, &mut self.world);
        crate::workers::with_workers_polling_booked(Some(&idle), || schedule.run(world));
        // Despawned contacts leave removal messages in the world until its trackers are
        // cleared (an app does it every frame): without this they pile up for the whole
        // run, about 80 bytes per grain every 100 steps of a flowing packing.
        self.world.clear_trackers();
        self.world
            .resource_mut::<StageTimings>()
            .close_mark(Instant::now());
        match self.world.resource::<Health>().blow_up.clone() {
            Some(b) => Err(b),
            None => Ok(()),
        }
    }

    /// Whether, between two steps that nothing observes ([`Self::step_before_another`]),
    /// the grains' positions, velocities and spins may be held in the [`GrainSnapshot`] in
    /// place of their components
    /// ([`DeferredKick::snapshot_holds_motion`](crate::resources::DeferredKick::snapshot_holds_motion)):
    /// true when no system of the plan besides those declared motion-free
    /// ([`SimBuilder::declare_motion_free`]) could read them there.
    pub fn may_hold_motion(&self) -> bool {
        self.world
            .resource::<crate::resources::DeferredKick>()
            .may_hold_motion
    }

    /// Steps completed.
    pub fn step_count(&self) -> u64 {
        self.world.resource::<Clock>().step
    }

    /// Simulated time, seconds.
    pub fn time(&self) -> f64 {
        self.world.resource::<Clock>().time
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        self.world.resource::<SimConfig>()
    }
}
