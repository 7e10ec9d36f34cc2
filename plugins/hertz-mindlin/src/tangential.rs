//! The Mindlin tangential part: an incremental tangential spring of stiffness
//! k_t = 8 G* √(R* δ), stored as a force, rotated into the tangent plane every step,
//! capped by Coulomb friction μ|F_n|, with an optional dashpot.

use glam::DVec3;
use talus_contact::*;
use talus_core::lanes::{F4, M4, V4};
use talus_linear_spring::{rotate_into_plane, rotate_into_plane_lanes};

use crate::analytic::{
    damping_from_restitution, hertz_max_overlap, hertz_stiffness, mindlin_stiffness,
};
use crate::params::{HertzModuli, TANGENTIAL_PARAMS, characteristic_velocity};

/// Mindlin's no-slip tangential stiffness k_t = 8 G* √(R* δ) applied incrementally to
/// the force, F_t ← F_t(rotated) − k_t Δ_t (Mindlin–Deresiewicz loading, the
/// `mindlin/force` choice of LAMMPS). While the contact sticks, a dashpot −c_t v_t (c_t a
/// fraction of the normal dashpot) acts beside the spring, limited so that the total stays
/// within μ|F_n|; when the spring alone exceeds μ|F_n| the contact slides, the spring is
/// reset to carry the capped force and the dashpot is idle. Parameters `friction`,
/// `tangential_damping_ratio`.
pub struct MindlinTangential;

/// Resolved parameters of [`MindlinTangential`] for one material pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MindlinParams {
    /// Effective shear modulus G*, Pa.
    pub effective_shear_modulus: f64,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// c_t / c_n.
    pub damping_ratio: f64,
    /// Stability limit of the tangential mode at the characteristic impact's largest
    /// overlap, s (infinite without friction).
    pub stability_limit: f64,
}

/// History of [`MindlinTangential`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MindlinHistory {
    /// Tangential spring force on `a` after the previous evaluation, N.
    pub spring: DVec3,
    /// Tangential dashpot force of the previous evaluation, N.
    pub dashpot: DVec3,
    /// k_t of the previous evaluation, N/m: the spring is released with it when the
    /// bodies separate.
    pub stiffness: f64,
    /// Elastic energy |F_spring|²/(2k_t) of the previous evaluation, J.
    pub energy: f64,
}

