//! Time integration (velocity Verlet or symplectic Euler, for translation and
//! rotation), gravity, kinetic energy and the health check.
//!
//! Both schemes are "kick, drift, force, kick" with different kick fractions:
//! velocity Verlet kicks half a step on each side of the drift, symplectic Euler a
//! whole step before it. Loops run over contiguous component slices with rayon.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use crate::components::*;
use crate::energy::{EnergyLedger, EnergySnapshot};
use crate::lanes::{F4, V4};
use crate::resources::{BlowUp, Clock, DeferredKick, Health, KineticEnergyDue, SimConfig};
use crate::snapshot::{GrainRecord, GrainSnapshot};

/// Grains below this count are integrated on one thread: spawning tasks costs more.
const PARALLEL_THRESHOLD: usize = 4096;

/// Chunk length for the fixed-shape parallel reductions (results do not depend on threads).
const REDUCTION_CHUNK: usize = 1024;

/// First kick and drift: v += a·dt·F/m, then x += dt·v. Also accumulates the work of
/// gravity over the drift, m g·Δx, which is exact for a uniform field. A second kick the
/// last step left pending ([`DeferredKick`]) is applied first, grain by grain in the same
/// pass, and the velocities it leaves are checked finite for the health check (through
/// the gravity work, which any non-finite velocity makes non-finite).
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
pub fn kick_drift_translation(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    mut ledger: ResMut<EnergyLedger>,
    mut deferred: ResMut<DeferredKick>,
    mut health: ResMut<Health>,
    mut snapshot: ResMut<GrainSnapshot>,
    mut grains: Query<
        (&mut Position, &mut Velocity, &Force, &Mass),
        (With<Grain>, Without<Frozen>),
    >,
    moving: Query<(Entity, &Force, &Mass), (With<Grain>, Without<Frozen>)>,
    periodic: Option<Res<crate::periodic::PeriodicBox>>,
) {
    let dt = clock.pass_dt;
    if dt == 0.0 {
        return;
    }
    let kick = config.integrator.kick_before_drift() * dt;
    let g = config.gravity;
    let pending = deferred.translation.take();
    if deferred.snapshot_holds_motion {
        // The last step's state is the snapshot's: kick and drift its records in place
        // (a grain's velocity and position in one line), the components untouched.
        let kicks = Kicks::new(pending, kick);
        // Each record is wrapped into the periodic box right after its drift, as the
        // snapshot asks (`GrainSnapshot::kick_drift_held`); a copy of the loop for each
        // case, so that the grain loop carries no test of it. The two drifts are written
        // out: one drift closure shared by both copies made the stage 1.6 times as long
        // (its share of the step 0.15 → 0.25 on 1 thread, session 51).
        let update = |records: &mut [GrainRecord],
                      f: &[Force],
                      m: &[Mass],
                      wrap: Option<&crate::periodic::WrapRule>| {
            match wrap {
                Some(wrap) => kick_records(records, f, m, kicks, |r, k| {
                    let dx = r.velocity * dt;
                    r.position += dx;
                    wrap.apply(&mut r.position);
                    m[k].0 * g.dot(dx)
                }),
                None => kick_records(records, f, m, kicks, |r, k| {
                    let dx = r.velocity * dt;
                    r.position += dx;
                    m[k].0 * g.dot(dx)
                }),
            }
        };
        let gravity_work = snapshot.kick_drift_held(
            moving.contiguous_iter().expect("grain query is dense"),
            (REDUCTION_CHUNK, PARALLEL_THRESHOLD),
            periodic.map(|p| *p),
            update,
        );
        ledger.gravity_work += gravity_work;
        if pending.is_some() {
            health.motion_finite = gravity_work.is_finite();
        }
        return;
    }
    let mut gravity_work = 0.0;
    let kicks = Kicks::new(pending, kick);
    for (mut p, mut v, f, m) in grains.contiguous_iter_mut().expect("grain query is dense") {
        let p = p.bypass_change_detection();
        let v = v.bypass_change_detection();
        let update =
            |((p, v), (f, m)): ((&mut [Position], &mut [Velocity]), (&[Force], &[Mass]))| {
                let drift = |v: &mut Velocity, k: usize| {
                    let dx = v.0 * dt;
                    p[k].0 += dx;
                    m[k].0 * g.dot(dx)
                };
                kick_blocks(v, f, m, kicks, |f| f.0, |m| m.0, velocity_of, drift)
            };
        gravity_work += if p.len() >= PARALLEL_THRESHOLD {
            let partial: Vec<f64> = p
                .par_chunks_mut(REDUCTION_CHUNK)
                .zip(v.par_chunks_mut(REDUCTION_CHUNK))
                .zip(
                    f.par_chunks(REDUCTION_CHUNK)
                        .zip(m.par_chunks(REDUCTION_CHUNK)),
                )
                .map(update)
                .collect();
            partial.iter().sum::<f64>()
        } else {
            update(((p, v), (f, m)))
        };
    }
    ledger.gravity_work += gravity_work;
    if pending.is_some() {
        health.motion_finite = gravity_work.is_finite();
    }
}

