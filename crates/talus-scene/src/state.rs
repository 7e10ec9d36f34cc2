//! Saved states: every grain, wall and contact (with its law's history), the periodic
//! box, the clock and the energy totals, as a RON file. A run resumed from a state is
//! bit-identical to the run that saved it; another scene can start from it (a packing).
//!
//! What makes resuming exact (docs/user-guide.md, "Saving and resuming"):
//! * grains are re-created in their saved order, so the dense order, and with it every
//!   sum over grains, is the same;
//! * contacts are re-created in their saved order (the order in which their forces are
//!   summed) with the geometry and force of their last evaluation, which the next step
//!   reads, and their law's history;
//! * the accumulated forces and torques are kept (velocity Verlet's first kick uses them),
//!   so no priming pass runs;
//! * floats are written in Rust's shortest round-trip form and read back exactly.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use talus_contact::systems::ContactLawTable;
use talus_contact::{Contact, ContactForce, ContactGeometry, ContactKind};
use talus_core::energy::{EnergyLedger, EnergySnapshot};
use talus_core::gear::GearHistory;
use talus_core::prelude::*;

/// Version of the state format written by this build.
pub const STATE_FORMAT: u32 = 1;

/// One grain of a saved state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedGrain {
    /// Centre, m.
    pub position: DVec3,
    /// Velocity, m/s.
    pub velocity: DVec3,
    /// Angular velocity, rad/s.
    pub angular_velocity: DVec3,
    /// Radius, m.
    pub radius: f64,
    /// Mass, kg.
    pub mass: f64,
    /// Moment of inertia, kg m².
    pub inertia: f64,
    /// Material, by name.
    pub material: String,
    /// Whether the grain is frozen (never moves).
    pub frozen: bool,
    /// Force accumulated at the last step, N.
    pub force: DVec3,
    /// Torque accumulated at the last step, N m.
    pub torque: DVec3,
}

/// One wall of a saved state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedWall {
    /// Name (walls are matched by name on loading).
    pub name: String,
    /// A point of the plane, m.
    pub point: DVec3,
    /// Unit normal.
    pub normal: DVec3,
    /// Velocity, m/s.
    pub velocity: DVec3,
    /// Load of the last step, N.
    pub load: DVec3,
}

/// The second body of a saved contact.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SavedBody {
    /// A grain, by its index in [`SavedState::grains`].
    Grain(u32),
    /// A wall, by name.
    Wall(String),
}

/// One contact of a saved state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedContact {
    /// The law's Rust type name: the contact is restored only into the same law.
    pub law: String,
    /// First body: a grain, by index in [`SavedState::grains`].
    pub a: u32,
    /// Second body; grain `a` itself for a vacant row of the law's table (a row kept for
    /// the next new contact of `a`'s region, [`Contact::is_vacant`]), which a resumed run
    /// needs to hand rows out as the saved run would.
    pub b: SavedBody,
    /// Unit normal of the last evaluation (from `b` towards `a`).
    pub normal: DVec3,
    /// Overlap of the last evaluation, m.
    pub overlap: f64,
    /// Contact point of the last evaluation, m: derived (grain `a`'s centre plus its
    /// branch vector, [`ContactGeometry::point`]), for readers of the file; optional, and
    /// ignored on restore.
    #[serde(default)]
    pub point: DVec3,
    /// Force on `a` of the last evaluation, N.
    pub force: DVec3,
    /// Torque on `a`, N m.
    pub torque_a: DVec3,
    /// Torque on `b`, N m.
    pub torque_b: DVec3,
    /// The law's per-contact history, as RON text.
    pub history: String,
}

/// The periodic box of a saved state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedPeriodicBox {
    /// Lower corner, m.
    pub lo: DVec3,
    /// Upper corner, m.
    pub hi: DVec3,
    /// Periodic axes.
    pub axes: [bool; 3],
}

