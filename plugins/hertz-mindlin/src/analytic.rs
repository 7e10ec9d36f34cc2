//! Closed-form Hertz–Mindlin results and the damping calibration: contact time and
//! maximum overlap of an elastic impact, effective moduli of two materials, time steps,
//! and the map between a restitution coefficient and the dimensionless damping γ̂ of
//! [`crate::HertzDamping`].
//!
//! Notation: m* reduced mass (kg), R* reduced radius (m), E* effective modulus (Pa),
//! G* effective shear modulus (Pa), v normal impact speed (m/s), δ overlap (m).

use std::f64::consts::PI;

/// t_c v / δ_max for an elastic Hertz impact: 2∫₀¹ dξ/√(1 − ξ^{5/2}) = 2√π Γ(7/5)/Γ(9/10).
pub const HERTZ_DURATION_OVER_OVERLAP: f64 = 2.943_275_184_324_706;

/// The prefactor of the Hertz contact time, t_c = 2.868 (m*²/(R* E*² v))^{1/5}: the
/// constant [`HERTZ_DURATION_OVER_OVERLAP`] × (15/16)^{2/5}.
pub const HERTZ_CONTACT_TIME_FACTOR: f64 = 2.868_265_699_195_333;

/// Duration of the elastic Hertz impact in the units of [`damped_hertz_impact`]:
/// [`HERTZ_DURATION_OVER_OVERLAP`] × (5/4)^{2/5}.
pub const DIMENSIONLESS_ELASTIC_DURATION: f64 = 3.218_065_459_719_045;

/// Shear modulus G = E / (2(1 + ν)) of an isotropic material, Pa.
pub fn shear_modulus(youngs_modulus: f64, poisson_ratio: f64) -> f64 {
    youngs_modulus / (2.0 * (1.0 + poisson_ratio))
}

/// Effective (contact) modulus of two materials, Pa:
/// 1/E* = (1 − ν_a²)/E_a + (1 − ν_b²)/E_b. For one material, E* = E / (2(1 − ν²)).
pub fn effective_modulus(e_a: f64, nu_a: f64, e_b: f64, nu_b: f64) -> f64 {
    1.0 / ((1.0 - nu_a * nu_a) / e_a + (1.0 - nu_b * nu_b) / e_b)
}

/// Effective shear modulus of two materials (Mindlin), Pa:
/// 1/G* = (2 − ν_a)/G_a + (2 − ν_b)/G_b with G = E/(2(1 + ν)).
/// For one material, G* = G / (2(2 − ν)).
pub fn effective_shear_modulus(e_a: f64, nu_a: f64, e_b: f64, nu_b: f64) -> f64 {
    1.0 / ((2.0 - nu_a) / shear_modulus(e_a, nu_a) + (2.0 - nu_b) / shear_modulus(e_b, nu_b))
}

/// Hertz normal force F_n = (4/3) E* √R* δ^{3/2}, N (zero without overlap).
pub fn hertz_force(effective_modulus: f64, reduced_radius: f64, overlap: f64) -> f64 {
    if overlap <= 0.0 {
        return 0.0;
    }
    4.0 / 3.0 * effective_modulus * (reduced_radius * overlap).sqrt() * overlap
}

/// Hertz normal stiffness dF_n/dδ = 2 E* √(R* δ), N/m (zero without overlap).
pub fn hertz_stiffness(effective_modulus: f64, reduced_radius: f64, overlap: f64) -> f64 {
    if overlap <= 0.0 {
        return 0.0;
    }
    2.0 * effective_modulus * (reduced_radius * overlap).sqrt()
}

/// Mindlin tangential stiffness k_t = 8 G* √(R* δ), N/m (zero without overlap).
pub fn mindlin_stiffness(effective_shear_modulus: f64, reduced_radius: f64, overlap: f64) -> f64 {
    if overlap <= 0.0 {
        return 0.0;
    }
    8.0 * effective_shear_modulus * (reduced_radius * overlap).sqrt()
}

/// Maximum overlap of an elastic head-on Hertz impact at normal speed `impact_speed`, m:
/// δ_max = (15 m* v² / (16 E* √R*))^{2/5} (all of ½m*v² stored as (8/15)E*√R* δ^{5/2}).
pub fn hertz_max_overlap(
    reduced_mass: f64,
    reduced_radius: f64,
    effective_modulus: f64,
    impact_speed: f64,
) -> f64 {
    (15.0 * reduced_mass * impact_speed * impact_speed
        / (16.0 * effective_modulus * reduced_radius.sqrt()))
    .powf(0.4)
}