/// The first kick and a second kick the last step left pending, resolved once per pass
/// so that a loop over grains carries no branch on them ([`kick_blocks`]): the pending
/// kick's `F/m` times its time is added first, then the first kick's, the operations of
/// the two separate passes in their order. Under velocity Verlet the two kicks span the
/// same half step, and their common increment is computed once (the same bits as
/// computing it twice).
#[derive(Clone, Copy, Debug)]
enum Kicks {
    /// The first kick alone, by this time, s.
    One(f64),
    /// A pending kick as long as the first: their common increment, added twice.
    SameTwice(f64),
    /// A pending kick (the first time, s), then the first kick (the second).
    Two(f64, f64),
}

impl Kicks {
    /// The kicks for a pending second kick's time (if any) and the first kick's.
    fn new(pending: Option<f64>, kick: f64) -> Self {
        match pending {
            Some(first) if first == kick => Self::SameTwice(kick),
            Some(first) => Self::Two(first, kick),
            None => Self::One(kick),
        }
    }
}

/// A snapshot record's velocity, for [`kick_blocks`].
#[inline(always)]
fn record_velocity(r: &mut GrainRecord) -> &mut DVec3 {
    &mut r.velocity
}

/// [`kick_blocks`] over snapshot records, `then` drifting each (a function of its own so
/// that each drift closure gets its own inlined copy of the loop).
#[inline(always)]
fn kick_records(
    records: &mut [GrainRecord],
    forces: &[Force],
    masses: &[Mass],
    kicks: Kicks,
    then: impl FnMut(&mut GrainRecord, usize) -> f64,
) -> f64 {
    kick_blocks(
        records,
        forces,
        masses,
        kicks,
        |f| f.0,
        |m| m.0,
        record_velocity,
        then,
    )
}

/// A grain's velocity, for [`kick_blocks`].
#[inline(always)]
fn velocity_of(v: &mut Velocity) -> &mut DVec3 {
    &mut v.0
}

/// A grain's spin, for [`kick_blocks`].
#[inline(always)]
fn spin_of(w: &mut AngularVelocity) -> &mut DVec3 {
    &mut w.0
}

/// Grains kicked a block at a time by [`kick_blocks`].
const KICK_BLOCK: usize = 64;

/// Kicks each item's velocity (reached by `velocity`) by its force over its mass times
/// the times of `kicks`, then hands it to `then` with its index in `items`,
/// and returns the sum of what `then` returns, taken in order as `Iterator::sum` takes it.
/// A block's divisions (time over mass) come first, in a loop of their own that the
/// compiler runs four at a time (a division is correctly rounded either way, so the bits
/// are the same); inside the grain loop each update waited on its own division.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn kick_blocks<T, F: Copy, M: Copy>(
    items: &mut [T],
    forces: &[F],
    masses: &[M],
    kicks: Kicks,
    force: impl Fn(F) -> DVec3,
    mass: impl Fn(M) -> f64,
    velocity: impl Fn(&mut T) -> &mut DVec3,
    mut then: impl FnMut(&mut T, usize) -> f64,
) -> f64 {
    let mut sum = -0.0;
    let (mut first_scale, mut kick_scale) = ([0.0; KICK_BLOCK], [0.0; KICK_BLOCK]);
    let blocks = items
        .chunks_mut(KICK_BLOCK)
        .zip(forces.chunks(KICK_BLOCK).zip(masses.chunks(KICK_BLOCK)));
    for (b, (items, (forces, masses))) in blocks.enumerate() {
        let base = b * KICK_BLOCK;
        let (first_time, kick_time) = match kicks {
            Kicks::One(kick) | Kicks::SameTwice(kick) => (None, kick),
            Kicks::Two(first, kick) => (Some(first), kick),
        };
        for (scale, &m) in kick_scale.iter_mut().zip(masses) {
            *scale = kick_time / mass(m);
        }
        if let Some(first_time) = first_time {
            for (scale, &m) in first_scale.iter_mut().zip(masses) {
                *scale = first_time / mass(m);
            }
        }
        let grains = items.iter_mut().zip(forces).enumerate();
        match kicks {
            Kicks::One(_) => {
                for (k, (item, &f)) in grains {
                    *velocity(item) += force(f) * kick_scale[k];
                    sum += then(item, base + k);
                }
            }
            Kicks::SameTwice(_) => {
                for (k, (item, &f)) in grains {
                    let dv = force(f) * kick_scale[k];
                    let v = velocity(item);
                    *v += dv;
                    *v += dv;
                    sum += then(item, base + k);
                }
            }
            Kicks::Two(..) => {
                for (k, (item, &f)) in grains {
                    let f = force(f);
                    let v = velocity(item);
                    *v += f * first_scale[k];
                    *v += f * kick_scale[k];
                    sum += then(item, base + k);
                }
            }
        }
    }
    sum
}

