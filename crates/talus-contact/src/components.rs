//! Components of contact entities and the resources that index them.

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus_core::energy::MAX_DISSIPATION_CHANNELS;

/// What kind of bodies a contact joins.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ContactKind {
    /// Two grains; `a` and `b` are grain entities.
    GrainGrain,
    /// A grain (`a`) and a plane wall (`b`).
    GrainWall,
}

/// The pair a contact joins, fixed for the contact's life.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Contact {
    /// First body, always a grain; forces are reported as acting on it.
    pub a: Entity,
    /// Second body: a grain or a wall.
    pub b: Entity,
    /// Grain–grain or grain–wall.
    pub kind: ContactKind,
    /// Index into the law's per-material-pair parameter table.
    pub pair_slot: u32,
}

impl Contact {
    /// A vacant row of its law's table: no pair, but a row kept for the next new contact
    /// of its grain's region (`a` and `b` are both that grain; no contact joins a grain to
    /// itself). It carries no force, evaluates to nothing, and is neither listed in the
    /// narrow phase's index nor counted, drawn or sampled; a saved state keeps it, so that
    /// a resumed run hands rows out alike. See `docs/architecture.md` §6.
    #[inline]
    pub fn is_vacant(&self) -> bool {
        self.a == self.b
    }

    /// The vacant row of grain `grain` (its key, whose region it stands in).
    #[inline]
    pub fn vacant(grain: Entity) -> Self {
        Self {
            a: grain,
            b: grain,
            kind: ContactKind::GrainGrain,
            pair_slot: 0,
        }
    }
}

/// Where a contact's bodies sit in this step's [`talus_core::snapshot::GrainSnapshot`],
/// written by the force loop: the summation of contact forces onto grains reads these
/// instead of looking the entities up again.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ContactBodies {
    /// Dense index of grain `a`.
    pub a: u32,
    /// Dense index of grain `b`, or [`WALL_BODY_BASE`] plus the wall's index in the
    /// snapshot's walls for a grain–wall contact.
    pub b: u32,
    /// The snapshot's [`layout`](talus_core::snapshot::GrainSnapshot::layout) the indices
    /// belong to (0: none yet): while it is unchanged the force loop reuses them instead of
    /// looking the entities up.
    pub layout: u32,
}

/// [`ContactBodies::b`] at or above this is a wall: `b - WALL_BODY_BASE` is its index.
pub const WALL_BODY_BASE: u32 = u32::MAX - 1024;

impl ContactBodies {
    /// The bodies of contact `c` in snapshot `s`, looked up by entity; `None` if one of
    /// them is not in the snapshot.
    pub fn look_up(s: &talus_core::snapshot::GrainSnapshot, c: &Contact) -> Option<Self> {
        let a = s.dense(c.a)? as u32;
        let b = match c.kind {
            ContactKind::GrainGrain => s.dense(c.b)? as u32,
            ContactKind::GrainWall => Self::wall_code(s.wall_index(c.b)?),
        };
        Some(Self {
            a,
            b,
            layout: s.layout,
        })
    }

    /// The body code of the snapshot's wall `k`, as [`Self::b`] holds it.
    #[inline]
    pub fn wall_code(k: usize) -> u32 {
        WALL_BODY_BASE + k as u32
    }

    /// The index among the snapshot's walls that a body code stands for, if it is a wall.
    #[inline]
    pub fn wall_of(code: u32) -> Option<usize> {
        (code >= WALL_BODY_BASE).then(|| (code - WALL_BODY_BASE) as usize)
    }

    /// Whether these are the bodies of a vacant row ([`Contact::is_vacant`]): one grain
    /// twice.
    #[inline]
    pub fn is_vacant(&self) -> bool {
        self.a == self.b
    }

    /// The index of `b` among the snapshot's walls if it is a wall.
    #[inline]
    pub fn wall_b(&self) -> Option<usize> {
        Self::wall_of(self.b)
    }
}

/// Geometry of the last evaluation. The contact point is not stored (the force loop
/// would write it at every step for the few readers that need it): [`Self::point`] gives
/// it from grain `a`'s centre and radius.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactGeometry {
    /// Unit normal pointing from `b` towards `a`.
    pub normal: DVec3,
    /// Overlap δ = R_a + R_b − distance (walls: R_a − distance to plane), metres.
    pub overlap: f64,
}

