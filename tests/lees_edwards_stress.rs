//! Stress regions, coarse-grained fields and save/resume in a box sheared by Lees–Edwards
//! boundaries, against independent references: a brute-force search over the sliding-brick
//! images of each box (grain membership and branch fractions), the Love–Weber sum Σ f ⊗ l
//! computed here with the sheared nearest image, the total mass and momentum of the grains
//! (the images across the gradient seam carrying their velocity jump), the sampled Gaussian
//! of a lone grain at its sheared image, and the uninterrupted run.

mod common;

use glam::DVec3;
use talus::contact::{Contact, ContactForce, ContactGeometry, ContactKind};
use talus::core::periodic::PeriodicBox;
use talus::core::prelude::*;
use talus::core::schedule::Simulation;
use talus::scene::state::SavedState;
use talus_stress::{FieldRecord, FieldSample, RegionStress, StressRecord, Tensor};

/// Edge of the periodic cube, m.
const CUBE: f64 = 0.02;
/// Shear rate of the gas, 1/s: the images across the z seam slide at γ̇ L = 1 m/s.
const RATE: f64 = 50.0;

/// A gas of 800 spheres (radius 0.7–0.9 mm, solid fraction about 0.2) in a cube periodic
/// along every axis and sheared with flow x, gradient z, soft contacts so that about a
/// hundred are open at a time, some through the sheared seam. `sampling` is the scene's
/// sampling section.
fn sheared_gas(sampling: &str, steps: u64) -> String {
    let (lo, hi) = (0.001, CUBE - 0.001);
    format!(
        r#"Scene(
    name: "sheared-gas",
    gravity: (0.0, 0.0, 0.0),
    steps: {steps},
    periodic: (x: (0.0, {CUBE}), y: (0.0, {CUBE}), z: (0.0, {CUBE}),
        shear: (rate: {RATE:e}, flow: "x", gradient: "z")),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 200.0, restitution: 0.8, friction: 0.3))],
    grains: [Random(material: "glass", region: (min: ({lo}, {lo}, {lo}), max: ({hi}, {hi}, {hi})),
        count: 800, radius: Uniform(min: 0.0007, max: 0.0009), seed: 5, velocity_spread: 1.0)],
    {sampling}
    output: (recording: false),
)"#
    )
}

/// The offset Δ of the sheared images at the current step, checked against the
/// definition Δ = γ̇ L t reduced modulo L into [−L/2, L/2).
fn offset(sim: &Simulation) -> f64 {
    let b = *sim.world.resource::<PeriodicBox>();
    let delta = b.shear.expect("sheared box").offset;
    let t = sim.world.resource::<Clock>().time;
    let raw = RATE * CUBE * t;
    let expected = raw - CUBE * (raw / CUBE + 0.5).floor();
    assert!(
        (delta - expected).abs() < 1e-12,
        "offset {delta} vs γ̇ L t = {expected}"
    );
    delta
}

/// The lattice shifts of the sliding-brick images of the cube within two periods:
/// k_z (L e_z + Δ e_x) + k_x L e_x + k_y L e_y, with the gradient index k_z.
fn brick_shifts(delta: f64) -> Vec<(i32, DVec3)> {
    let mut shifts = Vec::new();
    for kz in -2..=2 {
        for kx in -2..=2 {
            for ky in -2..=2 {
                let s = DVec3::new(
                    kz as f64 * delta + kx as f64 * CUBE,
                    ky as f64 * CUBE,
                    kz as f64 * CUBE,
                );
                shifts.push((kz, s));
            }
        }
    }
    shifts
}

/// The nearest sheared image of b seen from a: the separation b_image − a and the gradient
/// index of the image (which brick it lies in), by brute force over the brick shifts.
fn nearest_image(a: DVec3, b: DVec3, shifts: &[(i32, DVec3)]) -> (DVec3, i32) {
    shifts
        .iter()
        .map(|&(k, s)| (b + s - a, k))
        .min_by(|p, q| p.0.length_squared().total_cmp(&q.0.length_squared()))
        .unwrap()
}

/// Fraction of the segment a → b inside the box [lo, hi) (a plain Liang–Barsky clip,
/// written here independently of the sampler's).
fn clip(lo: DVec3, hi: DVec3, a: DVec3, b: DVec3) -> f64 {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for d in 0..3 {
        let delta = b[d] - a[d];
        if delta == 0.0 {
            if a[d] < lo[d] || a[d] >= hi[d] {
                return 0.0;
            }
            continue;
        }
        let (ta, tb) = ((lo[d] - a[d]) / delta, (hi[d] - a[d]) / delta);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
        if t1 <= t0 {
            return 0.0;
        }
    }
    t1 - t0
}