/// Everything a run needs to continue: see the module documentation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SavedState {
    /// [`STATE_FORMAT`] of the writer.
    pub format: u32,
    /// Version of Talus that wrote it.
    pub talus_version: String,
    /// Name of the scene that ran.
    pub scene: String,
    /// 2 or 3.
    pub dimension: u8,
    /// Time step of the run, s.
    pub time_step: f64,
    /// Steps done.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// The periodic box, if the scene has one.
    pub periodic: Option<SavedPeriodicBox>,
    /// Grains, in the run's dense order.
    pub grains: Vec<SavedGrain>,
    /// Walls.
    pub walls: Vec<SavedWall>,
    /// Contacts, in the order their forces are summed.
    pub contacts: Vec<SavedContact>,
    /// Energy flows so far.
    pub ledger: EnergyLedger,
    /// Energies of the saved state (the first sample of a resumed run).
    pub energy: EnergySnapshot,
    /// The Gear integrator's derivatives, when it is the integrator.
    pub gear: Option<GearHistory>,
    /// How far a sequential deposition has got, when the scene deposits.
    #[serde(default)]
    pub deposition: Option<crate::packing::DepositionProgress>,
}

impl SavedState {
    /// Takes the state of a simulation after a completed step (or the priming pass).
    pub fn capture(world: &mut World, scene: &str) -> Self {
        // One capture for both kinds of state: the binary encoding, read back at once.
        let mut bytes = Vec::new();
        encode_state(world, scene, &mut bytes).expect("writing to memory cannot fail");
        decode_state(&bytes, world.get_resource::<ContactLawTable>())
            .expect("a state just encoded decodes")
    }

    /// Writes the state as RON.
    pub fn write(&self, path: &Path) -> Result<(), String> {
        let text = ron::ser::to_string_pretty(
            self,
            ron::ser::PrettyConfig::new()
                .depth_limit(2)
                .struct_names(false),
        )
        .map_err(|e| format!("cannot encode the state: {e}"))?;
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
    }

    /// Reads a state written by [`Self::write`].
    pub fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read the state {}: {e}", path.display()))?;
        let state: Self = ron::from_str(&text).map_err(|e| {
            format!(
                "{}:{}:{}: not a Talus state file: {}",
                path.display(),
                e.span.start.line,
                e.span.start.col,
                e.code
            )
        })?;
        if state.format != STATE_FORMAT {
            return Err(format!(
                "{}: state format {} (this Talus reads format {STATE_FORMAT})",
                path.display(),
                state.format
            ));
        }
        Ok(state)
    }
}

/// Whether a state restores the clock and energy totals (a resumed run) or only the
/// bodies and contacts (a new scene that starts from a packing).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RestoreMode {
    /// Continue the saved run: clock, energy totals, forces and integrator history too.
    Resume,
    /// Start a new run from the saved bodies and contacts, at time 0.
    StartFrom,
}

/// Re-creates the saved contacts between grains already spawned (`grains[i]` is the
/// entity of saved grain `i`) and the walls of the world (matched by name; a wall
/// contact is kept only when the wall's plane is the saved one). A contact whose pair
/// is now served by another law, or by none, is dropped: the narrow phase creates it
/// afresh if the bodies touch. Returns how many contacts were restored.
pub fn restore_contacts(
    world: &mut World,
    state: &SavedState,
    grains: &[Entity],
) -> Result<usize, String> {
    let table = world.resource::<ContactLawTable>().clone();
    let mut walls: HashMap<String, (Entity, u16, DVec3, DVec3)> = HashMap::new();
    let mut q = world.query::<(Entity, &Wall)>();
    for (e, w) in q.iter(world) {
        walls.insert(w.name.clone(), (e, w.material.0, w.point, w.normal));
    }
    let saved_walls: HashMap<&str, &SavedWall> =
        state.walls.iter().map(|w| (w.name.as_str(), w)).collect();
    let mut restored = 0;
    for (k, c) in state.contacts.iter().enumerate() {
        let Some(&a) = grains.get(c.a as usize) else {
            return Err(format!("contacts[{k}]: grain {} is not in the state", c.a));
        };
        let mat_a = world.get::<MaterialId>(a).map_or(0, |m| m.0);
        let (b, kind, mat_b) = match &c.b {
            SavedBody::Grain(j) => {
                let Some(&b) = grains.get(*j as usize) else {
                    return Err(format!("contacts[{k}]: grain {j} is not in the state"));
                };
                (
                    b,
                    ContactKind::GrainGrain,
                    world.get::<MaterialId>(b).map_or(0, |m| m.0),
                )
            }
            SavedBody::Wall(name) => {
                let Some(&(b, mat, point, normal)) = walls.get(name) else {
                    continue;
                };
                let same_plane = saved_walls
                    .get(name.as_str())
                    .is_some_and(|w| w.point == point && w.normal == normal);
                if !same_plane {
                    continue;
                }
                (b, ContactKind::GrainWall, mat)
            }
        };
        let vacant = c.b == SavedBody::Grain(c.a);
        let slot = if vacant {
            // A vacant row (a grain paired with itself) of its law's table.
            table
                .slots
                .iter()
                .flatten()
                .find(|slot| slot.law_type == c.law)
        } else {
            table
                .get(mat_a, mat_b)
                .filter(|slot| slot.law_type == c.law)
        };
        let Some(slot) = slot else {
            continue;
        };
        let contact = if vacant {
            Contact::vacant(a)
        } else {
            Contact {
                a,
                b,
                kind,
                pair_slot: slot.pair_slot,
            }
        };
        let geometry = ContactGeometry {
            normal: c.normal,
            overlap: c.overlap,
        };
        let force = ContactForce {
            force: c.force,
            torque_a: c.torque_a,
            torque_b: c.torque_b,
        };
        let e = (slot.restore)(world, contact, geometry, force, &c.history)
            .map_err(|e| format!("contacts[{k}].history: {e}"))?;
        if vacant {
            // Not a contact: the narrow phase finds it among its table's vacant rows.
            continue;
        }
        world
            .resource_mut::<talus_collision::narrow::ContactIndex>()
            .register(a, b, e);
        restored += 1;
    }
    Ok(restored)
}

