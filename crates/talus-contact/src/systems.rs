//! Contact systems: the generic per-law force loop, and the summation of contact
//! forces, torques and energies onto grains, walls and the energy ledger.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;
use talus_core::prelude::*;

use crate::components::*;
use crate::kinematics::{ContactKinematics, ContactKinematicsLanes};
use crate::law::{ContactLaw, LawChannels, PairParams};
use crate::regions::{RegionRuns, RowRun};
use talus_core::lanes::{F4, V4};
use talus_core::regions::GrainRegions;
use talus_core::snapshot::{prefetch_address, prefetch_item};

/// Contacts per chunk of the force loop: each chunk is evaluated on one thread and sums
/// its contacts' energies into one [`ContactEnergySums`]. Fixed, not derived from the
/// thread count, so that the energy sums are the same on any number of threads. Small
/// enough that a flowing packing of 32,000 grains (about 16,000 contacts) has some
/// sixty chunks to share out: with 1,024 the threads' shares differed by up to a chunk
/// in seventeen, and the second thread waited for the first.
pub const ENERGY_CHUNK_LEN: usize = 256;

/// Most force-loop chunks one parallel job takes: rayon otherwise stops splitting at
/// about four jobs per thread, too coarse to even out chunks of unequal cost.
const FORCE_CHUNKS_PER_JOB: usize = 1;

/// Gives ended contacts of one law to new pairs ([`LawSlot::recycle`]): each listed entity
/// (with its row in its table, as the caller found it) is overwritten with what a spawn
/// would give its new pair (with the pair's bodies).
pub type RecycleContacts = fn(&mut World, &[(Entity, usize, Contact, ContactBodies)]);

/// Present: stages of a step run region by region ([`talus_core::regions`], regions of
/// `region_grains` grains), as the wave front through the packing will
/// (`docs/architecture.md` §11), each with the results of its whole-stage form:
/// - the force loops of steps whose energies are not booked ([`ContactEnergyBooking`])
///   evaluate each law's contacts region by region (each region's rows listed by
///   [`RegionRuns`]) instead of in table order. Each contact's results are the same bits
///   either way (a contact's evaluation reads nothing another writes); only the order in
///   which the contacts' counts are added changes, and which of two pairs with exactly the
///   same worst overlap is named;
/// - the force sums set each region's grains' totals from the rows that touch them
///   ([`RegionRuns::touching_runs_descending`]) instead of from every row: each grain
///   receives the same forces in the same order, so its totals are the same bits.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct RegionStages {
    /// Grains per region ([`talus_core::regions::REGION_GRAINS`] is the size the stages
    /// are measured with).
    pub region_grains: usize,
}

/// Whether the force loops use the laws' lane forms ([`ContactLaw::evaluate_lanes`])
/// where a law has one: on unless this resource says otherwise. The results are the same
/// bit for bit either way (a lane form must give its scalar form's bits); off, every
/// contact goes through [`ContactLaw::evaluate`], for comparisons and tests.
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaneForms(pub bool);

/// How a new contact between two materials is created: by the law assigned to the pair.
#[derive(Clone, Debug)]
pub struct LawSlot {
    /// Name of the law.
    pub law: &'static str,
    /// Index into the law's [`PairParams`].
    pub pair_slot: u32,
    /// Spawns a contact entity with the law's history component, and its bodies' places
    /// in the snapshot (so that its first evaluation can go through the law's lane form).
    pub spawn: fn(&mut World, Contact, ContactBodies) -> Entity,
    /// The archetype of this law's contacts (the five components [`Self::spawn`] gives,
    /// nothing else): a contact that ended in it may be handed to a new pair of the law by
    /// [`Self::recycle`].
    pub archetype: bevy_ecs::archetype::ArchetypeId,
    /// Gives each listed entity, a contact of [`Self::archetype`] that has ended, to a new
    /// pair: its components are overwritten with what [`Self::spawn`] would give that pair.
    /// Cheaper than a despawn and a spawn, and the table keeps its length.
    pub recycle: RecycleContacts,
    /// The law's Rust type name: a saved contact is restored only into the same law.
    pub law_type: &'static str,
    /// Appends the binary encoding of one of this law's contacts' history to the buffer
    /// (binary states); false if the contact has no history of this law.
    /// An error if the history cannot be encoded (its serde attributes need a
    /// self-describing format: docs/writing-a-contact-law.md §3.2).
    pub history_bytes: fn(&World, Entity, &mut Vec<u8>) -> Result<bool, String>,
    /// A history encoded by [`Self::history_bytes`] as RON text (saved state files);
    /// `None` if the bytes are not one of this law's histories.
    pub history_text: fn(&[u8]) -> Option<String>,
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

    /// The law slot of a material pair with its index in [`Self::slots`], where a list
    /// of pairs can keep it as a number.
    #[inline]
    pub fn slot_of(&self, a: u16, b: u16) -> Option<(u32, &LawSlot)> {
        let index = a as usize * self.n_materials + b as usize;
        let slot = self.slots.get(index)?.as_ref()?;
        Some((index as u32, slot))
    }

    /// The slot of the law whose contacts make up `archetype` (any of its material pairs:
    /// they share the law's spawn, recycling and history functions).
    pub fn by_archetype(&self, archetype: bevy_ecs::archetype::ArchetypeId) -> Option<&LawSlot> {
        self.slots
            .iter()
            .flatten()
            .find(|slot| slot.archetype == archetype)
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
        sim.world.insert_resource(ContactEnergyPartials::default());
        sim.world.insert_resource(ChunkGrainMasks::default());
        sim.world.insert_resource(IdleContacts::default());
        sim.world
            .insert_resource(crate::order::ContactTableSorts::default());
        sim.add_system(
            Stage::ApplyContactForces,
            "apply_contact_forces",
            apply_contact_forces,
        );
        // The sums write the totals, the frozen grains' only where a step's end is looked
        // at (`FrozenTotals`); synchronizing sums what a step left.
        sim.declare_frozen_totals_unread(&apply_contact_forces);
        sim.on_synchronize(sum_left_frozen_totals);
        sim.gravity_in_force_sums();
    }
}

