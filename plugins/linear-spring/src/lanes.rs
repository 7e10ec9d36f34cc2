//! The lane form of the linear spring–dashpot law: four persistent contacts at once.
//!
//! Every branch of [`LinearSpring::evaluate`](crate::LinearSpring) is here (a contact's
//! first evaluation with its onset weight, the persistent contact, sliding or not, the
//! release after the bodies part), with the same operations in the same order, each
//! lane taking its own branch by a mask, so that each lane has the bits of the scalar
//! form (`tests/lanes.rs` checks it). The rarer branches are computed only when a lane of
//! the four needs them.

use talus_contact::{ContactKinematicsLanes, LaneResponse};
use talus_core::lanes::{F4, V4};

use crate::{LinearParams, NormalDamping, TangentialSpring};

/// [`crate::rotate_into_plane`] in lanes, bit for bit.
#[inline(always)]
pub fn rotate_into_plane(spring: V4, n: V4) -> V4 {
    let projected = spring - n * n.dot(spring);
    let len2 = projected.length_squared();
    len2.gt(F4::zero()).select3(
        projected * (spring.length_squared() / len2).sqrt(),
        projected,
    )
}

/// `v.normalize_or(fallback)` of glam, in lanes.
#[inline(always)]
fn normalize_or(v: V4, fallback: V4) -> V4 {
    let rcp = F4::splat(1.0) / v.length();
    rcp.is_finite()
        .and(rcp.gt(F4::zero()))
        .select3(v * rcp, fallback)
}

/// [`crate::advance_tangential_spring`] in lanes: the single projection where the normal
/// did not turn (or the contact is new), the rotation split at the mean normal elsewhere.
#[inline(always)]
fn advance_tangential_spring(spring: V4, kin: &ContactKinematicsLanes) -> V4 {
    let n = kin.normal;
    let previous = kin.previous_normal;
    let displacement = kin.displacement;
    let unturned = previous.eq(n).or(previous.eq(V4::zero()));
    let split = || {
        let mid = normalize_or(previous + n, n);
        let step = displacement - mid * mid.dot(displacement);
        rotate_into_plane(rotate_into_plane(spring, mid) + step, n)
    };
    let single = || rotate_into_plane(spring, n) + (displacement - n * n.dot(displacement));
    // A flow turns every normal at every step; a packing at rest turns none. Only a mix
    // of the two needs both forms.
    match unturned.bits() {
        0 => split(),
        0xF => single(),
        _ => unturned.select3(single(), split()),
    }
}

/// The parameters of four contacts, in lanes.
struct Params {
    /// Normal stiffness.
    k: F4,
    /// Normal dashpot coefficient of each contact.
    c: F4,
    /// Tangential stiffness.
    kt: F4,
    /// Tangential dashpot coefficient.
    ct: F4,
    /// Friction coefficient.
    friction: F4,
}

impl Params {
    /// The parameters of four contacts of reduced masses `mass`, each formed as the scalar
    /// form forms it. Four contacts of one material pair (the common case) share one set,
    /// read once.
    #[inline(always)]
    fn of(p: [&LinearParams; 4], mass: F4) -> Self {
        let c_ratio = |p: &LinearParams| p.tangential_damping_ratio;
        if p[1..].iter().all(|q| std::ptr::eq(*q, p[0])) {
            let q = p[0];
            let k = F4::splat(q.normal_stiffness);
            let c = match q.normal_damping {
                NormalDamping::Coefficient(c) => F4::splat(c),
                NormalDamping::Ratio(zeta) => F4::splat(2.0 * zeta) * (mass * k).sqrt(),
                NormalDamping::Rate(gamma) => F4::splat(gamma) * mass,
            };
            return Self {
                k,
                c,
                kt: F4::splat(q.tangential_stiffness),
                ct: F4::splat(c_ratio(q)) * c,
                friction: F4::splat(q.friction),
            };
        }
        let lanes = |f: fn(&LinearParams) -> f64| F4::from_fn(|l| f(p[l]));
        let mass = mass.to_array();
        let c = F4::from_fn(|l| {
            p[l].normal_damping
                .coefficient(p[l].normal_stiffness, mass[l])
        });
        Self {
            k: lanes(|p| p.normal_stiffness),
            c,
            kt: lanes(|p| p.tangential_stiffness),
            ct: lanes(c_ratio) * c,
            friction: lanes(|p| p.friction),
        }
    }
}

