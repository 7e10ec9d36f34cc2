//! Contact systems: the generic per-law force loop, and the summation of contact
//! forces, torques and energies onto grains, walls and the energy ledger.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;
use talus_core::prelude::*;

use crate::components::*;
use crate::kinematics::ContactKinematics;
use crate::law::{ContactLaw, LawChannels, PairParams};

/// Contacts below this count are evaluated on one thread.
const PARALLEL_MIN_LEN: usize = 512;

/// How a new contact between two materials is created: by the law assigned to the pair.
#[derive(Clone, Debug)]
pub struct LawSlot {
    /// Name of the law.
    pub law: &'static str,
    /// Index into the law's [`PairParams`].
    pub pair_slot: u32,
    /// Spawns a contact entity with the law's history component.
    pub spawn: fn(&mut World, Contact) -> Entity,
    /// The law's Rust type name: a saved contact is restored only into the same law.
    pub law_type: &'static str,
    /// A copy of the history of one of this law's contacts (in-memory saved states).
    pub history: fn(&World, Entity) -> Option<Box<dyn std::any::Any + Send + Sync>>,
    /// A history copied by [`Self::history`] as RON text (saved state files); `None` if
    /// it is not this law's.
    pub history_text: fn(&(dyn std::any::Any + Send + Sync)) -> Option<String>,
    /// Re-creates a saved contact with its geometry, force and history (RON text).
    pub restore:
        fn(&mut World, Contact, ContactGeometry, ContactForce, &str) -> Result<Entity, String>,
}

/// Which law handles each material pair, indexed by `a * n_materials + b`.
#[derive(Resource, Clone, Debug, Default)]
pub struct ContactLawTable {
    /// One entry per ordered material pair; `None` means the pair does not interact.
    pub slots: Vec<Option<LawSlot>>,
    /// Number of materials.
    pub n_materials: usize,
}

impl ContactLawTable {
    /// The law slot of a material pair.
    #[inline]
    pub fn get(&self, a: u16, b: u16) -> Option<&LawSlot> {
        self.slots
            .get(a as usize * self.n_materials + b as usize)
            .and_then(|s| s.as_ref())
    }
}

/// Installs the contact bookkeeping: the law table and the systems that apply contact
/// forces and sum contact energies. Add it before any law.
pub struct ContactPlugin;

impl Plugin for ContactPlugin {
    fn name(&self) -> String {
        "contacts".into()
    }

    fn build(&self, sim: &mut SimBuilder) {
        let n = sim.world.resource::<Materials>().len();
        sim.world.insert_resource(ContactLawTable {
            slots: vec![None; n * n],
            n_materials: n,
        });
        sim.add_system(
            Stage::ApplyContactForces,
            "apply_contact_forces",
            apply_contact_forces,
        );
    }
}

