//! Packing generation protocols a scene can name: sequential deposition (batches of
//! grains dropped into a container, each once the last has settled) and isotropic
//! compression of a periodic cell at a bounded inertial number. Each ends the run with a
//! [`StopRequest`] when its packing is ready; with `output: (state: true)` the run then
//! saves the packing for other scenes (`start_from`). See docs/physics/packing.md.

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use talus_contact::{Contact, ContactForce, ContactGeometry, ContactKind, unbalanced_force_ratio};
use talus_core::grain_order::RowsOfCells;
use talus_core::prelude::*;
use talus_core::resources::StopRequest;

use crate::generate::random_insertion;
use crate::schema::{RadiusSpec, Region};

/// How far a deposition has got (saved with a state, so that a resumed run goes on).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DepositionProgress {
    /// Batches inserted so far (the first at the start of the run).
    pub batches_inserted: usize,
}

/// A sequential deposition under way.
#[derive(Resource, Clone, Debug)]
pub struct Deposition {
    /// Insertion region.
    pub region: Region,
    /// Radius distribution.
    pub radius: RadiusSpec,
    /// Grains per batch.
    pub batch_size: usize,
    /// Batches in all.
    pub batches: usize,
    /// Seed of batch 0 (batch k uses seed + k).
    pub seed: u64,
    /// Mean kinetic energy per grain below which the grains count as settled, J.
    pub settle_kinetic_energy: f64,
    /// Unbalanced-force ratio below which the grains count as settled.
    pub unbalanced_force: f64,
    /// Steps between settling checks.
    pub check_every: u64,
    /// Material and density of the deposited grains.
    pub material: MaterialId,
    /// Density, kg/m³.
    pub density: f64,
    /// Progress.
    pub progress: DepositionProgress,
}

/// Settling check and insertion of the next batch (in [`Stage::Sample`], after the
/// energies of the step are known).
pub fn deposition(world: &mut World) {
    let step = world.resource::<Clock>().step;
    let check_every = world.resource::<Deposition>().check_every;
    if step == 0 || !step.is_multiple_of(check_every) {
        return;
    }
    let dep = world.resource::<Deposition>().clone();
    let mut q = world.query_filtered::<(), (With<Grain>, Without<Frozen>)>();
    let n = q.iter(world).count().max(1);
    let e = world.resource::<EnergySnapshot>();
    let mean_kinetic = (e.translational_kinetic + e.rotational_kinetic) / n as f64;
    if mean_kinetic > dep.settle_kinetic_energy {
        return;
    }
    let ratio = unbalanced_force_ratio(world);
    if ratio.is_none_or(|r| r > dep.unbalanced_force) {
        return;
    }
    if dep.progress.batches_inserted >= dep.batches {
        world.resource_mut::<StopRequest>().0 = Some(format!(
            "deposited: {} batches settled (mean kinetic energy {mean_kinetic:.3e} J per grain, unbalanced-force ratio {:.3e})",
            dep.batches,
            ratio.unwrap_or(0.0)
        ));
        return;
    }
    let dimension = world.resource::<SimConfig>().dimension;
    let two_d = dimension == Dimension::Two;
    let mut q = world.query_filtered::<(&Position, &Radius), With<Grain>>();
    let existing: Vec<(DVec3, f64)> = q.iter(world).map(|(p, r)| (p.0, r.0)).collect();
    let k = dep.progress.batches_inserted;
    match random_insertion(
        &dep.region,
        dep.batch_size,
        &dep.radius,
        dep.seed.wrapping_add(k as u64),
        0.0,
        two_d,
        &existing,
    ) {
        Ok(mut batch) => {
            // In rows of cells, not in the order drawn, as a `Random` source's grains.
            if let Some(rows) = RowsOfCells::over(batch.iter().map(|(p, r, _)| (*p, *r))) {
                batch.sort_by_cached_key(|(p, ..)| rows.key(*p));
            }
            world.spawn_batch(
                batch
                    .into_iter()
                    .map(|(p, r, _)| GrainBundle::new(dimension, p, r, dep.density, dep.material))
                    .collect::<Vec<_>>(),
            );
            world.resource_mut::<Deposition>().progress.batches_inserted += 1;
        }
        Err((_, why)) => {
            world.resource_mut::<StopRequest>().0 = Some(format!(
                "deposition stopped: batch {} does not fit its region ({why})",
                k + 1
            ));
        }
    }
}

/// What an isotropic compression aims at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CompressionTarget {
    /// A solid fraction.
    SolidFraction(f64),
    /// A mean pressure, Pa.
    Pressure(f64),
}