/// A contact as the references see it: force on a, the centre of a, the far end of the
/// branch (the nearest sheared image of b, or the contact point for a wall), and whether
/// the branch crosses the sheared seam.
struct Branch {
    force: DVec3,
    a: DVec3,
    far: DVec3,
    through_seam: bool,
}

/// Every contact carrying a force, with branches to the nearest sheared image.
fn branches(sim: &mut Simulation, shifts: &[(i32, DVec3)]) -> Vec<Branch> {
    let mut q = sim
        .world
        .query::<(&Contact, &ContactGeometry, &ContactForce)>();
    let contacts: Vec<(Contact, ContactGeometry, ContactForce)> =
        q.iter(&sim.world).map(|(c, g, f)| (*c, *g, *f)).collect();
    let mut out = Vec::new();
    for (c, g, f) in contacts {
        if f.force == DVec3::ZERO {
            continue;
        }
        let a = sim.world.get::<Position>(c.a).unwrap().0;
        let (far, through_seam) = match c.kind {
            ContactKind::GrainGrain => {
                let b = sim.world.get::<Position>(c.b).unwrap().0;
                let (l, k) = nearest_image(a, b, shifts);
                (a + l, k != 0)
            }
            ContactKind::GrainWall => (g.point, false),
        };
        out.push(Branch {
            force: f.force,
            a,
            far,
            through_seam,
        });
    }
    out
}

/// The latest stress sample's regions.
fn regions(sim: &Simulation) -> Vec<RegionStress> {
    sim.world
        .resource::<StressRecord>()
        .latest
        .clone()
        .expect("a stress sample was taken")
        .regions
}

/// The latest field sample.
fn field(sim: &Simulation) -> FieldSample {
    sim.world
        .resource::<FieldRecord>()
        .latest
        .clone()
        .expect("a field sample was taken")
}

/// The tiling of the cell: cuts along x, y and z, each list spanning one period and
/// starting off the box's faces, so that boxes straddle every seam (the sheared one
/// included) and are bounded along the flow axis.
fn tiling() -> Vec<(String, DVec3, DVec3)> {
    let cuts = |start: f64, n: usize| -> Vec<f64> {
        (0..=n)
            .map(|i| start + CUBE * i as f64 / n as f64)
            .collect()
    };
    let (xs, ys, zs) = (cuts(-0.0031, 4), cuts(-0.004, 2), cuts(-0.0027, 4));
    let mut boxes = Vec::new();
    for i in 0..4 {
        for j in 0..2 {
            for k in 0..4 {
                boxes.push((
                    format!("b{i}{j}{k}"),
                    DVec3::new(xs[i], ys[j], zs[k]),
                    DVec3::new(xs[i + 1], ys[j + 1], zs[k + 1]),
                ));
            }
        }
    }
    boxes
}

