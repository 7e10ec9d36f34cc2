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

use std::any::Any;
use std::collections::HashMap;
use std::path::Path;

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
    /// Second body.
    pub b: SavedBody,
    /// Unit normal of the last evaluation (from `b` towards `a`).
    pub normal: DVec3,
    /// Overlap of the last evaluation, m.
    pub overlap: f64,
    /// Contact point of the last evaluation, m.
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
        CompactState::capture(world, scene).to_saved()
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
        let Some(slot) = table.get(mat_a, mat_b) else {
            continue;
        };
        if slot.law_type != c.law {
            continue;
        }
        let contact = Contact {
            a,
            b,
            kind,
            pair_slot: slot.pair_slot,
        };
        let geometry = ContactGeometry {
            normal: c.normal,
            overlap: c.overlap,
            point: c.point,
        };
        let force = ContactForce {
            force: c.force,
            torque_a: c.torque_a,
            torque_b: c.torque_b,
        };
        let e = (slot.restore)(world, contact, geometry, force, &c.history)
            .map_err(|e| format!("contacts[{k}].history: {e}"))?;
        world
            .resource_mut::<talus_collision::narrow::ContactIndex>()
            .register(a, b, e);
        restored += 1;
    }
    Ok(restored)
}

#[cfg(test)]
mod tests {
    use super::*;

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

/// One grain of a [`CompactState`]: a [`SavedGrain`] with its material as an index.
#[derive(Clone, Copy, Debug)]
struct CompactGrain {
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

/// The second body of a [`CompactContact`].
#[derive(Clone, Copy, Debug)]
enum CompactBody {
    /// A grain, by index in the state's grains.
    Grain(u32),
    /// A wall, by index in the state's walls.
    Wall(u32),
}

/// One contact of a [`CompactState`]: its law's history is a copy of the law's own value.
struct CompactContact {
    a: u32,
    b: CompactBody,
    /// The law's Rust type name (see [`SavedContact::law`]).
    law: &'static str,
    /// Turns [`Self::history`] into RON text.
    history_text: fn(&(dyn Any + Send + Sync)) -> Option<String>,
    geometry: ContactGeometry,
    force: ContactForce,
    history: Box<dyn Any + Send + Sync>,
}

/// The state of a run held in memory, as `talus run` keeps its last good state: what a
/// [`SavedState`] holds, with materials and walls as indices and each contact's history as
/// a copy of the law's own value rather than RON text. A contact then takes about a third
/// of the memory of a [`SavedContact`] (whose history text alone is a few hundred bytes).
/// [`Self::to_saved`] makes the [`SavedState`] to write.
pub struct CompactState {
    /// Everything but the grains and contacts (those lists are empty here).
    header: SavedState,
    material_names: Vec<String>,
    grains: Vec<CompactGrain>,
    contacts: Vec<CompactContact>,
}

impl CompactState {
    /// Takes the state of a simulation after a completed step (or the priming pass).
    pub fn capture(world: &mut World, scene: &str) -> Self {
        let config = world.resource::<SimConfig>().clone();
        let clock = world.resource::<Clock>().clone();
        let material_names: Vec<String> = world
            .resource::<Materials>()
            .0
            .iter()
            .map(|m| m.name.clone())
            .collect();
        // Grain index of each grain entity, by entity index (no hashing: a state of half a
        // million grains is taken at every report).
        let mut index: Vec<u32> = Vec::new();
        let mut q = world.query_filtered::<(
            Entity,
            (&Position, &Velocity, &AngularVelocity, &Radius),
            (&Mass, &MomentOfInertia, &MaterialId, &Force, &Torque),
            Has<Frozen>,
        ), With<Grain>>();
        // Sized once: growing by doubling would hold the old and the new buffer at once.
        let count = q.iter(world).len();
        let mut grain_entities: Vec<Entity> = Vec::with_capacity(count);
        let mut grains = Vec::with_capacity(count);
        for (e, (p, v, w, r), (m, i, mat, f, t), frozen) in q.iter(world) {
            let slot = e.index_u32() as usize;
            if index.len() <= slot {
                index.resize(slot + 1, u32::MAX);
            }
            index[slot] = grains.len() as u32;
            grain_entities.push(e);
            grains.push(CompactGrain {
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
            });
        }
        let grain_of = |e: Entity| {
            index
                .get(e.index_u32() as usize)
                .copied()
                .filter(|&k| k != u32::MAX && grain_entities[k as usize] == e)
        };
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
        let mut contacts = Vec::new();
        if let Some(table) = world.get_resource::<ContactLawTable>().cloned() {
            let mut q = world.query::<(Entity, &Contact, &ContactGeometry, &ContactForce)>();
            contacts.reserve_exact(q.iter(world).len());
            for (e, c, g, f) in q.iter(world) {
                let Some(a) = grain_of(c.a) else { continue };
                let (b, mat_b) = match c.kind {
                    ContactKind::GrainGrain => match grain_of(c.b) {
                        Some(j) => (CompactBody::Grain(j), grains[j as usize].material),
                        None => continue,
                    },
                    ContactKind::GrainWall => {
                        match wall_entities.iter().position(|&(w, _)| w == c.b) {
                            Some(k) => (CompactBody::Wall(k as u32), wall_entities[k].1),
                            None => continue,
                        }
                    }
                };
                let Some(slot) = table.get(grains[a as usize].material, mat_b) else {
                    continue;
                };
                let Some(history) = (slot.history)(world, e) else {
                    continue;
                };
                contacts.push(CompactContact {
                    a,
                    b,
                    law: slot.law_type,
                    history_text: slot.history_text,
                    geometry: *g,
                    force: *f,
                    history,
                });
            }
        }
        let periodic = world
            .get_resource::<PeriodicBox>()
            .map(|b| SavedPeriodicBox {
                lo: b.lo,
                hi: b.hi,
                axes: b.axes,
            });
        let header = SavedState {
            format: STATE_FORMAT,
            talus_version: env!("CARGO_PKG_VERSION").to_string(),
            scene: scene.to_string(),
            dimension: config.dimension.as_number() as u8,
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
        Self {
            header,
            material_names,
            grains,
            contacts,
        }
    }

    /// Steps done when the state was taken.
    pub fn step(&self) -> u64 {
        self.header.step
    }

    /// The same state as a [`SavedState`], with names and RON text, to write or restore.
    pub fn to_saved(&self) -> SavedState {
        let grains = self
            .grains
            .iter()
            .map(|g| SavedGrain {
                position: g.position,
                velocity: g.velocity,
                angular_velocity: g.angular_velocity,
                radius: g.radius,
                mass: g.mass,
                inertia: g.inertia,
                material: self.material_names[g.material as usize].clone(),
                frozen: g.frozen,
                force: g.force,
                torque: g.torque,
            })
            .collect();
        let contacts = self
            .contacts
            .iter()
            .filter_map(|c| {
                Some(SavedContact {
                    law: c.law.to_string(),
                    a: c.a,
                    b: match c.b {
                        CompactBody::Grain(j) => SavedBody::Grain(j),
                        CompactBody::Wall(k) => {
                            SavedBody::Wall(self.header.walls[k as usize].name.clone())
                        }
                    },
                    normal: c.geometry.normal,
                    overlap: c.geometry.overlap,
                    point: c.geometry.point,
                    force: c.force.force,
                    torque_a: c.force.torque_a,
                    torque_b: c.force.torque_b,
                    history: (c.history_text)(&*c.history)?,
                })
            })
            .collect();
        SavedState {
            grains,
            contacts,
            ..self.header.clone()
        }
    }
}
