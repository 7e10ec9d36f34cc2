//! The contact-law extension API.
//!
//! Writing a law takes two parts:
//! * [`ContactLaw`]: the typed, per-contact force routine with its parameter and
//!   history types. The core runs it in parallel over the law's contacts.
//! * [`LawDescriptor`]: what a scene sees: the law's name, its declared parameters,
//!   validation, and installation (usually one call to [`install_law`]).

use std::any::Any;

use bevy_ecs::prelude::*;
use talus_core::energy::{DissipationChannels, MAX_DISSIPATION_CHANNELS};
use talus_core::lanes::{F4, V4};
use talus_core::schedule::{SimBuilder, Stage};
use talus_core::snapshot::prefetch_item;

use crate::components::*;
use crate::kinematics::{ContactKinematics, ContactKinematicsLanes};
use crate::params::{ParamError, ParamSpec, ParamValues};
use crate::systems::{ContactLawTable, LawSlot, evaluate_law};

/// What a law returns for one contact in one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactResponse {
    /// Force on body `a` acting at the contact point, N. The core adds the
    /// torques branch × force itself.
    pub force: glam::DVec3,
    /// Extra torque on `a` besides branch × force (rolling, twisting), N m.
    pub torque_a: glam::DVec3,
    /// Extra torque on `b` besides branch × force, N m.
    pub torque_b: glam::DVec3,
    /// Elastic energy stored in the contact after this step, J.
    pub elastic_energy: f64,
    /// Energy dissipated during this step, per entry of [`ContactLaw::dissipation`], J.
    pub dissipated: [f64; MAX_DISSIPATION_CHANNELS],
    /// Energy the time integration created at this contact during this step, J: the
    /// trapezoidal work of the law's conservative forces on the bodies (the rule the
    /// integrator applies) plus the change of their potential energy. Zero in exact
    /// arithmetic and continuous time; a law that leaves it at zero still closes the
    /// balance up to its own integration error.
    pub integration_error: f64,
}

/// What a law's lane form returns for four contacts ([`ContactLaw::evaluate_lanes`]): a
/// [`ContactResponse`] per lane.
#[derive(Clone, Copy, Debug)]
pub struct LaneResponse {
    /// Force on body `a` at the contact point, N.
    pub force: V4,
    /// Extra torque on `a` besides branch × force, N m.
    pub torque_a: V4,
    /// Extra torque on `b` besides branch × force, N m.
    pub torque_b: V4,
    /// Elastic energy stored after this step, J (only read when energies are booked).
    pub elastic_energy: F4,
    /// Energy dissipated during this step, per entry of [`ContactLaw::dissipation`], J
    /// (only read when energies are booked).
    pub dissipated: [F4; MAX_DISSIPATION_CHANNELS],
    /// Energy the time integration created at the contact during this step, J (only read
    /// when energies are booked).
    pub integration_error: F4,
}

impl Default for LaneResponse {
    fn default() -> Self {
        Self {
            force: V4::zero(),
            torque_a: V4::zero(),
            torque_b: V4::zero(),
            elastic_energy: F4::zero(),
            dissipated: [F4::zero(); MAX_DISSIPATION_CHANNELS],
            integration_error: F4::zero(),
        }
    }
}