impl ContactGeometry {
    /// The contact point (the middle of the overlap) of this geometry for grain `a` with
    /// centre `a_centre` and radius `a_radius`: `a`'s centre plus its branch vector
    /// −n (R_a − δ/2), as the kinematics compute it ([`crate::ContactKinematics`]).
    #[inline]
    pub fn point(&self, a_centre: DVec3, a_radius: f64) -> DVec3 {
        a_centre + self.branch_a(a_radius)
    }

    /// The branch vector of grain `a` (radius `a_radius`): from its centre to the contact
    /// point, −n (R_a − δ/2).
    #[inline]
    pub fn branch_a(&self, a_radius: f64) -> DVec3 {
        -self.normal * (a_radius - 0.5 * self.overlap)
    }
}

/// Force and torques of the last evaluation.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactForce {
    /// Force on `a` (its opposite acts on `b`), N.
    pub force: DVec3,
    /// Torque on `a` about its centre, N m.
    pub torque_a: DVec3,
    /// Torque on `b` about its centre, N m (zero for walls).
    pub torque_b: DVec3,
}

impl ContactForce {
    /// Normal component of the force (positive when repulsive).
    pub fn normal_force(&self, geometry: &ContactGeometry) -> f64 {
        self.force.dot(geometry.normal)
    }

    /// Whether the contact acted at its last evaluation: its bodies overlap or it
    /// carries a force. A contact whose bodies have just separated is kept for one
    /// evaluation with no force, so that the law books the work of the step in which
    /// it ended; it is not active then and is neither counted nor drawn.
    pub fn is_active(&self, geometry: &ContactGeometry) -> bool {
        geometry.overlap > 0.0 || self.force != DVec3::ZERO
    }
}

/// Energies of a run of consecutive contacts of one law, summed by the force loop: what
/// [`crate::systems::apply_contact_forces`] adds into the energy ledger and the energy snapshot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactEnergySums {
    /// Elastic energy stored now, J.
    pub elastic: f64,
    /// Energy dissipated during the last step, per global dissipation channel, J.
    pub dissipated: [f64; MAX_DISSIPATION_CHANNELS],
    /// Work done on grains by moving walls through these contacts during the last step,
    /// by the trapezoidal rule ½(F_old + F_new)·u_wall Δt per contact, J.
    pub boundary_work: f64,
    /// Energy created by the time integration at these contacts during the last step,
    /// as the law measured it ([`crate::ContactResponse::integration_error`]), J.
    pub integration_error: f64,
    /// How many of these contacts carry a force ([`ContactForce::is_active`]).
    pub active: usize,
    /// How many of these rows are vacant ([`Contact::is_vacant`]).
    pub vacant: usize,
    /// The largest overlap over the smaller radius of the pair among these contacts, and
    /// the first pair (a, b) that reached it; zero and `None` if no contact overlaps.
    pub worst_overlap: (f64, Option<(Entity, Entity)>),
}

impl ContactEnergySums {
    /// Adds the sums of contacts evaluated after these: the energies and counts add, and
    /// the worst overlap stays the first pair that reached the largest ratio.
    #[inline]
    pub fn add(&mut self, later: &Self) {
        self.elastic += later.elastic;
        for (total, d) in self.dissipated.iter_mut().zip(&later.dissipated) {
            *total += d;
        }
        self.boundary_work += later.boundary_work;
        self.integration_error += later.integration_error;
        self.active += later.active;
        self.vacant += later.vacant;
        if later.worst_overlap.0 > self.worst_overlap.0 {
            self.worst_overlap = later.worst_overlap;
        }
    }
}

/// The contact energies of the current step as partial sums, one per chunk of
/// [`crate::systems::ENERGY_CHUNK_LEN`] contacts: each law's force system appends its chunks in
/// table order, the laws in schedule order; [`crate::systems::apply_contact_forces`] adds them in
/// that order and empties the list. Chunks of a fixed length make the sums independent of
/// the thread count, and no per-contact energy has to be stored.
#[derive(Resource, Clone, Debug, Default)]
pub struct ContactEnergyPartials {
    /// Partial sums of the step, in summation order.
    pub chunks: Vec<ContactEnergySums>,
}