/// Evaluates law `L` on all of its contacts in parallel, writing geometry, force and
/// torques into each contact entity, and appending the contacts' energies, summed per
/// chunk of [`ENERGY_CHUNK_LEN`] contacts in table order, to [`ContactEnergyPartials`].
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
pub fn evaluate_law<L: ContactLaw>(
    snapshot: Res<GrainSnapshot>,
    clock: Res<Clock>,
    params: Res<PairParams<L>>,
    channels: Res<LawChannels<L>>,
    booking: Option<Res<ContactEnergyBooking>>,
    lane_forms: Option<Res<LaneForms>>,
    region_loop: Option<Res<RegionStages>>,
    mut partials: ResMut<ContactEnergyPartials>,
    mut idle: ResMut<IdleContacts>,
    mut grain_masks: ResMut<ChunkGrainMasks>,
    mut region_runs: Local<RegionRuns>,
    mut outcomes: Local<Vec<ChunkOutcome>>,
    mut contacts: Query<(
        &Contact,
        &mut LawState<L::History>,
        &mut ContactGeometry,
        &mut ContactForce,
        &mut ContactBodies,
    )>,
) {
    let dt = clock.pass_dt;
    let snapshot = &*snapshot;
    let params = &params.0;
    let channel_ids = &channels.ids;
    let book = booking.is_none_or(|b| b.0);
    // `book` is a constant in each copy of the force loop ([`evaluate_chunk`]): without
    // it the compiler drops the law's energy terms, which feed nothing else.
    let evaluate = |c: &Contact,
                    h: &mut LawState<L::History>,
                    g: &mut ContactGeometry,
                    f: &mut ContactForce,
                    indices: &mut ContactBodies,
                    sums: &mut ContactEnergySums,
                    book: bool| {
        if c.is_vacant() {
            // A row kept for a new contact: nothing acts. Its bodies follow the grains'
            // order, which places it in its grain's region at the next sort.
            if indices.layout != snapshot.layout
                && let Some(fresh) = ContactBodies::look_up(snapshot, c)
            {
                *indices = fresh;
            }
            sums.vacant += 1;
            return;
        }
        let Bodies {
            mut kin,
            omega_a,
            omega_b,
            wall_velocity,
            indices: dense,
        } = bodies(snapshot, c, *indices);
        *indices = dense;
        let branch_shift = kin.set_displacement(g.normal, g.overlap, omega_a, omega_b, dt);
        let old_force = f.force;
        let r = L::evaluate(&params[c.pair_slot as usize], &kin, &mut h.0, dt);
        if book && c.kind == ContactKind::GrainWall {
            // The old force acted over the first half of the step, the new one acts over
            // the second: the trapezoidal rule velocity Verlet integrates.
            sums.boundary_work += 0.5 * (old_force + r.force).dot(wall_velocity) * dt;
        }
        *g = ContactGeometry {
            normal: kin.normal,
            overlap: kin.overlap,
        };
        *f = ContactForce {
            force: r.force,
            torque_a: kin.branch_a.cross(r.force) + r.torque_a,
            torque_b: kin.branch_b.cross(-r.force) + r.torque_b,
        };
        sums.active += usize::from(f.is_active(g));
        // Divide only for an overlap that may be the worst so far (a division per contact
        // is a tenth of the loop's latency). `>=`, not `>`: whenever the ratio exceeds the
        // worst, the rounded product cannot exceed the overlap, so no candidate is missed.
        if kin.overlap >= sums.worst_overlap.0 * kin.min_radius {
            let ratio = kin.overlap / kin.min_radius;
            if ratio > sums.worst_overlap.0 {
                sums.worst_overlap = (ratio, Some((c.a, c.b)));
            }
        }
        if !book {
            return;
        }
        sums.elastic += r.elastic_energy;
        // The integrator turns the old force with the old branch vectors and the new force
        // with the new ones; the law worked both over the mean.
        sums.integration_error +=
            r.integration_error + 0.25 * (old_force - r.force).dot(branch_shift);
        // By the law's own channel: a fixed-length add the compiler keeps in registers
        // (indexed by the channels' global ids, each contact's sums went through memory
        // at run-time addresses). Mapped to the global ids once per chunk.
        for (total, d) in sums.dissipated.iter_mut().zip(r.dissipated) {
            *total += d;
        }
    };
    let to_global = |local: ContactEnergySums| {
        let mut global = ContactEnergySums {
            dissipated: [0.0; MAX_DISSIPATION_CHANNELS],
            ..local
        };
        for (k, &id) in channel_ids.iter().enumerate() {
            global.dissipated[id] += local.dissipated[k];
        }
        global
    };
    // The lane form serves grain pairs in a box without a sheared seam (whose image
    // velocity only the scalar kinematics handle).
    let use_lanes = L::LANES && lane_forms.is_none_or(|on| on.0) && !snapshot.is_sheared();
    let lanes = use_lanes.then(|| LaneForm::<L> {
        snapshot,
        grains: snapshot.reader(),
        image: snapshot.image_lanes(),
        params,
        dt,
    });
    let lanes = lanes.as_ref();
    let partials = &mut partials.chunks;
    let idle = &mut *idle;
    idle.layout = snapshot.layout;
    idle.evaluated = true;
    // Kept from step to step for its allocation: a 512,000-grain chute's list of some
    // 1,000 chunks, made afresh, came from new pages of memory at every step.
    let outcomes = &mut *outcomes;
    let by_region = region_loop.filter(|_| !book);
    let regions = by_region.map(|on| GrainRegions::new(snapshot.len(), on.region_grains));
    // Only the force sums of two or more threads read the chunks' masks (`ChunkGrainMasks`).
    let mask_shift =
        (rayon::current_num_threads() > 1).then(|| ChunkGrainMasks::shift(snapshot.len()));
    for (c, mut h, mut g, mut f, mut d) in contacts
        .contiguous_iter_mut()
        .expect("contact query is dense")
    {
        let h = h.bypass_change_detection();
        let g = g.bypass_change_detection();
        let f = f.bypass_change_detection();
        let d = d.bypass_change_detection();
        // An indexed parallel iterator extends the list in chunk order.
        outcomes.clear();
        if let Some(regions) = &regions {
            region_runs.build(regions, snapshot, c, d, &[]);
            let batches = region_runs.make_batches(ENERGY_CHUNK_LEN);
            let columns = TableColumns::new(c, h, g, f, d);
            let (columns, runs) = (&columns, &*region_runs);
            outcomes.par_extend(
                (0..batches)
                    .into_par_iter()
                    .with_max_len(FORCE_CHUNKS_PER_JOB)
                    .map(|k| {
                        let (sums, idle) = evaluate_runs::<L, _>(
                            &evaluate,
                            lanes,
                            snapshot,
                            columns,
                            runs.batch(k),
                        );
                        (to_global(sums), idle, 0)
                    }),
            );
        } else {
            outcomes.par_extend(
                c.par_chunks(ENERGY_CHUNK_LEN)
                    .zip(h.par_chunks_mut(ENERGY_CHUNK_LEN))
                    .zip(g.par_chunks_mut(ENERGY_CHUNK_LEN))
                    .zip(f.par_chunks_mut(ENERGY_CHUNK_LEN))
                    .zip(d.par_chunks_mut(ENERGY_CHUNK_LEN))
                    .with_max_len(FORCE_CHUNKS_PER_JOB)
                    .map(|((((c, h), g), f), d)| {
                        let (sums, idle) = if book {
                            evaluate_chunk::<L, _, true>(
                                &evaluate, lanes, snapshot, c, h, g, f, &mut *d,
                            )
                        } else {
                            evaluate_chunk::<L, _, false>(
                                &evaluate, lanes, snapshot, c, h, g, f, &mut *d,
                            )
                        };
                        // The bodies as the sums will read them (the loop refreshed them).
                        let mask = mask_shift.map_or(0, |shift| ChunkGrainMasks::of_rows(d, shift));
                        (to_global(sums), idle, mask)
                    }),
            );
            if mask_shift.is_some() {
                grain_masks.record(d, outcomes.iter().map(|o| o.2));
            }
        }
        for (sums, pairs, _) in outcomes.drain(..) {
            partials.push(sums);
            idle.pairs.extend(pairs);
        }
    }
}

/// What the force loop returns for one chunk of a law's contacts: their energies, the pairs
/// of those that carried no force ([`IdleContacts`]) and the grains' mask of the chunk
/// ([`ChunkGrainMasks`]; 0 where the sums do not read it).
type ChunkOutcome = (ContactEnergySums, Vec<[u32; 2]>, u64);