/// First rotational kick: ω += a·dt·T/I (spheres need no orientation for contact physics).
/// A rotational second kick the last step left pending ([`DeferredKick`]) is applied first,
/// in the same pass, and the spins it leaves are checked finite for the health check.
#[allow(clippy::type_complexity)]
pub fn first_kick_rotation(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    mut deferred: ResMut<DeferredKick>,
    mut health: ResMut<Health>,
    mut snapshot: ResMut<GrainSnapshot>,
    mut grains: Query<
        (Entity, &mut AngularVelocity, &Torque, &MomentOfInertia),
        (With<Grain>, Without<Frozen>),
    >,
) {
    let kick = config.integrator.kick_before_drift() * clock.pass_dt;
    if kick == 0.0 {
        return;
    }
    let pending = deferred.rotation.take();
    let held = deferred.snapshot_holds_motion;
    let s = &mut *snapshot;
    let mut finite = true;
    for (e, mut w, t, i) in grains.contiguous_iter_mut().expect("grain query is dense") {
        // The spins of the last step are the snapshot's when it holds the motion.
        finite &= if held {
            let range = s.table_range(e);
            kick_spins(&mut s.omega[range], |w| w, t, i, pending, kick)
        } else {
            kick_spins(w.bypass_change_detection(), spin_of, t, i, pending, kick)
        };
    }
    if pending.is_some() {
        health.motion_finite &= finite;
    }
}

/// The first rotational kick of one table's spins (`spin` reaches the vector of an
/// element of `w`); when a kick was pending, whether every spin it left is finite (else
/// true: the second kick checked them).
fn kick_spins<W: Send>(
    w: &mut [W],
    spin: impl Fn(&mut W) -> &mut DVec3 + Sync,
    t: &[Torque],
    i: &[MomentOfInertia],
    pending: Option<f64>,
    kick: f64,
) -> bool {
    let kicks = Kicks::new(pending, kick);
    let kick_chunk = |(w, (t, i)): (&mut [W], (&[Torque], &[MomentOfInertia]))| {
        kick_blocks(w, t, i, kicks, |t| t.0, |i| i.0, &spin, |_, _| 0.0);
        // Without a branch or a chain of floating-point additions (see `finite_marker`).
        pending.is_none()
            || w.iter_mut().fold(true, |all, w| {
                let x = *spin(w);
                all & x.x.is_finite() & x.y.is_finite() & x.z.is_finite()
            })
    };
    if w.len() >= PARALLEL_THRESHOLD {
        // Chunks, each a plain loop: rayon's per-item plumbing costs more than a kick.
        w.par_chunks_mut(PARALLEL_THRESHOLD)
            .zip(
                t.par_chunks(PARALLEL_THRESHOLD)
                    .zip(i.par_chunks(PARALLEL_THRESHOLD)),
            )
            // One chunk a job, so that no thread is left to kick a run of them alone at
            // the end of the loop (as in `GrainSnapshot::kick_drift_held`).
            .with_max_len(1)
            .map(kick_chunk)
            .reduce(|| true, |a, b| a & b)
    } else {
        kick_chunk((w, (t, i)))
    }
}

/// Adds m·g to every grain's force (the contact stage has already overwritten it).
pub fn gravity(config: Res<SimConfig>, mut grains: Query<(&mut Force, &Mass), With<Grain>>) {
    let g = config.gravity;
    for (mut f, m) in grains.contiguous_iter_mut().expect("grain query is dense") {
        let f = f.bypass_change_detection();
        let update = |(f, m): (&mut Force, &Mass)| f.0 += g * m.0;
        if f.len() >= PARALLEL_THRESHOLD {
            f.par_chunks_mut(PARALLEL_THRESHOLD)
                .zip(m.par_chunks(PARALLEL_THRESHOLD))
                .for_each(|(f, m)| f.iter_mut().zip(m).for_each(update));
        } else {
            f.iter_mut().zip(m.iter()).for_each(update);
        }
    }
}

/// Servo-controlled walls: velocity along the normal = gain × (target load − load), the
/// load being the grains' push on the wall at the end of the last step (compressive
/// positive), clamped to the servo's largest speed. Scheduled only when a wall has one.
pub fn servo_walls(mut walls: Query<(&mut Wall, &WallLoad, &Servo)>) {
    for (mut wall, load, servo) in &mut walls {
        let n = wall.normal;
        let pushed = -load.0.dot(n);
        let speed =
            (servo.gain * (servo.target_load - pushed)).clamp(-servo.max_speed, servo.max_speed);
        wall.velocity = n * speed;
    }
}

