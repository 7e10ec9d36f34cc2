//! The thermodynamic contact law of Jiang & Liu (2018), eqs. (19)–(41), in 3-D with
//! rotation: an elastic spring u = (u_n, u_t) with the Hertz-like potential (19), an
//! Onsager closure (28)–(33) that moves mechanical energy into heat through a buffer,
//! the relaxation energy w_r, and the parameter model (37)–(41) as the default.
//!
//! Decisions (see `docs/laws/jiang-liu.md`):
//! * the yield coefficient λ_t^heat of (41), whose prefactor the source lost, is taken in
//!   its λ → ∞ limit: a return mapping of u_t onto the yield surface |u_t| = √(2ξ)(−u_n)
//!   after every sub-step, the released elastic energy booked as heat;
//! * w_r is integrated as s = w_r^{3/4}, whose rate is regular at s = 0, so that a
//!   collision starting at w_r = 0 takes the physical (maximal) branch;
//! * the Heaviside steps Θ(δ/d) are sharp by default and smoothed as
//!   ½[tanh((x − x0)/x1) + 1] when `heaviside_width` x1 > 0;
//! * the cohesive force −c, which switches with the contact, is weighted at the touch
//!   step and followed by one last pull at separation so that its discrete work can only
//!   lose energy, never create it.
//!
//! Energy: w_e is the contact's elastic energy; channel `heat` books ∫R dt; channel
//! `relaxation_storage` books the signed change of w_r, so that the running sum of that
//! channel is the relaxation energy stored now and kinetic + elastic + dissipated is the
//! paper's conserved sum (17).

#![warn(missing_docs)]

use std::any::Any;

use glam::DVec3;
use talus_contact::*;
use talus_core::schedule::SimBuilder;
use talus_linear_spring::rotate_into_plane;

/// Name scenes use.
pub const NAME: &str = "jiang_liu";

/// One line for `talus check` and the docs.
pub const SUMMARY: &str = "thermodynamic contact law of Jiang & Liu (2018): Hertz-like elastic spring, \
     relaxation-energy buffer, heat, Coulomb yield";

/// Index of the heat channel in [`ContactLaw::dissipation`].
pub const HEAT_CHANNEL: usize = 0;
/// Index of the relaxation-storage channel (signed change of w_r).
pub const RELAXATION_CHANNEL: usize = 1;

/// Per-contact quantities the law exposes to the recording, in this order: w_e (J), w_r
/// (J), the mean heat rate R of the last step (W), the heat the contact has released since
/// it started (J), u_n (m, negative in compression) and |u_t| (m).
pub const CONTACT_QUANTITIES: [&str; 6] = [
    "elastic_energy",
    "relaxation_energy",
    "heat_rate",
    "heat",
    "normal_displacement",
    "tangential_displacement",
];

/// Largest number of sub-steps one evaluation takes (bounds the cost of a stiff contact).
pub const MAX_SUBSTEPS: u32 = 4096;
/// Sub-step length as a fraction of the fastest relaxation time of the contact: explicit
/// midpoint is stable below 2 and accurate to about 1e-3 per time constant at 0.25.
pub const SUBSTEP_FRACTION: f64 = 0.25;

/// Default characteristic impact speed for the time scale, m/s.
pub const DEFAULT_CHARACTERISTIC_VELOCITY: f64 = 1.0;

/// Resolved parameters of one material pair: the coefficients of set (34), each a
/// prefactor of the functional form (37)–(41) or a constant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JiangLiuParams {
    /// Spring constant k of (19), kg s⁻² m^-½.
    pub stiffness: f64,
    /// Shear ratio ξ of (19) (yield |u_t| ≤ √(2ξ)(−u_n)).
    pub xi: f64,
    /// Wet-cohesion constant c of (19), N.
    pub cohesion: f64,
    /// α_n while the grains overlap (38 with this value inside contact; 1 outside).
    pub alpha_n: f64,
    /// α_t while the grains overlap.
    pub alpha_t: f64,
    /// Prefactor of η_n^relax (39) (paper: 0.1).
    pub eta_relax_n: f64,
    /// Prefactor of η_t^relax (39) (paper: 0.1).
    pub eta_relax_t: f64,
    /// η_n^heat, a dashpot acting while overlapping, N s/m (paper: 0).
    pub eta_heat_n: f64,
    /// η_t^heat, N s/m (paper: 0).
    pub eta_heat_t: f64,
    /// Prefactor of λ_n^relax in the form (40) (paper: 0).
    pub lambda_relax_n: f64,
    /// Prefactor of λ_t^relax (40) (paper: 0.1).
    pub lambda_relax_t: f64,
    /// λ_n^heat, constant, m N⁻¹ s⁻¹ (paper: 0).
    pub lambda_heat_n: f64,
    /// Smooth part of λ_t^heat, constant, m N⁻¹ s⁻¹ (paper: 0; the yield part of (41) is
    /// the return mapping).
    pub lambda_heat_t: f64,
    /// Prefactor of τ_r in (37) (paper: 0.06).
    pub relaxation_time_factor: f64,
    /// Heaviside offset x0 of Θ(x) ≈ ½[tanh((x − x0)/x1) + 1] (dimensionless, x = δ/d).
    pub heaviside_offset: f64,
    /// Heaviside width x1; 0 makes Θ the sharp step at x0.
    pub heaviside_width: f64,
    /// Impact speed the automatic time step is made for, m/s.
    pub characteristic_velocity: f64,
}