/// A contact law's force routine.
pub trait ContactLaw: Send + Sync + 'static {
    /// Parameters resolved for one material pair (after mixing and validation).
    type Params: Clone + Send + Sync + 'static;
    /// Per-contact history, created with `Default` when the contact starts. Serializable
    /// so that a saved state keeps it (and, later, so that it can migrate with its grains).
    type History: Default
        + Clone
        + Send
        + Sync
        + serde::Serialize
        + serde::de::DeserializeOwned
        + 'static;
    /// Names of the dissipation mechanisms, indexing [`ContactResponse::dissipated`]
    /// (asked once, when the law is installed).
    fn dissipation() -> Vec<&'static str>;

    /// Computes the response of one contact and updates its history over a step `dt`
    /// (`dt` is 0 in the priming pass that evaluates the initial forces).
    fn evaluate(
        params: &Self::Params,
        kin: &ContactKinematics,
        history: &mut Self::History,
        dt: f64,
    ) -> ContactResponse;

    /// Whether the law has a lane form ([`Self::evaluate_lanes`]). Without one (the
    /// default) every contact goes through [`Self::evaluate`].
    const LANES: bool = false;

    /// Evaluates four grain–grain contacts at once, one per lane of `kin` (built by the
    /// core with [`ContactKinematicsLanes::grain_grain`] and
    /// [`ContactKinematicsLanes::set_displacement`]): an optional fast path, for the
    /// cases a law sees most (a contact that persists, say), written with the lane types
    /// of [`talus_core::lanes`].
    ///
    /// `lanes` has bit `k` set for each lane the law may evaluate. Returns the lanes it
    /// did evaluate (a subset of `lanes`) and their responses: it must have updated their
    /// history exactly as [`Self::evaluate`] would and give, lane by lane, the same bits
    /// in every field `evaluate` would (with `book` false, only the force and torques
    /// count). The lanes it leaves out must keep their history untouched: the core
    /// evaluates them with [`Self::evaluate`], in order. `book` says whether the energies
    /// are read ([`talus_core::energy::ContactEnergyBooking`]); a law may skip them when
    /// it is false. The default evaluates no lane.
    #[inline(always)]
    fn evaluate_lanes(
        params: [&Self::Params; 4],
        kin: &ContactKinematicsLanes,
        history: [&mut Self::History; 4],
        lanes: u32,
        dt: f64,
        book: bool,
    ) -> (u32, LaneResponse) {
        let _ = (params, kin, history, lanes, dt, book);
        (0, LaneResponse::default())
    }

    /// Names of the per-contact quantities the law exposes from its history (for example
    /// an elastic energy or a heat rate), in the order [`Self::contact_quantities`] writes
    /// them. None by default; a law that exposes none costs nothing: exporters read
    /// contact quantities only of laws that name some, and only when they record.
    fn contact_quantity_names() -> &'static [&'static str] {
        &[]
    }

    /// Writes one contact's quantities, one per entry of [`Self::contact_quantity_names`],
    /// into `out` (which has exactly that length), from its history after the last
    /// evaluation.
    fn contact_quantities(history: &Self::History, out: &mut [f64]) {
        let _ = (history, out);
    }
}

/// One installed law's per-contact quantities, type-erased for exporters
/// ([`ContactLaw::contact_quantity_names`]).
#[derive(Clone, Debug)]
pub struct ContactQuantitySource {
    /// Name of the law.
    pub law: &'static str,
    /// Names of the quantities, in the order of each contact's values.
    pub names: &'static [&'static str],
    /// Appends, for each active contact of the law ([`ContactForce::is_active`]), its
    /// entity to the first vector and its `names.len()` values to the second.
    pub collect: fn(&mut World, &mut Vec<Entity>, &mut Vec<f64>),
}

/// The laws of a scene that expose per-contact quantities; present only when at least one
/// installed law names some.
#[derive(Resource, Clone, Debug, Default)]
pub struct ContactQuantitySources(pub Vec<ContactQuantitySource>);

/// [`ContactQuantitySource::collect`] of law `L`.
fn collect_quantities<L: ContactLaw>(
    world: &mut World,
    entities: &mut Vec<Entity>,
    values: &mut Vec<f64>,
) {
    let n = L::contact_quantity_names().len();
    let mut query = world.query::<(
        Entity,
        &ContactGeometry,
        &ContactForce,
        &LawState<L::History>,
    )>();
    for (entity, geometry, force, history) in query.iter(world) {
        if !force.is_active(geometry) {
            continue;
        }
        entities.push(entity);
        let start = values.len();
        values.resize(start + n, 0.0);
        L::contact_quantities(&history.0, &mut values[start..]);
    }
}

