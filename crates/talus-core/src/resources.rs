//! Resources every step reads: configuration, clock, materials, per-stage timings.

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Spatial dimension of a simulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Dimension {
    /// Disks in the xy-plane, rotating about z only.
    Two,
    /// Spheres in space.
    #[default]
    Three,
}

impl Dimension {
    /// 2 or 3.
    pub fn as_number(self) -> u8 {
        match self {
            Dimension::Two => 2,
            Dimension::Three => 3,
        }
    }
}

/// Time integration scheme for translation and rotation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Integrator {
    /// Velocity Verlet (kick–drift–kick), second order, symplectic. The default.
    #[default]
    VelocityVerlet,
    /// Symplectic (semi-implicit) Euler: kick then drift, first order.
    SymplecticEuler,
    /// Gear predictor–corrector, six values for positions and four for spins: high order
    /// for smooth forces, not symplectic (`crate::gear`).
    Gear,
}

impl Integrator {
    /// Fraction of the velocity update done before the drift; the rest is done
    /// after the new forces are known.
    pub fn kick_before_drift(self) -> f64 {
        match self {
            Integrator::VelocityVerlet => 0.5,
            Integrator::SymplecticEuler => 1.0,
            // Gear's own systems replace the kicks.
            Integrator::Gear => 0.0,
        }
    }
}

/// Global configuration of a simulation, fixed when it is built.
#[derive(Resource, Clone, Debug)]
pub struct SimConfig {
    /// 2-D or 3-D.
    pub dimension: Dimension,
    /// Time step, seconds.
    pub dt: f64,
    /// Gravitational acceleration, m/s².
    pub gravity: DVec3,
    /// Integration scheme.
    pub integrator: Integrator,
    /// Whether grain rotation is integrated (true only when some law can torque a grain).
    pub rotation: bool,
}

/// The simulation clock.
#[derive(Resource, Clone, Copy, Debug, Default)]
pub struct Clock {
    /// Steps completed.
    pub step: u64,
    /// Simulated time, seconds.
    pub time: f64,
    /// Time advanced by the pass being run: `dt` during a step, 0 during the priming
    /// pass that evaluates the initial forces (so history and energy do not move).
    pub pass_dt: f64,
}

/// A material: what the core needs to know (density); contact laws read their own
/// per-material parameters, resolved per material pair when the simulation is built.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name used in scene files.
    pub name: String,
    /// Density, kg/m³.
    pub density: f64,
}

/// All materials of a scene; [`crate::components::MaterialId`] indexes it.
#[derive(Resource, Clone, Debug, Default)]
pub struct Materials(pub Vec<Material>);

impl Materials {
    /// Number of materials.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether there is no material.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Index of the dense material-pair table for materials `a` and `b` (symmetric).
    pub fn pair_index(&self, a: u16, b: u16) -> usize {
        let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
        lo as usize * self.0.len() + hi as usize
    }
}

/// Wall-clock time spent in each stage so far, seconds.
#[derive(Resource, Clone, Debug, Default)]
pub struct StageTimings {
    /// Accumulated seconds per stage, in stage order.
    pub seconds: Vec<(crate::schedule::Stage, f64)>,
    pub(crate) last_mark: Option<(crate::schedule::Stage, std::time::Instant)>,
    /// Re-sorts of the grains in memory between the steps
    /// ([`SimBuilder::sort_grains_every`](crate::schedule::SimBuilder::sort_grains_every)).
    pub grain_sorts: u64,
    /// Seconds those re-sorts took (outside every stage).
    pub grain_sort_seconds: f64,
    /// Where the thread pool's other workers book the time they wait for work, stage by
    /// stage (by the stage's index in [`Stage::ALL`](crate::schedule::Stage::ALL)): shared
    /// with them while a step runs ([`crate::workers::with_workers_polling_booked`]).
    pub idle: std::sync::Arc<crate::workers::IdleBook>,
}