impl JiangLiuParams {
    /// The paper's parameter model (37)–(41) with spring constant `stiffness`.
    pub fn paper(stiffness: f64) -> Self {
        Self {
            stiffness,
            xi: 1.0,
            cohesion: 0.0,
            alpha_n: 0.0,
            alpha_t: 0.0,
            eta_relax_n: 0.1,
            eta_relax_t: 0.1,
            eta_heat_n: 0.0,
            eta_heat_t: 0.0,
            lambda_relax_n: 0.0,
            lambda_relax_t: 0.1,
            lambda_heat_n: 0.0,
            lambda_heat_t: 0.0,
            relaxation_time_factor: 0.06,
            heaviside_offset: 0.0,
            heaviside_width: 0.0,
            characteristic_velocity: DEFAULT_CHARACTERISTIC_VELOCITY,
        }
    }

    /// The Heaviside step Θ(x), sharp or smoothed per the parameters.
    #[inline]
    pub fn heaviside(&self, x: f64) -> f64 {
        if self.heaviside_width > 0.0 {
            0.5 * (((x - self.heaviside_offset) / self.heaviside_width).tanh() + 1.0)
        } else if x > self.heaviside_offset {
            1.0
        } else {
            0.0
        }
    }

    /// Grain scales of the paper for a pair: m = 2 m* and d = 4 R*, which are the grain
    /// mass and diameter of two equal grains, as (37)–(41) assume.
    #[inline]
    pub fn grain_scales(effective_mass: f64, effective_radius: f64) -> (f64, f64) {
        (2.0 * effective_mass, 4.0 * effective_radius)
    }

    /// Relaxation time τ_r = factor √(m/k) / d^{1/4} (37), s.
    #[inline]
    pub fn relaxation_time(&self, mass: f64, diameter: f64) -> f64 {
        self.relaxation_time_factor * (mass / self.stiffness).sqrt() / diameter.powf(0.25)
    }
}

/// Elastic potential w_e(u) of (19), J. For u_n ≥ 0 (a slack spring) only the cohesion
/// term c u_n remains, which keeps w_e continuous.
#[inline]
pub fn elastic_potential(p: &JiangLiuParams, u_n: f64, u_t: DVec3) -> f64 {
    if u_n >= 0.0 {
        return p.cohesion * u_n;
    }
    p.stiffness * (-u_n).sqrt() * (0.4 * u_n * u_n + u_t.length_squared() / p.xi) + p.cohesion * u_n
}

/// Spring forces π = −∂w_e/∂u of (20)–(21): (π_n, π_t), N.
#[inline]
pub fn spring_force(p: &JiangLiuParams, u_n: f64, u_t: DVec3) -> (f64, DVec3) {
    if u_n >= 0.0 {
        return (-p.cohesion, DVec3::ZERO);
    }
    let root = (-u_n).sqrt();
    let pi_n = -p.stiffness * root * (u_n + u_t.length_squared() / (2.0 * p.xi * u_n)) - p.cohesion;
    let pi_t = -(2.0 * p.stiffness / p.xi) * root * u_t;
    (pi_n, pi_t)
}

/// Projects u_t onto the yield surface (35) |u_t| ≤ √(2ξ)(−u_n) (the λ_t^heat → ∞ limit
/// of (41)); returns the projected u_t.
#[inline]
pub fn yield_projection(p: &JiangLiuParams, u_n: f64, u_t: DVec3) -> DVec3 {
    let limit = (2.0 * p.xi).sqrt() * (-u_n).max(0.0);
    let len = u_t.length();
    if len > limit {
        if len > 0.0 {
            u_t * (limit / len)
        } else {
            DVec3::ZERO
        }
    } else {
        u_t
    }
}