/// One material pair assigned to a law by a scene.
#[derive(Clone, Debug)]
pub struct PairAssignment {
    /// Material ids (a ≤ b).
    pub materials: (u16, u16),
    /// Material names, for messages.
    pub names: (String, String),
    /// Parameters after mixing, overrides and defaults.
    pub values: ParamValues,
    /// Smallest reduced mass among the pairs of grains (and walls) with these materials, kg.
    pub min_effective_mass: f64,
    /// Smallest reduced radius among those pairs, m.
    pub min_effective_radius: f64,
    /// Dimension of the scene: 2 (disks in the xy-plane) or 3 (spheres).
    pub dimension: talus_core::resources::Dimension,
    /// Each material's own parameters (defaults filled in) before mixing, when the pair's
    /// law comes from its materials: a law whose pair parameter is not a per-field mix
    /// (Hertz: 1/E* = (1 − ν_a²)/E_a + (1 − ν_b²)/E_b) computes it from these. `None`
    /// when a `pairs` entry sets the pair's parameters directly.
    pub material_values: Option<(ParamValues, ParamValues)>,
}

/// Time scales of a law for one pair: what the automatic time step is made from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeScale {
    /// Duration of a binary collision for the lightest pair, s.
    pub contact_time: f64,
    /// Largest step for which the integration of that contact is stable, s.
    pub stability_limit: f64,
}

/// What a scene sees of a law.
pub trait LawDescriptor: Send + Sync {
    /// The name scenes use.
    fn name(&self) -> &'static str;
    /// One line for `talus check` and the docs.
    fn summary(&self) -> &'static str;
    /// Declared parameters.
    fn params(&self) -> &[ParamSpec];
    /// The law's parts by kind and name, for `talus check` (empty for a law written whole).
    fn parts(&self) -> Vec<(crate::compose::SubModelKind, &'static str)> {
        Vec::new()
    }
    /// Name of the rolling-resistance part a scene selects with `rolling:`, if any.
    fn rolling(&self) -> Option<&'static str> {
        None
    }
    /// Name of the twisting-resistance part a scene selects with `twisting:`, if any.
    fn twisting(&self) -> Option<&'static str> {
        None
    }
    /// Gap up to which the law acts beyond touch, m (0: only while bodies overlap).
    fn interaction_range(&self, values: &ParamValues) -> f64 {
        let _ = values;
        0.0
    }
    /// Cross-field checks on a full parameter set (ranges are already checked).
    fn validate(&self, values: &ParamValues) -> Result<(), ParamError>;
    /// Whether the law can torque a grain with these parameters (so rotation is needed).
    fn produces_torque(&self, values: &ParamValues) -> bool;
    /// Resolves the typed parameters of one pair and its time scales.
    fn resolve(
        &self,
        pair: &PairAssignment,
    ) -> Result<(Box<dyn Any + Send + Sync>, TimeScale), ParamError>;
    /// Installs the law for the given pairs, with the typed parameters from [`Self::resolve`].
    fn install(&self, sim: &mut SimBuilder, pairs: &[(PairAssignment, Box<dyn Any + Send + Sync>)]);
}

/// The typed per-pair parameter table of a law.
#[derive(Resource)]
pub struct PairParams<L: ContactLaw>(pub Vec<L::Params>);

/// Global dissipation channel ids of a law's mechanisms (and the narrow phase's kept query
/// of the law's contacts).
#[derive(Resource)]
pub struct LawChannels<L: ContactLaw> {
    /// Global channel id of each entry of [`ContactLaw::dissipation`].
    pub ids: Vec<usize>,
    /// The state of the narrow phase's query of the law's contact rows
    /// ([`recycle_contacts`]), kept between steps (taken out while it runs, since it needs
    /// the world mutably). Kept here because this resource exists anyway: a resource of
    /// its own would be one more entity of the world, which shifts the ids of the grains
    /// spawned after it, and a pair's orientation (which grain is the contact's first
    /// body) follows the grains' entity order.
    recycle_query: std::sync::Mutex<Option<bevy_ecs::query::QueryState<RecycleColumns<L>>>>,
    _law: std::marker::PhantomData<fn() -> L>,
}

