//! The sampling system and what it produces: per region, the Love–Weber contact
//! stress, the kinetic stress, their sum, pressure and shear stress, the couple stress
//! when contacts carry torques, the solid fraction, and the inertial number.

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use talus_contact::{Contact, ContactForce, ContactGeometry, ContactKind};
use talus_core::prelude::*;

use crate::region::{
    Bounds, DomainInputs, RegionBoxes, RegionKind, RegionSpec, Seams, grain_extent, region_boxes,
    sample_domain,
};
use crate::tensor::Tensor;

/// Inertial number below which a region is quasi-static.
pub const QUASI_STATIC_LIMIT: f64 = 1e-3;
/// Inertial number above which a region is gas-like.
pub const GAS_LIKE_LIMIT: f64 = 0.3;

/// Flow regime of a region from its inertial number I.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlowRegime {
    /// I < 1e-3: slow deformation, persistent contact network.
    QuasiStatic,
    /// 1e-3 ≤ I ≤ 0.3: dense flow where inertia matters.
    DenseInertial,
    /// I > 0.3: dilute, collision-dominated.
    GasLike,
}

impl FlowRegime {
    /// The regime of an inertial number.
    pub fn of(inertial_number: f64) -> FlowRegime {
        if inertial_number < QUASI_STATIC_LIMIT {
            FlowRegime::QuasiStatic
        } else if inertial_number <= GAS_LIKE_LIMIT {
            FlowRegime::DenseInertial
        } else {
            FlowRegime::GasLike
        }
    }
}

/// Where a region's shear rate came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShearRateSource {
    /// Given by the scene (`shear_rate`).
    Scene,
    /// Least-squares fit of the grain velocities against their positions.
    Fit,
    /// The rate imposed by the scene's Lees–Edwards boundaries.
    LeesEdwards,
}

/// The stress state of one region at one instant. Stresses are Cauchy stresses in Pa
/// with tension positive, component (i, j) = force component i, plane normal j (the
/// traction on a plane of unit normal n is σ·n).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegionStress {
    /// Region name (`domain` for the whole domain).
    pub name: String,
    /// `domain`, `box` or `slab`.
    pub shape: RegionKind,
    /// Lower corner of the box whose volume was used, m (2-D: z = −0.5).
    pub min: [f64; 3],
    /// Upper corner of that box, m (2-D: z = 0.5).
    pub max: [f64; 3],
    /// Volume V, m³ (2-D: area × 1 m).
    pub volume: f64,
    /// Grains whose centre lies in the region.
    pub grains: usize,
    /// Active contacts with some part of their branch segment in the region.
    pub contacts: usize,
    /// Σ (grain volume) over the grains counted / V.
    pub solid_fraction: f64,
    /// Mass-weighted mean velocity of the grains counted, m/s.
    pub mean_velocity: [f64; 3],
    /// Total stress, `contact_stress + kinetic_stress`, Pa.
    pub stress: Tensor,
    /// Love–Weber contact (configurational) stress (1/V) Σ_c w_c f^c ⊗ l^c, Pa.
    pub contact_stress: Tensor,
    /// Kinetic stress −(1/V) Σ_p m_p v′_p ⊗ v′_p, Pa (v′ the velocity less the region's
    /// mean, and under Lees–Edwards shear less the streaming profile too).
    pub kinetic_stress: Tensor,
    /// Pressure p = −tr σ / D (D = 2 or 3, in-plane trace in 2-D), Pa; positive in
    /// compression.
    pub pressure: f64,
    /// Deviatoric stress q of the symmetric part s of σ′: √(3/2 s:s) in 3-D, √(1/2 s:s)
    /// in 2-D (the radius of Mohr's circle), Pa.
    pub shear_stress: f64,
    /// Kinetic pressure / pressure (`None` when the pressure is 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kinetic_share: Option<f64>,
    /// Frobenius norm of the antisymmetric part ½(σ − σᵀ), Pa.
    pub antisymmetric_norm: f64,
    /// Couple stress (1/V) Σ m ⊗ b over the extra contact moments m (those beyond
    /// branch × force) with b the branch from the grain centre to the contact point,
    /// N/m; present when some contact carries such a moment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub couple_stress: Option<Tensor>,
    /// Shear rate γ̇, 1/s, when given or estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shear_rate: Option<f64>,
    /// Where `shear_rate` came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shear_rate_source: Option<ShearRateSource>,
    /// I = γ̇ d √(ρ_s / p), when γ̇ is known and p > 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertial_number: Option<f64>,
    /// Flow regime of `inertial_number`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub regime: Option<FlowRegime>,
}