impl StageTimings {
    /// Accumulated seconds for one stage.
    pub fn get(&self, stage: crate::schedule::Stage) -> f64 {
        self.seconds
            .iter()
            .find(|(s, _)| *s == stage)
            .map(|(_, t)| *t)
            .unwrap_or(0.0)
    }

    /// Thread-seconds the pool's other workers waited for work while `stage` ran, summed
    /// over them (0 on one thread): the stage's serial work and load imbalance.
    pub fn idle_seconds(&self, stage: crate::schedule::Stage) -> f64 {
        self.idle.seconds(stage.index())
    }

    /// Forgets the seconds (and re-sorts, and idle time) accumulated so far (a stage being
    /// timed goes on being timed).
    pub fn clear(&mut self) {
        self.seconds.clear();
        self.grain_sorts = 0;
        self.grain_sort_seconds = 0.0;
        self.idle.clear();
    }
}

/// A run stopped because the state became unphysical.
#[derive(Clone, Debug, PartialEq)]
pub struct BlowUp {
    /// Step at which the problem was found.
    pub step: u64,
    /// What exceeded which bound.
    pub reason: String,
    /// Entities involved (grains, and for contacts the two bodies).
    pub entities: Vec<Entity>,
}

/// Set by a safety check when the run must stop; the driver stops and reports it.
#[derive(Resource, Clone, Debug)]
pub struct Health {
    /// The first problem found, if any.
    pub blow_up: Option<BlowUp>,
    /// Largest overlap / radius allowed before a run is stopped. Default: 0.5.
    pub max_overlap_ratio: f64,
    /// Whether every grain's velocity and spin was finite after the last kick (set by the
    /// second kick, or by the kinetic-energy sums under Gear; after a deferred second kick,
    /// by the next step's first kick, which then applies it: [`DeferredKick`]).
    pub motion_finite: bool,
}

impl Default for Health {
    /// No problem yet, overlaps bounded at half the smaller radius.
    fn default() -> Self {
        Self {
            blow_up: None,
            max_overlap_ratio: 0.5,
            motion_finite: true,
        }
    }
}

/// Whether the coming step sums the kinetic energies into the
/// [`EnergySnapshot`](crate::energy::EnergySnapshot). True unless a driver says
/// otherwise, so that the snapshot is current after every step. A driver that reads the
/// energies only at some steps (`talus run`, at its report and recording steps) clears it
/// for the others: their second kick then only checks that every velocity and spin is
/// finite (for the health check) and leaves the snapshot's kinetic terms as they were,
/// sparing a pass of arithmetic over the grains (2 ns a grain-step at 32,000 grains).
/// [`crate::integrate::sum_kinetic_energy`] brings them up to date at any time, with the
/// same bits.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct KineticEnergyDue(pub bool);

impl Default for KineticEnergyDue {
    fn default() -> Self {
        Self(true)
    }
}