/// Duration of an elastic head-on Hertz impact at normal speed `impact_speed`, s:
/// t_c = 2.868 (m*² / (R* E*² v))^{1/5} = 2.943 δ_max / v.
pub fn hertz_contact_time(
    reduced_mass: f64,
    reduced_radius: f64,
    effective_modulus: f64,
    impact_speed: f64,
) -> f64 {
    HERTZ_CONTACT_TIME_FACTOR
        * (reduced_mass * reduced_mass
            / (reduced_radius * effective_modulus * effective_modulus * impact_speed))
            .powf(0.2)
}

/// The time step that resolves an elastic Hertz impact at `impact_speed` with `steps`
/// steps: t_c / n, s.
pub fn hertz_time_step(
    steps: f64,
    reduced_mass: f64,
    reduced_radius: f64,
    effective_modulus: f64,
    impact_speed: f64,
) -> f64 {
    hertz_contact_time(
        reduced_mass,
        reduced_radius,
        effective_modulus,
        impact_speed,
    ) / steps
}

/// Rayleigh time step of a sphere, s: the time a Rayleigh surface wave takes to cross
/// half of it, t_R = π R √(ρ/G) / (0.1631 ν + 0.8766) (Li et al. 2005; the usual
/// reference in DEM codes, which run at 10–40 % of it).
pub fn rayleigh_time_step(
    radius: f64,
    density: f64,
    youngs_modulus: f64,
    poisson_ratio: f64,
) -> f64 {
    PI * radius * (density / shear_modulus(youngs_modulus, poisson_ratio)).sqrt()
        / (0.1631 * poisson_ratio + 0.8766)
}

/// Damping ratio ζ = γ̂/√5 of the linear oscillator that the damped Hertz impact becomes
/// in the time τ of [`restitution_from_damping`].
pub fn equivalent_damping_ratio(gamma: f64) -> f64 {
    gamma / 5.0f64.sqrt()
}

/// Restitution of the damped Hertz impact of [`crate::HertzDamping`] (the dashpot never
/// pulls: it acts until the total normal force vanishes), in closed form:
///
///   e = exp(−2ζ arccos ζ / √(1 − ζ²))     for ζ < 1,
///   e = exp(−2)                            for ζ = 1,
///   e = exp(−2ζ arcosh ζ / √(ζ² − 1))      for ζ > 1,     ζ = γ̂/√5.
///
/// Why: with q = √(4/5) x^{5/4} and p = x', the dimensionless impact of
/// [`damped_hertz_impact`] has energy ½p² + ½q², and in the time dτ = (√5/2) x^{1/4} dt it
/// becomes the linear oscillator q̈ = −q − 2ζ q̇ with the force q + 2ζp clipped at zero.
/// That force vanishes at τ* = 2 arccos ζ/√(1 − ζ²), where |p| = e^{−ζτ*}; then the bodies
/// fly apart at that speed. 0 for a negative or non-finite γ̂.
pub fn restitution_from_damping(gamma: f64) -> f64 {
    if !(gamma >= 0.0 && gamma.is_finite()) {
        return 0.0;
    }
    let zeta = equivalent_damping_ratio(gamma);
    let pulse = if zeta < 1.0 {
        2.0 * zeta.acos() / (1.0 - zeta * zeta).sqrt()
    } else if zeta > 1.0 {
        2.0 * zeta.acosh() / (zeta * zeta - 1.0).sqrt()
    } else {
        2.0
    };
    (-zeta * pulse).exp()
}

/// Restitution of the same impact when the dashpot acts until the overlap closes, pulling
/// at the end (the LIGGGHTS and EDEM default): the linear oscillator's
/// e = exp(−πζ/√(1 − ζ²)), ζ = γ̂/√5, and 0 (the bodies stay stuck) for ζ ≥ 1. This is why
/// their β = −ln e/√(ln²e + π²), with c = 2√(5/6) β √(m* k_n), i.e. γ̂ = √5 β, is exact
/// under that rule (and not under the one [`crate::HertzDamping`] uses).
pub fn restitution_until_overlap_closes(gamma: f64) -> f64 {
    let zeta = equivalent_damping_ratio(gamma);
    if !(0.0..1.0).contains(&zeta) {
        return 0.0;
    }
    (-std::f64::consts::PI * zeta / (1.0 - zeta * zeta).sqrt()).exp()
}