impl RegionStress {
    fn empty(spec: &RegionSpec) -> Self {
        Self {
            name: spec.name.clone(),
            shape: spec.shape.kind(),
            min: [0.0; 3],
            max: [0.0; 3],
            volume: 0.0,
            grains: 0,
            contacts: 0,
            solid_fraction: 0.0,
            mean_velocity: [0.0; 3],
            stress: Tensor::ZERO,
            contact_stress: Tensor::ZERO,
            kinetic_stress: Tensor::ZERO,
            pressure: 0.0,
            shear_stress: 0.0,
            kinetic_share: None,
            antisymmetric_norm: 0.0,
            couple_stress: None,
            shear_rate: None,
            shear_rate_source: None,
            inertial_number: None,
            regime: None,
        }
    }
}

/// One stress sample: every region at one step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StressSample {
    /// Step at which it was taken.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// The regions, in scene order (the domain first when sampled).
    pub regions: Vec<RegionStress>,
}

/// What to sample and how often: inserted by [`crate::StressPlugin`].
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct StressSettings {
    /// Sample when the step number is a multiple of this (step 0 included).
    pub every: u64,
    /// The regions.
    pub regions: Vec<RegionSpec>,
}

/// The latest stress sample, for the report and the recording.
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct StressRecord {
    /// The most recent sample, if one has been taken.
    pub latest: Option<StressSample>,
    /// Number of samples taken so far (tells readers whether `latest` is new).
    pub taken: u64,
}

/// Sums of one region over one sample.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    boxes: Option<RegionBoxes>,
    grains: usize,
    mass: f64,
    momentum: DVec3,
    first_moment: DVec3,
    diameter: f64,
    density: f64,
    solid_volume: f64,
    mean_velocity: DVec3,
    centroid: DVec3,
    /// Σ m v′ ⊗ v′.
    fluctuation: Tensor,
    /// Σ m (x − x̄) ⊗ (x − x̄).
    spread: Tensor,
    /// Σ m v′ ⊗ (x − x̄).
    velocity_position: Tensor,
    /// Σ w f ⊗ l.
    contact: Tensor,
    /// Σ w m ⊗ b.
    couple: Tensor,
    contacts: usize,
}

/// Scratch kept between samples so that sampling does not allocate once warmed up.
#[derive(Default)]
pub struct StressScratch {
    sums: Vec<Sums>,
}

/// Grain data the sampler reads.
type GrainQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Position,
        &'static Velocity,
        &'static Radius,
        &'static Mass,
        &'static MaterialId,
    ),
    With<Grain>,
>;