/// Strain-rate walls: each step the wall moves along its normal by share × L(1 − e^{−rate·dt}),
/// L the gap between its plane and its opposite's at the start of the step, so that the
/// gap follows L(t) = L₀ e^{−rate·t} exactly at the step times (not just to O(dt)).
/// Scheduled only when a wall has one.
pub fn strain_rate_walls(
    clock: Res<Clock>,
    drives: Query<(Entity, &StrainRateDrive)>,
    mut walls: Query<&mut Wall>,
) {
    let dt = clock.pass_dt;
    for (entity, drive) in &drives {
        let gap = match (walls.get(entity), walls.get(drive.opposite)) {
            (Ok(wall), Ok(opposite)) => (wall.point - opposite.point).dot(opposite.normal),
            _ => continue,
        };
        // (1 − e^{−rate·dt})/dt, the rate of the exact exponential over one step; rate itself
        // for a pass without a step.
        let mean_rate = if dt > 0.0 {
            -(-drive.rate * dt).exp_m1() / dt
        } else {
            drive.rate
        };
        if let Ok(mut wall) = walls.get_mut(entity) {
            let n = wall.normal;
            wall.velocity = n * (drive.share * mean_rate * gap);
        }
    }
}

/// Prescribed wall motion: point += dt · velocity.
pub fn move_walls(clock: Res<Clock>, mut walls: Query<&mut Wall>) {
    let dt = clock.pass_dt;
    for mut wall in &mut walls {
        if wall.velocity != DVec3::ZERO {
            let v = wall.velocity;
            wall.point += v * dt;
        }
    }
}

/// The grain columns the second kick and the kinetic-energy sums read (velocities and spins
/// writable for the kick).
type KineticQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static mut Velocity,
        &'static mut AngularVelocity,
        &'static Mass,
        &'static MomentOfInertia,
        &'static Force,
        &'static Torque,
    ),
    (With<Grain>, Without<Frozen>),
>;

/// Translational and rotational kinetic energy of the grains, and the staggering term
/// that turns them into the kinetic energy the integrator conserves exactly.
///
/// Both schemes are leapfrogs: the force F of the current positions kicks the velocity
/// from v₋ (before) to v₊ = v₋ + dt F/m (after). The trapezoidal work of the forces
/// equals the change of ½ m v₋·v₊ step by step, so that is the kinetic energy the
/// balance uses; it differs from ½ m v² by an O(dt²) term that vanishes with the force.
///
/// Scheduled on its own in [`Stage::Sample`](crate::schedule::Stage::Sample) for the Gear
/// integrator (it then changes nothing: the pass of [`second_kick_and_kinetic_energy`] with
/// no kick); the leapfrogs sum the same terms while they kick.
pub fn kinetic_energy(
    config: Res<SimConfig>,
    mut energy: ResMut<EnergySnapshot>,
    mut health: ResMut<Health>,
    mut grains: KineticQuery,
) {
    kick_and_sum_kinetic(&config, 0.0, true, &mut energy, &mut health, &mut grains);
}

/// Brings the kinetic energies of the [`EnergySnapshot`] up to date with the grains'
/// state, with the same sums, bit for bit, as the second kick takes: for a driver that
/// cleared [`KineticEnergyDue`] for a step and then needs them after it (a run stopped
/// at a step it did not plan to report).
pub fn sum_kinetic_energy(world: &mut World) {
    use bevy_ecs::system::RunSystemOnce;
    world
        .run_system_once(kinetic_energy)
        .expect("the core resources are installed");
}

/// Second kick of translation (and of rotation when it is integrated), v += (1 − a)·dt·F/m
/// and ω += (1 − a)·dt·T/I, followed in the same pass by the kinetic-energy sums of
/// [`kinetic_energy`] over the kicked state: one read of the velocities, spins, forces,
/// torques, masses and inertias instead of two. Each chunk is kicked whole before it is
/// summed, with the same operations in the same order as the two separate passes, so the
/// state and the sums are the same to the bit. At a step for which [`KineticEnergyDue`]
/// is cleared the sums are not taken; the velocities and spins are only checked finite.
pub fn second_kick_and_kinetic_energy(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    due: Res<KineticEnergyDue>,
    mut energy: ResMut<EnergySnapshot>,
    mut health: ResMut<Health>,
    mut deferred: ResMut<DeferredKick>,
    mut grains: KineticQuery,
) {
    // Zero in the priming pass: nothing moves, the energies are still sampled.
    let kick = (1.0 - config.integrator.kick_before_drift()) * clock.pass_dt;
    if deferred.allowed && !due.0 && kick != 0.0 {
        // Left to the next step's first kick (or `apply_deferred_kick`); the health
        // check reads what this step's first kick found.
        deferred.translation = Some(kick);
        deferred.rotation = config.rotation.then_some(kick);
        // The snapshot's records and spins are this step's positions, velocities and
        // spins (the components too, unless this step's kicks worked on the snapshot):
        // the next step may kick and drift them in place.
        deferred.snapshot_holds_motion = deferred.may_hold_motion;
        return;
    }
    debug_assert!(
        !deferred.snapshot_holds_motion,
        "a step that kicks to its end works on the components"
    );
    kick_and_sum_kinetic(&config, kick, due.0, &mut energy, &mut health, &mut grains);
}