/// The force loop over one chunk of a law's contacts, their energies summed (the
/// dissipation by the law's own channel, not yet by global id). Not
/// inlined, so that profiles show the force loop of each law under its own name.
/// `BOOK`: whether the contacts' energies are summed ([`ContactEnergyBooking`]). With
/// `lanes` (a law with a lane form), contacts go four at a time through
/// [`evaluate_four`]; the rest, and the lanes the law declines, through `evaluate`.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn evaluate_chunk<L: ContactLaw, F: ScalarEvaluation<L::History>, const BOOK: bool>(
    evaluate: &F,
    lanes: Option<&LaneForm<L>>,
    snapshot: &GrainSnapshot,
    c: &[Contact],
    h: &mut [LawState<L::History>],
    g: &mut [ContactGeometry],
    f: &mut [ContactForce],
    d: &mut [ContactBodies],
) -> (ContactEnergySums, Vec<[u32; 2]>) {
    let mut sums = ContactEnergySums::default();
    let n = c.len();
    let (h, g, f, d) = (&mut h[..n], &mut g[..n], &mut f[..n], &mut d[..n]);
    // The partners' state is read in no order the hardware can predict: ask for the
    // grains of the contacts a few rows ahead while these are evaluated.
    let prefetch = |d: &[ContactBodies], k: usize| {
        if let Some(ahead) = d.get(k)
            && ahead.layout == snapshot.layout
        {
            snapshot.prefetch(ahead.a as usize);
            snapshot.prefetch(ahead.b as usize);
        }
    };
    let mut k = 0;
    if let Some(form) = lanes {
        while k + 4 <= n {
            for ahead in k + LANE_PREFETCH_AHEAD..k + LANE_PREFETCH_AHEAD + 4 {
                prefetch(d, ahead);
            }
            let r = k..k + 4;
            evaluate_four::<L, F, BOOK>(
                evaluate,
                form,
                (&c[r.clone()]).try_into().expect("four contacts"),
                (&mut h[r.clone()]).try_into().expect("four contacts"),
                (&mut g[r.clone()]).try_into().expect("four contacts"),
                (&mut f[r.clone()]).try_into().expect("four contacts"),
                (&mut d[r]).try_into().expect("four contacts"),
                &mut sums,
            );
            k += 4;
        }
    }
    for k in k..n {
        prefetch(d, k + PREFETCH_AHEAD);
        evaluate(
            &c[k], &mut h[k], &mut g[k], &mut f[k], &mut d[k], &mut sums, BOOK,
        );
    }
    // The contacts that carried no force: the few the next narrow phase may end. (Every
    // row is counted in `sums.active` or `sums.vacant`, or listed here.)
    let mut idle = Vec::new();
    if sums.active + sums.vacant < n {
        for (g, (f, d)) in g.iter().zip(f.iter().zip(d.iter())) {
            if !f.is_active(g) && !d.is_vacant() {
                idle.push([d.a, d.b]);
            }
        }
    }
    (sums, idle)
}

/// The force loop over runs of a law table's rows ([`RegionRuns`]) at a step whose
/// energies are not booked: each run goes through [`evaluate_chunk`] as a chunk would.
/// `columns` must not be lent to another call at the same time with any of these rows.
fn evaluate_runs<L: ContactLaw, F: ScalarEvaluation<L::History>>(
    evaluate: &F,
    lanes: Option<&LaneForm<L>>,
    snapshot: &GrainSnapshot,
    columns: &TableColumns<L::History>,
    runs: &[RowRun],
) -> (ContactEnergySums, Vec<[u32; 2]>) {
    let mut sums = ContactEnergySums::default();
    let mut idle = Vec::new();
    for (q, &[first, end]) in runs.iter().enumerate() {
        // Between sorts many runs are a single row out of its region's run, read in no
        // order the hardware follows: ask for the rows of a run a few ahead, and for the
        // grains of one half as far, whose bodies have come in by now.
        if let Some(&[ahead, _]) = runs.get(q + RUN_PREFETCH_AHEAD) {
            columns.prefetch_row(ahead as usize);
        }
        if let Some(&[ahead, _]) = runs.get(q + RUN_PREFETCH_AHEAD / 2) {
            // SAFETY: a row of this call's runs, not lent out now.
            let bodies = unsafe { columns.bodies_of(ahead as usize) };
            if bodies.layout == snapshot.layout {
                snapshot.prefetch(bodies.a as usize);
                snapshot.prefetch(bodies.b as usize);
            }
        }
        // SAFETY: the runs hold every row of the table once and each batch of them goes to
        // one call, so no other call holds these rows.
        let (c, h, g, f, d) = unsafe { columns.rows(first as usize..end as usize) };
        let (run_sums, run_idle) =
            evaluate_chunk::<L, F, false>(evaluate, lanes, snapshot, c, h, g, f, d);
        sums.add(&run_sums);
        idle.extend(run_idle);
    }
    (sums, idle)
}

/// How many runs ahead [`evaluate_runs`] asks for a run's rows (and for its grains half as
/// far ahead).
const RUN_PREFETCH_AHEAD: usize = 8;

/// One law table's columns lent to the force loop's threads at once, each thread taking
/// rows no other takes (the runs of [`RegionRuns`], which hold every row once): the
/// rows of a region are not one slice of the table between its sorts, so the table cannot
/// be split into slices per thread.
struct TableColumns<'a, H: Send + Sync + 'static> {
    contacts: &'a [Contact],
    history: *mut LawState<H>,
    geometry: *mut ContactGeometry,
    force: *mut ContactForce,
    bodies: *mut ContactBodies,
    _borrow: std::marker::PhantomData<&'a mut [LawState<H>]>,
}

// SAFETY: the columns are handed out only as disjoint rows ([`TableColumns::rows`]), so
// threads share them as they would share disjoint `&mut` slices.
unsafe impl<H: Send + Sync + 'static> Send for TableColumns<'_, H> {}
unsafe impl<H: Send + Sync + 'static> Sync for TableColumns<'_, H> {}

#[allow(clippy::type_complexity)]
impl<'a, H: Send + Sync + 'static> TableColumns<'a, H> {
    fn new(
        contacts: &'a [Contact],
        history: &'a mut [LawState<H>],
        geometry: &'a mut [ContactGeometry],
        force: &'a mut [ContactForce],
        bodies: &'a mut [ContactBodies],
    ) -> Self {
        let n = contacts.len();
        assert!(
            history.len() == n && geometry.len() == n && force.len() == n && bodies.len() == n,
            "a table's columns have one row per contact"
        );
        Self {
            contacts,
            history: history.as_mut_ptr(),
            geometry: geometry.as_mut_ptr(),
            force: force.as_mut_ptr(),
            bodies: bodies.as_mut_ptr(),
            _borrow: std::marker::PhantomData,
        }
    }

    /// Asks for the cache lines of row `row` of every column, without reading them.
    #[inline(always)]
    fn prefetch_row(&self, row: usize) {
        if row < self.contacts.len() {
            prefetch_address(self.contacts.as_ptr().wrapping_add(row));
            prefetch_address(self.history.wrapping_add(row));
            prefetch_address(self.geometry.wrapping_add(row));
            prefetch_address(self.force.wrapping_add(row));
            prefetch_address(self.bodies.wrapping_add(row));
        }
    }

    /// The bodies of row `row`.
    ///
    /// # Safety
    /// No slice alive now may hold the row ([`Self::rows`]).
    unsafe fn bodies_of(&self, row: usize) -> ContactBodies {
        assert!(row < self.contacts.len());
        // SAFETY: in bounds, and not borrowed mutably now (the caller's promise).
        unsafe { *self.bodies.add(row) }
    }

    /// The columns' slices over `rows`.
    ///
    /// # Safety
    /// No two sets of slices alive at once may share a row.
    unsafe fn rows(
        &self,
        rows: std::ops::Range<usize>,
    ) -> (
        &'a [Contact],
        &'a mut [LawState<H>],
        &'a mut [ContactGeometry],
        &'a mut [ContactForce],
        &'a mut [ContactBodies],
    ) {
        assert!(rows.start <= rows.end && rows.end <= self.contacts.len());
        let (start, len) = (rows.start, rows.end - rows.start);
        // SAFETY: in bounds (above), from live `&mut` slices of `'a`, and not shared with
        // another caller (the caller's promise).
        unsafe {
            (
                &self.contacts[rows],
                std::slice::from_raw_parts_mut(self.history.add(start), len),
                std::slice::from_raw_parts_mut(self.geometry.add(start), len),
                std::slice::from_raw_parts_mut(self.force.add(start), len),
                std::slice::from_raw_parts_mut(self.bodies.add(start), len),
            )
        }
    }
}