/// Per-contact state: the spring, the relaxation buffer, and what the energy accounting
/// of the next step needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JiangLiuState {
    /// Normal spring displacement u_n, m (negative in compression).
    pub normal_displacement: f64,
    /// Tangential spring displacement u_t (in the tangent plane), m.
    pub tangential_displacement: DVec3,
    /// w_r^{3/4}, J^{3/4}: the integrated variable of the relaxation energy.
    pub relaxation_root: f64,
    /// Relaxation energy w_r, J.
    pub relaxation_energy: f64,
    /// Elastic energy w_e after the last evaluation, J.
    pub elastic_energy: f64,
    /// Heat released by this contact since it started, J.
    pub heat: f64,
    /// Mean heat rate R over the last step, W.
    pub heat_rate: f64,
    /// Force on `a` of the last evaluation, N (for the trapezoidal work of the next step).
    pub force: DVec3,
    /// Overlap of the last evaluation, m.
    pub overlap: f64,
    /// Relative velocity at the contact point of the last evaluation (a half-step
    /// velocity), m/s.
    pub velocity: DVec3,
    /// Whether the state has been started (false for a contact made this step).
    pub active: bool,
    /// Unit normal of the last evaluation (zero before the first): the step's relative
    /// displacement is split along the mean of the old and new normals.
    #[serde(default)]
    pub normal: DVec3,
}

/// Coefficients of one contact, with the grain scales folded in.
#[derive(Clone, Copy, Debug)]
struct Coefficients {
    /// d^{-3/8} k^{1/4} m^{1/2}: η^relax = prefactor × this × w_r^{1/4} Θ.
    eta_scale: f64,
    /// d^{-3/2} m^{-1/2} k^{-1}: λ^relax = prefactor × this × w_r^{1/2}.
    lambda_scale: f64,
    /// τ_r, s.
    relaxation_time: f64,
    /// Diameter d, m.
    diameter: f64,
}

/// Time derivatives of the state and the heat rate at one instant.
#[derive(Clone, Copy, Debug)]
struct Rates {
    du_n: f64,
    du_t: DVec3,
    ds: f64,
    heat: f64,
}

/// The right-hand sides of (30), (31), (32) written for s = w_r^{3/4}, and (33).
#[allow(clippy::too_many_arguments)]
#[inline]
fn rates(
    p: &JiangLiuParams,
    c: &Coefficients,
    u_n: f64,
    u_t: DVec3,
    s: f64,
    overlap: f64,
    v_n: f64,
    v_t: DVec3,
) -> Rates {
    let s = s.max(0.0);
    let w_quarter = s.cbrt(); // w_r^{1/4}
    let w_half = w_quarter * w_quarter; // w_r^{1/2}
    let w_r = w_quarter * s; // w_r = s^{4/3}
    let theta = p.heaviside(overlap / c.diameter);
    let (pi_n, pi_t) = spring_force(p, u_n, u_t);
    let gear_n = (1.0 - p.alpha_n) * theta;
    let gear_t = (1.0 - p.alpha_t) * theta;
    let lambda_n = p.lambda_heat_n + p.lambda_relax_n * c.lambda_scale * w_half;
    let lambda_t = p.lambda_heat_t + p.lambda_relax_t * c.lambda_scale * w_half;
    let (vn2, vt2) = (v_n * v_n, v_t.length_squared());
    let (pin2, pit2) = (pi_n * pi_n, pi_t.length_squared());
    // ds/dt = ¾ w_r^{-1/4} dw_r/dt: the w_r^{1/4} of η^relax cancels, which makes the rate
    // regular (and positive while the grains move) at w_r = 0.
    let ds = 0.75
        * (c.eta_scale * theta * (p.eta_relax_n * vn2 + p.eta_relax_t * vt2)
            + w_quarter * c.lambda_scale * (p.lambda_relax_n * pin2 + p.lambda_relax_t * pit2)
            - s / c.relaxation_time);
    let heat = p.lambda_heat_n * pin2
        + p.lambda_heat_t * pit2
        + theta * (p.eta_heat_n * vn2 + p.eta_heat_t * vt2)
        + w_r / c.relaxation_time;
    Rates {
        du_n: gear_n * v_n + lambda_n * pi_n,
        du_t: gear_t * v_t + lambda_t * pi_t,
        ds,
        heat,
    }
}

