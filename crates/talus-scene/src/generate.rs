//! Grain generation: explicit lists, lattices and seeded random insertion.

use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::schema::{GrainSource, RadiusSpec, Region};

/// A grain to be spawned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrainInit {
    /// Centre.
    pub position: DVec3,
    /// Radius.
    pub radius: f64,
    /// Velocity.
    pub velocity: DVec3,
    /// Angular velocity.
    pub angular_velocity: DVec3,
    /// Material id.
    pub material: u16,
    /// Index of the grain source in the scene.
    pub source: usize,
    /// The grain's own density, kg/m³, instead of its material's (data files).
    pub density: Option<f64>,
    /// A frozen grain never moves.
    pub frozen: bool,
    /// Index of the grain in a saved state it was restored from (`source` is then
    /// [`RESTORED_SOURCE`]); its mass, inertia, force and torque come from the state.
    pub saved: Option<u32>,
}

/// The `source` of grains restored from a saved state (not a `grains` entry).
pub const RESTORED_SOURCE: usize = usize::MAX;

/// Why a source could not produce its grains: (field relative to the source, expected).
pub type GenerateError = (String, String);

fn v(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

/// Generates the grains of one source. In 2-D every z coordinate is 0.
pub fn generate(
    source: &GrainSource,
    index: usize,
    material: u16,
    two_d: bool,
) -> Result<Vec<GrainInit>, GenerateError> {
    let flat = |p: DVec3| if two_d { DVec3::new(p.x, p.y, 0.0) } else { p };
    match source {
        GrainSource::List { grains, .. } => Ok(grains
            .iter()
            .map(|g| GrainInit {
                position: flat(v(g.position)),
                radius: g.radius,
                velocity: flat(v(g.velocity)),
                angular_velocity: if two_d {
                    DVec3::new(0.0, 0.0, g.angular_velocity[2])
                } else {
                    v(g.angular_velocity)
                },
                material,
                source: index,
                density: None,
                frozen: false,
                saved: None,
            })
            .collect()),
        GrainSource::Lattice {
            radius,
            region,
            spacing,
            velocity,
            ..
        } => {
            let a = spacing.unwrap_or(2.1 * radius);
            let lo = v(region.min) + DVec3::splat(*radius);
            let hi = v(region.max) - DVec3::splat(*radius);
            let count = |l: f64, h: f64| {
                if h < l {
                    0
                } else {
                    ((h - l) / a).floor() as usize + 1
                }
            };
            let (nx, ny) = (count(lo.x, hi.x), count(lo.y, hi.y));
            let nz = if two_d { 1 } else { count(lo.z, hi.z) };
            if nx * ny * nz == 0 {
                return Err((
                    "region".into(),
                    "a region at least one grain diameter wide in every direction".into(),
                ));
            }
            let mut out = Vec::with_capacity(nx * ny * nz);
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        let p = lo + DVec3::new(i as f64, j as f64, k as f64) * a;
                        out.push(GrainInit {
                            position: flat(p),
                            radius: *radius,
                            velocity: flat(v(*velocity)),
                            angular_velocity: DVec3::ZERO,
                            material,
                            source: index,
                            density: None,
                            frozen: false,
                            saved: None,
                        });
                    }
                }
            }
            Ok(out)
        }
        GrainSource::LammpsData { .. } => Err((
            "file".into(),
            "grains read by the scene builder (a data file is not generated)".into(),
        )),
        GrainSource::Random {
            region,
            count,
            radius,
            seed,
            velocity_spread,
            ..
        } => random_insertion(region, *count, radius, *seed, *velocity_spread, two_d, &[]).map(
            |grains| {
                grains
                    .into_iter()
                    .map(|(p, r, vel)| GrainInit {
                        position: p,
                        radius: r,
                        velocity: vel,
                        angular_velocity: DVec3::ZERO,
                        material,
                        source: index,
                        density: None,
                        frozen: false,
                        saved: None,
                    })
                    .collect()
            },
        ),
    }
}

