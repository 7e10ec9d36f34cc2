//! Stress regions, coarse-grained fields and save/resume in a box sheared by Lees–Edwards
//! boundaries, against independent references: a brute-force search over the sliding-brick
//! images of each box (grain membership and branch fractions), the Love–Weber sum Σ f ⊗ l
//! computed here with the sheared nearest image, the total mass and momentum of the grains
//! (the images across the gradient seam carrying their velocity jump), the sampled Gaussian
//! of a lone grain at its sheared image, and the uninterrupted run.

use crate::common;

use common::sampling::{field, regions};
use glam::DVec3;
use talus::contact::{Contact, ContactForce, ContactGeometry, ContactKind};
use talus::core::periodic::PeriodicBox;
use talus::core::prelude::*;
use talus::core::schedule::Simulation;
use talus::scene::state::SavedState;
use talus_stress::{FieldRecord, StressRecord, Tensor};

/// Edge of the periodic cube, m.
const CUBE: f64 = 0.02;
/// Shear rate of the gas, 1/s: the images across the z seam slide at γ̇ L = 1 m/s.
const RATE: f64 = 50.0;

/// A gas of 800 spheres (radius 0.7–0.9 mm, solid fraction about 0.2) in a cube periodic
/// along every axis and sheared with flow x, gradient z, soft contacts so that about a
/// hundred are open at a time, some through the sheared seam. `sampling` is the scene's
/// sampling section.
fn sheared_gas(sampling: &str, steps: u64) -> String {
    let shear = format!(",\n        shear: (rate: {RATE:e}, flow: \"x\", gradient: \"z\")");
    common::glass_gas("sheared-gas", steps, CUBE, &shear, sampling)
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
            // The middle of the overlap.
            ContactKind::GrainWall => {
                let ra = sim.world.get::<Radius>(c.a).unwrap().0;
                (a - g.normal * (ra - 0.5 * g.overlap), false)
            }
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
    let mut worst_mean_velocity = 0.0f64;
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
            // The held image at p − s moves k_z γ̇ L slower along the flow axis.
            let (mut held, mut mass, mut momentum) = (0, 0.0, DVec3::ZERO);
            for g in &grains {
                let images: Vec<i32> = shifts
                    .iter()
                    .filter(|(_, s)| {
                        let p = g.position - *s;
                        (0..3).all(|d| lo[d] <= p[d] && p[d] < hi[d])
                    })
                    .map(|(k, _)| *k)
                    .collect();
                assert!(images.len() <= 1);
                if let Some(&k) = images.first() {
                    held += 1;
                    mass += g.mass;
                    momentum += g.mass * (g.velocity - DVec3::X * (k as f64 * RATE * CUBE));
                }
            }
            if held > 0 {
                let mean = DVec3::from_array(r.mean_velocity);
                worst_mean_velocity =
                    worst_mean_velocity.max((mean - momentum / mass).length() / (RATE * CUBE));
            }
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
        "offsets {offsets:?} m; {seam_branches} branches through the sheared seam; {grain_mismatches} box samples with the wrong grains; per box vs brute force {worst_box:e}; tiling vs domain {worst_tiling:e}; domain vs Σ f⊗l {worst_domain:e}; mean velocity of the held images {worst_mean_velocity:e} of γ̇L"
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
    assert!(worst_mean_velocity < 1e-12);
}

/// erf(3/√2), the mass of a Gaussian within 3 standard deviations.
const ERF_3_OVER_SQRT2: f64 = 0.997_300_203_936_739_8;

/// The signed fraction of a grain's kernel that lands across the gradient seam, per the
/// documented kernel (`docs/physics/stress.md` §10): Gaussian weights at the nodes within
/// 3 w along z, normalised over them; nodes past the top face (unwrapped index ≥ n) see the
/// image one period down (+1), nodes below the bottom face the image one period up (−1).
fn seam_fraction(z: f64, cells: usize, w: f64) -> f64 {
    let h = CUBE / cells as f64;
    let (mut total, mut signed) = (0.0, 0.0);
    for i in -(cells as i64)..2 * cells as i64 {
        let d = (i as f64 + 0.5) * h - z;
        if d.abs() > 3.0 * w {
            continue;
        }
        let g = (-0.5 * (d / w).powi(2)).exp();
        total += g;
        if i >= cells as i64 {
            signed += g;
        } else if i < 0 {
            signed -= g;
        }
    }
    signed / total
}