fn spawn_contact<L: ContactLaw>(
    world: &mut World,
    contact: Contact,
    bodies: ContactBodies,
) -> Entity {
    world
        .spawn((
            contact,
            ContactGeometry::default(),
            ContactForce::default(),
            bodies,
            LawState::<L::History>(L::History::default()),
        ))
        .id()
}

/// Hands ended contacts of law `L` (entities of its five-component archetype) to new
/// pairs: each is left exactly as [`spawn_contact`] would have made it for its new pair.
///
/// The rows are written through the table's columns, found once, not looked up contact by
/// contact: a query's `get_mut` finds the entity's archetype and each of five columns
/// again for every contact (on the 32,000-grain chute, 105–165 ns a contact against
/// 80–100 this way). The rows are the caller's, checked against the table's entities. No
/// system reads the contacts' change ticks, so they are left alone, as the table sort
/// leaves them.
///
/// Each thread writes the rows of its share of the table (the columns split into one
/// contiguous range per thread, each job reading the whole list and taking the rows in its
/// range): the rows are few and far apart, each write waits on memory, and the narrow
/// phase's other threads would wait for a serial loop. What a row receives does not depend
/// on which thread writes it.
///
/// The query's state is kept between calls ([`LawChannels::recycle_query`]): made anew, it
/// matched every archetype of the world (each resource is an entity), 6–11 µs of serial
/// work a step on the 32,000-grain chute.
fn recycle_contacts<L: ContactLaw>(
    world: &mut World,
    reuses: &[(Entity, usize, Contact, ContactBodies)],
) {
    use rayon::prelude::*;
    let kept = world
        .get_resource::<LawChannels<L>>()
        .and_then(|law| law.recycle_query.lock().ok()?.take());
    let mut contacts = kept.unwrap_or_else(|| world.query());
    let mut recycled = 0;
    for (entities, mut contact, mut geometry, mut force, mut bodies, mut history) in contacts
        .query_mut(&mut *world)
        .contiguous_iter_mut()
        .expect("contact query is dense")
    {
        let share = entities.len().div_ceil(rayon::current_num_threads()).max(1);
        recycled += entities
            .par_chunks(share)
            .zip(contact.bypass_change_detection().par_chunks_mut(share))
            .zip(geometry.bypass_change_detection().par_chunks_mut(share))
            .zip(force.bypass_change_detection().par_chunks_mut(share))
            .zip(bodies.bypass_change_detection().par_chunks_mut(share))
            .zip(history.bypass_change_detection().par_chunks_mut(share))
            .enumerate()
            .map(
                |(k, (((((entities, contact), geometry), force), bodies), history))| {
                    let first = k * share;
                    let columns = (entities, contact, geometry, force, bodies, history);
                    recycle_rows::<L>(reuses, first, columns)
                },
            )
            .sum::<usize>();
    }
    if let Some(law) = world.get_resource::<LawChannels<L>>()
        && let Ok(mut slot) = law.recycle_query.lock()
    {
        *slot = Some(contacts);
    }
    assert_eq!(
        recycled,
        reuses.len(),
        "the narrow phase recycles only contacts of the law's archetype"
    );
}

/// The columns [`recycle_contacts`] writes, as a query.
type RecycleColumns<L> = (
    Entity,
    &'static mut Contact,
    &'static mut ContactGeometry,
    &'static mut ContactForce,
    &'static mut ContactBodies,
    &'static mut LawState<<L as ContactLaw>::History>,
);

/// The columns of a range of a law's table rows, for [`recycle_rows`].
type RecycledRows<'a, H> = (
    &'a [Entity],
    &'a mut [Contact],
    &'a mut [ContactGeometry],
    &'a mut [ContactForce],
    &'a mut [ContactBodies],
    &'a mut [LawState<H>],
);

