//! The lane form of the linear spring–dashpot law: four persistent contacts at once.
//!
//! It covers the contacts a dense flow is made of, those that overlapped at their last
//! evaluation and still overlap (`previous_overlap > 0`, `overlap > 0`), with the same
//! operations in the same order as [`LinearSpring::evaluate`](crate::LinearSpring), so
//! that each lane has the bits of the scalar form (`tests/lanes.rs` checks it). It leaves
//! the rest to the scalar form: a contact's first evaluation (the onset weight), the
//! evaluation after the bodies part (the release pull), and the one after that.

use talus_contact::{ContactKinematicsLanes, LaneResponse};
use talus_core::lanes::{F4, M4, V4};

use crate::{LinearParams, TangentialSpring};

/// [`crate::rotate_into_plane`] in lanes.
#[inline(always)]
fn rotate_into_plane(spring: V4, n: V4) -> V4 {
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

/// Lanes of `values` picked by `f`.
#[inline(always)]
fn lanes_of<T>(values: &[&T; 4], f: impl Fn(&T) -> f64) -> F4 {
    F4::from_fn(|k| f(values[k]))
}

/// Evaluates the persistent contacts among the four lanes (see the module doc); `lanes`
/// are those the core offers. Returns the lanes evaluated and their response.
#[inline(always)]
pub(crate) fn evaluate(
    p: [&LinearParams; 4],
    kin: &ContactKinematicsLanes,
    history: [&mut TangentialSpring; 4],
    lanes: u32,
    book: bool,
) -> (u32, LaneResponse) {
    let zero = F4::zero();
    let delta = kin.overlap;
    let persistent: M4 = delta
        .gt(zero)
        .and(kin.previous_overlap.gt(zero))
        .and(kin.previous_normal.eq(V4::zero()).not());
    let evaluated = persistent.bits() & lanes;
    let mut out = LaneResponse::default();
    if evaluated == 0 {
        return (0, out);
    }
    let n = kin.normal;
    let k = lanes_of(&p, |p| p.normal_stiffness);
    let mass = kin.effective_mass.to_array();
    let c = F4::from_fn(|l| {
        p[l].normal_damping
            .coefficient(p[l].normal_stiffness, mass[l])
    });
    let vn = kin.normal_velocity;
    // The onset weight is 1 for a contact that overlapped before this step.
    let spring_force = k * delta;
    let fn_mag = spring_force - c * vn;
    let old_spring = V4::from_fn(|l| history[l].spring);
    let old_tangential_dashpot = V4::from_fn(|l| history[l].tangential_dashpot);
    let normal_damping = -c * vn;

    let friction = lanes_of(&p, |p| p.friction);
    let sliding = friction.gt(zero);
    let kt = lanes_of(&p, |p| p.tangential_stiffness);
    let ct = lanes_of(&p, |p| p.tangential_damping_ratio) * c;
    let vt = kin.tangential_velocity;
    let trial = advance_tangential_spring(old_spring, kin);
    let ft_trial = trial * -kt - vt * ct;
    let cap = friction * fn_mag.abs();
    let ft_len = ft_trial.length();
    let slip = ft_len.gt(cap);
    let ft_capped = ft_trial * (cap / ft_len);
    let xi_capped = (-(ft_capped + vt * ct)).div(kt);
    let xi = slip.select3(xi_capped, trial);
    let ft = sliding.select3(slip.select3(ft_capped, ft_trial), V4::zero());
    let tangential_dashpot = vt * -ct;
    out.force = n * fn_mag + ft;

    if book {
        let half = F4::splat(0.5);
        let minus_half = F4::splat(-0.5);
        let displacement = kin.displacement;
        let tangential_displacement = displacement - n * n.dot(displacement);
        let previous = kin.previous_normal;
        let old_normal_spring = previous * F4::from_fn(|l| history[l].normal_spring);
        let old_normal_dashpot = previous * F4::from_fn(|l| history[l].normal_dashpot);
        let half_k = half * k;
        let potential = half_k * delta * delta;
        let normal_error = half * (old_normal_spring + n * spring_force).dot(displacement)
            + potential
            - half_k * (kin.previous_overlap * kin.previous_overlap);
        let normal_dashpot_work =
            zero + minus_half * (old_normal_dashpot + n * normal_damping).dot(displacement);
        let half_kt = half * kt;
        let slip_work = half_kt * (trial - tangential_displacement + xi).dot(trial - xi);
        let tangential_error = half_kt
            * (trial.length_squared()
                - old_spring.length_squared()
                - (old_spring + trial).dot(displacement));
        let tangential_dashpot_work = zero
            + minus_half * (old_tangential_dashpot + tangential_dashpot).dot(displacement);
        out.elastic_energy =
            sliding.select(potential + half_kt * xi.length_squared(), potential);
        out.integration_error =
            sliding.select(normal_error + tangential_error, normal_error);
        out.dissipated[0] = normal_dashpot_work;
        out.dissipated[1] = sliding.select(tangential_dashpot_work, zero);
        out.dissipated[2] = sliding.and(slip).select(zero + slip_work, zero);
    }

    let spring = sliding.select3(xi, old_spring).to_array();
    let tangential_dashpot = sliding
        .select3(tangential_dashpot, old_tangential_dashpot)
        .to_array();
    let (normal_spring, normal_dashpot) = (spring_force.to_array(), normal_damping.to_array());
    for (l, h) in history.into_iter().enumerate() {
        if evaluated >> l & 1 == 1 {
            *h = TangentialSpring {
                spring: spring[l],
                tangential_dashpot: tangential_dashpot[l],
                normal_dashpot: normal_dashpot[l],
                normal_spring: normal_spring[l],
            };
        }
    }
    (evaluated, out)
}