/// Applies the second kick the last step left pending ([`DeferredKick`]), so that the
/// grains' velocities and spins are those of the step's end, bit for bit as if the step
/// had kicked them itself; the kinetic energies are not summed (see
/// [`sum_kinetic_energy`]). Does nothing when no kick is pending.
pub fn apply_deferred_kick(world: &mut World) {
    use bevy_ecs::system::RunSystemOnce;
    let pending = world
        .get_resource::<DeferredKick>()
        .is_some_and(|d| d.translation.is_some() || d.rotation.is_some());
    if pending {
        world
            .run_system_once(finish_deferred_kick)
            .expect("the core resources are installed");
    }
}

/// The system of [`apply_deferred_kick`]: the pending kick through the second kick's own
/// pass (translation and rotation are left pending together, by the same amount).
fn finish_deferred_kick(
    config: Res<SimConfig>,
    mut deferred: ResMut<DeferredKick>,
    mut energy: ResMut<EnergySnapshot>,
    mut health: ResMut<Health>,
    mut grains: KineticQuery,
) {
    let translation = deferred.translation.take();
    let rotation = deferred.rotation.take();
    if let Some(kick) = translation.or(rotation) {
        kick_and_sum_kinetic(&config, kick, false, &mut energy, &mut health, &mut grains);
    }
}

/// Writes the positions, velocities and spins that the snapshot holds in place of the
/// grains' components ([`DeferredKick::snapshot_holds_motion`]) back into the components,
/// which then hold the last step's state again. Does nothing when the snapshot holds none.
pub fn write_back_held_motion(world: &mut World) {
    use bevy_ecs::system::RunSystemOnce;
    let held = world
        .get_resource::<DeferredKick>()
        .is_some_and(|d| d.snapshot_holds_motion);
    if held {
        world
            .run_system_once(copy_held_motion)
            .expect("the core resources are installed");
    }
}

/// The system of [`write_back_held_motion`], table by table, in parallel chunks.
#[allow(clippy::type_complexity)]
fn copy_held_motion(
    mut deferred: ResMut<DeferredKick>,
    snapshot: Res<GrainSnapshot>,
    mut grains: Query<(Entity, &mut Position, &mut Velocity, &mut AngularVelocity), With<Grain>>,
) {
    deferred.snapshot_holds_motion = false;
    for (e, mut p, mut v, mut w) in grains.contiguous_iter_mut().expect("grain query is dense") {
        let range = snapshot.table_range(e);
        let (p, v, w) = (
            p.bypass_change_detection(),
            v.bypass_change_detection(),
            w.bypass_change_detection(),
        );
        p.par_chunks_mut(REDUCTION_CHUNK)
            .zip(v.par_chunks_mut(REDUCTION_CHUNK))
            .zip(w.par_chunks_mut(REDUCTION_CHUNK))
            .zip(
                snapshot.records[range.clone()]
                    .par_chunks(REDUCTION_CHUNK)
                    .zip(snapshot.omega[range].par_chunks(REDUCTION_CHUNK)),
            )
            .for_each(|(((p, v), w), (records, omega))| {
                for ((p, v), (w, (r, o))) in p
                    .iter_mut()
                    .zip(v)
                    .zip(w.iter_mut().zip(records.iter().zip(omega)))
                {
                    p.0 = r.position;
                    v.0 = r.velocity;
                    w.0 = *o;
                }
            });
    }
}

/// Kicks every chunk of grains by `kick` (nothing when 0; spins only with rotation) and,
/// when `sum`, sums its kinetic energies ([`kinetic_energy`]) while it is in cache, per
/// fixed chunk of grains, the chunks in order: the same sums on any number of threads.
/// Records in `health` whether every velocity and spin came out finite (from the sums
/// when they are taken, else from a finiteness marker per chunk).
fn kick_and_sum_kinetic(
    config: &SimConfig,
    kick: f64,
    sum: bool,
    energy: &mut EnergySnapshot,
    health: &mut Health,
    grains: &mut KineticQuery,
) {
    let terms = KineticTerms::new(config);
    let mut partial: Vec<[f64; 3]> = Vec::new();
    for (mut v, mut w, m, i, f, t) in grains.contiguous_iter_mut().expect("grain query is dense") {
        let (v, w) = (v.bypass_change_detection(), w.bypass_change_detection());
        partial.par_extend(
            v.par_chunks_mut(REDUCTION_CHUNK)
                .zip(w.par_chunks_mut(REDUCTION_CHUNK))
                .zip(
                    m.par_chunks(REDUCTION_CHUNK)
                        .zip(i.par_chunks(REDUCTION_CHUNK)),
                )
                .zip(
                    f.par_chunks(REDUCTION_CHUNK)
                        .zip(t.par_chunks(REDUCTION_CHUNK)),
                )
                .map(|(((v, w), (m, i)), (f, t))| {
                    // The chunk (48 KiB of velocities and spins) is still in cache when
                    // it is summed.
                    if kick != 0.0 {
                        let kicks = Kicks::One(kick);
                        kick_blocks(v, f, m, kicks, |f| f.0, |m| m.0, velocity_of, |_, _| 0.0);
                        if terms.rotation {
                            kick_blocks(w, t, i, kicks, |t| t.0, |i| i.0, spin_of, |_, _| 0.0);
                        }
                    }
                    if sum {
                        terms.chunk_sums(v, w, m, i, f, t)
                    } else {
                        [finite_marker(v, w), 0.0, 0.0]
                    }
                }),
        );
    }
    if sum {
        energy.store_kinetic(&partial);
    }
    // A NaN or an infinity in a velocity or a spin reaches its chunk's sums or its marker.
    health.motion_finite = partial.iter().flatten().all(|x| x.is_finite());
}