/// Dimensionless damping γ̂ of [`crate::HertzDamping`] that gives the restitution `e` at
/// every impact speed: the root of [`restitution_from_damping`]`(γ̂) = e`, found by
/// bisection (the restitution falls monotonically from 1 at γ̂ = 0 towards 0 as γ̂
/// grows), to 10⁻¹² relative. `None` for `e` outside (0, 1].
pub fn damping_from_restitution(e: f64) -> Option<f64> {
    if !(e > 0.0 && e <= 1.0) {
        return None;
    }
    if e == 1.0 {
        return Some(0.0);
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while restitution_from_damping(hi) > e {
        lo = hi;
        hi *= 2.0;
        if !hi.is_finite() {
            return None;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if restitution_from_damping(mid) > e {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    Some(0.5 * (lo + hi))
}

/// The damping ratio β = −ln e / √(ln² e + π²) that LIGGGHTS and EDEM use with Hertz:
/// exact for a linear spring, and for Hertz when the dashpot acts until the overlap
/// closes (see [`restitution_until_overlap_closes`]), not under the no-tension rule of
/// [`crate::HertzDamping`]. Their dashpot c = 2√(5/6) β √(m* k_n) is ours with γ̂ = √5 β.
pub fn linear_damping_ratio(e: f64) -> f64 {
    let l = e.ln();
    -l / (l * l + PI * PI).sqrt()
}

/// Outcome of the dimensionless damped Hertz impact of [`damped_hertz_impact`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DampedImpact {
    /// Rebound speed over impact speed, e.
    pub restitution: f64,
    /// Time from first touch until the normal force vanishes, in units of δ₀/v.
    pub duration: f64,
    /// Largest overlap, in units of δ₀ = (m* v² / ((4/3) E* √R*))^{2/5}.
    pub max_overlap: f64,
}

/// Most RK4 steps of one dimensionless impact: a guard against a trajectory that would
/// never end (none does under the no-tension rule; under the other, ζ ≥ 1 sticks).
const MAX_IMPACT_STEPS: usize = 50_000_000;

/// Head-on Hertz impact with the damping of [`crate::HertzDamping`], dimensionless,
/// integrated numerically: the duration of the force pulse and the largest overlap, which
/// have no closed form, and an independent check of [`restitution_from_damping`].
///
/// With δ = δ₀ x, t = (δ₀/v) τ and δ₀ = (m* v² / K)^{2/5}, K = (4/3) E* √R*, the
/// collision m* δ̈ = −max(0, K δ^{3/2} + c(δ) δ̇) with c(δ) = γ̂ √(m* K) δ^{1/4} becomes
///
///   x'' = −max(0, x^{3/2} + γ̂ x^{1/4} x'),   x(0) = 0, x'(0) = 1,
///
/// free of m*, R*, E* and v: the restitution depends on γ̂ alone. The dashpot never pulls
/// (the total force is clipped at zero), so once the force vanishes during unloading the
/// bodies fly apart at constant speed and that speed is the rebound speed. Integrated with
/// classical RK4 at 10⁻³ of the elastic time scale (finer for large γ̂); the restitution is
/// accurate to about 10⁻⁸. Returns restitution 0 for a negative or non-finite γ̂.
pub fn damped_hertz_impact(gamma: f64) -> DampedImpact {
    impact_with_step(gamma, impact_step(gamma), true)
}

/// RK4 step of [`damped_hertz_impact`]: strong damping stops the approach early, at an
/// overlap of order γ̂^{-4/5}, so the step scales with that length (which also keeps
/// γ̂ x^{1/4} h well inside RK4's stability bound).
fn impact_step(gamma: f64) -> f64 {
    1e-3 * (1.0f64).min(gamma.powf(-0.8))
}

/// Finest step of the event location and of the start, relative to the step `h`.
const FINEST_STEP: f64 = 1e-7;

/// [`damped_hertz_impact`] with a given dimensionless RK4 step `h`, with the force
/// clipped at zero (`no_tension`) or not (the dashpot then acts until the overlap closes).
/// The acceleration has a kink where the force reaches zero and a singular derivative
/// (x^{1/4}) at first touch, where RK4 loses its order: the run starts with steps of
/// 10⁻⁷ h that double up to h, and a step across the end of the force pulse is retaken
/// with steps 16 times shorter until they are 10⁻⁷ h long.
fn impact_with_step(gamma: f64, h: f64, no_tension: bool) -> DampedImpact {
    if !(gamma >= 0.0 && gamma.is_finite() && h > 0.0) {
        return DampedImpact {
            restitution: 0.0,
            duration: 0.0,
            max_overlap: 0.0,
        };
    }
    let force = |x: f64, v: f64| -> f64 {
        let root = x.sqrt();
        x * root + gamma * root.sqrt() * v
    };
    let acceleration = |x: f64, v: f64| -> f64 {
        if x <= 0.0 {
            return 0.0;
        }
        if no_tension {
            -force(x, v).max(0.0)
        } else {
            -force(x, v)
        }
    };
    let rk4 = |x: f64, v: f64, h: f64| -> (f64, f64) {
        let (k1x, k1v) = (v, acceleration(x, v));
        let (k2x, k2v) = (
            v + 0.5 * h * k1v,
            acceleration(x + 0.5 * h * k1x, v + 0.5 * h * k1v),
        );
        let (k3x, k3v) = (
            v + 0.5 * h * k2v,
            acceleration(x + 0.5 * h * k2x, v + 0.5 * h * k2v),
        );
        let (k4x, k4v) = (v + h * k3v, acceleration(x + h * k3x, v + h * k3v));
        (
            x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x),
            v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v),
        )
    };
    let (mut x, mut v, mut t, mut max_overlap) = (0.0f64, 1.0f64, 0.0f64, 0.0f64);
    let mut step = FINEST_STEP * h;
    let mut refining = false;
    for _ in 0..MAX_IMPACT_STEPS {
        let (x_new, v_new) = rk4(x, v, step);
        let closed = x_new <= 0.0;
        let unloaded = no_tension && v_new < 0.0 && !closed && force(x_new, v_new) <= 0.0;
        if (closed || unloaded) && step > FINEST_STEP * h {
            // Locate the end of the pulse: retake the step in shorter ones.
            step /= 16.0;
            refining = true;
            continue;
        }
        max_overlap = max_overlap.max(x_new);
        if v > 0.0 && v_new <= 0.0 {
            // The turning point lies within the step: x + v²/(2|a|) to third order.
            let a = acceleration(x, v);
            if a < 0.0 {
                max_overlap = max_overlap.max(x - 0.5 * v * v / a);
            }
        }
        if closed {
            // The overlap closed within the step: interpolate.
            let s = x / (x - x_new);
            return DampedImpact {
                restitution: -(v + s * (v_new - v)),
                duration: t + s * step,
                max_overlap,
            };
        }
        if unloaded {
            // The force vanished: from here the bodies separate at constant speed.
            return DampedImpact {
                restitution: -v_new,
                duration: t + step,
                max_overlap,
            };
        }
        x = x_new;
        v = v_new;
        t += step;
        if !refining {
            step = (2.0 * step).min(h);
        }
    }
    DampedImpact {
        restitution: 0.0,
        duration: t,
        max_overlap,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_match_their_gamma_function_forms() {
        // Independent: the duration and overlap from the RK4 integral at γ̂ = 0.
        let elastic = damped_hertz_impact(0.0);
        assert!((elastic.duration - DIMENSIONLESS_ELASTIC_DURATION).abs() < 1e-8);
        assert!((elastic.restitution - 1.0).abs() < 1e-8);
        assert!((elastic.max_overlap - 1.25f64.powf(0.4)).abs() < 1e-8);
        assert!(
            (HERTZ_DURATION_OVER_OVERLAP * (15.0f64 / 16.0).powf(0.4) - HERTZ_CONTACT_TIME_FACTOR)
                .abs()
                < 1e-12
        );
        assert!(
            (HERTZ_DURATION_OVER_OVERLAP * 1.25f64.powf(0.4) - DIMENSIONLESS_ELASTIC_DURATION)
                .abs()
                < 1e-12
        );
    }

    #[test]
    fn integrated_impact_matches_the_closed_form() {
        // Under- and overdamped, and ζ = 1 (γ̂ = √5).
        for gamma in [0.01, 0.1, 0.5, 1.0, 2.0, 5.0f64.sqrt(), 3.0, 10.0, 50.0] {
            let integrated = damped_hertz_impact(gamma).restitution;
            let closed = restitution_from_damping(gamma);
            assert!(
                (integrated - closed).abs() < 1e-7 * closed.max(1e-3),
                "γ̂ = {gamma}: integrated {integrated}, closed form {closed}"
            );
        }
    }

    #[test]
    fn without_the_clip_the_linear_formula_is_exact() {
        // The dashpot acting until the overlap closes: RK4 against exp(−πζ/√(1 − ζ²)),
        // and the LIGGGHTS/EDEM γ̂ = √5 β giving back e.
        for e in [0.1, 0.3, 0.5, 0.8, 0.95] {
            let gamma = 5.0f64.sqrt() * linear_damping_ratio(e);
            let integrated = impact_with_step(gamma, impact_step(gamma), false).restitution;
            assert!(
                (integrated - e).abs() < 1e-7,
                "e = {e}: integrated {integrated}"
            );
            assert!((restitution_until_overlap_closes(gamma) - e).abs() < 1e-12);
        }
    }

    #[test]
    fn weak_damping_matches_first_order_perturbation() {
        // Energy lost along the elastic trajectory: 1 − e² ≈ 2γ̂·2∫x^{1/4}x' dt
        // = (2π/√5) γ̂, so (1 − e)/γ̂ → π/√5.
        let gamma = 1e-4;
        let expected = PI / 5.0f64.sqrt();
        for e in [
            damped_hertz_impact(gamma).restitution,
            restitution_from_damping(gamma),
        ] {
            let slope = (1.0 - e) / gamma;
            assert!((slope - expected).abs() / expected < 1e-3, "slope {slope}");
        }
    }

    #[test]
    fn restitution_converges_in_the_step() {
        for gamma in [0.1f64, 0.5, 2.0, 50.0] {
            let h = impact_step(gamma);
            let coarse = impact_with_step(gamma, h, true).restitution;
            let fine = impact_with_step(gamma, 0.25 * h, true).restitution;
            assert!(
                (coarse - fine).abs() < 1e-7,
                "γ̂ = {gamma}: {coarse} vs {fine}"
            );
        }
    }

    #[test]
    fn calibration_round_trips() {
        for e in [1e-6, 0.05, 0.2, 0.5, 0.8, 0.95, 0.999] {
            let gamma = damping_from_restitution(e).unwrap();
            let back = restitution_from_damping(gamma);
            assert!(
                (back - e).abs() < 1e-10 * e.max(1e-3),
                "e = {e}: γ̂ = {gamma}, back {back}"
            );
        }
        assert_eq!(damping_from_restitution(1.0), Some(0.0));
        assert_eq!(damping_from_restitution(0.0), None);
        assert_eq!(damping_from_restitution(1.5), None);
        assert_eq!(damping_from_restitution(f64::NAN), None);
    }

    #[test]
    fn restitution_falls_monotonically() {
        let mut last = 1.0;
        for k in 1..400 {
            let gamma = 0.01 * k as f64 * k as f64;
            let e = restitution_from_damping(gamma);
            assert!(e < last && e > 0.0, "γ̂ = {gamma}: e = {e}");
            last = e;
        }
    }

    #[test]
    fn linear_formula_misses_the_no_tension_restitution() {
        // Under the no-tension rule the LIGGGHTS/EDEM damping gives a livelier rebound.
        let gamma_linear = 5.0f64.sqrt() * linear_damping_ratio(0.5);
        let got = damped_hertz_impact(gamma_linear).restitution;
        assert!(got - 0.5 > 0.04, "got {got}");
    }

    #[test]
    fn moduli_of_one_material() {
        let (e, nu) = (2e11, 0.3);
        let e_star = effective_modulus(e, nu, e, nu);
        assert!((e_star - e / (2.0 * (1.0 - nu * nu))).abs() / e_star < 1e-14);
        let g_star = effective_shear_modulus(e, nu, e, nu);
        assert!((g_star - shear_modulus(e, nu) / (2.0 * (2.0 - nu))).abs() / g_star < 1e-14);
    }
}