/// Which grains each chunk of [`crate::systems::ENERGY_CHUNK_LEN`] rows of a contact table
/// touches, as the force loop of the current pass left the rows' bodies
/// ([`ContactBodies`]): for the force sums on two or more threads, where each thread sets
/// the totals of a range of grains and would otherwise test both bodies of every row
/// against its range. A chunk whose mask shares no bit with a thread's range holds no
/// side that thread adds, so it skips the chunk; the sides it adds, and their order, are
/// those of the full scan. The force loops fill it (on two or more threads only),
/// [`crate::systems::apply_contact_forces`] reads it and empties it, so it never outlives
/// the pass whose rows it describes.
#[derive(Resource, Clone, Debug, Default)]
pub struct ChunkGrainMasks {
    /// Per table: the address and length of its bodies column, which name the table
    /// within a pass, and where its masks lie in [`Self::masks`].
    tables: Vec<(usize, usize, std::ops::Range<usize>)>,
    /// Every recorded table's masks, one per chunk of rows in table order, kept in one
    /// list whose room outlives the pass (no allocation a step).
    masks: Vec<u64>,
}

impl ChunkGrainMasks {
    /// The bit of a body: its dense index over [`Self::shift`], bit 63 for everything
    /// above (the last grains and the walls' codes share it, which only costs a skip).
    #[inline]
    fn bit(body: u32, shift: u32) -> u64 {
        1 << (body >> shift).min(63)
    }

    /// How far the dense indices of a snapshot of `grains` grains are shifted to make
    /// a bit of a mask: the smallest shift that gives at most 64 blocks of grains.
    pub fn shift(grains: usize) -> u32 {
        let mut shift = 0;
        while grains.saturating_sub(1) >> shift >= 64 {
            shift += 1;
        }
        shift
    }

    /// The mask of the bodies of `rows` (one chunk), for a snapshot of `shift`.
    pub fn of_rows(rows: &[ContactBodies], shift: u32) -> u64 {
        rows.iter()
            .fold(0, |m, b| m | Self::bit(b.a, shift) | Self::bit(b.b, shift))
    }

    /// The mask of the grains `first..first + len`, for a snapshot of `shift`.
    pub fn of_range(first: usize, len: usize, shift: u32) -> u64 {
        if len == 0 {
            return 0;
        }
        let low = (first >> shift).min(63);
        let high = ((first + len - 1) >> shift).min(63);
        (u64::MAX >> (63 - high)) & (u64::MAX << low)
    }

    /// Records the chunks' masks of the table whose bodies column is `bodies`, replacing
    /// any earlier record of it.
    pub fn record(&mut self, bodies: &[ContactBodies], masks: impl IntoIterator<Item = u64>) {
        let key = (bodies.as_ptr() as usize, bodies.len());
        self.tables.retain(|t| (t.0, t.1) != key);
        let start = self.masks.len();
        self.masks.extend(masks);
        self.tables.push((key.0, key.1, start..self.masks.len()));
    }

    /// The chunks' masks of the table whose bodies column is `bodies`, if this pass's
    /// force loop recorded them.
    pub fn of_table(&self, bodies: &[ContactBodies]) -> Option<&[u64]> {
        let key = (bodies.as_ptr() as usize, bodies.len());
        self.tables
            .iter()
            .find(|t| (t.0, t.1) == key)
            .map(|t| &self.masks[t.2.clone()])
    }

    /// Forgets every table's masks (the pass they describe is over).
    pub fn clear(&mut self) {
        self.tables.clear();
        self.masks.clear();
    }
}

/// The contacts that carried no force at their last evaluation
/// ([`ContactForce::is_active`] false: the bodies had parted, and the law had booked the
/// step in which they did), by their bodies' codes in the snapshot ([`ContactBodies`]
/// `a` and `b`). The force loops append to it; the next narrow phase reads it, since these
/// are the only contacts it may end (a contact that acted is kept for one more
/// evaluation, touching or not), and empties it.
#[derive(Resource, Clone, Debug, Default)]
pub struct IdleContacts {
    /// Bodies of each idle contact, in the snapshot of `layout`, in no particular order.
    pub pairs: Vec<[u32; 2]>,
    /// The snapshot layout ([`talus_core::snapshot::GrainSnapshot::layout`]) of `pairs`.
    pub layout: u32,
    /// Whether a force pass ran since the last narrow phase (so that `pairs` accounts for
    /// every contact then in the index).
    pub evaluated: bool,
}

/// The law's per-contact history, e.g. a tangential spring.
#[derive(Component, Clone, Debug, Default)]
pub struct LawState<H: Send + Sync + 'static>(pub H);