/// 0 when every velocity and spin of a chunk is finite, NaN otherwise. The tests are
/// and-ed without a branch or a chain of floating-point additions (a running sum of
/// x − x, one addition a number in a row, cost as much as the kinetic sums themselves).
fn finite_marker(v: &[Velocity], w: &[AngularVelocity]) -> f64 {
    let finite = |x: DVec3| x.x.is_finite() & x.y.is_finite() & x.z.is_finite();
    let all = v.iter().fold(true, |all, v| all & finite(v.0))
        & w.iter().fold(true, |all, w| all & finite(w.0));
    if all { 0.0 } else { f64::NAN }
}

/// The coefficients of the kinetic-energy sums for the run's integrator.
#[derive(Clone, Copy)]
struct KineticTerms {
    /// Coefficient of v·F (and ω·T) in the staggering term.
    linear: f64,
    /// Coefficient of |F|²/m (and |T|²/I) in the staggering term.
    quadratic: f64,
    /// Whether torques kick spins (without rotation they are computed but never used).
    rotation: bool,
}

impl KineticTerms {
    fn new(config: &SimConfig) -> Self {
        // The configured step, also in the priming pass (whose own step is 0): the
        // staggering belongs to the scheme the run will use, so the first sample already
        // carries it and the balance does not jump at step 1.
        let dt = config.dt;
        // Stored velocity v = v₋ + (1 − a) dt F/m, so v₋ = v − (1 − a) dt F/m and
        // v₊ = v + a dt F/m: ½ m v₋·v₊ − ½ m v² = ½ dt (2a − 1) v·F − ½ a (1 − a) dt² |F|²/m.
        let a = config.integrator.kick_before_drift();
        // Gear is not a leapfrog: no staggering term (its energy error shows in the balance).
        let leapfrog = config.integrator != crate::resources::Integrator::Gear;
        Self {
            linear: if leapfrog {
                0.5 * dt * (2.0 * a - 1.0)
            } else {
                0.0
            },
            quadratic: if leapfrog {
                0.5 * a * (1.0 - a) * dt * dt
            } else {
                0.0
            },
            rotation: config.rotation,
        }
    }

    /// Σ½mv², Σ½Iω² and the staggering term over one chunk of grains. Four grains at a
    /// time, each lane summing every fourth grain of the chunk; the lanes are added in a
    /// fixed order at the end of the chunk.
    #[inline]
    fn chunk_sums(
        self,
        v: &[Velocity],
        w: &[AngularVelocity],
        m: &[Mass],
        i: &[MomentOfInertia],
        f: &[Force],
        t: &[Torque],
    ) -> [f64; 3] {
        let mut sums = Sums4::default();
        let n = v.len();
        let (w, m, i, f, t) = (&w[..n], &m[..n], &i[..n], &f[..n], &t[..n]);
        let full = n / 4 * 4;
        for (((v, w), (m, i)), (f, t)) in v[..full]
            .chunks_exact(4)
            .zip(w[..full].chunks_exact(4))
            .zip(m[..full].chunks_exact(4).zip(i[..full].chunks_exact(4)))
            .zip(f[..full].chunks_exact(4).zip(t[..full].chunks_exact(4)))
        {
            sums.add(self, Grain4::load(0, 4, v, w, m, i, f, t));
        }
        if full < n {
            sums.add(self, Grain4::load(full, n - full, v, w, m, i, f, t));
        }
        sums.total()
    }
}

/// Lane sums of Σ½mv², Σ½Iω² and the staggering term.
struct Sums4([F4; 3]);

impl Default for Sums4 {
    fn default() -> Self {
        Self([F4::zero(); 3])
    }
}

impl Sums4 {
    /// Adds four grains' terms, one per lane.
    #[inline(always)]
    fn add(&mut self, terms: KineticTerms, g: Grain4) {
        let (half, linear, quadratic) = (
            F4::splat(0.5),
            F4::splat(terms.linear),
            F4::splat(terms.quadratic),
        );
        let sums = &mut self.0;
        sums[0] = sums[0] + half * g.m * g.v.length_squared();
        sums[1] = sums[1] + half * g.i * g.w.length_squared();
        sums[2] = sums[2] + (linear * g.v.dot(g.f) - quadratic * g.f.length_squared() / g.m);
        if terms.rotation {
            sums[2] = sums[2] + (linear * g.w.dot(g.t) - quadratic * g.t.length_squared() / g.i);
        }
    }