/// The scalar evaluation of one contact (the force loop's closure): kinematics, the
/// law's [`ContactLaw::evaluate`], the contact's components and the chunk's sums.
trait ScalarEvaluation<H: Send + Sync + 'static>:
    Fn(
    &Contact,
    &mut LawState<H>,
    &mut ContactGeometry,
    &mut ContactForce,
    &mut ContactBodies,
    &mut ContactEnergySums,
    bool,
)
{
}

impl<H: Send + Sync + 'static, F> ScalarEvaluation<H> for F where
    F: Fn(
        &Contact,
        &mut LawState<H>,
        &mut ContactGeometry,
        &mut ContactForce,
        &mut ContactBodies,
        &mut ContactEnergySums,
        bool,
    )
{
}

/// What the lane form of law `L` reads besides its contacts.
struct LaneForm<'a, L: ContactLaw> {
    snapshot: &'a GrainSnapshot,
    /// The snapshot's grain arrays, for four-grain gathers.
    grains: talus_core::snapshot::GrainReader<'a>,
    /// The snapshot's nearest-image rule in lanes.
    image: talus_core::periodic::ImageLanes,
    params: &'a [L::Params],
    dt: f64,
}

/// Four consecutive contacts of a chunk through the law's lane form
/// ([`ContactLaw::evaluate_lanes`]): the grain pairs whose dense indices are current go
/// into the lanes; then, lane by lane in order, a contact the law evaluated gets its
/// components and its share of the sums exactly as the scalar path would give them, and
/// any other goes through the scalar path (`evaluate`). The results are therefore the
/// same bit for bit as four scalar evaluations.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn evaluate_four<L: ContactLaw, F: ScalarEvaluation<L::History>, const BOOK: bool>(
    evaluate: &F,
    form: &LaneForm<L>,
    c: &[Contact; 4],
    h: &mut [LawState<L::History>; 4],
    g: &mut [ContactGeometry; 4],
    f: &mut [ContactForce; 4],
    d: &mut [ContactBodies; 4],
    sums: &mut ContactEnergySums,
) {
    let s = form.snapshot;
    let mut valid = 0u32;
    for k in 0..4 {
        // A vacant row's bodies are one grain twice: the scalar path passes it over.
        let current =
            c[k].kind == ContactKind::GrainGrain && d[k].layout == s.layout && d[k].a != d[k].b;
        valid |= u32::from(current) << k;
    }
    // Lanes left out read grain 0 (there is one: these contacts have grains).
    let index = |k: usize, body: u32| {
        if valid >> k & 1 == 1 {
            body as usize
        } else {
            0
        }
    };
    let i: [usize; 4] = std::array::from_fn(|k| index(k, d[k].a));
    let j: [usize; 4] = std::array::from_fn(|k| index(k, d[k].b));
    let mut done = 0;
    let mut out = None;
    if valid != 0 {
        let (mut kin, spin) = ContactKinematicsLanes::grain_grain(&form.grains, &form.image, i, j);
        let branch_shift = kin.set_displacement(
            V4::from_fn(|k| g[k].normal),
            F4::from_fn(|k| g[k].overlap),
            spin,
            form.dt,
        );
        let params = std::array::from_fn(|k| &form.params[c[k].pair_slot as usize]);
        let old_force = BOOK.then(|| V4::from_fn(|k| f[k].force));
        let history = h.each_mut().map(|state| &mut state.0);
        let (evaluated, r) = L::evaluate_lanes(params, &kin, history, valid, form.dt, BOOK);
        done = evaluated & valid;
        if done != 0 {
            let torque_a = kin.branch_a.cross(r.force) + r.torque_a;
            let torque_b = kin.branch_b.cross(-r.force) + r.torque_b;
            // The integrator turns the old force with the old branch vectors and the new
            // force with the new ones; the law worked both over the mean (as the scalar
            // path books it).
            let shift_work =
                old_force.map(|old| (old - r.force).dot(branch_shift) * F4::splat(0.25));
            out = Some((kin, r, torque_a, torque_b, shift_work));
        }
    }
    let Some((kin, r, torque_a, torque_b, shift_work)) = out else {
        for k in 0..4 {
            evaluate(
                &c[k], &mut h[k], &mut g[k], &mut f[k], &mut d[k], sums, BOOK,
            );
        }
        return;
    };
    let (normal, overlap) = (kin.normal.to_array(), kin.overlap.to_array());
    let (force, torque_a, torque_b) =
        (r.force.to_array(), torque_a.to_array(), torque_b.to_array());
    let min_radius = kin.min_radius.to_array();
    for k in 0..4 {
        if done >> k & 1 == 0 {
            evaluate(
                &c[k], &mut h[k], &mut g[k], &mut f[k], &mut d[k], sums, BOOK,
            );
            continue;
        }
        // Field by field: a whole struct written at once went through a copy on the
        // stack whose wide reload waited for its narrow stores (10 % of the loop).
        let (geometry, forces) = (&mut g[k], &mut f[k]);
        geometry.normal = normal[k];
        geometry.overlap = overlap[k];
        forces.force = force[k];
        forces.torque_a = torque_a[k];
        forces.torque_b = torque_b[k];
        // The indices are those the lanes read, and still current.
        debug_assert_eq!(
            (d[k].a, d[k].b, d[k].layout),
            (i[k] as u32, j[k] as u32, s.layout)
        );
        sums.active += usize::from(f[k].is_active(&g[k]));
        if overlap[k] >= sums.worst_overlap.0 * min_radius[k] {
            let ratio = overlap[k] / min_radius[k];
            if ratio > sums.worst_overlap.0 {
                sums.worst_overlap = (ratio, Some((c[k].a, c[k].b)));
            }
        }
        if BOOK && let Some(shift_work) = shift_work {
            sums.elastic += r.elastic_energy.to_array()[k];
            sums.integration_error += r.integration_error.to_array()[k] + shift_work.to_array()[k];
            for (total, channel) in sums.dissipated.iter_mut().zip(&r.dissipated) {
                *total += channel.to_array()[k];
            }
        }
    }
}

/// How many contacts ahead of the four being evaluated the lane path asks for grains.
const LANE_PREFETCH_AHEAD: usize = 8;

/// How many contacts ahead the force loop asks for its grains' state.
const PREFETCH_AHEAD: usize = 4;

/// What the force loop reads of a contact's bodies, each looked up once.
struct Bodies {
    kin: ContactKinematics,
    omega_a: DVec3,
    omega_b: DVec3,
    /// Velocity of the wall (zero for a grain pair).
    wall_velocity: DVec3,
    /// Where the bodies sit in the snapshot.
    indices: ContactBodies,
}

/// `cached` are the contact's indices of its last evaluation, reused if the snapshot's
/// layout has not changed since.
#[inline]
fn bodies(snapshot: &GrainSnapshot, c: &Contact, cached: ContactBodies) -> Bodies {
    let valid = cached.layout == snapshot.layout;
    let grain = |entity: Entity, cached: u32| {
        let i = if valid {
            cached as usize
        } else {
            snapshot
                .dense(entity)
                .expect("a contact's grain is in the snapshot")
        };
        debug_assert_eq!(snapshot.entity[i], entity);
        i
    };
    let i = grain(c.a, cached.a);
    match c.kind {
        ContactKind::GrainGrain => {
            let j = grain(c.b, cached.b);
            Bodies {
                kin: ContactKinematics::grain_grain(snapshot, i, j),
                omega_a: snapshot.omega[i],
                omega_b: snapshot.omega[j],
                wall_velocity: DVec3::ZERO,
                indices: ContactBodies {
                    a: i as u32,
                    b: j as u32,
                    layout: snapshot.layout,
                },
            }
        }
        ContactKind::GrainWall => {
            let k = match cached.wall_b() {
                Some(k) if valid => k,
                _ => snapshot
                    .walls
                    .iter()
                    .position(|w| w.entity == c.b)
                    .expect("a contact's wall is in the snapshot"),
            };
            let w = &snapshot.walls[k];
            Bodies {
                kin: ContactKinematics::grain_wall(snapshot, i, w),
                omega_a: snapshot.omega[i],
                omega_b: DVec3::ZERO,
                wall_velocity: w.velocity,
                indices: ContactBodies {
                    a: i as u32,
                    b: ContactBodies::wall_code(k),
                    layout: snapshot.layout,
                },
            }
        }
    }
}