/// Opens every binary state: "TALUS", "BS" for binary state, and the format version.
const BINARY_MAGIC: [u8; 8] = *b"TALUSBS\x02";

/// The opening of format 1, still read: its contacts carry their contact point
/// ([`ContactGeometryPartsWithPoint`]), which format 2 derives instead.
const BINARY_MAGIC_1: [u8; 8] = *b"TALUSBS\x01";

/// The parts of a binary state before its grains.
#[derive(Serialize, Deserialize)]
struct BinaryHeader {
    /// Everything but the grains and contacts (those lists are empty here).
    state: SavedState,
    /// Material names, indexed by [`BinaryGrain::material`].
    materials: Vec<String>,
    /// Law type names, indexed by [`BinaryContact::law`].
    laws: Vec<String>,
    /// How many grains follow.
    grains: u64,
}

/// One grain of a binary state: a [`SavedGrain`] with its material as an index.
#[derive(Serialize, Deserialize)]
struct BinaryGrain {
    position: DVec3,
    velocity: DVec3,
    angular_velocity: DVec3,
    force: DVec3,
    torque: DVec3,
    radius: f64,
    mass: f64,
    inertia: f64,
    material: u16,
    frozen: bool,
}

/// The second body of a [`BinaryContact`].
#[derive(Serialize, Deserialize)]
enum BinaryBody {
    /// A grain, by index in the state's grains.
    Grain(u32),
    /// A wall, by index in the state's walls.
    Wall(u32),
}

/// One contact of a binary state; `H` is its law's history in the law's own binary
/// encoding (`&[u8]` when written, `Vec<u8>` when read).
#[derive(Serialize, Deserialize)]
struct BinaryContact<H, G = ContactGeometryParts> {
    a: u32,
    b: BinaryBody,
    /// Index into [`BinaryHeader::laws`].
    law: u16,
    geometry: G,
    force: ContactForceParts,
    history: H,
}

/// [`ContactGeometry`] as plain fields.
#[derive(Serialize, Deserialize)]
struct ContactGeometryParts(DVec3, f64);

/// A contact's geometry in format 1: normal, overlap and the contact point (not read).
#[derive(Serialize, Deserialize)]
struct ContactGeometryPartsWithPoint(DVec3, f64, DVec3);

impl From<ContactGeometryPartsWithPoint> for ContactGeometryParts {
    fn from(
        ContactGeometryPartsWithPoint(normal, overlap, _): ContactGeometryPartsWithPoint,
    ) -> Self {
        Self(normal, overlap)
    }
}

/// One entry of a binary state's contact list (`None` at its end) and the bytes after it.
type ContactAndRest<'a> = (Option<BinaryContact<Vec<u8>>>, &'a [u8]);

/// [`take_contact`] for one format's geometry.
type TakeContact = for<'a> fn(&'a [u8]) -> postcard::Result<ContactAndRest<'a>>;

