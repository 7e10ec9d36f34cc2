//! Energy bookkeeping: the work done on the grains by gravity and by walls, the energy
//! dissipated per mechanism, and the elastic energy held by contacts. Each term is
//! computed from its own formula, so the balance is a real check.

use bevy_ecs::prelude::*;

/// Largest number of dissipation mechanisms one contact law may report.
pub const MAX_DISSIPATION_CHANNELS: usize = 12;

/// Names of the dissipation mechanisms registered by the laws of a scene.
/// A law gets the channel ids for its mechanisms when it is built.
#[derive(Resource, Clone, Debug, Default)]
pub struct DissipationChannels {
    /// Channel names, indexed by channel id.
    pub names: Vec<String>,
}

impl DissipationChannels {
    /// Id of the channel with this name, registering it if it is new.
    pub fn register(&mut self, name: &str) -> usize {
        if let Some(i) = self.names.iter().position(|n| n == name) {
            return i;
        }
        self.names.push(name.to_string());
        self.names.len() - 1
    }
}

/// Running totals of the energy flows since the start of the run, joules.
#[derive(Resource, Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnergyLedger {
    /// Work done on the grains by gravity, Σ m g·Δx.
    pub gravity_work: f64,
    /// Work done on the grains by moving walls, Σ F_wall·u_wall Δt.
    pub wall_work: f64,
    /// Energy dissipated so far, per channel of [`DissipationChannels`].
    pub dissipated: Vec<f64>,
    /// Energy created so far by the time integration at contacts, as the laws measure
    /// it (the trapezoidal work of their conservative forces plus the change of their
    /// potential). Not a physical flow: the truncation error of the step, reported so
    /// that the rest of the bookkeeping can be checked to rounding.
    pub integration_error: f64,
}

impl EnergyLedger {
    /// Total energy dissipated by all mechanisms.
    pub fn total_dissipated(&self) -> f64 {
        self.dissipated.iter().sum()
    }
}

/// Whether the force loops book the contacts' energies at every step: the elastic
/// energy, the dissipation per mechanism, the work of moving walls through contacts and
/// the integration error (the scene's `output.energy_ledger`, on by default). Off, the
/// forces and the trajectory are the same bit for bit and the force loop skips those
/// sums; the ledger's contact terms and [`EnergySnapshot::elastic`] stay zero and the
/// report leaves them out. The kinetic energies and the work of gravity are kept. No
/// resource means booked.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ContactEnergyBooking(pub bool);

impl Default for ContactEnergyBooking {
    fn default() -> Self {
        Self(true)
    }
}

/// Instantaneous energies of the current state, recomputed by the sample stage.
#[derive(Resource, Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnergySnapshot {
    /// Σ ½ m v².
    pub translational_kinetic: f64,
    /// Σ ½ I ω².
    pub rotational_kinetic: f64,
    /// Σ (½ m v₋·v₊ − ½ m v²) + the same for rotation: added to the kinetic energy, it
    /// gives the kinetic energy whose change equals the trapezoidal work of the forces,
    /// which is what velocity Verlet conserves; O(dt²), zero where forces balance, J.
    pub kinetic_staggering: f64,
    /// Σ elastic energy stored in contacts.
    pub elastic: f64,
    /// Power dissipated during the last step, per channel of [`DissipationChannels`]
    /// (energy dissipated in the step / dt), W. For a law with a heat channel this is its
    /// heat rate summed over the contacts.
    pub dissipation_power: Vec<f64>,
    /// Number of active contacts.
    pub contacts: usize,
    /// Largest overlap divided by the smaller radius of the pair (walls: the grain radius).
    pub max_overlap_ratio: f64,
    /// The two bodies of the contact with the largest overlap ratio (not saved with a
    /// state: entity ids do not survive a restart).
    #[serde(skip)]
    pub worst_overlap_pair: Option<(Entity, Entity)>,
}

impl EnergySnapshot {
    /// Sets the kinetic energies from per-chunk sums [Σ½mv², Σ½Iω², staggering], added in
    /// the chunks' order (the same total on any number of threads).
    pub fn store_kinetic(&mut self, chunk_sums: &[[f64; 3]]) {
        let [mut translational, mut rotational, mut staggering] = [0.0; 3];
        for [t, r, s] in chunk_sums {
            translational += t;
            rotational += r;
            staggering += s;
        }
        self.translational_kinetic = translational;
        self.rotational_kinetic = rotational;
        self.kinetic_staggering = staggering;
    }
}