#[test]
fn coarse_grained_fields_of_a_sheared_gas_conserve_mass_momentum_and_stress() {
    // The sheared gas on a 10³ grid (2 mm cells), w = 1 mm. References per sample: the
    // total mass; the momentum Σ m v, where the part of a grain's kernel that lands
    // across the gradient seam carries its image's velocity v ∓ γ̇ L e_x (so the flow
    // component of the integral is P_x − γ̇ L Σ m s, s the signed fraction across the
    // seam of the documented kernel, computed here); the Love–Weber sum Σ f ⊗ l with
    // sheared nearest images, computed here, and the domain sample.
    let sampling = "sampling: (interval: 2e-4, fields: (cells: (10, 10, 10), width: 0.001)),";
    let (mut sim, _) = common::build(&sheared_gas(sampling, 1));
    sim.prime().unwrap();
    let every = sim
        .world
        .resource::<talus_stress::FieldSettings>()
        .spec
        .every;
    sim.run_steps(30 * every).unwrap();
    let volume = CUBE.powi(3);
    let (mut worst_mass, mut worst_momentum, mut worst_peculiar) = (0.0f64, 0.0f64, 0.0f64);
    let (mut worst_stress, mut worst_domain) = (0.0f64, 0.0f64);
    let mut kinetic_ratio: Vec<f64> = Vec::new();
    let mut seam_branches = 0;
    let mut across_seam = 0.0;
    for _ in 0..6 {
        sim.run_steps(every).unwrap();
        let delta = offset(&sim);
        let shifts = brick_shifts(delta);
        let f = field(&sim);
        assert_eq!(f.step, sim.step_count());
        let integral = |value: &dyn Fn(usize) -> f64| {
            (0..f.node_count()).map(value).sum::<f64>() * f.cell_volume
        };
        let grains = common::grains(&mut sim);
        let mass: f64 = grains.iter().map(|g| g.mass).sum();
        let scale: f64 = grains.iter().map(|g| g.mass * g.velocity.length()).sum();
        let seam_mass: f64 = grains
            .iter()
            .map(|g| g.mass * seam_fraction(g.position.z, 10, 0.001))
            .sum();
        across_seam += seam_mass.abs() / mass;
        let momentum = grains
            .iter()
            .fold(DVec3::ZERO, |p, g| p + g.mass * g.velocity)
            - DVec3::new(RATE * CUBE * seam_mass, 0.0, 0.0);
        worst_mass = worst_mass.max((integral(&|n| f.density[n]) / mass - 1.0).abs());
        for d in 0..3 {
            let p = integral(&|n| f.momentum[n][d]);
            worst_momentum = worst_momentum.max((p - momentum[d]).abs() / scale);
        }
        // The peculiar momentum: Σ m (v − u(x)) against ∫ (p − ρ u(r)), u the streaming
        // profile; equal up to the kernel's first moment along z times γ̇ (reported).
        let streaming = |z: f64| RATE * (z - 0.5 * CUBE);
        let peculiar: f64 = grains
            .iter()
            .map(|g| g.mass * (g.velocity.x - streaming(g.position.z)))
            .sum();
        let peculiar_field =
            integral(&|n| f.momentum[n][0] - f.density[n] * streaming(f.node_position(n).z));
        worst_peculiar = worst_peculiar.max((peculiar_field - peculiar).abs() / scale);

        let contacts = branches(&mut sim, &shifts);
        seam_branches += contacts.iter().filter(|c| c.through_seam).count();
        let reference = contacts
            .iter()
            .fold(Tensor::ZERO, |mut t, c| {
                t.add_outer(c.force, c.far - c.a, 1.0);
                t
            })
            .scaled(1.0 / volume);
        let mean = (0..f.node_count())
            .fold(Tensor::ZERO, |t, n| t.plus(f.contact_stress[n]))
            .scaled(f.cell_volume / volume);
        worst_stress = worst_stress.max(mean.minus(reference).norm() / reference.norm());
        let all = regions(&sim);
        let domain = all.iter().find(|r| r.name == "domain").unwrap();
        worst_domain =
            worst_domain.max(mean.minus(domain.contact_stress).norm() / reference.norm());
        // The kinetic field about the local velocity against the domain's about the
        // streaming profile: both measure the peculiar fluctuations.
        let kinetic_mean = integral(&|n| f.kinetic_stress[n].trace(3)) / volume;
        kinetic_ratio.push(kinetic_mean / domain.kinetic_stress.trace(3));
    }
    println!(
        "fields: mass {worst_mass:e}; momentum {worst_momentum:e} of Σ m|v| (mean seam fraction {:.3e}); peculiar x momentum {worst_peculiar:e}; contact stress vs Σ f⊗l/V {worst_stress:e}, vs domain {worst_domain:e}; {seam_branches} branches through the sheared seam; grid kinetic trace / domain {kinetic_ratio:?}",
        across_seam / 6.0
    );
    assert!(
        seam_branches >= 5,
        "too few contacts through the sheared seam"
    );
    assert!(worst_mass < 1e-6);
    assert!(worst_momentum < 1e-12);
    assert!(worst_stress < 1e-12);
    assert!(worst_domain < 1e-12);
}

