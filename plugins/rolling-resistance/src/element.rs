//! The rotational spring–dashpot–slider shared by the elastic–plastic rolling part and
//! the twisting part, with its energy bookkeeping, plus the geometric helpers both use.
//!
//! The spring stores the torque it exerts on body `a` (Ai et al.'s incremental form,
//! M_k ← M_k − k Δθ). When its stiffness changes between steps (it follows the normal
//! stiffness and, for twisting, the contact radius), the stored torque is scaled by
//! √(k_new/k_old) so that the stored energy |M_k|²/(2k) does not change without work:
//! with a constant stiffness this is Ai's form exactly. The slider caps |M_k| at the
//! part's limit and the dashpot acts only while the spring holds (Ai et al. 2011,
//! model C with f = 0).

use glam::DVec3;
use talus_contact::{ContactKinematics, ContactState, PairAssignment, SubModel, TimeScale};

/// Index of the dashpot's channel in the part's `DISSIPATION` list.
pub const DAMPING_CHANNEL: usize = 0;
/// Index of the slider's channel in the part's `DISSIPATION` list.
pub const SLIP_CHANNEL: usize = 1;

/// κ in I = κ m R² for rotation about the centre: 2/5 for a sphere, 1/2 for a disk.
#[inline]
pub fn centre_inertia_factor(planar: bool) -> f64 {
    if planar { 0.5 } else { 0.4 }
}

/// κ in I = κ m R² for rotation about a point of the rim (the contact point):
/// 2/5 + 1 = 7/5 for a sphere, 1/2 + 1 = 3/2 for a disk.
#[inline]
pub fn contact_inertia_factor(planar: bool) -> f64 {
    centre_inertia_factor(planar) + 1.0
}

/// The smallest spin inertia a part of this pair can meet, κ m*_min R*_min² (rotation
/// about the grain's centre), kg m².
#[inline]
pub fn min_spin_inertia(pair: &PairAssignment, planar: bool) -> f64 {
    centre_inertia_factor(planar)
        * pair.min_effective_mass
        * pair.min_effective_radius
        * pair.min_effective_radius
}

/// Ai et al.'s I_r of a contact about its contact point, κ_contact m* R_min² (exact for
/// equal grains and against a wall; 3/2 m R² for a disk on a wall), kg m².
#[inline]
pub fn contact_spin_inertia(planar: bool, kin: &ContactKinematics) -> f64 {
    contact_inertia_factor(planar) * kin.effective_mass * kin.min_radius * kin.min_radius
}

/// The rolling part of a relative spin: perpendicular to the normal in 3-D, the z
/// component in 2-D (where the normal lies in the xy-plane).
#[inline]
pub fn rolling_part(omega: DVec3, normal: DVec3, planar: bool) -> DVec3 {
    if planar {
        DVec3::new(0.0, 0.0, omega.z)
    } else {
        omega - normal * normal.dot(omega)
    }
}

/// Torque limit μ F_n⁺ R of a contact, N m (no tension: an attractive normal force
/// gives no limit).
#[inline]
pub fn torque_limit(friction: f64, state: &ContactState, lever: f64) -> f64 {
    friction * state.normal_force().max(0.0) * lever
}

/// Time scale of a stability bound alone (no contact time), for a rotational oscillator
/// of angular frequency `omega` and damping ratio `zeta`, integrated by the explicit
/// central-difference scheme: dt < 2/ω (√(1 + ζ²) − ζ). `None` if `omega` is not a
/// positive finite number.
pub fn oscillator_limit(omega: f64, zeta: f64) -> Option<TimeScale> {
    (omega.is_finite() && omega > 0.0).then(|| TimeScale {
        contact_time: f64::INFINITY,
        stability_limit: 2.0 / omega * ((1.0 + zeta * zeta).sqrt() - zeta),
    })
}

/// Upper estimate of the angular frequency of the normal part `N` for a pair, rad/s:
/// 2 / its stability limit (which is 2/ω for an undamped spring and shorter with
/// damping, so this errs on the stiff side).
pub fn normal_frequency<N: SubModel>(pair: &PairAssignment) -> Option<f64> {
    let params = N::resolve(&pair.values, pair).ok()?;
    let limit = N::time_scale(&params, pair)?.stability_limit;
    (limit.is_finite() && limit > 0.0).then(|| 2.0 / limit)
}