/// Writes the reuses of [`recycle_contacts`] whose rows fall in the range of table rows
/// from `first` whose columns are given; returns how many it wrote.
fn recycle_rows<L: ContactLaw>(
    reuses: &[(Entity, usize, Contact, ContactBodies)],
    first: usize,
    (entities, contact, geometry, force, bodies, history): RecycledRows<'_, L::History>,
) -> usize {
    let len = entities.len();
    let in_range =
        move |&(entity, row, pair, pair_bodies): &(Entity, usize, Contact, ContactBodies)| {
            let local = row.wrapping_sub(first);
            (local < len).then_some((entity, local, pair, pair_bodies))
        };
    let mut recycled = 0;
    // The rows are few and far apart: ask for those of a few contacts ahead.
    let mut ahead = reuses.iter().filter_map(in_range).skip(RECYCLE_AHEAD);
    for (entity, row, pair, pair_bodies) in reuses.iter().filter_map(in_range) {
        if let Some((_, ahead, _, _)) = ahead.next() {
            prefetch_item(entities, ahead);
            prefetch_item(contact, ahead);
            prefetch_item(geometry, ahead);
            prefetch_item(force, ahead);
            prefetch_item(bodies, ahead);
            prefetch_item(history, ahead);
        }
        if entities[row] != entity {
            continue;
        }
        contact[row] = pair;
        geometry[row] = ContactGeometry::default();
        force[row] = ContactForce::default();
        bodies[row] = pair_bodies;
        history[row].0 = L::History::default();
        recycled += 1;
    }
    recycled
}

/// How many contacts ahead [`recycle_contacts`] asks for the rows it will write.
const RECYCLE_AHEAD: usize = 4;

/// Re-creates a saved contact of law `L`: its geometry and force of the last evaluation
/// (which the next step reads) and its history parsed from RON text.
fn restore_contact<L: ContactLaw>(
    world: &mut World,
    contact: Contact,
    geometry: ContactGeometry,
    force: ContactForce,
    history: &str,
) -> Result<Entity, String> {
    let history: L::History = ron::from_str(history).map_err(|e| e.to_string())?;
    Ok(world
        .spawn((
            contact,
            geometry,
            force,
            ContactBodies::default(),
            LawState::<L::History>(history),
        ))
        .id())
}

