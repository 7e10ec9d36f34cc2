//! Time integration (velocity Verlet or symplectic Euler, for translation and
//! rotation), gravity, kinetic energy and the health check.
//!
//! Both schemes are "kick, drift, force, kick" with different kick fractions:
//! velocity Verlet kicks half a step on each side of the drift, symplectic Euler a
//! whole step before it. Loops run over contiguous component slices with rayon.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;
use smallvec::SmallVec;

use crate::components::*;
use crate::energy::{EnergyLedger, EnergySnapshot};
use crate::lanes::{F4, V4};
use crate::periodic::{PeriodicBox, PlainWrap};
use crate::resources::{BlowUp, Clock, Health, SimConfig};
use crate::snapshot::{ChunkMoves, FirstPassChunk, GrainRecord, GrainSnapshot, SnapshotRows};

/// Grains below this count are integrated on one thread: spawning tasks costs more.
const PARALLEL_THRESHOLD: usize = 4096;

/// Chunk length for the fixed-shape parallel reductions (results do not depend on threads).
const REDUCTION_CHUNK: usize = 1024;

/// The grain columns the step's first pass ([`kick_drift_snapshot`]) reads and writes.
type FirstPassQuery<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        (
            &'static mut Position,
            &'static mut Velocity,
            &'static mut AngularVelocity,
        ),
        (
            &'static Force,
            &'static Torque,
            &'static Mass,
            &'static MomentOfInertia,
        ),
        (&'static Radius, &'static MaterialId, Has<Frozen>),
    ),
    With<Grain>,
>;

/// Whether the step's first pass ([`kick_drift_snapshot`]) copies the grains into the
/// snapshot (the default, as without this resource), or leaves the copy to the broad
/// phase's [`crate::snapshot::gather_snapshot`] (for comparisons: the results are the
/// same to the bit).
#[derive(Resource, Clone, Copy, Debug)]
pub struct SnapshotInFirstPass(pub bool);

/// Grains per parallel work unit of the first pass, a multiple of `REDUCTION_CHUNK`.
const FIRST_PASS_CHUNK: usize = 4096;

/// What the first pass does to every moving grain of a chunk.
#[derive(Clone, Copy)]
struct FirstKick {
    /// Fraction of the step the first kick covers, times the step, s.
    kick: f64,
    /// The time step, s.
    dt: f64,
    /// Gravity, m/s².
    gravity: DVec3,
    /// Whether spins are kicked.
    rotate: bool,
}

impl FirstKick {
    /// One chunk of grains in one loop, each grain read once: kicked and drifted (when
    /// `moves`: v += a·dt·F/m, x += dt·v, and ω += a·dt·T/I when rotation is integrated),
    /// wrapped, and put into its row of the snapshot (when `rows`). Returns the gravity
    /// work over the drift, Σ m g·Δx (exact for a uniform field), of each part of `part`
    /// grains, each summed in grain order, and what the copy found. One loop, not one per
    /// task: separate loops over a chunk read its columns again from the cache, and a
    /// 512,000-grain packing's from memory (a chunk short enough to stay in cache ends
    /// each stream before the hardware's prefetch has caught up with it).
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    #[inline(never)]
    fn chunk(
        self,
        moves: bool,
        frozen: bool,
        wrap: Option<&PlainWrap>,
        part: usize,
        (p, v, w): (&mut [Position], &mut [Velocity], &mut [AngularVelocity]),
        (f, t, m, i, r, mat): (
            &[Force],
            &[Torque],
            &[Mass],
            &[MomentOfInertia],
            &[Radius],
            &[MaterialId],
        ),
        rows: Option<SnapshotRows>,
    ) -> FirstPassChunk {
        let n = p.len();
        let (v, w, f, t, m, i, r, mat) = (
            &mut v[..n],
            &mut w[..n],
            &f[..n],
            &t[..n],
            &m[..n],
            &i[..n],
            &r[..n],
            &mat[..n],
        );
        let step = Self {
            rotate: moves && self.rotate,
            ..self
        };
        let columns = (&mut *v, &mut *w, f, t, m, i, r, mat);
        // Two loops, with and without the copy, so that neither tests for it per grain.
        match rows {
            Some(rows) => {
                let (work, found) = step.pass::<true>(moves, frozen, wrap, part, p, columns, rows);
                (work, Some(found))
            }
            None => {
                let rows = SnapshotRows::none();
                (
                    step.pass::<false>(moves, frozen, wrap, part, p, columns, rows)
                        .0,
                    None,
                )
            }
        }
    }