#[test]
fn the_density_of_a_lone_grain_at_the_sheared_seam_is_the_gaussian_at_its_image() {
    // One grain 0.9 mm below the top of the gradient axis z of a sheared cube, at an
    // offset Δ far from a whole period, 40³ nodes (h = 0.5 mm), w = 1 mm. The nodes near
    // the bottom face see the grain's image one period up, at (x + Δ, y, z + L), moving
    // at v + γ̇ L e_x. Reference: m × the continuous Gaussian about the nearest sliding-
    // brick image / erf(3/√2)³, as for the plain periodic lone grain
    // (tests/coarse_graining.rs), within the bound of the discrete normalisation, 6.7e-3.
    let scene = format!(
        r#"Scene(
    name: "lone-sheared",
    gravity: (0.0, 0.0, 0.0),
    steps: 1,
    time_step: 1e-5,
    periodic: (x: (0.0, {CUBE}), y: (0.0, {CUBE}), z: (0.0, {CUBE}),
        shear: (rate: {RATE:e}, flow: "x", gradient: "z")),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 200.0, restitution: 0.8))],
    grains: [List(material: "glass", grains: [
        (position: (0.0103, 0.0097, 0.0191), radius: 0.001, velocity: (0.1, -0.2, 0.0))])],
    sampling: (domain: false, interval: 1e-5, fields: (cells: (40, 40, 40), width: 0.001)),
    output: (recording: false),
)"#
    );
    let (mut sim, _) = common::build(&scene);
    sim.prime().unwrap();
    // 0.0137 s: Δ = γ̇ L t = 0.0137 m, reduced to −0.0063 m.
    sim.run_steps(1370).unwrap();
    let delta = offset(&sim);
    assert!((delta + 0.0063).abs() < 1e-9, "{delta}");
    let shifts = brick_shifts(delta);
    let f = field(&sim);
    let g = common::grains(&mut sim)[0];
    assert!(
        CUBE - g.position.z < 0.001,
        "the grain stays next to the seam"
    );
    let w = 0.001;
    let truncated = ERF_3_OVER_SQRT2.powi(3);
    let (mut checked, mut through_seam) = (0, 0);
    let mut worst = 0.0f64;
    for n in 0..f.node_count() {
        // The image of the node nearest to the grain, k bricks up, and their separation
        // d: the node sees the grain's image k bricks down at the same separation.
        let (d, k) = nearest_image(g.position, f.node_position(n), &shifts);
        if d.abs().max_element() > 3.0 * w {
            assert_eq!(f.density[n], 0.0, "node {n}");
            continue;
        }
        let gauss = (-0.5 * d.length_squared() / (w * w)).exp()
            / ((2.0 * std::f64::consts::PI).powf(1.5) * w.powi(3));
        let expected = g.mass * gauss / truncated;
        worst = worst.max((f.density[n] / expected - 1.0).abs());
        // The velocity the node sees: the grain's, or its image's, which moves at
        // −k γ̇ L e_x beyond it.
        let image_velocity = g.velocity - DVec3::new(k as f64 * RATE * CUBE, 0.0, 0.0);
        assert!(
            (DVec3::from(f.velocity[n]) - image_velocity).length() < 1e-12,
            "node {n}: {:?} vs {image_velocity:?}",
            f.velocity[n]
        );
        assert!(f.kinetic_stress[n].norm() <= 1e-20 * f.density[n]);
        checked += 1;
        through_seam += usize::from(k != 0);
    }
    println!(
        "lone grain at the sheared seam: {checked} nodes ({through_seam} across the seam), largest relative difference {worst:e}"
    );
    assert!(checked > 1000 && through_seam > 100);
    let bound =
        3.0 * (-4.5f64).exp() * 0.5 / ((2.0 * std::f64::consts::PI).sqrt() * ERF_3_OVER_SQRT2);
    assert!(worst < bound, "{worst:e} above {bound:e}");
}