impl SubModel for MindlinTangential {
    const KIND: SubModelKind = SubModelKind::Tangential;
    const NAME: &'static str = "mindlin";
    const PARAMS: &'static [ParamSpec] = TANGENTIAL_PARAMS;
    const DISSIPATION: &'static [&'static str] = &[
        "tangential_damping",
        "friction_slip",
        "mindlin_stiffness_change",
    ];
    type Params = MindlinParams;
    type History = MindlinHistory;

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<MindlinParams, ParamError> {
        let moduli = HertzModuli::of_pair(pair)?;
        let friction = values.get("friction").unwrap_or(0.0);
        let damping_ratio = values.get("tangential_damping_ratio").unwrap_or(0.0);
        let mut stability_limit = f64::INFINITY;
        if friction > 0.0 {
            // Tangential mode of two spheres (rolling included): effective mass (2/7) m*,
            // at the stiffness of the characteristic impact's largest overlap.
            let (m, r) = (pair.min_effective_mass, pair.min_effective_radius);
            let v = characteristic_velocity(values);
            let e_star = moduli.effective_modulus;
            let overlap = hertz_max_overlap(m, r, e_star, v);
            let kt = mindlin_stiffness(moduli.effective_shear_modulus, r, overlap);
            let omega = (3.5 * kt / m).sqrt();
            // Its dashpot c_t = ratio × γ̂ √((2/3) m* k_n): damping ratio of the mode.
            let zeta = match values.get("restitution").and_then(damping_from_restitution) {
                Some(gamma) if damping_ratio > 0.0 => {
                    let kn = hertz_stiffness(e_star, r, overlap);
                    let ct = damping_ratio * gamma * (2.0 / 3.0 * m * kn).sqrt();
                    ct / (2.0 * (2.0 / 7.0 * m * kt).sqrt())
                }
                _ => 0.0,
            };
            stability_limit = 2.0 / omega * ((1.0 + zeta * zeta).sqrt() - zeta);
        }
        Ok(MindlinParams {
            effective_shear_modulus: moduli.effective_shear_modulus,
            friction,
            damping_ratio,
            stability_limit,
        })
    }

    fn needs(values: &ParamValues) -> Needs {
        Needs {
            rotation: values.get("friction").unwrap_or(0.0) > 0.0,
            range: 0.0,
        }
    }

    /// Only a stability limit (the contact time is the normal part's).
    fn time_scale(p: &MindlinParams, _pair: &PairAssignment) -> Option<TimeScale> {
        p.stability_limit.is_finite().then_some(TimeScale {
            contact_time: f64::INFINITY,
            stability_limit: p.stability_limit,
        })
    }

    #[inline]
    fn evaluate(
        p: &MindlinParams,
        kin: &ContactKinematics,
        h: &mut MindlinHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let displacement = kin.displacement;
        let n = kin.normal;
        let tangential_displacement = displacement - n * n.dot(displacement);
        let rotated = rotate_into_plane(h.spring, n);
        // The old spring force acted in the old tangent plane; the accounting below
        // rotates it first. The difference is energy the integration made.
        let rotation_error =
            0.5 * (h.spring.dot(displacement) - rotated.dot(tangential_displacement));
        if kin.overlap <= 0.0 {
            // Ended: the slider's cap is zero, so it releases the spring (the slip formula
            // below with a new spring force of zero, at the old stiffness); the dashpot's
            // last force worked over half a step.
            s.dissipate(0, -0.5 * h.dashpot.dot(displacement));
            if h.stiffness > 0.0 {
                let trial = rotated - h.stiffness * tangential_displacement;
                s.dissipate(1, 0.5 * rotated.dot(trial) / h.stiffness);
            }
            s.integration_error += rotation_error;
            *h = MindlinHistory::default();
            return;
        }
        if p.friction <= 0.0 {
            return;
        }
        let kt = mindlin_stiffness(p.effective_shear_modulus, kin.effective_radius, kin.overlap);
        let cap = p.friction * s.normal_force().abs();
        let trial = rotated - kt * tangential_displacement;
        let trial_squared = trial.length_squared();
        let (spring, dashpot) = if trial_squared > cap * cap {
            // Sliding. The spring and the dashpot sit side by side, in series with the
            // slider: while the contact slides the spring stays stretched to the cap, so
            // the dashpot sees no velocity and the spring carries the whole capped force.
            let spring = trial * (cap / trial_squared.sqrt());
            // Work of the slider force (the spring force) along the slip
            // (F_trial − F_spring)/k_t, by the trapezoidal rule.
            s.dissipate(1, 0.5 * (rotated + spring).dot(trial - spring) / kt);
            (spring, DVec3::ZERO)
        } else {
            // Sticking: the dashpot acts on the whole tangential velocity, limited so
            // that spring and dashpot together stay within the Coulomb cap.
            let ct = p.damping_ratio * s.damping_coefficient;
            let dashpot = -ct * kin.tangential_velocity;
            (trial, dashpot * dashpot_share(trial, dashpot, cap))
        };
        let energy = 0.5 * spring.length_squared() / kt;
        // The stored force kept its size while the stiffness went from the old k_t to
        // this one: its energy |F|²/(2k_t) changed by this much without any work. This is
        // the incremental Mindlin spring's own non-conservation (a property of the model,
        // not a truncation error), so it is booked on its own signed channel: positive
        // when the stiffening contact loses stored energy, negative when it gains.
        let stiffness_change = 0.5 * h.spring.length_squared() / kt - h.energy;
        s.dissipate(2, -stiffness_change);
        s.integration_error += rotation_error;
        s.tangential_force = spring + dashpot;
        s.elastic_energy += energy;
        s.dissipate(0, -0.5 * (h.dashpot + dashpot).dot(displacement));
        h.spring = spring;
        h.dashpot = dashpot;
        h.stiffness = kt;
        h.energy = energy;
    }

    const LANES: bool = true;

    #[inline(always)]
    fn evaluate_lanes(
        p: [&MindlinParams; 4],
        kin: &ContactKinematicsLanes,
        h: [&mut MindlinHistory; 4],
        s: &mut ContactStateLanes,
        _dt: f64,
        book: bool,
    ) {
        let zero = F4::zero();
        let (half, minus_half) = (F4::splat(0.5), F4::splat(-0.5));
        let displacement = kin.displacement;
        let n = kin.normal;
        let tangential_displacement = displacement - n * n.dot(displacement);
        let old_spring = V4::from_fn(|l| h[l].spring);
        let old_dashpot = V4::from_fn(|l| h[l].dashpot);
        let rotated = rotate_into_plane_lanes(old_spring, n);
        let released = kin.overlap.le(zero);
        let friction = F4::from_fn(|l| p[l].friction);
        // Lanes that touch with friction; those that touch without keep everything.
        let acting = (!released).and(friction.gt(zero));

        let shear_modulus = F4::from_fn(|l| p[l].effective_shear_modulus);
        let kt = F4::splat(8.0) * shear_modulus * (kin.effective_radius * kin.overlap).sqrt();
        let cap = friction * s.normal_force().abs();
        let trial = rotated - tangential_displacement * kt;
        let trial_squared = trial.length_squared();
        let slides = trial_squared.gt(cap * cap);
        let slid_spring = trial * (cap / trial_squared.sqrt());
        let ct = F4::from_fn(|l| p[l].damping_ratio) * s.damping_coefficient;
        let free_dashpot = kin.tangential_velocity * -ct;
        let stuck_dashpot = free_dashpot * dashpot_share_lanes(trial, free_dashpot, cap);
        let spring = slides.select3(slid_spring, trial);
        let dashpot = slides.select3(V4::zero(), stuck_dashpot);
        let energy = half * spring.length_squared() / kt;
        s.tangential_force = acting.select3(spring + dashpot, s.tangential_force);

        if book {
            let rotation_error =
                half * (old_spring.dot(displacement) - rotated.dot(tangential_displacement));
            let old_stiffness = F4::from_fn(|l| h[l].stiffness);
            let old_energy = F4::from_fn(|l| h[l].energy);
            // Channel 0: the dashpot's work; 1: the slider's; 2: the stiffness change.
            let released_trial = rotated - tangential_displacement * old_stiffness;
            let released_slip = half * rotated.dot(released_trial) / old_stiffness;
            let slip = half * (rotated + slid_spring).dot(trial - slid_spring) / kt;
            let stiffness_change = half * old_spring.length_squared() / kt - old_energy;
            let base = s.channel_base;
            let add = |total: F4, mask: M4, x: F4| mask.select(total + x, total);
            s.dissipated[base + 1] = add(s.dissipated[base + 1], acting.and(slides), slip);
            s.dissipated[base + 2] = add(s.dissipated[base + 2], acting, -stiffness_change);
            s.integration_error = add(s.integration_error, acting.or(released), rotation_error);
            s.elastic_energy = add(s.elastic_energy, acting, energy);
            let dashpot_work = released.select(
                minus_half * old_dashpot.dot(displacement),
                minus_half * (old_dashpot + dashpot).dot(displacement),
            );
            s.dissipated[base] = add(s.dissipated[base], acting.or(released), dashpot_work);
            let releases_spring = released.and(old_stiffness.gt(zero));
            s.dissipated[base + 1] = add(s.dissipated[base + 1], releases_spring, released_slip);
        }
        let (spring, dashpot) = (spring.to_array(), dashpot.to_array());
        let (kt, energy) = (kt.to_array(), energy.to_array());
        let (released, acting) = (released.bits(), acting.bits());
        for (l, h) in h.into_iter().enumerate() {
            if released >> l & 1 == 1 {
                *h = MindlinHistory::default();
            } else if acting >> l & 1 == 1 {
                *h = MindlinHistory {
                    spring: spring[l],
                    dashpot: dashpot[l],
                    stiffness: kt[l],
                    energy: energy[l],
                };
            }
        }
    }
}