/// [`crate::onset_weight`] in lanes: 1 where the contact overlapped before this step or
/// did not approach by more than its overlap, the fixed point of the scalar form's three
/// passes elsewhere. `damping_force` is the dashpot's force, positive repulsive.
#[inline(always)]
fn onset_weight(kin: &ContactKinematicsLanes, k: F4, damping_force: F4, dt: f64, delta: F4) -> F4 {
    let (zero, one) = (F4::zero(), F4::splat(1.0));
    let approach = -kin.normal.dot(kin.displacement);
    let settled = kin.previous_overlap.gt(zero).or(approach.le(delta));
    if settled.bits() == 0xF {
        return one;
    }
    let mut weight = F4::splat(0.5) * (one + delta / approach);
    let slowing = F4::splat(dt * dt) / kin.effective_mass;
    for _ in 0..3 {
        let next_approach = approach - slowing * (k * delta * weight + damping_force);
        let ratio = (delta + next_approach) / (approach + next_approach);
        // f64::clamp(0, 1).
        let ratio = ratio.lt(zero).select(zero, ratio);
        let ratio = ratio.gt(one).select(one, ratio);
        weight = (next_approach + approach).gt(zero).select(ratio, weight);
    }
    settled.select(one, weight)
}

/// The release of the lanes whose bodies no longer overlap, as the scalar form's first
/// branch computes it: the normal spring's pull ([`crate::normal_spring_release`]), with its
/// force, energies and the history it leaves.
struct Release {
    pull: F4,
    elastic_error: F4,
    dissipated: [F4; 3],
}

#[inline(always)]
fn release(
    kin: &ContactKinematicsLanes,
    k: F4,
    kt: F4,
    history: &Old,
    trial: V4,
    tangential_displacement: V4,
    book: bool,
) -> Release {
    let zero = F4::zero();
    let (half, minus_half) = (F4::splat(0.5), F4::splat(-0.5));
    let displacement = kin.displacement;
    let previous = kin.previous_normal;
    let old = previous * history.normal_spring;
    let was_touching = kin.previous_overlap.gt(zero);
    let overlapped = was_touching.select(kin.previous_overlap, zero);
    let old_potential = half * k * (overlapped * overlapped);
    let opening = kin.normal.dot(displacement);
    let excess = old.dot(displacement) - F4::splat(2.0) * old_potential;
    let asked = excess / (F4::splat(2.0) * opening);
    let old_length = old.length();
    // f64::min of a positive pull and a length.
    let capped = old_length.lt(asked).select(old_length, asked);
    let pulls = was_touching.and(opening.gt(zero)).and(excess.gt(zero));
    let pull = pulls.select(-capped, zero);
    let mut out = Release {
        pull,
        elastic_error: zero,
        dissipated: [zero; 3],
    };
    if book {
        let normal_error = half * (old + kin.normal * pull).dot(displacement) - old_potential;
        let tangential_error = half
            * kt
            * (trial.length_squared()
                - history.spring.length_squared()
                - (history.spring + trial).dot(displacement));
        out.elastic_error = normal_error + tangential_error;
        out.dissipated = [
            zero + minus_half * (previous * history.normal_dashpot).dot(displacement),
            zero + minus_half * history.tangential_dashpot.dot(displacement),
            zero + half
                * kt
                * (trial - tangential_displacement + V4::zero()).dot(trial - V4::zero()),
        ];
    }
    out
}

/// The history of four contacts before the step, in lanes.
struct Old {
    spring: V4,
    tangential_dashpot: V4,
    normal_dashpot: F4,
    normal_spring: F4,
}