/// Force (28)–(29) on body `a`, along +n for the normal part, N, with the cohesive part
/// −c of π_n weighted by `cohesion_weight` (1 but in the step a contact starts, §5).
#[allow(clippy::too_many_arguments)]
#[inline]
fn contact_force(
    p: &JiangLiuParams,
    c: &Coefficients,
    state: &JiangLiuState,
    n: DVec3,
    overlap: f64,
    v_n: f64,
    v_t: DVec3,
    cohesion_weight: f64,
) -> DVec3 {
    let theta = p.heaviside(overlap / c.diameter);
    let (pi_n, pi_t) = spring_force(p, state.normal_displacement, state.tangential_displacement);
    let pi_n = pi_n + (1.0 - cohesion_weight) * p.cohesion;
    let w_quarter = state.relaxation_root.max(0.0).cbrt();
    let eta_n = theta * (p.eta_heat_n + p.eta_relax_n * c.eta_scale * w_quarter);
    let eta_t = theta * (p.eta_heat_t + p.eta_relax_t * c.eta_scale * w_quarter);
    n * ((1.0 - p.alpha_n) * theta * pi_n - eta_n * v_n) + (1.0 - p.alpha_t) * theta * pi_t
        - eta_t * v_t
}

/// What one integration over an interval produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepHeat {
    /// Heat of (33) over the interval, J (with the yield part).
    pub heat: f64,
    /// Of which the return mapping onto the yield surface released, J.
    pub yield_heat: f64,
}

/// Integrates (30)–(33) for one contact over `duration` at constant relative velocity
/// (v_n, v_t), the overlap moving linearly from `overlap_start` to `overlap_end`, with
/// explicit-midpoint sub-steps no longer than [`SUBSTEP_FRACTION`] of the fastest
/// relaxation time; the yield return mapping after each sub-step. Updates u, s and w_r.
#[allow(clippy::too_many_arguments)]
pub fn integrate_state(
    p: &JiangLiuParams,
    effective_mass: f64,
    effective_radius: f64,
    state: &mut JiangLiuState,
    duration: f64,
    overlap_start: f64,
    overlap_end: f64,
    v_n: f64,
    v_t: DVec3,
) -> StepHeat {
    let c = coefficients(p, effective_mass, effective_radius);
    integrate_with(p, &c, state, duration, overlap_start, overlap_end, v_n, v_t)
}

#[inline]
fn coefficients(p: &JiangLiuParams, effective_mass: f64, effective_radius: f64) -> Coefficients {
    let (m, d) = JiangLiuParams::grain_scales(effective_mass, effective_radius);
    let k = p.stiffness;
    Coefficients {
        eta_scale: d.powf(-0.375) * k.powf(0.25) * m.sqrt(),
        lambda_scale: 1.0 / (d.powf(1.5) * m.sqrt() * k),
        relaxation_time: p.relaxation_time(m, d),
        diameter: d,
    }
}