    /// The lanes added in a fixed order.
    fn total(&self) -> [f64; 3] {
        self.0.map(|lanes| {
            let [a, b, c, d] = lanes.to_array();
            (a + b) + (c + d)
        })
    }
}

/// Four grains' state for the kinetic-energy sums, one per lane.
struct Grain4 {
    v: V4,
    w: V4,
    f: V4,
    t: V4,
    m: F4,
    i: F4,
}

impl Grain4 {
    /// Grains `k..k + live` of the columns; the lanes past `live` hold a grain at rest,
    /// unloaded, of unit mass and inertia, which adds zero to every sum.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn load(
        k: usize,
        live: usize,
        v: &[Velocity],
        w: &[AngularVelocity],
        m: &[Mass],
        i: &[MomentOfInertia],
        f: &[Force],
        t: &[Torque],
    ) -> Self {
        Self {
            v: lanes3(k, live, v, |x| x.0),
            w: lanes3(k, live, w, |x| x.0),
            f: lanes3(k, live, f, |x| x.0),
            t: lanes3(k, live, t, |x| x.0),
            m: lanes1(k, live, m, |x| x.0),
            i: lanes1(k, live, i, |x| x.0),
        }
    }
}

/// Vectors `k..k + live` of a column in lanes, zero past `live`.
#[inline(always)]
fn lanes3<T>(k: usize, live: usize, column: &[T], value: impl Fn(&T) -> DVec3) -> V4 {
    V4::from_fn(|l| {
        if l < live {
            value(&column[k + l])
        } else {
            DVec3::ZERO
        }
    })
}

/// Numbers `k..k + live` of a column in lanes, one past `live`.
#[inline(always)]
fn lanes1<T>(k: usize, live: usize, column: &[T], value: impl Fn(&T) -> f64) -> F4 {
    F4::from_fn(|l| if l < live { value(&column[k + l]) } else { 1.0 })
}