/// Installs a law for the given pairs: registers its dissipation channels, its
/// parameter table, its contact spawner for each pair, and its force system.
/// Requires [`crate::ContactPlugin`] to have been added.
pub fn install_law<L: ContactLaw>(
    sim: &mut SimBuilder,
    name: &'static str,
    pairs: &[(PairAssignment, Box<dyn Any + Send + Sync>)],
) {
    let ids: Vec<usize> = {
        let mut channels = sim.world.resource_mut::<DissipationChannels>();
        L::dissipation()
            .iter()
            .map(|c| channels.register(c))
            .collect()
    };
    assert!(
        ids.iter().all(|&i| i < MAX_DISSIPATION_CHANNELS),
        "a scene may use at most {MAX_DISSIPATION_CHANNELS} dissipation mechanisms"
    );
    // A law whose history does not survive postcard's encoding (serde attributes that need
    // a self-describing format) would lose its contacts from every binary state: a fault
    // of the law, told at once rather than at the first report.
    let probe = postcard::to_allocvec(&L::History::default())
        .map_err(|e| e.to_string())
        .and_then(|bytes| postcard::from_bytes::<L::History>(&bytes).map_err(|e| e.to_string()));
    assert!(
        probe.is_ok(),
        "law `{name}`: its history does not round-trip through postcard ({}); see docs/writing-a-contact-law.md §3.2",
        probe.err().unwrap_or_default()
    );
    // Create this law's contact archetype now, so that contacts are iterated (and their
    // forces summed) law by law in installation order, whichever law's contact came
    // first: a run restored from a saved state then sums in the same order. Its id tells
    // the narrow phase which ended contacts a new pair of this law may reuse.
    let archetype = if pairs.is_empty() {
        bevy_ecs::archetype::ArchetypeId::EMPTY
    } else {
        let probe = spawn_contact::<L>(
            &mut sim.world,
            Contact {
                a: Entity::PLACEHOLDER,
                b: Entity::PLACEHOLDER,
                kind: ContactKind::GrainGrain,
                pair_slot: 0,
            },
            ContactBodies::default(),
        );
        let archetype = sim.world.entity(probe).location().archetype_id;
        sim.world.despawn(probe);
        archetype
    };
    let mut table = Vec::with_capacity(pairs.len());
    for (slot, (pair, params)) in pairs.iter().enumerate() {
        let params = params
            .downcast_ref::<L::Params>()
            .expect("resolve() returns this law's parameter type")
            .clone();
        table.push(params);
        let n = sim
            .world
            .resource::<talus_core::resources::Materials>()
            .len();
        let (a, b) = pair.materials;
        let mut law_table = sim.world.resource_mut::<ContactLawTable>();
        if law_table.slots.len() < n * n {
            law_table.slots.resize(n * n, None);
        }
        let entry = Some(LawSlot {
            law: name,
            pair_slot: slot as u32,
            spawn: spawn_contact::<L>,
            archetype,
            recycle: recycle_contacts::<L>,
            law_type: std::any::type_name::<L>(),
            history_bytes: contact_history_bytes::<L>,
            history_text: contact_history_text::<L>,
            restore: restore_contact::<L>,
        });
        law_table.slots[a as usize * n + b as usize] = entry.clone();
        law_table.slots[b as usize * n + a as usize] = entry;
    }
    if !pairs.is_empty() {
        let law_type = std::any::type_name::<L>();
        let mut sorts = sim.world.resource_mut::<crate::order::ContactTableSorts>();
        if !sorts.0.iter().any(|&(t, _)| t == law_type) {
            sorts
                .0
                .push((law_type, crate::order::sort_law_contacts::<L>));
        }
    }
    sim.world.insert_resource(PairParams::<L>(table));
    sim.world.insert_resource(LawChannels::<L> {
        ids,
        recycle_query: std::sync::Mutex::new(None),
        _law: std::marker::PhantomData,
    });
    sim.add_system(
        Stage::ContactForces,
        format!("law:{name}"),
        evaluate_law::<L>,
    );
    if !pairs.is_empty() && !L::contact_quantity_names().is_empty() {
        let mut sources = sim
            .world
            .get_resource_or_insert_with(ContactQuantitySources::default);
        if !sources.0.iter().any(|s| s.law == name) {
            sources.0.push(ContactQuantitySource {
                law: name,
                names: L::contact_quantity_names(),
                collect: collect_quantities::<L>,
            });
        }
    }
}

/// The laws a program knows, by name and by the rolling and twisting parts a scene may add.
#[derive(Default)]
pub struct LawRegistry {
    laws: Vec<Box<dyn LawDescriptor>>,
}

impl LawRegistry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers a law. A law of the same name and parts replaces the earlier one.
    pub fn register(&mut self, law: Box<dyn LawDescriptor>) -> &mut Self {
        self.laws.retain(|l| {
            (l.name(), l.rolling(), l.twisting()) != (law.name(), law.rolling(), law.twisting())
        });
        self.laws.push(law);
        self
    }

    /// Looks a law up by name, without rolling or twisting part.
    pub fn get(&self, name: &str) -> Option<&dyn LawDescriptor> {
        self.get_with(name, None, None)
    }

    /// Looks a law up by name and its optional rolling and twisting parts.
    pub fn get_with(
        &self,
        name: &str,
        rolling: Option<&str>,
        twisting: Option<&str>,
    ) -> Option<&dyn LawDescriptor> {
        self.laws
            .iter()
            .find(|l| l.name() == name && l.rolling() == rolling && l.twisting() == twisting)
            .map(|b| b.as_ref())
    }

    /// Whether any law of this name is registered (with any parts).
    pub fn has(&self, name: &str) -> bool {
        self.laws.iter().any(|l| l.name() == name)
    }

    /// The rolling (or, with `twisting`, twisting) parts registered for a law.
    pub fn part_choices(&self, name: &str, twisting: bool) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = Vec::new();
        for l in self.laws.iter().filter(|l| l.name() == name) {
            let part = if twisting { l.twisting() } else { l.rolling() };
            if let Some(p) = part
                && !out.contains(&p)
            {
                out.push(p);
            }
        }
        out
    }

    /// Names of all registered laws, each once, in registration order.
    pub fn names(&self) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = Vec::new();
        for l in &self.laws {
            if !out.contains(&l.name()) {
                out.push(l.name());
            }
        }
        out
    }
}