/// Reads the next entry of a binary state's contact list, whose geometry is encoded as
/// `G`: `None` at the list's end.
fn take_contact<G: serde::de::DeserializeOwned + Into<ContactGeometryParts>>(
    bytes: &[u8],
) -> postcard::Result<ContactAndRest<'_>> {
    let (c, rest): (Option<BinaryContact<Vec<u8>, G>>, _) = postcard::take_from_bytes(bytes)?;
    let c = c.map(|c| BinaryContact {
        a: c.a,
        b: c.b,
        law: c.law,
        geometry: c.geometry.into(),
        force: c.force,
        history: c.history,
    });
    Ok((c, rest))
}

/// [`ContactForce`] as plain fields.
#[derive(Serialize, Deserialize)]
struct ContactForceParts(DVec3, DVec3, DVec3);

fn encode_error(e: impl std::fmt::Display) -> String {
    format!("cannot encode the state: {e}")
}

/// Appends one item's postcard encoding to `out`, through the reused buffer `buf`
/// (`postcard::to_io` would flush the writer after every item: a system call per grain).
fn put(item: &impl Serialize, buf: &mut Vec<u8>, out: &mut impl Write) -> Result<(), String> {
    buf.clear();
    *buf = postcard::to_extend(item, std::mem::take(buf)).map_err(encode_error)?;
    out.write_all(buf).map_err(encode_error)
}