#[allow(clippy::too_many_arguments)]
#[inline]
fn integrate_with(
    p: &JiangLiuParams,
    c: &Coefficients,
    state: &mut JiangLiuState,
    duration: f64,
    overlap_start: f64,
    overlap_end: f64,
    v_n: f64,
    v_t: DVec3,
) -> StepHeat {
    let mut out = StepHeat::default();
    if duration <= 0.0 {
        return out;
    }
    // Fastest relaxation rate: w_r's own decay (¾/τ for s), the spring relaxations
    // λ ∂π/∂u at the deepest overlap of the interval (estimated with the largest w_r the
    // interval can reach, w_r + its production bound).
    let depth = overlap_start
        .max(overlap_end)
        .max(-state.normal_displacement)
        .max(0.0);
    let spring_rate = p.stiffness * depth.sqrt();
    // s grows at most by its source ¾ η-part (the λ-part is bounded by the spring
    // relaxation it causes, which the sub-steps resolve).
    let s_bound = state.relaxation_root
        + 0.75
            * duration
            * c.eta_scale
            * (p.eta_relax_n * v_n * v_n + p.eta_relax_t * v_t.length_squared());
    let w_half = s_bound.max(0.0).powf(2.0 / 3.0);
    let rate = (0.75 / c.relaxation_time)
        .max(1.5 * spring_rate * (p.lambda_heat_n + p.lambda_relax_n * c.lambda_scale * w_half))
        .max(
            2.0 / p.xi
                * spring_rate
                * (p.lambda_heat_t + p.lambda_relax_t * c.lambda_scale * w_half),
        );
    let wanted = (duration * rate / SUBSTEP_FRACTION).ceil();
    let steps = if wanted.is_finite() {
        wanted.clamp(1.0, MAX_SUBSTEPS as f64)
    } else {
        MAX_SUBSTEPS as f64
    };
    let h = duration / steps;
    let slope = (overlap_end - overlap_start) / duration;
    let (mut u_n, mut u_t, mut s) = (
        state.normal_displacement,
        state.tangential_displacement,
        state.relaxation_root,
    );
    for i in 0..steps as u32 {
        let t0 = i as f64 * h;
        let k1 = rates(p, c, u_n, u_t, s, overlap_start + slope * t0, v_n, v_t);
        let (mn, mt, ms) = (
            u_n + 0.5 * h * k1.du_n,
            u_t + 0.5 * h * k1.du_t,
            (s + 0.5 * h * k1.ds).max(0.0),
        );
        // The midpoint too stays on the yield surface: while sliding, the state moves
        // along the surface, and a midpoint beyond it would overstate π_t (first order).
        let mt = yield_projection(p, mn, mt);
        let slider_force = spring_force(p, mn, mt).1.length();
        let k2 = rates(
            p,
            c,
            mn,
            mt,
            ms,
            overlap_start + slope * (t0 + 0.5 * h),
            v_n,
            v_t,
        );
        u_n += h * k2.du_n;
        u_t += h * k2.du_t;
        s = (s + h * k2.ds).max(0.0);
        out.heat += h * k2.heat;
        let projected = yield_projection(p, u_n, u_t);
        if projected != u_t {
            // Heat of the slip |u_t − u_t^proj| at the slider force, the spring force |π_t|
            // on the surface at the sub-step's midpoint (a slider in series with the
            // spring): the λ_t^heat → ∞ limit of ∫λ_t^heat π_t² dt, by the same midpoint
            // rule as the rest of the step, hence second order in the sub-step.
            let released = slider_force * (u_t - projected).length();
            out.yield_heat += released;
            out.heat += released;
            u_t = projected;
        }
    }
    state.normal_displacement = u_n;
    state.tangential_displacement = u_t;
    state.relaxation_root = s;
    state.relaxation_energy = s * s.cbrt();
    out
}

/// The law's force routine.
pub struct JiangLiu;

impl ContactLaw for JiangLiu {
    type Params = JiangLiuParams;
    type History = JiangLiuState;