/// The stress sampling system, in [`Stage::Sample`]: on steps that are multiples of
/// [`StressSettings::every`], computes every region and stores the result in
/// [`StressRecord`]. Velocities are the full-step ones (the stage runs after the second
/// kick); positions, contact forces and geometry are those of the force evaluation of
/// this step. Sums run in query order, so a sample is bit-reproducible.
#[allow(clippy::too_many_arguments)]
pub fn sample_stress(
    clock: Res<Clock>,
    config: Res<SimConfig>,
    materials: Option<Res<Materials>>,
    snapshot: Res<GrainSnapshot>,
    settings: Res<StressSettings>,
    mut record: ResMut<StressRecord>,
    mut scratch: Local<StressScratch>,
    grains: GrainQuery,
    contacts: Query<(&Contact, &ContactGeometry, &ContactForce)>,
) {
    if !clock.step.is_multiple_of(settings.every.max(1)) {
        return;
    }
    let dims = config.dimension.as_number() as usize;
    let density_of = |m: &MaterialId| {
        materials
            .as_ref()
            .and_then(|ms| ms.0.get(m.0 as usize))
            .map_or(0.0, |m| m.density)
    };

    // The domain box.
    let (grain_min, grain_max) = grain_extent(grains.iter().map(|(p, _, r, _, _)| (p.0, r.0)));
    // The domain box; along a periodic axis, the periodic box itself.
    let domain = sample_domain(
        &DomainInputs {
            walls: &snapshot.walls,
            grain_min,
            grain_max,
            dims,
        },
        snapshot.periodic(),
    );
    let seams = Seams::of(snapshot.periodic());

    let sums = &mut scratch.sums;
    sums.clear();
    sums.extend(settings.regions.iter().map(|r| Sums {
        boxes: Some(region_boxes(&r.shape, &domain, dims, &seams)),
        ..Sums::default()
    }));

    // A grain belongs to a region through the image of it that lies inside (across a
    // periodic seam, or a sheared one): its centroid, mean velocity and fluctuations are
    // taken at that image, which moves k γ̇ L_g slower along the flow axis when it is k
    // periods down a Lees–Edwards gradient axis.
    let held = |b: &RegionBoxes, p: DVec3, v: DVec3| {
        b.held_image(p).map(|(image, periods)| {
            let mut u = v;
            if let Some(shear) = &seams.shear {
                u[shear.flow] -= periods * shear.image_speed;
            }
            (image, u)
        })
    };

    // Grains, first pass: totals and means.
    for (p, v, r, m, mat) in &grains {
        let rho = density_of(mat);
        for s in sums.iter_mut() {
            let b = s.boxes.expect("set above");
            let Some((p, v)) = held(&b, p.0, v.0) else {
                continue;
            };
            s.grains += 1;
            s.mass += m.0;
            s.momentum += m.0 * v;
            s.first_moment += m.0 * p;
            s.diameter += 2.0 * r.0;
            s.density += rho;
            if rho > 0.0 {
                s.solid_volume += m.0 / rho;
            }
        }
    }
    for s in sums.iter_mut() {
        if s.mass > 0.0 {
            s.mean_velocity = s.momentum / s.mass;
            s.centroid = s.first_moment / s.mass;
        }
    }
    // Under Lees–Edwards shear the kinetic stress takes the peculiar velocity: less the
    // streaming profile γ̇ (x_g − c_g) e_f, i.e. (the profile being linear) less the
    // region's mean and γ̇ (x_g − x̄_g) e_f.
    let shear = snapshot.periodic().and_then(|b| b.shear);
    // Second pass: fluctuations about the mean (two passes, not Σ m v v − M v̄ v̄, so
    // that a fast-moving region keeps its small fluctuations to full precision).
    for (p, v, _, m, _) in &grains {
        for s in sums.iter_mut() {
            let b = s.boxes.expect("set above");
            let Some((p, v)) = held(&b, p.0, v.0) else {
                continue;
            };
            let dv = v - s.mean_velocity;
            let dx = p - s.centroid;
            let mut peculiar = dv;
            if let Some(shear) = &shear {
                peculiar[shear.flow] -= shear.rate * dx[shear.gradient];
            }
            s.fluctuation.add_outer(peculiar, peculiar, m.0);
            s.spread.add_outer(dx, dx, m.0);
            s.velocity_position.add_outer(dv, dx, m.0);
        }
    }

    // Contacts.
    let mut torques_carried = false;
    for (c, g, f) in &contacts {
        // A vacant row of a contact table holds no contact.
        if c.is_vacant() {
            continue;
        }
        let Some(i) = snapshot.dense(c.a) else {
            continue;
        };
        let active = f.is_active(g);
        let xa = snapshot.position(i);
        let ra = snapshot.radius(i);
        // The branch vectors exactly as the kinematics computed them, so that the
        // moment beyond branch × force is exactly zero for a law that adds none. The
        // contact point from `a`'s side: on `a`'s side of a periodic seam.
        let branch_a = g.branch_a(ra);
        let point = xa + branch_a;
        let moment_a = f.torque_a - branch_a.cross(f.force);
        let (far, moment_b) = match c.kind {
            ContactKind::GrainGrain => {
                let Some(j) = snapshot.dense(c.b) else {
                    continue;
                };
                let branch_b = g.normal * (snapshot.radius(j) - 0.5 * g.overlap);
                // The image of b nearest to a: across a periodic seam the branch is
                // the short way round.
                (
                    xa - snapshot.separation(xa, snapshot.position(j)),
                    f.torque_b - branch_b.cross(-f.force),
                )
            }
            // A wall has no centre: the branch ends at the contact point.
            ContactKind::GrainWall => (point, DVec3::ZERO),
        };
        let torque = moment_a != DVec3::ZERO || moment_b != DVec3::ZERO;
        torques_carried |= torque;
        let branch = far - xa;
        for s in sums.iter_mut() {
            let b = s.boxes.expect("set above");
            let weight = b.fraction(xa, far);
            if weight > 0.0 {
                s.contact.add_outer(f.force, branch, weight);
                s.contacts += usize::from(active);
            }
            if torque {
                let (wa, wb) = (b.fraction(xa, point), b.fraction(far, point));
                s.couple.add_outer(moment_a, point - xa, wa);
                if c.kind == ContactKind::GrainGrain {
                    s.couple.add_outer(moment_b, point - far, wb);
                }
            }
        }
    }

    // Results, written into the previous sample's storage.
    let sample = record.latest.get_or_insert_with(|| StressSample {
        step: 0,
        time: 0.0,
        regions: Vec::new(),
    });
    sample.step = clock.step;
    sample.time = clock.time;
    if sample.regions.len() != settings.regions.len()
        || sample
            .regions
            .iter()
            .zip(&settings.regions)
            .any(|(r, s)| r.name != s.name)
    {
        sample.regions.clear();
        sample
            .regions
            .extend(settings.regions.iter().map(RegionStress::empty));
    }
    for ((out, spec), s) in sample
        .regions
        .iter_mut()
        .zip(&settings.regions)
        .zip(sums.iter())
    {
        finish_region(
            out,
            spec,
            s,
            dims,
            torques_carried,
            shear.map(|shear| shear.rate),
        );
    }
    record.taken += 1;
}