/// Writes the state of a simulation after a completed step (or the priming pass) in
/// Talus's binary state format: a header, then the grains, then the contacts, each item
/// in postcard's encoding, streamed straight from the world (no copy of the state is
/// held: `talus run` writes its last good state this way at every report).
fn encode_state(world: &mut World, scene: &str, out: &mut impl Write) -> Result<(), String> {
    // The grains' components hold the last step's end state only after a step that was
    // not left for another, or after `Simulation::synchronize`.
    debug_assert!(
        !world
            .get_resource::<talus_core::resources::DeferredKick>()
            .is_some_and(|d| d.snapshot_holds_motion),
        "a state saved while the snapshot holds the motion: synchronize first"
    );
    debug_assert!(
        !world
            .get_resource::<talus_core::resources::FrozenTotals>()
            .is_some_and(|f| f.pending),
        "a state saved with the frozen grains' totals left unsummed: synchronize first"
    );
    let config = world.resource::<SimConfig>().clone();
    let clock = *world.resource::<Clock>();
    let materials: Vec<String> = world
        .resource::<Materials>()
        .0
        .iter()
        .map(|m| m.name.clone())
        .collect();
    let table = world.get_resource::<ContactLawTable>().cloned();
    let mut laws: Vec<String> = Vec::new();
    for slot in table.iter().flat_map(|t| t.slots.iter().flatten()) {
        if !laws.iter().any(|l| l == slot.law_type) {
            laws.push(slot.law_type.to_string());
        }
    }
    let mut walls = Vec::new();
    let mut wall_entities: Vec<(Entity, u16)> = Vec::new();
    let mut q = world.query::<(Entity, &Wall, &WallLoad)>();
    for (e, w, l) in q.iter(world) {
        wall_entities.push((e, w.material.0));
        walls.push(SavedWall {
            name: w.name.clone(),
            point: w.point,
            normal: w.normal,
            velocity: w.velocity,
            load: l.0,
        });
    }
    let periodic = world
        .get_resource::<PeriodicBox>()
        .map(|b| SavedPeriodicBox {
            lo: b.lo,
            hi: b.hi,
            axes: b.axes,
        });
    let state = SavedState {
        format: STATE_FORMAT,
        talus_version: env!("CARGO_PKG_VERSION").to_string(),
        scene: scene.to_string(),
        dimension: config.dimension.as_number(),
        time_step: config.dt,
        step: clock.step,
        time: clock.time,
        periodic,
        grains: Vec::new(),
        walls,
        contacts: Vec::new(),
        ledger: world.resource::<EnergyLedger>().clone(),
        energy: world.resource::<EnergySnapshot>().clone(),
        deposition: world
            .get_resource::<crate::packing::Deposition>()
            .map(|d| d.progress),
        gear: match config.integrator {
            Integrator::Gear => world.get_resource::<GearHistory>().cloned(),
            _ => None,
        },
    };
    let mut grains = world.query_filtered::<(
        Entity,
        (&Position, &Velocity, &AngularVelocity, &Radius),
        (&Mass, &MomentOfInertia, &MaterialId, &Force, &Torque),
        Has<Frozen>,
    ), With<Grain>>();
    out.write_all(&BINARY_MAGIC).map_err(encode_error)?;
    let header = BinaryHeader {
        state,
        materials,
        laws,
        grains: grains.iter(world).len() as u64,
    };
    let mut buf = Vec::new();
    put(&header, &mut buf, out)?;
    // Grain index of each grain entity, by entity index (no hashing: a state of half a
    // million grains is written at every report). A contact's bodies are checked to be
    // live grains by looking their material up, which also picks the contact's law.
    let mut index: Vec<u32> = Vec::new();
    for (k, (e, (p, v, w, r), (m, i, mat, f, t), frozen)) in grains.iter(world).enumerate() {
        let slot = e.index_u32() as usize;
        if index.len() <= slot {
            index.resize(slot + 1, u32::MAX);
        }
        index[slot] = k as u32;
        let grain = BinaryGrain {
            position: p.0,
            velocity: v.0,
            angular_velocity: w.0,
            force: f.0,
            torque: t.0,
            radius: r.0,
            mass: m.0,
            inertia: i.0,
            material: mat.0,
            frozen,
        };
        put(&grain, &mut buf, out)?;
    }
    let grain_of = |world: &World, e: Entity| {
        let material = world
            .get::<MaterialId>(e)
            .filter(|_| world.get::<Grain>(e).is_some())?;
        let k = index.get(e.index_u32() as usize).copied()?;
        (k != u32::MAX).then_some((k, material.0))
    };
    // Contacts follow, each tagged `Some`, and a `None` ends them (a contact whose body
    // is gone is skipped, so their number is known only at the end).
    if let Some(table) = table {
        let mut history = Vec::new();
        let mut q = world.query::<(Entity, &Contact, &ContactGeometry, &ContactForce)>();
        for (e, c, g, f) in q.iter(world) {
            let Some((a, mat_a)) = grain_of(world, c.a) else {
                continue;
            };
            let (b, mat_b) = match c.kind {
                ContactKind::GrainGrain => match grain_of(world, c.b) {
                    Some((j, mat_b)) => (BinaryBody::Grain(j), mat_b),
                    None => continue,
                },
                ContactKind::GrainWall => match wall_entities.iter().position(|&(w, _)| w == c.b) {
                    Some(k) => (BinaryBody::Wall(k as u32), wall_entities[k].1),
                    None => continue,
                },
            };
            // A vacant row belongs to the law of its table, whatever its grain's material.
            let slot = if c.is_vacant() {
                table.by_archetype(world.entity(e).location().archetype_id)
            } else {
                table.get(mat_a, mat_b)
            };
            let Some(slot) = slot else {
                continue;
            };
            history.clear();
            if !(slot.history_bytes)(world, e, &mut history)? {
                continue;
            }
            let contact = BinaryContact {
                a,
                b,
                law: header
                    .laws
                    .iter()
                    .position(|l| l == slot.law_type)
                    .unwrap_or(0) as u16,
                geometry: ContactGeometryParts(g.normal, g.overlap),
                force: ContactForceParts(f.force, f.torque_a, f.torque_b),
                history: history.as_slice(),
            };
            put(&Some(contact), &mut buf, out)?;
        }
    }
    put(&None::<BinaryContact<&[u8]>>, &mut buf, out)?;
    Ok(())
}