/// An isotropic compression of the periodic cell under way.
#[derive(Resource, Clone, Debug)]
pub struct Compression {
    /// The target.
    pub target: CompressionTarget,
    /// Largest strain rate, 1/s.
    pub max_strain_rate: f64,
    /// Bound on the inertial number.
    pub max_inertial_number: f64,
    /// Stop threshold of the unbalanced-force ratio.
    pub unbalanced_force: f64,
    /// Relative tolerance on a target pressure.
    pub pressure_tolerance: f64,
    /// Total grain volume (2-D: area), m³.
    pub grain_volume: f64,
    /// Mean grain diameter, m.
    pub mean_diameter: f64,
    /// Mean grain density, kg/m³.
    pub density: f64,
    /// Steps between checks of the unbalanced-force ratio.
    pub check_every: u64,
    /// Periodic axes the cell shrinks along (x, y in 2-D; x, y, z in 3-D).
    pub dims: usize,
    /// Strain rate of the last step, 1/s (for the report and tests).
    pub strain_rate: f64,
    /// Mean contact pressure at the last step, Pa.
    pub pressure: f64,
}

impl Compression {
    /// Solid fraction of a cell.
    pub fn solid_fraction(&self, cell: &PeriodicBox) -> f64 {
        let l = cell.length();
        let v: f64 = (0..self.dims).map(|a| l[a]).product();
        self.grain_volume / v
    }
}

/// Mean pressure p = (1/(D V)) Σ f·l of the contact (Love–Weber) stress in a periodic
/// cell, with l the nearest-image branch from b to a and f the force on a.
pub fn contact_pressure(world: &mut World, cell: &PeriodicBox, dims: usize) -> f64 {
    let mut contacts = world.query::<(&Contact, &ContactGeometry, &ContactForce)>();
    let mut positions = world.query::<&Position>();
    let world = &*world;
    let mut virial = 0.0;
    for (c, g, f) in contacts.iter(world) {
        if c.kind != ContactKind::GrainGrain || !f.is_active(g) {
            continue;
        }
        if let (Ok(pa), Ok(pb)) = (positions.get(world, c.a), positions.get(world, c.b)) {
            virial += f.force.dot(cell.min_image(pa.0 - pb.0));
        }
    }
    let l = cell.length();
    let v: f64 = (0..dims).map(|a| l[a]).product();
    virial / (dims as f64 * v)
}

/// One step of the compression (in [`Stage::Prepare`]): the strain rate from the target
/// and the inertial-number bound, the cell and the grain centres scaled homothetically
/// about the cell's lower corner, and the stop check.
pub fn compression(world: &mut World) {
    let comp = world.resource::<Compression>().clone();
    let dt = world.resource::<SimConfig>().dt;
    let step = world.resource::<Clock>().step;
    let cell = *world.resource::<PeriodicBox>();
    let p = contact_pressure(world, &cell, comp.dims);
    // Largest rate that keeps I = ε̇ d √(ρ/p) below the bound (the cap alone while the
    // pressure is still too low to set one).
    let bound = if p > 0.0 {
        (comp.max_inertial_number * (p / comp.density).sqrt() / comp.mean_diameter)
            .min(comp.max_strain_rate)
    } else {
        comp.max_strain_rate
    };
    let phi = comp.solid_fraction(&cell);
    let (mut rate, done) = match comp.target {
        CompressionTarget::SolidFraction(target) => {
            if phi < target {
                (bound, false)
            } else {
                (0.0, true)
            }
        }
        CompressionTarget::Pressure(target) => {
            let error = (target - p) / target;
            (
                bound * error.clamp(-1.0, 1.0),
                error.abs() <= comp.pressure_tolerance,
            )
        }
    };
    let mut scale = 1.0 - rate * dt;
    if let CompressionTarget::SolidFraction(target) = comp.target
        && rate > 0.0
    {
        // Land on the target, not past it.
        let to_target = (phi / target).powf(1.0 / comp.dims as f64);
        if scale < to_target {
            scale = to_target;
            rate = (1.0 - scale) / dt;
        }
    }
    {
        let mut c = world.resource_mut::<Compression>();
        c.strain_rate = rate;
        c.pressure = p;
    }
    if scale != 1.0 {
        let lo = cell.lo;
        let mut axes = DVec3::ONE;
        for a in comp.dims..3 {
            axes[a] = 0.0;
        }
        let factor = DVec3::ONE + axes * (scale - 1.0);
        {
            let mut cell = world.resource_mut::<PeriodicBox>();
            cell.hi = lo + (cell.hi - lo) * factor;
        }
        let mut q = world.query_filtered::<&mut Position, With<Grain>>();
        for mut x in q.iter_mut(world) {
            x.0 = lo + (x.0 - lo) * factor;
        }
    }
    if done && step.is_multiple_of(comp.check_every) {
        let ratio = unbalanced_force_ratio(world);
        if let Some(r) = ratio
            && r <= comp.unbalanced_force
        {
            let phi = world
                .resource::<Compression>()
                .solid_fraction(world.resource::<PeriodicBox>());
            world.resource_mut::<StopRequest>().0 = Some(format!(
                "compressed: solid fraction {phi:.6}, pressure {p:.4e} Pa, unbalanced-force ratio {r:.3e}"
            ));
        }
    }
}