    fn dissipation() -> Vec<&'static str> {
        vec!["heat", "relaxation_storage"]
    }

    fn contact_quantity_names() -> &'static [&'static str] {
        &CONTACT_QUANTITIES
    }

    fn contact_quantities(state: &JiangLiuState, out: &mut [f64]) {
        out.copy_from_slice(&[
            state.elastic_energy,
            state.relaxation_energy,
            state.heat_rate,
            state.heat,
            state.normal_displacement,
            state.tangential_displacement.length(),
        ]);
    }

    fn evaluate(
        p: &JiangLiuParams,
        kin: &ContactKinematics,
        state: &mut JiangLiuState,
        dt: f64,
    ) -> ContactResponse {
        let mut out = ContactResponse::default();
        let n = kin.normal;
        let displacement = kin.displacement;
        // Trapezoidal work of the old force over the step (the new one is added below):
        // what the integrator gives the bodies.
        let old_work = 0.5 * state.force.dot(displacement);
        if kin.overlap <= 0.0 {
            // The contact ended during this step. What the spring and the buffer still
            // hold has no excitation left and relaxes into heat (the paper's "quickly
            // decays to zero" after separation). A negative w_e is the part of the
            // cohesive well c u_n the last step left unbroken (u_n lags −δ by one step;
            // in continuous time u_n = −δ = 0 at separation): releasing it is no heat but
            // the integrator's error, booked there.
            let (w_e, w_r) = (state.elastic_energy, state.relaxation_energy);
            let released = w_e.max(0.0) + w_r;
            out.dissipated[HEAT_CHANNEL] = released;
            out.dissipated[RELAXATION_CHANNEL] = -w_r;
            let was_touching = state.active;
            *state = JiangLiuState::default();
            // Cohesion at separation (§5): the force −c acted over only the part of the
            // step still in contact, but the trapezoidal rule charges the last in-contact
            // force over half of it, so the mechanical energy K + w_e + w_r can rise by up
            // to ½ c Δ_n here. What it would rise by, `gain`, is taken back by a last
            // attractive force of at most c, which does −½ g Δ_n now and, while the
            // grains keep parting, negative work over the next step (booked then); never
            // so large that it reverses the parting.
            let gain = old_work - w_e - w_r;
            let parting = displacement.dot(n);
            if was_touching && p.cohesion > 0.0 && gain > 0.0 && parting > 0.0 && dt > 0.0 {
                let parting_speed = kin.relative_velocity.dot(n).max(0.0);
                let pull = (2.0 * gain / parting)
                    .min(p.cohesion)
                    .min(kin.effective_mass * parting_speed / dt);
                out.force = -pull * n;
                state.force = out.force;
            }
            // Work + Δw_e + Δw_r + heat, each from its own formula.
            out.integration_error =
                old_work + 0.5 * out.force.dot(displacement) - w_e - w_r + released;
            return out;
        }
        let c = coefficients(p, kin.effective_mass, kin.effective_radius);
        let (w_e_old, w_r_old) = (state.elastic_energy, state.relaxation_energy);
        let mut heat = 0.0;
        // Share of the cohesive force −c the touch step returns (1 after it).
        let mut cohesion_weight = 1.0;
        if dt > 0.0 {
            // Split the step's displacement along the mean of the old and new normals:
            // the trapezoidal work of the force is, to O(dt³), the normal force times
            // Δ·n_mid; splitting along the new normal alone shifts u_n (and u_t) by
            // O(dt²) per step away from that work, a first-order drift of the energy sum
            // in any impact with sliding (measured 1.4e-8 of K₀ still at 51200 steps per
            // contact, oblique). u_t is carried into the middle plane for the step and into
            // the new plane after it, keeping its length each time.
            let split = if state.active && state.normal != DVec3::ZERO {
                (state.normal + n).normalize_or(n)
            } else {
                n
            };
            let v = displacement / dt;
            let v_n = v.dot(split);
            let v_t = v - split * v_n;
            state.tangential_displacement = rotate_into_plane(state.tangential_displacement, split);
            let (duration, overlap_start) = if state.active {
                (dt, state.overlap)
            } else {
                // The contact began within this step: integrate from the instant of touch
                // (overlap 0 on the straight path of the step), with u = 0 and w_r = 0.
                let approach = -v_n * dt;
                let fraction = if approach > kin.overlap {
                    kin.overlap / approach
                } else {
                    1.0
                };
                state.normal_displacement = -(kin.overlap - fraction * approach).max(0.0);
                // Cohesion at touch (§5): −c acts over the part `fraction` of the step,
                // doing the work c·fraction·approach that the cohesive term c u_n of w_e
                // loses; the trapezoidal rule would charge ½ c·approach for the full −c,
                // a gain when fraction < ½. Returning 2·fraction of it (at most all)
                // makes this step's cohesive work exact and the next step's
                // ½(c_touch − c)Δ_n a loss, never a gain.
                cohesion_weight = (2.0 * fraction).min(1.0);
                (fraction * dt, kin.overlap - fraction * approach)
            };
            state.active = true;
            heat =
                integrate_with(p, &c, state, duration, overlap_start, kin.overlap, v_n, v_t).heat;
            state.tangential_displacement = rotate_into_plane(state.tangential_displacement, n);
        } else if !state.active {
            // Priming pass of grains that start overlapping: u_n = −δ (paper, section 3).
            state.normal_displacement = -kin.overlap;
            state.active = true;
        }
        state.tangential_displacement =
            yield_projection(p, state.normal_displacement, state.tangential_displacement);
        // The dashpot η v of (28)–(29) needs the velocity at the end of the step, where the
        // force acts; the engine hands the half-step one. Extrapolated from the last two
        // half-step velocities it is second-order accurate, which keeps the engine's
        // trapezoidal work of the dashpot consistent with the η v² the law moves into w_r
        // (with the half-step velocity the balance drifts at first order when η is large).
        let velocity = if state.velocity != DVec3::ZERO && dt > 0.0 {
            1.5 * kin.relative_velocity - 0.5 * state.velocity
        } else {
            kin.relative_velocity
        };
        let v_n = velocity.dot(n);
        let force = contact_force(
            p,
            &c,
            state,
            n,
            kin.overlap,
            v_n,
            velocity - n * v_n,
            cohesion_weight,
        );
        state.velocity = kin.relative_velocity;
        let w_e = elastic_potential(p, state.normal_displacement, state.tangential_displacement);
        let w_r = state.relaxation_energy;
        out.force = force;
        out.elastic_energy = w_e;
        out.dissipated[HEAT_CHANNEL] = heat;
        out.dissipated[RELAXATION_CHANNEL] = w_r - w_r_old;
        // Energy the time integration created at this contact: trapezoidal work of the
        // law's force on the bodies plus the change of everything the law stores plus the
        // heat, each from its own formula. Zero in continuous time by (17).
        out.integration_error = if dt > 0.0 {
            old_work + 0.5 * force.dot(displacement) + (w_e - w_e_old) + (w_r - w_r_old) + heat
        } else {
            0.0
        };
        state.elastic_energy = w_e;
        state.heat += heat;
        state.heat_rate = if dt > 0.0 { heat / dt } else { 0.0 };
        state.force = force;
        state.overlap = kin.overlap;
        state.normal = n;
        out
    }
}