/// Appends the binary (postcard) encoding of the history of a contact of law `L` to
/// `out`, for a binary state (the run's last good state on disk); `Ok(false)` if the
/// contact has no history of this law, an error if the history cannot be encoded.
fn contact_history_bytes<L: ContactLaw>(
    world: &World,
    contact: Entity,
    out: &mut Vec<u8>,
) -> Result<bool, String> {
    let Some(state) = world.get::<LawState<L::History>>(contact) else {
        return Ok(false);
    };
    *out = postcard::to_extend(&state.0, std::mem::take(out)).map_err(|e| {
        format!(
            "the history of a contact of {} cannot be encoded: {e}",
            std::any::type_name::<L>()
        )
    })?;
    Ok(true)
}

/// A history encoded by [`contact_history_bytes`] as RON text, for a saved state file.
fn contact_history_text<L: ContactLaw>(bytes: &[u8]) -> Option<String> {
    let history: L::History = postcard::from_bytes(bytes).ok()?;
    ron::to_string(&history).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A law whose history is a number that only a new contact has at zero.
    struct Counting;

    impl ContactLaw for Counting {
        type Params = ();
        type History = u64;
        fn dissipation() -> Vec<&'static str> {
            Vec::new()
        }
        fn evaluate(_: &(), _: &ContactKinematics, history: &mut u64, _: f64) -> ContactResponse {
            *history += 1;
            ContactResponse::default()
        }
    }

    /// Every component of a contact, for comparison.
    fn components(
        world: &World,
        e: Entity,
    ) -> (Contact, ContactGeometry, ContactForce, ContactBodies, u64) {
        (
            *world.get::<Contact>(e).unwrap(),
            *world.get::<ContactGeometry>(e).unwrap(),
            *world.get::<ContactForce>(e).unwrap(),
            *world.get::<ContactBodies>(e).unwrap(),
            world.get::<LawState<u64>>(e).unwrap().0,
        )
    }

    #[test]
    fn a_recycled_contact_is_what_a_spawn_would_make() {
        let mut world = World::new();
        let grains: Vec<Entity> = (0..4).map(|_| world.spawn_empty().id()).collect();
        let pair = |a: usize, b: usize, pair_slot| Contact {
            a: grains[a],
            b: grains[b],
            kind: ContactKind::GrainGrain,
            pair_slot,
        };
        let bodies = ContactBodies {
            a: 2,
            b: 3,
            layout: 7,
        };
        let old = spawn_contact::<Counting>(&mut world, pair(0, 1, 3), ContactBodies::default());
        // A contact that has lived: every component away from a new contact's.
        let mut e = world.entity_mut(old);
        *e.get_mut::<ContactGeometry>().unwrap() = ContactGeometry {
            normal: DVec3::X,
            overlap: -1e-9,
        };
        *e.get_mut::<ContactForce>().unwrap() = ContactForce {
            force: DVec3::Y,
            torque_a: DVec3::Z,
            torque_b: DVec3::NEG_Z,
        };
        *e.get_mut::<ContactBodies>().unwrap() = ContactBodies {
            a: 0,
            b: 1,
            layout: 5,
        };
        e.get_mut::<LawState<u64>>().unwrap().0 = 41;

        let row = world.entity(old).location().table_row.index();
        recycle_contacts::<Counting>(&mut world, &[(old, row, pair(2, 3, 1), bodies)]);
        let spawned = spawn_contact::<Counting>(&mut world, pair(2, 3, 1), bodies);
        assert_eq!(components(&world, old), components(&world, spawned));
        assert_eq!(world.get::<Contact>(old).unwrap().a, grains[2]);
    }
}