/// Kinematics of a contact from the snapshot.
#[inline]
pub fn kinematics(snapshot: &GrainSnapshot, c: &Contact) -> ContactKinematics {
    bodies(snapshot, c, ContactBodies::default()).kin
}

/// The grains' force and torque totals and masses, as the force sums write them.
type GrainTotals<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static mut Force,
        &'static mut Torque,
        &'static Mass,
    ),
    With<Grain>,
>;

/// The frozen grains, to tell their tables apart.
type FrozenGrains<'w, 's> = Query<'w, 's, Entity, (With<Grain>, With<Frozen>)>;

/// Sums contact forces and torques onto grains (overwriting last step's totals, the forces starting
/// from the grains' weights: [`SimBuilder::gravity_in_force_sums`]) and walls, and the contact
/// energies the force loops summed per chunk ([`ContactEnergyPartials`], emptied here) into the
/// ledger and the energy snapshot. Every sum is taken in a fixed order (contacts in reverse query
/// order for each grain, in query order for each wall, chunks in order for the energies), so the
/// results are bit-reproducible on any number of threads; the grains' sums run in parallel over
/// ranges of grains. At a step that may leave them ([`FrozenTotals::leave_this_step`]) the frozen
/// grains' totals are not summed ([`FrozenTotals::pending`]; [`sum_left_frozen_totals`] sums them
/// later).
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn apply_contact_forces(
    snapshot: Res<GrainSnapshot>,
    clock: Res<Clock>,
    channels: Res<DissipationChannels>,
    mut ledger: ResMut<EnergyLedger>,
    mut energy: ResMut<EnergySnapshot>,
    (mut partials, mut grain_masks): (ResMut<ContactEnergyPartials>, ResMut<ChunkGrainMasks>),
    contacts: Query<(&Contact, &ContactBodies, &ContactForce)>,
    (mut grains, frozen): (GrainTotals, FrozenGrains),
    mut walls: Query<(Entity, &mut WallLoad)>,
    (config, mut frozen_totals): (Res<SimConfig>, ResMut<FrozenTotals>),
    (region_stages, mut region_runs): (Option<Res<RegionStages>>, Local<Vec<RegionRuns>>),
    mut wall_force: Local<Vec<DVec3>>,
    mut picked: Local<Vec<Vec<u32>>>,
) {
    wall_force.clear();
    wall_force.resize(snapshot.walls.len(), DVec3::ZERO);
    if ledger.dissipated.len() < channels.names.len() {
        ledger.dissipated.resize(channels.names.len(), 0.0);
    }
    let full_tables: Vec<(&[Contact], &[ContactBodies], &[ContactForce])> = contacts
        .contiguous_iter()
        .expect("contact query is dense")
        .collect();
    let tables: Vec<(&[ContactBodies], &[ContactForce])> =
        full_tables.iter().map(|&(_, d, f)| (d, f)).collect();
    let regions = region_stages.map(|on| GrainRegions::new(snapshot.len(), on.region_grains));
    if let Some(regions) = &regions {
        // The frozen grains' totals are summed from every row (`sum_grain_totals`).
        let frozen_ranges: Vec<std::ops::Range<u32>> = frozen
            .contiguous_iter()
            .expect("grain query is dense")
            .filter_map(|entities| {
                let first = snapshot.dense(*entities.first()?)? as u32;
                Some(first..first + entities.len() as u32)
            })
            .collect();
        region_runs.resize_with(tables.len(), RegionRuns::default);
        for (&(c, d, _), runs) in full_tables.iter().zip(region_runs.iter_mut()) {
            runs.build(regions, &snapshot, c, d, &frozen_ranges);
        }
    }
    let by_region = regions.as_ref().map(|regions| (regions, &region_runs[..]));
    let leave_frozen = frozen_totals.leave_this_step && clock.pass_dt != 0.0;
    let which = if leave_frozen {
        TotalsOf::Moving
    } else {
        TotalsOf::All
    };
    let left = sum_grain_totals(
        &snapshot,
        &tables,
        by_region,
        Some(&grain_masks),
        &mut grains,
        &frozen,
        which,
        config.gravity,
        &mut picked,
    );
    grain_masks.clear();
    frozen_totals.pending = left;
    // Counts, the worst overlap and the energies come summed per chunk from the force
    // loop; the walls' loads from every contact with a wall, in table order.
    if !wall_force.is_empty() {
        for &(bodies, forces) in &tables {
            for (b, f) in bodies.iter().zip(forces) {
                if let Some(w) = b.wall_b() {
                    wall_force[w] -= f.force;
                }
            }
        }
    }
    let mut step = ContactEnergySums::default();
    for sums in partials.chunks.drain(..) {
        step.add(&sums);
    }
    let ContactEnergySums {
        elastic,
        dissipated,
        boundary_work: wall_work,
        integration_error,
        active: count,
        worst_overlap: (worst, worst_pair),
        vacant: _,
    } = step;
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

    for (entity, mut load) in &mut walls {
        if let Some(w) = snapshot.walls.iter().position(|w| w.entity == entity) {
            load.0 = wall_force[w];
        }
    }
}

/// Whose totals [`sum_grain_totals`] sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TotalsOf {
    /// Every grain's.
    All,
    /// Only those of the grains that move (not [`Frozen`]).
    Moving,
    /// Only those of the frozen grains.
    Frozen,
}

/// One range of grains of [`sum_grain_totals`] (a thread's, or a region's): its first
/// grain's dense index, the range's force and torque totals and masses, and its region
/// when the sums go region by region.
type SumPart<'a> = (
    usize,
    &'a mut [Force],
    &'a mut [Torque],
    &'a [Mass],
    Option<usize>,
);