/// Per-contact history of a [`TorqueSpringLaw`] element.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TorqueSpringHistory {
    /// Spring torque on body `a` after the last evaluation, N m.
    pub spring: DVec3,
    /// Dashpot torque on body `a` of the last evaluation, N m.
    pub dashpot: DVec3,
    /// Spring stiffness of the last evaluation, N m/rad (0 until the spring is loaded).
    /// The spring is released with it once the bodies separate, when the normal part
    /// reports no stiffness any more.
    pub stiffness: f64,
}

/// The constants of one element for one contact and step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TorqueSpringLaw {
    /// Spring stiffness k, N m/rad.
    pub stiffness: f64,
    /// Dashpot coefficient c, N m s.
    pub damping: f64,
    /// Slider limit on |M_k|, N m.
    pub cap: f64,
}

impl TorqueSpringLaw {
    /// The element that releases a spring when its contact ends: the cap is zero, so the
    /// slider lets go of whatever the spring held, and the dashpot is gone. Its stiffness
    /// is the last one the spring had, so that the release is booked like any slip.
    pub fn release(history: &TorqueSpringHistory) -> Self {
        Self {
            stiffness: history.stiffness,
            damping: 0.0,
            cap: 0.0,
        }
    }

    /// Advances the element over one step, books its energy into `state` and returns the
    /// torque on body `a` (spring + dashpot).
    ///
    /// * `rotated`: the spring torque of the last evaluation carried into the current
    ///   contact frame (same magnitude; the stiffness scaling is applied here);
    /// * `increment`: the relative rotation over the step along the element's own
    ///   directions (the rolling plane or the normal), rad;
    /// * `full_increment`: the whole relative rotation ω_rel dt, on which the torques of
    ///   the last evaluation worked;
    /// * `rate`: the relative angular velocity along the element's directions, rad/s.
    ///
    /// Energy (`docs/physics/energy-accounting.md`): the slider books the trapezoidal
    /// work of the spring torque along the slipped rotation, ½(M_rot + M_k)·(M_trial −
    /// M_k)/k; the dashpot ½(M_d,old + M_d)·Δθ; the stored energy is |M_k|²/(2k); the
    /// integration error is the trapezoidal work of the spring torques on the bodies,
    /// plus the change of the stored energy, plus the slip: zero but for the rotation of
    /// the contact frame and the stiffness scaling within the step (O(dt²) per step).
    #[inline]
    pub fn advance(
        &self,
        history: &mut TorqueSpringHistory,
        rotated: DVec3,
        increment: DVec3,
        full_increment: DVec3,
        rate: DVec3,
        state: &mut ContactState,
    ) -> DVec3 {
        let k = self.stiffness;
        let old_energy = stored_energy(history.spring, history.stiffness);
        // A stiffness that follows the overlap (k_tw ∝ δ, or k_n ∝ √δ under Hertz) would
        // otherwise change the stored energy |M|²/(2k) with no work done: the spring
        // keeps its energy instead, its torque scaling as √(k_new/k_old).
        let rotated = if history.stiffness > 0.0 && k > 0.0 && k != history.stiffness {
            rotated * (k / history.stiffness).sqrt()
        } else {
            rotated
        };
        let trial = rotated - increment * k;
        let trial_magnitude = trial.length();
        let sliding = trial_magnitude > self.cap;
        let spring = if !sliding {
            trial
        } else if trial_magnitude > 0.0 {
            trial * (self.cap / trial_magnitude)
        } else {
            DVec3::ZERO
        };
        let slip = if sliding && k > 0.0 {
            0.5 * (rotated + spring).dot(trial - spring) / k
        } else {
            0.0
        };
        let new_energy = stored_energy(spring, k);
        let spring_work = 0.5 * (history.spring + spring).dot(full_increment);
        state.dissipate(SLIP_CHANNEL, slip);
        state.elastic_energy += new_energy;
        state.integration_error += spring_work + new_energy - old_energy + slip;
        // Ai's model C: the dashpot works only while the spring holds; once it slides the
        // slider alone limits the torque.
        let dashpot = if sliding {
            DVec3::ZERO
        } else {
            -self.damping * rate
        };
        state.dissipate(
            DAMPING_CHANNEL,
            -0.5 * (history.dashpot + dashpot).dot(full_increment),
        );
        history.spring = spring;
        history.dashpot = dashpot;
        history.stiffness = k;
        spring + dashpot
    }
}

/// Energy |M|²/(2k) of a spring holding torque `torque` at stiffness `k` (0 for an
/// unloaded spring).
#[inline]
fn stored_energy(torque: DVec3, k: f64) -> f64 {
    if k > 0.0 {
        0.5 * torque.length_squared() / k
    } else {
        0.0
    }
}