/// Reads a state written by [`encode_state`], turning material and wall indices into
/// names and each contact's history into RON text by its law in `table`.
fn decode_state(bytes: &[u8], table: Option<&ContactLawTable>) -> Result<SavedState, String> {
    let fail = |e: postcard::Error| format!("not a readable binary state: {e}");
    let (rest, take_contact): (_, TakeContact) = match (
        bytes.strip_prefix(&BINARY_MAGIC),
        bytes.strip_prefix(&BINARY_MAGIC_1),
    ) {
        (Some(rest), _) => (rest, take_contact::<ContactGeometryParts>),
        (None, Some(rest)) => (rest, take_contact::<ContactGeometryPartsWithPoint>),
        (None, None) => {
            return Err(
                "not a Talus binary state (its first bytes are not TALUSBS, format 1 or 2)".into(),
            );
        }
    };
    let (header, mut rest): (BinaryHeader, _) = postcard::take_from_bytes(rest).map_err(fail)?;
    let BinaryHeader {
        mut state,
        materials,
        laws,
        grains,
    } = header;
    let material = |k: u16| {
        materials
            .get(k as usize)
            .cloned()
            .ok_or_else(|| format!("material {k} is not in the binary state"))
    };
    for _ in 0..grains {
        let (g, tail): (BinaryGrain, _) = postcard::take_from_bytes(rest).map_err(fail)?;
        rest = tail;
        state.grains.push(SavedGrain {
            position: g.position,
            velocity: g.velocity,
            angular_velocity: g.angular_velocity,
            radius: g.radius,
            mass: g.mass,
            inertia: g.inertia,
            material: material(g.material)?,
            frozen: g.frozen,
            force: g.force,
            torque: g.torque,
        });
    }
    loop {
        let (c, tail) = take_contact(rest).map_err(fail)?;
        rest = tail;
        let Some(c) = c else { break };
        let law = laws
            .get(c.law as usize)
            .ok_or_else(|| format!("law {} is not in the binary state", c.law))?;
        let history = table
            .and_then(|t| t.slots.iter().flatten().find(|s| s.law_type == law))
            .and_then(|slot| (slot.history_text)(&c.history))
            .ok_or_else(|| format!("a contact's history of law {law} cannot be read"))?;
        let ContactGeometryParts(normal, overlap) = c.geometry;
        let point = state.grains.get(c.a as usize).map_or(DVec3::ZERO, |a| {
            ContactGeometry { normal, overlap }.point(a.position, a.radius)
        });
        let ContactForceParts(force, torque_a, torque_b) = c.force;
        state.contacts.push(SavedContact {
            law: law.clone(),
            a: c.a,
            b: match c.b {
                BinaryBody::Grain(j) => SavedBody::Grain(j),
                BinaryBody::Wall(k) => SavedBody::Wall(
                    state
                        .walls
                        .get(k as usize)
                        .ok_or_else(|| format!("wall {k} is not in the binary state"))?
                        .name
                        .clone(),
                ),
            },
            normal,
            overlap,
            point,
            force,
            torque_a,
            torque_b,
            history,
        });
    }
    Ok(state)
}

/// A run's last good state kept on disk in Talus's binary state format, rewritten at
/// every report: `talus run` holds no copy of the state in memory (that copy was about a
/// third of a large run's memory). Each write goes to a temporary file that then
/// replaces the previous one, so a failed write leaves the last complete state.
#[derive(Debug)]
pub struct BinaryStateFile {
    path: PathBuf,
    step: Option<u64>,
}

impl BinaryStateFile {
    /// A state file at `path`; nothing is written yet.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            step: None,
        }
    }

    /// Writes the state of a simulation after a completed step (or the priming pass),
    /// replacing the previous one.
    /// On failure the previous state stays in place and the temporary file is removed.
    pub fn write(&mut self, world: &mut World, scene: &str) -> Result<(), String> {
        let tmp = self.path.with_extension("tmp");
        let written = (|| {
            let file = std::fs::File::create(&tmp)
                .map_err(|e| format!("cannot write {}: {e}", tmp.display()))?;
            let mut out = std::io::BufWriter::with_capacity(1 << 16, file);
            encode_state(world, scene, &mut out)?;
            out.flush()
                .map_err(|e| format!("cannot write {}: {e}", tmp.display()))?;
            drop(out);
            std::fs::rename(&tmp, &self.path)
                .map_err(|e| format!("cannot write {}: {e}", self.path.display()))
        })();
        match written {
            Ok(()) => {
                self.step = Some(world.resource::<Clock>().step);
                Ok(())
            }
            Err(e) => {
                let _ = std::fs::remove_file(&tmp);
                Err(e)
            }
        }
    }

    /// Steps done when the state on disk was taken, if one was written.
    pub fn step(&self) -> Option<u64> {
        self.step
    }

    /// The state on disk as a [`SavedState`], with names and each contact's history as
    /// RON text (by the laws of `world`, the run that wrote it), to write as RON.
    pub fn read(&self, world: &World) -> Result<SavedState, String> {
        let bytes = std::fs::read(&self.path)
            .map_err(|e| format!("cannot read {}: {e}", self.path.display()))?;
        decode_state(&bytes, world.get_resource::<ContactLawTable>())
            .map_err(|e| format!("{}: {e}", self.path.display()))
    }
}