/// Sets the force and torque totals of the grains `which` names from the contact tables
/// (see [`sum_range`]); returns whether it left a table of frozen grains out.
///
/// Each grain sums its contacts' forces in reverse table order ([`sum_range`]), whichever thread
/// does it, so the totals are the same bit for bit on any number of threads: the grains' force and
/// torque columns (in snapshot order) are split into one range per thread, and each range's thread
/// sets its totals to the weights, reads every contact's body indices (written by the force loop)
/// and adds the forces of those that touch it. Each grain table is a share of its own and each
/// share reads every contact, so a table left out (the frozen base of a chute) spares a whole pass
/// over the contacts.
///
/// With `by_region` (the regions and each table's rows listed by region, [`RegionStages`],
/// frozen grains untracked) the moving grains' ranges are the regions' grains instead, and
/// each reads only the rows that touch them ([`RegionRuns::touching_runs_descending`]),
/// from the last to the first as the whole scan does: the same additions in the same
/// order.
///
/// With `grain_masks` (the force loop's [`ChunkGrainMasks`] of this pass), a range that
/// picks skips the chunks of rows that touch none of its grains.
#[allow(clippy::too_many_arguments)]
fn sum_grain_totals(
    snapshot: &GrainSnapshot,
    tables: &[(&[ContactBodies], &[ContactForce])],
    by_region: Option<(&GrainRegions, &[RegionRuns])>,
    grain_masks: Option<&ChunkGrainMasks>,
    grains: &mut GrainTotals,
    frozen: &FrozenGrains,
    which: TotalsOf,
    g: DVec3,
    picked: &mut Vec<Vec<u32>>,
) -> bool {
    let n = snapshot.len();
    let range = n.div_ceil(rayon::current_num_threads()).max(1);
    let mut parts: Vec<SumPart> = Vec::new();
    let mut offset = 0;
    let mut left_frozen = false;
    for (e, f, t, m) in grains.contiguous_iter_mut().expect("grain query is dense") {
        debug_assert_eq!(&snapshot.entity[offset..offset + e.len()], e);
        let len = e.len();
        // `Frozen` is a table component: a table's grains are all frozen or none is.
        let is_frozen = e.first().is_some_and(|&first| frozen.contains(first));
        let wanted = match which {
            TotalsOf::All => true,
            TotalsOf::Moving => !is_frozen,
            TotalsOf::Frozen => is_frozen,
        };
        left_frozen |= is_frozen && !wanted;
        if wanted {
            let f = bevy_ecs::change_detection::ContiguousMut::bypass_change_detection_split(f).0;
            let t = bevy_ecs::change_detection::ContiguousMut::bypass_change_detection_split(t).0;
            if let Some((regions, _)) = by_region
                && !is_frozen
            {
                // The table's grains cut where the regions are (frozen grains are touched
                // from anywhere in the packing: their shares read every row, below).
                let (mut f, mut t, mut m, mut at) = (f, t, m, offset);
                while !f.is_empty() {
                    let region = regions.region_of(at as u32);
                    let piece = (regions.range(region).end - at).min(f.len());
                    let (f_here, f_rest) = f.split_at_mut(piece);
                    let (t_here, t_rest) = t.split_at_mut(piece);
                    let (m_here, m_rest) = m.split_at(piece);
                    parts.push((at, f_here, t_here, m_here, Some(region)));
                    (f, t, m, at) = (f_rest, t_rest, m_rest, at + piece);
                }
            } else {
                let shares = f
                    .chunks_mut(range)
                    .zip(t.chunks_mut(range))
                    .zip(m.chunks(range));
                for (k, ((f, t), m)) in shares.enumerate() {
                    parts.push((offset + k * range, f, t, m, None));
                }
            }
        }
        offset += len;
    }
    picked.resize_with(parts.len(), Vec::new);
    let pick = rayon::current_num_threads() > 1;
    let skip = grain_masks.map(|masks| (masks, ChunkGrainMasks::shift(n)));
    parts.into_par_iter().zip(picked.par_iter_mut()).for_each(
        |((first, force, torque, mass, region), picked)| match (region, by_region) {
            (Some(r), Some((_, runs))) => {
                // A region's rows are read by the regions whose grains they touch: most
                // of the sides they hold lie outside the range, so they are picked.
                let touching: Vec<Vec<RowRun>> = runs
                    .iter()
                    .map(|runs| runs.touching_runs_descending(r))
                    .collect();
                let rows = Some(&touching[..]);
                sum_range(
                    tables, rows, None, true, first, force, torque, mass, g, picked,
                )
            }
            _ => sum_range(
                tables, None, skip, pick, first, force, torque, mass, g, picked,
            ),
        },
    );
    left_frozen
}

/// Sums the frozen grains' force and torque totals that the last step left
/// ([`FrozenTotals::pending`]) from the contact forces it stored, with the same sums in
/// the same order as the step would have taken: called by
/// [`Simulation::synchronize`](talus_core::schedule::Simulation::synchronize). Does
/// nothing when none are pending.
pub fn sum_left_frozen_totals(world: &mut World) {
    use bevy_ecs::system::RunSystemOnce;
    let pending = world
        .get_resource::<FrozenTotals>()
        .is_some_and(|f| f.pending);
    if pending {
        world
            .run_system_once(sum_frozen_totals)
            .expect("the contact resources are installed");
    }
}

/// The system of [`sum_left_frozen_totals`].
fn sum_frozen_totals(
    snapshot: Res<GrainSnapshot>,
    config: Res<SimConfig>,
    mut frozen_totals: ResMut<FrozenTotals>,
    contacts: Query<(&ContactBodies, &ContactForce)>,
    mut grains: GrainTotals,
    frozen: FrozenGrains,
    mut picked: Local<Vec<Vec<u32>>>,
) {
    let tables: Vec<(&[ContactBodies], &[ContactForce])> = contacts
        .contiguous_iter()
        .expect("contact query is dense")
        .collect();
    sum_grain_totals(
        &snapshot,
        &tables,
        None,
        None,
        &mut grains,
        &frozen,
        TotalsOf::Frozen,
        config.gravity,
        &mut picked,
    );
    frozen_totals.pending = false;
}