/// Time scale of a Hertz-like spring f = k δ^{3/2} for reduced mass `m` at impact speed
/// `v`: contact time 2.943 δ_max / v with δ_max = (5 m v² / (4k))^{2/5}, and the stability
/// limit 2/ω of the stiffness (3/2) k √δ_max at the deepest overlap.
pub fn time_scale(stiffness: f64, m: f64, v: f64) -> TimeScale {
    let max_overlap = (5.0 * m * v * v / (4.0 * stiffness)).powf(0.4);
    let omega = (1.5 * stiffness * max_overlap.sqrt() / m).sqrt();
    TimeScale {
        contact_time: 2.943 * max_overlap / v,
        stability_limit: 2.0 / omega,
    }
}

/// A [0, 1] range.
const UNIT_CLOSED: ParamRange = ParamRange {
    min: 0.0,
    min_inclusive: true,
    max: 1.0,
    max_inclusive: true,
};

/// A range (−∞, ∞).
const ANY_FINITE: ParamRange = ParamRange {
    min: f64::NEG_INFINITY,
    min_inclusive: false,
    max: f64::INFINITY,
    max_inclusive: false,
};

macro_rules! spec {
    ($name:expr, $unit:expr, $doc:expr, $range:expr, $default:expr, $mix:expr) => {
        ParamSpec {
            name: $name,
            unit: $unit,
            doc: $doc,
            range: $range,
            default: $default,
            mix: $mix,
        }
    };
}

/// Declared parameters (set (34) of the paper plus the numerical knobs).
pub const PARAMS: &[ParamSpec] = &[
    spec!(
        "stiffness",
        "kg s^-2 m^-1/2",
        "spring constant k of (19): normal force k δ^{3/2}",
        ParamRange::POSITIVE,
        None,
        MixRule::Harmonic
    ),
    spec!(
        "xi",
        "1",
        "shear ratio ξ of (19); yield |u_t| ≤ √(2ξ)(−u_n)",
        ParamRange::POSITIVE,
        Some(1.0),
        MixRule::Arithmetic
    ),
    spec!(
        "cohesion",
        "N",
        "wet-cohesion constant c of (19)",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "alpha_n",
        "1",
        "gearbox coefficient α_n while overlapping (α_n = 1 apart), (38)",
        UNIT_CLOSED,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "alpha_t",
        "1",
        "gearbox coefficient α_t while overlapping (α_t = 1 apart), (38)",
        UNIT_CLOSED,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "eta_relax_n",
        "1",
        "prefactor of η_n^relax = A d^{-3/8} k^{1/4} m^{1/2} w_r^{1/4} Θ(δ/d), (39)",
        ParamRange::NON_NEGATIVE,
        Some(0.1),
        MixRule::Arithmetic
    ),
    spec!(
        "eta_relax_t",
        "1",
        "prefactor of η_t^relax, same form as η_n^relax, (39)",
        ParamRange::NON_NEGATIVE,
        Some(0.1),
        MixRule::Arithmetic
    ),
    spec!(
        "eta_heat_n",
        "N s/m",
        "η_n^heat, a dashpot acting while overlapping, (37)",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "eta_heat_t",
        "N s/m",
        "η_t^heat, (37)",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "lambda_relax_n",
        "1",
        "prefactor of λ_n^relax = B d^{-3/2} m^{-1/2} k^{-1} w_r^{1/2}, (37)",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "lambda_relax_t",
        "1",
        "prefactor of λ_t^relax, same form, (40)",
        ParamRange::NON_NEGATIVE,
        Some(0.1),
        MixRule::Arithmetic
    ),
    spec!(
        "lambda_heat_n",
        "m N^-1 s^-1",
        "λ_n^heat, constant, (37)",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "lambda_heat_t",
        "m N^-1 s^-1",
        "smooth part of λ_t^heat; its yield part (41) is a return mapping",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "relaxation_time_factor",
        "1",
        "prefactor of τ_r = F √(m/k) / d^{1/4}, (37)",
        ParamRange::POSITIVE,
        Some(0.06),
        MixRule::Arithmetic
    ),
    spec!(
        "heaviside_offset",
        "1",
        "x0 of Θ(x) ≈ ½[tanh((x − x0)/x1) + 1], x = δ/d",
        ANY_FINITE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "heaviside_width",
        "1",
        "x1 of the smoothed Θ; 0: the sharp step",
        ParamRange::NON_NEGATIVE,
        Some(0.0),
        MixRule::Arithmetic
    ),
    spec!(
        "characteristic_velocity",
        "m/s",
        "impact speed the automatic time step is made for",
        ParamRange::POSITIVE,
        Some(DEFAULT_CHARACTERISTIC_VELOCITY),
        MixRule::Max
    ),
];