/// The whole state as text: equal texts mean equal bits (floats are written in their
/// shortest round-trip form), the same contacts in the same order, the same histories.
fn fingerprint(sim: &mut Simulation) -> String {
    let state = SavedState::capture(&mut sim.world, "x");
    ron::to_string(&state).unwrap()
}

#[test]
fn a_resumed_sheared_run_is_bit_identical_to_the_uninterrupted_run() {
    // The sheared gas with a box across the sheared seam and fields: 1500 steps in one
    // go, and 737 steps, save, load, 763 more. The offset is a function of the time, the
    // grains' velocities are saved after their jumps through the seam, and the contacts
    // through it keep their tangential springs.
    let sampling = "sampling: (interval: 2e-4, regions: [Box(name: \"seam\", min: (0.003, -1.0, -0.004), max: (0.011, 1.0, 0.004))], fields: (cells: (5, 5, 5), width: 0.001)),";
    let (total, split) = (1500, 737);
    let scene = sheared_gas(sampling, total);
    let mut whole = common::build_or_resume(&scene, None);
    whole.run_steps(total).unwrap();

    let mut first = common::build_or_resume(&scene, None);
    first.run_steps(split).unwrap();
    let offset_at_split = offset(&first);
    let dir = common::temp_dir("le-resume");
    let path = dir.join("state.ron");
    SavedState::capture(&mut first.world, "sheared-gas")
        .write(&path)
        .unwrap();
    drop(first);
    let saved = SavedState::read(&path).unwrap();
    let mut second = common::build_or_resume(&scene, Some(&saved));
    assert_eq!(second.step_count(), split);
    second.run_steps(total - split).unwrap();

    // Contacts through the sheared seam at the end: their relative velocities carry the
    // image velocity γ̇ L = 1 m/s, so a wrong offset or velocity would show.
    let shifts = brick_shifts(offset(&whole));
    let contacts = branches(&mut whole, &shifts);
    let through = contacts.iter().filter(|c| c.through_seam).count();
    println!(
        "split at step {split} (offset {offset_at_split:.6e} m, {} contacts saved); at the end offset {:.6e} m, {through} contacts through the sheared seam",
        saved.contacts.len(),
        offset(&whole)
    );
    assert!(
        (offset_at_split / CUBE).abs() > 0.05,
        "a non-trivial offset at the split"
    );
    assert!(through > 0);
    assert!(
        fingerprint(&mut whole) == fingerprint(&mut second),
        "the resumed sheared run differs from the uninterrupted one"
    );
    let b = |sim: &Simulation| *sim.world.resource::<PeriodicBox>();
    assert_eq!(b(&whole), b(&second), "the same box and offset");
    let latest_stress = |sim: &Simulation| sim.world.resource::<StressRecord>().latest.clone();
    let latest_field = |sim: &Simulation| sim.world.resource::<FieldRecord>().latest.clone();
    assert!(latest_stress(&whole).is_some());
    assert!(
        latest_stress(&whole) == latest_stress(&second),
        "stress samples"
    );
    assert!(
        latest_field(&whole) == latest_field(&second),
        "field samples"
    );
    let _ = std::fs::remove_dir_all(dir);
}
