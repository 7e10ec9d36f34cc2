//! The JSON run report: what ran, how long each stage took, the energy series, and the
//! stress series when the scene samples stresses.
//! Its format is documented in `docs/report-format.md`.

use std::collections::BTreeMap;

use bevy_ecs::prelude::*;
use serde::{Deserialize, Serialize};
use talus_core::prelude::*;
use talus_stress::{StressRecord, StressSample};

/// One sample of the energy series. The contact energies and the balances built on them
/// (`elastic`, `dissipated*`, `wall_work`, `energy_balance`, `integration_error`,
/// `bookkeeping_balance`) are booked only when the scene keeps its energy ledger
/// (`output.energy_ledger`, [`ContactEnergyBooking`]); without it they are NaN here, left
/// out of the JSON, and the dissipation maps are empty.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ReportSample {
    /// Step number.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// Σ ½ m v², J.
    pub translational_kinetic: f64,
    /// Σ ½ I ω², J.
    pub rotational_kinetic: f64,
    /// Staggering term of the kinetic energy: ½ m v₋·v₊ − ½ m v² summed over grains,
    /// translation and rotation (see `docs/physics/energy-accounting.md`), J.
    pub kinetic_staggering: f64,
    /// Elastic energy stored in contacts, J.
    #[serde(default = "not_booked", skip_serializing_if = "is_not_a_number")]
    pub elastic: f64,
    /// Energy dissipated since the start, per mechanism, J.
    pub dissipated: BTreeMap<String, f64>,
    /// Sum of `dissipated`, J.
    #[serde(default = "not_booked", skip_serializing_if = "is_not_a_number")]
    pub dissipated_total: f64,
    /// Power dissipated per mechanism during the step of the sample, W (the heat rate R of
    /// a thermodynamic law, summed over contacts).
    pub dissipation_power: BTreeMap<String, f64>,
    /// Work done on the grains by gravity since the start, J.
    pub gravity_work: f64,
    /// Work done on the grains by moving walls since the start, J.
    #[serde(default = "not_booked", skip_serializing_if = "is_not_a_number")]
    pub wall_work: f64,
    /// kinetic (with its staggering term) + elastic + dissipated − work by gravity and
    /// walls: the physical energy balance, constant up to the integrator's error, J.
    #[serde(default = "not_booked", skip_serializing_if = "is_not_a_number")]
    pub energy_balance: f64,
    /// Energy created by the time integration at contacts since the start, as the laws
    /// measure it, J.
    #[serde(default = "not_booked", skip_serializing_if = "is_not_a_number")]
    pub integration_error: f64,
    /// `energy_balance − integration_error`: constant to rounding when every term is
    /// booked, J.
    #[serde(default = "not_booked", skip_serializing_if = "is_not_a_number")]
    pub bookkeeping_balance: f64,
    /// Active contacts.
    pub contacts: usize,
    /// Largest overlap / radius.
    pub max_overlap_ratio: f64,
    /// The most recent stress sample (its own `step` says when it was taken), present
    /// only when the scene has a `sampling` section.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stress: Option<StressSample>,
}

impl ReportSample {
    /// Samples the current state of a world.
    pub fn take(world: &World) -> Self {
        let mut sample = Self::take_all(world);
        if !world
            .get_resource::<ContactEnergyBooking>()
            .is_none_or(|b| b.0)
        {
            sample.elastic = f64::NAN;
            sample.dissipated.clear();
            sample.dissipated_total = f64::NAN;
            sample.dissipation_power.clear();
            sample.wall_work = f64::NAN;
            sample.energy_balance = f64::NAN;
            sample.integration_error = f64::NAN;
            sample.bookkeeping_balance = f64::NAN;
        }
        sample
    }