/// Turns the sums of one region into its reported stresses. `imposed_rate` is the
/// Lees–Edwards shear rate, used for regions that give none of their own.
fn finish_region(
    out: &mut RegionStress,
    spec: &RegionSpec,
    s: &Sums,
    dims: usize,
    torques: bool,
    imposed_rate: Option<f64>,
) {
    let boxes = s.boxes.expect("set by the sampler");
    let volume_box: Bounds = boxes.volume;
    let volume = volume_box.volume(dims);
    out.min = finite_or_zero(volume_box.min).to_array();
    out.max = finite_or_zero(volume_box.max).to_array();
    out.volume = volume;
    out.grains = s.grains;
    out.contacts = s.contacts;
    out.mean_velocity = s.mean_velocity.to_array();
    out.shear_rate = None;
    out.shear_rate_source = None;
    out.inertial_number = None;
    out.regime = None;
    out.kinetic_share = None;
    out.couple_stress = None;
    if volume <= 0.0 {
        // A region outside the domain (or a degenerate one): nothing to divide by.
        out.solid_fraction = 0.0;
        out.stress = Tensor::ZERO;
        out.contact_stress = Tensor::ZERO;
        out.kinetic_stress = Tensor::ZERO;
        out.pressure = 0.0;
        out.shear_stress = 0.0;
        out.antisymmetric_norm = 0.0;
        return;
    }
    let contact = s.contact.scaled(1.0 / volume);
    let kinetic = s.fluctuation.scaled(-1.0 / volume);
    let total = contact.plus(kinetic);
    let d = dims as f64;
    let pressure = -total.trace(dims) / d;
    let deviator = total.symmetric_part().deviator(dims);
    let q_factor = if dims == 3 { 1.5 } else { 0.5 };
    out.solid_fraction = s.solid_volume / volume;
    out.stress = total;
    out.contact_stress = contact;
    out.kinetic_stress = kinetic;
    out.pressure = pressure;
    out.shear_stress = (q_factor * deviator.contract(&deviator)).sqrt();
    out.antisymmetric_norm = total.antisymmetric_part().norm();
    if pressure != 0.0 {
        out.kinetic_share = Some(-kinetic.trace(dims) / d / pressure);
    }
    if torques {
        out.couple_stress = Some(s.couple.scaled(1.0 / volume));
    }
    let rate = match (spec.shear_rate, imposed_rate) {
        (Some(rate), _) => Some((rate, ShearRateSource::Scene)),
        (None, Some(rate)) => Some((rate.abs(), ShearRateSource::LeesEdwards)),
        (None, None) => fitted_shear_rate(spec, s, dims).map(|r| (r, ShearRateSource::Fit)),
    };
    if let Some((rate, source)) = rate.filter(|(r, _)| r.is_finite()) {
        out.shear_rate = Some(rate);
        out.shear_rate_source = Some(source);
        if pressure > 0.0 && s.grains > 0 {
            let n = s.grains as f64;
            let diameter = s.diameter / n;
            let density = s.density / n;
            let i = rate * diameter * (density / pressure).sqrt();
            if i.is_finite() {
                out.inertial_number = Some(i);
                out.regime = Some(FlowRegime::of(i));
            }
        }
    }
}