    /// The loop of [`Self::chunk`], with the copy into `rows` when `COPY`. A plain loop
    /// over locals: the copy's running maxima and moves stay in registers.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    #[inline(always)]
    fn pass<const COPY: bool>(
        self,
        moves: bool,
        frozen: bool,
        wrap: Option<&PlainWrap>,
        part: usize,
        p: &mut [Position],
        (v, w, f, t, m, i, r, mat): (
            &mut [Velocity],
            &mut [AngularVelocity],
            &[Force],
            &[Torque],
            &[Mass],
            &[MomentOfInertia],
            &[Radius],
            &[MaterialId],
        ),
        mut rows: SnapshotRows,
    ) -> (SmallVec<[f64; 16]>, ChunkMoves) {
        let Self {
            kick,
            dt,
            gravity,
            rotate,
        } = self;
        let n = p.len();
        let mut found = rows.found();
        let mut work = SmallVec::new();
        let mut start = 0;
        while start < n {
            let end = (start + part).min(n);
            // The same start as `Iterator::sum`'s.
            let mut sum: f64 = std::iter::empty::<f64>().sum();
            for g in start..end {
                let (mut position, mut velocity) = (p[g].0, v[g].0);
                if moves {
                    velocity += f[g].0 * (kick / m[g].0);
                    let dx = velocity * dt;
                    position += dx;
                    sum += m[g].0 * gravity.dot(dx);
                    v[g].0 = velocity;
                }
                if rotate {
                    w[g].0 += t[g].0 * (kick / i[g].0);
                }
                if let Some(wrap) = wrap {
                    wrap.apply(&mut position);
                }
                p[g].0 = position;
                if COPY {
                    // A frozen grain resists like an infinite mass (a zero inverse): a
                    // contact's reduced mass is then the moving grain's own (as LAMMPS
                    // does for frozen atoms).
                    let record = GrainRecord {
                        position,
                        radius: r[g].0,
                        velocity,
                        inverse_mass: if frozen { 0.0 } else { 1.0 / m[g].0 },
                    };
                    rows.put(&mut found, g, record, w[g].0, mat[g].0);
                }
            }
            if moves {
                work.push(sum);
            }
            start = end;
        }
        (work, found.finish())
    }
}

/// The step's first pass over the grains, chunk by chunk while each chunk is in cache:
/// the first kick, v += a·dt·F/m (and ω += a·dt·T/I when rotation is integrated), the
/// drift x += dt·v with the work of gravity over it, m g·Δx (exact for a uniform field),
/// the wrap into an unsheared periodic box, and the copy of every grain into the step's
/// [`GrainSnapshot`] (records, spins, materials, the largest radius and the moves since the
/// neighbour list's reference), which [`crate::snapshot::gather_snapshot`] would otherwise make in a pass
/// of its own: one read of the grains' state instead of four (kick and drift, spin kick,
/// wrap, copy). Frozen grains are copied and wrapped, never moved. The same operations in
/// the same order as the separate passes, so the same state and sums to the bit.
///
/// The copy is left to [`crate::snapshot::gather_snapshot`] when a sheared box's wrap follows this pass
/// (it moves grains after it), or when some grain lacks a column this pass reads.
#[allow(clippy::too_many_arguments)]
pub fn kick_drift_snapshot(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    periodic: Option<Res<PeriodicBox>>,
    mut ledger: ResMut<EnergyLedger>,
    mut snapshot: ResMut<GrainSnapshot>,
    mut grains: FirstPassQuery,
    every_grain: Query<(), With<Grain>>,
    switch: Option<Res<SnapshotInFirstPass>>,
) {
    let dt = clock.pass_dt;
    let kick = config.integrator.kick_before_drift() * dt;
    let step = FirstKick {
        kick,
        dt,
        gravity: config.gravity,
        rotate: config.rotation && kick != 0.0,
    };
    let box_ = periodic.map(|p| *p);
    let sheared = box_.is_some_and(|b| b.shear.is_some());
    let wrap = box_.filter(|_| !sheared).map(PlainWrap::new);
    let n: usize = grains
        .contiguous_iter()
        .expect("grain query is dense")
        .map(|(e, ..)| e.len())
        .sum();
    let copies = !sheared && n == every_grain.iter().len() && switch.is_none_or(|switch| switch.0);
    let s = &mut *snapshot;
    s.set_periodic(box_);
    let mut copy = copies.then(|| s.begin_copy(n));
    // Each chunk's gravity work and what its copy found, in chunk order (the snapshot's
    // scratch list: no allocation a step).
    let mut partials = s.take_first_pass_scratch();
    let mut gravity_work = 0.0;
    for (e, (mut p, mut v, mut w), (f, t, m, i), (r, mat, frozen)) in
        grains.contiguous_iter_mut().expect("grain query is dense")
    {
        let (p, v, w) = (
            p.bypass_change_detection(),
            v.bypass_change_detection(),
            w.bypass_change_detection(),
        );
        // Nothing moves in the priming pass, nor a frozen grain ever.
        let moves = dt != 0.0 && !frozen;
        // Large tables in fixed chunks in parallel, the gravity work summed per part of
        // `REDUCTION_CHUNK` grains and the parts' sums in order (the same on any number of
        // threads); small tables whole, their gravity work in one sum.
        let (len, part) = if p.len() >= PARALLEL_THRESHOLD {
            (FIRST_PASS_CHUNK, REDUCTION_CHUNK)
        } else {
            (p.len().max(1), p.len().max(1))
        };
        let rows = copy.as_mut().map(|copy| copy.table(s, e));
        let chunk = |from: usize,
                     grains: (&mut [Position], &mut [Velocity], &mut [AngularVelocity]),
                     rows: Option<SnapshotRows>| {
            let to = from + grains.0.len();
            let columns = (
                &f[from..to],
                &t[from..to],
                &m[from..to],
                &i[from..to],
                &r[from..to],
                &mat[from..to],
            );
            step.chunk(moves, frozen, wrap.as_ref(), part, grains, columns, rows)
        };
        partials.clear();
        let grain_chunks = p
            .par_chunks_mut(len)
            .zip(v.par_chunks_mut(len))
            .zip(w.par_chunks_mut(len))
            .enumerate();
        match rows {
            Some(rows) => partials.par_extend(
                grain_chunks
                    .zip(rows.chunks(len))
                    .map(|((c, ((p, v), w)), (_, rows))| chunk(c * len, (p, v, w), Some(rows))),
            ),
            None => partials
                .par_extend(grain_chunks.map(|(c, ((p, v), w))| chunk(c * len, (p, v, w), None))),
        }
        if moves {
            gravity_work += partials.iter().flat_map(|(work, _)| work).sum::<f64>();
        }
        if let Some(copy) = &mut copy {
            copy.chunk_results
                .extend(partials.drain(..).filter_map(|(_, found)| found));
            copy.add_chunk_results(s);
        }
    }
    s.put_first_pass_scratch(partials);
    if let Some(copy) = copy {
        s.first_pass_copied(copy);
    }
    ledger.gravity_work += gravity_work;
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
    mut grains: KineticQuery,
) {
    kick_and_sum_kinetic(&config, 0.0, &mut energy, &mut grains);
}