/// Stops the run on a non-finite velocity or spin after the kick (a non-finite force or
/// position reaches one), or on an overlap beyond the bound in [`Health`]. The grains it
/// names are those with a non-finite position, velocity or spin, or a moving grain with a
/// non-finite force: a frozen grain's force total is not read (it may be left unsummed,
/// [`FrozenTotals`](crate::resources::FrozenTotals)), and a contact that gives one a
/// non-finite force gives its moving partner the same.
#[allow(clippy::type_complexity)]
pub fn health_check(
    clock: Res<Clock>,
    energy: Res<EnergySnapshot>,
    mut health: ResMut<Health>,
    deferred: Option<Res<DeferredKick>>,
    snapshot: Option<Res<GrainSnapshot>>,
    grains: Query<
        (
            Entity,
            &Position,
            &Velocity,
            &AngularVelocity,
            &Force,
            Has<Frozen>,
        ),
        With<Grain>,
    >,
) {
    if health.blow_up.is_some() {
        return;
    }
    if !health.motion_finite {
        // The last step's motion is the snapshot's when it holds it, else the components';
        // the forces are the components'.
        let held = deferred.is_some_and(|d| d.snapshot_holds_motion);
        let finite = |x: DVec3| x.is_finite();
        let force_finite = |f: &Force, frozen: bool| frozen || finite(f.0);
        let bad: Vec<Entity> = match snapshot.filter(|_| held) {
            Some(s) => {
                let motion = (0..s.len()).filter(|&k| {
                    let r = &s.records[k];
                    !(finite(r.position) && finite(r.velocity) && finite(s.omega[k]))
                });
                let mut bad: Vec<Entity> = motion.map(|k| s.entity[k]).take(16).collect();
                let forces: Vec<Entity> = grains
                    .iter()
                    .filter(|&(e, .., f, frozen)| !force_finite(f, frozen) && !bad.contains(&e))
                    .map(|(e, ..)| e)
                    .take(16 - bad.len())
                    .collect();
                bad.extend(forces);
                bad
            }
            None => grains
                .iter()
                .filter(|&(_, p, v, w, f, frozen)| {
                    !(finite(p.0) && finite(v.0) && finite(w.0) && force_finite(f, frozen))
                })
                .map(|(e, ..)| e)
                .take(16)
                .collect(),
        };
        health.blow_up = Some(BlowUp {
            step: clock.step,
            reason: "a position, velocity, spin or force became NaN or infinite".into(),
            entities: bad,
        });
        return;
    }
    if energy.max_overlap_ratio > health.max_overlap_ratio {
        health.blow_up = Some(BlowUp {
            step: clock.step,
            reason: format!(
                "overlap / radius reached {:.4}, above the bound {} (time step too large or contact too soft?)",
                energy.max_overlap_ratio, health.max_overlap_ratio
            ),
            entities: energy
                .worst_overlap_pair
                .map(|(a, b)| vec![a, b])
                .unwrap_or_default(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy_ecs::system::RunSystemOnce;

    /// A world with the resources the second kick and the health check read, and
    /// `count` grains in motion and under load (grain `k`'s state scaled by k + 1).
    fn world_with_grains(count: usize, due: bool) -> (World, Vec<Entity>) {
        let mut world = World::new();
        world.insert_resource(SimConfig {
            dimension: crate::resources::Dimension::Three,
            dt: 1e-4,
            gravity: DVec3::ZERO,
            integrator: crate::resources::Integrator::VelocityVerlet,
            rotation: true,
        });
        world.insert_resource(Clock {
            step: 1,
            time: 1e-4,
            pass_dt: 1e-4,
        });
        world.insert_resource(KineticEnergyDue(due));
        world.insert_resource(EnergySnapshot::default());
        world.insert_resource(Health::default());
        world.insert_resource(DeferredKick::default());
        let grains = (0..count)
            .map(|k| {
                let s = (k + 1) as f64;
                world
                    .spawn((
                        Grain,
                        Position(DVec3::new(s, 0.0, 0.0)),
                        Velocity(DVec3::new(0.3, -0.2, 0.1) * s),
                        AngularVelocity(DVec3::new(-1.0, 2.0, 0.5) * s),
                        Mass(2.0 + 0.1 * s),
                        MomentOfInertia(0.01 * s),
                        Force(DVec3::new(1.0, 0.5, -2.0) * s),
                        Torque(DVec3::new(0.01, -0.02, 0.03) * s),
                    ))
                    .id()
            })
            .collect();
        (world, grains)
    }

    /// The energies summed on demand after a step whose kick did not sum them are those,
    /// bit for bit, that the kick sums when they are due: Σ½mv² and Σ½Iω² of the kicked
    /// state, checked against their own formula as well.
    #[test]
    fn energies_summed_on_demand_are_those_of_the_kick() {
        let count = 3000; // Three chunks, the last one partial.
        let (mut due_world, _) = world_with_grains(count, true);
        due_world
            .run_system_once(second_kick_and_kinetic_energy)
            .unwrap();
        let (mut world, _) = world_with_grains(count, false);
        world
            .run_system_once(second_kick_and_kinetic_energy)
            .unwrap();
        assert_eq!(
            *world.resource::<EnergySnapshot>(),
            EnergySnapshot::default(),
            "not due: the snapshot is left as it was"
        );
        assert!(world.resource::<Health>().motion_finite);
        sum_kinetic_energy(&mut world);
        let (on_demand, in_kick) = (
            world.resource::<EnergySnapshot>(),
            due_world.resource::<EnergySnapshot>(),
        );
        assert_eq!(on_demand, in_kick);
        let on_demand = on_demand.clone();
        let mut grains = world.query::<(&Velocity, &AngularVelocity, &Mass, &MomentOfInertia)>();
        let (translational, rotational) = grains.iter(&world).fold((0.0, 0.0), |(t, r), g| {
            (
                t + 0.5 * g.2.0 * g.0.0.length_squared(),
                r + 0.5 * g.3.0 * g.1.0.length_squared(),
            )
        });
        assert!((on_demand.translational_kinetic - translational).abs() <= 1e-12 * translational);
        assert!((on_demand.rotational_kinetic - rotational).abs() <= 1e-12 * rotational);
    }

    /// A NaN velocity or an infinite spin stops the run at the step it appears, whether
    /// the step sums the kinetic energies or not, naming the grain.
    #[test]
    fn a_non_finite_velocity_or_spin_stops_the_run_at_any_step() {
        for due in [true, false] {
            for spin in [false, true] {
                let (mut world, grains) = world_with_grains(2000, due);
                let bad = grains[1234];
                if spin {
                    world.get_mut::<AngularVelocity>(bad).unwrap().0.y = f64::INFINITY;
                } else {
                    world.get_mut::<Velocity>(bad).unwrap().0.z = f64::NAN;
                }
                world
                    .run_system_once(second_kick_and_kinetic_energy)
                    .unwrap();
                assert!(
                    !world.resource::<Health>().motion_finite,
                    "due {due}, spin {spin}"
                );
                world.run_system_once(health_check).unwrap();
                let blow_up = world.resource::<Health>().blow_up.clone();
                let blow_up = blow_up.expect("the run is stopped");
                assert_eq!(blow_up.step, 1);
                assert_eq!(blow_up.entities, vec![bad], "due {due}, spin {spin}");
            }
        }
        // And a finite state does not stop it.
        let (mut world, _) = world_with_grains(2000, false);
        world
            .run_system_once(second_kick_and_kinetic_energy)
            .unwrap();
        world.run_system_once(health_check).unwrap();
        assert!(world.resource::<Health>().blow_up.is_none());
    }
}