/// Evaluates the lanes `lanes` of four contacts (see the module doc). Returns the lanes
/// evaluated (all of `lanes`) and their response.
#[inline(always)]
pub(crate) fn evaluate(
    p: [&LinearParams; 4],
    kin: &ContactKinematicsLanes,
    history: [&mut TangentialSpring; 4],
    lanes: u32,
    dt: f64,
    book: bool,
) -> (u32, LaneResponse) {
    let zero = F4::zero();
    let mut out = LaneResponse::default();
    if lanes == 0 {
        return (0, out);
    }
    let delta = kin.overlap;
    // The scalar form releases where `delta <= 0` (not where `!(delta > 0)`: a NaN
    // overlap goes the contact's way there too).
    let released = delta.le(zero);
    let n = kin.normal;
    let Params {
        k,
        c,
        kt,
        ct,
        friction,
    } = Params::of(p, kin.effective_mass);
    let vn = kin.normal_velocity;
    let old = Old {
        spring: V4::from_fn(|l| history[l].spring),
        tangential_dashpot: V4::from_fn(|l| history[l].tangential_dashpot),
        normal_dashpot: F4::from_fn(|l| history[l].normal_dashpot),
        normal_spring: F4::from_fn(|l| history[l].normal_spring),
    };
    let normal_damping = -c * vn;
    let spring_force = k * delta * onset_weight(kin, k, normal_damping, dt, delta);
    let fn_mag = spring_force - c * vn;

    let sliding = friction.gt(zero);
    let vt = kin.tangential_velocity;
    let trial = advance_tangential_spring(old.spring, kin);
    let ft_trial = trial * -kt - vt * ct;
    let cap = friction * fn_mag.abs();
    let ft_len = ft_trial.length();
    let slip = ft_len.gt(cap);
    let ft_capped = ft_trial * (cap / ft_len);
    let xi_capped = -(ft_capped + vt * ct) / kt;
    let xi = slip.select3(xi_capped, trial);
    let ft = sliding.select3(slip.select3(ft_capped, ft_trial), V4::zero());
    let tangential_dashpot = vt * -ct;
    out.force = n * fn_mag + ft;
    let displacement = kin.displacement;
    let tangential_displacement = displacement - n * n.dot(displacement);

    if book {
        let half = F4::splat(0.5);
        let minus_half = F4::splat(-0.5);
        let previous = kin.previous_normal;
        let old_normal_spring = previous * old.normal_spring;
        let old_normal_dashpot = previous * old.normal_dashpot;
        let half_k = half * k;
        let potential = half_k * delta * delta;
        let overlapped = kin
            .previous_overlap
            .gt(zero)
            .select(kin.previous_overlap, zero);
        let normal_error = half * (old_normal_spring + n * spring_force).dot(displacement)
            + potential
            - half_k * (overlapped * overlapped);
        let normal_dashpot_work =
            zero + minus_half * (old_normal_dashpot + n * normal_damping).dot(displacement);
        let half_kt = half * kt;
        let slip_work = half_kt * (trial - tangential_displacement + xi).dot(trial - xi);
        let tangential_error = half_kt
            * (trial.length_squared()
                - old.spring.length_squared()
                - (old.spring + trial).dot(displacement));
        let tangential_dashpot_work =
            zero + minus_half * (old.tangential_dashpot + tangential_dashpot).dot(displacement);
        out.elastic_energy = sliding.select(potential + half_kt * xi.length_squared(), potential);
        out.integration_error = sliding.select(normal_error + tangential_error, normal_error);
        out.dissipated[0] = normal_dashpot_work;
        out.dissipated[1] = sliding.select(tangential_dashpot_work, zero);
        out.dissipated[2] = sliding.and(slip).select(zero + slip_work, zero);
    }

    let mut spring = sliding.select3(xi, old.spring);
    let mut tangential_dashpot = sliding.select3(tangential_dashpot, old.tangential_dashpot);
    let (mut normal_spring, mut normal_dashpot) = (spring_force, normal_damping);
    if released.any() {
        // Without friction the spring never held anything (nor has a stiffness to release
        // it with).
        let kt = sliding.select(kt, zero);
        let r = release(kin, k, kt, &old, trial, tangential_displacement, book);
        out.force = released.select3(n * r.pull, out.force);
        if book {
            out.elastic_energy = released.select(zero, out.elastic_energy);
            out.integration_error = released.select(r.elastic_error, out.integration_error);
            for (total, d) in out.dissipated.iter_mut().zip(r.dissipated) {
                *total = released.select(d, *total);
            }
        }
        spring = released.select3(V4::zero(), spring);
        tangential_dashpot = released.select3(V4::zero(), tangential_dashpot);
        normal_dashpot = released.select(zero, normal_dashpot);
        normal_spring = released.select(r.pull, normal_spring);
    }
    let (spring, tangential_dashpot) = (spring.to_array(), tangential_dashpot.to_array());
    let (normal_spring, normal_dashpot) = (normal_spring.to_array(), normal_dashpot.to_array());
    for (l, h) in history.into_iter().enumerate() {
        if lanes >> l & 1 == 1 {
            *h = TangentialSpring {
                spring: spring[l],
                tangential_dashpot: tangential_dashpot[l],
                normal_dashpot: normal_dashpot[l],
                normal_spring: normal_spring[l],
            };
        }
    }
    (lanes, out)
}