/// Second kick of translation (and of rotation when it is integrated), v += (1 − a)·dt·F/m
/// and ω += (1 − a)·dt·T/I, followed in the same pass by the kinetic-energy sums of
/// [`kinetic_energy`] over the kicked state: one read of the velocities, spins, forces,
/// torques, masses and inertias instead of two. Each chunk is kicked whole before it is
/// summed, with the same operations in the same order as the two separate passes, so the
/// state and the sums are the same to the bit.
pub fn second_kick_and_kinetic_energy(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    mut energy: ResMut<EnergySnapshot>,
    mut grains: KineticQuery,
) {
    // Zero in the priming pass: nothing moves, the energies are still sampled.
    let kick = (1.0 - config.integrator.kick_before_drift()) * clock.pass_dt;
    kick_and_sum_kinetic(&config, kick, &mut energy, &mut grains);
}

/// Kicks every chunk of grains by `kick` (nothing when 0; spins only with rotation) and
/// sums its kinetic energies ([`kinetic_energy`]) while it is in cache, per fixed chunk of
/// grains, the chunks in order: the same sums on any number of threads.
fn kick_and_sum_kinetic(
    config: &SimConfig,
    kick: f64,
    energy: &mut EnergySnapshot,
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
                        for (v, (f, m)) in v.iter_mut().zip(f.iter().zip(m)) {
                            v.0 += f.0 * (kick / m.0);
                        }
                        if terms.rotation {
                            for (w, (t, i)) in w.iter_mut().zip(t.iter().zip(i)) {
                                w.0 += t.0 * (kick / i.0);
                            }
                        }
                    }
                    terms.chunk_sums(v, w, m, i, f, t)
                }),
        );
    }
    energy.store_kinetic(&partial);
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

/// Stops the run on a non-finite position, velocity or force, or on an overlap beyond
/// the bound in [`Health`].
pub fn health_check(
    clock: Res<Clock>,
    energy: Res<EnergySnapshot>,
    mut health: ResMut<Health>,
    grains: Query<(Entity, &Position, &Velocity, &Force), With<Grain>>,
) {
    if health.blow_up.is_some() {
        return;
    }
    let finite = energy.translational_kinetic.is_finite() && energy.rotational_kinetic.is_finite();
    if !finite {
        let bad: Vec<Entity> = grains
            .iter()
            .filter(|(_, p, v, f)| !(p.0.is_finite() && v.0.is_finite() && f.0.is_finite()))
            .map(|(e, ..)| e)
            .take(16)
            .collect();
        health.blow_up = Some(BlowUp {
            step: clock.step,
            reason: "a position, velocity or force became NaN or infinite".into(),
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