/// One thread's share of [`sum_grain_totals`]: sets the force totals of the grains
/// `first..first + force.len()` (in snapshot order) to their weights m `g` and their torque
/// totals to zero, and adds to them the forces and torques of the contacts that touch
/// them in reverse table order: the last table first, each from its last row to its
/// first, the second body's side of a row before the first body's. The force loop, just
/// before, ran forwards, so the rows it wrote last are still in cache when this scan reads
/// them, and the totals this scan writes last (the lowest grains') are the first the next
/// step's kick reads (measured against a forward scan by switching between the two every
/// few steps inside one run: 2–4 % faster on 2 threads at every size, no faster on 1
/// thread; `docs/performance-log.md`, session 41).
///
/// With `rows` (one list per table, each from its last row to its first: a region's rows,
/// [`RegionRuns::touching_runs_descending`]) only those rows are scanned, in that order,
/// and always by picking.
///
/// With `skip` (the pass's [`ChunkGrainMasks`] and the snapshot's mask shift), a table
/// whose masks the force loop left is scanned only over the chunks of rows whose masks
/// share a bit with the range's: none of the other rows' sides is in the range, so the same
/// sides are added in the same order. The contact tables are in the order of their rows'
/// first bodies (between sorts, each region's new contacts in its own rows), so on two
/// threads each range skips most of the other's rows, and in the chunks it reads the sides
/// in and out of the range come in runs: a branch per side, as on one thread, predicts
/// them. (Until session 55 the chunks that also touched grains of another range were
/// picked first, as below; the branches took 10 % less of the stage on 2 threads at
/// 32,000 grains, `docs/performance-log.md`.)
///
/// Without masks and with `pick` (two or more threads; a region's rows), every contact's
/// two bodies are first tested against the range without a branch, each side in range
/// appended to `picked` as `row << 1 | side` (the write always happens, the length grows
/// by the test's 0 or 1), and only the picked sides are then summed: where a range meets
/// rows whose bodies lie in and out of it in no predictable pattern, a branch per side
/// mispredicted on so many that this stage took as long on two threads as on one (when
/// the tables were in no order). Either way the sums are taken in the same order.
///
/// A range of at least [`LATE_START_GRAINS`] grains has its totals set to their weights as
/// the scan of the contacts reaches them, down to [`START_LEAD`] grains below the smallest
/// body of each block of [`START_BLOCK`] contacts (of each block of picked contacts when
/// picking), instead of in a pass of their own first: the contact table is in the order of
/// its first bodies and a second body is at most two layers of cells further
/// (`docs/architecture.md`, "Grain order"), so as the scan runs down a total is set shortly
/// before the contacts add to it, while its line is still in cache. A pass of its own over
/// a large range writes every total out to memory and the additions read them back (13–18 %
/// of this stage at 512,000 grains on one thread, 10–16 % on two). The additions'
/// order, hence every bit, is the same either way.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn sum_range(
    tables: &[(&[ContactBodies], &[ContactForce])],
    rows: Option<&[Vec<RowRun>]>,
    skip: Option<(&ChunkGrainMasks, u32)>,
    pick: bool,
    first: usize,
    force: &mut [Force],
    torque: &mut [Torque],
    mass: &[Mass],
    g: DVec3,
    picked: &mut Vec<u32>,
) {
    let len = force.len();
    // The totals start from the weight m g: the gravity of `SimBuilder::gravity_in_force_sums`,
    // which then needs no pass of its own over the grains.
    let start = |force: &mut [Force], torque: &mut [Torque], from: usize, to: usize| {
        for (f, m) in force[from..to].iter_mut().zip(&mass[from..to]) {
            f.0 = g * m.0;
        }
        torque[from..to].fill(Torque(DVec3::ZERO));
    };
    // Adds one side of a contact; `b_side` for the second body, whose force is opposite.
    let add = |force: &mut [Force],
               torque: &mut [Torque],
               b: &ContactBodies,
               f: &ContactForce,
               b_side: bool| {
        if b_side {
            let j = b.b as usize - first;
            force[j].0 -= f.force;
            torque[j].0 += f.torque_b;
        } else {
            let i = b.a as usize - first;
            force[i].0 += f.force;
            torque[i].0 += f.torque_a;
        }
    };
    let in_range = |body: u32| (body as usize).wrapping_sub(first) < len;
    // The scan runs from the last row to the first (why: the function's doc). The totals
    // `set_from..` are set.
    let mut set_from = len;
    if len < LATE_START_GRAINS {
        start(force, torque, 0, len);
        set_from = 0;
    }
    // A body's offset in the range, `usize::MAX` outside it.
    let offset = |body: u32| {
        let k = (body as usize).wrapping_sub(first);
        if k < len { k } else { usize::MAX }
    };
    // Adds the sides in range of every row of `bodies`, from the last row to the first, a
    // branch per side (predicted where nearly every side is in range), setting the totals
    // as the scan reaches them.
    let add_rows = |bodies: &[ContactBodies],
                    forces: &[ContactForce],
                    force: &mut [Force],
                    torque: &mut [Torque],
                    set_from: &mut usize| {
        for (block, rows) in bodies.chunks(START_BLOCK).enumerate().rev() {
            if *set_from > 0 {
                let low = rows.iter().map(|b| offset(b.a).min(offset(b.b))).min();
                if let Some(low) = low.filter(|&l| l < *set_from) {
                    let from = low.saturating_sub(START_LEAD);
                    start(force, torque, from, *set_from);
                    *set_from = from;
                }
            }
            let block_start = block * START_BLOCK;
            for (row, b) in rows.iter().enumerate().rev() {
                let row = block_start + row;
                // The table is in the order of its first bodies, so the first sides'
                // totals are read in order; the second bodies' are not, and miss a
                // core's own cache: ask for them a few contacts ahead (below).
                if let Some(ahead) = row.checked_sub(SUM_AHEAD).map(|r| &bodies[r]) {
                    let j = (ahead.b as usize).wrapping_sub(first);
                    prefetch_item(force, j);
                    prefetch_item(torque, j);
                }
                let f = &forces[row];
                if in_range(b.b) {
                    add(force, torque, b, f, true);
                }
                if in_range(b.a) {
                    add(force, torque, b, f, false);
                }
            }
        }
    };
    // Listed rows are taken by picking.
    if !pick && rows.is_none() {
        for &(bodies, forces) in tables.iter().rev() {
            add_rows(bodies, forces, force, torque, &mut set_from);
        }
        // Grains no contact touches.
        start(force, torque, 0, set_from);
        return;
    }
    // Two entries a contact at most, plus the one written past the last kept; blocks of
    // contacts keep the list small (no buffer that grows with the packing) and in cache.
    picked.resize(2 * PICK_BLOCK + 1, 0);
    // The rows to scan, as slices in the order they are scanned (each from its end), with
    // the masks of a whole table's chunks where the force loop left them.
    let mut pieces: Vec<ScanPiece> = Vec::new();
    for (t, &(bodies, forces)) in tables.iter().enumerate().rev() {
        match rows {
            Some(rows) => pieces.extend(rows[t].iter().map(|&[first, end]| {
                let rows = first as usize..end as usize;
                (&bodies[rows.clone()], &forces[rows], None)
            })),
            None => {
                let masks = skip
                    .and_then(|(masks, _)| masks.of_table(bodies))
                    .filter(|m| m.len() == bodies.len().div_ceil(ENERGY_CHUNK_LEN));
                pieces.push((bodies, forces, masks));
            }
        }
    }
    let range_mask = skip.map_or(0, |(_, shift)| ChunkGrainMasks::of_range(first, len, shift));
    for (bodies, forces, masks) in pieces {
        if let Some(masks) = masks {
            // The chunks whose masks meet the range, each run of them from its last row to
            // its first as the whole scan takes them, a branch per side: the table is in the
            // order of its first bodies, so the sides in and out of the range come in runs
            // the branches predict (picking them cost 10 % more of the stage on 2 threads).
            let mut end = masks.len();
            while end > 0 {
                while end > 0 && masks[end - 1] & range_mask == 0 {
                    end -= 1;
                }
                let mut from = end;
                while from > 0 && masks[from - 1] & range_mask != 0 {
                    from -= 1;
                }
                if from < end {
                    let rows = from * ENERGY_CHUNK_LEN..(end * ENERGY_CHUNK_LEN).min(bodies.len());
                    add_rows(
                        &bodies[rows.clone()],
                        &forces[rows],
                        force,
                        torque,
                        &mut set_from,
                    );
                }
                end = from;
            }
            continue;
        }
        let blocks = bodies.chunks(PICK_BLOCK).zip(forces.chunks(PICK_BLOCK));
        for (bodies, forces) in blocks.rev() {
            let mut count = 0;
            // The lowest offset picked (`usize::MAX` for none).
            let mut low = usize::MAX;
            for (row, b) in bodies.iter().enumerate() {
                let code = (row as u32) << 1;
                picked[count] = code;
                count += usize::from(in_range(b.a));
                picked[count] = code | 1;
                count += usize::from(in_range(b.b));
                low = low.min(offset(b.a).min(offset(b.b)));
            }
            if low < set_from {
                let from = low.saturating_sub(START_LEAD);
                start(force, torque, from, set_from);
                set_from = from;
            }
            for k in (0..count).rev() {
                let code = picked[k];
                if k >= SUM_AHEAD {
                    let ahead = picked[k - SUM_AHEAD];
                    let b = &bodies[(ahead >> 1) as usize];
                    let j = if ahead & 1 == 1 { b.b } else { b.a } as usize;
                    prefetch_item(force, j.wrapping_sub(first));
                    prefetch_item(torque, j.wrapping_sub(first));
                }
                let row = (code >> 1) as usize;
                add(force, torque, &bodies[row], &forces[row], code & 1 == 1);
            }
        }
    }
    // Grains no contact touches.
    start(force, torque, 0, set_from);
}

/// Rows [`sum_range`] scans in one piece: their bodies and forces, and the masks of their
/// chunks ([`ChunkGrainMasks`]) when the piece is a whole table whose masks the force loop
/// left.
type ScanPiece<'a> = (&'a [ContactBodies], &'a [ContactForce], Option<&'a [u64]>);

/// The smallest range of grains whose totals [`sum_range`] sets as its scan reaches them:
/// on the chute (one thread), setting them late costs 3–11 % of the stage at 32,000
/// grains (1.5 MB of totals, in the L3 either way) and saves 5–10 % at 128,000 and 13–18 %
/// at 512,000 (`docs/performance-log.md`, session 32).
const LATE_START_GRAINS: usize = 65_536;

/// Contacts whose bodies [`sum_range`] takes together to find how far the totals must be
/// set before adding them.
const START_BLOCK: usize = 64;

/// How many grains below the smallest body of a block of contacts [`sum_range`] (scanning
/// down) sets at once, so that a new stretch of totals is set once every few blocks, not
/// at every one.
const START_LEAD: usize = 1024;

/// How many contacts (or picked sides) ahead [`sum_range`] asks for the totals it will add
/// to.
const SUM_AHEAD: usize = 16;

/// Contacts whose sides [`sum_range`] picks at a time.
const PICK_BLOCK: usize = 2048;

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

#[cfg(test)]
mod tests {
    use super::*;

    /// Numbers in [0, 1) from a 64-bit linear congruential generator: a fixed stream the
    /// test needs no crate for.
    struct Numbers(u64);