/// A second velocity kick left by one step to the next step's first kick.
///
/// Velocity Verlet ends a step with a half kick, v += ½dt F/m, and opens the next with
/// another by the same forces: two passes over every grain's velocity, spin, force,
/// torque, mass and inertia with nothing between them that reads them, when the step's
/// end state is not looked at. A step run by [`Simulation::step_before_another`]
/// (`talus run` between its reports, [`Simulation::run_steps`] but for its last step)
/// leaves its second kick pending here instead, and the next step's first kick applies it
/// in the same pass as its own: the same operations in the same order on each grain, so
/// the same bits, one pass over the grains fewer. [`Simulation::synchronize`] applies a
/// pending kick without stepping. A simulation whose plan has a system that could read
/// or change the grains between two steps (anything in the prepare, first- or
/// second-integration, sample or export stages besides the core's integrator, wall motion
/// and health check) never defers.
///
/// [`Simulation::step_before_another`]: crate::schedule::Simulation::step_before_another
/// [`Simulation::run_steps`]: crate::schedule::Simulation::run_steps
/// [`Simulation::synchronize`]: crate::schedule::Simulation::synchronize
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct DeferredKick {
    /// Whether this step may leave its second kick pending (set by the simulation before
    /// each step; only steps whose kinetic energies are not due leave it).
    pub allowed: bool,
    /// The pending kick of the translation, as the time it spans (the integrator's
    /// second-kick fraction of the step that left it, times its dt).
    pub translation: Option<f64>,
    /// The pending kick of the rotation (spins are integrated), as `translation`.
    pub rotation: Option<f64>,
    /// Whether the grains' positions, velocities and spins of the last step are held in
    /// the [`GrainSnapshot`](crate::snapshot::GrainSnapshot) only: set by a step that left
    /// its kick pending, so that the next step's kicks and drift work on the snapshot's
    /// records in place and its copy from the grains' components is skipped. The
    /// components are written back by [`Simulation::synchronize`] and before any step that
    /// does not defer its kick.
    ///
    /// [`Simulation::synchronize`]: crate::schedule::Simulation::synchronize
    pub snapshot_holds_motion: bool,
    /// Whether a step that leaves its kick pending may leave the motion in the snapshot
    /// ([`Self::snapshot_holds_motion`]): set when the simulation is built, true when no
    /// system of its plan but the core's own and those declared motion-free could read the
    /// grains' positions, velocities or spins
    /// ([`SimBuilder::declare_motion_free`](crate::schedule::SimBuilder::declare_motion_free)).
    pub may_hold_motion: bool,
}

/// Whether a step sums the force and torque totals of the frozen grains
/// ([`Frozen`](crate::components::Frozen)), which nothing in the step reads: a frozen
/// grain is never kicked, and its totals are there for whoever looks at the grains after
/// a step (a saved state, a user's query). A step run by
/// [`Simulation::step_before_another`](crate::schedule::Simulation::step_before_another)
/// whose end is not reported leaves them unsummed where the plan allows it
/// ([`Self::may_leave`]); the next step that sums them, or
/// [`Simulation::synchronize`](crate::schedule::Simulation::synchronize), brings them up
/// to date from the contact forces, which stay stored with their contacts (no system of
/// a step changes them after its sums): the same sums in the same order, the same bits. In LAMMPS's chute the 912 frozen grains' share
/// of the sums reads the whole contact table once more at every step.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrozenTotals {
    /// Set when the simulation is built: true when no system of its plan but those
    /// declared not to read them
    /// ([`SimBuilder::declare_frozen_totals_unread`](crate::schedule::SimBuilder::declare_frozen_totals_unread))
    /// reads the grains' `Force` or `Torque`, and a step may leave its kick pending.
    pub may_leave: bool,
    /// Set by the simulation before each step: whether this step may leave the frozen
    /// grains' totals unsummed (a step run by
    /// [`Simulation::step_before_another`](crate::schedule::Simulation::step_before_another)
    /// whose kinetic energies are not due, in a plan that allows it).
    pub leave_this_step: bool,
    /// Set by the force sums when they left the frozen grains' totals unsummed: they are
    /// an earlier step's until the next step that sums them or
    /// [`Simulation::synchronize`](crate::schedule::Simulation::synchronize).
    pub pending: bool,
}

/// Work a step may leave for later that [`Simulation::synchronize`] has to finish, one
/// function per plugin that leaves some (the contact crate's frozen grains' totals,
/// [`FrozenTotals`]): each is called after the held motion is written back and the
/// pending kick applied, and does nothing when it has nothing pending.
///
/// [`Simulation::synchronize`]: crate::schedule::Simulation::synchronize
#[derive(Resource, Clone, Debug, Default)]
pub struct SynchronizeHooks(pub Vec<fn(&mut World)>);

/// Set by a protocol system (a packing generator reaching its target, say) when the run
/// has done what it was for; the driver ends the run after the step and reports the reason.
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct StopRequest(pub Option<String>);