/// Evaluates law `L` on all of its contacts in parallel, writing geometry, force,
/// torques and energies into each contact entity.
#[allow(clippy::type_complexity)]
pub fn evaluate_law<L: ContactLaw>(
    snapshot: Res<GrainSnapshot>,
    clock: Res<Clock>,
    params: Res<PairParams<L>>,
    channels: Res<LawChannels<L>>,
    mut contacts: Query<(
        &Contact,
        &mut LawState<L::History>,
        &mut ContactGeometry,
        &mut ContactForce,
        &mut ContactEnergy,
    )>,
) {
    let dt = clock.pass_dt;
    let snapshot = &*snapshot;
    let params = &params.0;
    let channel_ids = &channels.ids;
    for (c, mut h, mut g, mut f, mut e) in contacts
        .contiguous_iter_mut()
        .expect("contact query is dense")
    {
        let h = h.bypass_change_detection();
        let g = g.bypass_change_detection();
        let f = f.bypass_change_detection();
        let e = e.bypass_change_detection();
        c.par_iter()
            .zip(h.par_iter_mut())
            .zip(g.par_iter_mut())
            .zip(f.par_iter_mut())
            .zip(e.par_iter_mut())
            .with_min_len(PARALLEL_MIN_LEN)
            .for_each(|((((c, h), g), f), e)| {
                let Bodies {
                    mut kin,
                    omega_a,
                    omega_b,
                    wall_velocity,
                } = bodies(snapshot, c);
                let branch_shift = kin.set_displacement(g.normal, g.overlap, omega_a, omega_b, dt);
                let old_force = f.force;
                let r = L::evaluate(&params[c.pair_slot as usize], &kin, &mut h.0, dt);
                // The old force acted over the first half of the step, the new one acts
                // over the second: the trapezoidal rule velocity Verlet integrates. Zero for
                // grain pairs (no wall velocity).
                e.boundary_work = 0.5 * (old_force + r.force).dot(wall_velocity) * dt;
                *g = ContactGeometry {
                    normal: kin.normal,
                    overlap: kin.overlap,
                    point: kin.point,
                };
                *f = ContactForce {
                    force: r.force,
                    torque_a: kin.branch_a.cross(r.force) + r.torque_a,
                    torque_b: kin.branch_b.cross(-r.force) + r.torque_b,
                };
                e.elastic = r.elastic_energy;
                // The integrator turns the old force with the old branch vectors and the
                // new force with the new ones; the law worked both over the mean.
                e.integration_error =
                    r.integration_error + 0.25 * (old_force - r.force).dot(branch_shift);
                e.dissipated = [0.0; MAX_DISSIPATION_CHANNELS];
                for (k, &id) in channel_ids.iter().enumerate() {
                    e.dissipated[id] = r.dissipated[k];
                }
            });
    }
}

/// What the force loop reads of a contact's bodies, each looked up once.
struct Bodies {
    kin: ContactKinematics,
    omega_a: DVec3,
    omega_b: DVec3,
    /// Velocity of the wall (zero for a grain pair).
    wall_velocity: DVec3,
}

#[inline]
fn bodies(snapshot: &GrainSnapshot, c: &Contact) -> Bodies {
    let i = snapshot
        .dense(c.a)
        .expect("a contact's grain is in the snapshot");
    match c.kind {
        ContactKind::GrainGrain => {
            let j = snapshot
                .dense(c.b)
                .expect("a contact's grain is in the snapshot");
            Bodies {
                kin: ContactKinematics::grain_grain(snapshot, i, j),
                omega_a: snapshot.omega[i],
                omega_b: snapshot.omega[j],
                wall_velocity: DVec3::ZERO,
            }
        }
        ContactKind::GrainWall => {
            let w = snapshot
                .walls
                .iter()
                .find(|w| w.entity == c.b)
                .expect("a contact's wall is in the snapshot");
            Bodies {
                kin: ContactKinematics::grain_wall(snapshot, i, w),
                omega_a: snapshot.omega[i],
                omega_b: DVec3::ZERO,
                wall_velocity: w.velocity,
            }
        }
    }
}

/// Kinematics of a contact from the snapshot.
#[inline]
pub fn kinematics(snapshot: &GrainSnapshot, c: &Contact) -> ContactKinematics {
    bodies(snapshot, c).kin
}

/// Scratch arrays of [`apply_contact_forces`], kept between steps to avoid allocation.
#[derive(Default)]
pub struct ForceAccumulators {
    force: Vec<DVec3>,
    torque: Vec<DVec3>,
    wall_force: Vec<DVec3>,
}