    impl Numbers {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        fn vector(&mut self) -> DVec3 {
            DVec3::new(self.next() - 0.5, self.next() - 0.5, self.next() - 0.5)
        }
    }

    /// The sums of one range past [`LATE_START_GRAINS`], whose totals are set late, on one thread's
    /// path and on the picking path of two, against their definition: each total the grain's weight
    /// plus, in reverse table order (the last table's last row first), the force (or its opposite)
    /// and torque of every contact that touches it. Contacts mostly in the order of their first
    /// bodies, their second bodies up to 3,000 grains further, every 40th row out of order (a
    /// recycled row), some with a wall, bodies before and after the range, two tables.
    #[test]
    fn totals_set_as_the_scan_reaches_them_are_the_plain_sums() {
        let first = 1_000;
        let len = LATE_START_GRAINS + 5_000;
        let grains = first + len + 3_000;
        let mut numbers = Numbers(7);
        let mut tables: Vec<(Vec<ContactBodies>, Vec<ContactForce>)> = vec![Default::default(); 2];
        for a in 0..grains as u32 {
            let table = &mut tables[(a % 7 == 0) as usize];
            for _ in 0..(numbers.next() * 2.5) as usize {
                let row = table.0.len();
                let a = if row % 40 == 39 {
                    (numbers.next() * grains as f64) as u32
                } else {
                    a
                };
                let b = if numbers.next() < 0.05 {
                    WALL_BODY_BASE + 2
                } else {
                    a + 1 + (numbers.next() * 3_000.0) as u32
                };
                table.0.push(ContactBodies { a, b, layout: 1 });
                table.1.push(ContactForce {
                    force: numbers.vector(),
                    torque_a: numbers.vector(),
                    torque_b: numbers.vector(),
                });
            }
        }
        let mass: Vec<Mass> = (0..len).map(|_| Mass(0.5 + numbers.next())).collect();
        let g = DVec3::new(0.44, 0.0, -0.9);
        let mut force_expected: Vec<DVec3> = mass.iter().map(|m| g * m.0).collect();
        let mut torque_expected = vec![DVec3::ZERO; len];
        for (bodies, forces) in tables.iter().rev() {
            for (b, f) in bodies.iter().zip(forces).rev() {
                let (i, j) = (b.a as usize, b.b as usize);
                if (first..first + len).contains(&i) {
                    force_expected[i - first] += f.force;
                    torque_expected[i - first] += f.torque_a;
                }
                if (first..first + len).contains(&j) {
                    force_expected[j - first] -= f.force;
                    torque_expected[j - first] += f.torque_b;
                }
            }
        }
        // Every total the same bits as the plain sum's.
        let same_totals = |force: &[Force], torque: &[Torque], how: &str| {
            for k in 0..len {
                assert_eq!(
                    force[k].0.to_array().map(f64::to_bits),
                    force_expected[k].to_array().map(f64::to_bits),
                    "force total of grain {} ({how})",
                    first + k
                );
                assert_eq!(
                    torque[k].0.to_array().map(f64::to_bits),
                    torque_expected[k].to_array().map(f64::to_bits),
                    "torque total of grain {} ({how})",
                    first + k
                );
            }
        };
        let views: Vec<(&[ContactBodies], &[ContactForce])> = tables
            .iter()
            .map(|(b, f)| (b.as_slice(), f.as_slice()))
            .collect();
        for pick in [false, true] {
            // Totals left from an earlier step: every one must be set again.
            let mut force = vec![Force(DVec3::NAN); len];
            let mut torque = vec![Torque(DVec3::NAN); len];
            let mut picked = Vec::new();
            sum_range(
                &views,
                None,
                None,
                pick,
                first,
                &mut force,
                &mut torque,
                &mass,
                g,
                &mut picked,
            );
            same_totals(&force, &torque, &format!("pick: {pick}"));
        }
        // In ranges of 6,000 grains, as threads sum them, each skipping the chunks of rows
        // whose masks miss its range (most of them here): a mask or a range's bits one
        // block short leaves sides out.
        let shift = ChunkGrainMasks::shift(grains);
        let mut masks = ChunkGrainMasks::default();
        for (bodies, _) in &tables {
            let chunks = bodies
                .chunks(ENERGY_CHUNK_LEN)
                .map(|rows| ChunkGrainMasks::of_rows(rows, shift));
            masks.record(bodies, chunks);
        }
        let mut force = vec![Force(DVec3::NAN); len];
        let mut torque = vec![Torque(DVec3::NAN); len];
        let mut picked = Vec::new();
        for start in (0..len).step_by(6_000) {
            let local = start..(start + 6_000).min(len);
            sum_range(
                &views,
                None,
                Some((&masks, shift)),
                true,
                first + start,
                &mut force[local.clone()],
                &mut torque[local.clone()],
                &mass[local],
                g,
                &mut picked,
            );
        }
        same_totals(
            &force,
            &torque,
            "summed in ranges, chunks skipped by their masks",
        );
        // Region by region, as the sums by region run: each region's part of the range from
        // the rows that touch the region's grains alone.
        let regions = GrainRegions::new(grains, 4096);
        let mut snapshot = GrainSnapshot::default();
        snapshot.layout = 1;
        let runs: Vec<RegionRuns> = tables
            .iter()
            .map(|(bodies, _)| {
                let mut runs = RegionRuns::default();
                // The cached bodies are current: the contacts are not read.
                let pairs = vec![Contact::vacant(Entity::PLACEHOLDER); bodies.len()];
                runs.build(&regions, &snapshot, &pairs, bodies, &[]);
                runs
            })
            .collect();
        let mut force = vec![Force(DVec3::NAN); len];
        let mut torque = vec![Torque(DVec3::NAN); len];
        let mut picked = Vec::new();
        for r in 0..regions.count() {
            let grains = regions.range(r);
            let part = grains.start.max(first)..grains.end.min(first + len);
            if part.is_empty() {
                continue;
            }
            let rows: Vec<Vec<RowRun>> = runs
                .iter()
                .map(|runs| runs.touching_runs_descending(r))
                .collect();
            let local = part.start - first..part.end - first;
            sum_range(
                &views,
                Some(&rows),
                None,
                false,
                part.start,
                &mut force[local.clone()],
                &mut torque[local.clone()],
                &mass[local],
                g,
                &mut picked,
            );
        }
        same_totals(&force, &torque, "by region");
    }

    /// A chunk's mask has the bit of each of its bodies' blocks of grains; a range's mask
    /// the bits of every block it reaches; indices past the 64th block (the walls' codes
    /// among them) all take bit 63.
    #[test]
    fn chunk_masks_hold_the_blocks_of_their_bodies() {
        assert_eq!(ChunkGrainMasks::shift(0), 0);
        assert_eq!(ChunkGrainMasks::shift(64), 0);
        assert_eq!(ChunkGrainMasks::shift(65), 1);
        assert_eq!(ChunkGrainMasks::shift(32_000), 9);
        let shift = ChunkGrainMasks::shift(32_000);
        let rows = [
            ContactBodies {
                a: 0,
                b: 511,
                layout: 1,
            },
            ContactBodies {
                a: 512,
                b: WALL_BODY_BASE,
                layout: 1,
            },
        ];
        assert_eq!(ChunkGrainMasks::of_rows(&rows, shift), 0b11 | 1 << 63);
        assert_eq!(ChunkGrainMasks::of_range(511, 2, shift), 0b11);
        assert_eq!(ChunkGrainMasks::of_range(1_024, 512, shift), 0b100);
        assert_eq!(ChunkGrainMasks::of_range(5, 0, shift), 0);
        assert_eq!(
            ChunkGrainMasks::of_range(31_000, 1_000, shift),
            1 << 60 | 1 << 61 | 1 << 62
        );
        assert_eq!(
            ChunkGrainMasks::of_range(0, usize::MAX >> 1, shift),
            u64::MAX
        );
    }
}