/// The shear rate from a mass-weighted least-squares fit v(x) ≈ v̄ + G (x − x̄) over the
/// region's grains. Slab: G restricted to the slab axis a, γ̇ = |∂v_t/∂x_a| with v_t the
/// velocity components other than a (in-plane in 2-D). Domain and box: the full gradient,
/// γ̇ = √(2 D′:D′) with D the strain rate ½(G + Gᵀ) and D′ its deviator, which is γ̇ for
/// simple shear. `None` when the positions do not determine the fit.
fn fitted_shear_rate(spec: &RegionSpec, s: &Sums, dims: usize) -> Option<f64> {
    match spec.shape {
        crate::region::RegionShape::Slab { axis, .. } => {
            let c = s.spread.0[axis][axis];
            if s.grains < 2 || c.is_nan() || c <= 0.0 {
                return None;
            }
            let sum: f64 = (0..dims)
                .filter(|&i| i != axis)
                .map(|i| (s.velocity_position.0[i][axis] / c).powi(2))
                .sum();
            Some(sum.sqrt())
        }
        _ => {
            if s.grains < dims + 1 {
                return None;
            }
            let inverse = s.spread.inverse_leading(dims)?;
            let gradient = s.velocity_position.mul(&inverse);
            let mut strain_rate = gradient.symmetric_part();
            // Only the in-plane block is fitted in 2-D.
            for i in dims..3 {
                for j in 0..3 {
                    strain_rate.0[i][j] = 0.0;
                    strain_rate.0[j][i] = 0.0;
                }
            }
            let deviator = strain_rate.deviator(dims);
            Some((2.0 * deviator.contract(&deviator)).sqrt())
        }
    }
}

fn finite_or_zero(v: DVec3) -> DVec3 {
    DVec3::new(
        if v.x.is_finite() { v.x } else { 0.0 },
        if v.y.is_finite() { v.y } else { 0.0 },
        if v.z.is_finite() { v.z } else { 0.0 },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regimes_of_the_worked_numbers() {
        // Seed 003: d √(ρ_s / p) = 2e-4 s; γ̇ = 1 /s gives I = 2e-4, γ̇ = 300 /s gives 6e-2.
        let time_scale = 2e-4;
        assert_eq!(FlowRegime::of(1.0 * time_scale), FlowRegime::QuasiStatic);
        assert_eq!(
            FlowRegime::of(300.0 * time_scale),
            FlowRegime::DenseInertial
        );
        assert_eq!(FlowRegime::of(0.5), FlowRegime::GasLike);
        assert_eq!(
            FlowRegime::of(QUASI_STATIC_LIMIT),
            FlowRegime::DenseInertial
        );
        assert_eq!(FlowRegime::of(GAS_LIKE_LIMIT), FlowRegime::DenseInertial);
    }
}