/// Random sequential insertion of `count` grains (centre, radius, velocity) in a
/// region, overlapping neither each other nor the `existing` grains (centre, radius).
pub fn random_insertion(
    region: &Region,
    count: usize,
    radius: &RadiusSpec,
    seed: u64,
    spread: f64,
    two_d: bool,
    existing: &[(DVec3, f64)],
) -> Result<Vec<(DVec3, f64, DVec3)>, GenerateError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (rmin, rmax) = match *radius {
        RadiusSpec::Fixed(r) => (r, r),
        RadiusSpec::Uniform { min, max } => (min, max),
    };
    let lo = v(region.min);
    let hi = v(region.max);
    let cell = 2.0 * rmax;
    let dims = ((hi - lo) / cell).floor().max(DVec3::ZERO) + DVec3::ONE;
    let (nx, ny, nz) = (
        dims.x as usize,
        dims.y as usize,
        if two_d { 1 } else { dims.z as usize },
    );
    if nx.saturating_mul(ny).saturating_mul(nz) > 50_000_000 {
        return Err((
            "region".into(),
            "a region at most 5e7 grain diameters in volume".into(),
        ));
    }
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); nx * ny * nz];
    let bin_of = |p: DVec3| {
        let q = (p - lo) / cell;
        let c = |x: f64, n: usize| (x.max(0.0) as usize).min(n - 1);
        (c(q.x, nx), c(q.y, ny), if two_d { 0 } else { c(q.z, nz) })
    };
    let mut out: Vec<(DVec3, f64, DVec3)> = Vec::with_capacity(count);
    // Existing grains that reach into the region take part in the overlap tests (as
    // entries past `count` in `placed`), without being returned.
    let mut placed: Vec<(DVec3, f64)> = Vec::new();
    for &(q, rq) in existing {
        let reach = rq + rmax;
        if (0..3).all(|d| (two_d && d == 2) || (q[d] > lo[d] - reach && q[d] < hi[d] + reach)) {
            let (bx, by, bz) = bin_of(q);
            bins[bx + nx * (by + ny * bz)].push(u32::MAX - placed.len() as u32);
            placed.push((q, rq));
        }
    }
    let max_attempts = 1000 * count as u64 + 10_000;
    let mut attempts = 0u64;
    while out.len() < count {
        attempts += 1;
        if attempts > max_attempts {
            return Err((
                "count".into(),
                format!(
                    "a number of grains that fits the region: only {} of {count} could be placed without overlap in {max_attempts} attempts",
                    out.len()
                ),
            ));
        }
        let r = if rmax > rmin {
            rng.random_range(rmin..=rmax)
        } else {
            rmin
        };
        let mut p = DVec3::ZERO;
        for d in 0..3 {
            let (a, b) = (lo[d] + r, hi[d] - r);
            if two_d && d == 2 {
                p[d] = 0.0;
            } else if b < a {
                return Err((
                    "region".into(),
                    "a region wider than the largest grain".into(),
                ));
            } else {
                p[d] = rng.random_range(a..=b);
            }
        }
        let (bx, by, bz) = bin_of(p);
        let mut free = true;
        'search: for z in bz.saturating_sub(1)..=(bz + 1).min(nz - 1) {
            for y in by.saturating_sub(1)..=(by + 1).min(ny - 1) {
                for x in bx.saturating_sub(1)..=(bx + 1).min(nx - 1) {
                    for &k in &bins[x + nx * (y + ny * z)] {
                        let (q, rq) = if k as usize >= count.max(out.len()) {
                            placed[(u32::MAX - k) as usize]
                        } else {
                            let (q, rq, _) = out[k as usize];
                            (q, rq)
                        };
                        if p.distance_squared(q) < (r + rq) * (r + rq) {
                            free = false;
                            break 'search;
                        }
                    }
                }
            }
        }
        if free {
            let mut vel = DVec3::ZERO;
            if spread > 0.0 {
                for d in 0..if two_d { 2 } else { 3 } {
                    vel[d] = rng.random_range(-spread..=spread);
                }
            }
            bins[bx + nx * (by + ny * bz)].push(out.len() as u32);
            out.push((p, r, vel));
        }
    }
    Ok(out)
}