    /// Every field, booked or not.
    fn take_all(world: &World) -> Self {
        let clock = world.resource::<Clock>();
        let e = world.resource::<EnergySnapshot>();
        let ledger = world.resource::<EnergyLedger>();
        let names = &world.resource::<DissipationChannels>().names;
        let dissipated: BTreeMap<String, f64> = names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), ledger.dissipated.get(i).copied().unwrap_or(0.0)))
            .collect();
        let dissipated_total = ledger.total_dissipated();
        let dissipation_power: BTreeMap<String, f64> = names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                (
                    n.clone(),
                    e.dissipation_power.get(i).copied().unwrap_or(0.0),
                )
            })
            .collect();
        let balance = e.translational_kinetic
            + e.rotational_kinetic
            + e.kinetic_staggering
            + e.elastic
            + dissipated_total
            - ledger.gravity_work
            - ledger.wall_work;
        Self {
            step: clock.step,
            time: clock.time,
            translational_kinetic: e.translational_kinetic,
            rotational_kinetic: e.rotational_kinetic,
            kinetic_staggering: e.kinetic_staggering,
            elastic: e.elastic,
            dissipated,
            dissipated_total,
            dissipation_power,
            gravity_work: ledger.gravity_work,
            wall_work: ledger.wall_work,
            energy_balance: balance,
            integration_error: ledger.integration_error,
            bookkeeping_balance: balance - ledger.integration_error,
            contacts: e.contacts,
            max_overlap_ratio: e.max_overlap_ratio,
            stress: world
                .get_resource::<StressRecord>()
                .and_then(|r| r.latest.clone()),
        }
    }

    /// Total kinetic energy.
    pub fn kinetic(&self) -> f64 {
        self.translational_kinetic + self.rotational_kinetic
    }
}

/// Whether a field is left out of the JSON: NaN, which a sample holds where the scene does
/// not book contact energies (JSON has no NaN).
fn is_not_a_number(x: &f64) -> bool {
    x.is_nan()
}

fn booked() -> bool {
    true
}

/// What a ledger field reads as when the scene does not book contact energies.
fn not_booked() -> f64 {
    f64::NAN
}

/// Wall-clock time of a run.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
pub struct WallClock {
    /// Whole run (excluding scene building), s.
    pub total: f64,
    /// The pass that evaluates the initial forces (first neighbour list, every initial
    /// contact made), s.
    #[serde(default)]
    pub priming: f64,
    /// The time steps themselves, s: `total` less the priming pass, the report samples
    /// and the last good state written at each (LAMMPS's "loop time").
    #[serde(default)]
    pub stepping: f64,
    /// Per stage, over the time steps (not the priming pass), s.
    pub stages: BTreeMap<String, f64>,
    /// Per stage, the thread-seconds the pool's other threads waited for work while it
    /// ran, summed over them (all zero on one thread): its serial work and load
    /// imbalance. On `n` threads a stage's share of idle threads is
    /// `stage_idle / ((n − 1) × stages)`.
    #[serde(default)]
    pub stage_idle: BTreeMap<String, f64>,
    /// Grain-steps per second of the time steps: grains × steps / `stepping`.
    pub grain_steps_per_second: f64,
    /// Re-sorts of the grains in memory between the time steps (`sort_grains_every`; the
    /// one before the first step is part of `priming`).
    #[serde(default)]
    pub grain_sorts: u64,
    /// Seconds those re-sorts took, part of `stepping` and of no stage.
    #[serde(default)]
    pub grain_sorting: f64,
}

/// A blow-up as reported.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BlowUpReport {
    /// Step at which it was found.
    pub step: u64,
    /// What exceeded which bound.
    pub reason: String,
    /// Entity ids (index and generation bits) of the bodies involved.
    pub bodies: Vec<u64>,
    /// File holding the last good state.
    pub last_good_state: Option<String>,
}

/// The whole report.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    /// Scene name.
    pub scene: String,
    /// Scene file.
    pub scene_file: String,
    /// Talus version.
    pub talus_version: String,
    /// 2 or 3.
    pub dimension: u8,
    /// Time step, s.
    pub time_step: f64,
    /// How the time step was chosen.
    pub time_step_reason: String,
    /// Integrator.
    pub integrator: String,
    /// Whether rotation was integrated.
    pub rotation: bool,
    /// Number of grains.
    pub grain_count: usize,
    /// Steps run.
    pub steps: u64,
    /// Simulated time, s.
    pub simulated_time: f64,
    /// Why the run stopped: "completed", "settled" or "blow_up".
    pub stopped: String,
    /// Plugins built.
    pub plugins: Vec<String>,
    /// Dissipation mechanisms.
    pub dissipation_channels: Vec<String>,
    /// Whether contact energies were booked (`output.energy_ledger`): without them the
    /// samples carry no energy balance.
    #[serde(default = "booked")]
    pub energy_ledger: bool,
    /// Energy series.
    pub samples: Vec<ReportSample>,
    /// How many times the Verlet neighbour list was built, the priming pass's build
    /// included (LAMMPS's "Neighbor list builds").
    #[serde(default)]
    pub neighbour_list_builds: u64,
    /// Timings (excluded from determinism comparisons).
    pub wall_clock: WallClock,
    /// Set if the run blew up.
    pub blow_up: Option<BlowUpReport>,
}