#[test]
fn boxes_tiling_a_sheared_cell_hold_their_sliding_brick_images() {
    // 32 boxes tiling the cell, 4 along the flow x, 2 along y, 4 along the gradient z,
    // the bottom layer across the sheared seam. References, per box and per sample:
    // the grains with an image inside (brute force over the brick shifts), and
    // Σ f ⊗ l × (fraction of the branch inside the box's images), both with the images
    // across the gradient seam shifted by Δ along x; and for the tiling, the domain.
    // Four slabs along the flow axis tile it too: unbounded along y and z, they are the
    // cell's gradient period as sliding bricks, i.e. the boxes [x₀, x₁) × [0, L)².
    let boxes = tiling();
    let slabs: Vec<(String, DVec3, DVec3)> = (0..4)
        .map(|i| {
            let x = |i: usize| -0.0031 + CUBE * i as f64 / 4.0;
            (
                format!("x{i}"),
                DVec3::new(x(i), 0.0, 0.0),
                DVec3::new(x(i + 1), CUBE, CUBE),
            )
        })
        .collect();
    let list: String = boxes
        .iter()
        .map(|(name, lo, hi)| {
            format!(
                "Box(name: \"{name}\", min: ({:e}, {:e}, {:e}), max: ({:e}, {:e}, {:e})),",
                lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
            )
        })
        .chain(slabs.iter().map(|(name, lo, hi)| {
            format!(
                "Slab(name: \"{name}\", axis: \"x\", min: {:e}, max: {:e}),",
                lo.x, hi.x
            )
        }))
        .collect();
    let sampling = format!("sampling: (interval: 2e-4, regions: [{list}]),");
    let (mut sim, _) = common::build(&sheared_gas(&sampling, 1));
    sim.prime().unwrap();
    let every = sim.world.resource::<talus_stress::StressSettings>().every;
    // Let the gas spread through the seams and the offset grow to a third of the period.
    sim.run_steps(30 * every).unwrap();
    let mut seam_branches = 0;
    let mut grain_mismatches = 0;
    let mut offsets = Vec::new();
    let (mut worst_box, mut worst_tiling, mut worst_domain) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..8 {
        sim.run_steps(every).unwrap();
        let delta = offset(&sim);
        offsets.push(delta);
        let shifts = brick_shifts(delta);
        let contacts = branches(&mut sim, &shifts);
        seam_branches += contacts.iter().filter(|c| c.through_seam).count();
        let reference_domain = contacts.iter().fold(Tensor::ZERO, |mut t, c| {
            t.add_outer(c.force, c.far - c.a, 1.0);
            t
        });
        let scale = reference_domain.norm();
        let grains = common::grains(&mut sim);
        let all = regions(&sim);
        let domain = all.iter().find(|r| r.name == "domain").unwrap();
        let domain_moment = domain.contact_stress.scaled(domain.volume);
        worst_domain = worst_domain.max(domain_moment.minus(reference_domain).norm() / scale);
        let mut tiled = Tensor::ZERO;
        let mut slabs_tiled = Tensor::ZERO;
        let mut counted = 0;
        for (name, lo, hi) in boxes.iter().chain(&slabs) {
            let is_box = name.starts_with('b');
            let r = all.iter().find(|r| &r.name == name).unwrap();
            let volume = (*hi - *lo).element_product();
            assert!(
                (r.volume / volume - 1.0).abs() < 1e-12,
                "{name}: {}",
                r.volume
            );
            let moment = r.contact_stress.scaled(r.volume);
            if is_box {
                tiled = tiled.plus(moment);
                counted += r.grains;
            } else {
                slabs_tiled = slabs_tiled.plus(moment);
            }
            // Grains: p is held when p − s lies in the box for a brick shift s (the box's
            // image at +s holds p), at most once since the box is narrower than a period.
            let held = grains
                .iter()
                .filter(|g| {
                    let images = shifts
                        .iter()
                        .filter(|(_, s)| {
                            let p = g.position - *s;
                            (0..3).all(|d| lo[d] <= p[d] && p[d] < hi[d])
                        })
                        .count();
                    assert!(images <= 1);
                    images == 1
                })
                .count();
            if r.grains != held {
                grain_mismatches += 1;
                println!("{name}: {} grains held, {held} by brute force", r.grains);
            }
            let expected = contacts.iter().fold(Tensor::ZERO, |mut t, c| {
                let w: f64 = shifts
                    .iter()
                    .map(|(_, s)| clip(*lo + *s, *hi + *s, c.a, c.far))
                    .sum();
                t.add_outer(c.force, c.far - c.a, w);
                t
            });
            worst_box = worst_box.max(moment.minus(expected).norm() / scale);
        }
        assert_eq!(counted, 800, "each grain in one box");
        worst_tiling = worst_tiling
            .max(tiled.minus(domain_moment).norm() / scale)
            .max(slabs_tiled.minus(domain_moment).norm() / scale);
    }
    println!(
        "offsets {offsets:?} m; {seam_branches} branches through the sheared seam; {grain_mismatches} box samples with the wrong grains; per box vs brute force {worst_box:e}; tiling vs domain {worst_tiling:e}; domain vs Σ f⊗l {worst_domain:e}"
    );
    assert!(
        offsets.iter().all(|d| (d / CUBE).abs() > 0.05),
        "the offset is far from a whole period"
    );
    assert!(
        seam_branches >= 10,
        "too few contacts through the sheared seam"
    );
    assert_eq!(grain_mismatches, 0, "boxes holding the wrong grains");
    assert!(worst_domain < 1e-12);
    assert!(worst_box < 1e-12);
    assert!(worst_tiling < 1e-12);
}