/// What scenes see of the law.
pub struct JiangLiuLaw;

impl JiangLiuLaw {
    /// Typed parameters from checked values (defaults of [`PARAMS`] for absent fields).
    pub fn resolve_params(values: &ParamValues) -> Result<JiangLiuParams, ParamError> {
        let get = |name: &str| -> f64 {
            values
                .get(name)
                .or_else(|| {
                    PARAMS
                        .iter()
                        .find(|s| s.name == name)
                        .and_then(|s| s.default)
                })
                .unwrap_or(0.0)
        };
        let stiffness = values.get("stiffness").ok_or_else(|| ParamError {
            field: "stiffness".into(),
            expected: format!("the spring constant k in kg s^-2 m^-1/2 (required by `{NAME}`)"),
        })?;
        for spec in PARAMS {
            if let Some(v) = values.get(spec.name)
                && !spec.range.contains(v)
            {
                return Err(ParamError {
                    field: spec.name.into(),
                    expected: spec.range.to_string(),
                });
            }
        }
        let p = JiangLiuParams {
            stiffness,
            xi: get("xi"),
            cohesion: get("cohesion"),
            alpha_n: get("alpha_n"),
            alpha_t: get("alpha_t"),
            eta_relax_n: get("eta_relax_n"),
            eta_relax_t: get("eta_relax_t"),
            eta_heat_n: get("eta_heat_n"),
            eta_heat_t: get("eta_heat_t"),
            lambda_relax_n: get("lambda_relax_n"),
            lambda_relax_t: get("lambda_relax_t"),
            lambda_heat_n: get("lambda_heat_n"),
            lambda_heat_t: get("lambda_heat_t"),
            relaxation_time_factor: get("relaxation_time_factor"),
            heaviside_offset: get("heaviside_offset"),
            heaviside_width: get("heaviside_width"),
            characteristic_velocity: get("characteristic_velocity"),
        };
        if p.alpha_n >= 1.0 && p.lambda_heat_n == 0.0 && p.lambda_relax_n == 0.0 {
            return Err(ParamError {
                field: "alpha_n".into(),
                expected:
                    "a value below 1 (α_n = 1 disconnects the normal spring: no contact force)"
                        .into(),
            });
        }
        Ok(p)
    }
}

impl LawDescriptor for JiangLiuLaw {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        SUMMARY
    }

    fn params(&self) -> &[ParamSpec] {
        PARAMS
    }

    fn validate(&self, values: &ParamValues) -> Result<(), ParamError> {
        Self::resolve_params(values).map(|_| ())
    }

    fn produces_torque(&self, values: &ParamValues) -> bool {
        // The tangential spring and dashpot torque the grains unless both are off.
        values.get("alpha_t").unwrap_or(0.0) < 1.0
            || values.get("eta_relax_t").unwrap_or(0.1) > 0.0
            || values.get("eta_heat_t").unwrap_or(0.0) > 0.0
    }

    fn resolve(
        &self,
        pair: &PairAssignment,
    ) -> Result<(Box<dyn Any + Send + Sync>, TimeScale), ParamError> {
        let p = Self::resolve_params(&pair.values)?;
        let scale = time_scale(
            p.stiffness,
            pair.min_effective_mass,
            p.characteristic_velocity,
        );
        Ok((Box::new(p), scale))
    }

    fn install(
        &self,
        sim: &mut SimBuilder,
        pairs: &[(PairAssignment, Box<dyn Any + Send + Sync>)],
    ) {
        install_law::<JiangLiu>(sim, NAME, pairs);
    }
}

/// Registers `jiang_liu`.
pub fn register(registry: &mut LawRegistry) {
    registry.register(Box::new(JiangLiuLaw));
}

#[cfg(test)]
mod tests;