/// [`dashpot_share`] in lanes, bit for bit.
#[inline(always)]
fn dashpot_share_lanes(spring: V4, dashpot: V4, cap: F4) -> F4 {
    let d2 = dashpot.length_squared();
    let fits = (spring + dashpot)
        .length_squared()
        .le(cap * cap)
        .or(d2.eq(F4::zero()));
    let b = spring.dot(dashpot);
    let c = spring.length_squared() - cap * cap;
    let share = ((-b + (b * b - d2 * c).max(F4::zero()).sqrt()) / d2).clamp(0.0, 1.0);
    fits.select(F4::splat(1.0), share)
}

/// The share s ∈ [0, 1] of the dashpot force `dashpot` that keeps |spring + s·dashpot|
/// within `cap`, given |spring| ≤ cap: 1 when the whole of it fits, else the positive root
/// of |spring + s·dashpot|² = cap².
#[inline]
fn dashpot_share(spring: DVec3, dashpot: DVec3, cap: f64) -> f64 {
    let d2 = dashpot.length_squared();
    if (spring + dashpot).length_squared() <= cap * cap || d2 == 0.0 {
        return 1.0;
    }
    let b = spring.dot(dashpot);
    let c = spring.length_squared() - cap * cap;
    ((-b + (b * b - d2 * c).max(0.0).sqrt()) / d2).clamp(0.0, 1.0)
}