/// Dropping the handle deletes the file: a run that ended well needs no last good state,
/// one that blew up has it as RON, and an early return leaves no scratch file behind.
impl Drop for BinaryStateFile {
    fn drop(&mut self) {
        if self.step.is_some() {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A contact list of format 1 (each geometry with its contact point) reads as the same
    /// contacts as one of format 2, the point dropped; the list ends at its `None`.
    #[test]
    fn contacts_of_binary_format_1_are_still_read() {
        let (normal, overlap, point) = (DVec3::new(0.0, 0.6, 0.8), 1e-5, DVec3::splat(2.5));
        let force = || ContactForceParts(DVec3::X, DVec3::Y, DVec3::Z);
        let history = [7u8, 8, 9];
        let mut old = postcard::to_allocvec(&Some(BinaryContact {
            a: 3,
            b: BinaryBody::Wall(1),
            law: 2,
            geometry: ContactGeometryPartsWithPoint(normal, overlap, point),
            force: force(),
            history: &history[..],
        }))
        .unwrap();
        old.extend(postcard::to_allocvec(&None::<BinaryContact<&[u8]>>).unwrap());
        let mut new = postcard::to_allocvec(&Some(BinaryContact {
            a: 3,
            b: BinaryBody::Wall(1),
            law: 2,
            geometry: ContactGeometryParts(normal, overlap),
            force: force(),
            history: &history[..],
        }))
        .unwrap();
        new.extend(postcard::to_allocvec(&None::<BinaryContact<&[u8]>>).unwrap());
        assert!(old.len() > new.len(), "format 1 carries the point");
        let read = |bytes: &[u8], take: TakeContact| {
            let (c, rest) = take(bytes).unwrap();
            let c = c.expect("a contact");
            let (end, rest) = take(rest).unwrap();
            assert!(end.is_none() && rest.is_empty(), "the list ends after it");
            let ContactGeometryParts(n, o) = c.geometry;
            let ContactForceParts(f, ta, tb) = c.force;
            let wall = matches!(c.b, BinaryBody::Wall(1));
            (c.a, wall, c.law, n, o, f, ta, tb, c.history)
        };
        assert_eq!(
            read(&old, take_contact::<ContactGeometryPartsWithPoint>),
            read(&new, take_contact::<ContactGeometryParts>)
        );
        assert_eq!(
            read(&new, take_contact::<ContactGeometryParts>),
            (
                3,
                true,
                2,
                normal,
                overlap,
                DVec3::X,
                DVec3::Y,
                DVec3::Z,
                history.to_vec()
            )
        );
    }

    #[test]
    fn floats_survive_the_text_round_trip_exactly() {
        // Awkward values: subnormals, many digits, extremes, negative zero.
        let mut x = 0x1234_5678_9abc_def0_u64;
        let mut values = vec![
            0.1,
            1.0 / 3.0,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            -0.0,
            1e300,
            // The largest subnormal, written as it is often quoted.
            #[allow(clippy::excessive_precision)]
            2.2250738585072009e-308,
        ];
        for _ in 0..2000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let v = f64::from_bits(x);
            if v.is_finite() {
                values.push(v);
            }
        }
        let grains: Vec<SavedGrain> = values
            .chunks(3)
            .filter(|c| c.len() == 3)
            .map(|c| SavedGrain {
                position: DVec3::new(c[0], c[1], c[2]),
                velocity: DVec3::new(c[2], c[0], c[1]),
                angular_velocity: DVec3::ZERO,
                radius: c[0],
                mass: c[1],
                inertia: c[2],
                material: "m".into(),
                frozen: false,
                force: DVec3::ZERO,
                torque: DVec3::ZERO,
            })
            .collect();
        let text = ron::to_string(&grains).unwrap();
        let back: Vec<SavedGrain> = ron::from_str(&text).unwrap();
        for (a, b) in grains.iter().zip(&back) {
            for (p, q) in [
                (a.position, b.position),
                (a.velocity, b.velocity),
                (
                    DVec3::new(a.radius, a.mass, a.inertia),
                    DVec3::new(b.radius, b.mass, b.inertia),
                ),
            ] {
                for d in 0..3 {
                    assert_eq!(p[d].to_bits(), q[d].to_bits(), "{} vs {}", p[d], q[d]);
                }
            }
        }
    }
}