/// Sums contact forces and torques onto grains (overwriting last step's totals) and
/// walls, and contact energies into the ledger and the energy snapshot. Serial, in
/// query order, so the sums are bit-reproducible.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn apply_contact_forces(
    snapshot: Res<GrainSnapshot>,
    clock: Res<Clock>,
    channels: Res<DissipationChannels>,
    mut ledger: ResMut<EnergyLedger>,
    mut energy: ResMut<EnergySnapshot>,
    contacts: Query<(&Contact, &ContactGeometry, &ContactForce, &ContactEnergy)>,
    mut grains: Query<(Entity, &mut Force, &mut Torque), With<Grain>>,
    mut walls: Query<(Entity, &mut WallLoad)>,
    mut acc: Local<ForceAccumulators>,
) {
    let n = snapshot.len();
    acc.force.clear();
    acc.force.resize(n, DVec3::ZERO);
    acc.torque.clear();
    acc.torque.resize(n, DVec3::ZERO);
    acc.wall_force.clear();
    acc.wall_force.resize(snapshot.walls.len(), DVec3::ZERO);
    if ledger.dissipated.len() < channels.names.len() {
        ledger.dissipated.resize(channels.names.len(), 0.0);
    }
    let mut elastic = 0.0;
    let mut integration_error = 0.0;
    let mut count = 0usize;
    let mut worst = 0.0f64;
    let mut worst_pair = None;
    let mut wall_work = 0.0;
    let mut dissipated = [0.0; MAX_DISSIPATION_CHANNELS];
    for (c, g, f, e) in &contacts {
        let i = snapshot.dense(c.a).expect("contact grain in snapshot");
        acc.force[i] += f.force;
        acc.torque[i] += f.torque_a;
        let ratio = match c.kind {
            ContactKind::GrainGrain => {
                let j = snapshot.dense(c.b).expect("contact grain in snapshot");
                acc.force[j] -= f.force;
                acc.torque[j] += f.torque_b;
                g.overlap / snapshot.radius[i].min(snapshot.radius[j])
            }
            ContactKind::GrainWall => {
                if let Some(w) = snapshot.walls.iter().position(|w| w.entity == c.b) {
                    acc.wall_force[w] -= f.force;
                }
                wall_work += e.boundary_work;
                g.overlap / snapshot.radius[i]
            }
        };
        if ratio > worst {
            worst = ratio;
            worst_pair = Some((c.a, c.b));
        }
        elastic += e.elastic;
        integration_error += e.integration_error;
        for (total, d) in dissipated.iter_mut().zip(e.dissipated.iter()) {
            *total += d;
        }
        count += usize::from(f.is_active(g));
    }
    for (total, d) in ledger.dissipated.iter_mut().zip(dissipated.iter()) {
        *total += d;
    }
    let dt = clock.pass_dt;
    energy.dissipation_power.clear();
    energy.dissipation_power.extend(
        dissipated[..channels.names.len()]
            .iter()
            .map(|d| if dt > 0.0 { d / dt } else { 0.0 }),
    );
    ledger.wall_work += wall_work;
    ledger.integration_error += integration_error;
    energy.elastic = elastic;
    energy.contacts = count;
    energy.max_overlap_ratio = worst;
    energy.worst_overlap_pair = worst_pair;

    let mut k = 0;
    for (e, mut f, mut t) in grains.contiguous_iter_mut().expect("grain query is dense") {
        let f = f.bypass_change_detection();
        let t = t.bypass_change_detection();
        debug_assert_eq!(&snapshot.entity[k..k + e.len()], e);
        for m in 0..e.len() {
            f[m].0 = acc.force[k + m];
            t[m].0 = acc.torque[k + m];
        }
        k += e.len();
    }
    for (entity, mut load) in &mut walls {
        if let Some(w) = snapshot.walls.iter().position(|w| w.entity == entity) {
            load.0 = acc.wall_force[w];
        }
    }
}

/// The unbalanced-force ratio of the packing (Yade's `unbalancedForce`): the mean size
/// of the net force on the free grains (contacts and body forces, as summed in the
/// `Force` accumulators after [`Stage::BodyForces`]) over the mean size of the active
/// contact forces. It tends to 0 as a packing reaches static equilibrium; `None` when
/// there is no active contact or no free grain. Read it after a step, not inside one.
pub fn unbalanced_force_ratio(world: &mut World) -> Option<f64> {
    let mut grains = world.query_filtered::<&Force, (With<Grain>, Without<Frozen>)>();
    let (mut net, mut n) = (0.0, 0usize);
    for f in grains.iter(world) {
        net += f.0.length();
        n += 1;
    }
    let mut contacts = world.query::<(&ContactGeometry, &ContactForce)>();
    let (mut contact, mut m) = (0.0, 0usize);
    for (g, f) in contacts.iter(world) {
        if f.is_active(g) {
            contact += f.force.length();
            m += 1;
        }
    }
    (n > 0 && m > 0 && contact > 0.0).then(|| (net / n as f64) / (contact / m as f64))
}
